"""Whether the data rule out an effect at the size that matters: a direct test where the
fitted interval cannot say.

`evidence.not_excluded` lets an effect join `none` when its 95 % interval reaches a size
that matters (spec.relevant_size). That interval is a linearisation at the fit's value,
and where the error is flat there (an EE-ball mu above the slip a push asks for acts as
the model's 1; a tiny drag changes little) it can be wide whatever the data say about
the size that matters itself: on clean development draws 90009 and 90020 (Drake's
plant, after one follow-up) EE-ball mu read 0.70-0.74 with intervals of 0.34..1.06 and
-0.34..1.83, and the fit's held-out error was no better than the unmodified model's.

The test: the model with the effect fixed at that size (the nominal value less / plus
it, the sides the interval reaches) is rolled out on the held-out windows and compared
with the unmodified model cluster by cluster (the paired z the verdict uses). The size
is excluded when it is clearly worse, z <= -z_excl, on every side the interval reaches,
and the fit's own value, where it lies beyond that size, is not better than `none` (a
cost that is not monotone in the effect keeps the interval's answer). Nothing is fitted
at the tested value, so all held-out windows are used once. z_excl is evidence.size_z:
one test per effect at 5 %, not shared among the effects as the rival rule's bar is.
"""
from __future__ import annotations

import functools

import numpy as np

from adaptive_c3.tools.diagnosis.engine.fit import cluster_z, evaluate
from adaptive_c3.tools.diagnosis.engine.profiled_size import fixed


def at_size(prob, cand, value: float, none_eval, per_cluster: bool = False, sized=None):
    """z (the problem's cluster_z; positive: better than the unmodified model) of `cand`
    fixed at `value` (model units), over the held-out clusters of `prob` (none_eval =
    evaluate(prob, None)); per_cluster: that model's per-cluster SSR instead. sized:
    (cand, value) -> the Fit to score (engine/profiled_size.Sizer: the nuisances the
    effect trades against fitted beside it), by default the candidate alone."""
    f = (sized or fixed)(cand, value)
    _, _, ssr, _ = evaluate(prob, f)
    return ssr if per_cluster else cluster_z(none_eval[2], ssr, prob.z_stat)


def size_test_problem(prob, windows, fold: np.ndarray, in_fit: np.ndarray, stride: int):
    """The problem a size test is scored on: every `stride`-th rollout window that the fit
    problem `prob` left out (in_fit [W] False), in their folds, on prob's base model as it
    stands (nuisances fitted); None when the fit kept every window. A costly model fits
    on a sparse subset (the Drake backend about 100 windows of ~8000), where the few
    contact events that show an effect are a handful of windows: on development draw
    90173 (clean, a follow-up with glancing strikes) EE-ball mu 0.5 was worse than `none`
    on each of the 16 strike episodes, yet scored z -1.0 on the fit's windows. Nothing
    is fitted on these windows, and the size and `none` are fixed before the test."""
    import copy
    dense = ~np.asarray(in_fit, bool) & (np.arange(len(fold)) % max(int(stride), 1) == 0) \
        & (np.asarray(fold) >= 0)
    if not np.any(dense):
        return None
    out = copy.copy(prob)
    out.windows, out.fold = windows.take(dense), np.asarray(fold)[dense]
    return out


