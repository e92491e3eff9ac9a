"""The ball-rolling diagram (paper Section VII-B), built from a BallRollingScenario.

Recipe (world frame W = robot base frame, table top z = 0):
  1. true plant      Panda (or a point EE) + table + ball of the TRUE radius, SAP, 1 ms
  2. robot           impedance controller (1 kHz, the plant step) -> simulated torque
                     driver with gravity compensation -> plant actuation
  3. ball sensing    overhead RgbdSensor -> Hough BallDetector at 80 Hz
                     (ball_rolling_camera.py), or (camera off) the true pose plus noise,
                     filtered the same way
  4. estimator       EE + ball estimates -> the controller model's 19-state
  5. LCS             Anitescu LCS of the controller model (MODEL radius) at 80 Hz, with
                     the planning dt and with the loop period
  6. learner         residual r_comp on the LCS offsets (200 Hz samples, 0.1 s
                     transitions, one Adam step per 10 samples = 20 Hz); its input is
                     the tip force the impedance controller commanded
  7. planner         C3 on the LCS with residual + the roll/return gait -> EE command
  8. loggers, Meshcat (optional)
"""
from __future__ import annotations

import dataclasses as dc
from dataclasses import dataclass

import numpy as np
from pydrake.multibody.plant import AddMultibodyPlant, MultibodyPlantConfig
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import Adder, ConstantVectorSource, Gain, VectorLogSink

from adaptive_c3.models.ball_rolling_controller_model import (BALL_VEL, STATE_NAMES,
                                                              ball_rolling_linearizer,
                                                              default_state,
                                                              ee_input_from_motion)
from adaptive_c3.diagrams.ball_rolling_camera import add_ball_camera
from adaptive_c3.diagrams.ball_rolling_world import (apply_true_ee_friction, ball_start_xy,
                                                     make_gait, start_states, true_mass,
                                                     true_radius, true_world)
from adaptive_c3.scenarios.ball_rolling_schema import BallRollingScenario
from adaptive_c3.systems.contact.anitescu_lcs import OPEN_PAIR_TOL
from adaptive_c3.systems.contact.anitescu_lcs_system import AnitescuLcsSystem
from adaptive_c3.systems.perception.ball_pose_sensor import BallPoseSensor
from adaptive_c3.systems.rolling.estimator import BallRollingEstimator
from adaptive_c3.systems.rolling.planner import BallRollingPlanner
from adaptive_c3.systems.c3.options import C3Options
from adaptive_c3.systems.learning.residual_learner import ResidualLearner
from adaptive_c3.systems.learning.violation_loss import LearnerOptions

LEARNER_SAMPLE_HZ = 200.0
LOG_PERIOD_S = 0.01
GRAVITY = 9.81


@dataclass
class BallRollingDiagram:
    diagram: object
    plant: object
    scene_graph: object
    planner: BallRollingPlanner
    learner: ResidualLearner
    lcs_system: AnitescuLcsSystem
    logs: dict              # name -> VectorLogSink
    true_radius: float
    ball_start: np.ndarray  # (3) true start position
    ee_start: np.ndarray    # (3)
    lambda_names: list


# The reference system's weights on the 19-state.
ROLL_Q = [500.0] * 3 + [0.0] * 4 + [5000.0, 5000.0, 1000.0] + [10.0] * 3 + [0.1] * 6


def c3_options(s: BallRollingScenario, phase: str, num_lambda: int) -> C3Options:
    c = s.c3
    q = list(c.q_diag) or list(ROLL_Q)
    if phase != "roll":   # return phase: the EE follows the gait, the ball is let be
        w = s.gait.return_ee_weight
        q = [w] * 3 + [0.0] * 4 + [5.0, 5.0, 1000.0] + [10.0] * 3 + [0.1] * 6
    nz = len(STATE_NAMES) + num_lambda + 3
    return C3Options.from_dict(dict(
        horizon=c.horizon, admm_iter=c.admm_iter, projection=c.projection,
        qp_backend=c.qp_backend, rho_scale=c.rho_scale, warm_start=c.warm_start,
        c3plus_reference=c.c3plus_reference,
        q_diag=q, qn_diag=q, r_diag=c.r_diag or [0.01] * 3,
        g_diag=c.g_diag or [0.001] * len(STATE_NAMES) + [1000.0] * num_lambda + [0.001] * 3,
        u_diag=c.u_diag or [100.0] * len(STATE_NAMES) + [1.0] * (num_lambda + 3)))


