"""The paper's Fig. 3 pattern on the cart-pole with the wrong wall offsets."""
import numpy as np
import pytest

from adaptive_c3.tools.studies.gradient_map import (
    BOTH, CONTACT_ONLY, NEITHER, PREDICTED_ONLY, gradient_map_data, make_gradient_map)

DPHI = np.array([-0.15, 0.15])


@pytest.fixture(scope="module")
def grid():
    return gradient_map_data(n_x=90, n_theta=90)


def test_all_four_regions_are_on_the_grid(grid):
    counts = {k: int(np.count_nonzero(grid["region"] == k))
              for k in (NEITHER, CONTACT_ONLY, PREDICTED_ONLY, BOTH)}
    assert all(c >= 50 for c in counts.values()), counts
    assert grid["kkt"] <= 1e-8


def test_zero_gradient_only_where_neither_says_contact(grid):
    region, gn = grid["region"], grid["grad_norm"]
    # cells on a region boundary (a gap of exactly 0 to rounding) are ambiguous
    clear = (grid["gap_true"] > 1e-9) & (grid["gap_model"] > 1e-9)
    assert np.all(gn[region == NEITHER] == 0.0)
    assert np.all(grid["loss"][region == NEITHER] == 0.0)
    assert np.all(gn[(region == PREDICTED_ONLY) & clear] > 0)
    assert np.all(gn[(region == BOTH) & clear] > 0)
    # contact only: nonzero except in the thin band next to the true wall that the KKT
    # conditions predict (q + r >= 0 and q + r + eps D'Qd z >= 0); eps Q_d = 100 makes
    # it 0.15 / (1 + 0.405 * 100) = 3.7 mm of pole-tip travel wide
    contact_only = (region == CONTACT_ONLY) & clear
    band = contact_only & (gn == 0)
    np.testing.assert_array_equal(gn == 0, grid["zero_predicted"])
    assert np.all(grid["gap_true"][band] < 0.0037)
    assert np.count_nonzero(band) <= 0.05 * np.count_nonzero(contact_only)


def test_gradient_points_r_toward_dphi(grid):
    region, g = grid["region"], grid["grad"]
    lt, lm = grid["lam_true"], grid["lam_model"]
    for wall in (0, 1):
        at_wall = (lt[..., wall] > 0) | (lm[..., wall] > 0)
        moving = at_wall & (np.abs(g[..., wall]) > 0)
        assert np.count_nonzero(moving) > 100
        # descent direction -grad moves r[wall] toward dphi[wall] (from r = 0)
        assert np.all(np.sign(-g[..., wall][moving]) == np.sign(DPHI[wall]))
        # and the other wall's residual is untouched there
        assert np.all(g[..., 1 - wall][at_wall] == 0.0)


def test_small_eps_flattens_contact_only(grid):
    """With eps Q_d = 1e-3 the contact-only region gives no gradient at all: the figure
    reproduces the paper's pattern only for eps Q_d large enough (documented)."""
    small = gradient_map_data(n_x=40, n_theta=40, epsilon=1e-3)
    clear = (small["gap_true"] > 1e-9) & (small["gap_model"] > 1e-9)
    co = (small["region"] == CONTACT_ONLY) & clear
    assert co.sum() > 50 and np.all(small["grad_norm"][co] == 0.0)
    assert np.all(small["grad_norm"][(small["region"] == PREDICTED_ONLY) & clear] > 0)
    np.testing.assert_array_equal(small["grad_norm"] == 0, small["zero_predicted"])


def test_make_gradient_map_writes_a_png(tmp_path):
    out = tmp_path / "fig3.png"
    data = make_gradient_map(out, n_x=30, n_theta=30)
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert out.stat().st_size > 10_000
    assert data["grad"].shape == (30, 30, 2)
