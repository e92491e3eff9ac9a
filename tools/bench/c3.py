"""`adaptive-c3 bench c3`: C3 solve times and closed-loop costs against two baselines.

Rows (median_ms over repeated solves; closed_loop_cost where a closed loop is run):
  c3/cartpole/{c3plus,qp,exact}/kkt, c3/cartpole/c3plus/osqp  - this project's C3
  c3/cartpole/baseline_fresh_mathprog  - the same ADMM, a fresh Drake MathematicalProgram
        solved by OsqpSolver for every QP step and every (QP-)projection
  c3/cartpole/ipopt_relaxed  - contact-implicit MPC with lam.eta <= s, s driven down over
        a few IPOPT solves per step (the smoothing approach)
  c3/ballroll/...  - a seeded random LCS of the ball-rolling size (n=19, m=8, k=3, N=5)
  c3/ballroll_model/...  - the ball-rolling model's own LCSs (tools/bench/c3_ball_model.py)
Closed-loop cost = sum_t dt (x'Qx + u'Ru) of the true LCS under the controller.
"""
from __future__ import annotations

import logging
import os
import platform
import time

import numpy as np
import scipy.linalg

from adaptive_c3.models.cartpole import cartpole_lcs
from adaptive_c3.systems.c3.options import C3Options, cartpole_c3_options
from adaptive_c3.systems.c3.solver import C3Solver
from adaptive_c3.systems.c3.projection import project_c3plus
from adaptive_c3.systems.c3.qp import silenced_c_stdout
from adaptive_c3.systems.contact.lcp import solve_lcp
from adaptive_c3.systems.contact.lcs import Lcs, as_sequence

__all__ = ["random_ballroll_lcs", "ballroll_c3_options", "FreshMathProgC3",
           "IpoptRelaxedMpc", "run_bench", "machine_info", "format_table"]

CARTPOLE_X0 = (0.1, -0.3, 0.0, 0.0)


def random_ballroll_lcs(seed: int = 0, n: int = 19, m: int = 8, k: int = 3,
                        dt: float = 0.1) -> Lcs:
    """A random but realistic LCS of the ball-rolling size (seeded).

    A = expm(dt (S - 0.5 I)) with S skew (stable, near identity), B ~ dt N(0, 1),
    E ~ N(0, 0.25), D = dt M E' with M = K K'/n + 0.1 I an inverse-mass-like PD matrix,
    so that E D is PSD (contact forces open the gaps they act on, as in a mechanical
    LCS; independent random D and E can pump energy and make any controller diverge),
    F = 0.1 L L' + 1e-3 I (PSD + eps I, as Anitescu's), c ~ U(-0.05, 0.1) so that
    some contacts are active near the origin.
    """
    rng = np.random.default_rng(seed)
    S = 0.3 * rng.normal(size=(n, n))
    A = scipy.linalg.expm(dt * (S - S.T - 0.5 * np.eye(n)))
    B = dt * rng.normal(size=(n, k))
    E = 0.5 * rng.normal(size=(m, n))
    K = rng.normal(size=(n, n))
    D = dt * (K @ K.T / n + 0.1 * np.eye(n)) @ E.T
    d = 1e-4 * rng.normal(size=n)
    L = rng.normal(size=(m, m))
    F = 0.1 * L @ L.T + 1e-3 * np.eye(m)
    H = 0.1 * rng.normal(size=(m, k))
    c = rng.uniform(-0.05, 0.1, size=m)
    return Lcs(A=A, B=B, D=D, d=d, E=E, F=F, H=H, c=c, dt=dt)


def ballroll_c3_options(projection: str = "c3plus", **overrides) -> C3Options:
    """The reference ball-rolling weights on the 19-state layout (N=5, G=0.001, U=1/100)."""
    q = np.r_[[500.0] * 3, [0.0] * 4, [5000.0, 5000.0, 1000.0], [10.0] * 3, [0.1] * 6]
    kw = dict(horizon=5, Q=np.diag(q), R=0.01 * np.eye(3), G=0.001 * np.ones(30),
              U=np.r_[100.0 * np.ones(19), np.ones(11)], rho_scale=2.0, admm_iter=10,
              projection=projection)
    kw.update(overrides)
    return C3Options(**kw)


# --- baselines ----------------------------------------------------------------------

