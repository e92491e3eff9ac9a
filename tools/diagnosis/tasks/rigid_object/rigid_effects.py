"""The effect libraries of the rigid-object diagnosis, one per model backend: each effect
is a named parameter change (a scenario key, the values tried, its unit and meaning).

kind: `physics` (something the model leaves out or gets wrong) or `nuisance` (contact
compliance, calibration offsets: fitted like the others but never reported as missing
physics). For the `drake` backend, `lcs` says what a finding means for the controller's
LCS: the LCS key that carries it, or why there is none.

Keys are `section.field` or `section.field[i]` (one entry of a list field).
"""
from __future__ import annotations

import copy
import re
from dataclasses import dataclass

from adaptive_c3.tools.diagnosis.backends.rigid_model import key_value


@dataclass(frozen=True)
class RigidEffect:
    name: str
    key: str             # scenario key the value goes to
    grid: tuple          # values tried
    unit: str
    physics: str         # what it means, in words
    integer: bool = False
    kind: str = "physics"          # or "nuisance"
    lcs: str = ""                  # drake effects: the LCS key, or "no LCS counterpart: why"
    refit: str = ""                # a second key re-fitted with it (a two-parameter effect)
    extend: tuple = ()             # (low, high): how far the grid may grow past its ends
                                   # while the interval reaches one (rigid_diagnose.extend_grid)


EFFECTS = (
    RigidEffect("table_offset", "patch.table_offset",
                (-5e-3, -4e-3, -3e-3, -2e-3, -1e-3, 0.0, 1e-3, 2e-3, 3e-3, 4e-3),
                "m", "the table top is not where the model puts it (calibration or geometry)",
                kind="nuisance"),
    RigidEffect("size_offset", "patch.size_offset", (-3e-3, -2e-3, -1e-3, 0.0, 1e-3, 2e-3, 3e-3),
                "m", "the object's contact geometry is larger or smaller than modelled"),
    RigidEffect("restitution", "patch.restitution", (0.0, 0.1, 0.2, 0.35, 0.5),
                "1", "impacts bounce back (the rigid model's impacts are perfectly inelastic)"),
    RigidEffect("friction_cone", "contact.friction_edges", (4, 6, 8, 12, 16), "edges",
                "friction is isotropic: the model's polyhedral cone of few edges gives less "
                "friction to slides between its edges (4 edges: 71 % of mu on the diagonal)",
                integer=True),
    RigidEffect("friction", "contact.friction", (0.08, 0.12, 0.18, 0.25, 0.35, 0.5),
                "1", "the friction coefficient differs from the model's"),
    RigidEffect("torsional_friction", "patch.torsional_friction", (0.0, 1e-3, 3e-3, 1e-2, 3e-2),
                "m", "contact patches resist spinning about the table normal (torsional "
                "friction; the rigid model's point contacts do not)"),
    RigidEffect("compliance", "contact.eps_c", (1e-4, 1e-3, 1e-2, 3e-2, 1e-1),
                "1/kg", "contact is compliant (the model's contact regulariser is too stiff)",
                kind="nuisance"),
    RigidEffect("inertia_scale", "patch.inertia_scale", (0.6, 0.8, 1.0, 1.25, 1.5),
                "1", "the rotational inertia differs from a solid box's"),
    RigidEffect("r_comp", "patch.r_comp", (-0.1, -0.05, -0.02, 0.0, 0.02, 0.05, 0.1),
                "m/s", "a constant residual on every complementarity row (the learner's r_comp)"),
)

