"""Linear complementarity problems: find z >= 0 with w = M z + q >= 0 and z'w = 0.

`solve_lcp` is Lemke's complementary pivoting method (artificial variable z0,
covering vector of ones) with a lexicographic minimum-ratio rule, so it cannot
cycle on degenerate problems. It is written for the small problems (m = 2..16)
that are solved once per simulation step. On a nearly singular problem (e.g. a PD M with
condition number ~1e10) the tableau's round-off can end Lemke on a wrong basis or a
ray; then one retry runs Lemke on the regularised M + eps I (eps = 1e-10 max(1, |M|))
and re-solves the ORIGINAL M on the basis it found. The result says so
(`LcpResult.regularization` = eps, and the message) and is `solved` only if it meets the
tolerance on the original problem. `solve_lcp_enumeration` tries every
complementary basis and is meant as ground truth in tests.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.linalg.lapack import dgesv

__all__ = ["LcpResult", "solve_lcp", "solve_lcp_enumeration"]

_INF = float("inf")


@dataclass(frozen=True)
class LcpResult:
    """Outcome of an LCP solve.

    z, w: the returned point and w = M z + q (both length m).
    solved: True only if (z, w) satisfies the LCP to the solver's tolerance.
    iterations: pivots (Lemke) or bases tried (enumeration).
    message: short human-readable status.
    residual: max(|z_i w_i|, -min(z), -min(w), 0) evaluated at the returned z.
    regularization: eps of the regularised retry (M + eps I) that produced z; 0 if the
        first Lemke run was used. z, w and residual always refer to the original M.
    """

    z: np.ndarray
    w: np.ndarray
    solved: bool
    iterations: int
    message: str
    residual: float
    regularization: float = 0.0


def _check_inputs(M, q, check_finite: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Return (M, q) as float arrays; ValueError naming the problem if invalid.

    check_finite=False skips the NaN/inf check (the caller then does it).
    """
    M = np.asarray(M, dtype=float)
    q = np.asarray(q, dtype=float)
    if q.ndim == 2 and 1 in q.shape:
        q = q.reshape(-1)
    if M.ndim != 2 or M.shape[0] != M.shape[1]:
        raise ValueError(f"LCP matrix M must be square 2-D, got shape {M.shape}")
    if q.ndim != 1:
        raise ValueError(f"LCP vector q must be 1-D, got shape {q.shape}")
    if q.shape[0] != M.shape[0]:
        raise ValueError(
            f"LCP size mismatch: M is {M.shape[0]}x{M.shape[1]} but q has length {q.shape[0]}"
        )
    if M.shape[0] == 0:
        raise ValueError("LCP is empty (M is 0x0)")
    if check_finite:
        _check_finite(M, q)
    return M, q


def _check_finite(M: np.ndarray, q: np.ndarray) -> None:
    if not np.isfinite(M).all():
        raise ValueError("LCP matrix M contains NaN or infinity")
    if not np.isfinite(q).all():
        raise ValueError("LCP vector q contains NaN or infinity")


def _residual(z: np.ndarray, w: np.ndarray) -> float:
    """max of complementarity |z_i w_i| and infeasibility of z and w."""
    return float(max(np.abs(z * w).max(), -z.min(), -w.min(), 0.0))


def _scale(M: np.ndarray, q: np.ndarray, z: np.ndarray) -> float:
    """Magnitude of the terms in w = M z + q, used to scale tolerances."""
    return max(1.0, float(np.abs(q).max()), float(np.abs(M).max()) * float(np.abs(z).max()))


def _lex_argmin(T: np.ndarray, col: list, rows: list, tie_tol: float) -> int:
    """Row of `rows` whose vector T[row, 0:m+1] / col[row] is lexicographically smallest.

    T[:, 0] is the right-hand side and T[:, 1:m+1] the current basis inverse, so
    these vectors are distinct and the minimum is unique (up to round-off).
    The first components are assumed tied already; comparison starts at column 1.
    """
    m = T.shape[0]
    for k in range(1, m + 1):
        vals = [T[i, k] / col[i] for i in rows]
        vmin = min(vals)
        thr = vmin + tie_tol * (1.0 + abs(vmin))
        rows = [i for i, v in zip(rows, vals) if v <= thr]
        if len(rows) == 1:
            break
    return rows[0]


_TEMPLATES: dict[int, np.ndarray] = {}


def _template(m: int) -> np.ndarray:
    """Initial tableau without q and M: columns [rhs | I | (-M) | -e]."""
    T = _TEMPLATES.get(m)
    if T is None:
        T = np.zeros((m, 2 * m + 2))
        T[:, 1 : m + 1] = np.eye(m)
        T[:, 2 * m + 1] = -1.0
        T.setflags(write=False)
        _TEMPLATES[m] = T
    return T


