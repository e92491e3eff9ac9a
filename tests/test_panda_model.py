"""The Panda URDF against the published kinematics, and the ball-rolling scene."""
import numpy as np
import pytest
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph, MultibodyPlant
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource

from adaptive_c3.models import panda_kinematics as pk
from adaptive_c3.models.ball_rolling_scene import (BALL_RADIUS, EE_TIP_FRAME,
                                                   FLANGE_FRAME, add_ball_rolling_scene,
                                                   panda_urdf_path)
from adaptive_c3.systems.franka.panda_sim_driver import GravityCompensatedDriver

# Published link masses (kg) of Gaz et al. 2019, links 1..7.
GAZ_MASSES = [4.970684, 0.646926, 3.228604, 3.587895, 1.225946, 1.666555, 0.735522]


@pytest.fixture(scope="module")
def arm():
    plant = MultibodyPlant(0.0)
    (panda,) = Parser(plant).AddModels(panda_urdf_path())
    plant.WeldFrames(plant.world_frame(), plant.GetFrameByName("panda_link0"))
    plant.Finalize()
    return plant, panda, plant.CreateDefaultContext()


def drake_pose(arm, frame, q):
    plant, _, ctx = arm
    plant.SetPositions(ctx, q)
    return plant.CalcRelativeTransform(ctx, plant.world_frame(),
                                       plant.GetFrameByName(frame)).GetAsMatrix4()


def test_structure_limits_and_actuators(arm):
    plant, panda, _ = arm
    assert plant.num_positions() == 7 and plant.num_actuators() == 7
    joints = [plant.GetJointByName(f"panda_joint{i}") for i in range(1, 8)]
    assert np.allclose([j.position_lower_limits()[0] for j in joints], pk.Q_MIN)
    assert np.allclose([j.position_upper_limits()[0] for j in joints], pk.Q_MAX)
    assert np.allclose([j.velocity_upper_limits()[0] for j in joints], pk.V_MAX)
    efforts = [plant.get_joint_actuator(i).effort_limit()
               for i in plant.GetJointActuatorIndices(panda)]
    assert efforts == [87.0] * 4 + [12.0] * 3
    masses = [plant.GetBodyByName(f"panda_link{i}").default_mass() for i in range(1, 8)]
    assert np.allclose(masses, GAZ_MASSES)
    tip = plant.GetBodyByName(EE_TIP_FRAME)
    assert tip.default_mass() > 0


def test_zero_configuration_matches_published_flange_pose(arm):
    # Franka docs: at q = 0 the flange is at x = a7 = 0.088 m,
    # z = d1 + d3 + d5 - d_flange = 0.333 + 0.316 + 0.384 - 0.107 = 0.926 m,
    # pointing down (flange z = -world z, flange y = -world y).
    X = drake_pose(arm, FLANGE_FRAME, np.zeros(7))
    assert np.allclose(X[:3, 3], [0.088, 0.0, 0.926], atol=1e-9)
    assert np.allclose(X[:3, :3], np.diag([1.0, -1.0, -1.0]), atol=1e-9)


@pytest.mark.parametrize("name", ["zero", "q_null", "random"])
def test_forward_kinematics_matches_dh(arm, name):
    rng = np.random.default_rng(42)
    if name == "zero":
        qs = [np.zeros(7)]
    elif name == "q_null":
        qs = [pk.Q_NULL]
    else:
        qs = [rng.uniform(pk.Q_MIN, pk.Q_MAX) for _ in range(25)]
    worst = 0.0
    for q in qs:
        for frame, X_dh in ((FLANGE_FRAME, pk.flange_pose(q)),
                            (EE_TIP_FRAME, pk.tip_pose(q))):
            X = drake_pose(arm, frame, q)
            worst = max(worst, np.abs(X - X_dh).max())
        # Every intermediate link frame too.
        for i, X_dh in enumerate(pk.link_transforms(q)[:7], start=1):
            worst = max(worst, np.abs(drake_pose(arm, f"panda_link{i}", q) - X_dh).max())
    print(f"FK max |Drake - DH| ({name}): {worst:.2e}")
    assert worst < 1e-6


def test_q_null_puts_tip_over_the_circle_centre():
    X = pk.tip_pose(pk.Q_NULL)
    assert np.allclose(X[:2, 3], [0.55, 0.0], atol=1e-3)
    assert 0.05 < X[2, 3] < 0.15


