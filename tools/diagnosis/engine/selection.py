"""Choose among the candidate fits (engine/fit.py) the one(s) the held-out data support.

Selection on the cross-validated SSR: score = N_eff ln(SSR/N) + p ln(N_eff) (BIC-like;
N_eff = N / horizon, the residuals of one window being correlated). An effect is
significant when its score beats the unmodified model's by SCORE_MARGIN (10, "very
strong" on the BIC scale) AND the held-out SSR drops by >= 2% (on clean data spurious
fits change it by < 0.1%). Among significant candidates, those within SCORE_MARGIN of
the best are "equally good"; of those the physical effect is preferred to r_comp, then
fewer parameters, then the lower score. Pairs of the four best single physical effects
are fitted too and compete under the same rule when they cut the held-out SSR of each
of their two effects alone by a further 5% (so a pair wins over a single effect only if
its score is lower by SCORE_MARGIN, and two physical contact offsets win over the
equally good two-parameter r_comp). Where the spec has calibration nuisances, an r_comp
with a pair offset inside the calibration tolerance is no choice (that part is
calibration; the other pair's contact_offset competes on its own), nor is a
contact_offset whose total with its pair's kept calibration is inside it (a re-estimate
of that calibration, not an effect). The per-cluster z of
each fit against the unmodified model (the problem's z_stat: paired, or the signed-rank
z) is reported and used by the verdict (engine/evidence.py); significance requires it
only where the problem sets min_z (the ball's free windows): reductions concentrated in
few clusters, e.g. contacts, make it a poor test of a whole recording.
"""
from __future__ import annotations

from itertools import combinations

import numpy as np

from adaptive_c3.tools.diagnosis.backends.effects import Candidate
from adaptive_c3.tools.diagnosis.engine.fit import (Fit, Problem, cluster_z, cv_fit, evaluate,
                                                    jackknife, widen_for_bias)

SCORE_MARGIN = 10.0     # "very strong" evidence on the BIC scale
MIN_REDUCTION = 0.02    # held-out SSR must drop by >= 2% to count
PAIR_REDUCTION = 0.05   # a pair must cut the chosen single effect's SSR by >= 5% more


def _score(ssr, n, p, horizon):
    n_eff = max(n / horizon, 2.0)
    return n_eff * np.log(max(ssr, 1e-300) / n) + p * np.log(n_eff)


def reduction_bar(by_effect: dict | None, fit: Fit, default: float) -> float:
    """The held-out SSR cut a choice of `fit` needs: by_effect's bar for a single effect
    that has its own (a spec's min_reduction_by_effect), else default."""
    name = fit.cands[0].name if len(fit.cands) == 1 else None
    return (by_effect or {}).get(name, default)


def score_fit(prob: Problem, fit: Fit, none_eval) -> Fit:
    ssr0, n, per0, _ = none_eval
    fit.test_ssr, fit.test_n, fit.test_cluster_ssr, fit.test_window_ssr = evaluate(prob, fit)
    fit.score = _score(fit.test_ssr, n, fit.num_params, prob.horizon)
    fit.z_stat = prob.z_stat
    fit.z_vs_none = cluster_z(per0, fit.test_cluster_ssr, prob.z_stat)
    fit.reduction = 1.0 - fit.test_ssr / ssr0 if ssr0 > 0 else 0.0
    min_red = prob.min_reduction
    if min_red is None:                # per model (see spec), and per effect where it has one
        min_red = reduction_bar(getattr(prob.spec, "min_reduction_by_effect", {}), fit,
                                getattr(prob.spec, "min_reduction", MIN_REDUCTION))
    fit.significant = bool(fit.score < _score(ssr0, n, 0, prob.horizon) - SCORE_MARGIN
                           and fit.reduction >= min_red and fit.z_vs_none >= prob.min_z)
    return fit


def _choose(fits, equal_rel: float = 0.0):
    sig = [f for f in fits if f.significant]
    if not sig:
        return None
    best = min(sig, key=lambda f: f.score)
    # equally good: within SCORE_MARGIN, or (models with a structural floor, equal_rel > 0)
    # within a relative held-out SSR margin of the best
    equal = [f for f in sig if f.score < best.score + SCORE_MARGIN
             or f.test_ssr <= best.test_ssr * (1.0 + equal_rel)]
    return min(equal, key=lambda f: (not f.physical, f.num_params, f.score))


def _at_bound(f, c, spec, rel: float = 0.02) -> bool:
    lo, hi = c.bounds(spec)
    span = hi - lo
    return bool(np.any(f.values <= lo + rel * span) or np.any(f.values >= hi - rel * span))


def _calibration_sized(f, spec, shift=None) -> bool:
    """A fit with an r_comp whose offset on some pair is within the calibration
    tolerance: that pair's part is calibration (a nuisance), not an effect; the other
    pair's contact_offset is the effect (chosen on its own merit), so it is no choice.
    The same for a pair of effects with a contact_offset within the tolerance (dev draw
    12038: a -0.78 mm table offset was answered `contact_offset[ball_table] +
    contact_offset[ee_ball]`, the EE-ball part 0.70 mm: the draw's radius errors), and
    for a single contact_offset whose total from the user's model (shift {pair: m}: the
    calibration kept for its pair, base_shift) is within it: a re-estimate of that pair's
    calibration. On the twenty-fourth set's 100315 (an EE-ball offset of 1.06 mm) a table
    offset of -0.30 mm on a table calibration of 0.50 mm was named (total 0.20 mm), and
    on development draw 90303 (a ball of 0.49x the mass) a table offset of 0.48 mm
    total; every single offset named within the tolerance on the seventeenth to
    twenty-fourth sets (4: 99628, 99701, 99726, 100315) was a wrong answer."""
    from adaptive_c3.tools.diagnosis.backends.effects import CALIBRATION_TOLERANCE
    effects, shift = f.effects(spec), shift or {}
    for c, p in effects:
        if c.name == "r_comp" and np.any(np.abs(p) < CALIBRATION_TOLERANCE):
            return True
        if c.name == "contact_offset" and \
                abs(float(p[0]) + shift.get(c.target, 0.0)) < CALIBRATION_TOLERANCE:
            return True
    return False


