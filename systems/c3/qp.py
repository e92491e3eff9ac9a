"""QP step of C3: the horizon QP without complementarity, three back-ends.

Every back-end solves, for a consensus scale s and a consensus target a_j (= delta_j - w_j),

    min  sum_{j=0}^{N} (x_j - xt_j)' Q_j (x_j - xt_j) + sum_{j<N} u_j' R_j u_j
         + s sum_{j<N} (z_j - a_j)' diag(g_j) (z_j - a_j)
    s.t. x_0 = x0,  x_{j+1} = A_j x_j + B_j u_j + D_j lam_j + d_j,
         [eta_j = E_j x_j + F_j lam_j + H_j u_j + c_j]   (C3+ only),
         [lam_0 = lam0]  (when the initial force is fixed),
         [u_lo <= u_j <= u_hi, x_lo <= x_j <= x_hi (j >= 1)]  (OSQP back-ends only),

with z_j = [x_j, lam_j, u_j(, eta_j)]. Q_N is the terminal weight.

* `KktQp` - exact, condensed: the states (and eta) are eliminated through the dynamics,
  x = Gamma v + chi with v = stacked [lam_j, u_j]; the small dense Hessian Hc + s Hg is
  Cholesky-factored once per call. Everything independent of s and a is computed once
  in the constructor (once per C3 solve). No inequality bounds.
* `OsqpQp` - the same condensed QP with bounds, by the `osqp` package (set up once per
  size, then P, q, A, l, u updated and warm-started); OSQP's loose solution is refined
  to the exact optimum by a primal active-set step (`refine_active_set`); when that
  fails OSQP's answer is used and counted (`unrefined`). The back-end used when bounds
  are present.
* `OsqpSparseQp`, `DrakeOsqpQp` (systems/c3/qp_sparse.py) - the non-condensed (sparse)
  QP with the `osqp` package and as a persistent Drake MathematicalProgram +
  OsqpSolver: an independent formulation for tests and the measured comparison in
  tools/bench/c3.py.
"""
from __future__ import annotations

import contextlib
import os
import sys
from dataclasses import dataclass

import numpy as np
import osqp
import scipy.sparse as sp
from scipy.linalg import lapack

__all__ = ["QpStepData", "KktQp", "OsqpQp", "refine_active_set"]


@dataclass
class QpStepData:
    """Stacked per-knot data of one C3 solve (N knots; arrays indexed by knot first)."""

    A: np.ndarray   # [N, n, n]
    B: np.ndarray   # [N, n, k]
    D: np.ndarray   # [N, n, m]
    d: np.ndarray   # [N, n]
    E: np.ndarray   # [N, m, n]
    F: np.ndarray   # [N, m, m]
    H: np.ndarray   # [N, m, k]
    c: np.ndarray   # [N, m]
    x0: np.ndarray  # [n]
    x_target: np.ndarray  # [N+1, n]
    Q: np.ndarray   # [N+1, n, n] (last = Q_N)
    R: np.ndarray   # [N, k, k]
    g: np.ndarray   # [N, nz] consensus weights at scale 1
    with_eta: bool = False
    lam0: np.ndarray | None = None     # fixed initial force, or None
    u_bounds: tuple | None = None      # (lo [k], hi [k])
    x_bounds: tuple | None = None      # (lo [n], hi [n]) on x_1..x_N

    @property
    def dims(self):
        N, n, m = self.D.shape
        return N, n, m, self.B.shape[2]


@contextlib.contextmanager
def silenced_c_stdout():
    """Silence C-level stdout around the comparison back-ends' OSQP calls: OSQP's
    polishing prints a line whenever no constraint is active, even when not verbose."""
    sys.stdout.flush()
    saved = os.dup(1)
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, 1)
    try:
        yield
    finally:
        os.dup2(saved, 1)
        os.close(saved)
        os.close(devnull)


