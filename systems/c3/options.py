"""C3's settings: the options struct (cost weights, ADMM schedule, projection, QP backend,
bounds), checked on construction and loadable from a YAML/dict, and the reference
cart-pole settings. The solver that uses them is systems/c3/solver.py."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["C3Options", "cartpole_c3_options", "PROJECTIONS", "QP_BACKENDS"]

PROJECTIONS = ("c3plus", "qp", "exact")
QP_BACKENDS = ("auto", "kkt", "osqp", "osqp_sparse", "drake_osqp")


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
