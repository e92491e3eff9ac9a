"""C3 (consensus complementarity control): ADMM contact-implicit MPC on an LCS.

Per solve from x0, with z_j = [x_j, lam_j, u_j] (C3+ adds eta_j = E x_j + F lam_j +
H u_j + c), its projected copy delta_j and the scaled dual w_j, repeat `admm_iter` times:

  1. QP step: minimise sum (x - x_target)'Q(x - x_target) + u'Ru + (z - delta + w)'G(z - delta + w)
     subject to the LCS dynamics only (systems/c3/qp.py);
  2. projection: delta_j = Proj_U(z_j + w_j) onto the complementarity set of knot j
     (systems/c3/projection.py: C3+, the convex QP projection, or the exact one);
  3. w <- w + z - delta, then G <- rho_scale G and w <- w / rho_scale.

Like the reference library (DAIRLab/c3 `C3::Solve`, and the ICRA 2024 authors' dairlib
`C3::Solve`), a final QP step with the last delta - w and G follows the loop, and the
plan (u0, x, lam, u) is that QP's solution (`end_on_qp_step=True`, the reference
cart-pole setting). With `end_on_qp_step=False` the plan is the projected delta
trajectory (lam, u from delta, x rolled out through the LCS dynamics).
Also as in the reference: when H_0 = 0 the initial force lam_0 does not depend on the
input, so it is fixed to the LCP solution at x0 (`fix_initial_force`).

`c3plus_reference=True` makes C3+ behave as DAIRLab/c3's `C3Plus`: the consensus cost
G acts on lam and eta only (its x and u entries are ignored), and the final QP step's
target is delta itself instead of delta - w. The default (False) keeps G on all of z
and the final target delta - w, as for the other projections.

Fall-backs are never silent: every solve reports in `C3Solution.info["fallbacks"]` (and
adds to `C3Solver.fallbacks`, the totals since construction) how often
  qp_unrefined             the OSQP QP step's exact refinement failed (OSQP's eps answer used),
  projection_iter_limit    the QP projection's OSQP stopped at its iteration limit,
  projection_unrefined     a knot's QP projection was not refined (OSQP's iterate used),
  lam0_lcp_failed          the LCP for lam_0 was not solved (lam_0 left free),
  lam0_lcp_regularized     that LCP needed Lemke's regularised retry (systems/contact/lcp.py).
"""
from __future__ import annotations

import time
import warnings
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg

from adaptive_c3.systems.c3.options import C3Options
from adaptive_c3.systems.c3.projection import ExactProjector, QpProjector, project_c3plus
from adaptive_c3.systems.c3.qp import KktQp, OsqpQp, QpStepData
from adaptive_c3.systems.c3.qp_sparse import DrakeOsqpQp, OsqpSparseQp
from adaptive_c3.systems.contact.lcp import solve_lcp
from adaptive_c3.systems.contact.lcs import Lcs, LcsSequence, as_sequence

__all__ = ["C3Solution", "C3Solver", "FALLBACKS"]

FALLBACKS = ("qp_unrefined", "projection_iter_limit", "projection_unrefined",
             "lam0_lcp_failed", "lam0_lcp_regularized")


def shift_knots(traj: np.ndarray, shift: float) -> np.ndarray:
    """traj [N, ...] advanced by `shift` knots: row i is traj at i + shift, linearly
    interpolated between knots and held at the last one."""
    if not (np.isfinite(shift) and shift >= 0):
        raise ValueError(f"shift must be finite and >= 0, got {shift}")
    N = traj.shape[0]
    pos = np.minimum(np.arange(N) + shift, N - 1)
    lo = np.floor(pos).astype(int)
    hi = np.minimum(lo + 1, N - 1)
    a = (pos - lo).reshape((N,) + (1,) * (traj.ndim - 1))
    return (1.0 - a) * traj[lo] + a * traj[hi]


