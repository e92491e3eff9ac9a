"""Schema of the rigid-object scenarios (a free body tossed onto a table, no input).

Registered with the scenario loader under `task: rigid_object`. The model is the
Anitescu LCS of a MultibodyPlant (models/rigid_object.py): the object's corners (small
spheres) against the table's half space, at the recording's time step. `patch` holds
the effects `diagnose` may add to that model; all zero / one means the plain rigid model.
"""
import dataclasses as dc
import math
from typing import List

from adaptive_c3.scenarios.common import ScenarioError, register_task


@dc.dataclass
class RigidBodySpec:
    """The object: a box of box_size (m, body x, y, z) with its centre of mass at the
    box centre; inertia_diag (kg m^2, body frame) empty means a solid box of that mass."""
    box_size: List[float] = dc.field(default_factory=lambda: [0.1048, 0.1048, 0.1048])
    mass: float = 0.37               # kg
    inertia_diag: List[float] = dc.field(default_factory=list)


@dc.dataclass
class ContactModel:
    """The rigid model's contact: corner spheres against the table's half space."""
    table_height: float = 0.0        # m, table top in world z
    friction: float = 0.18           # mu (the ContactNets authors' estimate for the cube)
    friction_edges: int = 4          # n_e per corner
    eps_c: float = 1.0e-3            # Anitescu regulariser, 1/kg (F positive definite)
    corner_radius: float = 1.0e-3    # m, the corner spheres (their surface reaches the corner)
    dt: float = 0.0                  # LCS step, s; 0 = the recording's step


@dc.dataclass
class ModelPatch:
    """Effects added to the rigid model (what `diagnose` fits; 0 / 1 = none)."""
    table_offset: float = 0.0        # m, added to table_height
    size_offset: float = 0.0         # m, added to each box edge's half-width
    restitution: float = 0.0         # Newton restitution of the normal approach speed
    torsional_friction: float = 0.0  # m, torque about the table normal per unit normal force
    mass_scale: float = 1.0          # scales mass and inertia together
    inertia_scale: float = 1.0       # scales the inertia only
    r_comp: List[float] = dc.field(default_factory=list)  # additive complementarity residual
    # m, the centre of mass from the box's centre, body frame (an uneven shell, a weight on
    # one face); the recorded position stays the box's centre
    com_offset: List[float] = dc.field(default_factory=lambda: [0.0, 0.0, 0.0])


@dc.dataclass
class DrakeBaseline:
    """The true-world simulation of the scenario: Drake's MultibodyPlant with SAP (`evaluate
    --model drake`, `diagnose --model drake`), geometry, mass and inertia from `body`,
    `contact` and the geometry/inertia keys of `patch`."""
    time_step: float = 0.0           # s; 0 = the recording's step / 4
    contact_model: str = "point"     # "point" (corner spheres) or "hydroelastic" (a compliant box)
    point_stiffness: float = 0.0     # N/m; 0 = Drake's default
    hydroelastic_modulus: float = 1.0e7   # Pa, the box (contact_model hydroelastic)
    relaxation_time: float = 0.0     # s, SAP's dissipation time scale; 0 = Drake's default
    friction: float = -1.0           # < 0 = contact.friction (SAP uses one coefficient)
    viscous_drag: float = 0.0        # N s/m, force -c v on the body's centre (world)
    angular_drag: float = 0.0        # N m s, torque -c w (world)
    external_force: List[float] = dc.field(default_factory=lambda: [0.0, 0.0, 0.0])  # N, world
    torsional_friction: float = 0.0  # m, torque per N of normal force against spin about the table normal
    rolling_resistance: float = 0.0  # m, torque per N of normal force against rotation in the table plane
    contact_geometry: str = "corner_spheres"   # point contact: "corner_spheres" or "box" (one contact point)
    discrete_contact_approximation: str = "sap"   # Drake's: "sap", "similar" or "lagged"
    hunt_crossley_dissipation: float = -1.0   # s/m, used by similar/lagged (not SAP); < 0 = Drake's default


@dc.dataclass
class RigidObjectScenario:
    task: str = "rigid_object"
    name: str = "rigid_object"
    body: RigidBodySpec = dc.field(default_factory=RigidBodySpec)
    contact: ContactModel = dc.field(default_factory=ContactModel)
    patch: ModelPatch = dc.field(default_factory=ModelPatch)
    drake: DrakeBaseline = dc.field(default_factory=DrakeBaseline)
    seed: int = 0


