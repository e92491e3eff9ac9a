"""C3 solver (systems/c3/solver.py) and its QP step back-ends (systems/c3/qp.py)."""
import numpy as np
import pytest
import scipy.linalg

from adaptive_c3.models.cartpole import cartpole_lcs
from adaptive_c3.systems.c3.options import C3Options, cartpole_c3_options
from adaptive_c3.systems.c3.solver import C3Solver
from adaptive_c3.systems.c3.qp import KktQp, OsqpQp, QpStepData
from adaptive_c3.systems.c3.qp_sparse import DrakeOsqpQp
from adaptive_c3.systems.contact.lcs import LcsSequence
from adaptive_c3.tools.bench.c3 import ballroll_c3_options, random_ballroll_lcs

X0S = ([0.1, -0.3, 0.0, 0.0], [0.3, 0.0, 0.3, 0.0])


def _closed_loop(options, x0, seconds=8.0):
    """True cart-pole LCS stepped with Lcs.step; C3 replans every step (dt = 0.01)."""
    lcs = cartpole_lcs()
    solver = C3Solver(options)
    x = np.array(x0, float)
    xs, touched = [x], False
    for _ in range(int(round(seconds / lcs.dt))):
        sol = solver.solve(lcs, x)
        x, lam = lcs.step(x, sol.u0)
        touched |= bool(np.any(lam > 1e-6))
        xs.append(x)
    return np.array(xs), touched


def _assert_stabilised(xs, dt=0.01):
    """|x|_inf < 0.05 over the whole last second of the 8 s run (so by 7 s at latest)."""
    tail = np.abs(xs[-int(1.0 / dt):]).max()
    assert tail < 0.05, f"not stabilised: max |x| over the last second is {tail:.3g}"


# --- closed loop -----------------------------------------------------------------

@pytest.mark.parametrize("x0", X0S)
def test_cartpole_c3plus_uses_walls_and_stabilises(x0):
    xs, touched = _closed_loop(cartpole_c3_options(), x0)
    assert touched, "the pole never made contact"
    _assert_stabilised(xs)


@pytest.mark.parametrize("projection", ["qp", "exact"])
def test_cartpole_other_projections_stabilise(projection):
    xs, touched = _closed_loop(cartpole_c3_options(projection), X0S[0])
    assert touched
    _assert_stabilised(xs)


def test_cartpole_without_warm_start_stabilises():
    xs, touched = _closed_loop(cartpole_c3_options(warm_start=False), X0S[1])
    assert touched
    _assert_stabilised(xs)


def test_cartpole_with_input_bounds_respects_them_and_stabilises():
    """|u| <= 5 N (the unbounded plan starts at ~12 N): the OSQP back-end is used."""
    lcs = cartpole_lcs()
    solver = C3Solver(cartpole_c3_options(u_bounds=([-5.0], [5.0])))
    x = np.array(X0S[0])
    xs, us = [x], []
    for _ in range(800):
        sol = solver.solve(lcs, x)
        assert sol.info["qp_backend"] == "osqp"
        assert np.all(np.abs(sol.u_plan) <= 5.0 + 1e-9)
        us.append(sol.u0[0])
        x, _ = lcs.step(x, sol.u0)
        xs.append(x)
    assert max(np.abs(us)) > 5.0 - 1e-6          # the bound was active
    _assert_stabilised(np.array(xs))


def test_cartpole_delta_output_stabilises():
    xs, touched = _closed_loop(cartpole_c3_options(end_on_qp_step=False), X0S[0])
    assert touched
    _assert_stabilised(xs)


# --- QP step back-ends ---------------------------------------------------------------

