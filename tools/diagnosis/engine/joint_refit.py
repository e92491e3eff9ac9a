"""The chosen effect re-estimated jointly with the calibration offsets kept as nuisance.

Nuisances are fitted first, before any effect (selection.fit_nuisance), and each candidate is
then fitted with them held. Where a calibration offset and the effect move the same
quantity, the calibration takes up part of the effect and the effect's fit keeps only
the rest: a table raised by c lifts a pressed ball, and so the EE over it, as an EE-ball
gap closed by c does. Dev draw 90010 recorded with no second-engine variation (true
EE-ball offset -2.18 mm, table exact): the table calibrated to -0.62 mm, then the offset
read -1.68 mm; jointly (-2.11, -0.08) mm cut the fit's SSR from 20776 to 17280. On the
ninth evaluation set the EE-ball offsets read 0.2-1 mm from the truth with intervals
0.05-1 mm wide.

A gradient refit does not leave the sequential point on Drake's plant (its cost is a
staircase of contact events, engine/held_out.py; on draw 90010 widen_for_nuisance's joint
LM returned its start), so the refit is a Nelder-Mead simplex in steps of value_scale (the
fit grid's resolution): on all the fit windows, then per fold (the effect alone, the
calibrations at their joint values) so that the held-out scores stay out-of-fold. Where
no calibration is kept the simplex polishes the effect alone: LM also stops at its grid
start there (dev draws 90055 and 90026, EE-ball offsets of 1.66 and 2.24 mm, both read
2.50 mm, a grid point; 2.06 and 2.31 after). The effect's interval is recentred on the
new value; its sd is the larger of the one it had and the joint sandwich's (which carries
the effect's correlation with the calibration).

A calibration of the pair the effect offsets itself is not refitted: the two are one
quantity and the report gives their sum (report.calibration_shift). Specs opt in with
`rugged_cost` (the LCS's measured model form, BallSpec.model_form_bias, was calibrated on
the sequential fit).
"""
from __future__ import annotations

import copy

import numpy as np
from scipy.optimize import minimize

from adaptive_c3.tools.diagnosis.engine.fit import (Fit, Problem, _jacobian, _sandwich_sd,
                                                    _split, bounds_of)
from adaptive_c3.tools.diagnosis.engine.selection import score_fit

SIMPLEX_STEP = 0.5           # the first simplex: this share of each value_scale
X_TOL = 0.05                 # ... stop when it is this small (in those steps)
MAX_ROLLOUTS = 40            # cost evaluations on all windows (per fold: half)


def value_scale(spec, cand) -> float:
    """A resolution of a candidate's values: the spacing of its fit grid (spec.grids, or
    the effect's own), refined by the spec's grid_halvings (Drake's EE-ball offset: 2 mm
    halved twice, 0.5 mm)."""
    grid = (getattr(spec, "grids", None) or {}).get(cand.name)
    if grid is None:
        grid = cand.definition().grid(spec, cand.target)
    grid = np.unique(np.asarray(grid, float))
    spacing = float(np.min(np.diff(grid))) if len(grid) > 1 else 1.0
    return spacing / 2 ** int(getattr(spec, "grid_halvings", 0))


def _offset_pairs(fit: Fit, spec) -> set:
    pairs = {c.target for c in fit.cands if c.name == "contact_offset"}
    if any(c.name == "r_comp" for c in fit.cands):
        pairs |= set(getattr(spec, "pair_names", ()))
    return pairs


def simplex_fit(prob: Problem, cands, x0, W, max_rollouts: int) -> tuple[np.ndarray, float]:
    """Nelder-Mead on the summed squared residuals over windows W, from x0 (bounded)."""
    spec = prob.spec
    lo, hi = bounds_of(cands, spec)
    step = np.concatenate([np.full(c.num_params(spec), SIMPLEX_STEP * value_scale(spec, c))
                           for c in cands])
    x0 = np.clip(np.asarray(x0, float), lo, hi)

    def cost(z):
        r = prob.residuals(_split(x0 + z * step, cands, spec), W)
        return float(np.sum(r ** 2))

    n = len(x0)
    simplex = np.vstack([np.zeros(n), np.eye(n)])
    res = minimize(cost, np.zeros(n), method="Nelder-Mead",
                   bounds=list(zip((lo - x0) / step, (hi - x0) / step)),
                   options=dict(initial_simplex=simplex, xatol=X_TOL, fatol=1e-6 * cost(simplex[0]),
                                maxfev=max_rollouts))
    return np.clip(x0 + res.x * step, lo, hi), float(res.fun)


def refit_with_calibration(prob: Problem, fit: Fit | None, kept: list, none_eval) -> Fit | None:
    """Refit `fit` (the chosen effect) by a simplex with the calibration offsets among `kept`
    (fit_nuisance's fits, whose effects are in prob.base) free, if any. On a lower cost than
    the sequential fit's, the fit's values, fold values, scores and interval, the kept
    calibrations' values and prob.base change in place. Returns the fit."""
    spec = prob.spec
    if fit is None or not getattr(spec, "rugged_cost", False):
        return fit
    pairs = _offset_pairs(fit, spec)
    cals = [f for f in kept if len(f.cands) == 1 and f.cands[0].name == "calibration_offset"
            and f.cands[0].target not in pairs]
    cal_cands = [f.cands[0] for f in cals]
    rest = [(c, p) for c, p in prob.base if c not in cal_cands]
    joint_prob = copy.copy(prob)
    joint_prob.base = rest
    cands = list(fit.cands) + cal_cands
    x_seq = np.concatenate([fit.values] + [f.values for f in cals])
    W = prob.used()
    r_seq = joint_prob.residuals(_split(x_seq, cands, spec), W)
    x, cost = simplex_fit(joint_prob, cands, x_seq, W, MAX_ROLLOUTS)
    if not cost < float(np.sum(r_seq ** 2)):
        return fit
    p = fit.num_params
    new_cal = _split(x[p:], cal_cands, spec)
    prob.base = rest + new_cal
    for f, (_, v) in zip(cals, new_cal):
        f.values = np.asarray(v, float)
    shift = x[:p] - fit.values
    for k in prob.folds:
        fit.fold_values[k], _ = simplex_fit(prob, list(fit.cands), fit.fold_values[k] + shift,
                                             prob.train(k), MAX_ROLLOUTS // 2)
    # the joint sandwich: the effect's sd with the calibration free beside it
    lo, hi = bounds_of(cands, spec)
    r = joint_prob.residuals(_split(x, cands, spec), W).ravel()
    Jt = _jacobian(lambda th: joint_prob.residuals(_split(th, cands, spec), W).ravel(), x, r,
                   lo, hi, np.maximum(np.abs(hi - lo) / 20.0, 1e-6),
                   getattr(spec, "jacobian_step", 1e-4))
    sd_joint = _sandwich_sd(Jt, r, prob.clusters(W), W)[:p]
    q = (fit.ci[:, 1] - fit.values) / np.maximum(fit.sd, 1e-300)
    fit.values = x[:p]
    fit.sd = np.maximum(fit.sd, sd_joint)
    fit.ci = np.stack([fit.values - q * fit.sd, fit.values + q * fit.sd], 1)
    fit.joint_calibration = dict(before=x_seq.tolist(), after=x.tolist(),
                                 cost_before=float(np.sum(r_seq ** 2)), cost_after=cost)
    return score_fit(prob, fit, none_eval)
