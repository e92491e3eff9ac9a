"""Judge the effects of an ambiguous set against each other again on the windows the fit
left out.

`evidence.verdict` keeps a rival effect beside the chosen one unless the chosen fit is
clearly better on the fit's held-out clusters. On a costly model those are about 100
sparse windows (the Drake backend's `fit_windows`), where two effects that differ only
in some windows tie: a viscous drag and a rolling resistance differ in how a coast's
deceleration grows with speed, so a few coasts of different speeds tell them apart. On
the twenty-ninth set's 100807 and 100816 (drags of 0.17 and 0.085 N s/m, after a
follow-up of coasts from 0.05 to 0.3 m/s) the drag was chosen with intervals of 0.13 to
0.22 and 0.076 to 0.11, yet rolling resistance stayed beside it.

The test: each pair of effects in the set, each by its fit (its fold values, each fitted
without its fold), cluster by cluster over the left-out windows (boundary.size_test_problem,
where nothing is fitted), by the statistics the verdict used (the paired z, and the
ranks where the choice was judged by them). Two free-ball effects are compared on the
left-out free windows (evidence.free_ball_problem) with the free-ball fit's 0.3 s
rollouts (on 0.1 s ones the two part too little: 100720, 100728 and 100839, drags of
0.16-0.20 N s/m, read z -1.9..+0.5 there). A free-ball effect against another kind is
judged on all left-out windows and on the free ones, where it was fitted, and is beaten
only when beaten on both: on the thirty-second set's 101138 (a drag of 0.23 N s/m, after
a follow-up of coasts) an EE-ball offset of 0.94 mm that absorbed the pushes' mismatch
beat the drag's fit (0.226) at z 5.0 over all windows, and the confident answer named
the offset. Any other effect is judged on all left-out windows, where it was fitted (on
the free ones a mass or an EE-ball mu does nothing). An effect that another is clearly
better than there leaves the set, the chosen one too: on development draw 100518 (a
table offset of -1.3 mm) the EE-ball offset was chosen and the table's, beside it, beat
it at z 11 on the left-out windows. The bar is
evidence.worse_z over the tests that could drop any one effect (the other members) and
the two looks (the fit's clusters, then these), so the truth leaves the set in at most
5 % of diagnoses across both. Where a pair is judged by two statistics (the paired z and
the ranks, on the free windows), an effect leaves only when both put it beyond the bar
(an intersection-union test: no share of the 5 % between them). Taking either, with the
5 % shared, dropped the truth on the thirtieth set's 100935 (a rolling resistance of
3.2 mm, beaten by a drag at paired z 2.49 but rank z 1.92, bar 2.24: the two fits' error
on the left-out free windows differed by 0.5 % of what either explained) and left a
confident wrong drag. The chosen effect leaves only
for one fitted on the same windows (both free-ball fits or both not) that may lead the
answer (the caller's `may_lead`: its interval, widened as the chosen one's was, clear of
the model's value and beyond its size that matters, and no calibration re-estimate,
evidence.may_answer); it then leads. A rival whose interval holds the
model's value is as consistent with the data as the model without it, so the chosen
effect it beat stays, the rival beside it: on the thirty-fifth set's 101422 (a drag of
0.12 N s/m, one recording) a rolling resistance beat the chosen drag at z 2.14 (bar 2.0)
and led a confident answer of 0.13 mm with an interval of -0.2..0.48 mm. `none` is no member here (boundary.confirm_on_left_out and beyond_size judge
it). Recorded as judged["left_out_rivals"]: each member the test dropped or kept, with
the z (beaten_z) of the member that beat it most (positive: that one is better).
"""
from __future__ import annotations

import numpy as np

from adaptive_c3.tools.diagnosis.engine.fit import cluster_z, evaluate

LOOKS = 2      # the rival rule on the fit's clusters, then this test on the left-out ones


