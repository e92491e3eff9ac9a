"""Issue 30: a calibration fitted before the effect takes up part of an effect that moves
the same quantity; the chosen effect is refitted jointly with it (engine/joint_refit.py)."""
import numpy as np

from adaptive_c3.scenarios.schema import SCENARIO_DIR, load_scenario
from adaptive_c3.tools.diagnosis.backends.effects import Candidate
from adaptive_c3.tools.diagnosis.engine.held_out import held_out_interval, widen_to_held_out
from adaptive_c3.tools.diagnosis.engine.fit import Fit, Problem, cv_fit, evaluate
from adaptive_c3.tools.diagnosis.engine.selection import score_fit
from adaptive_c3.tools.diagnosis.engine.joint_refit import refit_with_calibration
from adaptive_c3.tools.diagnosis.engine.locate import Windows
from adaptive_c3.tools.diagnosis.tasks.ball_rolling.effects_ball import ball_spec

EE_OFFSET = Candidate("contact_offset", "ee_ball")
TABLE_CAL = Candidate("calibration_offset", "ball_table")
EE_CAL = Candidate("calibration_offset", "ee_ball")


class PressProblem(Problem):
    """A pressed ball: one residual sees the EE's height over the table (the EE-ball
    offset plus the table's), weighted 4 noise sd per mm; the other the ball's height
    (the table's alone), 1 sd per mm. Either offset moves the first; only the table's the
    second."""

    def __init__(self, spec, truth=(-2.2e-3, 0.0), windows: int = 120):
        n = windows
        W = Windows(np.zeros((n, 19)), np.zeros((n, 2, 19)), np.zeros((n, 3, 3)),
                    np.arange(n) * 10, np.arange(n) // 12, np.arange(n) * 0.1)
        super().__init__(spec, [], W, np.arange(n) % 3, np.ones((2, 19)), cluster_steps=50)
        self.truth = truth
        self.noise = np.random.default_rng(5).normal(0.0, 1.0, (n, 2, 2))

    def residuals(self, effects, W):
        a = b = 0.0
        for c, v in list(self.base) + list(effects):
            if c == EE_OFFSET or c == EE_CAL:
                a += float(v[0])
            elif c == TABLE_CAL:
                b += float(v[0])
        idx = W.row // 10
        r = np.zeros((len(W), 2, 19))
        r[..., 0] = self.noise[idx, :, 0] + 4e3 * (a + b - sum(self.truth))
        r[..., 1] = self.noise[idx, :, 1] + 1e3 * (b - self.truth[1])
        return r


def _sequential(spec, table_cal=-6e-4, cal=TABLE_CAL):
    """The state fit_nuisance + select leave: the calibration kept at `table_cal`, the
    effect fitted with it held."""
    prob = PressProblem(spec)
    prob.base = [(cal, np.array([table_cal]))]
    kept = Fit((cal,), np.array([table_cal]), np.array([[table_cal] * 2]), np.zeros(1), 0.0)
    none_eval = evaluate(prob, None)
    chosen = score_fit(prob, cv_fit(prob, [EE_OFFSET], init=np.array([-1e-3])), none_eval)
    return prob, kept, chosen, none_eval


def _spec(opt_in=True):
    spec = ball_spec(load_scenario(str(SCENARIO_DIR / "ball_rolling.yaml"))[0])
    spec.rugged_cost = opt_in
    return spec


def test_the_joint_refit_recovers_an_offset_a_calibration_took_up():
    prob, kept, chosen, none_eval = _sequential(_spec())
    assert abs(chosen.values[0] - (-1.6e-3)) < 5e-5            # the sequential bias
    assert not chosen.ci[0, 0] <= -2.2e-3 <= chosen.ci[0, 1]  # its interval misses
    ssr_before = chosen.test_ssr
    refit_with_calibration(prob, chosen, [kept], none_eval)
    assert abs(chosen.values[0] - (-2.2e-3)) < 5e-5
    assert chosen.ci[0, 0] <= -2.2e-3 <= chosen.ci[0, 1]
    assert abs(kept.values[0]) < 5e-5                          # the table was exact
    assert [c for c, _ in prob.base] == [TABLE_CAL] and abs(prob.base[0][1][0]) < 5e-5
    assert chosen.test_ssr < ssr_before                       # held out, per fold
    assert all(abs(v[0] - (-2.2e-3)) < 1e-4 for v in chosen.fold_values.values())
    assert chosen.joint_calibration["cost_after"] < chosen.joint_calibration["cost_before"]


def test_no_refit_without_opt_in_or_for_the_same_pair():
    prob, kept, chosen, none_eval = _sequential(_spec(opt_in=False))
    before = chosen.values.copy()
    refit_with_calibration(prob, chosen, [kept], none_eval)
    assert np.array_equal(chosen.values, before) and kept.values[0] == -6e-4
    # the EE-ball calibration and offset are one quantity: left to the report's sum
    prob, kept, chosen, none_eval = _sequential(_spec(), cal=EE_CAL)
    before = chosen.values.copy()
    refit_with_calibration(prob, chosen, [kept], none_eval)
    assert np.array_equal(chosen.values, before) and kept.values[0] == -6e-4


class StaircaseProblem(Problem):
    """An offset seen only through contact events: each of 40 clusters holds one event
    that opens at its own gap threshold, so the cost is a staircase in the offset (flat
    between thresholds, where a linearised interval is of zero width)."""

    def __init__(self, spec, truth=1.6e-3, clusters: int = 40):
        n = clusters * 5
        W = Windows(np.zeros((n, 19)), np.zeros((n, 2, 19)), np.zeros((n, 3, 3)),
                    np.arange(n) * 10, np.arange(n) // 5, np.arange(n) * 0.1)
        super().__init__(spec, [], W, (np.arange(n) // 5) % 3, np.ones((2, 19)),
                         cluster_steps=50)
        rng = np.random.default_rng(9)
        self.truth = truth
        self.thresholds = truth + rng.normal(0.0, 4e-4, clusters)   # per-event scatter
        self.noise = rng.normal(0.0, 1.0, (n, 2, 19))

    def residuals(self, effects, W):
        a = sum(float(v[0]) for c, v in list(self.base) + list(effects) if c == EE_OFFSET)
        ev = W.row // 50
        miss = (a > self.thresholds[ev]) != (self.truth > self.thresholds[ev])
        return self.noise[W.row // 10] + 3.0 * miss[:, None, None]


def test_the_held_out_interval_of_a_staircase_cost_holds_the_truth():
    prob = StaircaseProblem(_spec())
    # a fit stalled on a step 0.3 mm off, its linearised interval of no width
    fit = Fit((EE_OFFSET,), np.array([1.9e-3]), np.array([[1.9e-3, 1.9e-3]]), np.zeros(1), 0.0)
    lo, hi = held_out_interval(prob, fit)
    assert lo < 1.6e-3 < hi < 1.9e-3            # the stalled value itself is rejected
    assert hi - lo < 1.5e-3                     # and so are values far off
    widen_to_held_out(prob, fit)                # the reported interval holds both
    assert fit.ci[0, 0] == lo and fit.ci[0, 1] == 1.9e-3 and fit.sd[0] > 0
    # a fit at the truth: the far side of the scatter of thresholds is rejected
    fit = Fit((EE_OFFSET,), np.array([1.6e-3]), np.array([[1.6e-3, 1.6e-3]]), np.zeros(1), 0.0)
    lo2, hi2 = held_out_interval(prob, fit)
    assert lo2 < 1.6e-3 < hi2 and hi2 < 1.6e-3 + 1.5e-3


STIFFNESS = Candidate("stiffness_calibration", "contacts")


class SoftContactProblem(Problem):
    """A pressed EE whose height reads the EE-ball offset plus its sinking into a contact
    of stiffness k (30 N/m * 1/k of it): a 4x softer contact than the model's looks like a
    0.9 mm larger offset, and no residual sees k alone."""

    def __init__(self, spec, truth=-2.7e-3, k_true=2.5e4, windows: int = 120):
        n = windows
        W = Windows(np.zeros((n, 19)), np.zeros((n, 2, 19)), np.zeros((n, 3, 3)),
                    np.arange(n) * 10, np.arange(n) // 12, np.arange(n) * 0.1)
        super().__init__(spec, [], W, np.arange(n) % 3, np.ones((2, 19)), cluster_steps=50)
        self.truth, self.k_true = truth, k_true
        self.noise = np.random.default_rng(7).normal(0.0, 1.0, (n, 2, 19))

    def residuals(self, effects, W):
        a, k = 0.0, 1e5
        for c, v in list(self.base) + list(effects):
            if c == EE_OFFSET:
                a += float(v[0])
            elif c == STIFFNESS:
                k = float(v[0])
        sink = 30.0 * (1.0 / k - 1.0 / self.k_true)
        return self.noise[W.row // 10] + 4e3 * (a - self.truth + sink)


def test_the_held_out_interval_is_profiled_over_the_contact_stiffness():
    spec = _spec()
    fit = Fit((EE_OFFSET,), np.array([-1.8e-3]), np.array([[-1.8e-3] * 2]), np.zeros(1), 0.0)
    lo, hi = held_out_interval(SoftContactProblem(spec), fit)
    assert not lo <= -2.7e-3 <= hi               # at the model's stiffness alone
    spec.nuisance = tuple(spec.nuisance) + (("stiffness_calibration", "contacts"),)
    spec.stiffness_groups = {"contacts": ((0, 1), 1e5)}
    lo, hi = held_out_interval(SoftContactProblem(spec), fit)
    assert lo <= -2.7e-3 <= hi and hi < -1.5e-3  # profiled over 0.25-2x the stiffness
