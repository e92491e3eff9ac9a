"""The baseline users would try: sparse regression of the one-step residual (SINDy-style).

The one-step residual of the model, r_k = x_{k+1} - f(x_k, u_k), weighted by the noise
floor, is regressed onto a library of candidate terms with sequentially thresholded
least squares (STLSQ, Brunton et al. 2016; our own implementation, no pysindy). To map
the result onto the same effect names, the library holds one column per physical
candidate of the effect library: its first-order effect on x_{k+1} at the nominal model,
d f / d theta (e.g. viscous damping on cart_x -> dt Minv[:, cart] * (-v_cart),
actuator_gain -> B u, contact_offset -> the change of the model's contact force),
so the coefficient of a term is the parameter's deviation in physical units. This is
the most favourable mapping a user could write; its blind spots are those of one-step
linear regression: contact the model does not predict (its sensitivity is zero there),
and effects whose one-step signature is below the noise.

Naming: no surviving term -> none; otherwise the term with the largest contribution
(RMS of coefficient x column, in noise units). Interval: OLS on the surviving terms.
"""
from __future__ import annotations

import numpy as np

from adaptive_c3.tools.diagnosis.backends.effects import applicable_candidates, patch, sensitivity_columns
from adaptive_c3.tools.diagnosis.engine.locate import (LAG, estimate_noise, make_windows, one_step,
                                               prediction_floor)

THRESHOLD = 0.1     # STLSQ threshold on standardised coefficients (noise-floor units)
RIDGE = 0.01        # ridge weight per sample on standardised columns (as pysindy's alpha)


def _ridge(X, y, alpha):
    A = X.T @ X + alpha * len(y) * np.eye(X.shape[1])
    return np.linalg.solve(A, X.T @ y)


def stlsq(X: np.ndarray, y: np.ndarray, threshold: float = THRESHOLD, iters: int = 10,
          alpha: float = RIDGE):
    """Sequentially thresholded ridge regression (pysindy's STLSQ) on standardised columns.
    Returns (coefficients in the original column units, active mask)."""
    norm = np.sqrt(np.mean(X ** 2, 0))
    norm = np.where(norm > 0, norm, 1.0)
    Xs = X / norm
    active = np.sqrt(np.mean(X ** 2, 0)) > 0
    xi = np.zeros(X.shape[1])
    for _ in range(iters):
        xi = np.zeros(X.shape[1])
        if not active.any():
            break
        xi[active] = _ridge(Xs[:, active], y, alpha)
        new = active & (np.abs(xi) >= threshold)
        if np.array_equal(new, active):
            break
        active = new
    xi[~active] = 0.0
    return xi / norm, active, norm


def sindy_diagnose(rec, spec, base=(), train_mask=None) -> dict:
    """Name an effect by sparse regression. Returns a dict in the report's `selected` form
    plus `terms` (all surviving terms)."""
    base = list(base)
    if hasattr(spec, "prepare"):          # time-varying models (ball rolling)
        spec.prepare(rec)
    P0 = patch(spec, base)
    W1 = make_windows(rec, 1)
    sigma = estimate_noise(P0, W1)
    floor1 = prediction_floor(P0, sigma, 1)[0]
    if train_mask is not None:
        W1 = W1.take(train_mask(W1))
    e, _ = one_step(P0, W1)
    cands = [c for c in applicable_candidates(spec)[0] if c.definition().physical]
    S = sensitivity_columns(spec, cands, W1.X0, W1.U, LAG, base_effects=base,
                            rows=W1.row)                                      # [W, n, C]
    w = getattr(spec, "fit_weight", None)
    keep = np.ones(S.shape[1], bool) if w is None else np.asarray(w) > 0     # fitted states
    X = (S / floor1[None, :, None])[:, keep].reshape(-1, len(cands))
    y = (e / floor1)[:, keep].reshape(-1)
    xi, active, norm = stlsq(X, y)
    contrib = np.abs(xi) * norm
    terms = []
    if active.any():
        Xa = X[:, active]
        coef = np.linalg.lstsq(Xa, y, rcond=None)[0]
        res = y - Xa @ coef
        s2 = res @ res / max(len(y) - active.sum(), 1)
        sd = np.sqrt(np.diag(np.linalg.pinv(Xa.T @ Xa)) * s2)
        for k, j in enumerate(np.flatnonzero(active)):
            c = cands[j]
            val = float(c.nominal(spec)[0] + coef[k])
            terms.append(dict(name=c.name, target=c.target, contribution=float(contrib[j]),
                              params=[dict(name=c.param_names(spec)[0], value=val,
                                           unit=c.units(spec)[0],
                                           ci95=[val - 1.96 * sd[k], val + 1.96 * sd[k]])]))
        terms.sort(key=lambda t: -t["contribution"])
    selected = [terms[0]] if terms else [{"name": "none"}]
    return dict(selected=selected, terms=terms)