def _step_data(lcs, N, x0, eta, lam0=None, bounds=None, seed=0):
    rng = np.random.default_rng(seed)
    n, k, m = lcs.num_states, lcs.num_inputs, lcs.num_lambda
    st = {a: np.stack([getattr(lcs, a) * (1 + 0.05 * j) if a in ("d", "c") else getattr(lcs, a)
                       for j in range(N)]) for a in "A B D d E F H c".split()}
    Q = np.diag(rng.uniform(1, 100, n))
    R = np.diag(rng.uniform(0.01, 1, k))
    QN = scipy.linalg.solve_discrete_are(lcs.A, lcs.B, Q, R)
    nz = n + m + k + (m if eta else 0)
    data = QpStepData(**st, x0=x0, x_target=0.01 * rng.normal(size=(N + 1, n)),
                      Q=np.array([Q] * N + [QN]), R=np.array([R] * N),
                      g=rng.uniform(0.0, 0.1, (N, nz)), with_eta=eta, lam0=lam0,
                      u_bounds=None if bounds is None else bounds[0],
                      x_bounds=None if bounds is None else bounds[1])
    return data, rng.normal(size=(N, nz))


@pytest.mark.parametrize("eta", [False, True])
@pytest.mark.parametrize("fix_lam0", [False, True])
def test_kkt_equals_osqp_and_sparse_drake_backends(eta, fix_lam0):
    """The condensed Cholesky solve, the osqp-package back-end and an independent
    non-condensed formulation (Drake MathematicalProgram + OsqpSolver) agree to 1e-6
    on the same QP, at the first and the last ADMM scale."""
    lcs = random_ballroll_lcs(3)
    N, n, m = 5, lcs.num_states, lcs.num_lambda
    x0 = 0.05 * np.random.default_rng(1).normal(size=n)
    lam0 = np.abs(np.random.default_rng(2).normal(size=m)) if fix_lam0 else None
    data, a = _step_data(lcs, N, x0, eta, lam0)
    kkt, osq, drk = KktQp(data), OsqpQp().setup(data), DrakeOsqpQp().setup(data)
    for scale in (1.0, 1024.0):
        z1, x1 = kkt.solve(scale, a)
        for other in (osq, drk):
            z2, x2 = other.solve(scale, a)
            np.testing.assert_allclose(z1, z2, atol=1e-6, rtol=0)
            np.testing.assert_allclose(x1, x2, atol=1e-6, rtol=0)
        # The condensed solution satisfies the LCS dynamics (and eta's definition).
        np.testing.assert_allclose(x1[0], x0, atol=1e-12)
        for j in range(N):
            lam, u = z1[j, n:n + m], z1[j, n + m:n + m + lcs.num_inputs]
            np.testing.assert_allclose(
                x1[j + 1], data.A[j] @ x1[j] + data.B[j] @ u + data.D[j] @ lam + data.d[j],
                atol=1e-10)
            np.testing.assert_allclose(z1[j, :n], x1[j], atol=1e-12)
            if eta:
                np.testing.assert_allclose(
                    z1[j, n + m + lcs.num_inputs:],
                    data.E[j] @ x1[j] + data.F[j] @ lam + data.H[j] @ u + data.c[j], atol=1e-10)
        if fix_lam0:
            np.testing.assert_allclose(z1[0, n:n + m], lam0, atol=1e-12)


def test_osqp_backend_with_active_bounds():
    """With bounds (where only OSQP applies) the result is feasible, at least as good as
    Drake's OSQP on the sparse formulation, and equal to it within 1e-5."""
    lcs = random_ballroll_lcs(4)
    N, n, k = 5, lcs.num_states, lcs.num_inputs
    x0 = 0.05 * np.random.default_rng(5).normal(size=n)
    bounds = ((-0.05 * np.ones(k), 0.05 * np.ones(k)), (-0.1 * np.ones(n), 0.1 * np.ones(n)))
    data, a = _step_data(lcs, N, x0, True, None, bounds)
    unb, _ = _step_data(lcs, N, x0, True, None, None)
    osq, drk = OsqpQp().setup(data), DrakeOsqpQp().setup(data)
    m = lcs.num_lambda
    active = 0
    for scale in (1.0, 32.0, 1024.0):
        z1, x1 = osq.solve(scale, a)
        z2, x2 = drk.solve(scale, a)
        u1 = z1[:, n + m:n + m + k]
        assert np.all(np.abs(u1) <= 0.05 + 1e-9) and np.all(np.abs(x1[1:]) <= 0.1 + 1e-9)
        active += int(np.sum(np.isclose(np.abs(u1), 0.05, atol=1e-9)))
        np.testing.assert_allclose(z1, z2, atol=1e-5, rtol=0)
        # Unconstrained optimum violates the bounds (so they are really active).
        zu, _ = KktQp(unb).solve(scale, a)
        assert np.abs(zu[:, n + m:n + m + k]).max() > 0.05
    assert active > 0


