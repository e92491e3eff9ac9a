"""Projection steps of C3: map z + w onto the complementarity set of each knot.

Per knot the LCS constrains delta = [x, lam, u] (lengths n, m, k) by

    0 <= lam  _|_  eta = E x + F lam + H u + c >= 0.

Three projections, all weighted by a diagonal U (the "U-norm"
||v||_U^2 = sum_i U_i v_i^2):

* `project_c3plus` - C3+: eta is a separate copy variable, delta = [x, lam, u, eta];
  elementwise closed form (x, u unchanged).
* `QpProjector` - the convex QP projection of the reference library (valid for PSD F):
  lam >= 0, eta >= 0 imposed, the product lam'eta replaced by the convex surrogate
  lam' F lam, with the lam-distance measured in alpha F instead of U_lam.
  All knots are stacked into one block-diagonal OSQP problem (set up once, then only
  q changes between ADMM iterations), solved loosely and then refined per knot to the
  exact optimum by an active-set step (qp.refine_active_set); OSQP's iteration limits
  and failed refinements (the unrefined iterate is returned) are counted.
* `ExactProjector` - the exact U-norm projection by enumerating the complementary
  modes (m <= 10); ground truth for tests and for small m.
"""
from __future__ import annotations

import itertools

import numpy as np
import osqp
import scipy.sparse as sp

from adaptive_c3.systems.c3.qp import refine_active_set

__all__ = ["project_c3plus", "QpProjector", "ExactProjector", "project_exact",
           "complementarity_violation"]

# Weight used for zero-weight entries of U in the exact projection (relative to max U):
# such entries are "almost free"; an entry with zero weight that also appears in the
# constraints (e.g. u with H != 0) would otherwise make the projection ill-posed.
_ZERO_WEIGHT_FLOOR = 1e-6


def project_c3plus(zw: np.ndarray, n: int, m: int, k: int, u_lam, u_eta) -> np.ndarray:
    """C3+ projection of zw [..., n+2m+k] in z = [x, lam, u, eta] order.

    Per element i: if sqrt(U_eta_i) eta_c > sqrt(U_lam_i) lam_c then lam = 0,
    eta = max(eta_c, 0), else eta = 0, lam = max(lam_c, 0). x and u are unchanged.
    u_lam, u_eta: weights broadcastable to [..., m] (must be >= 0).
    Returns a new array.
    """
    zw = np.asarray(zw, float)
    out = zw.copy()
    lam_c = zw[..., n:n + m]
    eta_c = zw[..., n + m + k:n + 2 * m + k]
    eta_larger = np.sqrt(u_eta) * eta_c > np.sqrt(u_lam) * lam_c
    out[..., n:n + m] = np.where(eta_larger, 0.0, np.maximum(lam_c, 0.0))
    out[..., n + m + k:n + 2 * m + k] = np.where(eta_larger, np.maximum(eta_c, 0.0), 0.0)
    return out


def complementarity_violation(delta, E, F, H, c, n: int, m: int, k: int) -> dict:
    """Violation measures of delta = [x, lam, u] for one knot (all >= 0, 0 if exact).

    Returns {"lam_neg": max(-lam, 0), "eta_neg": max(-eta, 0),
             "product": max |lam_i eta_i|} with eta = E x + F lam + H u + c.
    """
    delta = np.asarray(delta, float)
    x, lam, u = delta[:n], delta[n:n + m], delta[n + m:n + m + k]
    eta = E @ x + F @ lam + H @ u + c
    return {"lam_neg": float(max(0.0, -lam.min())), "eta_neg": float(max(0.0, -eta.min())),
            "product": float(np.abs(lam * eta).max())}


def _csc_pattern(rows, cols, shape):
    """(order, indices, indptr) putting COO entries into CSC order (no duplicates)."""
    rows = np.asarray(rows, np.int64)
    cols = np.asarray(cols, np.int64)
    order = np.lexsort((rows, cols))
    indptr = np.searchsorted(cols[order], np.arange(shape[1] + 1)).astype(np.int64)
    return order, rows[order], indptr