def excluded(prob, fit, sides, none_eval, z_excl, parts=None, sized=None) -> tuple[bool, list]:
    """(excluded, [(value, z, [z per recording])] tested): `sides` are (value, direction)
    of the sizes that matter the fit's interval reaches, in model units (direction -1:
    below the nominal value, +1: above). Excluded when each is clearly worse than `none`
    and the fit's own value, when at or beyond one of them, is not better (z_vs_none <=
    0 on its own held-out clusters, or clearly worse than `none` on prob's, _own_z).
    z_excl: the bar, or a callable giving it for a number of tests (evidence.size_z).

    parts [clusters of prob] (recording_parts): the recording each cluster came from.
    With two or more, a size is also scored on each recording alone, and it is clearly
    worse when any of the 1 + k tests (all recordings, each alone) reaches z <=
    -z_excl(1 + k), the 5 % shared among them (Bonferroni), and none of them finds it
    clearly better (z >= z_excl(1 + k): the recordings disagree). Each recording is its own
    experiment, and one that rules a size out is not overruled by another where the
    effect hardly shows: on the twenty-second set's 100117 (a force below its size) a
    ball of twice the mass scored z -2.25 on the first recording alone and -0.99 pooled
    with a follow-up of glancing strikes, which left the mass beside `none`. sized: as
    at_size's."""
    if prob is None or not sides or len(fit.cands) != 1 or len(fit.values) != 1:
        return False, []
    groups, bar = _recordings_and_bar(parts, z_excl)
    v = float(fit.values[0])
    tested = []
    for s, direction in sides:
        if direction * (v - s) >= 0.0 and fit.z_vs_none > 0.0 \
                and _own_z(prob, fit, none_eval) > -bar:
            return False, tested
        z, each = _z_pooled_and_alone(prob, fit.cands[0], s, none_eval, groups, sized)
        tested.append((float(s), z, each))
        if min([z, *each]) > -bar or max([z, *each]) >= bar:   # not ruled out, or disputed
            return False, tested
    return True, tested


def _own_z(prob, fit, none_eval) -> float:
    """z of `fit` (its fold values) against `none` over prob's clusters (the windows the
    size tests are scored on). A fit at or beyond a size that matters keeps its effect
    when it beat `none` on its own held-out clusters, unless it is clearly worse than
    `none` here: on the fortieth set's 101903 and 101932 (EE-ball mu 0.61 and 0.56, after
    a follow-up) a ball mass of 0.28x [0.28, 0.29] had beaten `none` on the fit's ~100
    sparse windows and scored z -3.8 and -3.2 on the left-out ones, and stayed beside
    `none` untested at 0.5x."""
    return float(cluster_z(none_eval[2], evaluate(prob, fit)[2], prob.z_stat))


def _recordings_and_bar(parts, z_excl) -> tuple[list, float]:
    """([cluster mask] per recording, none with fewer than two; the bar of the 1 + k
    tests): z_excl a bar, or a callable giving it for a number of tests."""
    groups = [] if parts is None or len(np.unique(parts)) < 2 else \
        [np.asarray(parts) == p for p in np.unique(parts)]
    return groups, (z_excl(1 + len(groups)) if callable(z_excl) else float(z_excl))


def _z_pooled_and_alone(prob, cand, value, none_eval, groups, sized=None):
    """(z over all clusters, [z over each recording's]) of `cand` fixed at `value` against
    `none` (at_size), or against sized.reference(cand) where the size is profiled."""
    ssr = at_size(prob, cand, value, none_eval, per_cluster=True, sized=sized)
    return _z_of(size_reference_ssr(prob, cand, none_eval, sized), ssr, prob.z_stat, groups)


def size_reference_ssr(prob, cand, none_eval, sized) -> np.ndarray:
    """Per-cluster SSR a size of `cand` is compared with: `none`'s, or where the size
    test fits nuisances beside it (profiled_size.Sizer), the model's own value with the
    same nuisances fitted."""
    if not hasattr(sized, "reference_ssr"):
        return none_eval[2]
    return sized.reference_ssr(prob, cand, none_eval[2])


def _z_of(base, ssr, stat, groups) -> tuple[float, list]:
    """(z over all clusters, [z over each recording's]) of per-cluster SSR `ssr` against
    `base` (positive: ssr lower)."""
    return (float(cluster_z(base, ssr, stat)),
            [float(cluster_z(base[g], ssr[g], stat)) for g in groups])


