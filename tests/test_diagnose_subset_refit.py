"""Issue 30: a refit on a subset of the windows (a fold left out, a jackknife group) is one
Gauss-Newton step on a costly model, unless the windows left out carry most of the
information; then the model is refitted (engine/fit.subset_refit)."""
import numpy as np

from adaptive_c3.scenarios.schema import SCENARIO_DIR, load_scenario
from adaptive_c3.tools.diagnosis.backends.effects import Candidate
from adaptive_c3.tools.diagnosis.engine.fit import (LINEAR_REFIT_MAX_DROP, Problem,
                                                    fit_candidates, jackknife, jackknife_groups,
                                                    linear_refit, subset_refit)
from adaptive_c3.tools.diagnosis.engine.locate import Windows
from adaptive_c3.tools.diagnosis.tasks.ball_rolling.effects_ball import ball_spec

EE_OFFSET = Candidate("contact_offset", "ee_ball")


class CoastProblem(Problem):
    """Two kinds of window: a few `coast` windows (row < 20) see the offset steeply and
    linearly, r = 3e4 (v - 1 mm); the others weakly and curved, r = 3e6 (v - 2 mm)^2.
    Over all windows the coasts decide (v ~ 1 mm); without them the optimum is 2 mm,
    and one Gauss-Newton step from 1 mm stops halfway."""

    def __init__(self, spec, coasts: int = 2, rests: int = 10):
        n = coasts + rests
        W = Windows(np.zeros((n, 19)), np.zeros((n, 1, 19)), np.zeros((n, 1, 3)),
                    np.arange(n) * 10, np.arange(n), np.arange(n) * 0.1)
        super().__init__(spec, [], W, np.arange(n) % 3, np.ones((1, 19)), cluster_steps=10)
        self.coasts = coasts

    def residuals(self, effects, W):
        v = sum(float(p[0]) for c, p in list(self.base) + list(effects) if c == EE_OFFSET)
        r = np.zeros((len(W), 1, 19))
        coast = W.row < 10 * self.coasts
        r[coast, 0, 0] = 3e4 * (v - 1e-3)
        r[~coast, 0, 0] = 3e6 * (v - 2e-3) ** 2
        return r


def _fit(linear=True, coasts=2):
    spec = ball_spec(load_scenario(str(SCENARIO_DIR / "ball_rolling.yaml"))[0])
    spec.linear_refits = linear
    prob = CoastProblem(spec, coasts=coasts)
    return prob, fit_candidates(prob, [EE_OFFSET], init=np.array([0.5e-3]))


def test_dropping_most_of_the_information_refits_the_model():
    prob, fit = _fit()
    assert abs(fit.values[0] - 1e-3) < 1e-4                 # the coasts decide
    rests = prob.used().row >= 20
    step = linear_refit(fit, keep=rests)[0]
    assert abs(step - 2e-3) > 3e-4                           # the step stops short
    assert abs(subset_refit(prob, fit, rests)[0] - 2e-3) < 5e-5     # the refit does not


def test_a_small_share_left_out_keeps_the_gauss_newton_step():
    prob, fit = _fit()
    keep = prob.used().row != 100                            # one rest window out
    Jt, shape = fit.lin[1], fit.lin[4]
    info = np.sum(Jt.reshape((len(Jt), shape[0], -1)) ** 2, axis=2)[0]
    assert info[~keep].sum() / info.sum() <= LINEAR_REFIT_MAX_DROP
    assert subset_refit(prob, fit, keep)[0] == linear_refit(fit, keep=keep)[0]


def test_a_cheap_model_always_refits():
    prob, fit = _fit(linear=False)
    keep = prob.used().row != 100
    ref = fit_candidates(prob, [EE_OFFSET], init=fit.values, ci=False,
                         W=prob.used().take(keep)).values[0]
    assert subset_refit(prob, fit, keep)[0] == ref


def test_the_jackknife_reads_the_refit_of_the_group_holding_the_coast():
    """One group of episodes holds the only coast: its delete-one-group estimate is the
    model's refit without it (2 mm), not the step halfway."""
    prob, fit = _fit(coasts=1)
    W = prob.used()
    gid = jackknife_groups(W, 4)
    est = [fit_candidates(prob, [EE_OFFSET], init=fit.values, ci=False,
                          W=W.take(gid != g)).values[0] for g in range(4)]
    assert abs(est[0] - 2e-3) < 5e-5 and all(abs(e - 2e-3) > 5e-4 for e in est[1:])
    sd_model = np.sqrt(3 / 4 * np.sum((np.array(est) - np.mean(est)) ** 2))
    jackknife(prob, fit, groups=4)
    assert abs(fit.sd[0] - sd_model) < 0.02 * sd_model