def test_kkt_backend_refuses_bounds():
    lcs = random_ballroll_lcs(0)
    data, _ = _step_data(lcs, 5, np.zeros(19), False, None,
                         ((-np.ones(3), np.ones(3)), (-np.ones(19), np.ones(19))))
    with pytest.raises(ValueError):
        KktQp(data)


# --- solver behaviour -----------------------------------------------------------------

def test_solution_fields_and_residuals():
    lcs = cartpole_lcs()
    sol = C3Solver(cartpole_c3_options()).solve(lcs, X0S[0])
    N = 10
    assert sol.u0.shape == (1,) and sol.x_plan.shape == (N + 1, 4)
    assert sol.lam_plan.shape == (N, 2) and sol.u_plan.shape == (N, 1)
    assert sol.delta.shape == (N, 4 + 2 + 1 + 2)          # C3+ carries eta
    assert sol.iterations == 10
    assert np.isfinite(sol.primal_residual) and np.isfinite(sol.dual_residual)
    np.testing.assert_allclose(sol.x_plan[0], X0S[0])
    np.testing.assert_allclose(sol.u0, sol.u_plan[0])
    assert sol.lam0_fixed                                   # cart-pole: H = 0
    # delta (the projected copy) is complementary: lam_i eta_i = 0, both >= 0.
    lam, eta = sol.delta[:, 4:6], sol.delta[:, 7:9]
    assert np.all(lam >= 0) and np.all(eta >= 0) and np.all(lam * eta == 0)
    # More ADMM iterations bring z and delta closer (consensus).
    few = C3Solver(cartpole_c3_options(admm_iter=1, warm_start=False)).solve(lcs, X0S[0])
    assert sol.primal_residual < few.primal_residual


def test_delta_output_follows_the_projected_trajectory():
    lcs = cartpole_lcs()
    sol = C3Solver(cartpole_c3_options(end_on_qp_step=False)).solve(lcs, X0S[1])
    np.testing.assert_array_equal(sol.lam_plan, sol.delta[:, 4:6])
    np.testing.assert_array_equal(sol.u_plan, sol.delta[:, 6:7])
    for j in range(10):
        np.testing.assert_allclose(
            sol.x_plan[j + 1],
            lcs.A @ sol.x_plan[j] + lcs.B @ sol.u_plan[j] + lcs.D @ sol.lam_plan[j] + lcs.d)


def test_time_varying_sequence():
    """A constant LcsSequence gives the single-Lcs answer; a time-varying one is planned
    with each knot's own dynamics."""
    base = cartpole_lcs()
    x0 = np.array(X0S[0])
    opts = cartpole_c3_options(warm_start=False)
    single = C3Solver(opts).solve(base, x0)
    seq_const = LcsSequence.constant(base, 10)
    np.testing.assert_allclose(C3Solver(opts).solve(seq_const, x0).u_plan, single.u_plan,
                               atol=1e-12)
    knots = [base.replace(d=np.array([0.0, 0.0, 0.02 * j, -0.01 * j]),
                          c=base.c + 0.01 * j) for j in range(10)]
    tv = C3Solver(opts).solve(LcsSequence(tuple(knots)), x0)
    assert np.abs(tv.u_plan - single.u_plan).max() > 1e-3
    for j, s in enumerate(knots):
        np.testing.assert_allclose(
            tv.x_plan[j + 1], s.A @ tv.x_plan[j] + s.B @ tv.u_plan[j] + s.D @ tv.lam_plan[j]
            + s.d, atol=1e-9)
        np.testing.assert_allclose(    # eta of the final QP uses knot j's E, F, H, c
            tv.z[j, 7:9], s.E @ tv.x_plan[j] + s.F @ tv.lam_plan[j] + s.H @ tv.u_plan[j] + s.c,
            atol=1e-9)
    with pytest.raises(ValueError):
        C3Solver(opts).solve(LcsSequence(tuple(knots[:5])), x0)     # wrong horizon