def favoured_alone(prob, fit, sides, none_eval, z_excl, parts, sized=None) -> list:
    """[(value, z, [z per recording])] of the sizes `sides` ((value, direction), those the
    fit's interval did not reach or the tests excluded) that one test (pooled or one
    recording alone, at z >= z_excl(1 + k)) finds clearly better than both `none` and the
    pooled fit's own value; [] with fewer than two recordings. The pooled interval
    follows the recordings together, and a follow-up whose model form pulls the fit to
    the other side can leave a size one recording clearly shows outside it: on the
    twenty-third set's 100203 (a ball 2.45x heavy) mass 2x beat `none` at z +3.5 on the
    first recording, the follow-up's fit read below 1, only 0.5x was tested, and the
    answer was a confident `none`. Such a size is not ruled out (the recordings
    disagree), so the effect stays beside `none`. Beating `none` alone is not a
    disagreement: an effect just below its size that matters, its interval between the
    model's value and that size, makes the size better than `none` on every recording
    (the fortieth set's 101932, EE-ball mu 0.56: mu 0.5 beat the model's 1 at z +4.2,
    interval 0.51..0.70), while the fit's value beats the size there."""
    groups, bar = _recordings_and_bar(parts, z_excl)
    if prob is None or not groups or len(fit.cands) != 1 or not sides:
        return []
    cand = fit.cands[0]
    own = functools.cache(lambda: at_size(prob, cand, float(fit.values[0]), none_eval,
                                          per_cluster=True))
    base = size_reference_ssr(prob, cand, none_eval, sized)   # the same for every side
    out = []
    for s, _ in sides:
        ssr = at_size(prob, cand, s, none_eval, per_cluster=True, sized=sized)
        z, each = _z_of(base, ssr, prob.z_stat, groups)
        if max([z, *each]) < bar:
            continue
        z_own, each_own = _z_of(own(), ssr, prob.z_stat, groups)
        if any(a >= bar and b >= bar for a, b in zip([z, *each], [z_own, *each_own])):
            out.append((float(s), z, each))
    return out


def recording_parts(prob, part_of_row) -> np.ndarray | None:
    """[clusters of prob]: the recording each cluster came from (part_of_row [T]: the
    recording of each row, Recording.extras["part"] after concat_recordings), or None
    with fewer than two recordings there."""
    from adaptive_c3.tools.diagnosis.engine.fit import cluster_rows
    if prob is None or part_of_row is None:
        return None
    parts = np.asarray(part_of_row)[cluster_rows(prob)]
    return parts if len(np.unique(parts)) >= 2 else None


def untrusted_interval(spec, fit, free, prob) -> bool:
    """A fit whose interval says nothing about the sizes beyond it: on a staircase cost
    (spec.rugged_cost) a candidate that is not chosen keeps its local fit's sandwich
    interval, and a fit that stopped on a step can be clearly worse than `none` on the
    held-out windows with an interval a few % wide (development draw 90092, EE-ball mu
    0.35: mu read 0.60 [0.579, 0.621] with a held-out SSR 3.6x the other candidates',
    so mu 0.5 was never tested and the truth left the ambiguous set). Such a fit
    (z_vs_none < 0, its interval from all windows, not the free ones) is judged by the
    model fixed at the size that matters instead (at_size, `excluded`)."""
    return (prob is not None and bool(getattr(spec, "rugged_cost", False))
            and fit.cands not in free and fit.z_vs_none < 0.0)


def size_sides(cand, spec, nominal: float, size, interval=None) -> list:
    """[(value, direction)]: the sizes that matter below (-1) and above (+1) the nominal
    value that `interval` (lo, hi) reaches, or, with no interval to read, every finite
    one within the candidate's bounds."""
    lo_b, hi_b = (float(b[0]) for b in cand.bounds(spec))
    out = []
    for value, direction in ((nominal - size[0], -1), (nominal + size[1], +1)):
        if interval is None:
            if np.isfinite(value) and lo_b <= value <= hi_b:
                out.append((value, direction))
        elif interval[0] <= value if direction < 0 else interval[1] >= value:
            out.append((value, direction))
    return out