class FreshMathProgC3:
    """The same ADMM built the straightforward Drake way: a new MathematicalProgram per
    QP step (and per knot for the QP projection), each solved by OsqpSolver."""

    def __init__(self, options: C3Options):
        from pydrake.solvers import OsqpSolver
        self.options = options
        self._osqp = OsqpSolver()
        self._helper = C3Solver(options)   # for weights / terminal cost only

    def _qp_step(self, seq, x0, xt, Qs, G, a, lam0, eta):
        from pydrake.solvers import MathematicalProgram
        o = self.options
        N = o.horizon
        n, k, m = seq[0].num_states, seq[0].num_inputs, seq[0].num_lambda
        prog = MathematicalProgram()
        x = [prog.NewContinuousVariables(n, f"x{j}") for j in range(N + 1)]
        lam = [prog.NewContinuousVariables(m, f"l{j}") for j in range(N)]
        u = [prog.NewContinuousVariables(k, f"u{j}") for j in range(N)]
        et = [prog.NewContinuousVariables(m, f"e{j}") for j in range(N)] if eta else []
        prog.AddLinearEqualityConstraint(np.eye(n), x0, x[0])
        if lam0 is not None:
            prog.AddLinearEqualityConstraint(np.eye(m), lam0, lam[0])
        for j, s in enumerate(seq):
            prog.AddLinearEqualityConstraint(np.hstack([s.A, s.D, s.B, -np.eye(n)]), -s.d,
                                             np.concatenate([x[j], lam[j], u[j], x[j + 1]]))
            if eta:
                prog.AddLinearEqualityConstraint(np.hstack([s.E, s.F, s.H, -np.eye(m)]), -s.c,
                                                 np.concatenate([x[j], lam[j], u[j], et[j]]))
        for j in range(N + 1):
            prog.AddQuadraticCost(2 * Qs[j], -2 * Qs[j] @ xt[j], x[j], is_convex=True)
        for j in range(N):
            prog.AddQuadraticCost(2 * o.R, np.zeros(k), u[j], is_convex=True)
            zj = np.concatenate([x[j], lam[j], u[j]] + ([et[j]] if eta else []))
            prog.AddQuadraticCost(2 * np.diag(G[j]), -2 * G[j] * a[j], zj, is_convex=True)
        res = self._osqp.Solve(prog)
        z = np.array([res.GetSolution(np.concatenate([x[j], lam[j], u[j]] +
                                                     ([et[j]] if eta else [])))
                      for j in range(N)])
        return z

    def _qp_projection(self, s, y, U, n, m, k):
        """The reference library's C3QP::SolveSingleProjection with a fresh program."""
        from pydrake.solvers import MathematicalProgram
        prog = MathematicalProgram()
        v = prog.NewContinuousVariables(n + m + k, "d")
        alpha = self.options.qp_projection_alpha
        prog.AddLinearConstraint(np.hstack([s.E, s.F, s.H]), -s.c, np.full(m, np.inf), v)
        prog.AddBoundingBoxConstraint(0, np.inf, v[n:n + m])
        Fs = 0.5 * (s.F + s.F.T)
        Ut = np.diag(U)
        Ut[n:n + m, n:n + m] = alpha * Fs
        prog.AddQuadraticCost(Ut, -Ut @ y, v, is_convex=True)
        prog.AddQuadraticCost((1 - alpha) * Fs, np.zeros(m), v[n:n + m], is_convex=True)
        return self._osqp.Solve(prog).GetSolution(v)

    def solve(self, lcs, x0, x_target=None) -> np.ndarray:
        """Returns u0 (same ADMM, end on a QP step, cold start)."""
        with silenced_c_stdout():      # Drake's OSQP polishing prints
            return self._solve(lcs, x0, x_target)

    def _solve(self, lcs, x0, x_target):
        o = self.options
        N = o.horizon
        seq = as_sequence(lcs, N)
        s0 = seq[0]
        n, k, m = s0.num_states, s0.num_inputs, s0.num_lambda
        h = self._helper
        G, U = h.weights(s0)
        eta = o.projection == "c3plus"
        Qs = np.array([o.Q] * N + [h.terminal_weight(s0)])
        xt = np.zeros((N + 1, n)) if x_target is None else np.broadcast_to(x_target, (N + 1, n))
        lam0 = None
        if o.fix_initial_force and not np.any(s0.H):
            r = solve_lcp(s0.F, s0.E @ x0 + s0.c)
            lam0 = r.z if r.solved else None
        delta = np.zeros((N, G.shape[1]))
        delta[:, :n] = x0
        w = np.zeros_like(delta)
        scale = 1.0
        for _ in range(o.admm_iter):
            z = self._qp_step(seq, x0, xt, Qs, scale * G, delta - w, lam0, eta)
            if eta:
                delta = project_c3plus(z + w, n, m, k, U[:, n:n + m], U[:, n + m + k:])
            else:
                delta = np.array([self._qp_projection(seq[j], z[j] + w[j], U[j], n, m, k)
                                  for j in range(N)])
            w = (w + z - delta) / o.rho_scale
            scale *= o.rho_scale
        z = self._qp_step(seq, x0, xt, Qs, scale * G, delta - w, lam0, eta)
        return z[0, n + m:n + m + k]


