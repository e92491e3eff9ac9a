"""Fit candidate effects, pick the one(s) held-out data support, give 95% intervals.

Fit: each candidate's parameters minimise the noise-normalised multi-step prediction
error (open-loop rollouts of `horizon` steps from recorded states with recorded inputs):
a coarse grid over the physical range, then a bounded Levenberg-Marquardt (least
squares) from the best grid point.

Held-out scoring is K-fold cross-validation (K = 3) over episodes (or over time blocks
when there are fewer than three episodes): every window is predicted by parameters
fitted on the other folds, so every contact event in the recording is used both to
fit (in two folds) and to test (in one); a single train/test split can leave, say, all
contact with one wall in the training part. The reported values and intervals come from
the fit on all the data.

Intervals: a cluster-robust sandwich at the optimum, cov = (J'J)^-1 (sum_c g_c g_c')
(J'J)^-1 with g_c = J_c' r_c summed over blocks of 50 steps (overlapping rollout windows
are strongly correlated); plus a bias allowance: the shift of the estimate when refitted
with half the rollout horizon (noisy start states bias the fit, the more so the shorter
the rollout), sd^2 + shift^2; 95% = +-1.96 sd. For the chosen effect the sd is the
larger of that and a delete-one-episode jackknife (the sandwich is too narrow when the
information sits in few events, e.g. contacts), with the Student t quantile for
(episodes - 1) degrees of freedom; and the shift of the chosen effect when refitted with
the spec's nuisances free (widen_for_nuisance) is added to its sd.

Choosing among the fits: engine/selection.py.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
from scipy.stats import rankdata, t as student_t

from adaptive_c3.tools.diagnosis.backends.effects import Candidate, patch, rollout
from adaptive_c3.tools.diagnosis.engine.locate import LAG, Windows


@dataclass
class Problem:
    spec: object
    base: list                 # effects already in the scenario: [(Candidate, params)]
    windows: Windows           # all rollout windows
    fold: np.ndarray           # [W] fold id (0..K-1), -1 = not used
    weight: np.ndarray         # [H, n] = 1 / prediction floor
    cluster_steps: int = 50
    min_reduction: float | None = None   # significance: held-out SSR cut (None: the spec's)
    min_z: float = -np.inf               # ... and z against the unmodified model
    z_stat: str = "paired"               # the cluster statistic of every z (cluster_z)

    @property
    def horizon(self) -> int:
        return self.weight.shape[0]

    @property
    def folds(self) -> list:
        return sorted(int(k) for k in np.unique(self.fold) if k >= 0)

    def used(self) -> Windows:
        return self.windows.take(self.fold >= 0)

    def train(self, k) -> Windows:
        return self.windows.take((self.fold >= 0) & (self.fold != k))

    def test(self, k) -> Windows:
        return self.windows.take(self.fold == k)

    def truncated(self, horizon: int) -> "Problem":
        """The same problem with shorter rollouts (for the horizon-sensitivity check)."""
        W = self.windows
        cut = Windows(W.X0, W.Xt[:, :horizon], W.U[:, :LAG + horizon], W.row, W.episode, W.t0)
        return replace(self, windows=cut, weight=self.weight[:horizon])

    def present(self, c) -> np.ndarray:
        """The value candidate `c` has in the base model (a kept nuisance; the last one
        listed, which the patch applies last), else its nominal value."""
        return next((np.asarray(v, float) for b, v in reversed(self.base) if b == c),
                    np.asarray(c.nominal(self.spec), float))

    def residuals(self, effects, W: Windows) -> np.ndarray:
        """[W, H, n] normalised rollout residuals of the model with `effects` added."""
        P = patch(self.spec, self.base + list(effects))
        X, _ = rollout(P, W.X0, W.U, self.horizon, LAG, W.row)
        r = (X - W.Xt) * self.weight
        return np.where(np.isfinite(r), r, 1e6)

    def clusters(self, W: Windows) -> np.ndarray:
        ids = W.episode * 100000 + (W.row // self.cluster_steps)
        return np.unique(ids, return_inverse=True)[1]


@dataclass
class Fit:
    cands: tuple               # Candidates
    values: np.ndarray         # fitted on all the data
    ci: np.ndarray             # [p, 2]
    sd: np.ndarray
    train_ssr: float
    fold_values: dict = field(default_factory=dict)   # fold -> values fitted without it
    test_ssr: float = np.nan   # cross-validated
    test_n: int = 0
    test_cluster_ssr: np.ndarray = field(default_factory=lambda: np.zeros(0))
    test_window_ssr: np.ndarray = field(default_factory=lambda: np.zeros(0))
    score: float = np.nan
    z_vs_none: float = 0.0
    z_stat: str = "paired"     # the statistic of z_vs_none (its problem's cluster_z)
    reduction: float = 0.0
    significant: bool = False
    shift: np.ndarray = field(default_factory=lambda: np.zeros(0))
    lin: tuple | None = field(default=None, repr=False)   # (r, J', lo, hi, [W, H, n])

    @property
    def num_params(self) -> int:
        return len(self.values)

    def effects(self, spec, values=None):
        return _split(self.values if values is None else values, self.cands, spec)

    def fold_effects(self, spec, k):
        return self.effects(spec, self.fold_values.get(k, self.values))

    def label(self) -> str:
        return " + ".join(c.label() for c in self.cands) or "none"

    @property
    def physical(self) -> bool:
        return all(c.definition().physical for c in self.cands)


def _split(theta, cands, spec):
    out, i = [], 0
    for c in cands:
        p = c.num_params(spec)
        out.append((c, np.asarray(theta[i:i + p], float)))
        i += p
    return out


def bounds_of(cands, spec) -> tuple[np.ndarray, np.ndarray]:
    """(lower, upper) bounds of the stacked parameters of a candidate list."""
    return (np.concatenate([c.bounds(spec)[0] for c in cands]),
            np.concatenate([c.bounds(spec)[1] for c in cands]))


def fit_candidates(prob: Problem, cands, init=None, ci: bool = True, W=None) -> Fit:
    """Least-squares fit of one candidate or a set (jointly) on windows W (default: all)."""
    spec = prob.spec
    W = prob.used() if W is None else W
    lo, hi = bounds_of(cands, spec)

    def fun(theta):
        return prob.residuals(_split(theta, cands, spec), W).ravel()

    if init is None:
        if len(cands) == 1 and cands[0].num_params(spec) == 1:
            grid = cands[0].definition().grid(spec, cands[0].target)
            grid = (getattr(spec, "grids", None) or {}).get(cands[0].name, grid)
            npts = getattr(spec, "grid_points", 0)
            if npts and len(grid) > npts:       # costly models: a coarser grid
                grid = grid[np.unique(np.linspace(0, len(grid) - 1, npts).round().astype(int))]
            costs = [np.sum(fun(np.array([g])) ** 2) for g in grid]
            init = np.array([grid[int(np.argmin(costs))]])
            halvings = getattr(spec, "grid_halvings", 0)
            if halvings:
                init = _refine_on_grid(fun, np.asarray(grid, float), np.asarray(costs), lo, hi,
                                       halvings)
        else:
            init = np.concatenate([c.nominal(spec) for c in cands])
    init = np.clip(np.asarray(init, float), lo + 1e-12, hi - 1e-12)
    scale = np.maximum(np.abs(hi - lo) / 20.0, 1e-6)
    ftol, xtol = getattr(spec, "fit_tolerance", (1e-10, 1e-9))
    theta, r, Jt = levenberg_marquardt(fun, init, lo, hi, scale, ftol=ftol, xtol=xtol,
                                       jac_step=getattr(spec, "jacobian_step", 1e-4))
    lin = (r, Jt, lo, hi, (len(W), prob.horizon, -1))
    if not ci:
        return Fit(tuple(cands), theta, np.zeros((len(theta), 2)), np.zeros(len(theta)),
                   float(r @ r), lin=lin)
    sd = _sandwich_sd(Jt, r, prob.clusters(W), W)
    ci = np.stack([theta - 1.96 * sd, theta + 1.96 * sd], 1)
    return Fit(tuple(cands), theta, ci, sd, float(r @ r), lin=lin)


def _refine_on_grid(fun, grid, costs, lo, hi, halvings: int) -> np.ndarray:
    """A start for LM on a coarse grid (spec.grid_halvings): from the best grid point, try the
    points half-way to each neighbour, keep the best, and halve again. A Gauss-Newton step
    from a grid point can point the wrong way where the residuals bend sharply (a contact
    that opens: dev draw 80022's EE-ball offset of 2.8 mm started at the 4 mm point, whose
    cost was 1.6x the optimum's, and LM never left it)."""
    i = int(np.argmin(costs))
    x, c = float(grid[i]), float(costs[i])
    half = 0.5 * float(np.min(np.diff(grid))) if len(grid) > 1 else 0.0
    for _ in range(halvings if half > 0 else 0):
        trial = [t for t in (x - half, x + half) if lo[0] <= t <= hi[0]]
        tc = [float(np.sum(fun(np.array([t])) ** 2)) for t in trial]
        if tc and min(tc) < c:
            x, c = trial[int(np.argmin(tc))], min(tc)
        half *= 0.5
    return np.array([x])


def _linear(prob: Problem) -> bool:
    """Refits (folds, jackknife, half horizon) by one Gauss-Newton step (costly models)."""
    return bool(getattr(prob.spec, "linear_refits", False))


def linear_refit(fit: Fit, keep=None, horizon: int | None = None) -> np.ndarray:
    """The refit's values on a subset of the windows (keep [W] bool) and/or the first
    `horizon` rollout steps, as one Gauss-Newton step from the all-data optimum with the
    residuals and Jacobian already there (no rollout; the infinitesimal jackknife)."""
    r, Jt, lo, hi, shape = fit.lin
    R = r.reshape(shape)
    J = Jt.reshape((len(Jt),) + R.shape)
    if keep is not None:
        R, J = R[keep], J[:, keep]
    if horizon is not None:
        R, J = R[:, :horizon], J[:, :, :horizon]
    Jf = J.reshape(len(J), -1)
    A = Jf @ Jf.T
    step = -np.linalg.solve(A + 1e-9 * np.trace(A) * np.eye(len(A)) + 1e-300, Jf @ R.ravel())
    return np.clip(fit.values + step, lo, hi)


# a subset that leaves out more than this share of a parameter's information is refitted
# by the model, not by one Gauss-Newton step (subset_refit)
LINEAR_REFIT_MAX_DROP = 0.5


def window_information(fit: Fit) -> np.ndarray:
    """[p, W] each parameter's information per fit window: the sum of its squared
    sensitivities (fit.lin's Jacobian) over the window's residuals."""
    Jt, shape = fit.lin[1], fit.lin[4]
    return np.sum(Jt.reshape((len(Jt), shape[0], -1)) ** 2, axis=2)


def subset_refit(prob: Problem, fit: Fit, keep: np.ndarray) -> np.ndarray:
    """The fit's values refitted on the used windows `keep` ([W] bool): by one Gauss-Newton
    step from the all-data optimum on a costly model (linear_refit), unless the windows
    left out hold more than LINEAR_REFIT_MAX_DROP of a parameter's information (sum of
    squared sensitivities); then, as on a cheap model, by the model itself from the fit's
    values. The step is a small-change estimate: it extrapolates the kept windows'
    residuals linearly from the all-data optimum, and where those windows see the
    parameter weakly or curved it stops short or overshoots (tests/test_diagnose_subset_
    refit.py: halfway to the kept windows' optimum). Where
    one coast carries a rolling resistance (development draw 90106, 3.7 mm: 99.8 % of the
    free windows' information in one group of episodes) the model's refit without it
    read 6.2 mm and the step 6.3 mm: there the rests themselves prefer a larger value."""
    keep = np.asarray(keep, bool)
    if _linear(prob):
        info = window_information(fit)
        dropped = info[:, ~keep].sum(axis=1) / np.maximum(info.sum(axis=1), 1e-300)
        if np.all(dropped <= LINEAR_REFIT_MAX_DROP):
            return linear_refit(fit, keep=keep)
    return fit_candidates(prob, list(fit.cands), init=fit.values, ci=False,
                          W=prob.used().take(keep)).values


def cv_fit(prob: Problem, cands, init=None) -> Fit:
    """Fit on all the data (grid + LM), then once per fold without that fold."""
    fit = fit_candidates(prob, cands, init)
    used_fold = prob.fold[prob.fold >= 0]
    for k in prob.folds:
        fit.fold_values[k] = subset_refit(prob, fit, used_fold != k)
    return fit


def widen_for_bias(prob: Problem, fit: Fit) -> Fit:
    """Add the horizon sensitivity to the sandwich interval (see the module doc)."""
    half = max(prob.horizon // 2, 1)
    short = (linear_refit(fit, horizon=half) if _linear(prob) else
             fit_candidates(prob.truncated(half), list(fit.cands), init=fit.values,
                            ci=False).values)
    fit.shift = fit.values - short
    fit.sd = np.sqrt(fit.sd ** 2 + fit.shift ** 2)
    fit.ci = np.stack([fit.values - 1.96 * fit.sd, fit.values + 1.96 * fit.sd], 1)
    return fit


def jackknife_groups(W: Windows, groups: int = 8) -> np.ndarray:
    """[W] the jackknife's group of each window: episodes dealt round-robin into `groups`
    (time blocks when there are fewer than four episodes)."""
    eps = np.unique(W.episode)
    if len(eps) >= 4:
        return np.searchsorted(eps, W.episode) % groups
    return (np.arange(len(W)) * groups) // len(W)


def jackknife(prob: Problem, fit: Fit, groups: int = 8) -> Fit:
    """Widen the chosen fit's interval with a delete-one-group jackknife over episodes
    (or time blocks) and the Student t quantile."""
    gid = jackknife_groups(prob.used(), groups)
    ids = np.unique(gid)
    if len(ids) < 3:
        return fit
    est = np.array([subset_refit(prob, fit, gid != g) for g in ids])
    G = len(ids)
    sd_jk = np.sqrt((G - 1) / G * np.sum((est - est.mean(0)) ** 2, 0))
    shift = fit.shift if len(fit.shift) else np.zeros_like(fit.values)
    fit.sd = np.sqrt(np.maximum(fit.sd ** 2, sd_jk ** 2 + shift ** 2))
    q = float(student_t.ppf(0.975, G - 1))
    fit.ci = np.stack([fit.values - q * fit.sd, fit.values + q * fit.sd], 1)
    return fit


def widen_for_nuisance(prob: Problem, fit: Fit, user_base: list, kept=()) -> Fit:
    """Nuisance allowance on the chosen fit's interval: the chosen effect refitted jointly
    with every nuisance of the spec free, from the user's model (`user_base`, without the
    nuisances `kept`, whose values start the refit); the shift of the effect's values is
    added to the interval's sd. A nuisance the held-out data did not pin down (a sensor
    delay or a calibration below significance) can still pull the estimate, and an
    interval that leaves it out is too narrow. A calibration of a contact pair that the
    effect itself offsets (contact_offset, r_comp) is left out: the two are one quantity,
    and the report gives their sum."""
    if fit is None:
        return fit
    offset_pairs = {c.target for c in fit.cands if c.name == "contact_offset"}
    if any(c.name == "r_comp" for c in fit.cands):
        offset_pairs |= set(getattr(prob.spec, "pair_names", ()))
    start = {f.cands[0]: f.values for f in kept}
    nuis = [Candidate(n, t) for n, t in getattr(prob.spec, "nuisance", ())
            if not (n == "calibration_offset" and t in offset_pairs)]
    nuis = [c for c in nuis if c not in fit.cands]
    if not nuis:
        return fit
    init = np.concatenate([fit.values] + [start.get(c, c.nominal(prob.spec)) for c in nuis])
    user = replace(prob, base=list(user_base))
    joint = fit_candidates(user, list(fit.cands) + nuis, init=init, ci=False)
    return add_to_interval(fit, joint.values[:fit.num_params] - fit.values)


def add_to_interval(fit: Fit, allowance: np.ndarray) -> Fit:
    """The interval widened by an allowance (per value, in the values' units) added to
    its sd in quadrature, at the interval's present quantile (1.96 or Student t)."""
    q = (fit.ci[:, 1] - fit.values) / np.maximum(fit.sd, 1e-300)
    fit.sd = np.sqrt(fit.sd ** 2 + np.asarray(allowance, float) ** 2)
    fit.ci = np.stack([fit.values - q * fit.sd, fit.values + q * fit.sd], 1)
    return fit


def _jacobian(fun, x, r, lo, hi, scale, jac_step: float = 1e-4):
    """The transposed Jacobian [p, N] (rows contiguous: p x p products stay cheap), by
    forward differences of jac_step * scale."""
    Jt = np.empty((len(x), r.size))
    for j in range(len(x)):
        h = jac_step * scale[j]
        if x[j] + h > hi[j]:
            h = -h
        xp = x.copy()
        xp[j] += h
        Jt[j] = (fun(xp) - r) / h
    return Jt


def levenberg_marquardt(fun, x0, lo, hi, scale, max_iter: int = 30, ftol: float = 1e-10,
                        xtol: float = 1e-9, jac_step: float = 1e-4):
    """Bounded (projected) Levenberg-Marquardt for a few parameters and many residuals.
    Returns (x, residuals at x, Jacobian at x). scipy's least_squares spends most of its
    time on n_residuals-sized linear algebra; here every step is a p x p solve. Stops when
    the cost falls by <= ftol (relative) or no parameter moves by more than xtol * scale.
    jac_step: the forward-difference step, relative to scale (a model solved to a
    tolerance, e.g. Drake's SAP, needs a larger one than the LCS's closed forms)."""
    x = np.asarray(x0, float).copy()
    r = fun(x)
    cost, mu = r @ r, 1e-3
    Jt = _jacobian(fun, x, r, lo, hi, scale, jac_step)
    for _ in range(max_iter):
        g, A = Jt @ r, Jt @ Jt.T
        diag = np.maximum(np.diag(A), 1e-12 * (np.trace(A) + 1e-30))
        improved = False
        while mu < 1e10:
            step = -np.linalg.solve(A + mu * np.diag(diag), g)
            xn = np.clip(x + step, lo, hi)
            rn = fun(xn)
            cn = rn @ rn
            if cn < cost:
                improved = True
                break
            mu *= 8.0
        if not improved:
            break
        done = (cost - cn) <= ftol * cost or np.all(np.abs(xn - x) <= xtol * scale)
        x, r, cost, mu = xn, rn, cn, max(mu / 4.0, 1e-9)
        Jt = _jacobian(fun, x, r, lo, hi, scale, jac_step)
        if done:
            break
    return x, r, Jt


def _sandwich_sd(Jt, r, cl, W: Windows) -> np.ndarray:
    p = Jt.shape[0]
    per = Jt.shape[1] // len(W)
    rw = r.reshape(len(W), per)
    g = np.stack([np.sum(Jt[j].reshape(len(W), per) * rw, 1) for j in range(p)], 1)
    C = cl.max() + 1
    gc = np.zeros((C, p))
    np.add.at(gc, cl, g)
    bread = np.linalg.pinv(Jt @ Jt.T)
    meat = gc.T @ gc * (C / max(C - 1, 1))
    cov = bread @ meat @ bread
    return np.sqrt(np.maximum(np.diag(cov), 0.0))


def evaluate(prob: Problem, fit: Fit | None):
    """Cross-validated SSR, residual count, per-cluster SSR and per-window SSR [W used, in
    prob.used() order] (fit None = the unmodified model)."""
    ssr, n, per_c = 0.0, 0, []
    used_fold = prob.fold[prob.fold >= 0]
    per_window = np.zeros(len(used_fold))
    for k in prob.folds:
        W = prob.test(k)
        effects = [] if fit is None else fit.fold_effects(prob.spec, k)
        r = prob.residuals(effects, W)
        per_w = np.sum(r.reshape(len(W), -1) ** 2, 1)
        per_window[used_fold == k] = per_w
        ssr += float(per_w.sum())
        n += r.size
        per_c.append(np.bincount(prob.clusters(W), weights=per_w))
    return ssr, n, np.concatenate(per_c) if per_c else np.zeros(0), per_window


def cluster_rows(prob: Problem) -> np.ndarray:
    """The recording row of each cluster's first window, in the order of evaluate's
    per-cluster SSR (fold by fold)."""
    out = []
    for k in prob.folds:
        W = prob.test(k)
        _, first = np.unique(prob.clusters(W), return_index=True)
        out.append(np.asarray(W.row)[first])
    return np.concatenate(out) if out else np.zeros(0, int)


def paired_z(a: np.ndarray, b: np.ndarray) -> float:
    """z of the mean per-cluster SSR reduction from a to b (positive = b better)."""
    d = a - b
    if len(d) < 2:
        return 0.0
    se = d.std(ddof=1) / np.sqrt(len(d))
    return float(d.mean() / se) if se > 0 else (np.inf if d.mean() > 0 else 0.0)


def signed_rank_z(a: np.ndarray, b: np.ndarray) -> float:
    """Wilcoxon signed-rank z of the per-cluster SSR reduction from a to b (positive = b
    better; normal approximation, zero differences dropped, tied ranks averaged). Unlike
    paired_z it counts how consistently the clusters gain, not how large the mean gain is
    against their spread: a gain carried by a few long coasts beside many small ones
    does not cap it, and a few large losses do not sink it."""
    d = np.asarray(a, float) - np.asarray(b, float)
    d = d[d != 0.0]
    n = len(d)
    if n < 2:
        return 0.0
    r = rankdata(np.abs(d))
    _, ties = np.unique(r, return_counts=True)
    var = n * (n + 1) * (2 * n + 1) / 24.0 - float(np.sum(ties ** 3 - ties)) / 48.0
    return float((r[d > 0].sum() - n * (n + 1) / 4.0) / np.sqrt(var)) if var > 0 else 0.0


Z_STATS = {"paired": paired_z, "signed_rank": signed_rank_z}


def cluster_z(a: np.ndarray, b: np.ndarray, stat: str = "paired") -> float:
    """z of the per-cluster SSR reduction from a to b by the named statistic (Z_STATS)."""
    return Z_STATS[stat](a, b)