def _pair_groups(num_lambda: int) -> list:
    """The EE-ball rows and the ball-table rows: each pair's edges share one gap."""
    half = num_lambda // 2
    return [list(range(half)), list(range(half, num_lambda))]


def learner_options(s: BallRollingScenario) -> LearnerOptions:
    cfg = s.learner
    qd = list(cfg.qd_diag)
    if not qd:   # reference: 1e5 on the ball's translational velocity, 0 elsewhere
        qd = [0.0] * len(STATE_NAMES)
        for i in range(BALL_VEL.start, BALL_VEL.stop):
            qd[i] = 1e5
    return LearnerOptions(epsilon=cfg.epsilon, gamma=cfg.gamma,
                          learning_rate=cfg.learning_rate, batch_size=cfg.batch_size,
                          Qd=qd, max_step=cfg.max_step, lr_decay_steps=cfg.lr_decay_steps)


def _impedance_settings(s: BallRollingScenario):
    from adaptive_c3.systems.franka.impedance_law import ImpedanceGains
    imp = s.impedance
    gains = ImpedanceGains(translational_stiffness=imp.translational_stiffness,
                           translational_damping=imp.translational_damping,
                           rotational_stiffness=imp.rotational_stiffness,
                           rotational_damping=imp.rotational_damping,
                           nullspace_stiffness=imp.nullspace_stiffness,
                           nullspace_damping=imp.nullspace_damping,
                           operational_space=imp.operational_space)
    return gains, {"tilt_deg": imp.ee_tilt_deg, "q_null": imp.q_null}


def make_impedance_controller(s: BallRollingScenario):
    """The Panda's ImpedanceController with the scenario's gains (simulation and bridge)."""
    from adaptive_c3.systems.franka.impedance_controller import ImpedanceController
    gains, kw = _impedance_settings(s)
    return ImpedanceController(gains, **kw)


def make_impedance_law(s: BallRollingScenario):
    """The same law without the LeafSystem (the 1 kHz impedance process)."""
    from adaptive_c3.systems.franka.impedance_controller import ImpedanceLaw
    gains, kw = _impedance_settings(s)
    return ImpedanceLaw(gains, **kw)


def _add_robot(builder, plant, s, panda, ee_instance):
    """Impedance control of the EE; returns the system whose "ee.state" is measured and
    the (desired_state, feedforward) input ports."""
    imp = s.impedance
    if panda is not None:
        from adaptive_c3.systems.franka.panda_sim_driver import GravityCompensatedDriver
        ctrl = builder.AddSystem(make_impedance_controller(s))
        driver = builder.AddSystem(GravityCompensatedDriver())
        state = plant.get_state_output_port(panda)
        builder.Connect(state, ctrl.GetInputPort("panda.state"))
        builder.Connect(state, driver.GetInputPort("panda.state"))
        builder.Connect(ctrl.GetOutputPort("panda.torque_command"),
                        driver.GetInputPort("panda.torque_command"))
        builder.Connect(driver.GetOutputPort("panda.actuation"),
                        plant.get_actuation_input_port(panda))
        return ctrl
    from adaptive_c3.systems.franka.point_ee_impedance import PointEeImpedance
    ctrl = builder.AddSystem(PointEeImpedance(
        stiffness=imp.translational_stiffness, damping=imp.translational_damping,
        mass=s.point_ee_mass))
    builder.Connect(plant.get_state_output_port(ee_instance),
                    ctrl.GetInputPort("point_ee.state"))
    builder.Connect(ctrl.GetOutputPort("point_ee.actuation"),
                    plant.get_actuation_input_port(ee_instance))
    return ctrl