def test_dh_jacobian_and_ik(arm):
    plant, _, ctx = arm
    rng = np.random.default_rng(3)
    q = pk.Q_NULL + 0.2 * rng.normal(size=7)
    plant.SetPositions(ctx, q)
    from pydrake.multibody.tree import JacobianWrtVariable
    J = plant.CalcJacobianSpatialVelocity(ctx, JacobianWrtVariable.kV,
                                          plant.GetFrameByName(EE_TIP_FRAME), np.zeros(3),
                                          plant.world_frame(), plant.world_frame())
    assert np.allclose(J, pk.tip_jacobian(q), atol=1e-9)
    X_goal = pk.tip_pose(q)
    q_ik = pk.solve_ik(X_goal[:3, 3], X_goal[:3, :3])
    assert q_ik is not None
    assert np.allclose(drake_pose(arm, EE_TIP_FRAME, q_ik), X_goal, atol=1e-5)
    assert pk.solve_ik([2.0, 0.0, 0.1], np.diag([1.0, -1.0, -1.0])) is None  # unreachable


def test_scene_ball_rests_on_table_and_arm_holds():
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlantSceneGraph(builder, 1e-3)
    scene = add_ball_rolling_scene(plant, ball_position=(0.65, 0.0))
    plant.Finalize()
    drv = builder.AddSystem(GravityCompensatedDriver())
    zero = builder.AddSystem(ConstantVectorSource(np.zeros(7)))
    builder.Connect(zero.get_output_port(), drv.GetInputPort("panda.torque_command"))
    builder.Connect(plant.get_state_output_port(scene.panda),
                    drv.GetInputPort("panda.state"))
    builder.Connect(drv.GetOutputPort("panda.actuation"),
                    plant.get_actuation_input_port(scene.panda))
    diagram = builder.Build()
    sim = Simulator(diagram)
    ctx = plant.GetMyMutableContextFromRoot(sim.get_mutable_context())
    plant.SetPositions(ctx, scene.panda, pk.Q_NULL)
    ball = plant.GetBodyByName("ball")
    p0 = plant.EvalBodyPoseInWorld(ctx, ball).translation()
    assert np.allclose(p0, [0.65, 0.0, BALL_RADIUS])
    sim.AdvanceTo(0.5)
    p1 = plant.EvalBodyPoseInWorld(ctx, ball).translation()
    # At rest on the table top (z = 0): centre within 0.5 mm of the radius height.
    assert abs(p1[2] - BALL_RADIUS) < 5e-4 and np.linalg.norm(p1[:2] - p0[:2]) < 1e-4
    assert np.max(np.abs(plant.GetPositions(ctx, scene.panda) - pk.Q_NULL)) < 1e-4
    # The only contact is ball-table: no arm self-contact, no arm-table contact.
    contacts = plant.get_contact_results_output_port().Eval(ctx)
    names = {frozenset((plant.get_body(c.bodyA_index()).name(),
                        plant.get_body(c.bodyB_index()).name()))
             for c in [contacts.point_pair_contact_info(i)
                       for i in range(contacts.num_point_pair_contacts())]}
    assert names == {frozenset(("ball", "world"))}


def test_unit_sphere_mesh_is_the_generators_and_close_to_a_sphere():
    """The Panda's visual spheres are models/unit_sphere.obj scaled (issue 18: fewer
    triangles to render); the file is what the generator writes, every vertex on the
    unit sphere, and the silhouette within 1 % of the radius."""
    import numpy as np

    from adaptive_c3.models.unit_sphere import OBJ_PATH, SEGMENTS, unit_sphere_obj
    text = OBJ_PATH.read_text()
    assert text == unit_sphere_obj()
    v = np.array([[float(a) for a in ln.split()[1:]] for ln in text.splitlines()
                  if ln.startswith("v ")])
    assert np.allclose(np.linalg.norm(v, axis=1), 1.0, atol=1e-5)
    assert 1 - np.cos(np.pi / SEGMENTS) < 0.01


def test_panda_visual_spheres_render_as_meshes_of_their_radius():
    from pydrake.geometry import Mesh, Role, Sphere
    from pydrake.multibody.plant import MultibodyPlant

    from adaptive_c3.models.ball_rolling_scene import add_panda
    plant = MultibodyPlant(1e-3)
    from pydrake.geometry import SceneGraph
    sg = SceneGraph()
    plant.RegisterAsSourceForSceneGraph(sg)
    add_panda(plant)
    plant.Finalize()
    insp = sg.model_inspector()
    shapes = [insp.GetShape(g) for g in insp.GetAllGeometryIds(Role.kPerception)]
    meshes = [s for s in shapes if isinstance(s, Mesh)]
    assert len(meshes) == 27 and not any(isinstance(s, Sphere) for s in shapes)
    assert {round(m.scale3()[0], 4) for m in meshes} >= {0.075, 0.065, 0.0195}
    # collision geometry stays spheres
    assert all(isinstance(insp.GetShape(g), Sphere)
               for g in insp.GetAllGeometryIds(Role.kProximity))