def _solve_small(A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Solve A x = b for a small square A (LAPACK dgesv, low call overhead).

    Raises np.linalg.LinAlgError if A is exactly singular.
    """
    if b.shape[0] == 1:
        a = float(A[0, 0])
        if a == 0.0:
            raise np.linalg.LinAlgError("singular 1x1 system")
        return b / a
    _, _, x, info = dgesv(A, b)
    if info != 0:
        raise np.linalg.LinAlgError(f"dgesv failed (info={info})")
    return x


# Relative size of the diagonal added by the regularised retry (times max(1, |M|)).
REGULARIZATION = 1e-10


def solve_lcp(M, q, max_iterations: int | None = None, tol: float = 1e-10,
              regularize: bool = True) -> LcpResult:
    """Solve LCP(M, q) by Lemke's method with a lexicographic ratio rule.

    M: (m, m) matrix, q: (m,) vector. max_iterations caps the pivots
    (default 50 (m + 1)). tol: relative tolerance for pivot elements and for the
    final residual check (scaled by max(1, |q|, |M| |z|)).
    regularize: when the first run fails (other than by the iteration cap), retry once
    on M + eps I (module docstring); the result then has regularization = eps.
    Returns an LcpResult; solved=False (with a message) on ray termination,
    iteration cap, or a final residual above tolerance. Raises ValueError for
    malformed input.
    """
    res = _lemke(M, q, max_iterations, tol)
    if res.solved or not regularize or res.message.startswith("iteration cap"):
        return res
    M, q = np.asarray(M, float), np.asarray(q, float).reshape(-1)
    eps = REGULARIZATION * max(1.0, float(np.abs(M).max()))
    retry = _lemke(M + eps * np.eye(M.shape[0]), q, max_iterations, tol)
    best = None
    for z in (_basis_resolve(M, q, retry.z), retry.z):
        if z is None:
            continue
        w = M @ z + q
        r = _residual_nonneg_z(z, w)
        if best is None or r < best[2]:
            best = (z, w, r)
    z, w, r = best
    thresh = tol * max(1.0, float(np.abs(q).max()), float(np.abs(M).max()) * float(z.max()))
    if r <= thresh and r < res.residual:
        return LcpResult(z, w, True, res.iterations + retry.iterations,
                         f"solved by Lemke after a regularised retry (eps {eps:.3g}; first "
                         f"run: {res.message})", r, eps)
    if r < res.residual:
        return LcpResult(z, w, False, res.iterations + retry.iterations,
                         f"{res.message}; regularised retry (eps {eps:.3g}) left residual "
                         f"{r:.3g}", r, eps)
    return LcpResult(res.z, res.w, False, res.iterations + retry.iterations,
                     f"{res.message}; regularised retry (eps {eps:.3g}) did not help",
                     res.residual)


def _basis_resolve(M: np.ndarray, q: np.ndarray, z: np.ndarray) -> np.ndarray | None:
    """Solve the original M on the support of z: M_aa z_a = -q_a, others 0 (clipped >= 0)."""
    a = np.flatnonzero(z > 0)
    out = np.zeros_like(z)
    if a.size:
        try:
            za = _solve_small(M[np.ix_(a, a)], -q[a])
        except np.linalg.LinAlgError:
            return None
        if not np.isfinite(za).all():
            return None
        out[a] = np.maximum(za, 0.0)
    return out


def _lemke(M, q, max_iterations: int | None, tol: float) -> LcpResult:
    """One run of Lemke's method (see solve_lcp)."""
    M, q = _check_inputs(M, q, check_finite=False)
    m = q.shape[0]
    qlist = q.tolist()
    mnorm = float(np.abs(M).max())
    if not (math.isfinite(mnorm) and math.isfinite(sum(qlist))):
        _check_finite(M, q)  # raises unless only the sum overflowed
    qmin = min(qlist)
    if qmin >= 0.0:  # z = 0 is a solution
        return LcpResult(np.zeros(m), q.copy(), True, 0, "trivial solution (q >= 0)", 0.0)

    if max_iterations is None:
        max_iterations = 50 * (m + 1)
    piv_tol = tol * max(1.0, mnorm)
    tie_tol = 1e-12
    z0_id = 2 * m

    # Tableau for w - M z - e z0 = q, columns [rhs | w_0..w_{m-1} | z_0..z_{m-1} | z0].
    # Variable ids: w_i -> i, z_i -> m + i, z0 -> 2m; the column of id v is v + 1.
    # Columns 1..m always hold the current basis inverse (used by the lex rule).
    T = _template(m).copy()
    T[:, 0] = q
    np.negative(M, out=T[:, m + 1 : 2 * m + 1])
    basis = list(range(m))

    # First pivot: z0 enters; the row of the lexicographically smallest (q_i, e_i)
    # leaves (exact ties in q_i go to the largest index), which makes the rhs >= 0.
    r = max(i for i in range(m) if qlist[i] == qmin)
    entering = z0_id
    piv = -1.0

    iterations = 0
    message = ""
    terminated = False
    while iterations < max_iterations:
        iterations += 1
        # Pivot on (r, entering): row r /= piv, other rows -= col_i * new row r.
        f = T[:, entering + 1] * (1.0 / piv)
        f[r] = 1.0 - 1.0 / piv
        np.subtract(T, np.multiply.outer(f, T[r]), out=T)
        leaving = basis[r]
        basis[r] = entering
        if leaving == z0_id:
            terminated = True
            message = "solved by Lemke"
            break
        entering = leaving + m if leaving < m else leaving - m

        # Lexicographic minimum-ratio test on the entering column.
        col = T[:, entering + 1].tolist()
        rhs = T[:, 0].tolist()
        ratios = [b / c if c > piv_tol else _INF for b, c in zip(rhs, col)]
        rmin = min(ratios)
        if rmin == _INF:
            message = "ray termination (no solution found by Lemke)"
            break
        thr = rmin + tie_tol * (1.0 + abs(rmin))
        ties = [i for i, t in enumerate(ratios) if t <= thr]
        if len(ties) == 1:
            r = ties[0]
        else:
            z0_rows = [i for i in ties if basis[i] == z0_id]
            r = z0_rows[0] if z0_rows else _lex_argmin(T, col, ties, tie_tol)
        piv = col[r]
    else:
        message = f"iteration cap ({max_iterations}) reached"

    # Polish: recompute the basic z from the final basis with a linear solve,
    # M[a, a] z_a = -q_a; fall back to the tableau values if that fails.
    zrows = [i for i in range(m) if m <= basis[i] < z0_id]
    zidx = [basis[i] - m for i in zrows]
    z = None
    if terminated and zidx:
        try:
            za = _solve_small(M.take(zidx, 0).take(zidx, 1), np.negative(q.take(zidx)))
            if not math.isfinite(sum(za.tolist())):
                raise np.linalg.LinAlgError("non-finite solution of the basis system")
            z = np.zeros(m)
            z[zidx] = za
            np.maximum(z, 0.0, out=z)
        except np.linalg.LinAlgError:
            z = None
    used_tableau = z is None
    if used_tableau:
        z = _tableau_z(T, m, zrows, zidx)
    w = M @ z + q
    res = _residual_nonneg_z(z, w)
    if not terminated:
        return LcpResult(z, w, False, iterations, message, res)

    thresh = tol * max(1.0, max(map(abs, qlist)), mnorm * float(z.max()))
    if res > thresh and not used_tableau:
        z_tab = _tableau_z(T, m, zrows, zidx)
        w_tab = M @ z_tab + q
        res_tab = _residual_nonneg_z(z_tab, w_tab)
        if res_tab < res:
            z, w, res = z_tab, w_tab, res_tab
    if res > thresh:
        return LcpResult(
            z, w, False, iterations,
            f"Lemke terminated but residual {res:.3g} exceeds tolerance {thresh:.3g}", res,
        )
    return LcpResult(z, w, True, iterations, message, res)


def _tableau_z(T: np.ndarray, m: int, zrows: list, zidx: list) -> np.ndarray:
    """z read from the tableau's right-hand side (basic z entries), clipped at 0."""
    z = np.zeros(m)
    if zrows:
        z[zidx] = T[zrows, 0]
        np.maximum(z, 0.0, out=z)
    return z


def _residual_nonneg_z(z: np.ndarray, w: np.ndarray) -> float:
    """Residual max(|z_i w_i|, -w_i, 0) for a z already known to be >= 0 (inf if NaN)."""
    vals = [max(abs(a * b), -b) for a, b in zip(z.tolist(), w.tolist())]
    if any(map(math.isnan, vals)):
        return _INF
    return max(0.0, max(vals))


def solve_lcp_enumeration(M, q, tol: float = 1e-9) -> LcpResult:
    """Solve LCP(M, q) by trying all 2^m complementary bases (m <= 12).

    For each set a of indices with z_a free (others zero) solve
    M_aa z_a = -q_a and accept the first basis with z >= 0, w >= 0 within
    tol (scaled by max(1, |q|, |M| |z|)). For a P-matrix this is the unique
    solution. solved=False if no basis works. Raises ValueError for malformed
    input or m > 12.
    """
    M, q = _check_inputs(M, q)
    m = q.shape[0]
    if m > 12:
        raise ValueError(f"enumeration is limited to m <= 12, got m = {m}")
    best = None
    tried = 0
    for mask in range(1 << m):
        tried += 1
        idx = [i for i in range(m) if (mask >> i) & 1]
        z = np.zeros(m)
        if idx:
            sub = M[np.ix_(idx, idx)]
            rhs = -q[idx]
            try:
                za = np.linalg.solve(sub, rhs)
            except np.linalg.LinAlgError:
                za = np.linalg.lstsq(sub, rhs, rcond=None)[0]
            if not np.isfinite(za).all():
                continue
            z[idx] = za
        thresh = tol * _scale(M, q, z)
        if z.min() < -thresh:
            continue
        z = np.maximum(z, 0.0)
        w = M @ z + q
        res = _residual(z, w)
        if res <= thresh:
            return LcpResult(z, w, True, tried, f"solved by enumeration (basis mask {mask})", res)
        if best is None or res < best[2]:
            best = (z, w, res)
    if best is None:
        z = np.zeros(m)
        w = q.copy()
        best = (z, w, _residual(z, w))
    return LcpResult(best[0], best[1], False, tried, "no complementary basis solves the LCP", best[2])
