"""A free rigid box on a table, as a MultibodyPlant, and the recording layout it maps to.

The body is a box (size, mass, inertia from the scenario's `body`) on a quaternion
floating joint; its collision geometry is eight small spheres whose surfaces reach the
box's corners, against the table's half space at z = table height. (Drake's signed
distance has no box-vs-half-space; corner spheres also keep point contact from
flipping between corners.) With time_step = 0 the plant is the continuous one the
Anitescu linearizer needs; with time_step > 0 it is a SAP discrete plant (Drake's own
simulation of the same scenario).

Two state layouts:
- the recording's, RECORDING_STATE_NAMES (13): centre position x, y, z (m, world),
  quaternion qw, qx, qy, qz (world from body), linear velocity vx, vy, vz (m/s, world),
  angular velocity wx, wy, wz (rad/s, BODY frame) - the layout of ContactNets' tosses;
- the plant's (13): q = [qw, qx, qy, qz, x, y, z], v = [w_world (3), v_world (3)].
`plant_state` / `recording_state` convert between them (rows or arrays of rows).
"""
from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np
from pydrake.geometry import (AddCompliantHydroelasticProperties, AddContactMaterial,
                              AddRigidHydroelasticProperties, Box, HalfSpace,
                              ProximityProperties, Sphere)
from pydrake.math import RigidTransform
from pydrake.multibody.plant import AddMultibodyPlant, CoulombFriction, MultibodyPlantConfig
from pydrake.multibody.tree import RotationalInertia, SpatialInertia
from pydrake.systems.framework import DiagramBuilder

from adaptive_c3.systems.contact.anitescu_lcs import AnitescuLinearizer, ContactPair

RECORDING_STATE_NAMES = ("x", "y", "z", "qw", "qx", "qy", "qz",
                         "vx", "vy", "vz", "wx", "wy", "wz")
BODY_NAME = "object"
APPROXIMATIONS = ("sap", "similar", "lagged")   # Drake's discrete contact approximations (not
                                                # TAMSI: deprecated by Drake)


@dataclass(frozen=True)
class RigidObjectParams:
    """Everything that shapes the plant (the scenario's body, contact and patch)."""
    half_size: tuple            # m, half-widths along body x, y, z (patched)
    mass: float                 # kg (patched)
    inertia_diag: tuple         # kg m^2 about the centre of mass, body axes (patched)
    table_height: float         # m (patched)
    friction: float
    corner_radius: float        # m
    com_offset: tuple = (0.0, 0.0, 0.0)   # m, centre of mass from the box's centre, body frame

    @classmethod
    def from_scenario(cls, s) -> "RigidObjectParams":
        b, c, p = s.body, s.contact, s.patch
        half = np.asarray(b.box_size, float) / 2 + p.size_offset
        mass = b.mass * p.mass_scale
        if b.inertia_diag:
            inertia = np.asarray(b.inertia_diag, float) * p.mass_scale
        else:   # a solid box of the nominal size
            w = np.asarray(b.box_size, float)
            inertia = mass / 12.0 * np.array([w[1] ** 2 + w[2] ** 2, w[0] ** 2 + w[2] ** 2,
                                              w[0] ** 2 + w[1] ** 2])
        return cls(tuple(float(h) for h in half), float(mass),
                   tuple(float(i) for i in inertia * p.inertia_scale),
                   float(c.table_height + p.table_offset), float(c.friction),
                   float(c.corner_radius), tuple(float(v) for v in p.com_offset))

    @property
    def size(self) -> float:
        """The object's size for error percentages: its longest edge, m."""
        return 2.0 * max(self.half_size)


@dataclass
class RigidObjectPlant:
    diagram: object
    plant: object
    body: object
    contact_pairs: list          # ContactPair per corner, against the table


