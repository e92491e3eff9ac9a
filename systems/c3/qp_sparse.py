"""The non-condensed (sparse) QP step of C3: the same QP as systems/c3/qp.py states, with
the states, forces, inputs (and C3+'s eta) all as variables and the dynamics as equality
constraints, solved by the `osqp` package (`OsqpSparseQp`) and as a persistent Drake
MathematicalProgram with OsqpSolver (`DrakeOsqpQp`): an independent formulation for tests
and the measured comparison in tools/bench/c3.py."""
from __future__ import annotations

import numpy as np
import osqp
import scipy.sparse as sp

from adaptive_c3.systems.c3.qp import QpStepData, silenced_c_stdout

__all__ = ["OsqpSparseQp", "DrakeOsqpQp"]


class _SparseLayout:
    """Variable layout and fixed sparsity patterns of the non-condensed QP."""

    def __init__(self, data: QpStepData):
        N, n, m, k = data.dims
        eta = data.with_eta
        nb = m + k + (m if eta else 0)
        self.N, self.n, self.m, self.k, self.nb, self.eta = N, n, m, k, nb, eta
        nxv = (N + 1) * n
        self.nvar = nxv + N * nb
        self.xi = np.arange(nxv).reshape(N + 1, n)
        blk = nxv + np.arange(N * nb).reshape(N, nb)
        self.li, self.ui = blk[:, :m], blk[:, m:m + k]
        self.ei = blk[:, m + k:] if eta else None
        self.zi = np.concatenate([self.xi[:N], blk], axis=1)       # [N, nz]
        self.fix_lam0 = data.lam0 is not None
        self.has_ub = data.u_bounds is not None
        self.has_xb = data.x_bounds is not None
        self.key = (N, n, m, k, eta, self.fix_lam0, self.has_ub, self.has_xb)
        # P upper triangle: dense Q block per x_j, dense R block per u_j, diagonal lam/eta.
        iu_n, ju_n = np.triu_indices(n)
        iu_k, ju_k = np.triu_indices(k)
        rows, cols = [], []
        for j in range(N + 1):
            rows.append(self.xi[j][iu_n]); cols.append(self.xi[j][ju_n])
        for j in range(N):
            rows.append(self.ui[j][iu_k]); cols.append(self.ui[j][ju_k])
            rows.append(self.li[j]); cols.append(self.li[j])
            if eta:
                rows.append(self.ei[j]); cols.append(self.ei[j])
        self.p_rows, self.p_cols = np.concatenate(rows), np.concatenate(cols)
        self._iu_n, self._ju_n, self._iu_k, self._ju_k = iu_n, ju_n, iu_k, ju_k
        self.p_order = np.lexsort((self.p_rows, self.p_cols))

    def p_values(self, data: QpStepData, scale: float) -> np.ndarray:
        """Upper-triangular P values (in the layout's COO order) for consensus scale."""
        N, n, m, k = self.N, self.n, self.m, self.k
        g = scale * data.g
        Qx = 2.0 * data.Q.copy()
        idx = np.arange(n)
        Qx[:N, idx, idx] += 2.0 * g[:, :n]
        Ru = 2.0 * data.R.copy()
        kdx = np.arange(k)
        Ru[:, kdx, kdx] += 2.0 * g[:, n + m:n + m + k]
        parts = [Qx[j][self._iu_n, self._ju_n] for j in range(N + 1)]
        for j in range(N):
            parts.append(Ru[j][self._iu_k, self._ju_k])
            parts.append(2.0 * g[j, n:n + m])
            if self.eta:
                parts.append(2.0 * g[j, n + m + k:])
        return np.concatenate(parts)

    def q_vector(self, data: QpStepData, scale: float, a: np.ndarray) -> np.ndarray:
        q = np.zeros(self.nvar)
        q[self.xi] = -2.0 * np.einsum("jab,jb->ja", data.Q, data.x_target)
        q[self.zi] += -2.0 * scale * data.g * a
        return q

    def constraints(self, data: QpStepData):
        """(rows, cols, vals, lower, upper) of all linear constraints, fixed pattern."""
        N, n, m, k = self.N, self.n, self.m, self.k
        rows, cols, vals, lo, hi = [], [], [], [], []
        r0 = 0

        def block(row_idx, col_idx, mat):
            rr, cc = np.meshgrid(row_idx, col_idx, indexing="ij")
            rows.append(rr.ravel()); cols.append(cc.ravel()); vals.append(np.asarray(mat).ravel())

        def ident(row_idx, col_idx, sign=1.0):
            rows.append(np.asarray(row_idx)); cols.append(np.asarray(col_idx))
            vals.append(np.full(len(row_idx), sign))

        ident(np.arange(n), self.xi[0]); lo.append(data.x0); hi.append(data.x0); r0 = n
        for j in range(N):                          # A x + D lam + B u - x+ = -d
            rr = r0 + np.arange(n)
            block(rr, self.xi[j], data.A[j]); block(rr, self.li[j], data.D[j])
            block(rr, self.ui[j], data.B[j]); ident(rr, self.xi[j + 1], -1.0)
            lo.append(-data.d[j]); hi.append(-data.d[j]); r0 += n
        if self.eta:                                # E x + F lam + H u - eta = -c
            for j in range(N):
                rr = r0 + np.arange(m)
                block(rr, self.xi[j], data.E[j]); block(rr, self.li[j], data.F[j])
                block(rr, self.ui[j], data.H[j]); ident(rr, self.ei[j], -1.0)
                lo.append(-data.c[j]); hi.append(-data.c[j]); r0 += m
        if self.fix_lam0:
            ident(r0 + np.arange(m), self.li[0]); lo.append(data.lam0); hi.append(data.lam0)
            r0 += m
        if self.has_ub:
            ulo, uhi = data.u_bounds
            for j in range(N):
                ident(r0 + np.arange(k), self.ui[j]); lo.append(ulo); hi.append(uhi); r0 += k
        if self.has_xb:
            xlo, xhi = data.x_bounds
            for j in range(1, N + 1):
                ident(r0 + np.arange(n), self.xi[j]); lo.append(xlo); hi.append(xhi); r0 += n
        cat = np.concatenate
        return cat(rows), cat(cols), cat(vals), cat(lo).astype(float), cat(hi).astype(float), r0

    def unpack(self, X: np.ndarray):
        return X[self.zi], X[self.xi]