class IpoptRelaxedMpc:
    """Contact-implicit MPC with relaxed complementarity, solved by Drake's IPOPT.

    Variables x, lam, u, eta over the horizon; LCS dynamics, eta = Ex+F lam+Hu+c,
    lam >= 0, eta >= 0 and lam_i eta_i <= s; s is driven down over `schedule`, each
    solve warm-started from the previous one (the first from the last MPC solution).
    """

    def __init__(self, horizon, Q, R, QN, schedule=(1e-2, 1e-3, 1e-4)):
        from pydrake.solvers import IpoptSolver, SolverOptions
        self.N, self.Q, self.R, self.QN = horizon, Q, R, QN
        self.schedule = tuple(schedule)
        self._ipopt = IpoptSolver()
        self._opts = SolverOptions()
        for name, val in (("print_level", 0), ("tol", 1e-6), ("max_iter", 300)):
            self._opts.SetOption(IpoptSolver.id(), name, val)
        self._guess = None
        self.failures = 0

    def solve(self, lcs: Lcs, x0, x_target=None) -> np.ndarray:
        from pydrake.solvers import MathematicalProgram
        N, n, k, m = self.N, lcs.num_states, lcs.num_inputs, lcs.num_lambda
        xt = np.zeros(n) if x_target is None else np.asarray(x_target, float)
        prog = MathematicalProgram()
        x = prog.NewContinuousVariables(N + 1, n, "x")
        lam = prog.NewContinuousVariables(N, m, "l")
        u = prog.NewContinuousVariables(N, k, "u")
        eta = prog.NewContinuousVariables(N, m, "e")
        prog.AddLinearEqualityConstraint(np.eye(n), x0, x[0])
        sigma = prog.NewContinuousVariables(1, "s")      # the relaxation level, fixed
        fix = prog.AddLinearEqualityConstraint(np.eye(1), [self.schedule[0]], sigma)
        Qb = np.zeros((3, 3))
        Qb[0, 1] = Qb[1, 0] = 1.0                        # lam_i eta_i - s <= 0
        for j in range(N):
            prog.AddLinearEqualityConstraint(
                np.hstack([lcs.A, lcs.D, lcs.B, -np.eye(n)]), -lcs.d,
                np.concatenate([x[j], lam[j], u[j], x[j + 1]]))
            prog.AddLinearEqualityConstraint(
                np.hstack([lcs.E, lcs.F, lcs.H, -np.eye(m)]), -lcs.c,
                np.concatenate([x[j], lam[j], u[j], eta[j]]))
            prog.AddBoundingBoxConstraint(0, np.inf, lam[j])
            prog.AddBoundingBoxConstraint(0, np.inf, eta[j])
            for i in range(m):
                prog.AddQuadraticConstraint(Qb, np.array([0.0, 0.0, -1.0]), -np.inf, 0.0,
                                            np.array([lam[j, i], eta[j, i], sigma[0]]))
            prog.AddQuadraticCost(2 * self.Q, -2 * self.Q @ xt, x[j], is_convex=True)
            prog.AddQuadraticCost(2 * self.R, np.zeros(k), u[j], is_convex=True)
        prog.AddQuadraticCost(2 * self.QN, -2 * self.QN @ xt, x[N], is_convex=True)
        all_vars = prog.decision_variables()
        guess = self._guess if self._guess is not None and self._guess.size == all_vars.size \
            else np.zeros(all_vars.size)
        result = None
        for s in self.schedule:
            fix.evaluator().UpdateCoefficients(np.eye(1), [s])
            result = self._ipopt.Solve(prog, guess, self._opts)
            if not result.is_success():
                self.failures += 1
            guess = result.GetSolution(all_vars)
        self._guess = guess
        return result.GetSolution(u[0])


# --- harness ------------------------------------------------------------------------

