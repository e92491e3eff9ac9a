"""Issue 30: a size the spec always tests (spec.always_size_tested, the Drake ball's mass
below its nominal value) is checked by the model fixed there before a `none` is left
confident, even where the mass fit's interval stops short of it: a light ball's fit
leans to the model's value (the forty-second set's 102110 and 102137)."""
import copy

import numpy as np
import pytest

from adaptive_c3.scenarios.schema import SCENARIO_DIR, load_scenario
from adaptive_c3.tools.diagnosis.backends.effects import Candidate
from adaptive_c3.tools.diagnosis.engine.boundary import at_size
from adaptive_c3.tools.diagnosis.engine.evidence import not_excluded, verdict
from adaptive_c3.tools.diagnosis.engine.fit import Problem
from adaptive_c3.tools.diagnosis.engine.locate import Windows
from adaptive_c3.tools.diagnosis.tasks.ball_rolling.drake_ball import DrakeBallSpec
from adaptive_c3.tools.diagnosis.tasks.ball_rolling.effects_ball import ball_spec
from tests.test_diagnose_size_test import scored_fit

MASS = Candidate("mass_scale", "ball")


class MassProblem(Problem):
    """Windows whose residual, on unit noise, grows with the gap between the ball's mass
    scale and the data's (`truth`) below `shows_at`: a ball heavier than that acts as the
    model's (the fit's cost is flat there, where a light ball's fit stops)."""

    def __init__(self, spec, truth: float, gain: float = 6.0, shows_at: float = 0.7,
                 windows: int = 120):
        rng = np.random.default_rng(5)
        n = windows
        W = Windows(np.zeros((n, 19)), np.zeros((n, 2, 19)), np.zeros((n, 3, 3)),
                    np.arange(n) * 10, np.arange(n) // 12, np.arange(n) * 0.1)
        super().__init__(spec, [], W, np.arange(n) % 3, np.ones((2, 19)), cluster_steps=50)
        self.truth, self.gain, self.shows_at = truth, gain, shows_at
        self.noise = rng.normal(0.0, 1.0, (n, 2, 19))

    def residuals(self, effects, W):
        m = next((float(v[0]) for c, v in effects if c.name == "mass_scale"), 1.0)
        light = max(self.shows_at - m, 0.0) - max(self.shows_at - self.truth, 0.0)
        return self.noise[W.row // 10] + self.gain * light


def _spec(always: bool):
    out = copy.copy(ball_spec(load_scenario(str(SCENARIO_DIR / "ball_rolling.yaml"))[0]))
    out.always_size_tested = {"mass_scale": (-1,)} if always else {}
    return out


def _leaning_fit(prob):
    """A mass fit that leans to the model's 1: 0.94 [0.66, 1.22] (102110's, two
    recordings), its interval short of the size that matters (0.5x)."""
    return scored_fit(prob, MASS, 0.94, [0.66, 1.22], 0.14)


def test_the_drake_ball_spec_tests_a_light_ball_always():
    assert DrakeBallSpec.__dataclass_fields__["always_size_tested"].default_factory() == {
        "mass_scale": (-1,)}


def test_a_light_ball_the_fit_missed_joins_none():
    """Data of a 0.45x ball, the fit at 0.94: the interval alone leaves `none` confident;
    the mass fixed at 0.5x beats `none`, so with the size always tested it joins."""
    for always, joins in ((False, False), (True, True)):
        spec = _spec(always)
        prob = MassProblem(spec, truth=0.45)
        fit, none_eval = _leaning_fit(prob)
        assert at_size(prob, MASS, 0.5, none_eval) > 0
        judged = verdict([fit], None, none_eval, 0.1)
        assert judged["verdict"] == "none"
        not_excluded(judged, spec, [fit], none_eval, prob=prob)
        names = [a["name"] for a in judged["ambiguous"]]
        assert names == (["none", "mass_scale"] if joins else [])
    assert judged["size_tests"][0]["tested"][0]["value"] == 0.5
    assert judged["size_tests"][0]["excluded"] is False
    assert "not read at this size" in judged["ambiguous"][1]["note"]


def test_a_nominal_ball_stays_a_confident_none():
    """Data of the model's ball: the mass fixed at 0.5x is clearly worse than `none`, so
    the test excludes it and `none` stays confident; the 2x side is not tested."""
    spec = _spec(True)
    prob = MassProblem(spec, truth=1.0)
    fit, none_eval = _leaning_fit(prob)
    judged = verdict([fit], None, none_eval, 0.1)
    not_excluded(judged, spec, [fit], none_eval, prob=prob)
    assert judged["verdict"] == "none" and judged["ambiguous"] == []
    assert judged["size_tests"][0]["excluded"] is True
    assert [t["value"] for t in judged["size_tests"][0]["tested"]] == [0.5]


def test_without_a_problem_to_test_on_the_interval_decides():
    """No held-out problem (prob None): nothing can be tested, the interval decides."""
    spec = _spec(True)
    prob = MassProblem(spec, truth=0.45)
    fit, none_eval = _leaning_fit(prob)
    judged = verdict([fit], None, none_eval, 0.1)
    not_excluded(judged, spec, [fit], none_eval)
    assert judged["verdict"] == "none" and judged["ambiguous"] == []


STIFF = Candidate("stiffness_calibration", "contacts")


def _value(prob, effects, name: str, default: float) -> float:
    """The value of effect `name` among the problem's base and `effects` (later ones
    override), or `default`."""
    return next((float(v[0]) for c, v in reversed(list(prob.base) + list(effects))
                 if c.name == name), default)


class FrequencyProblem(MassProblem):
    """Windows whose residual grows in some states with the gap between the model's
    contact frequency, log(k / m), and the data's (a light ball on a soft contact), and
    in the others with the mass alone (the ball's share of the pushed inertia)."""

    def __init__(self, spec, truth: float, truth_k: float, inertia: float = 0.3):
        super().__init__(spec, truth)
        self.truth_k, self.inertia = truth_k, inertia

    def residuals(self, effects, W):
        m = _value(self, effects, "mass_scale", 1.0)
        k = _value(self, effects, "stiffness_calibration", 1e5) / 1e5
        gap = np.log(k / m) - np.log(self.truth_k / self.truth)
        r = self.noise[W.row // 10].copy()
        r[..., :10] += 4.0 * gap                    # the contact's states
        r[..., 10:] += self.inertia * (m - self.truth)   # the EE's response
        return r


def _profiled_spec():
    spec = _spec(True)
    spec.stiffness_groups = {"contacts": ((0, 1), 1e5)}
    spec.size_profile = {"mass_scale": (("stiffness_calibration", "contacts"),)}
    spec.profile_start = DrakeBallSpec.profile_start.__get__(spec)
    return spec


def test_a_light_ball_on_a_soft_contact_is_tested_with_the_stiffness_fitted():
    """Data of a 0.47x ball on a 0.5x stiffness (102110's): at the model's stiffness the
    mass at 0.5x doubles the contact frequency and is clearly worse than `none`; with
    the stiffness fitted beside it (on the fit windows) it is not, and joins `none`."""
    from adaptive_c3.tools.diagnosis.engine.profiled_size import Sizer
    spec = _profiled_spec()
    prob = FrequencyProblem(spec, truth=0.47, truth_k=0.5)
    fit, none_eval = _leaning_fit(prob)
    assert at_size(prob, MASS, 0.5, none_eval) < -3.0            # the stiffness rules it out
    sized = Sizer(prob, spec)
    profiled = sized(MASS, 0.5)
    assert [c.name for c in profiled.cands] == ["mass_scale", "stiffness_calibration"]
    assert abs(profiled.values[1] / 1e5 - 0.5 * 0.5 / 0.47) < 0.05   # k / m matched
    assert at_size(prob, MASS, 0.5, none_eval, sized=sized) > 0
    judged = verdict([fit], None, none_eval, 0.1)
    not_excluded(judged, spec, [fit], none_eval, prob=prob)
    assert [a["name"] for a in judged["ambiguous"]] == ["none", "mass_scale"]


@pytest.mark.parametrize("kept", [True, False])
def test_a_nominal_ball_on_a_soft_contact_is_still_ruled_out(kept):
    """Data of the model's ball on a 0.5x stiffness, the stiffness kept as a nuisance
    (fit_nuisance) or not: with the stiffness fitted beside it the mass at 0.5x matches
    the contact frequency, and the ball's own share of the motion still rules it out, so
    `none` stays confident. Not kept, `none` itself misses the frequency: the size is
    compared with the model's mass with the stiffness fitted too (Sizer.reference), not
    with `none`, which the fitted stiffness alone would beat."""
    from adaptive_c3.tools.diagnosis.engine.profiled_size import Sizer
    spec = _profiled_spec()
    prob = FrequencyProblem(spec, truth=1.0, truth_k=0.5, inertia=3.0)
    prob.base = [(STIFF, np.array([5e4]))] if kept else []
    fit, none_eval = _leaning_fit(prob)
    if not kept:
        assert at_size(prob, MASS, 0.5, none_eval, sized=Sizer(prob, spec)) > 3.0
    judged = verdict([fit], None, none_eval, 0.1)
    not_excluded(judged, spec, [fit], none_eval, prob=prob)
    assert judged["verdict"] == "none" and judged["ambiguous"] == []
    assert judged["size_tests"][0]["excluded"] is True


class BumpyFrequencyProblem(FrequencyProblem):
    """FrequencyProblem whose contact states also carry a ripple in log k: a rugged cost
    (Drake's staircase), where a profiled fit stays in the dip it starts in."""

    def residuals(self, effects, W):
        r = super().residuals(effects, W)
        k = _value(self, effects, "stiffness_calibration", 1e5) / 1e5
        r[..., :10] += np.sin(12.0 * np.log(k))
        return r


@pytest.mark.parametrize("grid", [0, 5])
def test_a_size_and_its_reference_start_from_the_same_points(monkeypatch, grid):
    """Data of the model's ball on a 0.3x contact, a rugged cost in the stiffness: from the
    model's stiffness the reference's fit stays in a dip far from 0.3x, while the size's
    start (the stiffness scaled with the mass) lands near its own best, so without the
    grid of starts the 0.5x ball beats the reference on the data of a nominal ball. With
    the same grid of starts for both, the reference fits the contact as well as the size
    does, and the ball's own share of the motion rules 0.5x out."""
    from adaptive_c3.tools.diagnosis.engine import profiled_size
    from adaptive_c3.tools.diagnosis.engine.fit import cluster_z
    monkeypatch.setattr(profiled_size, "PROFILE_GRID", grid)
    spec = _profiled_spec()
    prob = BumpyFrequencyProblem(spec, truth=1.0, truth_k=0.3, inertia=0.3)
    fit, none_eval = _leaning_fit(prob)
    sized = profiled_size.Sizer(prob, spec)
    ref_ssr = sized.reference_ssr(prob, MASS, none_eval[2])
    size_ssr = at_size(prob, MASS, 0.5, none_eval, per_cluster=True, sized=sized)
    z = cluster_z(ref_ssr, size_ssr, prob.z_stat)      # > 0: the size beats the reference
    assert (z > 2.0) if grid == 0 else (z < -2.0)


class BumpyDampingProblem(FrequencyProblem):
    """FrequencyProblem whose contact states also carry the gap to the data's relaxation
    time (`truth_tau` x the model's), on a ripple in log tau: a profiled fit started at
    the model's relaxation time stays in the dip it starts in."""

    def __init__(self, spec, truth_tau: float, **kw):
        super().__init__(spec, **kw)
        self.truth_tau = truth_tau

    def residuals(self, effects, W):
        r = super().residuals(effects, W)
        tau = _value(self, effects, "dissipation_calibration", 2e-3) / 2e-3
        gap = np.log(tau / self.truth_tau)
        r[..., :10] += 3.0 * gap + 2.0 * np.sin(9.0 * np.log(tau))
        return r


@pytest.mark.parametrize("scales", [(1.0,), (0.5, 1.0, 2.0)])
def test_a_profiled_fit_starts_from_the_second_nuisance_scaled_too(monkeypatch, scales):
    """Data of a 0.5x ball on a contact with twice the model's relaxation time and a
    rugged cost in it: started at the model's relaxation time the profiled fit stays in
    a dip far from 2x; with starts at 0.5, 1 and 2x it (profiled_size.SECOND_SCALES)
    the fit lands by the truth, at a lower training cost."""
    from adaptive_c3.tools.diagnosis.engine import profiled_size
    monkeypatch.setattr(profiled_size, "SECOND_SCALES", scales)
    spec = _profiled_spec()
    spec.relaxation_groups = {"contacts": ((0, 1), 2e-3)}
    spec.size_profile = {"mass_scale": (("stiffness_calibration", "contacts"),
                                        ("dissipation_calibration", "contacts"))}
    prob = BumpyDampingProblem(spec, truth_tau=2.0, truth=0.5, truth_k=0.5)
    sized = profiled_size.Sizer(prob, spec)
    fitted = sized(MASS, 0.5)
    assert [c.name for c in fitted.cands] == ["mass_scale", "stiffness_calibration",
                                              "dissipation_calibration"]
    tau = fitted.values[2] / 2e-3
    assert (abs(np.log(tau / 2.0)) < 0.1) == (len(scales) == 3)