def _chol_solve(H: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """Solve H v = rhs for symmetric PSD H by Cholesky (tiny regularisation if singular)."""
    L, info = lapack.dpotrf(H, lower=1, clean=0, overwrite_a=0)
    if info != 0:
        reg = 1e-10 * (1.0 + float(np.abs(np.diag(H)).max()))
        L, info = lapack.dpotrf(H + reg * np.eye(H.shape[0]), lower=1, clean=0)
        if info != 0:
            return np.linalg.lstsq(H, rhs, rcond=None)[0]
    v, info = lapack.dpotrs(L, rhs, lower=1)
    return v


class _Condensed:
    """The QP in the stacked free inputs v: min v'(Hc + s Hg)v + 2 (gc + s gG(a))'v + const.

    x_j = Gamma_j v + chi_j and z_j = T_j v + t_j (eta eliminated for C3+, lam_0 folded
    into the constants when fixed). Built once per C3 solve.
    """

    def __init__(self, data: QpStepData):
        N, n, m, k = data.dims
        p = m + k
        nv = N * p
        eta = data.with_eta
        nz = n + p + (m if eta else 0)
        A, E = data.A, data.E
        DB = np.concatenate([data.D, data.B], axis=2)             # [N, n, p]
        FH = np.concatenate([data.F, data.H], axis=2)             # [N, m, p]
        Gam = np.zeros((N + 1, n, nv))
        chi = np.empty((N + 1, n))
        chi[0] = data.x0
        for j in range(N):
            if j:
                Gam[j + 1, :, : j * p] = A[j] @ Gam[j, :, : j * p]
            Gam[j + 1, :, j * p:(j + 1) * p] = DB[j]
            chi[j + 1] = A[j] @ chi[j] + data.d[j]
        T = np.zeros((N, nz, nv))
        t = np.zeros((N, nz))
        T[:, :n] = Gam[:N]
        t[:, :n] = chi[:N]
        eye_p = np.eye(p)
        for j in range(N):
            T[j, n:n + p, j * p:(j + 1) * p] = eye_p
        if eta:
            T[:, n + p:] = E @ Gam[:N]
            for j in range(N):
                T[j, n + p:, j * p:(j + 1) * p] += FH[j]
            t[:, n + p:] = np.einsum("jab,jb->ja", E, chi[:N]) + data.c
        if data.lam0 is not None:                                 # fold lam_0 into constants
            lam0 = np.asarray(data.lam0, float)
            chi += Gam[:, :, :m] @ lam0
            t += T[:, :, :m] @ lam0
            Gam = Gam[:, :, m:]
            T = T[:, :, m:]
        self._free0 = m if data.lam0 is not None else 0
        self._lam0 = data.lam0
        nvf = Gam.shape[2]
        # Cost blocks independent of the ADMM iteration.
        # Per-knot products (stacked matmuls) keep every BLAS call small: OpenBLAS then
        # stays single-threaded, which avoids multi-ms thread wake-ups on a busy machine.
        QG = data.Q @ Gam                                          # [N+1, n, nvf]
        GamT = Gam.transpose(0, 2, 1)
        Hc = (GamT @ QG).sum(axis=0)
        gc = np.einsum("jav,ja->v", QG, chi - data.x_target)
        off = m - self._free0
        for j in range(N):                                         # input cost R on u_j
            s = j * p + off
            Hc[s:s + k, s:s + k] += data.R[j]
        T2 = T.reshape(N * nz, nvf)
        TG = T * data.g[:, :, None]
        self._Hc = Hc
        self._Hg = (T.transpose(0, 2, 1) @ TG).sum(axis=0)
        TG = TG.reshape(N * nz, nvf)
        self._gc = gc
        self._TGt = np.ascontiguousarray(TG.T)
        self._T2, self._t, self._Gam, self._chi = T2, t, Gam, chi
        self._dims = (N, n, m, k, nz)

    def gradient(self, scale: float, a: np.ndarray) -> np.ndarray:
        return self._gc + scale * (self._TGt @ (self._t - a).ravel())

    def unpack(self, v: np.ndarray):
        N, n, m, k, nz = self._dims
        z = (self._T2 @ v).reshape(N, nz) + self._t
        x = self._Gam @ v + self._chi
        if self._lam0 is not None:
            z[0, n:n + m] = self._lam0
        return z, x


class KktQp(_Condensed):
    """Condensed exact QP step (no inequality bounds). Build once per C3 solve."""

    def __init__(self, data: QpStepData):
        if data.u_bounds is not None or data.x_bounds is not None:
            raise ValueError("the KKT QP step has no inequality bounds; use the OSQP back-end")
        super().__init__(data)

    def solve(self, scale: float, a: np.ndarray):
        """(z [N, nz], x [N+1, n]) for consensus scale s and target a [N, nz]."""
        v = _chol_solve(self._Hc + scale * self._Hg, -self.gradient(scale, a))
        return self.unpack(v)


class OsqpQp:
    """Condensed QP step with the `osqp` package (bounds allowed).

    The dense Hessian's upper triangle and the bound rows (u_j boxes; x_j bounds as
    rows Gamma_j) keep a fixed sparsity pattern, so the workspace is set up once per
    problem size and afterwards only updated (P, q each ADMM iteration; A, l, u each
    C3 solve) and warm-started from the previous solution.
    """

    def __init__(self, eps: float = 1e-3, max_iter: int = 20000, refine_iter: int = 60):
        self.eps, self.max_iter, self.refine_iter = eps, max_iter, refine_iter
        self._solver = None
        self._key = None
        # QP steps whose exact refinement failed, so OSQP's loose (eps) answer was used
        self.unrefined = 0

    def setup(self, data: QpStepData):
        cond = _Condensed(data)
        self._A_lo_hi = None
        N, n, m, k, nz = cond._dims
        nv = cond._Hc.shape[0]
        off = m - cond._free0
        u_cols = (np.arange(N)[:, None] * (m + k) + off + np.arange(k)).ravel()
        rows = [np.eye(nv)[u_cols]]
        inf = np.full(N * k, np.inf)
        lo = [np.tile(data.u_bounds[0], N) if data.u_bounds is not None else -inf]
        hi = [np.tile(data.u_bounds[1], N) if data.u_bounds is not None else inf]
        if data.x_bounds is not None:
            rows.append(cond._Gam[1:].reshape(N * n, nv))
            lo.append((data.x_bounds[0] - cond._chi[1:]).ravel())
            hi.append((data.x_bounds[1] - cond._chi[1:]).ravel())
        Amat = np.vstack(rows)
        lo, hi = np.concatenate(lo), np.concatenate(hi)
        iu, ju = np.triu_indices(nv)
        order = np.lexsort((iu, ju))
        self._iu, self._ju = iu[order], ju[order]
        ar, ac = np.indices(Amat.shape)
        a_order = np.lexsort((ar.ravel(), ac.ravel()))
        Ax = Amat.ravel()[a_order]
        self._cond = cond
        self._A_lo_hi = (Amat, lo, hi)
        key = (nv, Amat.shape[0])
        Px = 2.0 * cond._Hc[self._iu, self._ju]
        if self._solver is not None and self._key == key:
            self._solver.update(Px=Px, Ax=Ax, l=lo, u=hi)
        else:
            P = sp.csc_matrix((Px, self._iu, np.searchsorted(self._ju, np.arange(nv + 1))),
                              shape=(nv, nv))
            A = sp.csc_matrix((Ax, ar.ravel()[a_order],
                               np.searchsorted(ac.ravel()[a_order], np.arange(nv + 1))),
                              shape=Amat.shape)
            self._solver = osqp.OSQP()
            # OSQP's own polishing prints to stdout whenever no bound is active, so the
            # active-set refinement is done here (_polish) instead.
            self._solver.setup(P, np.zeros(nv), A, lo, hi, verbose=False, eps_abs=self.eps,
                               eps_rel=self.eps, polishing=False, max_iter=self.max_iter,
                               warm_starting=True)
            self._key = key
        return self

    def solve(self, scale: float, a: np.ndarray):
        """(z [N, nz], x [N+1, n]) for consensus scale s and target a [N, nz]."""
        cond = self._cond
        H = cond._Hc + scale * cond._Hg
        g = cond.gradient(scale, a)
        self._solver.update(Px=2.0 * H[self._iu, self._ju], q=2.0 * g)
        res = self._solver.solve(raise_error=False)
        status = res.info.status_val
        # OSQP's answer (even an iteration limit or a false infeasibility verdict on these
        # badly scaled problems) only starts the exact refinement, which checks the KKT
        # conditions itself.
        A, lo, hi = self._A_lo_hi
        x_start = np.asarray(res.x, float)
        if not np.isfinite(x_start).all():
            x_start = np.zeros_like(x_start)
        v, ok = refine_active_set(H, g, A, lo, hi, x_start, 10.0 * self.eps,
                                  self.refine_iter)
        if not ok and status not in (1, 2):
            raise RuntimeError(f"OSQP QP step failed: {res.info.status}")
        self.unrefined += not ok
        return cond.unpack(v)


def refine_active_set(H, g, A, lo, hi, v, near: float, max_iter: int = 60):
    """Exact solution of min v'Hv/2 + g'v s.t. lo <= A v <= hi, refined from a nearby v.

    A primal active-set method started at v (e.g. OSQP's loose-tolerance solution)
    with the bounds within `near` (relative) of being active: solve the equality-
    constrained QP on the working set, step towards it until a bound blocks (then add
    it), drop the bound with the most wrong-signed multiplier, until the KKT conditions
    hold. H must be positive definite on the feasible directions. Returns (v, True) on
    convergence, else (the input v, False).
    """
    v0 = v
    Av = A @ v
    scale = 1.0 + np.abs(Av).max()
    side = np.where(Av >= hi - near * scale, 1, np.where(Av <= lo + near * scale, -1, 0))
    tol = 1e-10 * scale
    # Multiplier tolerance per row, from the gradient entries the row touches.
    mtol_all = 1e-10 * (1.0 + np.abs(A) @ (np.abs(g) + np.abs(H @ v)))
    nv = H.shape[0]
    for _ in range(max_iter):
        W = side != 0
        if W.any():
            Aw = A[W]
            na = Aw.shape[0]
            K = np.zeros((nv + na, nv + na))
            K[:nv, :nv] = H
            K[:nv, nv:] = Aw.T
            K[nv:, :nv] = Aw
            rhs = np.r_[-g, np.where(side > 0, hi, lo)[W]]
            try:
                sol = np.linalg.solve(K, rhs)
            except np.linalg.LinAlgError:
                sol = np.linalg.lstsq(K, rhs, rcond=None)[0]
            v_new, mu = sol[:nv], sol[nv:]
        else:
            v_new, mu = _chol_solve(H, -g), np.zeros(0)
        step = v_new - v
        Ap = A @ step
        Av = A @ v
        with np.errstate(divide="ignore", invalid="ignore"):
            r_up = np.where(~W & (Ap > tol), (hi - Av) / Ap, np.inf)
            r_lo = np.where(~W & (Ap < -tol), (lo - Av) / Ap, np.inf)
        ratio = np.maximum(np.minimum(r_up, r_lo), 0.0)
        j = int(np.argmin(ratio)) if ratio.size else 0
        if ratio.size and ratio[j] < 1.0:          # blocked: move and add bound j
            v = v + ratio[j] * step
            side[j] = 1 if r_up[j] <= r_lo[j] else -1
            continue
        v = v_new
        # H v + g + A_W' mu = 0: an upper bound needs mu >= 0, a lower one mu <= 0.
        wrongness = np.where(side[W] > 0, -mu, mu) - mtol_all[W]
        if wrongness.size and wrongness.max() > 0:
            side[np.flatnonzero(W)[int(np.argmax(wrongness))]] = 0
            continue
        Av = A @ v
        if np.all(Av <= hi + 1e3 * tol) and np.all(Av >= lo - 1e3 * tol):
            return v, True
        break
    return v0, False
