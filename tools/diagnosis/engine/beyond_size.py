"""The beyond-size test: takes `none` out of an ambiguous set when one of its effects is
shown, on the windows the fit left out, to lie beyond its size that matters (the
counterpart of boundary.excluded, which rules an effect out at that size), and the rule
by which the effect it shows becomes the answer."""
from __future__ import annotations

from adaptive_c3.tools.diagnosis.backends.effects import Candidate
from adaptive_c3.tools.diagnosis.engine.boundary import (at_size, calibration_under,
                                                         in_model_units, size_reference_ssr,
                                                         size_sides, size_that_matters)
from adaptive_c3.tools.diagnosis.engine.fit import cluster_z, evaluate
from adaptive_c3.tools.diagnosis.engine.proposals import (DEFAULT_SEPARATION, MORE_EVIDENCE,
                                                         proposal)


def beyond_size(judged, spec, fits, size_prob, size_none, z_bar, shift=None, sized=None):
    """Take `none` out of an ambiguous set when one of its effects is shown, on the windows
    the fit left out, to lie beyond its size that matters; returns that effect's fit
    (the answer names it when the set is then that effect alone), else None.

    `none` beside an effect says the effect may be too small to matter. not_excluded reads
    that from the linearised interval, which on a staircase cost stays wide whatever the
    data say: on development draws 90219 and 90222 (EE-ball mu 0.42 and 0.31, Drake's
    plant, after one follow-up) and on the twenty-first set's 100019 (mu 0.34: fit 0.21
    to 0.81) mu fixed at 0.5 beat `none` by z +3.6..+4.1 on the left-out windows, yet the
    interval reached above 0.5, so `none` stayed. The test, the counterpart of
    `excluded`: for a member whose fit (its fold values, each fitted without its fold)
    lies beyond its size, that fit against `none` AND against the model fixed at the size
    (at_size), cluster by cluster over the left-out windows (size_test_problem). Both at
    z >= z_bar(members tested) (evidence.worse_z): `none` is then wrong only if both
    comparisons err for one member (an intersection-union test, each at its share of
    5 %). An offset read through a calibration shift is tested at the total from the
    user's model (calibration_under); skipped for an effect with a measured model-form
    bias, whose sizes are not the model's values (in_model_units). Recorded as
    judged["beyond_size"].

    sized (profiled_size.Sizer): an effect with nuisances it trades against
    (spec.size_profile: the ball's mass, the contact's stiffness and relaxation time) is
    scored at its value, at `none` (Sizer.reference) and at the size with those fitted
    beside each, as the size tests do: at the kept nuisances the forty-fifth set's 102425
    (EE-ball mu 0.67, below size, on a 0.24x-stiff contact) had a 0.23x mass beat `none`
    at z +4.5 and lose the right `none`. With two or more members left, the lead is
    returned too (the verdict stays ambiguous), so the answer is never a `none` the set
    no longer holds."""
    amb = judged.get("ambiguous") or []
    if size_prob is None or len(amb) < 2 or not any(a["name"] == "none" for a in amb):
        return None
    by_label = {f.label(): f for f in fits if len(f.cands) == 1 and len(f.values) == 1}
    tests, members = [], []          # the records, and (set row, fit) beside each
    for a in amb:
        f = by_label.get(Candidate(a["name"], a["target"]).label())
        if a["name"] == "none" or f is None or not f.physical:
            continue
        c = f.cands[0]
        size = size_that_matters(spec, c)
        if size is None or not in_model_units(spec, c):
            continue
        add = calibration_under(c, shift)      # sizes are totals from the user's model
        v, nominal = float(f.values[0]) + add, float(c.nominal(spec)[0])
        side = [s for s, d in size_sides(c, spec, nominal, size) if d * (v - s) >= 0.0]
        if not side:
            continue
        ref = sized.reference(c) if hasattr(sized, "reference") else None   # profiled
        fit_c = evaluate(size_prob, f if ref is None else sized(c, float(f.values[0])))[2]
        size_c = at_size(size_prob, c, side[0] - add, None, per_cluster=True, sized=sized)
        none_c = size_reference_ssr(size_prob, c, size_none(), sized)
        tests.append(dict(name=c.label(), value=v, size=float(side[0]),
                          z_vs_none=float(cluster_z(none_c, fit_c, size_prob.z_stat)),
                          z_vs_size=float(cluster_z(size_c, fit_c, size_prob.z_stat)),
                          **({} if ref is None else
                             dict(fitted_beside=[x.label() for x in ref.cands[1:]]))))
        members.append((a, f))
    if not tests:
        return None
    bar = z_bar(len(tests))
    for t in tests:
        t["beyond"] = bool(t["z_vs_none"] >= bar and t["z_vs_size"] >= bar)
    judged["beyond_size"] = tests
    shown = sorted((i for i, t in enumerate(tests) if t["beyond"]),
                   key=lambda i: -tests[i]["z_vs_size"])
    if not shown:
        return None
    return take_none_out(judged, *members[shown[0]])


def take_none_out(judged, first, fit):
    """`none` leaves the ambiguous set, `first` (a member, its fit `fit`) shown beyond its
    size: named when it is then alone, else it leads the rest (the verdict stays
    ambiguous, the proposals now separate it from each of them); returns fit."""
    rest = [a for a in judged["ambiguous"] if a["name"] != "none" and a is not first]
    if not rest:
        judged.update(verdict="named", ambiguous=[], separating_excitation=[])
        return fit
    judged["ambiguous"] = [first, *rest]
    judged["separating_excitation"] = [
        proposal([first["name"], a["name"]], MORE_EVIDENCE.get(a["name"], DEFAULT_SEPARATION))
        for a in rest]
    return fit


def answers_beyond_size(shown, chosen, verdict: str) -> bool:
    """Whether beyond_size's fit `shown` becomes the answer: when it is named (beyond its
    size, alone in the set once `none` left), or when it leads a set `none` left and
    nothing was chosen (the answer is then never a `none` the set no longer holds). An
    effect already chosen stays when the set is still ambiguous."""
    return shown is not None and shown is not chosen and (verdict == "named"
                                                          or chosen is None)
