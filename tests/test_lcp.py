"""Tests of the LCP solvers (Lemke with lexicographic pivoting, and enumeration)."""

from __future__ import annotations

import dataclasses
from fractions import Fraction

import numpy as np
import pytest

from adaptive_c3.systems.contact.lcp import LcpResult, solve_lcp, solve_lcp_enumeration

SIZES = range(1, 11)
SEEDS = range(12)


# --- helpers ---------------------------------------------------------------
def assert_valid(M, q, res: LcpResult, tol: float = 1e-9) -> None:
    """res is a solution of LCP(M, q) and its fields are consistent."""
    M = np.asarray(M, float)
    q = np.asarray(q, float)
    assert res.solved, res.message
    z, w = res.z, res.w
    assert z.shape == q.shape and w.shape == q.shape
    np.testing.assert_allclose(w, M @ z + q, rtol=0, atol=1e-12 * (1 + np.abs(M).max() * np.abs(z).max()))
    assert z.min() >= -tol
    assert w.min() >= -tol
    assert np.abs(z * w).max() <= tol
    assert res.residual <= tol
    # the residual reported is the one of the returned z
    recomputed = max(np.abs(z * w).max(), -z.min(), -w.min(), 0.0)
    assert res.residual == pytest.approx(recomputed, abs=1e-15)


def p_matrix_spd(rng, m):
    A = rng.standard_normal((m, m))
    return A @ A.T + np.diag(rng.uniform(0.1, 2.0, m))


def p_matrix_diag_dominant(rng, m):
    """Non-symmetric, strictly row diagonally dominant with positive diagonal (a P-matrix)."""
    M = rng.uniform(-1.0, 1.0, (m, m))
    np.fill_diagonal(M, 0.0)
    M[np.diag_indices(m)] = np.abs(M).sum(axis=1) + rng.uniform(0.1, 1.0, m)
    return M


def p_matrix_pd_nonsym(rng, m):
    """Positive definite (not symmetric): SPD plus skew part, a P-matrix."""
    S = rng.standard_normal((m, m))
    return p_matrix_spd(rng, m) + (S - S.T)