def _add_ball_pose_sensor(builder, plant, s, ball_instance, start_xy):
    """Camera off: the true ball pose plus noise, filtered like the detector's estimate."""
    cam = s.camera
    sens = builder.AddSystem(BallPoseSensor(
        period=1.0 / cam.rate_hz, noise_m=cam.position_noise_m, alpha=cam.filter_alpha,
        seed=s.seed, initial_position=(start_xy[0], start_xy[1], s.model.ball_radius)))
    builder.Connect(plant.get_state_output_port(ball_instance),
                    sens.GetInputPort("ball.true_state"))
    return sens


def _log(builder, port, name, logs):
    sink = builder.AddSystem(VectorLogSink(port.size(), LOG_PERIOD_S))
    sink.set_name(f"log_{name}")
    builder.Connect(port, sink.get_input_port())
    logs[name] = sink


@dataclass
class BallRollingController:
    """Handles to the controller side (estimator, LCS, learner, planner) of the diagram."""
    planner: BallRollingPlanner
    learner: ResidualLearner
    lcs_system: AnitescuLcsSystem
    lcs_state: object            # OutputPort: the 19-state estimate
    ee_desired_state: object     # OutputPort (6): for the impedance controller
    ee_feedforward_force: object  # OutputPort (3)
    lambda_names: list
    r_comp: object = None        # OutputPort (m): the learned residual at the planning dt


