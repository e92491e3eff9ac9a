"""The effect library of `diagnose`: small parametric extensions of an LCS model.

Every effect has an exact name, a target (a generalized coordinate, a contact pair,
a body, a group of pairs, or the whole system), parameters with physical units, the
value at which it is absent ("nominal"), bounds and a coarse search grid.

The model being diagnosed is described by a `SystemSpec`: the LCS, names, which state
entries are positions / velocities, the inverse mass matrix of the linearisation
(generalized forces -> accelerations) and a `rebuild` hook for mass changes. An effect
is applied inside the explicit-Euler LCS step:

    q   = E x + H u_eff + c                       (contact offsets, r_comp)
    lam = LCP(F, q)                               (stiffness scales F)
    lam = max(0, lam + b * penetration rate) where lam > 0   (contact damping)
    x+  = A x + B u_eff + D lam + d + G tau(x)    (G = dt * Minv on the velocity rows)

with u_eff the (gain-scaled, delayed) input and tau the generalized forces of viscous
damping and constant external forces; Coulomb friction is then applied as an exact
stick-slip law per coordinate (it may stop, but never reverse, the coordinate's motion). All rollouts are batched over
many windows at once (the small LCPs are solved in closed form, vectorised).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from adaptive_c3.systems.contact.lcp import solve_lcp
from adaptive_c3.systems.contact.lcs import Lcs

MAX_DELAY_STEPS = 12         # input history kept for actuator_delay


@dataclass
class SystemSpec:
    """What the diagnosis needs to know about a model besides its LCS."""
    name: str
    lcs: Lcs
    state_names: tuple
    input_names: tuple
    pair_names: tuple
    coord_names: tuple            # generalized coordinates (one per velocity)
    q_idx: np.ndarray             # state rows holding positions, in coord order
    v_idx: np.ndarray             # state rows holding velocities, in coord order
    minv: np.ndarray              # [nv, nv] inverse mass matrix of the linearisation
    body_names: tuple = ()
    rebuild: Callable | None = None   # rebuild({body: scale}) -> (Lcs, minv)
    stiffness_groups: dict = field(default_factory=dict)  # target -> (pair idx, k0 N/m)
    relaxation_groups: dict = field(default_factory=dict)  # target -> (pair idx, tau0 s)
    friction_pairs: tuple = ()    # pairs with tangential friction (friction_coefficient)
    rolling_pairs: tuple = ()     # pairs where rolling resistance applies
    not_applicable: dict = field(default_factory=dict)   # effect name -> reason
    rotational: tuple = ()        # coordinates measured in rad (torques in N*m)

    @property
    def dt(self) -> float:
        return self.lcs.dt


@dataclass(frozen=True)
class EffectDef:
    name: str
    kind: str                     # coord | pair | body | group | system | pairs_all
    params: tuple                 # parameter name suffixes
    unit: Callable                # (spec, target) -> unit string
    nominal: Callable             # (spec, target) -> value where the effect is absent
    bounds: Callable              # (spec, target) -> (lo, hi)
    grid: Callable                # (spec, target) -> 1-D array of trial values
    physical: bool = True
    description: str = ""
    nuisance_only: bool = False   # fitted only as a nuisance (spec.nuisance), never named


def _coord_unit(force: bool, per_velocity: bool):
    def unit(spec, target):
        rot = _is_rotational(spec, target)
        base = "N*m" if rot else "N"
        if per_velocity:
            return base + ("*s/rad" if rot else "*s/m")
        return base
    return unit


def _is_rotational(spec, coord) -> bool:
    return coord in spec.rotational


def _scaled(lo_lin, hi_lin, lo_rot, hi_rot, n=21, symmetric=False):
    def grid(spec, target):
        lo, hi = (lo_rot, hi_rot) if _is_rotational(spec, target) else (lo_lin, hi_lin)
        return np.linspace(-hi if symmetric else lo, hi, n)

    def bounds(spec, target):
        lo, hi = (lo_rot, hi_rot) if _is_rotational(spec, target) else (lo_lin, hi_lin)
        return (-2 * hi if symmetric else lo, 2 * hi)
    return grid, bounds


_vd_grid, _vd_bounds = _scaled(0.0, 10.0, 0.0, 0.5)


def _delay_bounds(spec, target):          # s: up to the input history the windows keep
    return (0.0, (MAX_DELAY_STEPS - 1) * spec.dt)


def _delay_grid(spec, target):
    return np.arange(0, MAX_DELAY_STEPS - 1, 0.5) * spec.dt
_cf_grid, _cf_bounds = _scaled(0.0, 5.0, 0.0, 0.3)
_ef_grid, _ef_bounds = _scaled(0.0, 5.0, 0.0, 0.5, symmetric=True)
_zero = lambda spec, target: 0.0          # noqa: E731
CALIBRATION_TOLERANCE = 1e-3              # m: how well a table height or tool radius is known
_one = lambda spec, target: 1.0           # noqa: E731
COMPLIANCE_TOLERANCE = 5.0                # x: how well a compliant model's contact
                                          # stiffness and relaxation time are known


def _k0(spec, target):
    return spec.stiffness_groups[target][1]


def _tau0(spec, target):
    return spec.relaxation_groups[target][1]


def _within_tolerance(nominal):
    """(bounds, grid) of a compliance nuisance: nominal / COMPLIANCE_TOLERANCE to nominal x
    COMPLIANCE_TOLERANCE, a geometric grid of 9 inside."""
    def bounds(spec, target):
        x0 = nominal(spec, target)
        return x0 / COMPLIANCE_TOLERANCE, x0 * COMPLIANCE_TOLERANCE

    def grid(spec, target):
        return nominal(spec, target) * np.geomspace(0.25, 4.0, 9)
    return bounds, grid


EFFECTS = {e.name: e for e in [
    EffectDef("contact_offset", "pair", ("offset",), lambda s, t: "m", _zero,
              lambda s, t: (-0.3, 0.3), lambda s, t: np.linspace(-0.2, 0.2, 41),
              description="the contact surface is further away (+) or closer (-) than modelled"),
    EffectDef("contact_stiffness", "group", ("stiffness",), lambda s, t: "N/m", _k0,
              lambda s, t: (_k0(s, t) / 20, _k0(s, t) * 20),
              lambda s, t: _k0(s, t) * np.geomspace(0.2, 5.0, 25),
              description="the contact is stiffer or softer than modelled"),
    EffectDef("contact_damping", "group", ("damping",), lambda s, t: "N*s/m", _zero,
              lambda s, t: (0.0, 100.0), lambda s, t: np.linspace(0.0, 30.0, 31),
              description="the contact force has a term proportional to penetration rate"),
    EffectDef("contact_dissipation", "group", ("relaxation_time",), lambda s, t: "s", _tau0,
              lambda s, t: (_tau0(s, t) / 20, _tau0(s, t) * 20),
              lambda s, t: _tau0(s, t) * np.geomspace(0.2, 5.0, 25),
              description="the contact dissipates faster or slower than modelled (a "
                          "compliant model's relaxation time, e.g. SAP's)"),
    EffectDef("friction_coefficient", "pair", ("mu",), lambda s, t: "1", _one,
              lambda s, t: (0.0, 3.0), lambda s, t: np.linspace(0.1, 2.0, 20)),
    EffectDef("rolling_resistance", "pair", ("coefficient",), lambda s, t: "m", _zero,
              lambda s, t: (0.0, 0.05), lambda s, t: np.linspace(0.0, 0.01, 11)),
    EffectDef("torsional_friction", "pair", ("coefficient",), lambda s, t: "m", _zero,
              lambda s, t: (0.0, 0.05), lambda s, t: np.linspace(0.0, 0.01, 11),
              description="a torque opposing the spin about the contact normal, coefficient "
                          "x the body's weight"),
    EffectDef("viscous_damping", "coord", ("coefficient",), _coord_unit(True, True), _zero,
              _vd_bounds, _vd_grid, description="a force opposing and proportional to velocity"),
    EffectDef("coulomb_friction", "coord", ("force",), _coord_unit(True, False), _zero,
              _cf_bounds, _cf_grid, description="a constant-magnitude force opposing motion"),
    EffectDef("mass_scale", "body", ("scale",), lambda s, t: "1", _one,
              lambda s, t: (0.2, 5.0), lambda s, t: np.geomspace(0.4, 2.5, 25),
              description="the body is heavier or lighter than modelled"),
    EffectDef("actuator_gain", "system", ("gain",), lambda s, t: "1", _one,
              lambda s, t: (0.1, 5.0), lambda s, t: np.geomspace(0.4, 2.5, 25),
              description="the actuators deliver a different force than commanded"),
    EffectDef("actuator_delay", "system", ("delay",), lambda s, t: "s", _zero,
              _delay_bounds, _delay_grid,
              description="the input acts later than it is recorded"),
    EffectDef("sensor_delay", "system", ("delay",), lambda s, t: "s", _zero,
              _delay_bounds, _delay_grid, nuisance_only=True,
              description="the recorded states lag the true ones (a camera's latency, an "
                          "estimate resampled between its samples): each recorded sample "
                          "blends the two true samples about the delay"),
    EffectDef("external_force", "coord", ("force",), _coord_unit(True, False), _zero,
              _ef_bounds, _ef_grid, description="a constant force (a tilt, a spring, a cable)"),
    EffectDef("calibration_offset", "pair", ("offset",), lambda s, t: "m", _zero,
              lambda s, t: (-CALIBRATION_TOLERANCE, CALIBRATION_TOLERANCE),
              lambda s, t: np.linspace(-CALIBRATION_TOLERANCE, CALIBRATION_TOLERANCE, 9),
              nuisance_only=True,
              description="a contact surface off by no more than a calibration tolerance "
                          "(a table height, a tool radius): part of the base model"),
    EffectDef("stiffness_calibration", "group", ("stiffness",), lambda s, t: "N/m", _k0,
              *_within_tolerance(_k0), nuisance_only=True,
              description="the contact stiffer or softer than the model by no more than a "
                          "modelling tolerance: part of the base model"),
    EffectDef("dissipation_calibration", "group", ("relaxation_time",), lambda s, t: "s", _tau0,
              *_within_tolerance(_tau0), nuisance_only=True,
              description="the contact's relaxation time off by no more than a modelling "
                          "tolerance: part of the base model"),
    EffectDef("r_comp", "pairs_all", ("residual",), lambda s, t: "m", _zero,
              lambda s, t: (-0.3, 0.3), lambda s, t: np.linspace(-0.2, 0.2, 41), physical=False,
              description="the paper's additive complementarity residual (catch-all for contact)"),
]}
EFFECT_NAMES = tuple(EFFECTS)


@dataclass(frozen=True)
class Candidate:
    """One effect on one target; r_comp has one parameter per contact pair."""
    name: str
    target: str

    def definition(self) -> EffectDef:
        return EFFECTS[self.name]

    def num_params(self, spec) -> int:
        return len(spec.pair_names) if self.definition().kind == "pairs_all" else 1

    def param_names(self, spec) -> list:
        d = self.definition()
        if d.kind == "pairs_all":
            return [f"{p}" for p in spec.pair_names]
        return [d.params[0]]

    def units(self, spec) -> list:
        return [self.definition().unit(spec, self.target)] * self.num_params(spec)

    def nominal(self, spec) -> np.ndarray:
        return np.full(self.num_params(spec), self.definition().nominal(spec, self.target))

    def bounds(self, spec):
        lo, hi = self.definition().bounds(spec, self.target)
        p = self.num_params(spec)
        return np.full(p, lo, float), np.full(p, hi, float)

    def label(self) -> str:
        return f"{self.name}[{self.target}]" if self.target else self.name


def applicable_candidates(spec: SystemSpec) -> tuple[list, dict]:
    """(candidates, {effect name: reason it does not apply})."""
    cands, skipped = [], dict(spec.not_applicable)
    targets = getattr(spec, "effect_targets", None) or {}
    for name, d in EFFECTS.items():
        if name in skipped or d.nuisance_only:
            continue
        if name in targets:
            cands += [Candidate(name, t) for t in targets[name]]
            continue
        if d.kind == "coord":
            cands += [Candidate(name, c) for c in spec.coord_names]
        elif d.kind == "pair":
            pairs = spec.pair_names
            if name == "friction_coefficient":
                pairs = spec.friction_pairs
            elif name == "rolling_resistance":
                pairs = spec.rolling_pairs
            if not pairs:
                skipped[name] = "the model has no contact pair with this effect"
            cands += [Candidate(name, p) for p in pairs]
        elif d.kind == "body":
            if spec.rebuild is None or not spec.body_names:
                skipped[name] = "the model cannot be rebuilt with other masses"
            else:
                cands += [Candidate(name, b) for b in spec.body_names]
        elif d.kind == "group":
            if not spec.stiffness_groups:
                skipped[name] = "the model has no compliant contact"
            cands += [Candidate(name, g) for g in spec.stiffness_groups]
        elif d.kind == "pairs_all":
            if spec.pair_names:
                cands.append(Candidate(name, "all_pairs"))
        else:
            cands.append(Candidate(name, ""))
    return cands, skipped


# ----------------------------------------------------------------- the patched model
@dataclass
class Patched:
    """Matrices of the model with a set of effects applied (see module docstring)."""
    A: np.ndarray
    B: np.ndarray
    D: np.ndarray
    d: np.ndarray
    E: np.ndarray
    F: np.ndarray
    H: np.ndarray
    c: np.ndarray
    G: np.ndarray                 # [n, nv] generalized force -> state increment
    v_idx: np.ndarray
    viscous: np.ndarray           # [nv] N*s/m per coordinate
    coulomb: np.ndarray           # [nv]
    external: np.ndarray          # [nv]
    delay_steps: float = 0.0
    damping: np.ndarray | None = None   # [m] contact damping, N*s/m
    rate: np.ndarray | None = None      # [m, n] gap rate map (E_q on the velocity rows)


def patch(spec: SystemSpec, effects) -> Patched:
    """Apply [(Candidate, params), ...] to the spec's LCS."""
    custom = getattr(spec, "custom_patch", None)
    if custom is not None:            # e.g. ball rolling: a time-varying LCS per sample
        return custom(list(effects))
    lcs, minv = spec.lcs, spec.minv
    masses = {}
    for c, p in effects:                  # repeated effects compose (scenario + candidate)
        if c.name == "mass_scale":
            masses[c.target] = masses.get(c.target, 1.0) * float(p[0])
    if masses:
        lcs, minv = spec.rebuild(masses)
    n, nv = lcs.num_states, len(spec.v_idx)
    G = np.zeros((n, nv))
    G[spec.v_idx] = spec.dt * minv
    B, H, c = lcs.B.copy(), lcs.H.copy(), lcs.c.copy()
    E, F = lcs.E.copy(), lcs.F.copy()
    viscous, coulomb, external = np.zeros(nv), np.zeros(nv), np.zeros(nv)
    damping = np.zeros(lcs.num_lambda)
    delay = 0.0
    stiff = {g: k0 for g, (_, k0) in spec.stiffness_groups.items()}
    for cand, p in effects:
        if cand.name == "contact_stiffness":
            stiff[cand.target] = float(p[0])    # an absolute value (N/m): the last one holds
    for g, (pairs, k0) in spec.stiffness_groups.items():
        idx = np.asarray(pairs)
        F[np.ix_(idx, idx)] *= k0 / max(stiff[g], 1e-9)
    rate = np.zeros_like(E)
    rate[:, spec.v_idx] = E[:, spec.q_idx]          # d(gap)/dt = E_q v
    for cand, p in effects:
        name, t = cand.name, cand.target
        if name in ("contact_offset", "calibration_offset"):
            c[spec.pair_names.index(t)] += p[0]
        elif name == "r_comp":
            c += np.asarray(p, float)
        elif name == "contact_damping":
            damping[np.asarray(spec.stiffness_groups[t][0])] += p[0]
        elif name == "viscous_damping":
            viscous[spec.coord_names.index(t)] += p[0]
        elif name == "coulomb_friction":
            coulomb[spec.coord_names.index(t)] += p[0]
        elif name == "external_force":
            external[spec.coord_names.index(t)] += p[0]
        elif name == "actuator_gain":
            B, H = B * p[0], H * p[0]
        elif name == "actuator_delay":
            delay += float(p[0]) / spec.dt
        elif name in ("mass_scale", "contact_stiffness"):
            pass
        else:
            raise ValueError(f"effect {name} is not modelled for {spec.name}")
    return Patched(A=lcs.A, B=B, D=lcs.D, d=lcs.d, E=E, F=F, H=H, c=c, G=G,
                   v_idx=np.asarray(spec.v_idx), viscous=viscous, coulomb=coulomb,
                   external=external, delay_steps=delay, damping=damping, rate=rate)