def closed_loop(lcs: Lcs, policy, x0, steps: int, Q, R) -> dict:
    """Run the true LCS under policy(x) -> (u, solve_s); returns cost and timings."""
    x = np.asarray(x0, float)
    cost, times, touched, xs = 0.0, [], False, [x]
    for _ in range(steps):
        u, dt_s = policy(x)
        times.append(dt_s)
        cost += lcs.dt * float(x @ Q @ x + u @ R @ u)
        x, lam = lcs.step(x, u)
        touched |= bool(np.any(lam > 1e-9))
        xs.append(x)
        if not np.all(np.abs(x) < 1e6):
            return {"cost": float("inf"), "times": times, "touched": touched,
                    "x_final": x, "diverged": True}
    return {"cost": cost, "times": times, "touched": touched, "x_final": x,
            "diverged": False, "xs": np.array(xs)}


def _timed(fn):
    def policy(x):
        t0 = time.perf_counter()
        u = fn(x)
        return np.asarray(u, float), time.perf_counter() - t0
    return policy


def _row(name, times, **extra):
    t = np.asarray(times, float) * 1e3
    row = {"name": name, "median_ms": float(np.median(t)), "p90_ms": float(np.percentile(t, 90)),
           "max_ms": float(t.max()), "solves": int(t.size)}
    row.update(extra)
    return row


def _c3_policy(options, lcs):
    solver = C3Solver(options)
    return _timed(lambda x: solver.solve(lcs, x).u0)


