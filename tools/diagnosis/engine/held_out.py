"""The interval of a chosen effect as the values held-out data do not reject.

The fit's own interval is linearised at its value (a sandwich, a jackknife of refits, a
horizon and a nuisance allowance: engine/fit.py). Where a few contact events carry the
cost (a gap that opens or closes a contact in one window) the cost is a staircase in the
value: a local fit stops on a step, its refits stop on the same one, and the interval
says nothing about the next step. On development draw 90055 (Drake's plant, an EE-ball
offset of 1.66 mm) the cost on all windows fell from 37702 to 24486 between 2.0 and
2.1 mm, one fold's share by 12647, and the fit read 2.50 mm [2.47, 2.53].

Here the model with the effect fixed at a value is rolled out on the held-out windows and
compared, cluster by cluster (the paired z the verdict uses), with the best value found;
a value is rejected at z <= -INTERVAL_Z. The scan steps out from the fit's value on each
side (steps growing x1.5 from FIRST_STEP of value_scale or the fit's sd; a first step
already rejected is halved up to MAX_HALVINGS times) until a value is rejected, and each
edge is interpolated to z = -INTERVAL_Z between the last value kept and the first
rejected (the farthest value scanned where none is).

Contact compliance is a nuisance (a softer contact lets the EE sink further into a
pressed ball, as a larger EE-ball gap does): the scan is repeated with the contact
stiffness at COMPLIANCE_STEPS times its present value, and the interval is the union over
the stiffnesses whose best value held-out data do not reject either (a profile over the
stiffness; the scan at a stiffness starts from the effect's simplex fit there).
Development draw 90093 (an EE-ball offset of -2.68 mm, contact 4x softer than
the model's): offset -1.75 mm at the model's stiffness cost 29759, -2.3 mm at 0.4x
25367, -2.68 mm at 0.24x 26613.
"""
from __future__ import annotations

import copy

import numpy as np

from adaptive_c3.tools.diagnosis.backends.effects import Candidate
from adaptive_c3.tools.diagnosis.engine.boundary import at_size
from adaptive_c3.tools.diagnosis.engine.fit import paired_z
from adaptive_c3.tools.diagnosis.engine.joint_refit import simplex_fit, value_scale

INTERVAL_Z = 1.96          # a value stays in the interval while z > -this
FIRST_STEP = 0.2           # the scan's first step: this share of value_scale (or the sd)
STEP_GROWTH = 1.5
MAX_STEPS = 8              # per side
MAX_HALVINGS = 3           # of a first step that is already rejected
COMPLIANCE_STEPS = (0.25, 0.5)    # softer: a stiffer contact than the model's sinks less
VARIANT_ROLLOUTS = 16             # the simplex fit of the effect at each stiffness
STIFFNESS = "stiffness_calibration"


def compliance_variants(prob) -> list:
    """prob, and copies whose base has the spec's contact-stiffness nuisance at
    COMPLIANCE_STEPS x its present value (kept in prob.base, else nominal) within the
    nuisance's bounds; just [prob] for a spec without one."""
    out = [prob]
    for name, target in getattr(prob.spec, "nuisance", ()):
        if name != STIFFNESS:
            continue
        c = Candidate(name, target)
        lo, hi = (float(b[0]) for b in c.bounds(prob.spec))
        present = float(prob.present(c)[0])
        rest = [(cc, p) for cc, p in prob.base if cc != c]
        for f in COMPLIANCE_STEPS:
            variant = copy.copy(prob)
            variant.base = rest + [(c, np.array([float(np.clip(present * f, lo, hi))]))]
            out.append(variant)
    return out


def _edges(vs, ssr, start, ref, z_crit) -> tuple[float, float]:
    """Edges of the values kept (paired z against the per-cluster SSR `ref` above -z_crit)
    walking out from `start` in the sorted values vs, interpolated to z = -z_crit."""
    zs = [paired_z(ref, ssr[v]) for v in vs]
    i = vs.index(start)
    edges = []
    for walk in (range(i - 1, -1, -1), range(i + 1, len(vs))):
        kept, edge = i, None
        for j in walk:
            if zs[j] <= -z_crit:
                t = (zs[kept] + z_crit) / max(zs[kept] - zs[j], 1e-12)
                edge = vs[kept] + (vs[j] - vs[kept]) * t
                break
            kept = j
        edges.append(float(vs[kept] if edge is None else edge))
    return edges[0], edges[1]


def held_out_interval(prob, fit, z_crit: float = INTERVAL_Z) -> tuple[float, float] | None:
    """(low, high): the values of a one-parameter fit that held-out data do not reject,
    profiled over the contact compliance (module doc). None for several parameters."""
    if prob is None or len(fit.cands) != 1 or len(fit.values) != 1:
        return None
    cand, v0 = fit.cands[0], float(fit.values[0])
    lo, hi = (float(b[0]) for b in cand.bounds(prob.spec))
    first = max(float(fit.sd[0]), FIRST_STEP * value_scale(prob.spec, cand))
    variants = compliance_variants(prob)
    ssr = [dict() for _ in variants]            # per variant: value -> per-cluster SSR

    def best():
        return min(((i, v) for i, s in enumerate(ssr) for v in s),
                   key=lambda iv: ssr[iv[0]][iv[1]].sum())

    for i, variant in enumerate(variants):
        start = v0 if i == 0 else float(simplex_fit(variant, [cand], np.array([v0]),
                                                    variant.used(), VARIANT_ROLLOUTS)[0][0])
        ssr[i][start] = at_size(variant, cand, start, None, per_cluster=True)
        for direction in (-1.0, 1.0):
            v, step, halvings = start, first, MAX_HALVINGS
            for _ in range(MAX_STEPS + MAX_HALVINGS):
                nv = float(np.clip(v + direction * step, lo, hi))
                ssr[i][nv] = at_size(variant, cand, nv, None, per_cluster=True)
                bi, bv = best()
                if paired_z(ssr[bi][bv], ssr[i][nv]) <= -z_crit:
                    if v == start and halvings:     # a first step too long
                        step, halvings = step / 2, halvings - 1
                        continue
                    break
                v, step = nv, step * STEP_GROWTH
                if nv in (lo, hi):
                    break
    bi, bv = best()
    edges = []
    for i in range(len(variants)):
        own = min(ssr[i], key=lambda v: ssr[i][v].sum())
        if (i, own) != (bi, bv) and paired_z(ssr[bi][bv], ssr[i][own]) <= -z_crit:
            continue                                # this stiffness is ruled out
        edges.append(_edges(sorted(ssr[i]), ssr[i], own, ssr[bi][bv], z_crit))
    return min(e[0] for e in edges), max(e[1] for e in edges)


def widen_to_held_out(prob, fit) -> None:
    """The fit's 95 % interval extended to its held_out_interval (sd rescaled to match,
    at the interval's quantile); recorded as fit.held_out_ci. Specs opt in with
    `rugged_cost`, as for joint_refit.refit_with_calibration."""
    if fit is None or not getattr(prob.spec, "rugged_cost", False):
        return
    edges = held_out_interval(prob, fit)
    if edges is None:
        return
    fit.held_out_ci = edges
    lo, hi = min(fit.ci[0, 0], edges[0]), max(fit.ci[0, 1], edges[1])
    q = (fit.ci[0, 1] - fit.values[0]) / max(float(fit.sd[0]), 1e-300)
    q = q if q > 0 else INTERVAL_Z          # a fit without an sd of its own
    fit.ci = np.array([[lo, hi]])
    fit.sd = np.array([max(float(fit.sd[0]), (hi - lo) / (2 * q))])
