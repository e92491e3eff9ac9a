"""Free-window effects on Drake's ball plant are chosen and judged against `none` by the
signed-rank z over clusters (engine/fit.py signed_rank_z), not the paired z: a drag's
gain sits in a few fast coasts, which caps the paired z however consistent the rest of
the coasts are. A rival is clearly worse by either statistic, the 5 % shared among the
two."""
import numpy as np
from scipy.stats import norm, wilcoxon

from adaptive_c3.tools.diagnosis.backends.effects import Candidate
from adaptive_c3.tools.diagnosis.engine.evidence import FREE_MIN_Z, verdict, worse_z
from adaptive_c3.tools.diagnosis.engine.fit import Fit, cluster_z, paired_z, signed_rank_z
from adaptive_c3.tools.diagnosis.tasks.ball_rolling.drake_ball import DrakeBallSpec
from adaptive_c3.tools.diagnosis.tasks.ball_rolling.effects_ball import BallSpec

NONE = 100 + np.random.default_rng(3).normal(0, 1, 40)   # per-cluster held-out SSR, as is


def test_signed_rank_z_is_wilcoxons_normal_approximation_with_ties_and_zeros():
    rng = np.random.default_rng(10)
    a = np.round(rng.normal(10, 2, 35), 0)   # rounded: tied differences and zeros
    b = np.round(rng.normal(9, 2, 35), 0)
    d = a - b
    assert np.any(d == 0) and len(np.unique(np.abs(d))) < len(d)
    p = wilcoxon(d, zero_method="wilcox", correction=False, method="approx").pvalue
    assert np.isclose(abs(signed_rank_z(a, b)), norm.isf(p / 2), rtol=1e-9)
    assert np.sign(signed_rank_z(a, b)) == np.sign(np.median(d[d != 0]))
    assert signed_rank_z(a, b) == -signed_rank_z(b, a)
    assert cluster_z(a, b, "paired") == paired_z(a, b)


def test_a_gain_in_a_few_fast_coasts_passes_on_ranks_not_on_the_paired_z():
    rng = np.random.default_rng(11)
    gain = np.abs(rng.normal(0.5, 0.3, 40))       # every coast a little better...
    gain[:4] += 60.0                               # ... and four fast coasts much better
    drag = NONE - gain
    assert paired_z(NONE, drag) < 4.0 < FREE_MIN_Z
    assert signed_rank_z(NONE, drag) > FREE_MIN_Z
    spurious = NONE - rng.normal(0.0, 1.0, 40)     # fits noise: gains and losses alike
    assert abs(signed_rank_z(NONE, spurious)) < 2.0


def _fit(name, target, clusters, stat):
    f = Fit((Candidate(name, target),), np.array([1.0]), np.zeros((1, 2)), np.zeros(1), 0.0)
    f.test_cluster_ssr = np.asarray(clusters, float)
    f.test_ssr, f.test_n = float(f.test_cluster_ssr.sum()), 1000
    f.score = f.test_ssr
    f.reduction = 1 - f.test_ssr / float(NONE.sum())
    f.z_stat = stat
    f.z_vs_none = cluster_z(NONE, f.test_cluster_ssr, stat)
    return f


def _judge(chosen_clusters, rival_clusters, stat, family=8):
    chosen = _fit("viscous_damping", "ball", chosen_clusters, stat)
    rival = _fit("rolling_resistance", "ball_table", rival_clusters, stat)
    assert rival.z_vs_none > 2.0
    v = verdict([chosen, rival], chosen, (float(NONE.sum()), 1000, NONE, None), 0.1, family)
    return [a["name"] for a in v["ambiguous"]]


def test_a_rival_worse_in_a_few_fast_coasts_is_ruled_out_by_the_paired_z():
    """The rival loses much in the fast coasts and gains a little in the slow ones: its
    loss's paired z calls it worse, its ranks cannot; ruled out on either statistic."""
    rng = np.random.default_rng(12)
    drag = NONE - 10 - np.abs(rng.normal(0, 0.2, 40))
    rolling = drag + rng.normal(-0.15, 0.3, 40)    # the slow coasts: a little better
    rolling[:10] += 8.0                            # the fast coasts: much worse
    assert signed_rank_z(rolling, drag) < worse_z(8) < worse_z(16) < paired_z(rolling, drag)
    assert _judge(drag, rolling, "paired") == []
    assert _judge(drag, rolling, "signed_rank") == []


def test_a_rival_worse_in_many_slow_coasts_is_ruled_out_by_ranks_where_they_judge():
    """The rival loses a little in most coasts and gains much in two: its paired z cannot
    call it worse, its ranks can, on a problem judged by ranks (at the shared 5 %)."""
    rng = np.random.default_rng(13)
    chosen = NONE - 10 - np.abs(rng.normal(0, 0.2, 40))
    rival = chosen + np.abs(rng.normal(0.4, 0.2, 40))
    rival[:2] -= 15.0
    assert paired_z(rival, chosen) < worse_z(8) < worse_z(16) < signed_rank_z(rival, chosen)
    assert _judge(chosen, rival, "paired") == ["viscous_damping", "rolling_resistance"]
    assert _judge(chosen, rival, "signed_rank") == []


def test_two_tests_share_the_5_percent():
    """Between worse_z(8) and worse_z(16) on both statistics: clearly worse at the
    paired bar alone, not when both tests are run."""
    rng = np.random.default_rng(14)
    chosen = NONE - 10 - np.abs(rng.normal(0, 0.2, 40))
    for scale in np.linspace(0.05, 1.0, 400):
        rival = chosen + scale + rng.normal(0, 1.0, 40)
        z = (paired_z(rival, chosen), signed_rank_z(rival, chosen))
        if worse_z(8) < min(z) and max(z) < worse_z(16):
            break
    else:
        raise AssertionError("no rival between the bars")
    assert _judge(chosen, rival, "paired") == []
    assert _judge(chosen, rival, "signed_rank") == ["viscous_damping", "rolling_resistance"]


def test_drakes_ball_plant_uses_ranks_and_the_lcs_keeps_the_paired_z():
    assert DrakeBallSpec.free_z_stat == "signed_rank"
    assert getattr(BallSpec, "free_z_stat", "paired") == "paired"
