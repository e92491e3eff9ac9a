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

from adaptive_c3.systems.c3.projection import ExactProjector, QpProjector, project_c3plus
from adaptive_c3.systems.c3.qp import DrakeOsqpQp, KktQp, OsqpQp, OsqpSparseQp, QpStepData
from adaptive_c3.systems.contact.lcp import solve_lcp
from adaptive_c3.systems.contact.lcs import Lcs, LcsSequence, as_sequence

__all__ = ["C3Options", "C3Solution", "C3Solver", "cartpole_c3_options",
           "PROJECTIONS", "QP_BACKENDS", "FALLBACKS"]

PROJECTIONS = ("c3plus", "qp", "exact")
QP_BACKENDS = ("auto", "kkt", "osqp", "osqp_sparse", "drake_osqp")
FALLBACKS = ("qp_unrefined", "projection_iter_limit", "projection_unrefined",
             "lam0_lcp_failed", "lam0_lcp_regularized")


def _matrix(name, value, shape=None) -> np.ndarray:
    try:
        arr = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"C3 option {name} must be numeric, got {value!r}") from None
    if arr.ndim == 1 and shape is None:
        arr = np.diag(arr)
    if arr.ndim != 2 or arr.shape[0] != arr.shape[1]:
        raise ValueError(f"C3 option {name} must be a square matrix, got shape {arr.shape}")
    if shape is not None and arr.shape != shape:
        raise ValueError(f"C3 option {name} has shape {arr.shape}, expected {shape}")
    if not np.isfinite(arr).all():
        raise ValueError(f"C3 option {name} has non-finite entries")
    if not np.allclose(arr, arr.T, atol=1e-9 * (1.0 + np.abs(arr).max())):
        raise ValueError(f"C3 option {name} must be symmetric")
    return arr


def _check_psd(name, M, strict=False):
    ev = np.linalg.eigvalsh(M)
    tol = 1e-10 * (1.0 + np.abs(ev).max())
    if strict and ev.min() <= tol:
        raise ValueError(f"C3 option {name} must be positive definite (min eigenvalue {ev.min():.3g})")
    if ev.min() < -tol:
        raise ValueError(f"C3 option {name} must be positive semidefinite "
                         f"(min eigenvalue {ev.min():.3g})")


def _bounds(name, value, size):
    if value is None:
        return None
    if isinstance(value, dict):
        if set(value) != {"lower", "upper"}:
            raise ValueError(f"C3 option {name} as a mapping needs exactly 'lower' and 'upper'")
        value = (value["lower"], value["upper"])
    try:
        lo, hi = (np.array(v, dtype=float).reshape(-1) for v in value)
    except (TypeError, ValueError):
        raise ValueError(f"C3 option {name} must be (lower, upper) vectors") from None
    if lo.shape != (size,) or hi.shape != (size,):
        raise ValueError(f"C3 option {name} needs {size} lower and {size} upper entries")
    if np.any(np.isnan(lo)) or np.any(np.isnan(hi)) or np.any(lo > hi):
        raise ValueError(f"C3 option {name} must have lower <= upper (no NaN)")
    return lo, hi


