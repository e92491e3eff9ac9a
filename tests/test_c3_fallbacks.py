"""C3's fall-backs are counted, never silent (systems/c3/solver.py FALLBACKS): each
counter is made to fire by a deliberately broken or ill-conditioned input."""
import numpy as np

from adaptive_c3.models.cartpole import cartpole_lcs
from adaptive_c3.systems.c3.projection import QpProjector
from adaptive_c3.systems.c3.options import cartpole_c3_options
from adaptive_c3.systems.c3.solver import FALLBACKS, C3Solver
from adaptive_c3.systems.contact.lcs import Lcs

X0 = np.array([0.1, -0.3, 0.0, 0.0])


def _with_wall_lcp(F, c):
    """The cart-pole LCS with its wall LCP replaced by (F, c) and E = 0, so the lam_0
    LCP at any x0 is LCP(F, c)."""
    p = cartpole_lcs()
    return Lcs(A=p.A, B=p.B, D=p.D, d=p.d, E=np.zeros_like(p.E), F=np.asarray(F, float),
               H=p.H, c=np.asarray(c, float), dt=p.dt)


def _only(events, key, at_least=1):
    assert events[key] >= at_least, events
    assert all(v == 0 for k, v in events.items() if k != key), events


def test_no_fallbacks_on_the_reference_problem():
    for projection in ("c3plus", "qp", "exact"):
        solver = C3Solver(cartpole_c3_options(projection))
        sol = solver.solve(cartpole_lcs(), X0)
        assert set(sol.info["fallbacks"]) == set(FALLBACKS)
        assert sum(sol.info["fallbacks"].values()) == 0
        assert sol.lam0_fixed


def test_unsolvable_lam0_lcp_is_counted():
    """LCP(F, c) with F = [[1, -1], [-1, 1]], c = [-1, -1] has no solution: lam_0 is left
    free, and the solve says so."""
    lcs = _with_wall_lcp([[1.0, -1.0], [-1.0, 1.0]], [-1.0, -1.0])
    solver = C3Solver(cartpole_c3_options())
    sol = solver.solve(lcs, X0)
    assert not sol.lam0_fixed
    _only(sol.info["fallbacks"], "lam0_lcp_failed")
    solver.solve(lcs, X0)
    assert solver.fallbacks["lam0_lcp_failed"] == 2            # totals accumulate


def _lemke_breaking_lcp():
    """The first of the nearly singular PD problems of tests/test_lcp.py (F = J J' +
    1e-9 I, cond ~1e10, m = 8) on which plain Lemke fails."""
    from adaptive_c3.systems.contact.lcp import solve_lcp
    from tests.test_lcp import _nearly_singular_pd
    rng = np.random.default_rng(0)
    for _ in range(300):
        F, c = _nearly_singular_pd(rng)
        if not solve_lcp(F, c, regularize=False).solved:
            return F, c
    raise AssertionError("no problem breaks plain Lemke any more")


def test_regularised_lam0_lcp_is_counted():
    """lam_0's LCP is one on which plain Lemke fails: the regularised retry solves it
    and the solve counts it."""
    F, c = _lemke_breaking_lcp()
    p = cartpole_lcs()
    lcs = Lcs(A=p.A, B=p.B, D=np.zeros((4, 8)), d=p.d, E=np.zeros((8, 4)), F=F,
              H=np.zeros((8, 1)), c=c, dt=p.dt)
    opts = cartpole_c3_options(G=np.r_[0.1 * np.ones(12), 0.0], U=np.r_[1000.0 * np.ones(4),
                                                                     np.ones(8), 0.0])
    sol = C3Solver(opts).solve(lcs, X0)
    assert sol.lam0_fixed
    _only(sol.info["fallbacks"], "lam0_lcp_regularized")


def test_unrefined_osqp_qp_step_is_counted():
    """Input bounds select the OSQP back-end; with zero refinement iterations allowed its
    exact refinement cannot succeed, so OSQP's loose answer is used - and counted."""
    solver = C3Solver(cartpole_c3_options(u_bounds=([-5.0], [5.0])))
    solver.solve(cartpole_lcs(), X0)
    assert solver.fallbacks["qp_unrefined"] == 0
    solver._osqp.refine_iter = 0
    sol = solver.solve(cartpole_lcs(), X0)
    # one QP step per ADMM iteration plus the final one
    _only(sol.info["fallbacks"], "qp_unrefined", at_least=solver.options.admm_iter + 1)


def test_qp_projection_iteration_limit_and_unrefined_iterate_are_counted():
    """A QP projection whose OSQP may run 1 iteration and whose refinement none."""
    solver = C3Solver(cartpole_c3_options("qp"))
    solver._qp_proj = QpProjector(solver.options.qp_projection_alpha, max_iter=1,
                                  refine_iter=0)
    sol = solver.solve(cartpole_lcs(), X0)
    ev = sol.info["fallbacks"]
    assert ev["projection_iter_limit"] == solver.options.admm_iter
    assert ev["projection_unrefined"] >= 1
    assert ev["qp_unrefined"] == ev["lam0_lcp_failed"] == ev["lam0_lcp_regularized"] == 0


def test_qp_projection_iteration_limit_alone_is_repaired():
    """With its refinement intact, the 1-iteration OSQP projection is still made exact:
    the limit is counted, no unrefined iterate is returned."""
    proj = QpProjector(0.01, max_iter=1)
    ref = QpProjector(0.01)
    lcs = cartpole_lcs()
    N, n, m, k = 3, 4, 2, 1
    E, F, H, c = (np.broadcast_to(a, (N,) + a.shape) for a in (lcs.E, lcs.F, lcs.H, lcs.c))
    U = np.ones((N, n + m + k))
    y = np.random.default_rng(0).normal(size=(N, n + m + k))
    got = proj.setup(E, F, H, c, U).project(y)
    want = ref.setup(E, F, H, c, U).project(y)
    assert proj.iteration_limits == 1 and proj.refine_failures == 0
    np.testing.assert_allclose(got, want, atol=1e-8)


def test_controller_surfaces_the_counts():
    from adaptive_c3.systems.c3.controller import C3Controller
    ctrl = C3Controller(cartpole_c3_options(), 4, 1, 2)
    assert ctrl.fallback_counts() == {**dict.fromkeys(FALLBACKS, 0), "rejected": 0}
    ctrl.solver.solve(_with_wall_lcp([[1.0, -1.0], [-1.0, 1.0]], [-1.0, -1.0]), X0)
    assert ctrl.fallback_counts()["lam0_lcp_failed"] == 1