class QpProjector:
    """Convex QP projection (reference C3's "QP" projection) for N knots at once.

    Per knot, with y = z + w = [x_c, lam_c, u_c]:

        min  1/2 (d - y)' U~ (d - y) + 1/2 (1 - alpha) lam' Fs lam
        s.t. lam >= 0,  E x + F lam + H u + c >= 0

    where Fs = (F + F')/2 and U~ is diag(U) with its lam block replaced by alpha Fs.
    The lam terms together equal 1/2 lam'Fs lam - alpha y_lam' Fs lam + const: the
    force is pulled towards alpha * lam_c but kept as small as the non-penetration
    constraint allows, which is the convex (Anitescu, F PSD) surrogate of lam'eta = 0.
    The result satisfies lam >= 0 and eta >= 0 (to solver tolerance) but only
    approximately lam'eta = 0 (see tests/test_c3_projection.py for measured bounds).
    """

    def __init__(self, alpha: float = 0.01, eps: float = 1e-7, max_iter: int = 20000,
                 refine_iter: int = 60):
        if not 0.0 <= alpha <= 1.0:
            raise ValueError(f"QP projection alpha must be in [0, 1], got {alpha}")
        self.alpha = float(alpha)
        self.eps = float(eps)
        self.max_iter, self.refine_iter = int(max_iter), int(refine_iter)
        self._solver = None
        self._key = None
        # Counted over the projector's life (setup does not reset them): OSQP stopped at
        # its iteration/time limit, and knots whose exact refinement failed so OSQP's
        # unrefined iterate was returned.
        self.iteration_limits = 0
        self.refine_failures = 0

    def setup(self, E, F, H, c, U):
        """Set the per-knot data: E [N,m,n], F [N,m,m], H [N,m,k], c [N,m], U [N,nz]."""
        E, F, H = (np.asarray(a, float) for a in (E, F, H))
        c = np.asarray(c, float)
        U = np.asarray(U, float)
        N, m, n = E.shape
        k = H.shape[2]
        nz = n + m + k
        if U.shape != (N, nz):
            raise ValueError(f"QP projection weights have shape {U.shape}, expected {(N, nz)}")
        self._dims = (N, n, m, k)
        Fs = 0.5 * (F + np.transpose(F, (0, 2, 1)))
        # Objective Hessian per knot: diag(U) on x, u; Fs on lam (upper triangle).
        self._wt = U.copy()
        self._wt[:, n:n + m] = 0.0
        self._Fs_alpha = self.alpha * Fs
        iu, ju = np.triu_indices(m)
        p_rows, p_cols, p_vals = [], [], []
        for j in range(N):
            off = j * nz
            xu = np.r_[np.arange(n), np.arange(n + m, nz)]
            p_rows.append(off + xu)
            p_cols.append(off + xu)
            p_vals.append(U[j, xu])
            p_rows.append(off + n + iu)
            p_cols.append(off + n + ju)
            p_vals.append(Fs[j][iu, ju])
        nvar = N * nz
        p_rows, p_cols, p_vals = map(np.concatenate, (p_rows, p_cols, p_vals))
        # Constraints per knot: lam >= 0 (m rows), E x + F lam + H u >= -c (m rows).
        a_rows, a_cols, a_vals = [], [], []
        for j in range(N):
            off, roff = j * nz, j * 2 * m
            a_rows.append(roff + np.arange(m))
            a_cols.append(off + n + np.arange(m))
            a_vals.append(np.ones(m))
            EFH = np.hstack([E[j], F[j], H[j]])
            r, cc = np.indices((m, nz))
            a_rows.append(roff + m + r.ravel())
            a_cols.append(off + cc.ravel())
            a_vals.append(EFH.ravel())
        a_rows, a_cols, a_vals = map(np.concatenate, (a_rows, a_cols, a_vals))
        shape_p, shape_a = (nvar, nvar), (2 * m * N, nvar)
        p_order, p_idx, p_ptr = _csc_pattern(p_rows, p_cols, shape_p)
        a_order, a_idx, a_ptr = _csc_pattern(a_rows, a_cols, shape_a)
        Px, Ax = p_vals[p_order], a_vals[a_order]
        # Dense per-knot copies for the exact active-set refinement after OSQP. A
        # proximal term reg_i (d_i - y_i)^2 / 2 makes the Hessian definite without moving
        # zero-weight entries away from y: reg = 1e-9 max(U) on zero-weight x, u entries
        # and 1e-10 max|F| on lam (F may be singular); 0 elsewhere.
        ar = np.arange(nz)
        self._reg = np.where(U == 0.0, 1e-9 * max(1.0, float(U.max())), 0.0)
        self._reg[:, n:n + m] = 1e-10 * max(float(np.abs(Fs).max()), 1e-12)
        self._P = np.zeros((N, nz, nz))
        self._P[:, ar, ar] = self._wt + self._reg
        self._P[:, n:n + m, n:n + m] += Fs
        self._A = np.zeros((N, 2 * m, nz))
        self._A[:, :m, n:n + m] = np.eye(m)
        self._A[:, m:] = np.concatenate([E, F, H], axis=2)
        self._lo = np.concatenate([np.zeros((N, m)), -c], axis=1)
        self._hi = np.full(2 * m, np.inf)
        lower = np.concatenate([np.r_[np.zeros(m), -c[j]] for j in range(N)])
        upper = np.full(2 * m * N, np.inf)
        key = (N, n, m, k)
        if self._solver is not None and self._key == key:
            self._solver.update(Px=Px, Ax=Ax, l=lower)
        else:
            P = sp.csc_matrix((Px, p_idx, p_ptr), shape=shape_p)
            A = sp.csc_matrix((Ax, a_idx, a_ptr), shape=shape_a)
            self._solver = osqp.OSQP()
            self._solver.setup(P, np.zeros(nvar), A, lower, upper, verbose=False,
                               eps_abs=self.eps, eps_rel=self.eps, polishing=False,
                               max_iter=self.max_iter, warm_starting=True)
            self._key = key
        return self

    def project(self, y: np.ndarray) -> np.ndarray:
        """Projected delta [N, nz] of y [N, nz] = z + w."""
        N, n, m, k = self._dims
        y = np.asarray(y, float)
        q = -(self._wt * y)
        q[:, n:n + m] = -np.einsum("jab,jb->ja", self._Fs_alpha, y[:, n:n + m])
        self._solver.update(q=q.ravel())
        res = self._solver.solve(raise_error=False)
        if res.info.status_val not in (1, 2, 7, 8):  # solved (inaccurate), iter/time limit
            raise RuntimeError(f"QP projection failed: OSQP status {res.info.status}")
        self.iteration_limits += res.info.status_val in (7, 8)
        d = np.asarray(res.x, float).reshape(N, -1)
        g = q - self._reg * y
        # Exact solve on OSQP's active set, all knots in one batched KKT solve (an
        # inactive row i becomes the equation mu_i = 0); knots whose result is not
        # primal/dual feasible are refined by the active-set method.
        A, lo = self._A, self._lo
        Ad = np.einsum("jab,jb->ja", A, d)
        scale = 1.0 + np.abs(Ad).max(axis=1, keepdims=True)
        ymul = np.asarray(res.y, float).reshape(N, -1)   # < 0: lower bound active
        W = ((Ad <= lo + 10.0 * self.eps * scale) & (ymul < 0)).astype(float)
        nz, nc = d.shape[1], A.shape[1]
        K = np.zeros((N, nz + nc, nz + nc))
        K[:, :nz, :nz] = self._P
        K[:, :nz, nz:] = A.transpose(0, 2, 1) * W[:, None, :]
        K[:, nz:, :nz] = A * W[:, :, None]
        K[:, nz + np.arange(nc), nz + np.arange(nc)] = 1.0 - W
        rhs = np.concatenate([-g, W * lo], axis=1)
        try:
            sol = np.linalg.solve(K, rhs[..., None])[..., 0]
        except np.linalg.LinAlgError:
            sol = None
        if sol is not None:
            v, mu = sol[:, :nz], sol[:, nz:]
            Av = np.einsum("jab,jb->ja", A, v)
            Pv = np.einsum("jab,jb->ja", self._P, v)
            # multiplier tolerance per row, from the gradient entries the row touches
            mtol = 1e-10 * (1.0 + np.einsum("jab,jb->ja", np.abs(A), np.abs(g) + np.abs(Pv)))
            good = ((Av >= lo - 1e-9 * scale).all(axis=1) & (mu <= mtol).all(axis=1))
            d[good] = v[good]
            redo = np.flatnonzero(~good)
        else:
            redo = range(N)
        for j in redo:
            d[j], ok = refine_active_set(self._P[j], g[j], A[j], lo[j], self._hi, d[j],
                                         100.0 * self.eps, self.refine_iter)
            self.refine_failures += not ok
        return d