def batch_lcp(F: np.ndarray, Q: np.ndarray) -> np.ndarray:
    """lam [W, m] solving LCP(F, q_w) for every row of Q (F diagonal: closed form)."""
    diag = np.diag(F)
    if np.allclose(F, np.diag(diag)) and np.all(diag > 0):
        return np.maximum(0.0, -Q / diag)
    lam = np.zeros_like(Q)
    for w in np.flatnonzero(np.any(Q < 0, axis=1)):
        res = solve_lcp(F, Q[w])
        lam[w] = res.z
    return lam


def delayed_inputs(U: np.ndarray, lag: int, delay_steps: float, h: int) -> np.ndarray:
    """u_eff at step h of windows whose inputs U [W, lag + H, k] start `lag` steps early."""
    if delay_steps <= 0:
        return U[:, lag + h]
    n = int(np.floor(delay_steps))
    a = delay_steps - n
    i0 = max(lag + h - n, 0)
    i1 = max(lag + h - n - 1, 0)
    return (1 - a) * U[:, i0] + a * U[:, i1]


def rollout(P: Patched, X0: np.ndarray, U: np.ndarray, horizon: int, lag: int, rows=None):
    """Open-loop rollouts of many windows: X [W, horizon, n] (x_1..x_H), lam [W, H, m].
    rows: the recording row of each window's start (time-varying models need it)."""
    if hasattr(P, "rollout"):
        return P.rollout(X0, U, horizon, lag, rows)
    X = np.array(X0, float)
    xs, lams = [], []
    for h in range(horizon):
        u = delayed_inputs(U, lag, P.delay_steps, h)
        lam = batch_lcp(P.F, X @ P.E.T + u @ P.H.T + P.c)
        if P.damping is not None and np.any(P.damping):
            lam = contact_damping_force(P, X, lam)
        tau = P.external - P.viscous * X[:, P.v_idx]
        X = X @ P.A.T + u @ P.B.T + lam @ P.D.T + P.d + tau @ P.G.T
        X = apply_coulomb(P, X)
        xs.append(X)
        lams.append(lam)
    return np.stack(xs, 1), np.stack(lams, 1)


