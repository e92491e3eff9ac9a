"""The ball-rolling scene: Panda arm, table and ball, added to a MultibodyPlant.

Frames and units: world frame W = the robot base frame (panda_link0 welded at the
origin), metres, kg. The table is a large box whose TOP face is the plane z = 0 of W,
i.e. the robot base stands on the table top, as in the controller (LCS) model where the
table top is z = 0. The ball therefore rests with its centre at z = ball radius.

Everything is offline: the arm comes from models/panda.urdf (no package:// URIs), the
table and ball are Drake primitives.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pydrake.geometry import Box, HalfSpace, ProximityProperties, RoleAssign, Sphere
from pydrake.math import RigidTransform
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import CoulombFriction, MultibodyPlant
from pydrake.multibody.tree import ModelInstanceIndex, PrismaticJoint, SpatialInertia

from adaptive_c3.models.drake_warnings import silence_half_space_deformable_warning

PANDA_URDF = Path(__file__).with_name("panda.urdf")
EE_TIP_FRAME = "panda_ee_tip"   # sphere centre of the end-effector tool
FLANGE_FRAME = "panda_link8"
BASE_FRAME = "panda_link0"

TABLE_TOP_Z = 0.0               # m, table top in the world / robot base frame
BALL_RADIUS = 0.0315            # m (reference experiment)
BALL_MASS = 0.132               # kg
BALL_COLOR = (1.0, 0.4, 0.0, 1.0)   # bright orange (RGBA): what the detector looks for
TABLE_COLOR = (0.55, 0.55, 0.52, 1.0)  # neutral grey: no hue for the detector to confuse
# Table box: x from -0.3 to 1.1 m, y from -0.6 to 0.6 m (covers the base and the circle
# of radius 0.1 m about (0.55, 0)), 0.05 m thick.
TABLE_SIZE = (1.4, 1.2, 0.05)
TABLE_CENTER_XY = (0.4, 0.0)


def panda_urdf_path() -> str:
    """Absolute path of the project's Panda URDF."""
    return str(PANDA_URDF)


def add_panda(plant: MultibodyPlant, name: str | None = None) -> ModelInstanceIndex:
    """Adds the Panda (from models/panda.urdf) welded to the world at the origin."""
    parser = Parser(plant)
    if name is not None:
        parser.SetAutoRenaming(True)
    (panda,) = parser.AddModels(file_name=str(PANDA_URDF))
    if name is not None:
        plant.RenameModelInstance(panda, name)
    plant.WeldFrames(plant.world_frame(),
                     plant.GetFrameByName(BASE_FRAME, panda), RigidTransform())
    return panda


def add_table(plant: MultibodyPlant, *, top_z: float = TABLE_TOP_Z,
              size=TABLE_SIZE, center_xy=TABLE_CENTER_XY, mu: float = 1.0,
              color=TABLE_COLOR, half_space: bool = False) -> None:
    """Registers a table box on the world body with its top face at z = top_z.

    half_space=True: the collision geometry is the half space below z = top_z instead
    of the box (the visual stays the box). A compliant fruit meets a half space more
    cheaply than the box's rigid-hydroelastic mesh (a whole fruit trial: real-time
    factor 0.35 -> 0.44); an object that leaves the box's top then stays on the
    infinite plane, so judge "off the table" from its x-y position."""
    X_WT = RigidTransform([center_xy[0], center_xy[1], top_z - size[2] / 2])
    box = Box(*size)
    world = plant.world_body()
    if half_space:
        silence_half_space_deformable_warning()
        plant.RegisterCollisionGeometry(world, RigidTransform([0.0, 0.0, top_z]),
                                        HalfSpace(), "table_collision",
                                        CoulombFriction(mu, mu))
    else:
        plant.RegisterCollisionGeometry(world, X_WT, box, "table_collision",
                                        CoulombFriction(mu, mu))
    plant.RegisterVisualGeometry(world, X_WT, box, "table_visual",
                                 np.asarray(color, float))


def add_ball(plant: MultibodyPlant, *, radius: float = BALL_RADIUS,
             mass: float = BALL_MASS, color=BALL_COLOR, mu: float = 1.0,
             name: str = "ball") -> ModelInstanceIndex:
    """Adds a free solid sphere (its own model instance `name`, body `name`)."""
    instance = plant.AddModelInstance(name)
    body = plant.AddRigidBody(name, instance,
                              SpatialInertia.SolidSphereWithMass(mass, radius))
    plant.RegisterCollisionGeometry(body, RigidTransform(), Sphere(radius),
                                    f"{name}_collision", CoulombFriction(mu, mu))
    plant.RegisterVisualGeometry(body, RigidTransform(), Sphere(radius),
                                 f"{name}_visual", np.asarray(color, float))
    return instance


@dataclass(frozen=True)
class BallRollingScene:
    """Handles to what add_ball_rolling_scene added."""
    panda: ModelInstanceIndex | None
    ball: ModelInstanceIndex
    ball_radius: float
    table_top_z: float