def validate_rigid_object(s: RigidObjectScenario) -> None:
    def need(cond, msg):
        if not cond:
            raise ScenarioError(msg)

    def finite(v):
        return isinstance(v, (int, float)) and math.isfinite(v)

    b, c, p, d = s.body, s.contact, s.patch, s.drake
    need(len(b.box_size) == 3 and all(finite(v) and v > 0 for v in b.box_size),
         f"body.box_size must be 3 lengths > 0, got {b.box_size}")
    need(finite(b.mass) and b.mass > 0, f"body.mass must be > 0, got {b.mass}")
    need(len(b.inertia_diag) in (0, 3) and all(finite(v) and v > 0 for v in b.inertia_diag),
         f"body.inertia_diag must be empty or 3 values > 0, got {b.inertia_diag}")
    need(finite(c.table_height), "contact.table_height must be finite")
    need(finite(c.friction) and c.friction >= 0, f"contact.friction must be >= 0, got {c.friction}")
    need(c.friction_edges >= 2, f"contact.friction_edges must be >= 2, got {c.friction_edges}")
    need(finite(c.eps_c) and c.eps_c > 0, f"contact.eps_c must be > 0, got {c.eps_c}")
    need(finite(c.corner_radius) and 0 < c.corner_radius < min(b.box_size) / 2,
         f"contact.corner_radius must be in (0, half the smallest edge), got {c.corner_radius}")
    need(finite(c.dt) and c.dt >= 0, f"contact.dt must be >= 0 (0: the recording's), got {c.dt}")
    need(finite(p.table_offset) and abs(p.table_offset) < 0.1, "patch.table_offset must be within 0.1 m")
    need(finite(p.size_offset) and min(b.box_size) / 2 + p.size_offset > c.corner_radius,
         f"patch.size_offset leaves no box, got {p.size_offset}")
    need(finite(p.restitution) and 0 <= p.restitution <= 1,
         f"patch.restitution must be in [0, 1], got {p.restitution}")
    need(finite(p.torsional_friction) and 0 <= p.torsional_friction < 0.1,
         f"patch.torsional_friction must be in [0, 0.1) m, got {p.torsional_friction}")
    for key in ("mass_scale", "inertia_scale"):
        v = getattr(p, key)
        need(finite(v) and v > 0, f"patch.{key} must be > 0, got {v}")
    need(all(finite(v) for v in p.r_comp), "patch.r_comp must be finite")
    need(len(p.com_offset) == 3 and all(finite(v) and abs(v) < min(b.box_size) / 2
                                        for v in p.com_offset),
         f"patch.com_offset must be 3 values (m) inside the box, got {p.com_offset}")
    need(finite(d.time_step) and d.time_step >= 0, f"drake.time_step must be >= 0, got {d.time_step}")
    need(finite(d.point_stiffness) and d.point_stiffness >= 0, "drake.point_stiffness must be >= 0")
    need(finite(d.relaxation_time) and d.relaxation_time >= 0, "drake.relaxation_time must be >= 0")
    need(finite(d.friction), "drake.friction must be finite")
    need(d.contact_model in ("point", "hydroelastic"),
         f"drake.contact_model must be point or hydroelastic, got {d.contact_model!r}")
    need(finite(d.hydroelastic_modulus) and d.hydroelastic_modulus > 0,
         "drake.hydroelastic_modulus must be > 0")
    need(finite(d.viscous_drag) and d.viscous_drag >= 0, "drake.viscous_drag must be >= 0")
    need(finite(d.angular_drag) and d.angular_drag >= 0, "drake.angular_drag must be >= 0")
    need(len(d.external_force) == 3 and all(finite(v) for v in d.external_force),
         f"drake.external_force must be 3 finite values (N), got {d.external_force}")
    for key in ("torsional_friction", "rolling_resistance"):
        v = getattr(d, key)
        need(finite(v) and 0 <= v < 0.1, f"drake.{key} must be in [0, 0.1) m, got {v}")
    need(d.contact_geometry in ("corner_spheres", "box"),
         f"drake.contact_geometry must be corner_spheres or box, got {d.contact_geometry!r}")
    need(d.discrete_contact_approximation in ("sap", "similar", "lagged"),
         "drake.discrete_contact_approximation must be sap, similar or lagged, got "
         f"{d.discrete_contact_approximation!r}")
    need(finite(d.hunt_crossley_dissipation),
         "drake.hunt_crossley_dissipation must be finite (< 0: Drake's default)")


register_task("rigid_object", RigidObjectScenario, validate_rigid_object)
