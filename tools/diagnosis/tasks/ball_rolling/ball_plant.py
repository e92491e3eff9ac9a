"""The ball-rolling world in Drake, shared by the concealed-draw harness (which makes data
with it) and the `drake` diagnosis backend (which replays recordings through it).

An EE tip sphere on three prismatic joints (x, y, z, world frame, actuated: the recorded
EE force, N), a free ball, a table (a box whose top is at world z = table_z); discrete
MultibodyPlant with SAP and point contact. Every geometry gets the same point stiffness
(N/m; Drake combines a pair's in series: the pair's is half) and SAP relaxation time (s);
friction per geometry (Drake combines a pair's as 2ab/(a+b): `geometry_friction` turns
per-pair coefficients into per-geometry ones).

`copies` > 1 builds that many independent EE + ball worlds side by side in one plant
(copy i shifted by i * SPACING in world x, one shared table), so many rollout windows
advance with one discrete update (Drake's per-update overhead, ~0.25 ms, dominates one
small world). Copy 0 is named `ee` / `ball`, copy i `ee_i` / `ball_i`.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

SPACING = 1.0             # m between copies in world x (windows move mm-cm)
TABLE_SIZE = 2.0          # m, the table's edge for one copy


@dataclass(frozen=True)
class BallWorld:
    """Physical parameters of the world: lengths m, masses kg, stiffness N/m, times s."""
    ee_radius: float = 0.0195
    ball_radius: float = 0.0315
    ball_mass: float = 0.132
    ee_mass: float = 1.0
    mu_ee: float = 1.0            # per geometry (see geometry_friction)
    mu_ball: float = 1.0
    mu_table: float = 1.0
    stiffness: float = 1e5        # point stiffness of every geometry
    relaxation_time: float = 2e-3
    table_z: float = 0.0          # world z of the table top
    time_step: float = 1e-3       # SAP step


def geometry_friction(mu_ee_ball: float, mu_ball_table: float) -> tuple[float, float, float]:
    """(mu_ee, mu_ball, mu_table) per geometry whose combinations 2ab/(a+b) are the given
    per-pair coefficients (the ball gets the larger one; both pairs exact)."""
    from adaptive_c3.models.ball_rolling_scene import partner_friction
    mb = max(mu_ee_ball, mu_ball_table)
    return partner_friction(mu_ee_ball, mb), mb, partner_friction(mu_ball_table, mb)


@dataclass
class BallPlant:
    plant: object
    diagram: object
    copies: int
    q_idx: np.ndarray        # [copies, 10] plant position index of recording q rows 0-9
    v_idx: np.ndarray        # [copies, 9] plant velocity index of recording v rows 10-18
    ball_bodies: list        # BodyIndex of each copy's ball

    def to_plant(self, X: np.ndarray) -> np.ndarray:
        """Plant state [nq + nv] from recording-layout states X [copies, 19] (copy i
        shifted by i * SPACING in x)."""
        plant = self.plant
        nq = plant.num_positions()
        x = np.zeros(nq + plant.num_velocities())
        Xs = np.array(X, float)
        shift = SPACING * np.arange(self.copies)
        Xs[:, 0] += shift
        Xs[:, 7] += shift
        x[self.q_idx] = Xs[:, :10]
        x[nq + self.v_idx] = Xs[:, 10:19]
        return x

    def from_plant(self, x: np.ndarray) -> np.ndarray:
        """Recording-layout states [copies, 19] of a plant state (shift undone)."""
        nq = self.plant.num_positions()
        X = np.concatenate([x[self.q_idx], x[nq + self.v_idx]], axis=1)
        shift = SPACING * np.arange(self.copies)
        X[:, 0] -= shift
        X[:, 7] -= shift
        return X


def proximity_properties(stiffness: float, relaxation_time: float, mu: float):
    """A geometry's contact material: point stiffness (N/m), SAP relaxation time (s) and
    friction mu (static = dynamic)."""
    from pydrake.geometry import AddContactMaterial, ProximityProperties
    from pydrake.multibody.plant import CoulombFriction
    props = ProximityProperties()
    AddContactMaterial(props, point_stiffness=stiffness, friction=CoulombFriction(mu, mu))
    props.AddProperty("material", "relaxation_time", relaxation_time)
    return props


def build_ball_plant(w: BallWorld, copies: int = 1, add_systems=None,
                     sampled_outputs: bool = True) -> BallPlant:
    """The world's diagram (see the module doc). add_systems(builder, plant, ball_bodies):
    a hook that adds systems (e.g. force elements) before the diagram is built.
    sampled_outputs False: the plant's output ports are computed when read instead of
    stored at every step (MultibodyPlantConfig.use_sampled_output_ports); the same
    states, less work per step, for a caller that reads only the state."""
    from pydrake.geometry import Box, Sphere
    from pydrake.math import RigidTransform
    from pydrake.multibody.plant import AddMultibodyPlant, MultibodyPlantConfig
    from pydrake.multibody.tree import PrismaticJoint, SpatialInertia
    from pydrake.systems.framework import DiagramBuilder
    builder = DiagramBuilder()
    plant, _ = AddMultibodyPlant(MultibodyPlantConfig(
        time_step=w.time_step, discrete_contact_approximation="sap", contact_model="point",
        use_sampled_output_ports=sampled_outputs), builder)

    def props(m):
        return proximity_properties(w.stiffness, w.relaxation_time, m)
    ees, balls = [], []
    for i in range(copies):
        tag = "" if i == 0 else f"_{i}"
        inst = plant.AddModelInstance("ee" + tag)
        lx = plant.AddRigidBody("ee_x_link", inst, SpatialInertia.Zero())
        ly = plant.AddRigidBody("ee_y_link", inst, SpatialInertia.Zero())
        ee = plant.AddRigidBody("ee", inst,
                                SpatialInertia.SolidSphereWithMass(w.ee_mass, w.ee_radius))
        joints = []
        for name, a, b, ax in (("ee_x", plant.world_frame(), lx.body_frame(), [1, 0, 0]),
                               ("ee_y", lx.body_frame(), ly.body_frame(), [0, 1, 0]),
                               ("ee_z", ly.body_frame(), ee.body_frame(), [0, 0, 1])):
            joint = plant.AddJoint(PrismaticJoint(name, a, b, ax))
            plant.AddJointActuator(name, joint)
            joints.append(joint)
        plant.RegisterCollisionGeometry(ee, RigidTransform(), Sphere(w.ee_radius), "ee",
                                        props(w.mu_ee))
        binst = plant.AddModelInstance("ball" + tag)
        ball = plant.AddRigidBody("ball", binst,
                                  SpatialInertia.SolidSphereWithMass(w.ball_mass, w.ball_radius))
        plant.RegisterCollisionGeometry(ball, RigidTransform(), Sphere(w.ball_radius), "ball",
                                        props(w.mu_ball))
        ees.append(joints)
        balls.append(ball)
    length = TABLE_SIZE + SPACING * (copies - 1)
    plant.RegisterCollisionGeometry(
        plant.world_body(), RigidTransform([0.5 * SPACING * (copies - 1), 0, w.table_z - 0.05]),
        Box(length, TABLE_SIZE, 0.1), "table", props(w.mu_table))
    plant.Finalize()
    if add_systems is not None:
        add_systems(builder, plant, [b.index() for b in balls])
    diagram = builder.Build()
    q_idx = np.array([[j.position_start() for j in joints]
                      + list(range(b.floating_positions_start(), b.floating_positions_start() + 7))
                      for joints, b in zip(ees, balls)])
    v_idx = np.array([[j.velocity_start() for j in joints]
                      + list(range(b.floating_velocities_start_in_v(),
                                   b.floating_velocities_start_in_v() + 6))
                      for joints, b in zip(ees, balls)])
    return BallPlant(plant, diagram, copies, q_idx, v_idx, [b.index() for b in balls])