class ExactProjector:
    """Exact projection onto {[x, lam, u] : 0 <= lam _|_ E x + F lam + H u + c >= 0}.

    Minimises ||delta - y||_U over the complementarity set of one knot. The set is
    the union over the 2^m modes (lam_i = 0, eta_i >= 0 or eta_i = 0, lam_i >= 0) of
    polyhedra; each mode's inequality QP is solved exactly by enumerating which of
    its m inequalities are active, so together the candidates are the 3^m faces
    {lam_I = 0, eta_J = 0, I u J = all}. The optimum is the U-projection of y onto the
    affine hull of the face it lies on, so the best *feasible* face projection is the
    global optimum. In scaled coordinates s = sqrt(U) (delta - y) the constraint values
    are [lam; eta] = r + B s with B = C U^-1/2, C = [[0 I 0]; [E F H]], r their value
    at y, so a face's projection is the least-norm s = -pinv(B_J) r_J (rank-deficient,
    i.e. inconsistent faces are detected by their residual). Zero weights in U are
    replaced by 1e-6 max(U) (almost free entries).
    """

    def __init__(self, E, F, H, c, U_diag, tol: float = 1e-9):
        E, F, H = (np.asarray(a, float) for a in (E, F, H))
        m, n = E.shape
        k = H.shape[1]
        if m > 10:
            raise ValueError(f"exact projection enumerates 3^m faces; m = {m} > 10")
        w = np.asarray(U_diag, float).reshape(-1)[: n + m + k].copy()
        if w.shape != (n + m + k,) or np.any(w < 0) or not np.isfinite(w).all():
            raise ValueError("exact projection needs n+m+k finite, non-negative U weights")
        w = np.where(w > 0, w, _ZERO_WEIGHT_FLOOR * max(float(w.max()), 1.0))
        self.n, self.m, self.k = n, m, k
        self.tol = tol
        C = np.zeros((2 * m, n + m + k))
        C[:m, n:n + m] = np.eye(m)
        C[m:] = np.hstack([E, F, H])
        self._C = C
        self._ct = np.r_[np.zeros(m), np.asarray(c, float)]
        self._isw = 1.0 / np.sqrt(w)
        self._B = C * self._isw
        self._groups = None if m > 8 else list(self._face_groups())

    def _face_groups(self):
        """Yield (J [F, s], pinv(B_J) [F, nz, s]) grouped by face size s = m + #both."""
        m = self.m
        by_size: dict[int, list] = {}
        for assign in itertools.product((0, 1, 2), repeat=m):
            J = [i for i, a in enumerate(assign) if a in (0, 2)]      # lam_i = 0
            J += [m + i for i, a in enumerate(assign) if a in (1, 2)]  # eta_i = 0
            by_size.setdefault(len(J), []).append(J)
        for faces in by_size.values():
            J = np.array(faces, np.int64)
            yield J, np.linalg.pinv(self._B[J], rcond=1e-12)

    def project(self, y: np.ndarray, return_distance: bool = False):
        """Exact projection of y [..., n+m+k]; optionally also the U-distance squared."""
        y = np.asarray(y, float)
        shape = y.shape
        nz = self.n + self.m + self.k
        Y = y.reshape(-1, shape[-1])[:, :nz]
        r = Y @ self._C.T + self._ct                     # [B, 2m] constraint values
        tol = self.tol * (1.0 + np.abs(r).max(axis=1))[:, None]
        best = np.full(Y.shape[0], np.inf)
        best_s = np.zeros_like(Y)
        rows = np.arange(Y.shape[0])
        groups = self._groups if self._groups is not None else self._face_groups()
        for J, Binv in groups:
            s = -np.einsum("fzs,bfs->bfz", Binv, r[:, J])  # [B, F, nz]
            p = r[:, None, :] + s @ self._B.T              # [B, F, 2m]
            pJ = np.take_along_axis(p, np.broadcast_to(J, p.shape[:2] + J.shape[1:]), axis=2)
            feasible = (np.abs(pJ).max(axis=2) <= tol) & (p.min(axis=2) >= -tol)
            dist2 = np.where(feasible, np.einsum("bfz,bfz->bf", s, s), np.inf)
            f = dist2.argmin(axis=1)
            better = dist2[rows, f] < best
            best = np.where(better, dist2[rows, f], best)
            best_s[better] = s[rows[better], f[better]]
        if not np.isfinite(best).all():
            raise RuntimeError("exact projection found no feasible face (inconsistent LCS?)")
        out = y.copy()
        out[..., :nz] = (Y + best_s * self._isw).reshape(shape[:-1] + (nz,))
        if return_distance:
            return out, best.reshape(shape[:-1])
        return out


def project_exact(y, U_diag, E, F, H, c) -> np.ndarray:
    """Exact U-weighted projection of y = [x, lam, u] onto the complementarity set."""
    return ExactProjector(E, F, H, c, U_diag).project(y)
