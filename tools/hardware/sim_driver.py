"""`adaptive-c3 sim-driver`: the true plant as if it were the robot, speaking only LCM.

The simulated rig for the LCM bridge (tools/hardware/bridge.py): Panda + table + ball of the
TRUE radius (SAP, the scenario's sim_time_step), with the simulated Franka torque driver
(`GravityCompensatedDriver`: the command means torque WITHOUT gravity, as on the real
robot). It publishes and subscribes only the robot's / vision's LCM messages:

  PANDA_STATUS   drake.lcmt_panda_status   every status_period (1 ms): q, v, the torque
                 commanded/measured; utime = this process's simulation time (us)
  BALL_ESTIMATE  drake.lcmt_robot_state    at camera.rate_hz (80 Hz): the ball estimate
                 as a vision process would send it - true centre + camera.position_noise_m
                 noise, low-pass filtered (`BallPoseSensor`). Layout (see hardware.py):
                 num_joints = 6, joint_name = BALL_ESTIMATE_NAMES = [ball_x, ball_y,
                 ball_z, ball_vx, ball_vy, ball_vz], joint_position = the values (m, m/s,
                 robot base frame W, table top z = 0); utime = time of the estimate (us)
  PANDA_COMMAND  drake.lcmt_panda_command  (subscribed) joint_torque (7, N m, without
                 gravity). Like the robot's communication reflex, a command older than
                 command_timeout (100 ms) or malformed counts as zero (the arm then
                 holds itself against gravity only).

The simulator runs in real time by default (a robot process); `build_sim_driver` is
also used in lock-step by tools/hardware/bridge.py's loopback run (one process, memq://).
"""
from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.multibody.plant import AddMultibodyPlant, MultibodyPlantConfig
from pydrake.systems.framework import DiagramBuilder, LeafSystem
from pydrake.systems.primitives import VectorLogSink

from adaptive_c3.tools.hardware.lcm_channels import (BALL_CHANNEL, BALL_ESTIMATE_NAMES,
                                                   COMMAND_CHANNEL, NQ, STATUS_CHANNEL,
                                                   fast_drake_lcm_copies, open_lcm)

class CommandDecoder(LeafSystem):
    """lcmt_panda_command -> joint torques (7), zero if stale / malformed / non-finite.

    input  "lcmt_panda_command" abstract (Python message)
    output "panda.torque_command" (7) N m, without gravity
    Staleness is judged by receive time (a change of utime) on this diagram's clock.
    """

    def __init__(self, period: float, timeout: float = 0.1):
        super().__init__()
        from drake import lcmt_panda_command
        self._timeout = float(timeout)
        self._in = self.DeclareAbstractInputPort("lcmt_panda_command",
                                                 AbstractValue.Make(lcmt_panda_command()))
        # [last utime, receive time, tau (7), count of messages]
        self._xd = self.DeclareDiscreteState(np.r_[-1.0, -np.inf, np.zeros(NQ), 0.0])
        self.DeclarePeriodicDiscreteUpdateEvent(period, 0.0, self._update)
        self.DeclareVectorOutputPort("panda.torque_command", NQ, self._calc,
                                     prerequisites_of_calc={self.xd_ticket()})

    def _update(self, context, discrete_state):
        s = context.get_discrete_state(self._xd).get_value().copy()
        msg = self._in.Eval(context)
        if msg.num_joint_torque > 0 and float(msg.utime) != s[0]:
            tau = np.asarray(msg.joint_torque, float)
            s[0], s[1], s[-1] = float(msg.utime), context.get_time(), s[-1] + 1
            ok = tau.shape == (NQ,) and np.all(np.isfinite(tau))
            s[2:2 + NQ] = tau if ok else 0.0
        discrete_state.get_mutable_vector(self._xd).set_value(s)

    def _calc(self, context, output):
        s = context.get_discrete_state(self._xd).get_value()
        fresh = context.get_time() - s[1] <= self._timeout
        output.SetFromVector(s[2:2 + NQ] if fresh else np.zeros(NQ))

    def messages(self, context) -> int:
        return int(context.get_discrete_state(self._xd).get_value()[-1])


