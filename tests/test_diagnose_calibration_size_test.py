"""Issue 30: an offset fitted on top of its pair's calibration is size-tested at the total
from the user's model, on the side the calibration took, before a `none` is left
confident. The offset's fit starts at 0 on top of the calibration and leans there: on the
forty-third set's 102234 (an EE-ball offset of -1.04 mm) the +-1 mm calibration took
-0.70 mm, the offset read 0 +-0.13 mm, and the total of -1 mm was never tested."""
import copy

import numpy as np

from adaptive_c3.scenarios.schema import SCENARIO_DIR, load_scenario
from adaptive_c3.tools.diagnosis.backends.effects import Candidate
from adaptive_c3.tools.diagnosis.engine.beyond_size import beyond_size
from adaptive_c3.tools.diagnosis.engine.boundary import at_size, calibration_under
from adaptive_c3.tools.diagnosis.engine.evidence import not_excluded, verdict
from adaptive_c3.tools.diagnosis.engine.fit import Problem
from adaptive_c3.tools.diagnosis.engine.locate import Windows
from adaptive_c3.tools.diagnosis.tasks.ball_rolling.effects_ball import ball_spec
from tests.test_diagnose_size_test import scored_fit

OFFSET = Candidate("contact_offset", "ee_ball")
CALIBRATION = Candidate("calibration_offset", "ee_ball")


class GapProblem(Problem):
    """Windows whose residual, on unit noise, grows in some states with the gap between
    the model's total EE-ball offset (the calibration in the base plus the offset on top)
    and the data's (`truth`, m)."""

    def __init__(self, spec, truth: float, calibration: float, gain: float = 4e3,
                 windows: int = 120):
        rng = np.random.default_rng(7)
        n = windows
        W = Windows(np.zeros((n, 19)), np.zeros((n, 2, 19)), np.zeros((n, 3, 3)),
                    np.arange(n) * 10, np.arange(n) // 12, np.arange(n) * 0.1)
        super().__init__(spec, [(CALIBRATION, np.array([calibration]))], W,
                         np.arange(n) % 3, np.ones((2, 19)), cluster_steps=50)
        self.truth, self.gain = truth, gain
        self.noise = rng.normal(0.0, 1.0, (n, 2, 19))

    def residuals(self, effects, W):
        total = sum(float(v[0]) for c, v in list(self.base) + list(effects)
                    if c.name in ("calibration_offset", "contact_offset"))
        r = self.noise[W.row // 10].copy()
        r[..., :6] += self.gain * (total - self.truth)
        return r


def _spec():
    """The ball's spec without the LCS's measured model form, as the Drake backend's is
    (drake_ball.drake_ball_spec: its offsets are the plant's own values)."""
    spec = copy.copy(ball_spec(load_scenario(str(SCENARIO_DIR / "ball_rolling.yaml"))[0]))
    spec.model_form_bias = {}
    return spec


def _leaning_fit(prob):
    """The offset's fit on top of the calibration: 0 +-0.13 mm (102234's)."""
    return scored_fit(prob, OFFSET, 0.0, [-1.3e-4, 1.3e-4], 6.5e-5)


def _judge(truth, calibration=-0.7e-3):
    spec = _spec()
    prob = GapProblem(spec, truth, calibration)
    fit, none_eval = _leaning_fit(prob)
    judged = verdict([fit], None, none_eval, 0.1)
    assert judged["verdict"] == "none"
    not_excluded(judged, spec, [fit], none_eval, shift={"ee_ball": calibration}, prob=prob)
    return judged, prob, none_eval


def test_the_model_value_of_a_total_is_the_total_less_the_calibration():
    assert calibration_under(OFFSET, {"ee_ball": -7e-4}) == -7e-4
    assert calibration_under(Candidate("contact_offset", "ball_table"),
                             {"ee_ball": -7e-4}) == 0.0
    assert calibration_under(Candidate("mass_scale", "ball"), {"ball": 1.0}) == 0.0


def test_an_offset_the_calibration_took_most_of_joins_none():
    """Data of a total of -1.04 mm, the calibration at -0.70 mm: the interval (a total of
    -0.83..-0.57 mm) stops short of -1 mm, yet the total fixed there beats `none`, so the
    offset joins; only the calibration's side is tested, and reported as a total."""
    judged, prob, none_eval = _judge(-1.04e-3)
    assert at_size(prob, OFFSET, -1e-3 + 0.7e-3, none_eval) > 0
    assert [a["name"] for a in judged["ambiguous"]] == ["none", "contact_offset"]
    test = judged["size_tests"][0]
    assert test["excluded"] is False
    assert [t["value"] for t in test["tested"]] == [-1e-3]
    assert "on top of the pair's calibration" in judged["ambiguous"][1]["note"]


def test_a_calibration_that_took_it_all_leaves_a_confident_none():
    """Data of a total of -0.70 mm, all of it calibration: the total of -1 mm is clearly
    worse than `none` there, so `none` stays confident; +1 mm is not tested."""
    judged, _, _ = _judge(-0.7e-3)
    assert judged["verdict"] == "none" and judged["ambiguous"] == []
    test = judged["size_tests"][0]
    assert test["excluded"] is True and [t["value"] for t in test["tested"]] == [-1e-3]


def test_without_a_calibration_the_interval_decides():
    """No calibration kept for the pair (the offset fitted from the user's model): its
    interval stops short of both sizes and nothing is tested."""
    spec = _spec()
    prob = GapProblem(spec, -0.3e-3, 0.0)
    prob.base = []
    fit, none_eval = _leaning_fit(prob)
    judged = verdict([fit], None, none_eval, 0.1)
    not_excluded(judged, spec, [fit], none_eval, shift={}, prob=prob)
    assert judged["verdict"] == "none" and "size_tests" not in judged


def test_an_offset_beyond_its_size_as_a_total_is_named():
    """{none, offset} with the offset's fit on top of the calibration at a total beyond
    -1 mm: beyond_size scores it against the total fixed at -1 mm (not the model's value
    -1 mm, which would be -1.7 mm in all) and names it."""
    from adaptive_c3.tools.diagnosis.engine.evidence import fit_row
    spec = _spec()
    prob = GapProblem(spec, -1.6e-3, -0.7e-3, gain=8e3)
    fit, none_eval = scored_fit(prob, OFFSET, -0.9e-3, [-1.0e-3, -0.8e-3], 5e-5)
    judged = dict(verdict="ambiguous", ambiguous=[fit_row(None, none_eval),
                                                  fit_row(fit, none_eval)])
    shown = beyond_size(judged, spec, [fit], prob, lambda: none_eval, lambda n: 2.0,
                        {"ee_ball": -0.7e-3})
    assert shown is fit and judged["verdict"] == "named"
    test = judged["beyond_size"][0]
    assert abs(test["value"] - -1.6e-3) < 1e-9 and test["size"] == -1e-3