def test_warm_start_uses_previous_plan_shifted():
    lcs = cartpole_lcs()
    solver = C3Solver(cartpole_c3_options())
    first = solver.solve(lcs, X0S[0])
    x1, _ = lcs.step(np.array(X0S[0]), first.u0)
    warm = solver.solve(lcs, x1)
    again = C3Solver(cartpole_c3_options()).solve(lcs, x1, warm=first)
    np.testing.assert_allclose(warm.u_plan, again.u_plan, atol=1e-12)
    solver.reset()
    cold = solver.solve(lcs, x1)
    np.testing.assert_allclose(cold.u_plan, C3Solver(cartpole_c3_options()).solve(lcs, x1).u_plan,
                               atol=1e-12)
    assert np.abs(cold.delta - warm.delta).max() > 0          # the warm start mattered


def test_target_shifts_the_plan():
    lcs = cartpole_lcs()
    opts = cartpole_c3_options(warm_start=False)
    target = np.array([0.05, 0.0, 0.0, 0.0])
    sol = C3Solver(opts).solve(lcs, target, x_target=target)
    assert np.abs(sol.u0).max() < np.abs(C3Solver(opts).solve(lcs, target).u0).max()


def _check_ballroll_plan(sol, lcs, x0, proj, n=19, m=8, k=3):
    """The plan starts at x0 and follows the LCS dynamics; the last projected copy delta
    lies in the set the projection promises: exact - the complementarity set; C3+ - lam
    and its eta copy complementary; QP - lam >= 0, eta >= 0 (product only approximately
    0, measured 4.2e-3 on this problem)."""
    np.testing.assert_array_equal(sol.x_plan[0], x0)
    np.testing.assert_array_equal(sol.u0, sol.u_plan[0])
    x, u, lam = sol.x_plan, sol.u_plan, sol.lam_plan
    pred = x[:-1] @ lcs.A.T + u @ lcs.B.T + lam @ lcs.D.T + lcs.d
    np.testing.assert_allclose(x[1:], pred, atol=1e-10)
    d_lam, d_x, d_u = sol.delta[:, n:n + m], sol.delta[:, :n], sol.delta[:, n + m:n + m + k]
    eta = d_x @ lcs.E.T + d_lam @ lcs.F.T + d_u @ lcs.H.T + lcs.c
    assert d_lam.min() >= -1e-9
    if proj == "c3plus":
        eta_copy = sol.delta[:, n + m + k:]
        assert eta_copy.min() >= 0.0 and np.abs(d_lam * eta_copy).max() == 0.0
    else:
        assert eta.min() >= -1e-9
        assert np.abs(d_lam * eta).max() <= (1e-9 if proj == "exact" else 1e-2)


@pytest.mark.parametrize("proj", ["c3plus", "qp", "exact"])
def test_ballroll_size_solver_plans_are_consistent(proj):
    """Ball-rolling-sized LCS (n 19, m 8, k 3), every projection: see _check_ballroll_plan."""
    lcs = random_ballroll_lcs(0)
    x0 = 0.05 * np.random.default_rng(1).normal(size=19)
    sol = C3Solver(ballroll_c3_options(proj)).solve(lcs, x0)
    assert sol.u0.shape == (3,)
    _check_ballroll_plan(sol, lcs, x0, proj)
    assert sum(sol.info["fallbacks"].values()) == 0


@pytest.mark.parametrize("proj", ["c3plus", "exact"])
def test_ballroll_plan_check_catches_broken_plans(proj):
    """The check fails on an unprojected delta (the QP iterate z) and on a plan whose
    states do not follow the dynamics."""
    import dataclasses
    lcs = random_ballroll_lcs(0)
    x0 = 0.05 * np.random.default_rng(1).normal(size=19)
    sol = C3Solver(ballroll_c3_options(proj)).solve(lcs, x0)
    with pytest.raises(AssertionError):
        _check_ballroll_plan(dataclasses.replace(sol, delta=sol.z), lcs, x0, proj)
    x_bad = sol.x_plan.copy()
    x_bad[2, 0] += 1e-6
    with pytest.raises(AssertionError):
        _check_ballroll_plan(dataclasses.replace(sol, x_plan=x_bad), lcs, x0, proj)