class BallEstimateEncoder(LeafSystem):
    """ball.position (3), ball.velocity (3) -> lcmt_robot_state (BALL_ESTIMATE layout)."""

    def __init__(self):
        super().__init__()
        from drake import lcmt_robot_state
        self._p = self.DeclareVectorInputPort("ball.position", 3)
        self._v = self.DeclareVectorInputPort("ball.velocity", 3)
        self.DeclareAbstractOutputPort("lcmt_robot_state",
                                       lambda: AbstractValue.Make(lcmt_robot_state()),
                                       self._calc)

    def _calc(self, context, output):
        from drake import lcmt_robot_state
        msg = lcmt_robot_state()
        msg.utime = int(round(context.get_time() * 1e6))
        values = np.r_[self._p.Eval(context), self._v.Eval(context)]
        msg.num_joints = len(BALL_ESTIMATE_NAMES)
        msg.joint_name = list(BALL_ESTIMATE_NAMES)
        msg.joint_position = [float(v) for v in values]
        output.set_value(msg)


@dataclass
class SimDriver:
    diagram: object
    plant: object
    command: CommandDecoder
    logs: dict              # name -> VectorLogSink: ball_true (13), panda_state (14), tau (7)
    true_radius: float
    ball_start: np.ndarray


def build_sim_driver(s, lcm, *, status_period: float = 1e-3,
                     command_timeout: float = 0.1, log_period: float = 0.01) -> SimDriver:
    """The true plant speaking LCM through `lcm` (a DrakeLcm). See the module doc."""
    from drake import lcmt_panda_command, lcmt_robot_state
    from pydrake.manipulation import PandaStatusSender
    from pydrake.systems.lcm import (LcmInterfaceSystem, LcmPublisherSystem,
                                     LcmSubscriberSystem)
    from pydrake.systems.primitives import Demultiplexer

    from adaptive_c3.diagrams.ball_rolling import (_set_panda_start, ball_start_xy,
                                                   make_gait, true_radius)
    from adaptive_c3.models.ball_rolling_controller_model import default_state
    from adaptive_c3.models.ball_rolling_scene import add_ball_rolling_scene
    from adaptive_c3.systems.perception.ball_pose_sensor import BallPoseSensor
    from adaptive_c3.systems.franka.panda_sim_driver import GravityCompensatedDriver

    if s.robot != "panda":
        raise ValueError("the simulated driver needs robot: panda")
    fast_drake_lcm_copies()
    m = s.model
    R_true = true_radius(s)
    builder = DiagramBuilder()
    plant, _ = AddMultibodyPlant(MultibodyPlantConfig(
        time_step=s.sim_time_step, discrete_contact_approximation="sap"), builder)
    start_xy = ball_start_xy(s)
    scene = add_ball_rolling_scene(plant, ball_radius=R_true, ball_mass=m.ball_mass,
                                   ball_position=tuple(start_xy), mu=m.friction,
                                   with_arm=True)
    plant.Finalize()
    x_start = default_state(tuple(start_xy), ball_radius=m.ball_radius,
                            ee_radius=m.ee_radius)
    ee_start = make_gait(s).ee_target("settle", x_start)
    _set_panda_start(plant, scene.panda, ee_start, s)

    builder.AddSystem(LcmInterfaceSystem(lcm))
    sub = builder.AddSystem(LcmSubscriberSystem.Make(COMMAND_CHANNEL, lcmt_panda_command, lcm))
    cmd = builder.AddSystem(CommandDecoder(s.sim_time_step, command_timeout))
    builder.Connect(sub.get_output_port(), cmd.get_input_port())
    driver = builder.AddSystem(GravityCompensatedDriver())
    state = plant.get_state_output_port(scene.panda)
    builder.Connect(cmd.get_output_port(), driver.GetInputPort("panda.torque_command"))
    builder.Connect(state, driver.GetInputPort("panda.state"))
    builder.Connect(driver.GetOutputPort("panda.actuation"),
                    plant.get_actuation_input_port(scene.panda))

    # status: q, v measured; the torque command as commanded and measured
    from drake import lcmt_panda_status
    demux = builder.AddSystem(Demultiplexer([NQ, NQ]))
    builder.Connect(state, demux.get_input_port())
    sender = builder.AddSystem(PandaStatusSender(NQ))
    for name in ("position_commanded", "position_measured"):
        builder.Connect(demux.get_output_port(0), sender.GetInputPort(name))
    for name in ("velocity_commanded", "velocity_measured"):
        builder.Connect(demux.get_output_port(1), sender.GetInputPort(name))
    for name in ("torque_commanded", "torque_measured"):
        builder.Connect(cmd.get_output_port(), sender.GetInputPort(name))
    pub = builder.AddSystem(LcmPublisherSystem.Make(
        STATUS_CHANNEL, lcmt_panda_status, lcm, status_period, use_cpp_serializer=True))
    builder.Connect(sender.get_output_port(), pub.get_input_port())

    cam = s.camera
    sens = builder.AddSystem(BallPoseSensor(
        period=1.0 / cam.rate_hz, noise_m=cam.position_noise_m, alpha=cam.filter_alpha,
        seed=s.seed, initial_position=(start_xy[0], start_xy[1], m.ball_radius)))
    builder.Connect(plant.get_state_output_port(scene.ball), sens.GetInputPort("ball.true_state"))
    enc = builder.AddSystem(BallEstimateEncoder())
    builder.Connect(sens.GetOutputPort("ball.position"), enc.GetInputPort("ball.position"))
    builder.Connect(sens.GetOutputPort("ball.velocity"), enc.GetInputPort("ball.velocity"))
    ball_pub = builder.AddSystem(LcmPublisherSystem.Make(
        BALL_CHANNEL, lcmt_robot_state, lcm, 1.0 / cam.rate_hz))
    builder.Connect(enc.get_output_port(), ball_pub.get_input_port())

    logs = {}
    for name, port in (("ball_true", plant.get_state_output_port(scene.ball)),
                       ("panda_state", state), ("tau", cmd.get_output_port())):
        sink = builder.AddSystem(VectorLogSink(port.size(), log_period))
        builder.Connect(port, sink.get_input_port())
        logs[name] = sink
    diagram = builder.Build()
    diagram.set_name(f"sim_driver[{s.name}]")
    return SimDriver(diagram, plant, cmd, logs, R_true, np.r_[start_xy, R_true])


