"""The fit's windows: every stride-th, plus (for a spec that asks) the windows in which
EE-ball contact begins, so that a sparse stride does not miss the strikes."""
from types import SimpleNamespace

import numpy as np

from adaptive_c3.tools.diagnosis.diagnose import fit_windows
from adaptive_c3.tools.diagnosis.engine.evidence import EE_TOUCH, contact_onsets
from adaptive_c3.tools.diagnosis.engine.locate import Windows


def _windows(rows):
    n = len(rows)
    return Windows(np.zeros((n, 19)), np.zeros((n, 10, 19)), np.zeros((n, 12, 3)),
                   np.asarray(rows), np.zeros(n, int), np.asarray(rows) * 0.01)


def _gap(touchdowns, length=400, contact_steps=20):
    """EE-ball gaps (m): 5 mm clear, in contact for contact_steps from each touchdown."""
    phi = np.full((length, 2), 0.005)
    for t in touchdowns:
        phi[t:t + contact_steps, 0] = -0.0005
    return phi


def test_one_onset_window_per_touchdown_with_contact_at_its_second_step():
    touchdowns = [50, 130, 251]
    spec = SimpleNamespace(cache={"phi": _gap(touchdowns)})
    W = _windows(np.arange(380))
    onset = contact_onsets(spec, W)
    assert list(W.row[onset]) == [t - 2 for t in touchdowns]
    gap = spec.cache["phi"][:, 0]
    for r in W.row[onset]:
        assert gap[r] > EE_TOUCH and gap[r + 1] > EE_TOUCH and gap[r + 2] <= EE_TOUCH


def test_fit_windows_add_the_onsets_to_the_stride_within_the_budget():
    touchdowns = list(range(20, 380, 30))           # 12 touchdowns
    spec = SimpleNamespace(cache={"phi": _gap(touchdowns, contact_steps=10)},
                           onset_fit_windows=5)
    W = _windows(np.arange(390))
    keep = fit_windows(spec, W, stride=50)
    stride_part = np.arange(390) % 50 == 0
    added = keep & ~stride_part
    assert np.all(keep[stride_part])
    assert added.sum() == 5                          # the budget, spread evenly
    assert np.all(contact_onsets(spec, W)[added])
    assert W.row[added].min() == touchdowns[0] - 2 and W.row[added].max() == touchdowns[-1] - 2
    # the stride alone lands on none of these onsets
    assert not np.any(contact_onsets(spec, W)[stride_part])


def test_fit_windows_are_the_stride_alone_without_a_budget_or_the_cache():
    W = _windows(np.arange(200))
    stride_only = np.arange(200) % 7 == 0
    with_cache = SimpleNamespace(cache={"phi": _gap([60, 120])})
    no_cache = SimpleNamespace(onset_fit_windows=10)
    assert np.array_equal(fit_windows(with_cache, W, 7), stride_only)
    assert np.array_equal(fit_windows(no_cache, W, 7), stride_only)
