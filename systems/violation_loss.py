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

How the QP is solved (exactly, not approximately):

* Scaling. eps can be 1e-7, so the unscaled objective mixes terms ~9 orders of magnitude apart. We solve
  J(y) = eps * l(y) = 1/2 y' H y + g' y + const instead, with
      H = [[eps D'Qd D + F'F/gamma, I - F'/gamma], [I - F/gamma, I/gamma]],
      g = [eps D'Qd z + F'(q + r)/gamma, -(q + r)/gamma],
  whose entries are O(1/gamma) whatever eps is (the eps term only adds).
* Method. Block principal pivoting (Judice & Pires) on the KKT conditions of the
  bound-constrained QP, which are the LCP y >= 0, H y + g >= 0, y'(H y + g) = 0 with H
  positive definite: guess the free set, solve H_FF y_F = -g_F (one small dense solve),
  flip every infeasible index; after 3 rounds without fewer infeasibilities it falls back
  to Murty's single least-index flip, which is finite for P-matrices. It enumerates
  nothing; warm-started from the free set of the previous call for the same sample it
  usually stops after one solve.
* Polishing. Given lam, the best eta is closed-form, eta = max(0, q + r + F lam -
  gamma lam), so after the pivoting lam is clipped at 0 and eta recomputed; then
  w* = min(q + r + F lam, gamma lam) element-wise. In the "neither" case (no contact in
  the data, none predicted) lam* = 0 exactly and so the gradient is exactly zero.
* Exactness. Every solve is checked: the KKT residual is the natural residual
  max_i |min(y_i, (H y + g)_i)| of the eps-scaled problem J, i.e. an absolute error in
  the units of q (distance, for the lam rows) and of lam (for the eta rows). It must be
  <= KKT_TOL = 1e-8, else RuntimeError. (For the unscaled l the same point has residual
  KKT/eps: the tolerance is deliberately stated on J.)

Batched loss and gradient are the mean over the buffer. `adam_update` is Adam with a
mask of learned entries and a hard clip of each update to +-max_step (default 0.01, the
units of c): one bad batch cannot move any residual entry by more than max_step.

Q_d for the cart-pole: the state mixes positions and velocities, but one LCS step at
dt = 0.01 moves positions by dt*velocity, so D (and z from contact) sit almost entirely
in the velocity rows; Q_d = I weights the velocity error and is what we use (positions
add nothing that velocities do not already show).

About eps (and Q_d). The minimiser (lam*, eta*) depends on eps only through eps Q_d;
eps alone scales l and dl/dr by 1/eps, which Adam's normalisation ignores. Where the
model (with r) predicts no contact, q + r >= 0, the KKT conditions of lam = 0,
eta = q + r show the gradient is exactly zero iff also
    q + r + eps D'Qd z >= 0.
Where the model predicts contact ("both" with a wrong model, "predicted only") the
gradient is nonzero for any eps (it vanishes only where the model explains the data). Where only the data has contact (z = -D lam_true) it
is nonzero only where the model's gap q + r is below eps (D'Qd D lam_true): next to the
true contact boundary (lam_true -> 0) there is always a band of zero gradient, of width
|dc| / (1 + eps a k) in the contact distance (dc the model's offset error,
a = (D'Qd D)_ii, k the contact stiffness). Cart-pole with Q_d = I (a = 8.1e-3, k = 50,
dc = 0.15 m): eps = 1e-3 leaves the whole contact-only region flat, eps = 1 about 70 % of it, eps = 100 a band of 3.7 mm of pole-tip travel.
So for the cart-pole use Q_d = I, eps = 100 (the dynamics and violation terms are then
of the same size), gamma = 1e-2 (sigma_min(F + F') = 0.04). The paper's eps = 1e-7 goes
with Q_d = 1e5 and the ball's much larger D.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Iterable, Sequence

import numpy as np

from adaptive_c3.systems.lcs import Lcs

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

    def __post_init__(self):
        check_epsilon(self.epsilon)
        g = float(self.gamma)
        if not np.isfinite(g) or g <= 0:
            raise ValueError(f"learner gamma must be > 0 (and < sigma_min(F + F')), got {g}")
        lr = float(self.learning_rate)
        if not np.isfinite(lr) or lr <= 0:
            raise ValueError(f"learner learning_rate must be > 0, got {lr}")
        if (isinstance(self.batch_size, bool) or int(self.batch_size) != self.batch_size
                or int(self.batch_size) < 1):
            raise ValueError(f"learner batch_size must be a positive integer, got "
                             f"{self.batch_size}")
        object.__setattr__(self, "batch_size", int(self.batch_size))
        ms = float(self.max_step)
        if not np.isfinite(ms) or ms <= 0:
            raise ValueError(f"learner max_step must be > 0, got {ms}")
        for name in ("beta1", "beta2"):
            b = float(getattr(self, name))
            if not 0.0 <= b < 1.0:
                raise ValueError(f"learner {name} must be in [0, 1), got {b}")
        ae = float(self.adam_eps)
        if not np.isfinite(ae) or ae <= 0:
            raise ValueError(f"learner adam_eps must be > 0, got {ae}")

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
    """Validate 0 < gamma < sigma_min(F + F'); returns sigma_min(F + F').

    F + F' must be positive definite (then its singular values are its eigenvalues);
    otherwise the loss is not convex in (lam, eta) and no gamma is valid.
    """
    F = np.asarray(F, float)
    g = float(gamma)
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
    if not np.all(np.isfinite(Q)):
        raise ValueError("learner Qd has non-finite entries")
    if not np.allclose(Q, Q.T, rtol=1e-12, atol=0.0):
        raise ValueError("learner Qd must be symmetric")
    if np.linalg.eigvalsh(Q)[0] < -1e-12 * max(1.0, np.abs(Q).max()):
        raise ValueError("learner Qd must be positive semidefinite")
    return Q


# --------------------------------------------------------------------------- samples
class PreparedSample:
    """One transition turned into its QP data (the r-independent parts).

    Holds z, q, D, F, Q_d, the eps-scaled Hessian H and b = eps D'Qd z. `free` is the
    warm-start guess of the free set and `_inv` caches the inverses of H's principal
    blocks for recently used free sets (updated by every solve; results never depend on
    them, only speed).
    """

    __slots__ = ("z", "q", "D", "F", "Qd", "H", "b", "epsilon", "gamma", "free", "FtG",
                 "_inv")

    def __init__(self, z, q, D, F, Qd, epsilon, gamma):
        m = q.shape[0]
        self.z, self.q, self.D, self.F, self.Qd = z, q, D, F, Qd
        self.epsilon, self.gamma = epsilon, gamma
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
        free = np.zeros(2 * m, dtype=bool)
        free[m:] = True  # the "no contact" guess: lam = 0, eta = q + r
        self.free = free
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

    Qd may be anything `qd_matrix` accepts (an n x n array is used as is). With
    check=True, epsilon and gamma are validated (ValueError) against this LCS's F.
    """
    n, k = lcs.num_states, lcs.num_inputs
    x_next = np.asarray(x_next, float).reshape(-1)
    x = np.asarray(x, float).reshape(-1)
    u = np.asarray(u, float).reshape(-1)
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
    """The inner QP's solution for one sample at residual r.

    lam, eta: the minimiser; loss: l_eps (unscaled); grad: dl/dr; w: q + F lam + r - eta;
    kkt: natural KKT residual of the eps-scaled QP; iterations: pivoting rounds.
    """

    lam: np.ndarray
    eta: np.ndarray
    loss: float
    grad: np.ndarray
    w: np.ndarray
    kkt: float
    iterations: int


def _pivot(s: PreparedSample, g, tol):
    """Block principal pivoting for min 1/2 y'Hy + g'y s.t. y >= 0 (H PD).

    Returns (y, free, rounds). Starts from s.free.
    """
    H = s.H
    free = s.free
    best = g.shape[0] + 1
    backup = 3
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
    """Solve the QPs of several samples (same m and n) at r together, vectorised.

    The same block pivoting as `solve_sample`, run on all samples at once: a free set F
    is solved as the masked system (H on F x F, identity elsewhere) with one batched
    LU call per round. Returns (lam [B, m], eta [B, m], loss [B], grad [B, m], kkt [B]).
    Samples whose batched solve misses KKT_TOL are re-solved one by one (with refinement).
    """
    B = len(samples)
    m = samples[0].q.shape[0]
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
    best = np.full(B, nv + 1)
    backup = np.full(B, 3)
    eye = np.eye(nv)
    y = np.zeros((B, nv))
    todo = np.arange(B)
    for _ in range(_MAX_PIVOTS):
        f = free[todo]
        Ht = H[todo]
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
    """Mean loss and mean gradient over the samples; returns (loss, grad, n_used).

    Samples whose solution is non-finite are skipped (not counted in the mean); with no
    usable sample the loss is NaN and the gradient zero.
    """
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
    """One Adam step. Returns (delta, m1, m2, t) with delta the change to add to r.

    Entries outside the mask get no gradient, keep their moments and a zero delta. The
    delta is clipped element-wise to +-options.max_step. A non-finite gradient gives a
    zero delta and leaves the state unchanged.
    """
    grad = np.asarray(grad, float)
    mask = np.ones(grad.shape[0], bool) if mask is None else np.asarray(mask, bool)
    if not np.all(np.isfinite(grad)):
        return np.zeros_like(grad), m1, m2, t
    b1, b2 = options.beta1, options.beta2
    t = int(t) + 1
    g = np.where(mask, grad, 0.0)
    m1 = np.where(mask, b1 * m1 + (1 - b1) * g, m1)
    m2 = np.where(mask, b2 * m2 + (1 - b2) * g * g, m2)
    mhat = m1 / (1 - b1 ** t)
    vhat = m2 / (1 - b2 ** t)
    delta = -options.learning_rate * mhat / (np.sqrt(vhat) + options.adam_eps)
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
    if not np.all(np.isfinite(r)):
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
        self.m1 = np.zeros(self.num_lambda)
        self.m2 = np.zeros(self.num_lambda)
        self.t = 0
        self.num_rejected = 0  # non-finite transitions refused so far
        self._Qd_cache: dict[int, np.ndarray] = {}

    def prepare(self, x_next, x, u, lcs: Lcs) -> PreparedSample | None:
        """QP data for one transition; None (and counted) if it has non-finite entries."""
        if lcs.num_lambda != self.num_lambda:
            raise ValueError(f"LCS has m={lcs.num_lambda}, the learner m={self.num_lambda}")
        n = lcs.num_states
        Q = self._Qd_cache.get(n)
        if Q is None:
            Q = self._Qd_cache[n] = qd_matrix(self.options.Qd, n)
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