# --- options -----------------------------------------------------------------------

def test_options_from_dict():
    d = {"horizon": 10, "q_diag": [10, 3, 1, 1], "r_diag": [1], "g_diag": [0.1] * 6 + [0],
         "u_diag": [1000] * 4 + [1, 1, 0], "rho_scale": 2, "admm_iter": 10,
         "projection": "qp", "warm_start": False, "rate_hz": 80,
         "u_bounds": {"lower": [-20], "upper": [20]}}
    o = C3Options.from_dict(d)
    np.testing.assert_array_equal(o.Q, np.diag([10.0, 3, 1, 1]))
    np.testing.assert_array_equal(o.R, np.eye(1))
    assert o.horizon == 10 and o.projection == "qp" and o.warm_start is False
    assert o.QN is None and o.qp_backend == "auto"
    np.testing.assert_array_equal(o.u_bounds[0], [-20.0])
    o2 = C3Options.from_dict({**d, "qn_diag": [1, 2, 3, 4]})
    np.testing.assert_array_equal(o2.QN, np.diag([1.0, 2, 3, 4]))


def test_cartpole_reference_options_and_riccati():
    o = cartpole_c3_options()
    assert (o.horizon, o.admm_iter, o.rho_scale) == (10, 10, 2.0)
    np.testing.assert_array_equal(o.Q, np.diag([10.0, 3, 1, 1]))
    np.testing.assert_array_equal(o.G, [0.1, 0.1, 0.1, 0.1, 0.1, 0.1, 0.0])
    lcs = cartpole_lcs()
    P = C3Solver(o).terminal_weight(lcs)
    A, B, Q, R = lcs.A, lcs.B, o.Q, o.R
    resid = A.T @ P @ A - P - A.T @ P @ B @ np.linalg.solve(R + B.T @ P @ B, B.T @ P @ A) + Q
    assert np.abs(resid).max() < 1e-6 * np.abs(P).max()


GOOD = {"horizon": 10, "q_diag": [10, 3, 1, 1], "r_diag": [1], "g_diag": [0.1] * 6 + [0],
        "u_diag": [1000] * 4 + [1, 1, 0]}


@pytest.mark.parametrize("change", [
    {"horizon": 0}, {"horizon": 2.5}, {"horizon": "10"}, {"horizon": True},
    {"q_diag": [10, -3, 1, 1]}, {"r_diag": [0]}, {"r_diag": []}, {"q_diag": "abc"},
    {"g_diag": [0.1] * 6 + [-1]}, {"u_diag": [float("nan")] * 7}, {"g_diag": [0.1] * 4},
    {"rho_scale": 0.5}, {"rho_scale": float("inf")}, {"rho_scale": "2"},
    {"admm_iter": 0}, {"projection": "miqp"}, {"qp_backend": "gurobi"},
    {"warm_start": "yes"}, {"end_on_qp_step": 1}, {"qp_projection_alpha": 2.0},
    {"u_bounds": {"lower": [1], "upper": [-1]}}, {"u_bounds": [[-1, -1], [1, 1]]},
    {"x_bounds": {"low": [0] * 4}}, {"u_bounds": [[-1], [1]], "qp_backend": "kkt"},
    {"qn_diag": "lqr"}, {"unknown_key": 1},
])
def test_bad_options_raise_value_error(change):
    with pytest.raises(ValueError):
        C3Options.from_dict({**GOOD, **change})