def confirm_on_left_out(judged, chosen, size_prob, size_none, z_bar: float, prob=None,
                        nuisance=()) -> None:
    """Take `none` out of the set when the chosen effect clearly beats the unmodified model
    on the windows the fit left out (size_test_problem): `none` joins a chosen effect
    whose gain is not consistent over the fit's clusters (verdict) or whose interval
    holds the model's value (require_support). On a costly model both read about 100
    sparse windows, where an effect carried by contact events shows in a handful: on the
    sixteenth evaluation set EE-ball mu 0.26-0.34 and mass 0.47x and 2.0x were chosen
    right with `none` beside them (intervals 0.07..3 and 0.2..1.46). The test: the fit's
    fold values (each fitted without its fold) rolled out on the left-out windows of
    that fold, against `none` (size_none(): its evaluation there, computed once), by the
    problem's cluster z; confirmed at z >= z_bar. The effect (or pair), its values and
    the windows are fixed before the test; nothing is fitted on them. Recorded as
    judged["confirmation"]; other members of the set stay.

    prob, nuisance (the fit problem and the nuisance fits it kept): the gain must also
    be the effect's rather than a nuisance's the fit did not keep (nuisance_rivals):
    the effect must beat each such nuisance there at z >= z_bar, whether or not that
    nuisance beats `none` itself (see nuisance_rivals: 90400's rival read z 1.8)."""
    amb = judged.get("ambiguous") or []
    if size_prob is None or chosen is None or len(amb) < 2 or \
            not any(a["name"] == "none" for a in amb) or amb[0]["name"] == "none":
        return
    score, effect_c = _against_none(size_prob, chosen, size_none)
    ok = bool(score["z_vs_none"] >= z_bar)
    rivals = nuisance_rivals(prob, chosen, effect_c, size_prob, size_none, nuisance) \
        if ok and prob is not None else []
    ok = ok and all(r["z_effect_vs_it"] >= z_bar for r in rivals)
    judged["confirmation"] = dict(name=chosen.label(), confirmed=ok, **score,
                                  windows=int(np.sum(size_prob.fold >= 0)),
                                  nuisance_rivals=rivals)
    if not ok:
        return
    judged["ambiguous"] = [a for a in amb if a["name"] != "none"]
    judged["separating_excitation"] = [p for p in judged["separating_excitation"]
                                       if "none" not in p["between"]]
    if len(judged["ambiguous"]) < 2:
        judged.update(verdict="named", ambiguous=[], separating_excitation=[])


def nuisance_rivals(prob, chosen, effect_c, size_prob, size_none, nuisance) -> list:
    """[{name, z_effect_vs_it, z_it_vs_none}]: each nuisance of prob.spec.nuisance that the
    fit did not keep (`nuisance`: the kept fits), fitted on prob's windows as the chosen
    effect was (cv_fit: fold values), and scored on the left-out windows against the
    chosen effect (effect_c: its per-cluster SSR there) and against `none` (cluster z;
    positive: the first is better). A gain
    on the left-out windows that an unkept nuisance also gives is no evidence for the
    effect: on development draw 90400 (EE-ball mu 0.30, Drake's plant) a mass of 2.2x,
    its interval holding 1, was confirmed at z 2.2 while an actuator delay the fit had
    not kept scored z 1.8 against `none` there and the mass did not beat it (z -0.3)."""
    from adaptive_c3.tools.diagnosis.backends.effects import Candidate
    from adaptive_c3.tools.diagnosis.engine.fit import cv_fit
    kept = {f.cands[0] for f in nuisance}
    out = []
    for name, target in getattr(prob.spec, "nuisance", ()):
        c = Candidate(name, target)
        if c in kept or c in chosen.cands:
            continue
        _, _, it_c, _ = evaluate(size_prob, cv_fit(prob, [c]))
        out.append(dict(name=c.label(),
                        z_effect_vs_it=float(cluster_z(it_c, effect_c, size_prob.z_stat)),
                        z_it_vs_none=float(cluster_z(size_none()[2], it_c, size_prob.z_stat))))
    return out