@dataclass(frozen=True)
class C3Solution:
    """One C3 solve. Units are those of the LCS (x, lam, u)."""

    u0: np.ndarray            # [k] first input of the plan
    x_plan: np.ndarray        # [N+1, n]
    lam_plan: np.ndarray      # [N, m]
    u_plan: np.ndarray        # [N, k]
    delta: np.ndarray         # [N, nz] last projected copy (nz includes eta for C3+)
    w: np.ndarray             # [N, nz] last scaled dual
    z: np.ndarray             # [N, nz] last QP-step solution
    iterations: int           # ADMM iterations run
    primal_residual: float    # ||z - delta|| of the last ADMM iteration
    dual_residual: float      # ||G (delta - delta_prev)|| of the last ADMM iteration
    solve_time_s: float       # wall time of the solve, s
    lam0_fixed: bool = False  # lam_0 fixed to the LCP solution at x0 (H_0 = 0)
    info: dict = field(default_factory=dict)


def _same_systems(a, b) -> bool:
    return a is not None and len(a) == len(b) and all(x is y for x, y in zip(a, b))


class C3Solver:
    """C3 solver (pure numpy/scipy/osqp); keeps its last solution for warm starts."""

    def __init__(self, options: C3Options):
        if not isinstance(options, C3Options):
            raise ValueError("C3Solver needs a C3Options")
        self.options = options
        self.last_solution: C3Solution | None = None
        self._qn_cache = None          # (A, B, QN)
        self._osqp = None
        self._drake = None
        self._qp_proj = None
        self._proj_key = None
        self._exact: dict = {}
        self.fallbacks = dict.fromkeys(FALLBACKS, 0)

    def reset(self):
        """Forget the warm start."""
        self.last_solution = None

    # --- helpers ---------------------------------------------------------------
    def terminal_weight(self, lcs: Lcs) -> np.ndarray:
        """Q_N: options.QN, or the (cached) discrete Riccati solution for lcs's A, B."""
        o = self.options
        if o.QN is not None:
            return o.QN
        c = self._qn_cache
        if c is not None and np.array_equal(c[0], lcs.A) and np.array_equal(c[1], lcs.B):
            return c[2]
        try:
            QN = scipy.linalg.solve_discrete_are(lcs.A, lcs.B, o.Q, o.R)
            if not np.isfinite(QN).all():
                raise np.linalg.LinAlgError("non-finite Riccati solution")
            QN = 0.5 * (QN + QN.T)
        except (np.linalg.LinAlgError, ValueError) as exc:
            warnings.warn(f"C3: discrete Riccati equation failed ({exc}); using QN = Q")
            QN = o.Q
        self._qn_cache = (lcs.A, lcs.B, QN)
        return QN

    def weights(self, lcs: Lcs) -> tuple[np.ndarray, np.ndarray]:
        """The per-knot diagonals (G [N, nz], U [N, nz]) used with this LCS (first knot's
        F scales the default eta weights of C3+, see C3Options)."""
        o = self.options
        n, k, m = lcs.num_states, lcs.num_inputs, lcs.num_lambda
        f_diag = np.abs(np.diag(lcs.F))
        eta_scale2 = (1.0 / np.maximum(f_diag, max(1e-3 * f_diag.max(), 1e-12))) ** 2
        out = []
        for name, W in (("G", o.G), ("U", o.U)):
            W = np.broadcast_to(W, (o.horizon, W.shape[-1])) if W.ndim == 1 else W
            L = W.shape[1]
            if L == n + m + k:
                W = np.concatenate([W, W[:, n:n + m] * eta_scale2], axis=1) \
                    if o.projection == "c3plus" else np.array(W)
            elif L == n + 2 * m + k:
                W = np.array(W) if o.projection == "c3plus" else np.array(W[:, : n + m + k])
            else:
                raise ValueError(f"C3 option {name} has {L} entries per knot; the LCS needs "
                                 f"n+m+k = {n + m + k} (or n+2m+k = {n + 2 * m + k} with "
                                 "eta weights)")
            out.append(W)
        return out[0], out[1]

    def _project(self, seq, zw, U, n, m, k) -> np.ndarray:
        o = self.options
        if o.projection == "c3plus":
            return project_c3plus(zw, n, m, k, U[:, n:n + m], U[:, n + m + k:])
        if o.projection == "qp":
            return self._qp_proj.project(zw)
        out = np.empty_like(zw)
        for idx, proj in self._exact_groups:
            out[idx] = proj.project(zw[idx])
        return out

    def _setup_projection(self, seq, data, U, n, m, k):
        o = self.options
        if o.projection == "qp":
            key = (tuple(seq.systems), U.tobytes())
            if self._qp_proj is None or self._proj_key is None or not (
                    _same_systems(self._proj_key[0], key[0])
                                             and self._proj_key[1] == key[1]):
                self._qp_proj = self._qp_proj or QpProjector(o.qp_projection_alpha)
                self._qp_proj.setup(data.E, data.F, data.H, data.c, U)
                self._proj_key = key
        elif o.projection == "exact":
            groups: dict = {}
            for j, s in enumerate(seq):
                groups.setdefault((id(s), U[j].tobytes()), (s, U[j], []))[2].append(j)
            cache, self._exact_groups = {}, []
            for key, (s, u, idx) in groups.items():
                hit = self._exact.get(key)
                proj = hit[1] if hit is not None and hit[0] is s else ExactProjector(
                    s.E, s.F, s.H, s.c, u)
                cache[key] = (s, proj)
                self._exact_groups.append((np.array(idx), proj))
            self._exact = cache

    def _backend_counts(self) -> dict:
        """Cumulative fall-back counters of the stateful back-ends (OSQP QP, QP projection)."""
        osqp_qp, proj = self._osqp, self._qp_proj
        return {"qp_unrefined": getattr(osqp_qp, "unrefined", 0),
                "projection_iter_limit": getattr(proj, "iteration_limits", 0),
                "projection_unrefined": getattr(proj, "refine_failures", 0)}

    def _qp(self, data):
        o = self.options
        backend = o.qp_backend
        if backend == "auto":
            backend = "osqp" if (o.u_bounds or o.x_bounds) else "kkt"
        if backend == "kkt":
            return KktQp(data), backend
        if backend in ("osqp", "osqp_sparse"):
            cls = OsqpQp if backend == "osqp" else OsqpSparseQp
            if not isinstance(self._osqp, cls):
                self._osqp = cls()
            return self._osqp.setup(data), backend
        self._drake = self._drake or DrakeOsqpQp()
        return self._drake.setup(data), backend

    # --- the solve -------------------------------------------------------------
    def solve(self, lcs: Lcs | LcsSequence, x0, x_target=None,
              warm: C3Solution | None = None, warm_shift: float = 1.0) -> C3Solution:
        """Plan from x0 towards x_target ([n] or [N+1, n]; default 0).

        warm: the solution to warm-start from (default: this solver's last one, if
        options.warm_start); its delta is shifted `warm_shift` knots (>= 0, fractions
        interpolated linearly, the last knot held): 1 when each solve starts one LCS
        step after the last, (time between the plans' start states) / dt when C3 runs
        faster than its LCS step.
        """
        t_start = time.perf_counter()
        o = self.options
        N = o.horizon
        seq = as_sequence(lcs, N)
        s0 = seq[0]
        n, k, m = s0.num_states, s0.num_inputs, s0.num_lambda
        if (n, k) != (o.num_states, o.num_inputs):
            raise ValueError(f"LCS has n={n}, k={k}; the C3 options are for "
                             f"n={o.num_states}, k={o.num_inputs}")
        x0 = np.asarray(x0, float).reshape(-1)
        if x0.shape != (n,) or not np.isfinite(x0).all():
            raise ValueError(f"x0 must be {n} finite numbers")
        if x_target is None:
            xt = np.zeros((N + 1, n))
        else:
            xt = np.asarray(x_target, float)
            xt = np.broadcast_to(xt, (N + 1, n)) if xt.shape == (n,) else xt
            if xt.shape != (N + 1, n) or not np.isfinite(xt).all():
                raise ValueError(f"x_target must be {n} or [{N + 1}, {n}] finite numbers")
        G, U = self.weights(s0)
        c3plus = o.projection == "c3plus"
        reference = c3plus and o.c3plus_reference
        if reference:                  # DAIRLab/c3 C3Plus: consensus on lam, eta only
            G = G.copy()
            G[:, :n] = 0.0
            G[:, n + m:n + m + k] = 0.0
        nz = G.shape[1]

        if all(s is s0 for s in seq):
            st = {name: np.broadcast_to(getattr(s0, name), (N,) + getattr(s0, name).shape)
                  for name in ("A", "B", "D", "d", "E", "F", "H", "c")}
        else:
            st = {name: np.stack([getattr(s, name) for s in seq])
                  for name in ("A", "B", "D", "d", "E", "F", "H", "c")}
        Qs = np.empty((N + 1, n, n))
        Qs[:N] = o.Q
        Qs[N] = self.terminal_weight(s0)
        lam0 = None
        events = dict.fromkeys(FALLBACKS, 0)
        if o.fix_initial_force and not np.any(s0.H):
            res = solve_lcp(s0.F, s0.E @ x0 + s0.c)
            if res.solved:
                lam0 = res.z
            events["lam0_lcp_failed"] = int(not res.solved)
            events["lam0_lcp_regularized"] = int(res.regularization > 0)
        data = QpStepData(**st, x0=x0, x_target=xt, Q=Qs,
                          R=np.broadcast_to(o.R, (N, k, k)), g=G, with_eta=c3plus,
                          lam0=lam0, u_bounds=o.u_bounds, x_bounds=o.x_bounds)
        qp, backend = self._qp(data)
        self._setup_projection(seq, data, U, n, m, k)
        before = self._backend_counts()

        warm = warm if warm is not None else (self.last_solution if o.warm_start else None)
        delta = np.zeros((N, nz))
        if warm is not None and warm.delta.shape == (N, nz):
            delta = shift_knots(warm.delta, warm_shift)
        else:
            delta[:, :n] = x0
        w = np.zeros((N, nz))
        scale = 1.0
        primal = dual = float("nan")
        z = delta
        for _ in range(o.admm_iter):
            z, x = qp.solve(scale, delta - w)
            new_delta = self._project(seq, z + w, U, n, m, k)
            w = w + z - new_delta
            primal = float(np.linalg.norm(z - new_delta))
            dual = float(np.linalg.norm(scale * G * (new_delta - delta)))
            delta = new_delta
            w /= o.rho_scale
            scale *= o.rho_scale
        if o.end_on_qp_step:
            z, x = qp.solve(scale, delta if reference else delta - w)
            lam_plan, u_plan = z[:, n:n + m], z[:, n + m:n + m + k]
        else:
            lam_plan, u_plan = delta[:, n:n + m], delta[:, n + m:n + m + k]
            x = np.empty((N + 1, n))
            x[0] = x0
            for j, s in enumerate(seq):
                x[j + 1] = s.A @ x[j] + s.B @ u_plan[j] + s.D @ lam_plan[j] + s.d
        for key, count in self._backend_counts().items():
            events[key] = count - before[key]
        for key, count in events.items():
            self.fallbacks[key] += count
        sol = C3Solution(u0=np.array(u_plan[0]), x_plan=np.array(x), lam_plan=np.array(lam_plan),
                         u_plan=np.array(u_plan), delta=delta, w=w, z=np.array(z),
                         iterations=o.admm_iter, primal_residual=primal, dual_residual=dual,
                         solve_time_s=time.perf_counter() - t_start,
                         lam0_fixed=lam0 is not None,
                         info={"qp_backend": backend, "projection": o.projection,
                               "fallbacks": events})
        self.last_solution = sol
        return sol