@dataclass
class C3Options:
    """C3 settings. Sizes: n states (from Q), k inputs (from R), m forces (from the LCS).

    G, U: diagonal weights over z = [x, lam, u] (length n+m+k) or, for C3+, over
    [x, lam, u, eta] (n+2m+k); either one row for every knot or a [horizon, len] array
    (per-knot). Given only n+m+k entries, C3+ weights eta_i by lam_i's weight / F_ii^2
    (F of the first LCS, F_ii floored at 1e-3 max F_ii), i.e. it measures eta in the
    force units of F_ii lam_i; for the cart-pole (F = I/ks) that is ks^2 = 2500 x the
    lam weight, without which C3+ does not stabilise it (eta in metres vs lam in N). QN None = the discrete
    Riccati solution of the first LCS's (A, B) with Q, R (falls back to Q with a warning
    when the Riccati equation has no stabilising solution).
    """

    horizon: int
    Q: np.ndarray
    R: np.ndarray
    G: np.ndarray
    U: np.ndarray
    QN: np.ndarray | None = None
    rho_scale: float = 2.0
    admm_iter: int = 10
    projection: str = "c3plus"
    warm_start: bool = True
    u_bounds: tuple | None = None   # (lower [k], upper [k])
    x_bounds: tuple | None = None   # (lower [n], upper [n]) on the planned x_1..x_N
    qp_backend: str = "auto"        # auto: kkt without bounds, osqp with bounds
    end_on_qp_step: bool = True
    fix_initial_force: bool = True
    qp_projection_alpha: float = 0.01
    c3plus_reference: bool = False  # C3+ as DAIRLab/c3's C3Plus (module docstring)

    def __post_init__(self):
        for name in ("horizon", "admm_iter"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
                raise ValueError(f"C3 option {name} must be an integer >= 1, got {v!r}")
            setattr(self, name, int(v))
        self.Q = _matrix("Q", self.Q)
        _check_psd("Q", self.Q)
        self.R = _matrix("R", self.R)
        _check_psd("R", self.R, strict=True)
        n, k = self.Q.shape[0], self.R.shape[0]
        if self.QN is not None:
            self.QN = _matrix("QN", self.QN, (n, n) if np.ndim(self.QN) == 2 else None)
            if self.QN.shape != (n, n):
                raise ValueError(f"C3 option QN has shape {self.QN.shape}, expected {(n, n)}")
            _check_psd("QN", self.QN)
        for name in ("G", "U"):
            try:
                arr = np.array(getattr(self, name), dtype=float)
            except (TypeError, ValueError):
                raise ValueError(f"C3 option {name} must be numeric weights") from None
            if arr.ndim == 2 and arr.shape[0] != self.horizon:
                raise ValueError(f"C3 option {name} per-knot weights need {self.horizon} rows, "
                                 f"got {arr.shape[0]}")
            if arr.ndim not in (1, 2) or arr.shape[-1] <= n + k:
                raise ValueError(f"C3 option {name} must be a diagonal over [x, lam, u] "
                                 f"(more than n+k = {n + k} entries), got shape {arr.shape}")
            if not np.isfinite(arr).all() or np.any(arr < 0):
                raise ValueError(f"C3 option {name} weights must be finite and >= 0")
            setattr(self, name, arr)
        rho = self.rho_scale
        if isinstance(rho, bool) or not isinstance(rho, (int, float, np.floating)) \
                or not np.isfinite(rho) or rho < 1.0:
            raise ValueError(f"C3 option rho_scale must be a finite number >= 1, got {rho!r}")
        self.rho_scale = float(rho)
        if self.projection not in PROJECTIONS:
            raise ValueError(f"C3 option projection must be one of {PROJECTIONS}, "
                             f"got {self.projection!r}")
        if self.qp_backend not in QP_BACKENDS:
            raise ValueError(f"C3 option qp_backend must be one of {QP_BACKENDS}, "
                             f"got {self.qp_backend!r}")
        for name in ("warm_start", "end_on_qp_step", "fix_initial_force", "c3plus_reference"):
            if not isinstance(getattr(self, name), (bool, np.bool_)):
                raise ValueError(f"C3 option {name} must be true or false")
        a = self.qp_projection_alpha
        if isinstance(a, bool) or not isinstance(a, (int, float)) or not 0.0 <= a <= 1.0:
            raise ValueError(f"C3 option qp_projection_alpha must be in [0, 1], got {a!r}")
        self.u_bounds = _bounds("u_bounds", self.u_bounds, k)
        self.x_bounds = _bounds("x_bounds", self.x_bounds, n)
        if self.qp_backend == "kkt" and (self.u_bounds or self.x_bounds):
            raise ValueError("C3 qp_backend 'kkt' cannot handle u_bounds/x_bounds; "
                             "use 'osqp' or 'auto'")

    @property
    def num_states(self) -> int:
        return self.Q.shape[0]

    @property
    def num_inputs(self) -> int:
        return self.R.shape[0]

    _KEYS = ("horizon", "q_diag", "r_diag", "qn_diag", "g_diag", "u_diag", "rho_scale",
             "admm_iter", "projection", "warm_start", "u_bounds", "x_bounds", "qp_backend",
             "end_on_qp_step", "fix_initial_force", "qp_projection_alpha", "c3plus_reference")

    @classmethod
    def from_dict(cls, d: dict, ignore=("rate_hz",)) -> "C3Options":
        """Options from a scenario's `c3` mapping (diagonals as lists).

        Keys: horizon, q_diag, r_diag, g_diag, u_diag (required); qn_diag (list, or
        "riccati"/null for the Riccati solution), rho_scale, admm_iter, projection,
        warm_start, u_bounds / x_bounds ({lower, upper} or [lower, upper]), qp_backend,
        end_on_qp_step, fix_initial_force, qp_projection_alpha, c3plus_reference. Keys
        in `ignore` (the controller's rate_hz) are skipped; anything else raises
        ValueError.
        """
        if not isinstance(d, dict):
            raise ValueError(f"C3 options must be a mapping, got {type(d).__name__}")
        unknown = set(d) - set(cls._KEYS) - set(ignore)
        if unknown:
            raise ValueError(f"unknown C3 option(s) {sorted(unknown)}; allowed: {list(cls._KEYS)}")
        missing = [k for k in ("horizon", "q_diag", "r_diag", "g_diag", "u_diag") if k not in d]
        if missing:
            raise ValueError(f"C3 options miss required key(s) {missing}")
        for key in ("q_diag", "r_diag", "g_diag", "u_diag"):
            v = d[key]
            if not isinstance(v, (list, tuple, np.ndarray)) or len(v) == 0:
                raise ValueError(f"C3 option {key} must be a non-empty list of numbers")
        qn = d.get("qn_diag")
        if isinstance(qn, str):
            if qn.lower() != "riccati":
                raise ValueError(f"C3 option qn_diag must be a list or 'riccati', got {qn!r}")
            qn = None
        kw = dict(horizon=d["horizon"], Q=np.diag(np.array(d["q_diag"], float)),
                  R=np.diag(np.array(d["r_diag"], float)), G=d["g_diag"], U=d["u_diag"],
                  QN=None if qn is None else np.diag(np.array(qn, float)))
        for key in ("rho_scale", "admm_iter", "projection", "warm_start", "u_bounds",
                    "x_bounds", "qp_backend", "end_on_qp_step", "fix_initial_force",
                    "qp_projection_alpha", "c3plus_reference"):
            if key in d:
                kw[key] = d[key]
        try:
            return cls(**kw)
        except ValueError:
            raise
        except Exception as exc:  # e.g. a string where a number was expected
            raise ValueError(f"invalid C3 options: {exc}") from None


def cartpole_c3_options(projection: str = "c3plus", **overrides) -> C3Options:
    """Reference cart-pole settings (the C3 authors' public cart-pole, DAIRLab/c3).

    N = 10, Q = diag(10, 3, 1, 1), R = 1, QN = Riccati, 10 ADMM iterations, rho_scale 2,
    G = 0.1 on [x, lam] and 0 on u. U follows the reference cartpole options
    (u_x 1000, u_lambda 1, u_u 0): projections repair complementarity by moving the
    forces, not the states (moving x by 1 mm costs as much as moving lam by 31 mN);
    u is unconstrained by the walls (H = 0) so its weight is irrelevant. C3+ weights
    eta by the lam weight x ks^2 (G 250, U 2500; see C3Options), so its rule compares
    the gap eta with the spring deflection F lam = lam / ks.
    """
    kw = dict(horizon=10, Q=np.diag([10.0, 3.0, 1.0, 1.0]), R=np.eye(1),
              G=np.r_[0.1 * np.ones(4), 0.1 * np.ones(2), 0.0],
              U=np.r_[1000.0 * np.ones(4), np.ones(2), 0.0],
              QN=None, rho_scale=2.0, admm_iter=10, projection=projection)
    kw.update(overrides)
    return C3Options(**kw)


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