def left_out_scores(judged, fits, size_prob, size_none) -> None:
    """Record, for each single-effect member of a set that holds `none`, its fit (fold
    values) against `none` on the left-out windows: judged["left_out"] = [{name,
    z_vs_none, reduction}]. A record for the report and the harness; no answer changes."""
    amb = judged.get("ambiguous") or []
    if size_prob is None or not any(a["name"] == "none" for a in amb):
        return
    from adaptive_c3.tools.diagnosis.backends.effects import Candidate
    by_label = {f.label(): f for f in fits if len(f.cands) == 1}
    done = judged.get("confirmation") or {}      # the chosen fit, already scored there
    out = []
    for a in amb:
        f = by_label.get(Candidate(a["name"], a["target"]).label())
        if a["name"] == "none" or f is None:
            continue
        score = {k: done[k] for k in ("z_vs_none", "reduction")} \
            if done.get("name") == f.label() else against_none(size_prob, f, size_none)
        out.append(dict(name=f.label(), **score))
    judged["left_out"] = out


def against_none(prob, fit, none_eval) -> dict:
    """{z_vs_none, reduction} of `fit` (its fold values) against the unmodified model over
    prob's held-out clusters; none_eval(): `none`'s evaluation there."""
    return _against_none(prob, fit, none_eval)[0]


def _against_none(prob, fit, none_eval):
    """(against_none's dict, the fit's per-cluster SSR there)."""
    none_ssr, _, none_c, _ = none_eval()
    ssr, _, per_c, _ = evaluate(prob, fit)
    return dict(z_vs_none=float(cluster_z(none_c, per_c, prob.z_stat)),
                reduction=float(1.0 - ssr / none_ssr)), per_c


def size_that_matters(spec, cand):
    """(below, above) the nominal value: the size of `cand` that matters
    (spec.relevant_size, by the effect's label, else its name), or None."""
    sizes = getattr(spec, "relevant_size", None) or {}
    return sizes.get(cand.label(), sizes.get(cand.name))


def reaches_size(size, nominal: float, lo: float, hi: float) -> bool:
    """Whether [lo, hi] reaches the size that matters, (below, above) the nominal value."""
    return nominal - lo >= size[0] or hi - nominal >= size[1]


def within_size(spec, fit, shift=None) -> dict | None:
    """The finding {name, value, unit, ci95, nominal, size} when `fit`, a single effect
    with one parameter and a size that matters (spec.relevant_size: (below, above) the
    nominal value), has its whole physical 95 % interval (report.effect_params: through
    the model's measured model form, an offset as the total from the user's model)
    within that size; else None."""
    from adaptive_c3.tools.diagnosis.engine.report import effect_params
    if fit is None or len(fit.cands) != 1:
        return None
    c = fit.cands[0]
    size = size_that_matters(spec, c)
    if size is None or len(fit.values) != 1:
        return None
    p = effect_params(fit, spec, shift)[0]["params"][0]
    nominal = float(c.nominal(spec)[0])
    lo, hi = (float(v) for v in p["ci95"])
    if reaches_size(size, nominal, lo, hi):
        return None
    return dict(name=c.label(), value=float(p["value"]), unit=p["unit"], ci95=[lo, hi],
                nominal=nominal, size=[float(v) for v in size])


def _member_fit(row, fits):
    """The fit behind an ambiguous set's row: the single effect of that label whose values
    are the row's (a free-ball effect has a fit on all windows and one on the free ones)."""
    for f in fits:
        if len(f.cands) == 1 and (f.cands[0].name, f.cands[0].target) == \
                (row["name"], row["target"]) and \
                np.allclose(f.values, row.get("values", []), rtol=1e-9, atol=0.0):
            return f
    return None


