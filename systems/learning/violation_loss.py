"""Violation-based implicit loss for the contact residual r_comp (paper Sec. VI, Alg. 1).

For one measured transition (x_next, x, u) and the prior LCS theta* = (A, B, D, d, E, F,
H, c) at (x, u), with residual r added to the complementarity offset:

    z = A x + B u + d - x_next,        q = E x + H u + c,
    l_eps(r) = min_{lam >= 0, eta >= 0}  1/2 (D lam + z)' Qd (D lam + z)
               + (1/eps) (lam' eta + 1/(2 gamma) ||q + F lam + r - eta||^2).

The inner problem is a strictly convex QP in y = (lam, eta) with simple bounds when
0 < gamma < sigma_min(F + F'): eliminating eta leaves the curvature
(F + F' - gamma I)/2 on lam. By the envelope theorem

    dl/dr = (1/(eps gamma)) w*,   w* = q + F lam* + r - eta*.

How the QP is solved (exactly):

* Scaling: eps can be 1e-7, so we solve J(y) = eps * l(y) = 1/2 y' H y + g' y + const,
      H = [[eps D'Qd D + F'F/gamma, I - F'/gamma], [I - F/gamma, I/gamma]],
      g = [eps D'Qd z + F'(q + r)/gamma, -(q + r)/gamma],
  whose entries are O(1/gamma) whatever eps is.
* Method: block principal pivoting (Judice & Pires) on the KKT conditions, the LCP
  y >= 0, H y + g >= 0, y'(H y + g) = 0 with H positive definite: guess the free set,
  solve H_FF y_F = -g_F, flip every infeasible index; after 3 rounds without fewer
  infeasibilities, Murty's single least-index flip (finite for P-matrices). Warm-started
  from the previous free set of the same sample it usually stops after one solve.
* Polishing: given lam the best eta is eta = max(0, q + r + F lam - gamma lam), so lam
  is clipped at 0 and eta recomputed; w* = min(q + r + F lam, gamma lam). With no
  contact in data or model lam* = 0 exactly and the gradient is exactly zero.
* Exactness: the natural KKT residual max_i |min(y_i, (H y + g)_i)| of J (units of q for
  the lam rows, of lam for the eta rows) must be <= KKT_TOL = 1e-8, else RuntimeError.

Batched loss and gradient are the mean over the buffer. `adam_update` is Adam with a
mask of learned entries, an optional inverse-time step-size decay, and a hard clip of
each update to +-max_step (units of c): one bad batch cannot move an entry further.

About eps: the minimiser depends on eps only through eps Q_d (eps alone scales dl/dr,
which Adam ignores). Where only the data has contact the gradient is nonzero only where
q + r < eps D'Qd D lam_true: a zero-gradient band of width |dc| / (1 + eps a k) remains
(dc the offset error, a = (D'Qd D)_ii, k the stiffness). Cart-pole, Q_d = I (a = 8.1e-3,
k = 50, dc = 0.15): eps = 1e-3 leaves all of it flat, eps = 100 a 3.7 mm band; so
eps = 100, gamma = 1e-2 there. The paper's eps = 1e-7 goes with Q_d = 1e5 (ball).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Iterable, Sequence

import numpy as np

from adaptive_c3.systems.contact.lcs import Lcs

__all__ = [
    "KKT_TOL", "LearnerOptions", "PreparedSample", "SampleSolution", "StepResult",
    "ViolationLossLearner", "adam_update", "batch_loss_and_grad", "check_epsilon",
    "check_gamma", "prepare_sample", "qd_matrix", "solve_batch", "solve_sample", "violation_loss",
]

KKT_TOL = 1e-8  # natural KKT residual allowed in the eps-scaled QP (see module doc)
_MAX_PIVOTS = 500


# --------------------------------------------------------------------------- options
@dataclass(frozen=True)
class LearnerOptions:
    """Hyper-parameters of the residual learner.

    epsilon: LCP violation weight eps > 0 (ball rolling: paper 1e-7, reference code 2e-5;
        cart-pole with Q_d = I: 100, see the module doc). Required.
    gamma: 0 < gamma < sigma_min(F + F') of every sample's F (checked per sample);
        1e-2 for both tasks. Required.
    learning_rate: Adam step size xi.
    batch_size: n_b, transitions per batch (the ring buffer length).
    Qd: state-error weight: None -> identity, a scalar -> s I, a length-n list -> diag,
        or an n x n symmetric PSD matrix.
    mask: which residual entries are learned (None -> all); a length-m bool list.
    max_step: clip of each Adam update per entry (units of c; e.g. m for walls).
    beta1, beta2, adam_eps: Adam's moment decays and denominator guard.
    lr_decay_steps: optional inverse-time decay of the step size, xi_t = xi / (1 + t / T)
        with t the Adam step count and T = lr_decay_steps; 0 (default) keeps xi fixed.
    """

    epsilon: float
    gamma: float
    learning_rate: float = 1e-3
    batch_size: int = 10
    Qd: object = None
    mask: object = None
    max_step: float = 0.01
    beta1: float = 0.9
    beta2: float = 0.999
    adam_eps: float = 1e-8
    lr_decay_steps: float = 0.0

    def __post_init__(self):
        check_epsilon(self.epsilon)
        bs = self.batch_size
        if isinstance(bs, bool) or int(bs) != bs or int(bs) < 1:
            raise ValueError(f"learner batch_size must be a positive integer, got {bs}")
        object.__setattr__(self, "batch_size", int(bs))
        for name, ok, what in (
                ("gamma", lambda v: v > 0, "> 0 (and < sigma_min(F + F'))"),
                ("learning_rate", lambda v: v > 0, "> 0"),
                ("max_step", lambda v: v > 0, "> 0"),
                ("beta1", lambda v: 0 <= v < 1, "in [0, 1)"),
                ("beta2", lambda v: 0 <= v < 1, "in [0, 1)"),
                ("lr_decay_steps", lambda v: v >= 0, ">= 0 (0 = off)"),
                ("adam_eps", lambda v: v > 0, "> 0")):
            v = float(getattr(self, name))
            if not (np.isfinite(v) and ok(v)):
                raise ValueError(f"learner {name} must be {what}, got {v}")

    def mask_array(self, m: int) -> np.ndarray:
        """The learned-entry mask as a length-m bool array."""
        if self.mask is None:
            return np.ones(m, dtype=bool)
        mask = np.asarray(self.mask).reshape(-1)
        if mask.shape != (m,):
            raise ValueError(f"learner mask has {mask.size} entries, the LCS has m={m}")
        if mask.dtype != bool:
            if not np.all(np.isin(mask, (0, 1))):
                raise ValueError("learner mask entries must be booleans (or 0/1)")
            mask = mask.astype(bool)
        return mask


def check_epsilon(epsilon: float) -> float:
    e = float(epsilon)
    if not np.isfinite(e) or e <= 0:
        raise ValueError(f"learner epsilon must be > 0 (the LCP violation weight), got {e}")
    return e


def check_gamma(F, gamma: float) -> float:
    """Validate 0 < gamma < sigma_min(F + F') (F + F' must be PD); returns the sigma_min."""
    F, g = np.asarray(F, float), float(gamma)
    S = F + F.T
    smin = float(np.linalg.eigvalsh(S)[0]) if S.size else np.inf
    if not smin > 0:
        raise ValueError(f"learner needs F + F' positive definite; its smallest eigenvalue "
                         f"is {smin:.3g}, so no gamma makes the loss convex")
    if not (np.isfinite(g) and 0 < g < smin):
        raise ValueError(f"learner gamma = {g:.6g} is outside (0, sigma_min(F + F') = "
                         f"{smin:.6g}); choose a smaller gamma")
    return smin


def qd_matrix(Qd, n: int) -> np.ndarray:
    """Q_d as an n x n symmetric PSD matrix (see LearnerOptions.Qd)."""
    if Qd is None:
        return np.eye(n)
    Q = np.asarray(Qd, float)
    if Q.ndim == 0:
        Q = float(Q) * np.eye(n)
    elif Q.ndim == 1:
        if Q.shape != (n,):
            raise ValueError(f"learner Qd diagonal has {Q.size} entries, the state has n={n}")
        Q = np.diag(Q)
    elif Q.shape != (n, n):
        raise ValueError(f"learner Qd has shape {Q.shape}, expected ({n}, {n})")
    if not np.isfinite(Q).all():
        raise ValueError("learner Qd has non-finite entries")
    if not np.allclose(Q, Q.T, rtol=1e-12, atol=0.0):
        raise ValueError("learner Qd must be symmetric")
    if np.linalg.eigvalsh(Q)[0] < -1e-12 * max(1.0, np.abs(Q).max()):
        raise ValueError("learner Qd must be positive semidefinite")
    return Q


# --------------------------------------------------------------------------- samples
class PreparedSample:
    """One transition's r-independent QP data: z, q, D, F, Q_d, the eps-scaled Hessian H,
    b = eps D'Qd z; `free` (warm-start free set) and `_inv` (cached inverses of H's
    principal blocks) only affect speed, never results."""

    __slots__ = ("z", "q", "D", "F", "Qd", "H", "b", "epsilon", "gamma", "free", "FtG",
                 "_inv")

    def __init__(self, z, q, D, F, Qd, epsilon, gamma):
        m = q.shape[0]
        self.z, self.q, self.D, self.F, self.Qd, self.epsilon, self.gamma = (
            z, q, D, F, Qd, epsilon, gamma)
        QD = Qd @ D
        inv_g = 1.0 / gamma
        H = np.empty((2 * m, 2 * m))
        H[:m, :m] = epsilon * (D.T @ QD) + inv_g * (F.T @ F)
        H[:m, m:] = np.eye(m) - inv_g * F.T
        H[m:, :m] = np.eye(m) - inv_g * F
        H[m:, m:] = inv_g * np.eye(m)
        self.H = 0.5 * (H + H.T)
        self.b = epsilon * (QD.T @ z)
        self.FtG = F.T * inv_g
        self.free = np.arange(2 * m) >= m  # the "no contact" guess: lam = 0, eta = q + r
        self._inv = {}

    def reduced_inverse(self, free):
        """(indices, inverse of H[free, free]) for a free set, cached."""
        key = free.tobytes()
        hit = self._inv.get(key)
        if hit is None:
            idx = np.flatnonzero(free)
            inv = np.linalg.inv(self.H[np.ix_(idx, idx)]) if idx.size else None
            if len(self._inv) >= 8:
                self._inv.clear()
            hit = self._inv[key] = (idx, inv)
        return hit


def prepare_sample(x_next, x, u, lcs: Lcs, epsilon: float, gamma: float,
                   Qd=None, check: bool = True) -> PreparedSample | None:
    """The QP data of one transition, or None if any of x_next, x, u is non-finite.
    Qd: anything `qd_matrix` accepts; check=True validates epsilon, gamma against F."""
    n, k = lcs.num_states, lcs.num_inputs
    x_next, x, u = (np.asarray(v, float).reshape(-1) for v in (x_next, x, u))
    for name, v, size in (("x_next", x_next, n), ("x", x, n), ("u", u, k)):
        if v.shape != (size,):
            raise ValueError(f"transition {name} has {v.size} entries, the LCS expects {size}")
    if not (np.isfinite(x_next).all() and np.isfinite(x).all() and np.isfinite(u).all()):
        return None
    if check:
        check_epsilon(epsilon)
        check_gamma(lcs.F, gamma)
    Q = Qd if (isinstance(Qd, np.ndarray) and Qd.shape == (n, n)) else qd_matrix(Qd, n)
    z = lcs.A @ x + lcs.B @ u + lcs.d - x_next
    q = lcs.E @ x + lcs.H @ u + lcs.c
    return PreparedSample(z, q, lcs.D, lcs.F, Q, float(epsilon), float(gamma))


@dataclass(frozen=True)
class SampleSolution:
    """One sample's inner QP solution at r: lam, eta (the minimiser); loss l_eps
    (unscaled); grad dl/dr; w = q + F lam + r - eta; kkt (natural KKT residual of the
    eps-scaled QP); iterations (pivoting rounds)."""

    lam: np.ndarray
    eta: np.ndarray
    loss: float
    grad: np.ndarray
    w: np.ndarray
    kkt: float
    iterations: int


def _pivot(s: PreparedSample, g, tol):
    """Block principal pivoting for min 1/2 y'Hy + g'y s.t. y >= 0 (H PD), from s.free.
    Returns (y, free, rounds)."""
    H, free, best, backup = s.H, s.free, g.shape[0] + 1, 3
    for it in range(1, _MAX_PIVOTS + 1):
        idx, inv = s.reduced_inverse(free)
        y = np.zeros(g.shape[0])
        if inv is not None:
            y[idx] = -(inv @ g[idx])
        grad = H @ y + g
        bad = np.where(free, y < -tol, grad < -tol)
        if not bad.any():
            return y, free, it
        nbad = int(np.count_nonzero(bad))
        if nbad < best:
            best, backup = nbad, 3
            free = free ^ bad
        elif backup > 0:
            backup -= 1
            free = free ^ bad
        else:  # Murty's least-index rule (on the largest index), finite for P-matrices
            j = np.flatnonzero(bad)[-1]
            free = free.copy()
            free[j] = not free[j]
    raise RuntimeError("violation-loss QP: block pivoting did not terminate "
                       f"in {_MAX_PIVOTS} rounds")


def _polish(s: PreparedSample, y, qr, g):
    """Clip lam at 0, set eta to its closed-form optimum; returns (lam, eta, w0, y, kkt)."""
    m = qr.shape[0]
    lam = np.maximum(y[:m], 0.0)
    w0 = qr + s.F @ lam
    eta = np.maximum(w0 - s.gamma * lam, 0.0)
    y = np.concatenate((lam, eta))
    kkt = float(np.abs(np.minimum(y, s.H @ y + g)).max())
    return lam, eta, w0, y, kkt


def solve_sample(s: PreparedSample, r) -> SampleSolution:
    """Solve the inner QP of one prepared sample at residual r (exact; see module doc)."""
    m = s.q.shape[0]
    gam, eps = s.gamma, s.epsilon
    qr = s.q + r
    g = np.concatenate((s.b + s.FtG @ qr, qr * (-1.0 / gam)))
    tol = 1e-13 * max(1.0, float(np.abs(g).max()))
    y, free, its = _pivot(s, g, tol)
    lam, eta, w0, y, kkt = _polish(s, y, qr, g)
    if kkt > KKT_TOL:
        # one refinement step on the identified free set, then re-polish
        idx = np.flatnonzero(y > 0)
        if idx.size:
            res = s.H @ y + g
            y[idx] -= np.linalg.solve(s.H[np.ix_(idx, idx)], res[idx])
        lam, eta, w0, y, kkt = _polish(s, y, qr, g)
        if kkt > KKT_TOL:
            raise RuntimeError(f"violation-loss QP: KKT residual {kkt:.3g} > {KKT_TOL:g} "
                               "(gamma too close to sigma_min(F + F')?)")
    s.free = free
    w = np.minimum(w0, gam * lam)  # = w0 - eta exactly, whether eta = 0 or eta > 0
    e = s.D @ lam + s.z
    loss = 0.5 * float(e @ (s.Qd @ e)) + (float(lam @ eta) + float(w @ w) / (2 * gam)) / eps
    return SampleSolution(lam, eta, loss, w / (eps * gam), w, kkt, its)


def violation_loss(x_next, x, u, lcs: Lcs, r, epsilon: float, gamma: float,
                   Qd=None) -> tuple[float, np.ndarray]:
    """(l_eps, dl/dr) for one transition; ValueError for non-finite data."""
    s = prepare_sample(x_next, x, u, lcs, epsilon, gamma, Qd)
    if s is None:
        raise ValueError("transition has non-finite entries")
    sol = solve_sample(s, _check_r(r, lcs.num_lambda))
    return sol.loss, sol.grad


def solve_batch(samples: Sequence[PreparedSample], r):
    """Solve the QPs of several samples (same m, n) at r together: `solve_sample`'s
    pivoting with one batched LU per round (free set F as H on F x F, identity elsewhere).
    Returns (lam [B, m], eta [B, m], loss [B], grad [B, m], kkt [B]); samples missing
    KKT_TOL are re-solved one by one (with refinement)."""
    B, m = len(samples), samples[0].q.shape[0]
    nv = 2 * m
    r = np.asarray(r, float)
    H = np.stack([s.H for s in samples])
    F = np.stack([s.F for s in samples])
    gam = np.array([s.gamma for s in samples])
    eps = np.array([s.epsilon for s in samples])
    qr = np.stack([s.q for s in samples]) + r
    g = np.empty((B, nv))
    g[:, :m] = np.stack([s.b for s in samples]) + np.einsum("bij,bj->bi",
                                                            np.stack([s.FtG for s in samples]), qr)
    g[:, m:] = -qr / gam[:, None]
    tol = 1e-13 * np.maximum(1.0, np.abs(g).max(axis=1))
    free = np.stack([s.free for s in samples])
    best, backup = np.full(B, nv + 1), np.full(B, 3)
    eye, y, todo = np.eye(nv), np.zeros((B, nv)), np.arange(B)
    for _ in range(_MAX_PIVOTS):
        f, Ht = free[todo], H[todo]
        M = Ht * (f[:, :, None] & f[:, None, :]) + eye * ~f[:, None, :]
        yt = np.linalg.solve(M, (-g[todo] * f)[:, :, None])[:, :, 0]
        yt[~f] = 0.0
        grad = np.einsum("bij,bj->bi", Ht, yt) + g[todo]
        tl = tol[todo, None]
        bad = np.where(f, yt < -tl, grad < -tl)
        y[todo] = yt
        nbad = bad.sum(axis=1)
        keep = nbad > 0
        if not keep.any():
            todo = todo[:0]
            break
        todo, bad, nbad = todo[keep], bad[keep], nbad[keep]
        improve = nbad < best[todo]
        use_backup = ~improve & (backup[todo] > 0)
        murty = ~improve & ~use_backup
        best[todo[improve]] = nbad[improve]
        backup[todo[improve]] = 3
        backup[todo[use_backup]] -= 1
        flip = bad.copy()
        if murty.any():
            last = nv - 1 - np.argmax(bad[murty][:, ::-1], axis=1)
            flip[murty] = False
            flip[np.flatnonzero(murty), last] = True
        free[todo] ^= flip
    if todo.size:
        raise RuntimeError("violation-loss QP: block pivoting did not terminate "
                           f"in {_MAX_PIVOTS} rounds")
    lam = np.maximum(y[:, :m], 0.0)
    w0 = qr + np.einsum("bij,bj->bi", F, lam)
    eta = np.maximum(w0 - gam[:, None] * lam, 0.0)
    yp = np.concatenate((lam, eta), axis=1)
    kkt = np.abs(np.minimum(yp, np.einsum("bij,bj->bi", H, yp) + g)).max(axis=1)
    w = np.minimum(w0, gam[:, None] * lam)
    e = np.einsum("bij,bj->bi", np.stack([s.D for s in samples]), lam) + np.stack(
        [s.z for s in samples])
    Qe = np.einsum("bij,bj->bi", np.stack([s.Qd for s in samples]), e)
    loss = 0.5 * np.einsum("bi,bi->b", e, Qe) + (
        np.einsum("bi,bi->b", lam, eta) + np.einsum("bi,bi->b", w, w) / (2 * gam)) / eps
    grad = w / (eps * gam)[:, None]
    for i, s in enumerate(samples):
        s.free = free[i]
    for i in np.flatnonzero(kkt > KKT_TOL):
        sol = solve_sample(samples[i], r)
        lam[i], eta[i], loss[i], grad[i], kkt[i] = (sol.lam, sol.eta, sol.loss, sol.grad,
                                                    sol.kkt)
    return lam, eta, loss, grad, kkt


def batch_loss_and_grad(samples: Sequence[PreparedSample], r) -> tuple[float, np.ndarray, int]:
    """Mean loss and gradient over the samples; returns (loss, grad, n_used). Samples with
    a non-finite solution are skipped; with none usable: NaN loss, zero gradient."""
    r = np.asarray(r, float)
    samples = list(samples)
    if not samples:
        return float("nan"), np.zeros(r.shape[0]), 0
    _, _, loss, grad, _ = solve_batch(samples, r)
    ok = np.isfinite(loss) & np.isfinite(grad).all(axis=1)
    used = int(ok.sum())
    if used == 0:
        return float("nan"), np.zeros(r.shape[0]), 0
    return float(loss[ok].mean()), grad[ok].mean(axis=0), used


# --------------------------------------------------------------------------- Adam
def adam_update(grad, m1, m2, t: int, options: LearnerOptions, mask=None):
    """One Adam step; returns (delta, m1, m2, t), delta the change to add to r. Entries
    outside the mask keep their moments and get a zero delta; delta is clipped to
    +-options.max_step; a non-finite gradient gives a zero delta and no state change.
    The step size is options.learning_rate / (1 + t / lr_decay_steps) if that is > 0."""
    grad = np.asarray(grad, float)
    mask = np.ones(grad.shape[0], bool) if mask is None else np.asarray(mask, bool)
    if not np.isfinite(grad).all():
        return np.zeros_like(grad), m1, m2, t
    b1, b2 = options.beta1, options.beta2
    t = int(t) + 1
    g = np.where(mask, grad, 0.0)
    m1 = np.where(mask, b1 * m1 + (1 - b1) * g, m1)
    m2 = np.where(mask, b2 * m2 + (1 - b2) * g * g, m2)
    mhat = m1 / (1 - b1 ** t)
    vhat = m2 / (1 - b2 ** t)
    lr = options.learning_rate
    if options.lr_decay_steps > 0:
        lr = lr / (1.0 + t / options.lr_decay_steps)
    delta = -lr * mhat / (np.sqrt(vhat) + options.adam_eps)
    delta = np.clip(np.where(mask, delta, 0.0), -options.max_step, options.max_step)
    return delta, m1, m2, t


@dataclass(frozen=True)
class StepResult:
    """What one learner step did: batch loss (before the step), mean gradient, the change
    applied to r, samples used and samples rejected (non-finite) in this call."""

    loss: float
    grad: np.ndarray
    delta: np.ndarray
    used: int
    rejected: int


def _check_r(r, m) -> np.ndarray:
    r = np.asarray(r, float).reshape(-1)
    if r.shape != (m,):
        raise ValueError(f"residual has {r.size} entries, the LCS has m={m}")
    if not np.isfinite(r).all():
        raise ValueError("residual has non-finite entries")
    return r


class ViolationLossLearner:
    """The residual r_comp with its Adam state; `step` is Algorithm 1 on one batch."""

    def __init__(self, options: LearnerOptions, num_lambda: int, initial_residual=None):
        self.options = options
        self.num_lambda = int(num_lambda)
        self.mask = options.mask_array(self.num_lambda)
        self.r = (np.zeros(self.num_lambda) if initial_residual is None
                  else _check_r(initial_residual, self.num_lambda).copy())
        self.m1, self.m2, self.t = np.zeros(self.num_lambda), np.zeros(self.num_lambda), 0
        self.num_rejected = 0  # non-finite transitions refused so far
        self._Qd_cache: dict[int, np.ndarray] = {}

    def prepare(self, x_next, x, u, lcs: Lcs) -> PreparedSample | None:
        """QP data for one transition; None (and counted) if it has non-finite entries."""
        if lcs.num_lambda != self.num_lambda:
            raise ValueError(f"LCS has m={lcs.num_lambda}, the learner m={self.num_lambda}")
        n = lcs.num_states
        if n not in self._Qd_cache:
            self._Qd_cache[n] = qd_matrix(self.options.Qd, n)
        Q = self._Qd_cache[n]
        s = prepare_sample(x_next, x, u, lcs, self.options.epsilon, self.options.gamma, Q)
        if s is None:
            self.num_rejected += 1
        return s

    def loss_and_grad(self, samples: Iterable[PreparedSample | None]):
        """(mean loss, mean gradient, used) at the current r; None entries are skipped."""
        return batch_loss_and_grad([s for s in samples if s is not None], self.r)

    def step(self, samples: Iterable[PreparedSample | None]) -> StepResult:
        """One Adam step on the batch (None entries, i.e. rejected samples, are skipped)."""
        samples = list(samples)
        good = [s for s in samples if s is not None]
        loss, grad, used = batch_loss_and_grad(good, self.r)
        rejected = len(samples) - used
        if used == 0:
            return StepResult(loss, grad, np.zeros(self.num_lambda), 0, rejected)
        delta, self.m1, self.m2, self.t = adam_update(grad, self.m1, self.m2, self.t,
                                                      self.options, self.mask)
        self.r = self.r + delta
        return StepResult(loss, grad, delta, used, rejected)

    def step_transitions(self, transitions) -> StepResult:
        """Prepare (x_next, x, u, lcs) tuples and take one step on them."""
        return self.step([self.prepare(*t) for t in transitions])