def add_ball_rolling_controller(builder, s: BallRollingScenario, ee_state, ee_force,
                                ball_position, ball_velocity, *, x_start=None,
                                ee_start=None, transport_s: float = 0.0) -> BallRollingController:
    """Adds steps 4-7 (estimator, LCS, learner, planner) reading the given output ports:
    ee_state (6, EE tip position and velocity in W), ee_force (3, the tip force the
    impedance controller commands, N in W), ball_position (3) and ball_velocity (3). The
    same function serves simulation and the LCM bridge. transport_s: how long a plan takes
    to reach the impedance loop (for c3.predict_state with a measured lead)."""
    m = s.model
    gait = make_gait(s)
    if x_start is None:
        x_start = default_state(tuple(ball_start_xy(s)), ball_radius=m.ball_radius,
                                ee_radius=m.ee_radius)
    x_start = np.array(x_start, float)
    if ee_start is None:
        ee_start = gait.ee_target("settle", x_start)
    estimator = builder.AddSystem(BallRollingEstimator(m.ball_radius))
    builder.Connect(ee_state, estimator.GetInputPort("ee.state"))
    builder.Connect(ball_position, estimator.GetInputPort("ball.position"))
    builder.Connect(ball_velocity, estimator.GetInputPort("ball.velocity"))
    lcs_state = estimator.GetOutputPort("lcs_state")

    # 5. LCS at the planning dt and at the loop period
    x_start[0:3] = ee_start
    lin_kwargs = dict(num_edges=m.friction_edges, eps_c=m.eps_c, ball_radius=m.ball_radius,
                      ball_mass=m.ball_mass, ee_radius=m.ee_radius, ee_mass=m.ee_mass,
                      mu=m.friction)
    # one linearizer: the three LCS systems (planning dt, loop period, learner dt) update
    # together at the same state and share its evaluation there
    lin = ball_rolling_linearizer(dt=m.planning_dt, **lin_kwargs)
    if m.open_pair_gate:      # no friction on a pair out of reach (anitescu_lcs.py)
        lin.open_pair_tol = OPEN_PAIR_TOL
    lcs_sys = builder.AddSystem(AnitescuLcsSystem(lin, s.c3.rate_hz, initial_state=x_start))
    loop_sys = builder.AddSystem(AnitescuLcsSystem(lin, s.c3.rate_hz, initial_state=x_start,
                                                   dt=1.0 / s.c3.rate_hz))
    num_lambda = len(lin.lambda_names())

    # 6. learner, on its own LCS step (r_comp is rescaled to the planning dt: both carry
    #    the same gap offset, r dt)
    dt_learn = m.learner_dt or m.planning_dt
    learn_sys = lcs_sys
    if abs(dt_learn - m.planning_dt) > 1e-12:
        learn_sys = builder.AddSystem(AnitescuLcsSystem(lin, s.c3.rate_hz,
                                                        initial_state=x_start, dt=dt_learn))
    stride = max(1, int(round(LEARNER_SAMPLE_HZ / s.learner.rate_hz)))
    learner = builder.AddSystem(ResidualLearner(
        learner_options(s), len(STATE_NAMES), 3, num_lambda, rate_hz=LEARNER_SAMPLE_HZ,
        enabled=s.learner.enabled, transition_dt=dt_learn, transition_stride=stride,
        input_lag=1,
        tied_groups=_pair_groups(num_lambda) if s.learner.tie_residual == "pairs" else (),
        input_from_motion=(ee_input_from_motion(m.ee_mass, GRAVITY)
                           if m.learner_input == "motion" else None)))
    to_plan = builder.AddSystem(Gain(dt_learn / m.planning_dt, num_lambda))
    to_plan.set_name("r_comp_at_planning_dt")
    builder.Connect(learner.GetOutputPort("r_comp"), to_plan.get_input_port())
    r_comp = to_plan.get_output_port()

    # 7. planner
    planner = builder.AddSystem(BallRollingPlanner(
        gait, c3_options(s, "roll", num_lambda), c3_options(s, "return", num_lambda),
        num_lambda=num_lambda, rate_hz=s.c3.rate_hz,
        ee_ball_rows=tuple(range(num_lambda // 2)), planning_dt=m.planning_dt,
        feedforward=s.impedance.feedforward, model_ee_weight=m.ee_mass * GRAVITY,
        predict_state=s.c3.predict_state,
        predict_latency_s=s.c3.predict_latency_s if s.c3.predict_latency_s >= 0 else None,
        transport_s=transport_s, warm_start_shift=s.c3.warm_start_shift,
        residual_in_lcs=s.learner.residual_in_lcs))

    u_port = planner.GetOutputPort("lcs_input")
    for sys_ in {lcs_sys, loop_sys, learn_sys}:
        builder.Connect(lcs_state, sys_.GetInputPort("state"))
        builder.Connect(u_port, sys_.GetInputPort("input"))
    builder.Connect(lcs_state, learner.GetInputPort("state"))
    # the learner sees the force the robot applied at the tip (not the planned one),
    # plus the model EE's weight, which the robot's own gravity compensation carries
    weight = builder.AddSystem(ConstantVectorSource([0.0, 0.0, m.ee_mass * GRAVITY]))
    applied = builder.AddSystem(Adder(2, 3))
    builder.Connect(ee_force, applied.get_input_port(0))
    builder.Connect(weight.get_output_port(), applied.get_input_port(1))
    builder.Connect(applied.get_output_port(), learner.GetInputPort("input"))
    builder.Connect(learn_sys.GetOutputPort("lcs"), learner.GetInputPort("lcs"))
    builder.Connect(lcs_state, planner.GetInputPort("state"))
    builder.Connect(lcs_sys.GetOutputPort("lcs"), planner.GetInputPort("lcs"))
    builder.Connect(loop_sys.GetOutputPort("lcs"), planner.GetInputPort("lcs_loop"))
    builder.Connect(r_comp, planner.GetInputPort("r_comp"))

    return BallRollingController(planner, learner, lcs_sys, lcs_state,
                                 planner.GetOutputPort("ee.desired_state"),
                                 planner.GetOutputPort("ee.feedforward_force"),
                                 list(lin.lambda_names()), r_comp)


def controller_prior(s: BallRollingScenario) -> BallRollingScenario:
    """The scenario as the controller sees it. For a fruit the prior is a sphere of the
    kind's nominal radius and mass (models.fruit.nominal_sphere); radius_error and the
    model ball's size do not apply."""
    if s.model.object == "ball":
        return s
    from adaptive_c3.models.fruit import nominal_sphere
    radius, mass = nominal_sphere(s.model.object)
    return dc.replace(s, model=dc.replace(s.model, ball_radius=radius, ball_mass=mass,
                                          radius_error=0.0))


def build_ball_rolling_diagram(s: BallRollingScenario, meshcat=None) -> BallRollingDiagram:
    s = controller_prior(s)
    builder = DiagramBuilder()

    # 1. true plant
    config = MultibodyPlantConfig(time_step=s.sim_time_step,
                                  discrete_contact_approximation="sap")
    plant, scene_graph = AddMultibodyPlant(config, builder)
    start_xy = ball_start_xy(s)
    x_start, ee_start = start_states(s)
    scene, ee_instance = true_world(s)(plant)
    plant.Finalize()
    apply_true_ee_friction(plant, scene_graph, s, scene.panda, ee_instance)
    if s.model.object != "ball":      # a fruit: rigid hydroelastic contact
        from adaptive_c3.models.fruit import make_rigid_hydroelastic
        make_rigid_hydroelastic(plant, scene_graph)
    if scene.panda is not None:
        _set_panda_start(plant, scene.panda, ee_start, s)

    # 2-3. robot, ball sensing; 4-7. the controller
    robot = _add_robot(builder, plant, s, scene.panda, ee_instance)
    if s.camera.enabled:
        ball_sensor = add_ball_camera(builder, plant, s)
    else:
        ball_sensor = _add_ball_pose_sensor(builder, plant, s, scene.ball, start_xy)
    ctrl = add_ball_rolling_controller(
        builder, s, robot.GetOutputPort("ee.state"), robot.GetOutputPort("ee.commanded_force"),
        ball_sensor.GetOutputPort("ball.position"), ball_sensor.GetOutputPort("ball.velocity"),
        x_start=x_start, ee_start=ee_start)
    builder.Connect(ctrl.ee_desired_state, robot.GetInputPort("ee.desired_state"))
    builder.Connect(ctrl.ee_feedforward_force, robot.GetInputPort("ee.feedforward_force"))
    planner, learner, lcs_sys = ctrl.planner, ctrl.learner, ctrl.lcs_system
    lcs_state = ctrl.lcs_state

    # 8. loggers, visualisation
    logs = {}
    _log(builder, plant.get_state_output_port(scene.ball), "ball_true", logs)
    _log(builder, robot.GetOutputPort("ee.state"), "ee", logs)
    _log(builder, lcs_state, "lcs_state", logs)
    for name in ("ee.desired_state", "lcs_input", "phase", "ball_target"):
        _log(builder, planner.GetOutputPort(name), name, logs)
    _log(builder, ctrl.r_comp, "r_comp", logs)
    _log(builder, learner.GetOutputPort("loss"), "loss", logs)
    _log(builder, robot.GetOutputPort("ee.commanded_force"), "ee_force", logs)
    if s.camera.enabled:
        _log(builder, ball_sensor.GetOutputPort("ball.detection_ok"), "detection_ok", logs)
    if meshcat is not None:
        from pydrake.geometry import MeshcatVisualizer
        MeshcatVisualizer.AddToBuilder(builder, scene_graph, meshcat)

    diagram = builder.Build()
    diagram.set_name(f"ball_rolling[{s.name}]")
    return BallRollingDiagram(diagram, plant, scene_graph, planner, learner, lcs_sys, logs,
                              scene.ball_radius, np.r_[start_xy, scene.ball_radius], ee_start,
                              ctrl.lambda_names)


def _set_panda_start(plant, panda, ee_start, s):
    from adaptive_c3.models.panda_kinematics import solve_ik
    from adaptive_c3.systems.franka.impedance_law import tilted_ee_rotation
    q = solve_ik(ee_start, tilted_ee_rotation(s.impedance.ee_tilt_deg),
                 q_guess=np.asarray(s.impedance.q_null, float))
    if q is None:
        raise ValueError(f"the Panda cannot reach the start pose {np.round(ee_start, 3)}")
    plant.SetDefaultPositions(panda, q)


__all__ = ["BallRollingDiagram", "BallRollingController", "add_ball_rolling_controller",
           "build_ball_rolling_diagram", "c3_options",
           "learner_options", "make_gait", "make_impedance_controller", "true_mass", "true_radius", "ball_start_xy"]