def below_size(judged, spec, chosen, fits=(), shift=None) -> bool:
    """Turn an answer whose every effect is too small to matter into `none`: True (and
    judged's verdict set to "none", the findings kept as judged["below_size"]) when the
    named single effect, or each effect of an ambiguous set (`fits`: the fits its rows
    came from), has its whole physical 95 % interval within its size that matters
    (within_size). Such an effect is there but changes nothing the user's model needs:
    on the eighteenth evaluation set a clean draw whose table sat 0.17 mm off (a
    variation the draws give every recording) was named a table offset of -0.16 mm
    [-0.45, -0.07] after its follow-up, a confident wrong answer under the rule that too
    small to matter is a right `none`; on development draw 90251 (drag 0.084 N s/m,
    below its 0.1) the follow-up left drag 0.083 [0.074, 0.093] and rolling resistance
    in a set. One interval that reaches its size keeps the answer, and so does a pair
    (its members' sizes are read separately by require_support). The `none` that results
    is then checked as every `none` is (not_excluded): effects whose intervals reach
    their sizes join it."""
    if judged.get("verdict") == "named" and chosen is not None:
        members = [chosen]
    elif judged.get("verdict") == "ambiguous":
        rows = [a for a in judged["ambiguous"] if a["name"] != "none"]
        members = [_member_fit(a, [f for f in (chosen, *fits) if f is not None])
                   for a in rows]
    else:
        return False
    found = [within_size(spec, f, shift) for f in members]
    if not found or any(x is None for x in found):
        return False
    judged.update(verdict="none", ambiguous=[], separating_excitation=[], below_size=found)
    judged.pop("evidence", None)      # it described the dropped effect's gain
    return True


def holds_none(judged) -> bool:
    """Whether the verdict is ambiguous with `none` in its set: where a member's size
    decides whether it stays beside `none` (ruled_out_members, direct_reading)."""
    return judged.get("verdict") == "ambiguous" and any(
        a["name"] == "none" for a in judged.get("ambiguous") or [])


def ruled_out_members(judged) -> list[str]:
    """Take out of an ambiguous set that holds `none` each effect whose sizes that matter
    were all ruled out (evidence.not_excluded's size tests: each size its interval
    reaches, the model fixed there, clearly worse than `none` on the held-out windows),
    or whose direct reading lies within its size (engine/direct_reading.py); returns
    their labels. `none` beside an effect says it may be too small to matter, and
    the tests say it is: the counterpart of below_size, read from the model at its sizes
    rather than from the linearised interval. On the thirty-fifth set's clean draw 101411,
    after its follow-up, a ball mass of 1.4x [0.04, 2.76] led a set with `none` although
    the ball at 0.5x and at 2x was worse than `none` at z -3.7 and -4.1. When `none` alone
    is left the verdict is `none`."""
    amb = judged.get("ambiguous") or []
    if not holds_none(judged):
        return []
    from adaptive_c3.tools.diagnosis.backends.effects import Candidate
    out = {t["name"] for t in judged.get("size_tests", []) if t["excluded"]} | {
        r["name"] for r in judged.get("direct_readings", []) if r["within"]}   # direct_reading
    gone = [a for a in amb if a["name"] != "none"
            and Candidate(a["name"], a["target"]).label() in out]
    if not gone:
        return []
    labels = [Candidate(a["name"], a["target"]).label() for a in gone]
    kept = [a for a in amb if not any(a is g for g in gone)]
    judged["ambiguous"] = kept
    judged["separating_excitation"] = [
        p for p in judged.get("separating_excitation", [])
        if not {a["name"] for a in gone} & set(p["between"])]
    judged["ruled_out_members"] = labels
    if len(kept) < 2:
        judged.update(verdict="none", ambiguous=[], separating_excitation=[])
        judged.pop("evidence", None)       # it described the dropped effect's gain
    return labels


def in_model_units(spec, cand) -> bool:
    """Whether `cand`'s sizes that matter are values of the model itself, so that the model
    fixed there can be rolled out: not an effect with a measured model-form bias
    (spec.model_form_bias: its size is the physical value)."""
    return cand.label() not in (getattr(spec, "model_form_bias", None) or {})


def calibration_under(cand, shift=None) -> float:
    """m: the calibration offset kept for `cand`'s pair (shift {pair: m},
    report.calibration_shift) when `cand` is a contact_offset fitted on top of it, else 0.
    Such an offset's sizes that matter are totals from the user's model: the model value
    that gives the total `s` is s - calibration_under(cand, shift)."""
    return (shift or {}).get(cand.target, 0.0) if cand.name == "contact_offset" else 0.0