def calibration_reestimate(f, spec, shift=None) -> bool:
    """_calibration_sized, where the spec fits calibration offsets as a nuisance (without
    them no offset is calibration)."""
    calibrates = any(n == "calibration_offset" for n, _ in getattr(spec, "nuisance", ()))
    return calibrates and _calibration_sized(f, spec, shift)


def base_shift(prob: Problem) -> dict:
    """{pair: m}: the calibration offsets in prob.base (the kept nuisances)."""
    from adaptive_c3.tools.diagnosis.backends.effects import calibration_sums
    return calibration_sums(prob.base)


def fit_nuisance(prob: Problem) -> list:
    """Fits of the spec's nuisance effects (spec.nuisance: [(name, target)]) that the
    held-out data support, each then kept in prob.base for everything that follows. A
    nuisance-only effect (a calibration tolerance) fitted at its bound is not kept: the
    data want more than the tolerance, so it is left to the candidates.

    The nuisances are fitted one after another, each with those before it held, so an
    early one takes up what a later one explains better: with spec.nuisance_sweeps = 2,
    every kept nuisance is then fitted once more with all the others held (one
    backfitting sweep), kept or dropped by the same rules. On the twenty-fourth set's
    100315 (an EE-ball offset of 1.06 mm) the table's calibration took 0.50 mm before the
    EE-ball's took 0.75 mm; a table offset of -0.30 mm on top of it was then named, its
    total 0.20 mm within the table's calibration tolerance: a re-estimate of the
    nuisance, which beat the sequential one at z 12.8 on the left-out windows."""
    kept, added = [], {}         # added: the base entries each kept fit put there

    def keep(f):
        added[id(f)] = f.effects(prob.spec)
        prob.base = list(prob.base) + added[id(f)]
        kept.append(f)

    for name, target in getattr(prob.spec, "nuisance", ()):
        f = _supported_nuisance(prob, Candidate(name, target))
        if f is not None:
            keep(f)
    for _ in range(int(getattr(prob.spec, "nuisance_sweeps", 1)) - 1):
        if len(kept) < 2:
            break
        for f in list(kept):
            mine = added.pop(id(f))
            prob.base = [e for e in prob.base if not any(e is m for m in mine)]
            kept.remove(f)
            g = _supported_nuisance(prob, f.cands[0], f)
            if g is not None:
                keep(g)
    return kept


def _supported_nuisance(prob: Problem, c, before=None) -> Fit | None:
    """The fit of nuisance `c` on prob (the other nuisances held in prob.base) when the
    held-out data support it and, for a nuisance-only effect, it is not at its bound;
    else None. before: its fit of an earlier sweep (recorded as fit.earlier_values)."""
    f = score_fit(prob, cv_fit(prob, [c]), evaluate(prob, None))
    if c.definition().nuisance_only and _at_bound(f, c, prob.spec):
        return None    # the data want more than the tolerance: an effect, not calibration
    if not f.significant:
        return None
    if before is not None:
        f.earlier_values = np.asarray(before.values, float)
    return f


def select(prob: Problem, cands, progress=None, pairs: bool = True, offset: int = 0):
    """Fit everything, choose. Returns (chosen Fit or None, all fits, none evaluation).
    progress: a Progress bar advanced to offset + fits done."""
    none_eval = evaluate(prob, None)
    fits, by_cand = [], {}
    for i, c in enumerate(cands):
        init = None
        if c.name == "r_comp":
            init = np.array([by_cand[Candidate("contact_offset", p)].values[0]
                             if Candidate("contact_offset", p) in by_cand else 0.0
                             for p in prob.spec.pair_names])
        f = widen_for_bias(prob, score_fit(prob, cv_fit(prob, [c], init), none_eval))
        fits.append(f)
        by_cand[c] = f
        if progress:
            progress.update(offset + i + 1)
    eligible = list(fits)
    if pairs:
        singles = sorted([f for f in fits if f.physical],
                         key=lambda f: f.score)[:getattr(prob.spec, "pair_singles", 4)]
        for a, b in combinations(singles, 2):
            if a.cands[0].name == b.cands[0].name == "actuator_delay":
                continue
            init = np.concatenate([a.values, b.values])
            f = score_fit(prob, cv_fit(prob, [a.cands[0], b.cands[0]], init), none_eval)
            fits.append(f)
            # a pair must explain clearly more than either of its effects alone
            pair_red = getattr(prob.spec, "pair_reduction", PAIR_REDUCTION)
            if f.test_ssr < (1 - pair_red) * min(a.test_ssr, b.test_ssr):
                eligible.append(f)
            if progress:
                progress.update(offset + len(fits))
    shift = base_shift(prob)
    eligible = [f for f in eligible if not calibration_reestimate(f, prob.spec, shift)]
    chosen = _choose(eligible, getattr(prob.spec, "equal_reduction", 0.0))
    if chosen is not None:
        if not len(chosen.shift):
            widen_for_bias(prob, chosen)
        jackknife(prob, chosen)
    return chosen, fits, none_eval