def rivals_on_left_out(judged, chosen, fits, fits_free, size_prob, free_left_out=None,
                       may_lead=None):
    """Drop from judged's ambiguous set each effect another member clearly beats on the
    left-out windows of size_prob (two free-ball effects: on the free windows of
    free_left_out, the free-ball fit's longer rollouts, where given); the verdict is
    `named` when one is left. may_lead(fit) -> bool: whether a fit may take the chosen
    one's place (by default any; the caller widens its interval before it says). Returns
    the fit that now leads the answer when it is not `chosen`, else None."""
    from adaptive_c3.tools.diagnosis.engine.evidence import (FREE_EFFECTS, free_ball_problem,
                                                             worse_z)
    amb = judged.get("ambiguous") or []
    if size_prob is None or chosen is None or len(amb) < 2 or len(chosen.cands) != 1:
        return None
    members = _members(amb, chosen, fits, fits_free)
    if len(members) < 2 or not any(f is chosen for _, f, _ in members):
        return None
    free_prob = []                     # the left-out free windows, made once when needed

    def free_windows():
        if not free_prob:
            free_prob.append(free_ball_problem(free_left_out if free_left_out is not None
                                               else size_prob))
        return free_prob[0]

    def problems(f, g):
        """Where f is judged against g: two free-ball effects on the free windows; a
        free-ball f against another kind on all windows and on the free ones, where it
        was fitted (beaten only when beaten on both); any other f on all windows."""
        f_free, g_free = (h.cands[0].name in FREE_EFFECTS for h in (f, g))
        if not f_free or free_windows() is None:
            return [size_prob]
        return [free_windows()] if g_free else [size_prob, free_windows()]

    per_c = {}

    def ssr(prob, f):
        if (id(prob), id(f)) not in per_c:
            per_c[id(prob), id(f)] = evaluate(prob, f)[2]
        return per_c[id(prob), id(f)]

    bar = worse_z(LOOKS * (len(members) - 1))
    out, dropped = [], []
    for row, f, family in members:
        best = None                          # (z, fit, problem) of its strongest rival
        for _, g, g_family in members:
            if g is f or (f is chosen and g_family != family):
                continue
            z, prob = min(((beaten_z(ssr(p, f), ssr(p, g), p.z_stat), p)
                           for p in problems(f, g)), key=lambda zp: zp[0])
            if best is None or z > best[0]:
                best = (z, g, prob)
        if best is None:
            continue
        gone = best[0] >= bar
        out.append(dict(name=f.label(), beaten_by=best[1].label(), z=best[0],
                        bar=float(bar), dropped=gone, windows=int(np.sum(best[2].fold >= 0))))
        if gone:
            dropped.append(row)
    judged["left_out_rivals"] = out
    if not dropped:
        return None
    kept = [a for a in amb if not any(a is d for d in dropped)]
    lead, lead_row = chosen, next(a for a, f, _ in members if f is chosen)
    if any(lead_row is d for d in dropped):    # the chosen one fell: the best kept of its kind
        family = next(k for _, f, k in members if f is chosen)
        same = [(a, f) for a, f, k in members if k == family and any(a is b for b in kept)]
        pick = next(((a, f) for a, f in same if may_lead is None or may_lead(f)), None)
        if pick:
            lead_row, lead = pick
        else:                    # what beat it fell too, or may not lead: it stays
            dropped = [d for d in dropped if d is not lead_row]
            kept = [a for a in amb if not any(a is d for d in dropped)]
            next(r for r in out if r["name"] == chosen.label()).update(
                dropped=False, kept="the effects fitted as it was that stay may not "
                "answer: an interval holding the model's value or within the size that "
                "matters, or a calibration re-estimate" if same else
                "no effect fitted as it was stays")
    judged["ambiguous"] = [lead_row] + [a for a in kept if a is not lead_row]
    if not dropped:
        return None
    gone = {d["name"] for d in dropped}
    judged["separating_excitation"] = [p for p in judged.get("separating_excitation", [])
                                       if not gone & set(p["between"])]
    if len(judged["ambiguous"]) < 2:
        judged.update(verdict="named", ambiguous=[], separating_excitation=[])
    return None if lead is chosen else lead


def beaten_z(f_c: np.ndarray, g_c: np.ndarray, z_stat: str = "paired") -> float:
    """How clearly g beats f, from their per-cluster SSR: the paired z, or where the
    problem counts clusters by another statistic (z_stat), the smaller of the two, so that
    f is beaten only when both statistics say so."""
    stats = ("paired",) if z_stat == "paired" else ("paired", z_stat)
    return min(float(cluster_z(f_c, g_c, st)) for st in stats)


def _members(amb, chosen, fits, fits_free) -> list:
    """[(set row, fit, "free" | "all")] of the set's single physical effects: the chosen
    fit for its own row, else the free-ball fit of a free-ball effect where there is one,
    else the fit on all windows."""
    from adaptive_c3.tools.diagnosis.backends.effects import Candidate
    from adaptive_c3.tools.diagnosis.engine.evidence import FREE_EFFECTS
    free = {f.label(): f for f in fits_free if len(f.cands) == 1}
    every = {f.label(): f for f in fits if len(f.cands) == 1}
    chosen_family = "free" if any(f is chosen for f in fits_free) else "all"
    out = []
    for a in amb:
        if a["name"] == "none":
            continue
        label = Candidate(a["name"], a["target"]).label()
        if label == chosen.label():
            out.append((a, chosen, chosen_family))
            continue
        f = free.get(label) if a["name"] in FREE_EFFECTS else None
        family = "free" if f is not None else "all"
        f = f or every.get(label)
        if f is not None and f.physical and len(f.values) == 1:
            out.append((a, f, family))
    return out
