"""The controller's model of the ball-rolling task, as a MultibodyPlant.

An end-effector (EE) sphere on three prismatic joints (world x, y, z) driven by three
force actuators (N), a free ball, and a table: a large box whose top face is the world
plane z = 0. Contacts used by the LCS: EE-ball and ball-table, mu = 1, 4 friction-cone
edges each (m = 8 contact impulses).

State (19, MultibodyPlant's natural order, checked in tests):
    [ee_xyz (m), ball_quat_wxyz, ball_xyz (m), ee_vel (m/s), ball_angvel (rad/s, world),
     ball_vel (m/s, world)]
Input (3): EE forces along world x, y, z (N).

The plant is written with the MultibodyPlant API (no files, no package:// URIs).
With time_step = 0 it is the continuous plant the linearizer needs; with
time_step > 0 it is a SAP / point-contact discrete plant used to check the LCS
against Drake's own simulation.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from pydrake.geometry import (AddContactMaterial, Box, ProximityProperties, SceneGraph,
                              Sphere)
from pydrake.math import RigidTransform
from pydrake.multibody.plant import (AddMultibodyPlant, CoulombFriction, MultibodyPlant,
                                     MultibodyPlantConfig)
from pydrake.multibody.tree import PrismaticJoint, SpatialInertia
from pydrake.systems.framework import Diagram, DiagramBuilder

from adaptive_c3.systems.contact.anitescu_lcs import AnitescuLinearizer, ContactPair

STATE_NAMES = (
    "ee_x_x", "ee_y_x", "ee_z_x",
    "ball_qw", "ball_qx", "ball_qy", "ball_qz", "ball_x", "ball_y", "ball_z",
    "ee_x_v", "ee_y_v", "ee_z_v",
    "ball_wx", "ball_wy", "ball_wz", "ball_vx", "ball_vy", "ball_vz",
)
INPUT_NAMES = ("ee_force_x", "ee_force_y", "ee_force_z")
CONTACT_PAIR_NAMES = ("ee_ball", "ball_table")

# Index helpers into the 19-vector state.
EE_POS = slice(0, 3)
BALL_QUAT = slice(3, 7)
BALL_POS = slice(7, 10)
EE_VEL = slice(10, 13)
BALL_ANGVEL = slice(13, 16)
BALL_VEL = slice(16, 19)

TABLE_SIZE = (2.0, 2.0, 0.1)  # m; top face at z = 0


@dataclass
class ControllerModel:
    """The built model: diagram (plant + scene graph) and the LCS contact pairs."""

    diagram: Diagram
    plant: MultibodyPlant
    scene_graph: SceneGraph
    contact_pairs: list = field(default_factory=list)  # [ContactPair]
    ball_radius: float = 0.0315
    ee_radius: float = 0.0195

    def __iter__(self):  # allows: diagram, plant, scene_graph, pairs = build_...()
        return iter((self.diagram, self.plant, self.scene_graph, self.contact_pairs))


def _proximity(mu: float, stiffness: float | None, dissipation: float | None,
               relaxation_time: float | None) -> ProximityProperties:
    props = ProximityProperties()
    AddContactMaterial(props, dissipation=dissipation, point_stiffness=stiffness,
                       friction=CoulombFriction(mu, mu))
    if relaxation_time is not None:
        props.AddProperty("material", "relaxation_time", relaxation_time)
    return props


def build_controller_plant(ball_radius: float = 0.0315, ball_mass: float = 0.132,
                           ee_radius: float = 0.0195, ee_mass: float = 0.01,
                           mu: float = 1.0, time_step: float = 0.0,
                           point_stiffness: float | None = None,
                           hunt_crossley_dissipation: float | None = None,
                           relaxation_time: float | None = None,
                           gravity: bool = True) -> ControllerModel:
    """Build the EE + ball + table plant with its SceneGraph in a Diagram.

    time_step = 0 gives a continuous plant; time_step > 0 a discrete plant with SAP and
    point contact. point_stiffness (N/m), hunt_crossley_dissipation (s/m) and
    relaxation_time (s, SAP's dissipation time scale) set the compliant contact
    material of the simulated plant; None keeps Drake's defaults. They do not enter
    the LCS (which is rigid, Anitescu).
    """
    for name, value in (("ball_radius", ball_radius), ("ball_mass", ball_mass),
                        ("ee_radius", ee_radius), ("ee_mass", ee_mass)):
        if not (np.isfinite(value) and value > 0):
            raise ValueError(f"{name} must be a positive number, got {value}")
    if not (np.isfinite(mu) and mu >= 0):
        raise ValueError(f"mu must be >= 0, got {mu}")
    builder = DiagramBuilder()
    config = MultibodyPlantConfig(time_step=float(time_step),
                                  discrete_contact_approximation="sap" if time_step > 0
                                  else "",
                                  contact_model="point")
    plant, scene_graph = AddMultibodyPlant(config, builder)
    plant.set_name("ball_rolling_plant")
    props = _proximity(mu, point_stiffness, hunt_crossley_dissipation, relaxation_time)

    # End effector: three prismatic joints world -> ee_x_link -> ee_y_link -> ee.
    ee_inst = plant.AddModelInstance("ee")
    link_x = plant.AddRigidBody("ee_x_link", ee_inst, SpatialInertia.Zero())
    link_y = plant.AddRigidBody("ee_y_link", ee_inst, SpatialInertia.Zero())
    ee = plant.AddRigidBody("ee", ee_inst,
                            SpatialInertia.SolidSphereWithMass(ee_mass, ee_radius))
    joints = [
        plant.AddJoint(PrismaticJoint("ee_x", plant.world_frame(), link_x.body_frame(),
                                      [1.0, 0.0, 0.0])),
        plant.AddJoint(PrismaticJoint("ee_y", link_x.body_frame(), link_y.body_frame(),
                                      [0.0, 1.0, 0.0])),
        plant.AddJoint(PrismaticJoint("ee_z", link_y.body_frame(), ee.body_frame(),
                                      [0.0, 0.0, 1.0])),
    ]
    for joint, name in zip(joints, INPUT_NAMES):
        plant.AddJointActuator(name, joint)
    ee_geom = plant.RegisterCollisionGeometry(ee, RigidTransform(), Sphere(ee_radius),
                                              "ee_collision", props)
    plant.RegisterVisualGeometry(ee, RigidTransform(), Sphere(ee_radius), "ee_visual",
                                 np.array([0.8, 0.2, 0.2, 1.0]))

    # Ball: a free body (quaternion floating joint added at Finalize).
    ball_inst = plant.AddModelInstance("ball")
    ball = plant.AddRigidBody("ball", ball_inst,
                              SpatialInertia.SolidSphereWithMass(ball_mass, ball_radius))
    ball_geom = plant.RegisterCollisionGeometry(ball, RigidTransform(),
                                                Sphere(ball_radius), "ball_collision",
                                                props)
    plant.RegisterVisualGeometry(ball, RigidTransform(), Sphere(ball_radius),
                                 "ball_visual", np.array([0.1, 0.4, 0.9, 1.0]))

    # Table: a large box welded to the world, top face at z = 0.
    X_WT = RigidTransform([0.0, 0.0, -TABLE_SIZE[2] / 2])
    table_geom = plant.RegisterCollisionGeometry(plant.world_body(), X_WT,
                                                 Box(*TABLE_SIZE), "table_collision",
                                                 props)
    plant.RegisterVisualGeometry(plant.world_body(), X_WT, Box(*TABLE_SIZE),
                                 "table_visual", np.array([0.6, 0.5, 0.4, 1.0]))
    if not gravity:
        plant.mutable_gravity_field().set_gravity_vector([0.0, 0.0, 0.0])
    plant.Finalize()
    diagram = builder.Build()

    pairs = [ContactPair("ee_ball", ee_geom, ball_geom, mu),
             ContactPair("ball_table", ball_geom, table_geom, mu)]
    return ControllerModel(diagram, plant, scene_graph, pairs, ball_radius, ee_radius)


def ball_rolling_linearizer(dt: float = 0.1, num_edges: int = 4, eps_c: float = 1e-2,
                            **model_kwargs) -> AnitescuLinearizer:
    """An AnitescuLinearizer for the continuous controller model (kwargs -> the plant)."""
    model_kwargs.pop("time_step", None)
    model = build_controller_plant(time_step=0.0, **model_kwargs)
    return AnitescuLinearizer(model.diagram, model.plant, model.contact_pairs,
                              num_edges=num_edges, dt=dt, eps_c=eps_c)


def ee_input_from_motion(ee_mass: float, gravity: float = 9.81):
    """f(x_k, x_next, dt) -> the EE force (N, world frame) under which the model's free EE
    (mass ee_mass) moves as measured: m (v_next - v_k) / dt + m g. For the residual learner:
    the real EE is position controlled by an arm whose force law is not the model's, so the
    model is handed the input that reproduces the EE's measured motion."""
    weight = np.array([0.0, 0.0, ee_mass * gravity])

    def u_from_motion(x_k, x_next, dt):
        return ee_mass * (np.asarray(x_next)[EE_VEL] - np.asarray(x_k)[EE_VEL]) / dt + weight
    return u_from_motion


def default_state(ball_xy=(0.55, 0.0), ee_offset=None, ball_radius: float = 0.0315,
                  ee_radius: float = 0.0195) -> np.ndarray:
    """A 19-state with the ball resting on the table at ball_xy (identity orientation)
    and the EE centred at ball centre + ee_offset; the default offset puts the EE
    touching the ball from -x at the ball's centre height."""
    x = np.zeros(len(STATE_NAMES))
    ball = np.array([ball_xy[0], ball_xy[1], ball_radius])
    if ee_offset is None:
        ee_offset = (-(ball_radius + ee_radius), 0.0, 0.0)
    x[BALL_QUAT] = [1.0, 0.0, 0.0, 0.0]
    x[BALL_POS] = ball
    x[EE_POS] = ball + np.asarray(ee_offset, float)
    return x