NO_LCS = "no LCS counterpart"
DRAKE_EFFECTS = (
    RigidEffect("friction", "drake.friction", (0.12, 0.15, 0.17, 0.19, 0.21, 0.24, 0.28, 0.34,
                                               0.42),
                "1", "the friction coefficient differs from the simulation's",
                lcs="contact.friction"),
    RigidEffect("inertia_scale", "patch.inertia_scale", (0.8, 1.15, 1.3, 1.5, 1.7, 2.0),
                "1", "the rotational inertia differs from a solid box's (a thin-walled cube "
                "has 1.67x; friction re-fitted with it: a slower-turning cube tumbles longer "
                "and slides less after it lands)", lcs="patch.inertia_scale",
                refit="drake.friction"),
    RigidEffect("corner_rounding", "contact.corner_radius", (1e-3, 2e-3, 3e-3, 5e-3, 8e-3),
                "m", "the object's edges and corners are rounded (radius of the corner "
                "spheres, whose surfaces still reach the faces; friction re-fitted with it)",
                lcs="contact.corner_radius", refit="drake.friction"),
    RigidEffect("table_offset", "patch.table_offset", (-3e-3, -2e-3, -1e-3, 0.0, 1e-3, 2e-3),
                "m", "the table top is not where the simulation puts it (calibration)",
                kind="nuisance", lcs="patch.table_offset"),
    *(RigidEffect(f"com_offset_{axis}", f"patch.com_offset[{i}]",
                  (-9e-3, -6e-3, -3e-3, 0.0, 3e-3, 6e-3, 9e-3, 1.2e-2), "m",
                  f"the centre of mass is off the box's centre along body {axis} (an uneven "
                  "shell, a weight on one face: the object lands on that face more often; "
                  "friction re-fitted with it)", lcs=f"patch.com_offset[{i}]",
                  refit="drake.friction", extend=(-0.03, 0.03)) for i, axis in enumerate("xyz")),
    RigidEffect("size_offset", "patch.size_offset", (-2e-3, -1e-3, 0.0, 1e-3, 2e-3),
                "m", "the object's contact geometry is larger or smaller than modelled",
                lcs="patch.size_offset"),
    RigidEffect("point_stiffness", "drake.point_stiffness", (1e3, 2e3, 5e3, 1e4, 3e4),
                "N/m", "contact is softer than Drake's default point contact (compliance; "
                "friction re-fitted with it)", kind="nuisance", refit="drake.friction",
                lcs=f"{NO_LCS}: the LCS is rigid (contact.eps_c is a regulariser, not a "
                "stiffness)"),
    RigidEffect("relaxation_time", "drake.relaxation_time", (1e-3, 3e-3, 1e-2, 3e-2, 0.1, 0.3),
                "s", "contact dissipates differently from Drake's default (SAP relaxation "
                "time; 1-3 ms lets impacts bounce; friction re-fitted with it)",
                kind="nuisance", refit="drake.friction",
                lcs=f"{NO_LCS}: the LCS's impacts are perfectly inelastic"),
    RigidEffect("viscous_drag", "drake.viscous_drag", (0.0, 0.02, 0.05, 0.1, 0.2),
                "N s/m", "a viscous drag on the body's velocity (air or a tether; Drake's "
                "plant has none: added as a force element)",
                lcs=f"{NO_LCS}: the LCS has no velocity-dependent force term"),
    RigidEffect("angular_drag", "drake.angular_drag", (0.0, 1e-4, 3e-4, 1e-3, 3e-3),
                "N m s", "a viscous drag on the body's spin (added as a force element)",
                lcs=f"{NO_LCS}: the LCS has no velocity-dependent torque term"),
    RigidEffect("torsional_friction", "drake.torsional_friction", (0.0, 1e-3, 3e-3, 1e-2, 3e-2),
                "m", "contact patches resist spinning about the table normal beyond what the "
                "point contacts' friction gives (torsional friction: torque per newton of "
                "normal force; added as a force element)", lcs="patch.torsional_friction"),
    RigidEffect("rolling_resistance", "drake.rolling_resistance", (0.0, 1e-3, 3e-3, 1e-2),
                "m", "the body resists rotating about axes in the table plane while pressed "
                "on it (rolling resistance: torque per newton of normal force; added as a "
                "force element)", lcs=f"{NO_LCS}: the LCS has no rolling resistance term"),
    RigidEffect("external_force_z", "drake.external_force[2]", (-0.3, -0.1, 0.0, 0.1, 0.3),
                "N", "a constant vertical force on the body (a magnet, a tether, a wrong "
                "gravity; added as a force element)",
                lcs=f"{NO_LCS}: the LCS's affine term d would carry it (not a scenario key)"),
)

