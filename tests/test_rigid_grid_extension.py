"""Issue 30: a rigid-object effect's grid grows past an end its bootstrap interval reaches
(rigid_diagnose.extend_grid): the real cube's centre-of-mass offset read [6.1, 12.0] mm on
a grid that ended at 12 mm, an interval clipped by the search range."""
import numpy as np

from adaptive_c3.tools.diagnosis.tasks.rigid_object.rigid_diagnose import (
    MAX_EXTEND, bootstrap_interval, extend_grid)
from adaptive_c3.tools.diagnosis.tasks.rigid_object.rigid_effects import DRAKE_EFFECTS, RigidEffect

MINIMA = np.random.default_rng(4).normal(10.0, 1.0, 60)   # per-episode best values


def scores(values):
    """[values, episodes] per-episode errors with each episode's minimum at MINIMA."""
    v = np.asarray(values, float)[:, None]
    return (v - MINIMA[None, :]) ** 2 + 1.0


def effect(extend):
    return RigidEffect("e", "patch.e", (0.0, 3.0, 6.0, 9.0), "m", "test", extend=extend)


def test_the_grid_grows_until_the_interval_is_inside():
    grid = [0.0, 3.0, 6.0, 9.0]
    calls = []

    def score_values(vs):
        calls.append(list(vs))
        return scores(vs), [{}] * len(vs)

    g, S, w = extend_grid(effect((-30.0, 30.0)), grid, scores(grid), [{}] * 4, score_values)
    assert g == sorted(g) and g[:4] == grid and g[4:] == [12.0]
    assert np.allclose(S, scores(g)) and len(w) == len(g)
    lo, hi = bootstrap_interval(g, S, np.random.default_rng(1))
    assert 9.0 < lo < 10.0 < hi < 12.0               # the interval is no longer at the end
    lo0, hi0 = bootstrap_interval(grid, scores(grid), np.random.default_rng(1))
    assert hi0 == 9.0                                 # clipped before
    assert calls == [[12.0]]


def test_limits_and_effects_without_them():
    grid = [0.0, 3.0, 6.0, 9.0]
    fixed = extend_grid(effect(()), grid, scores(grid), [{}] * 4, None)
    assert fixed[0] == grid
    g, _, _ = extend_grid(effect((-30.0, 9.0)), grid, scores(grid), [{}] * 4,
                          lambda vs: (scores(vs), [{}] * len(vs)))
    assert g == grid                                  # 12 is past the limit
    far = [-9.0, -6.0, -3.0, 0.0]                     # minima 3-5 steps past the end
    g, _, _ = extend_grid(effect((-30.0, 30.0)), far, scores(far), [{}] * 4,
                          lambda vs: (scores(vs), [{}] * len(vs)))
    assert g[-1] == far[-1] + 3.0 * MAX_EXTEND        # at most MAX_EXTEND steps


def test_the_centre_of_mass_offsets_may_grow():
    com = [e for e in DRAKE_EFFECTS if e.name.startswith("com_offset")]
    assert len(com) == 3 and all(e.extend == (-0.03, 0.03) for e in com)