def run_bench(quick: bool = False) -> list[dict]:
    """All C3 rows; quick=True shortens the closed loops (whole bench < ~30 s)."""
    rows = []
    # --- cart-pole -------------------------------------------------------------
    cp = cartpole_lcs()
    opts = cartpole_c3_options()
    Q, R = opts.Q, opts.R
    steps = 300 if quick else 800
    cl_note = f"{steps * cp.dt:g} s from x0={list(CARTPOLE_X0)}"
    for proj, backend in (("c3plus", "kkt"), ("qp", "kkt"), ("exact", "kkt"),
                          ("c3plus", "osqp")):
        o = cartpole_c3_options(proj, qp_backend=backend)
        r = closed_loop(cp, _c3_policy(o, cp), CARTPOLE_X0, steps, Q, R)
        rows.append(_row(f"c3/cartpole/{proj}/{backend}", r["times"],
                         closed_loop_cost=r["cost"], closed_loop=cl_note,
                         touched_wall=r["touched"],
                         final_abs_max=float(np.abs(r["x_final"]).max())))
    c3_cost = rows[0]["closed_loop_cost"]
    fresh = FreshMathProgC3(cartpole_c3_options("qp"))
    xs = closed_loop(cp, _c3_policy(opts, cp), CARTPOLE_X0, 100, Q, R)["xs"]
    reps = 5 if quick else 20
    times = []
    for x in xs[np.linspace(0, len(xs) - 1, reps).astype(int)]:
        t0 = time.perf_counter()
        fresh.solve(cp, x)
        times.append(time.perf_counter() - t0)
    rows.append(_row("c3/cartpole/baseline_fresh_mathprog", times,
                     note="qp projection; closed loop not run (same math as c3/cartpole/qp/kkt)"))
    QN = C3Solver(opts).terminal_weight(cp)
    ip = IpoptRelaxedMpc(opts.horizon, Q, R, QN)
    ip_steps = 100 if quick else 300        # IPOPT needs 40 ms .. 1 s per step
    drake_log = logging.getLogger("drake")  # IPOPT iteration-limit warnings are counted
    previous = drake_log.level
    drake_log.setLevel(logging.ERROR)
    try:
        r = closed_loop(cp, _timed(lambda x: ip.solve(cp, x)), CARTPOLE_X0, ip_steps, Q, R)
    finally:
        drake_log.setLevel(previous)
    c3_same = closed_loop(cp, _c3_policy(opts, cp), CARTPOLE_X0, ip_steps, Q, R)["cost"]
    rows.append(_row("c3/cartpole/ipopt_relaxed", r["times"], closed_loop_cost=r["cost"],
                     closed_loop=f"{ip_steps * cp.dt:g} s from x0={list(CARTPOLE_X0)}",
                     c3plus_closed_loop_cost_same_window=c3_same,
                     cost_ratio_vs_c3plus=r["cost"] / c3_same if c3_same else None,
                     ipopt_failures=ip.failures, touched_wall=r["touched"]))
    for row in rows[:4]:
        row["closed_loop_cost_ratio_vs_c3plus_kkt"] = row["closed_loop_cost"] / c3_cost
    base = next(r for r in rows if r["name"] == "c3/cartpole/baseline_fresh_mathprog")
    for row in rows[:4]:
        row["baseline"] = base["name"]
        row["speedup"] = base["median_ms"] / row["median_ms"]

    # --- ball-rolling-size random LCS -------------------------------------------
    lcs = random_ballroll_lcs(0)
    bo = ballroll_c3_options()
    rng = np.random.default_rng(1)
    x0 = 0.05 * rng.normal(size=19)
    bsteps = 40 if quick else 100
    brows = {}
    bounds = dict(u_bounds=(-np.ones(3), np.ones(3)), x_bounds=(-np.ones(19), np.ones(19)))
    variants = [("c3plus/kkt", {}), ("qp/osqp", dict(projection="qp", qp_backend="osqp")),
                ("qp/kkt", dict(projection="qp")),
                ("c3plus/osqp", dict(qp_backend="osqp")),
                ("c3plus/osqp_sparse", dict(qp_backend="osqp_sparse")),
                ("c3plus/drake_osqp", dict(qp_backend="drake_osqp")),
                ("c3plus/osqp_bounds", dict(qp_backend="osqp", **bounds))]
    for name, kw in variants:
        o = ballroll_c3_options(**kw)
        n_steps = bsteps
        r = closed_loop(lcs, _c3_policy(o, lcs), x0, n_steps, bo.Q, bo.R)
        brows[name] = _row(f"c3/ballroll/{name}", r["times"], closed_loop_cost=r["cost"],
                           closed_loop=f"{n_steps} steps of 0.1 s, seeded x0",
                           touched=r["touched"])
    xs = closed_loop(lcs, _c3_policy(bo, lcs), x0, 20, bo.Q, bo.R)["xs"]
    reps = 5 if quick else 15
    for label, proj in (("baseline_fresh_mathprog", "qp"),
                        ("baseline_fresh_mathprog_c3plus", "c3plus")):
        fr = FreshMathProgC3(ballroll_c3_options(proj))
        times = []
        for x in xs[np.linspace(0, len(xs) - 1, reps).astype(int)]:
            t0 = time.perf_counter()
            fr.solve(lcs, x)
            times.append(time.perf_counter() - t0)
        brows[label] = _row(f"c3/ballroll/{label}", times,
                            note=f"{proj} projection, fresh MathematicalProgram + OsqpSolver")
    base = brows["baseline_fresh_mathprog"]
    for name, row in brows.items():
        if not name.startswith("baseline"):
            row["baseline"] = base["name"]
            row["speedup"] = base["median_ms"] / row["median_ms"]
    k = brows["c3plus/kkt"]
    k["speedup_vs_fresh_mathprog_c3plus"] = (brows["baseline_fresh_mathprog_c3plus"]["median_ms"]
                                             / k["median_ms"])
    k["target_median_ms"] = 2.0
    k["meets_target"] = bool(k["median_ms"] <= 2.0 and k["speedup"] >= 10.0)
    rows.extend(brows.values())
    from adaptive_c3.tools.bench.c3_ball_model import run_ball_model_rows
    rows.extend(run_ball_model_rows(FreshMathProgC3, quick))   # the real ball-model LCSs
    return rows


def machine_info() -> dict:
    import importlib.metadata

    import numpy
    try:
        drake_version = importlib.metadata.version("drake")
    except importlib.metadata.PackageNotFoundError:  # pragma: no cover
        drake_version = None
    return {"platform": platform.platform(), "python": platform.python_version(),
            "cpu_count": os.cpu_count(), "numpy": numpy.__version__, "drake": drake_version,
            "openblas_num_threads": os.environ.get("OPENBLAS_NUM_THREADS")}


def format_table(rows: list[dict]) -> str:
    lines = [f"{'name':44s} {'median_ms':>10s} {'speedup':>8s} {'cl_cost':>10s}"]
    for r in rows:
        sp = f"{r['speedup']:.1f}x" if r.get("speedup") else ""
        cc = f"{r['closed_loop_cost']:.4g}" if r.get("closed_loop_cost") is not None else ""
        lines.append(f"{r['name']:44s} {r['median_ms']:10.3f} {sp:>8s} {cc:>10s}")
    return "\n".join(lines)


if __name__ == "__main__":  # pragma: no cover
    import sys
    print(format_table(run_bench(quick="--quick" in sys.argv)))
