"""The fit's windows: every stride-th, plus (for a spec that asks) the windows in which a
strike begins, so that a sparse stride does not miss where EE-ball friction shows."""
from types import SimpleNamespace

import numpy as np

from adaptive_c3.tools.diagnosis.diagnose import fit_windows
from adaptive_c3.tools.diagnosis.engine.evidence import EE_TOUCH, strike_onsets
from adaptive_c3.tools.diagnosis.engine.locate import Windows

BALL_R, EE_R = 0.04, 0.01


def _recording(touchdowns, strikes, length=400, contact_steps=10):
    """(gaps [length, 2] in m, EE-minus-ball direction per row): 5 mm clear, in contact
    for contact_steps from each touchdown (EE above the ball) and strike (EE beside it)."""
    phi = np.full((length, 2), 0.005)
    side = np.tile([0.0, 0.0, 1.0], (length, 1))
    for t in touchdowns + strikes:
        phi[t:t + contact_steps, 0] = -0.0005
    for t in strikes:
        side[t - 5:t + contact_steps] = [np.cos(0.2), 0.0, np.sin(0.2)]   # 11 deg up
    return phi, side


def _windows(rows, side):
    n = len(rows)
    X0 = np.zeros((n, 19))
    X0[:, 7:10] = [0.5, 0.0, BALL_R]
    X0[:, 0:3] = X0[:, 7:10] + (BALL_R + EE_R + 0.005) * side[rows]
    return Windows(X0, np.zeros((n, 10, 19)), np.zeros((n, 12, 3)), np.asarray(rows),
                   np.zeros(n, int), np.asarray(rows) * 0.01)


def test_one_window_per_strike_with_contact_at_its_second_step_and_no_touchdowns():
    touchdowns, strikes = [50, 251], [130, 320]
    phi, side = _recording(touchdowns, strikes)
    spec = SimpleNamespace(cache={"phi": phi})
    W = _windows(np.arange(380), side)
    onset = strike_onsets(spec, W)
    assert list(W.row[onset]) == [t - 2 for t in strikes]
    for r in W.row[onset]:
        assert phi[r, 0] > EE_TOUCH and phi[r + 1, 0] > EE_TOUCH and phi[r + 2, 0] <= EE_TOUCH


def test_fit_windows_add_the_strikes_to_the_stride_within_the_budget():
    strikes = list(range(20, 380, 30))              # 12 strikes
    phi, side = _recording([5, 215], strikes)
    spec = SimpleNamespace(cache={"phi": phi}, strike_fit_windows=5)
    W = _windows(np.arange(390), side)
    keep = fit_windows(spec, W, stride=50)
    stride_part = np.arange(390) % 50 == 0
    added = keep & ~stride_part
    assert np.all(keep[stride_part])
    assert added.sum() == 5                          # the budget, spread evenly
    assert np.all(strike_onsets(spec, W)[added])
    assert W.row[added].min() == strikes[0] - 2 and W.row[added].max() == strikes[-1] - 2
    assert not np.any(strike_onsets(spec, W)[stride_part])   # the stride alone: none


def test_fit_windows_are_the_stride_alone_without_strikes_a_budget_or_the_cache():
    W_rows = np.arange(200)
    stride_only = W_rows % 7 == 0
    phi, side = _recording([60, 120], [])
    pushes_only = SimpleNamespace(cache={"phi": phi}, strike_fit_windows=10)
    phi_s, side_s = _recording([60], [120])
    no_budget = SimpleNamespace(cache={"phi": phi_s})
    no_cache = SimpleNamespace(strike_fit_windows=10)
    assert np.array_equal(fit_windows(pushes_only, _windows(W_rows, side), 7), stride_only)
    assert np.array_equal(fit_windows(no_budget, _windows(W_rows, side_s), 7), stride_only)
    assert np.array_equal(fit_windows(no_cache, _windows(W_rows, side), 7), stride_only)