def psd_rank_deficient(rng, m):
    k = max(1, m // 2)
    B = rng.standard_normal((m, k))
    return B @ B.T


def psd_plus_skew(rng, m):
    k = max(1, m - 2)
    B = rng.standard_normal((m, k))
    S = rng.standard_normal((m, m))
    return B @ B.T + (S - S.T)


def solvable_q(rng, M, degenerate=False):
    """q = w* - M z* with complementary z*, w* >= 0, so LCP(M, q) has a solution.

    With degenerate=True some indices get z*_i = w*_i = 0 (a degenerate solution).
    """
    m = M.shape[0]
    active = rng.random(m) < 0.5
    z = np.where(active, rng.uniform(0.1, 2.0, m), 0.0)
    w = np.where(active, 0.0, rng.uniform(0.1, 2.0, m))
    if degenerate:
        both_zero = rng.random(m) < 0.4
        z[both_zero] = 0.0
        w[both_zero] = 0.0
    return w - M @ z


# --- P-matrices: unique solution, must match enumeration --------------------
@pytest.mark.parametrize("make", [p_matrix_spd, p_matrix_diag_dominant, p_matrix_pd_nonsym])
@pytest.mark.parametrize("m", SIZES)
def test_p_matrix_matches_enumeration(make, m):
    for seed in SEEDS:
        rng = np.random.default_rng(1000 * m + seed)
        M = make(rng, m)
        for q in (rng.standard_normal(m), 3.0 * rng.standard_normal(m) - 1.0):
            res = solve_lcp(M, q)
            ref = solve_lcp_enumeration(M, q)
            assert ref.solved
            assert_valid(M, q, res)
            np.testing.assert_allclose(res.z, ref.z, rtol=0, atol=1e-9)
            np.testing.assert_allclose(res.w, ref.w, rtol=0, atol=1e-9)


@pytest.mark.parametrize("m", [12, 16])
def test_p_matrix_larger_sizes_are_valid(m):
    for seed in range(20):
        rng = np.random.default_rng(seed)
        M = p_matrix_spd(rng, m) if seed % 2 else p_matrix_diag_dominant(rng, m)
        q = rng.standard_normal(m)
        assert_valid(M, q, solve_lcp(M, q))


# --- PSD / monotone: Lemke solves whenever a solution exists -----------------
@pytest.mark.parametrize("make", [psd_rank_deficient, psd_plus_skew])
@pytest.mark.parametrize("m", SIZES)
def test_psd_random_q_agrees_with_enumeration(make, m):
    n_solvable = 0
    for seed in SEEDS:
        rng = np.random.default_rng(7000 + 100 * m + seed)
        M = make(rng, m)
        q = rng.standard_normal(m)
        res = solve_lcp(M, q)
        ref = solve_lcp_enumeration(M, q)
        if ref.solved:
            n_solvable += 1
            assert_valid(M, q, res)
            if make is psd_rank_deficient:
                # for symmetric PSD M, w = M z + q is the same at every solution
                np.testing.assert_allclose(res.w, ref.w, rtol=0, atol=1e-8)
        if res.solved:
            assert_valid(M, q, res)
        else:
            # Lemke ends on a ray only if the (copositive-plus) LCP has no solution
            assert not ref.solved
            assert "ray" in res.message
    if make is psd_plus_skew or m == 1:
        assert n_solvable > 0


@pytest.mark.parametrize("make", [psd_rank_deficient, psd_plus_skew])
@pytest.mark.parametrize("m", SIZES)
def test_psd_solvable_by_construction(make, m):
    for seed in SEEDS:
        rng = np.random.default_rng(9000 + 100 * m + seed)
        M = make(rng, m)
        q = solvable_q(rng, M)
        assert_valid(M, q, solve_lcp(M, q))


# --- degenerate problems ----------------------------------------------------
@pytest.mark.parametrize("m", SIZES)
def test_degenerate_q_with_zeros(m):
    for seed in SEEDS:
        rng = np.random.default_rng(500 + 100 * m + seed)
        for M in (p_matrix_spd(rng, m), psd_rank_deficient(rng, m), psd_plus_skew(rng, m)):
            # a solution with z_i = w_i = 0 for some i
            q = solvable_q(rng, M, degenerate=True)
            assert_valid(M, q, solve_lcp(M, q))
            # q with exact zeros among negative and positive entries
            q2 = np.where(rng.random(m) < 0.5, 0.0, rng.standard_normal(m))
            res = solve_lcp(M, q2)
            ref = solve_lcp_enumeration(M, q2)
            if ref.solved:
                assert_valid(M, q2, res)
            if not res.solved:
                assert not ref.solved and "ray" in res.message
        # for the positive definite one a solution always exists
        M = p_matrix_spd(rng, m)
        q2 = np.where(rng.random(m) < 0.5, 0.0, -rng.random(m))
        assert_valid(M, q2, solve_lcp(M, q2))


def test_q_zero_and_q_nonnegative_are_trivial():
    M = np.array([[1.0, 2.0], [-3.0, 1.0]])
    for q in (np.zeros(2), np.array([0.0, 1.0]), np.array([2.0, 3.0])):
        res = solve_lcp(M, q)
        assert_valid(M, q, res)
        assert res.iterations == 0
        np.testing.assert_array_equal(res.z, 0.0)


def test_equal_negative_q_entries():
    """All q_i equal: the first ratio test is a full tie."""
    for m in range(1, 9):
        rng = np.random.default_rng(m)
        for M in (np.eye(m), np.ones((m, m)) + np.eye(m), p_matrix_spd(rng, m), np.ones((m, m))):
            q = -np.ones(m)
            res = solve_lcp(M, q)
            assert_valid(M, q, res)
            ref = solve_lcp_enumeration(M, q)
            np.testing.assert_allclose(M @ res.z + q, ref.w, atol=1e-9)


@pytest.mark.parametrize("m", [2, 3, 5, 8])
def test_repeated_rows_and_columns(m):
    """M = B B' with repeated rows of B: repeated rows/columns of M, singular."""
    for seed in SEEDS:
        rng = np.random.default_rng(300 + seed)
        B = rng.standard_normal((m, m))
        B[-1] = B[0]
        if m > 3:
            B[-2] = B[1]
        M = B @ B.T
        assert np.linalg.matrix_rank(M) < m
        q = rng.standard_normal(m)
        res = solve_lcp(M, q)
        ref = solve_lcp_enumeration(M, q)
        if ref.solved:
            assert_valid(M, q, res)
            np.testing.assert_allclose(res.w, ref.w, atol=1e-8)
        q = solvable_q(rng, M, degenerate=True)
        assert_valid(M, q, solve_lcp(M, q))


@pytest.mark.parametrize("m", [1, 2, 4, 7])
def test_duplicated_constraints(m):
    """Appending a copy of constraint i (row and column of M, entry of q) keeps it solvable
    and, for a P-matrix original, leaves w unchanged."""
    for seed in SEEDS:
        rng = np.random.default_rng(40 + seed)
        M = p_matrix_spd(rng, m)
        q = rng.standard_normal(m)
        i = int(rng.integers(m))
        M2 = np.zeros((m + 1, m + 1))
        M2[:m, :m] = M
        M2[m, :m] = M[i]
        M2[:m, m] = M[:, i]
        M2[m, m] = M[i, i]
        q2 = np.append(q, q[i])
        res = solve_lcp(M2, q2)
        assert_valid(M2, q2, res)
        base = solve_lcp(M, q)
        np.testing.assert_allclose(res.w[:m], base.w, atol=1e-9)
        # total force on the duplicated constraint is the original one
        z_merged = res.z[:m].copy()
        z_merged[i] += res.z[m]
        np.testing.assert_allclose(z_merged, base.z, atol=1e-9)


def _naive_lemke_cycles(M, q, init: str, rule: str, prefer_z0: bool, cap: int = 100) -> bool:
    """Exact-arithmetic Lemke without the lexicographic rule: ratio ties go to the
    smallest (rule="first") or largest (rule="last") row index, optionally preferring
    the row of z0. The first pivot takes the smallest (init="first") or largest
    (init="last") index among the most negative q_i.
    Returns True if a basis repeats (the method cycles)."""
    m = len(q)
    T = [
        [Fraction(q[i])] + [Fraction(int(i == j)) for j in range(m)]
        + [Fraction(-M[i][j]) for j in range(m)] + [Fraction(-1)]
        for i in range(m)
    ]
    basis = list(range(m))
    qmin = min(q)
    r = [i for i in range(m) if q[i] == qmin][0 if init == "first" else -1]
    entering = 2 * m
    seen = set()
    for _ in range(cap):
        piv = T[r][entering + 1]
        T[r] = [x / piv for x in T[r]]
        for i in range(m):
            c = T[i][entering + 1]
            if i != r and c != 0:
                T[i] = [a - c * b for a, b in zip(T[i], T[r])]
        leaving, basis[r] = basis[r], entering
        if leaving == 2 * m:
            return False
        key = (tuple(sorted(basis)), entering)
        if key in seen:
            return True
        seen.add(key)
        entering = leaving + m if leaving < m else leaving - m
        rows = [i for i in range(m) if T[i][entering + 1] > 0]
        if not rows:
            return False
        ratios = {i: T[i][0] / T[i][entering + 1] for i in rows}
        rmin = min(ratios.values())
        ties = [i for i in rows if ratios[i] == rmin]
        z0_rows = [i for i in ties if basis[i] == 2 * m]
        if prefer_z0 and z0_rows:
            r = z0_rows[0]
        else:
            r = ties[0] if rule == "first" else ties[-1]
    return True


# Degenerate LCPs (found by a random search) on which Lemke without the
# lexicographic rule cycles, with the tie-breaking (init, rule, prefer_z0) that cycles.
# The first is a P-matrix (M + M' is positive definite), so Lemke must solve it.
CYCLING_P_MATRIX = ([[2, -3, 6], [3, 2, -2], [-2, 6, 5]], [-1, -1, -1], "last", "last", True)
CYCLING_SOLVABLE = [
    CYCLING_P_MATRIX,
    ([[1, -2, 1], [0, 0, 2], [-1, 1, 1]], [-1, -1, -1], "first", "first", False),
    ([[-1, 1, 2], [1, 1, 0], [-2, -2, 2]], [-2, -2, -2], "first", "first", False),
    ([[1, -1, 2, 2], [1, -2, -1, 0], [2, 0, -2, -2], [-1, 0, 0, 2]], [-1, 1, -1, 0], "first", "first", False),
    ([[-2, 1, 0, 1], [2, -2, 2, 0], [2, 1, -1, 2], [1, -2, -2, 0]], [1, -2, -2, 1], "last", "first", True),
]
CYCLING_UNSOLVABLE = [
    ([[-1, 1, 1, 1], [0, -2, -2, 0], [0, 1, 1, -1], [-2, -1, 1, 1]], [-2, -2, -2, 1], "first", "first", False),
    ([[0, -2, 2], [1, 0, -2], [2, 1, 0]], [-2, 0, -2], "last", "first", True),
    ([[-1, -1, 2, -1], [0, -2, -1, 0], [1, 2, 0, 0], [-2, 1, 1, -1]], [-2, 1, -2, 1], "last", "last", True),
]


@pytest.mark.parametrize("M,q,init,rule,prefer_z0", CYCLING_SOLVABLE + CYCLING_UNSOLVABLE)
def test_examples_really_cycle_without_lexicographic_rule(M, q, init, rule, prefer_z0):
    assert _naive_lemke_cycles(M, q, init, rule, prefer_z0)


@pytest.mark.parametrize("M,q,init,rule,prefer_z0", CYCLING_SOLVABLE)
def test_lexicographic_rule_does_not_cycle(M, q, init, rule, prefer_z0):
    res = solve_lcp(M, q)
    assert solve_lcp_enumeration(M, q).solved
    assert res.iterations < 50
    if res.solved:
        assert_valid(M, q, res)
    else:
        # M is not copositive-plus, so a ray is allowed, but never the cap
        assert "ray" in res.message


def test_lexicographic_rule_solves_cycling_p_matrix():
    M, q, _, _, _ = CYCLING_P_MATRIX
    assert np.all(np.linalg.eigvalsh(np.add(M, np.transpose(M))) > 0)
    res = solve_lcp(M, q)
    assert_valid(M, q, res)
    np.testing.assert_allclose(res.z, solve_lcp_enumeration(M, q).z, atol=1e-9)


@pytest.mark.parametrize("M,q,init,rule,prefer_z0", CYCLING_UNSOLVABLE)
def test_cycling_unsolvable_ends_on_ray(M, q, init, rule, prefer_z0):
    res = solve_lcp(M, q)
    assert not res.solved
    assert "ray" in res.message
    assert not solve_lcp_enumeration(M, q).solved


# --- infeasible problems, iteration cap, scaling -----------------------------
@pytest.mark.parametrize(
    "M,q",
    [
        ([[-1.0]], [-1.0]),
        ([[0.0]], [-1.0]),
        ([[1.0, -1.0], [-1.0, 1.0]], [-1.0, -1.0]),  # PSD, infeasible
        ([[0.0, 1.0], [-1.0, 0.0]], [-1.0, -1.0]),  # skew, infeasible
    ],
)
def test_infeasible_reports_not_solved(M, q):
    res = solve_lcp(M, q)
    assert isinstance(res, LcpResult)
    assert not res.solved
    assert res.message
    assert res.residual > 1e-6
    assert not solve_lcp_enumeration(M, q).solved


def test_iteration_cap_reports_not_solved():
    rng = np.random.default_rng(3)
    M = p_matrix_spd(rng, 8)
    q = -np.abs(rng.standard_normal(8)) - 0.5
    full = solve_lcp(M, q)
    assert full.solved and full.iterations > 2
    res = solve_lcp(M, q, max_iterations=2)
    assert not res.solved
    assert "cap" in res.message
    assert res.iterations == 2


@pytest.mark.parametrize("scale_m,scale_q", [(1e3, 1e-3), (1e-3, 1e3), (1e4, 1.0), (1.0, 1e-4)])
def test_badly_scaled_problems(scale_m, scale_q):
    for seed in range(10):
        rng = np.random.default_rng(seed)
        M = p_matrix_spd(rng, 6) * scale_m
        q = rng.standard_normal(6) * scale_q
        res = solve_lcp(M, q)
        ref = solve_lcp_enumeration(M, q)
        assert res.solved, res.message
        zs = np.abs(ref.z).max() + 1e-300
        np.testing.assert_allclose(res.z, ref.z, rtol=0, atol=1e-9 * max(1.0, zs))
        assert res.residual <= 1e-9 * max(1.0, np.abs(q).max())


@pytest.mark.parametrize("m", [3, 5, 7, 9])
def test_ill_conditioned_hilbert(m):
    """Hilbert matrices (condition number up to ~1e11) with a known solution."""
    i = np.arange(m)
    H = 1.0 / (i[:, None] + i[None, :] + 1.0)
    for seed in range(6):
        rng = np.random.default_rng(seed)
        z_star = rng.uniform(0.0, 1.0, m) * (rng.random(m) < 0.7)
        w_star = rng.uniform(0.0, 1.0, m) * (z_star == 0)
        q = w_star - H @ z_star
        res = solve_lcp(H, q)
        assert_valid(H, q, res)
        np.testing.assert_allclose(res.z, z_star, atol=1e-6)


def test_unsolved_result_reports_its_own_residual():
    M = np.array([[1.0, -1.0], [-1.0, 1.0]])
    q = np.array([-1.0, -1.0])
    res = solve_lcp(M, q)
    assert not res.solved
    np.testing.assert_allclose(res.w, M @ res.z + q)
    expected = max(np.abs(res.z * res.w).max(), -res.z.min(), -res.w.min(), 0.0)
    assert res.residual == pytest.approx(expected)


def test_lcs_like_problem_two_walls():
    """The cart-pole wall LCP: F = I / ks, q = E x + c."""
    F = np.eye(2) / 50.0
    for q in ([-0.05, 0.75], [0.75, -0.05], [0.35, 0.35], [-0.0, 0.7]):
        res = solve_lcp(F, q)
        assert_valid(F, q, res)
        np.testing.assert_allclose(res.z, np.maximum(0.0, -np.asarray(q)) * 50.0, atol=1e-12)


# --- result and enumeration behaviour --------------------------------------
def test_result_is_frozen_and_typed():
    res = solve_lcp(np.eye(2), [-1.0, 2.0])
    with pytest.raises(dataclasses.FrozenInstanceError):
        res.solved = False
    assert isinstance(res.iterations, int)
    assert isinstance(res.residual, float)
    np.testing.assert_allclose(res.z, [1.0, 0.0])
    np.testing.assert_allclose(res.w, [0.0, 2.0])


def test_enumeration_reports_no_solution_and_limits_size():
    res = solve_lcp_enumeration([[-1.0]], [-1.0])
    assert not res.solved
    with pytest.raises(ValueError, match="m <= 12"):
        solve_lcp_enumeration(np.eye(13), np.ones(13))


def test_accepts_lists_and_column_q():
    res = solve_lcp([[2, 1], [1, 2]], np.array([[-1.0], [-1.0]]))
    assert_valid([[2, 1], [1, 2]], [-1, -1], res)
    np.testing.assert_allclose(res.z, [1 / 3, 1 / 3], atol=1e-12)


@pytest.mark.parametrize("solver", [solve_lcp, solve_lcp_enumeration])
@pytest.mark.parametrize(
    "M,q,match",
    [
        (np.ones((2, 3)), np.ones(2), "square"),
        (np.ones(3), np.ones(3), "square"),
        (np.ones((2, 2, 2)), np.ones(2), "square"),
        (np.eye(2), np.ones(3), "mismatch"),
        (np.eye(2), np.ones((2, 2)), "1-D"),
        (np.zeros((0, 0)), np.zeros(0), "empty"),
        (np.array([[1.0, np.nan], [0.0, 1.0]]), np.ones(2), "M contains NaN"),
        (np.eye(2), np.array([1.0, np.inf]), "q contains NaN or inf"),
    ],
)
def test_bad_input_raises(solver, M, q, match):
    with pytest.raises(ValueError, match=match):
        solver(M, q)


def _nearly_singular_pd(rng, m=8, rank=5):
    """PD M = J J' + 1e-9 I (condition number ~1e10) and q with a known bounded solution."""
    J = rng.standard_normal((m, rank))
    M = J @ J.T + 1e-9 * np.eye(m)
    act = rng.random(m) < 0.5
    z_star = np.where(act, rng.random(m), 0.0)
    q = np.where(act, 0.0, rng.random(m)) - M @ z_star
    return M, q


def test_regularised_retry_on_nearly_singular_pd():
    """Plain Lemke fails on some of these problems (round-off picks a wrong basis); the
    regularised retry solves them on the original M and says so."""
    rng = np.random.default_rng(0)
    plain_failures, retried = 0, []
    for _ in range(300):
        M, q = _nearly_singular_pd(rng)
        assert np.linalg.cond(M) > 1e9
        plain = solve_lcp(M, q, regularize=False)
        assert plain.regularization == 0.0
        if plain.solved:
            continue
        plain_failures += 1
        res = solve_lcp(M, q)
        if res.solved:
            assert res.regularization > 0.0 and "regularised retry" in res.message
            assert_valid(M, q, res)
            retried.append(res)
    assert plain_failures >= 3                      # the problem class does break Lemke
    assert len(retried) == plain_failures           # measured: 6 of 300, all repaired


def test_retry_is_not_used_on_well_conditioned_problems():
    rng = np.random.default_rng(1)
    for _ in range(50):
        M = p_matrix_spd(rng, 6)
        res = solve_lcp(M, rng.standard_normal(6))
        assert res.solved and res.regularization == 0.0