class OsqpSparseQp:
    """Sparse (non-condensed) QP step with the `osqp` package: set up once, update, solve."""

    def __init__(self, eps: float = 1e-9, max_iter: int = 50000):
        self.eps, self.max_iter = eps, max_iter
        self._solver = None
        self._layout = None
        self._data = None

    def setup(self, data: QpStepData):
        """Load one C3 solve's data (re-uses the OSQP workspace if the structure matches)."""
        layout = _SparseLayout(data)
        rows, cols, vals, lo, hi, nrow = layout.constraints(data)
        a_order = np.lexsort((rows, cols))
        Px = layout.p_values(data, 1.0)[layout.p_order]
        Ax = vals[a_order]
        if self._solver is not None and self._layout.key == layout.key:
            self._solver.update(Px=Px, Ax=Ax, l=lo, u=hi)
        else:
            nv = layout.nvar
            P = sp.csc_matrix((Px, layout.p_rows[layout.p_order], np.searchsorted(
                layout.p_cols[layout.p_order], np.arange(nv + 1))), shape=(nv, nv))
            A = sp.csc_matrix((Ax, rows[a_order], np.searchsorted(
                cols[a_order], np.arange(nv + 1))), shape=(nrow, nv))
            self._solver = osqp.OSQP()
            self._solver.setup(P, np.zeros(layout.nvar), A, lo, hi, verbose=False,
                               eps_abs=self.eps, eps_rel=self.eps, polishing=True,
                               max_iter=self.max_iter, warm_starting=True)
        self._layout, self._data = layout, data
        return self

    def solve(self, scale: float, a: np.ndarray):
        """(z [N, nz], x [N+1, n]) for consensus scale s and target a [N, nz]."""
        lay, data = self._layout, self._data
        self._solver.update(Px=lay.p_values(data, scale)[lay.p_order],
                            q=lay.q_vector(data, scale, a))
        with silenced_c_stdout():     # its polishing prints when no bound is active
            res = self._solver.solve(raise_error=False)
        if res.info.status_val not in (1, 2):
            raise RuntimeError(f"OSQP QP step failed: {res.info.status}")
        return lay.unpack(np.asarray(res.x, float))


class DrakeOsqpQp:
    """The sparse QP step as a persistent Drake MathematicalProgram + OsqpSolver."""

    def __init__(self, eps: float = 1e-7):
        from pydrake.solvers import OsqpSolver, SolverOptions
        self._osqp = OsqpSolver()
        self._opts = SolverOptions()
        for name, value in (("eps_abs", eps), ("eps_rel", eps), ("polishing", 1),
                            ("max_iter", 50000), ("verbose", 0)):
            self._opts.SetOption(OsqpSolver.id(), name, value)
        self._key = None

    def setup(self, data: QpStepData):
        from pydrake.solvers import MathematicalProgram
        layout = _SparseLayout(data)
        rows, cols, vals, lo, hi, nrow = layout.constraints(data)
        A = sp.csc_matrix((vals, (rows, cols)), shape=(nrow, layout.nvar))
        if self._key != layout.key:
            self._prog = MathematicalProgram()
            self._vars = self._prog.NewContinuousVariables(layout.nvar, "X")
            n = layout.nvar
            self._cost = self._prog.AddQuadraticCost(np.eye(n), np.zeros(n), self._vars,
                                                     is_convex=True).evaluator()
            self._con = self._prog.AddLinearConstraint(A, lo, hi, self._vars).evaluator()
            self._key = layout.key
            self._guess = np.zeros(n)
        else:
            self._con.UpdateCoefficients(A, lo, hi)
        self._layout, self._data = layout, data
        return self

    def solve(self, scale: float, a: np.ndarray):
        lay, data = self._layout, self._data
        P = np.zeros((lay.nvar, lay.nvar))
        P[lay.p_rows, lay.p_cols] = lay.p_values(data, scale)
        self._cost.UpdateCoefficients(P + np.triu(P, 1).T, lay.q_vector(data, scale, a))
        with silenced_c_stdout():
            result = self._osqp.Solve(self._prog, self._guess, self._opts)
        if not result.is_success():
            raise RuntimeError(f"Drake OSQP QP step failed: {result.get_solution_result()}")
        X = result.GetSolution(self._vars)
        self._guess = X
        return lay.unpack(X)