def contact_damping_force(P: Patched, X: np.ndarray, lam: np.ndarray) -> np.ndarray:
    """A linear damper in parallel with the contact spring, acting only while in contact
    (lam > 0) and never pulling: lam_i <- max(0, lam_i + b_i * penetration rate)."""
    pen_rate = -(X @ P.rate.T)
    active = lam > 0
    return np.where(active, np.maximum(0.0, lam + P.damping * pen_rate), lam)


def apply_coulomb(P: Patched, X: np.ndarray) -> np.ndarray:
    """Exact time-stepping Coulomb friction per coordinate: an opposing generalized force
    of magnitude f that cannot reverse the coordinate's velocity within the step (stick)."""
    for j in np.flatnonzero(P.coulomb):
        col = P.G[:, j]
        gain = col[P.v_idx[j]]                       # dt * Minv_jj
        v_free = X[:, P.v_idx[j]]
        tau = -np.sign(v_free) * np.minimum(P.coulomb[j], np.abs(v_free) / gain)
        X = X + tau[:, None] * col
    return X


def sensitivity_columns(spec: SystemSpec, cands, X: np.ndarray, U: np.ndarray, lag: int,
                        eps_rel: float = 1e-3, base_effects=(), rows=None) -> np.ndarray:
    """d x_{k+1} / d theta at the nominal model for each 1-parameter candidate: [W, n, C]."""
    cols, base_effects = [], list(base_effects)
    base = rollout(patch(spec, base_effects), X, U, 1, lag, rows)[0][:, 0]
    for cand in cands:
        lo, hi = cand.bounds(spec)
        step = eps_rel * max(float(hi[0] - lo[0]), 1e-6)
        p = cand.nominal(spec) + step
        x1 = rollout(patch(spec, base_effects + [(cand, p)]), X, U, 1, lag, rows)[0][:, 0]
        cols.append((x1 - base) / step)
    return np.stack(cols, -1)