def test_missing_keys_and_bad_solve_inputs_raise():
    for key in ("horizon", "q_diag", "g_diag"):
        with pytest.raises(ValueError):
            C3Options.from_dict({k: v for k, v in GOOD.items() if k != key})
    with pytest.raises(ValueError):
        C3Options.from_dict([1, 2])
    with pytest.raises(ValueError):
        C3Options(horizon=10, Q=np.eye(4), R=np.eye(1), G=np.ones((3, 7)), U=np.ones(7))
    solver = C3Solver(C3Options.from_dict(GOOD))
    lcs = cartpole_lcs()
    with pytest.raises(ValueError):
        solver.solve(lcs, [0.1, 0.2, 0.3])                  # wrong x0 size
    with pytest.raises(ValueError):
        solver.solve(lcs, [np.nan, 0, 0, 0])
    with pytest.raises(ValueError):
        solver.solve(lcs, np.zeros(4), x_target=np.zeros(3))
    bad_g = C3Solver(C3Options.from_dict({**GOOD, "g_diag": [0.1] * 8, "u_diag": [1] * 8}))
    with pytest.raises(ValueError):                       # 8 is neither n+m+k nor n+2m+k
        bad_g.solve(lcs, np.zeros(4))
    with pytest.raises(ValueError):                       # LCS sizes differ from options
        C3Solver(ballroll_c3_options()).solve(lcs, np.zeros(4))


def test_shift_knots_moves_a_trajectory_by_fractions_of_a_knot():
    from adaptive_c3.systems.c3.solver import shift_knots
    traj = np.arange(5.0)[:, None] * np.array([[1.0, 10.0]])      # row i = [i, 10 i]
    np.testing.assert_allclose(shift_knots(traj, 1.0)[:, 0], [1, 2, 3, 4, 4])
    np.testing.assert_allclose(shift_knots(traj, 0.25)[:, 0], [0.25, 1.25, 2.25, 3.25, 4])
    np.testing.assert_allclose(shift_knots(traj, 0.0), traj)
    np.testing.assert_allclose(shift_knots(traj, 7.0)[:, 1], [40] * 5)
    with pytest.raises(ValueError):
        shift_knots(traj, -0.1)


# --- C3+ as DAIRLab/c3's C3Plus ------------------------------------------------------

def test_c3plus_reference_mode_stabilises_the_cartpole():
    xs, touched = _closed_loop(cartpole_c3_options(c3plus_reference=True), X0S[0])
    assert touched
    _assert_stabilised(xs)


def test_c3plus_reference_mode_ignores_g_on_x_and_u_and_ends_on_delta():
    """Reference mode: the plan does not change when G's x, u entries change (they are
    not used), and the final QP tracks delta (so its lam is closer to delta's than the
    default's final QP, which tracks delta - w, is to its own delta)."""
    lcs = cartpole_lcs()
    x0 = np.array(X0S[0])
    base = dict(warm_start=False, c3plus_reference=True)
    a = C3Solver(cartpole_c3_options(**base)).solve(lcs, x0)
    g_other = np.r_[5.0 * np.ones(4), 0.1 * np.ones(2), 3.0]
    b = C3Solver(cartpole_c3_options(G=g_other, **base)).solve(lcs, x0)
    np.testing.assert_array_equal(a.u_plan, b.u_plan)
    default = C3Solver(cartpole_c3_options(G=g_other, warm_start=False)).solve(lcs, x0)
    assert np.abs(default.u_plan - a.u_plan).max() > 1e-6       # the default does use G
    n, m = 4, 2
    gap_ref = np.abs(a.lam_plan - a.delta[:, n:n + m]).max()
    gap_def = np.abs(default.lam_plan - default.delta[:, n:n + m]).max()
    assert gap_ref < gap_def


def test_bench_rows_on_the_real_ball_model_lcs():
    """The c3/ballroll_model rows solve on the controller model's Anitescu LCSs (n 19,
    m 8, k 3), with the shipped roll-phase options, without fall-backs."""
    from adaptive_c3.tools.bench.c3_ball_model import ball_model_problems, run_ball_model_rows
    problems, options = ball_model_problems(2)
    for lcs, x, xt in problems:
        assert (lcs.num_states, lcs.num_lambda, lcs.num_inputs) == (19, 8, 3)
        assert lcs.dt == pytest.approx(0.1)
        sol = C3Solver(options).solve(lcs, x, xt)
        _check_ballroll_plan(sol, lcs, x, "c3plus")
    from adaptive_c3.tools.bench.c3 import FreshMathProgC3
    rows = {r["name"]: r for r in run_ball_model_rows(FreshMathProgC3, quick=True)}
    ours = rows["c3/ballroll_model/c3plus/kkt"]
    assert ours["baseline"] in rows and ours["solves"] == 8
    assert sum(ours["fallbacks"].values()) == 0