NOT_IDENTIFIABLE = {
    "mass_scale": "no input acts on the body: scaling its mass and inertia together leaves "
                  "its motion unchanged (inertia_scale is tried instead)",
    "rolling_friction": "the rigid model has no rolling resistance term yet (a cube "
                        "tumbles on its edges rather than rolls); not tried",
}
DRAKE_NOT_IDENTIFIABLE = {
    "mass_scale": NOT_IDENTIFIABLE["mass_scale"],
    "static_friction": "SAP uses one (dynamic) friction coefficient; a static one would be "
                       "ignored by the simulation, so it is not a knob",
    "hunt_crossley_dissipation": "SAP ignores it (its dissipation is the relaxation time, "
                                 "which is tried, down to 1 ms, where impacts bounce); it "
                                 "acts under drake.discrete_contact_approximation similar "
                                 "or lagged, which a scenario may set",
    "sensor_delay": "the tosses have no input: a delay only shifts time, which the fitted "
                    "initial state absorbs",
}


def library(model: str) -> tuple:
    return DRAKE_EFFECTS if model == "drake" else EFFECTS


def not_identifiable(model: str) -> dict:
    return DRAKE_NOT_IDENTIFIABLE if model == "drake" else NOT_IDENTIFIABLE


_KEY = re.compile(r"^(\w+)\.(\w+)(?:\[(\d+)\])?$")


def split_key(key: str) -> tuple[str, str, int | None]:
    """'section.field' or 'section.field[i]' -> (section, field, i or None)."""
    m = _KEY.match(key)
    if not m:
        raise ValueError(f"bad effect key {key!r}")
    return m.group(1), m.group(2), (int(m.group(3)) if m.group(3) is not None else None)


def set_key(container, key: str, value, as_dict: bool = False) -> None:
    """Set a key on a scenario object (or, as_dict, on its YAML dict) in key_value's type."""
    section, field, index = split_key(key)
    if as_dict:
        sec = container.setdefault(section, {})
        if index is None:
            sec[field] = key_value(f"{section}.{field}", value)
        else:         # a list the YAML leaves out starts as the schema's default
            if field not in sec:
                from adaptive_c3.scenarios.rigid_object_schema import RigidObjectScenario
                sec[field] = list(getattr(getattr(RigidObjectScenario(), section), field))
            sec[field][index] = float(value)
        return
    sec = getattr(container, section)
    if index is None:
        setattr(sec, field, key_value(f"{section}.{field}", value))
    else:
        entries = list(getattr(sec, field))
        entries[index] = float(value)
        setattr(sec, field, entries)


def with_values(scenario, values: dict):
    """A copy of the scenario with these keys set (key_value's types)."""
    s = copy.deepcopy(scenario)
    for key, v in values.items():
        set_key(s, key, v)
    return s


def current_value(scenario, key: str) -> float | None:
    """The value a key has in the scenario, a "Drake default" sentinel resolved where it
    has a number (drake.friction < 0: contact.friction; relaxation_time 0: 0.1 s) and None
    where it has none (drake.point_stiffness 0)."""
    section, field, index = split_key(key)
    v = getattr(getattr(scenario, section), field)
    if index is not None:
        return float(v[index])
    if isinstance(v, list):
        return float(v[0]) if v else 0.0
    if key == "drake.friction" and v < 0:
        return float(scenario.contact.friction)
    if key == "drake.relaxation_time" and v <= 0:
        return 0.1
    if key == "drake.point_stiffness" and v <= 0:
        return None
    return float(v)