# ----------------------------------------------------------------- the cart-pole
def cartpole_minv(p) -> np.ndarray:
    """Inverse mass matrix of the linearised cart-pole (pole = point mass at lc).

    It reproduces the model's B (column 0) and gravity / wall columns exactly."""
    mc, mp, lc = p.mc, p.mp, p.lc
    return np.array([[1 / mc, 1 / (mc * lc)],
                     [1 / (mc * lc), (mc + mp) / (mc * mp * lc * lc)]])


def cartpole_spec(scenario) -> SystemSpec:
    """The diagnosis view of a cart-pole scenario's *model* (wall offset error included)."""
    from dataclasses import replace
    from adaptive_c3.models.cartpole import (CartpoleParams, INPUT_NAMES, LAMBDA_NAMES,
                                             STATE_NAMES, cartpole_lcs)
    m = scenario.model
    params = CartpoleParams(wall_stiffness=m.wall_stiffness, wall_distance=m.wall_distance)
    err = list(m.wall_offset_error)

    def rebuild(scales):
        p = replace(params, mc=params.mc * scales.get("cart", 1.0),
                    mp=params.mp * scales.get("pole", 1.0))
        return cartpole_lcs(p, err), cartpole_minv(p)

    return SystemSpec(
        name="cartpole", lcs=cartpole_lcs(params, err), state_names=STATE_NAMES,
        input_names=INPUT_NAMES, pair_names=LAMBDA_NAMES,
        coord_names=("cart_x", "pole_theta"), q_idx=np.array([0, 1]), v_idx=np.array([2, 3]),
        minv=cartpole_minv(params), body_names=("cart", "pole"), rebuild=rebuild,
        stiffness_groups={"walls": ((0, 1), float(m.wall_stiffness))},
        rotational=("pole_theta",),
        not_applicable={
            "friction_coefficient": "the cart-pole's wall contacts are frictionless "
                                    "(normal force only); no tangential force to scale",
            "rolling_resistance": "nothing rolls in the cart-pole model",
            "contact_dissipation": "the wall contacts are springs; their damping is "
                                   "contact_damping",
            "torsional_friction": "the cart-pole's wall contacts are frictionless"})


def calibration_sums(effects) -> dict:
    """{pair: m}: the calibration_offset values among `effects` [(Candidate, values)],
    summed per pair (the shift a contact_offset of that pair is read on top of)."""
    out = {}
    for c, p in effects:
        if c.name == "calibration_offset":
            out[c.target] = out.get(c.target, 0.0) + float(np.ravel(p)[0])
    return out