def add_ball_rolling_scene(plant: MultibodyPlant, *, ball_radius: float = BALL_RADIUS,
                           ball_mass: float = BALL_MASS, ball_color=BALL_COLOR,
                           ball_position=(0.65, 0.0), mu: float = 1.0,
                           table_top_z: float = TABLE_TOP_Z,
                           with_arm: bool = True, fruit=None) -> BallRollingScene:
    """Adds arm (welded at the origin), table (top at table_top_z) and a free ball.

    The ball's default pose is at rest on the table at (ball_position[0],
    ball_position[1], table_top_z + ball_radius). `mu` is the Coulomb friction of
    every geometry added here (Drake combines a pair's coefficients). with_arm=False
    gives the camera/detector test scene (table + ball only). fruit: a FruitSpec
    (models/fruit.py) put in place of the ball, in a model instance also named "ball"
    (then call models.fruit.make_rigid_hydroelastic after Finalize, so the compliant
    fruit meets the table with hydroelastic contact). Call before Finalize().
    """
    panda = add_panda(plant) if with_arm else None
    add_table(plant, top_z=table_top_z, mu=mu, half_space=fruit is not None)
    if fruit is not None:   # a models.fruit.FruitSpec instead of the ball
        from adaptive_c3.models.fruit import add_fruit
        body = add_fruit(plant, fruit, name="ball", position=ball_position, mu=mu,
                         table_top_z=table_top_z)
        return BallRollingScene(panda, body.model_instance(), fruit.radius, table_top_z)
    ball = add_ball(plant, radius=ball_radius, mass=ball_mass, color=ball_color, mu=mu)
    body = plant.GetBodyByName("ball", ball)
    plant.SetDefaultFloatingBaseBodyPose(body, RigidTransform(
        [ball_position[0], ball_position[1], table_top_z + ball_radius]))
    return BallRollingScene(panda, ball, ball_radius, table_top_z)


def partner_friction(pair_mu: float, other_mu: float) -> float:
    """The coefficient a geometry needs so that Drake's combination with a geometry of
    other_mu, 2ab/(a+b), is pair_mu (needs pair_mu < 2 other_mu)."""
    return pair_mu * other_mu / (2 * other_mu - pair_mu)


def set_body_friction(plant: MultibodyPlant, scene_graph, body, mu: float) -> None:
    """Replaces the Coulomb friction (static = dynamic = mu) of every collision geometry
    of `body`, keeping the rest of its proximity properties. Call after Finalize and
    before a context is created."""
    inspector = scene_graph.model_inspector()
    for gid in plant.GetCollisionGeometriesForBody(body):
        props = ProximityProperties(inspector.GetProximityProperties(gid))
        props.UpdateProperty("material", "coulomb_friction", CoulombFriction(mu, mu))
        scene_graph.AssignRole(plant.get_source_id(), gid, props, RoleAssign.kReplace)


def add_point_ee(plant: MultibodyPlant, *, radius: float = 0.0195, mass: float = 1.0,
                 position=(0.55, 0.0, 0.1), mu: float = 1.0,
                 name: str = "point_ee") -> ModelInstanceIndex:
    """A sphere on three world prismatic joints (x, y, z) with force actuators - the
    controller model's EE with a realistic mass, for robot: point_ee. The instance's
    state is [x, y, z, vx, vy, vz]; its actuation [fx, fy, fz] (N, world)."""
    instance = plant.AddModelInstance(name)
    link_x = plant.AddRigidBody(f"{name}_x_link", instance, SpatialInertia.Zero())
    link_y = plant.AddRigidBody(f"{name}_y_link", instance, SpatialInertia.Zero())
    tip = plant.AddRigidBody(name, instance, SpatialInertia.SolidSphereWithMass(mass, radius))
    frames = (plant.world_frame(), link_x.body_frame(), link_y.body_frame(), tip.body_frame())
    for i, axis in enumerate(np.eye(3)):
        joint = plant.AddJoint(PrismaticJoint(f"{name}_{'xyz'[i]}", frames[i], frames[i + 1],
                                              axis))
        joint.set_default_translation(float(position[i]))
        plant.AddJointActuator(f"{name}_{'xyz'[i]}", joint)
    plant.RegisterCollisionGeometry(tip, RigidTransform(), Sphere(radius),
                                    f"{name}_collision", CoulombFriction(mu, mu))
    plant.RegisterVisualGeometry(tip, RigidTransform(), Sphere(radius), f"{name}_visual",
                                 np.array([0.3, 0.3, 0.35, 1.0]))
    return instance


def make_arm_plant(time_step: float = 0.0, gravity: bool = True) -> MultibodyPlant:
    """A finalized plant holding only the Panda (welded at the origin).

    Used as the internal model of the impedance controller and the simulated driver
    (kinematics, Jacobians, mass matrix, gravity torques). No SceneGraph.
    """
    plant = MultibodyPlant(time_step)
    add_panda(plant)
    if not gravity:
        plant.mutable_gravity_field().set_gravity_vector([0.0, 0.0, 0.0])
    plant.Finalize()
    return plant