def driver_summary(drv: SimDriver, context) -> dict:
    """Ball displacement and EE-ball approach from the driver's logs."""
    from adaptive_c3.systems.franka.impedance_controller import ArmModel
    ball = drv.logs["ball_true"].FindLog(context)
    arm = drv.logs["panda_state"].FindLog(context)
    b = ball.data().T
    qs = arm.data().T
    model = ArmModel()
    gaps = []
    for q, p in zip(qs[::5], b[::5, 4:7]):
        model.set_state(q[:NQ], q[NQ:])
        gaps.append(np.linalg.norm(model.tip_pose()[0] - p))
    dctx = drv.diagram.GetSubsystemContext(drv.command, context)
    return {"sim_time_s": float(context.get_time()),
            "ball_displacement_m": float(np.linalg.norm(b[-1, 4:6] - b[0, 4:6])),
            "ball_final": b[-1, 4:7].tolist(),
            "min_ee_ball_distance_m": float(min(gaps)) if gaps else None,
            "commands_received": drv.command.messages(dctx)}


def cmd_sim_driver(args) -> int:
    from pydrake.systems.analysis import Simulator

    from adaptive_c3.scenarios.schema import ScenarioError, load_scenario
    from adaptive_c3.tools.user_input import UserError, resolve_scenario_path
    s, _ = load_scenario(resolve_scenario_path(args.scenario), list(args.set or []))
    if s.task != "ball_rolling":
        raise ScenarioError(f"sim-driver needs a ball_rolling scenario, got task '{s.task}'")
    if s.robot != "panda":
        raise ScenarioError("sim-driver needs robot: panda")
    duration = float(args.duration if args.duration is not None else s.sim_duration_s)
    if not (math.isfinite(duration) and duration > 0):
        raise UserError(f"--duration must be > 0, got {args.duration}")
    lcm = open_lcm(args.lcm_url)
    drv = build_sim_driver(s, lcm, status_period=args.status_period)
    sim = Simulator(drv.diagram)
    sim.set_target_realtime_rate(1.0)
    sim.Initialize()
    print(f"sim-driver: publishing {STATUS_CHANNEL}, {BALL_CHANNEL}; listening on "
          f"{COMMAND_CHANNEL} at {args.lcm_url} for {duration:g} s", flush=True)
    start = time.perf_counter()
    t = 0.0
    try:
        while t < duration - 1e-12:
            t = min(t + 0.1, duration)
            sim.AdvanceTo(t)
    except KeyboardInterrupt:
        pass
    summary = driver_summary(drv, sim.get_context())
    summary["wall_s"] = time.perf_counter() - start
    print(json.dumps(summary), flush=True)
    return 0


__all__ = ["build_sim_driver", "cmd_sim_driver", "SimDriver", "CommandDecoder",
           "BallEstimateEncoder", "driver_summary"]