def build_rigid_object_plant(params: RigidObjectParams, time_step: float = 0.0,
                             point_stiffness: float | None = None,
                             relaxation_time: float | None = None,
                             friction: float | None = None,
                             hydroelastic_modulus: float | None = None,
                             add_systems=None, geometry: str = "corner_spheres",
                             approximation: str = "sap",
                             hunt_crossley_dissipation: float | None = None
                             ) -> RigidObjectPlant:
    """The box + table plant. time_step 0: continuous (for the linearizer); > 0: SAP.
    point_stiffness (N/m) and relaxation_time (s, SAP's dissipation) None: Drake's defaults.
    hydroelastic_modulus (Pa): hydroelastic contact of a compliant box (instead of the corner
    spheres) against a rigid table (None: point contact). add_systems(builder, plant, body), if given, adds
    systems (e.g. force elements) to the diagram before it is built. geometry (point
    contact): "corner_spheres" (eight, up to four contacts on a face) or "box" (one Box:
    one contact point against the half space; SAP only, no contact_pairs for the
    linearizer). approximation (time_step > 0): Drake's discrete contact approximation,
    "sap" (dissipation: relaxation_time), "similar" or "lagged" (convex approximations of
    Hunt-Crossley: dissipation hunt_crossley_dissipation, s/m; relaxation_time ignored).
    hunt_crossley_dissipation None: Drake's default."""
    if approximation not in APPROXIMATIONS:
        raise ValueError(f"approximation must be one of {APPROXIMATIONS}, got {approximation!r}")
    if geometry not in ("corner_spheres", "box"):
        raise ValueError(f"geometry must be corner_spheres or box, got {geometry!r}")
    builder = DiagramBuilder()
    hydro = hydroelastic_modulus is not None
    config = MultibodyPlantConfig(time_step=float(time_step),
                                  contact_model="hydroelastic_with_fallback" if hydro else "point",
                                  discrete_contact_approximation=approximation if time_step > 0 else "")
    plant, _ = AddMultibodyPlant(config, builder)
    plant.set_name("rigid_object_plant")
    mu = params.friction if friction is None else float(friction)
    props = ProximityProperties()
    AddContactMaterial(props, dissipation=hunt_crossley_dissipation,
                       point_stiffness=point_stiffness, friction=CoulombFriction(mu, mu))
    if relaxation_time is not None:
        props.AddProperty("material", "relaxation_time", float(relaxation_time))
    table_props = ProximityProperties(props)
    if hydro:
        AddRigidHydroelasticProperties(table_props)

    body = plant.AddRigidBody(BODY_NAME, SpatialInertia.MakeFromCentralInertia(
        params.mass, np.asarray(params.com_offset, float),
        RotationalInertia(*params.inertia_diag)))
    r = params.corner_radius
    pairs = []
    table = plant.RegisterCollisionGeometry(
        plant.world_body(), RigidTransform([0.0, 0.0, params.table_height]), HalfSpace(),
        "table", table_props)
    box = hydro or geometry == "box"
    if box:     # a (compliant, if hydroelastic) box carries the contact: no corner spheres
        box_props = ProximityProperties(props)
        if hydro:
            AddCompliantHydroelasticProperties(0.5 * min(params.half_size),
                                               float(hydroelastic_modulus), box_props)
        plant.RegisterCollisionGeometry(body, RigidTransform(),
                                        Box(*(2.0 * np.asarray(params.half_size))), "box",
                                        box_props)
    for i, signs in enumerate(itertools.product((-1.0, 1.0), repeat=3) if not box else []):
        centre = np.asarray(signs) * (np.asarray(params.half_size) - r)
        corner = plant.RegisterCollisionGeometry(body, RigidTransform(centre), Sphere(r),
                                                 f"corner{i}", props)
        pairs.append(ContactPair(f"corner{i}_table", corner, table, params.friction))
    plant.Finalize()
    if add_systems is not None:
        add_systems(builder, plant, body)
    diagram = builder.Build()
    return RigidObjectPlant(diagram, plant, body, pairs)


def rigid_object_linearizer(params: RigidObjectParams, dt: float, num_edges: int = 4,
                            eps_c: float = 1e-3) -> AnitescuLinearizer:
    model = build_rigid_object_plant(params, time_step=0.0)
    return AnitescuLinearizer(model.diagram, model.plant, model.contact_pairs,
                              num_edges=num_edges, dt=dt, eps_c=eps_c)


# ---------------------------------------------------------------------- layouts
def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    """[..., 4] unit quaternions (w, x, y, z) -> [..., 3, 3] rotation matrices."""
    q = np.asarray(q, float)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = np.moveaxis(q, -1, 0)
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
    ], -2)


def quaternion_rate(q: np.ndarray, w_world: np.ndarray) -> np.ndarray:
    """q_dot (w, x, y, z) of a unit quaternion turning at w_world (rad/s, world frame):
    0.5 [0, w] (x) q."""
    q, w = np.asarray(q, float), np.asarray(w_world, float)
    return 0.5 * np.r_[-w @ q[1:], q[0] * w + np.cross(w, q[1:])]


def plant_state(x_rec: np.ndarray) -> np.ndarray:
    """Recording layout -> plant layout (quaternion normalised, omega to world)."""
    x_rec = np.asarray(x_rec, float)
    q = x_rec[..., 3:7] / np.linalg.norm(x_rec[..., 3:7], axis=-1, keepdims=True)
    w_world = np.einsum("...ij,...j->...i", quat_to_matrix(q), x_rec[..., 10:13])
    return np.concatenate([q, x_rec[..., 0:3], w_world, x_rec[..., 7:10]], axis=-1)


def recording_state(x_plant: np.ndarray) -> np.ndarray:
    """Plant layout -> recording layout (omega to the body frame)."""
    x_plant = np.asarray(x_plant, float)
    q = x_plant[..., 0:4]
    w_body = np.einsum("...ji,...j->...i", quat_to_matrix(q), x_plant[..., 7:10])
    return np.concatenate([x_plant[..., 4:7], q, x_plant[..., 10:13], w_body], axis=-1)


def orientation_error_deg(q_a: np.ndarray, q_b: np.ndarray) -> np.ndarray:
    """Angle (deg) of the rotation between two arrays of quaternions (w, x, y, z)."""
    q_a = np.asarray(q_a, float)
    q_b = np.asarray(q_b, float)
    dot = np.abs(np.sum(q_a * q_b, axis=-1)) / (np.linalg.norm(q_a, axis=-1)
                                                 * np.linalg.norm(q_b, axis=-1))
    return np.degrees(2.0 * np.arccos(np.clip(dot, 0.0, 1.0)))
