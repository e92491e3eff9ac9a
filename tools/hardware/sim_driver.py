"""`adaptive-c3 sim-driver`: the true plant as if it were the robot, speaking only LCM.

The simulated rig for the LCM bridge (tools/hardware/bridge.py): Panda + table + ball of the
TRUE radius (SAP, the scenario's sim_time_step), with the simulated Franka torque driver
(`GravityCompensatedDriver`: the command means torque WITHOUT gravity, as on the real
robot). It publishes and subscribes only the robot's / vision's LCM messages:

  PANDA_STATUS   drake.lcmt_panda_status   every status_period (1 ms): q, v, the torque
                 commanded/measured, robot_mode = kMove; utime = the driver's clock
                 (microseconds since the epoch: the wall clock in real time)
  BALL_ESTIMATE  drake.lcmt_robot_state    at camera.rate_hz (80 Hz): the ball estimate
                 as a vision process would send it - true centre + camera.position_noise_m
                 noise, low-pass filtered (`BallPoseSensor`). Layout (see hardware.py):
                 num_joints = 6, joint_name = BALL_ESTIMATE_NAMES = [ball_x, ball_y,
                 ball_z, ball_vx, ball_vy, ball_vz], joint_position = the values (m, m/s,
                 robot base frame W, table top z = 0); utime = time of the estimate (us)
  PANDA_COMMAND  drake.lcmt_panda_command  (subscribed) joint_torque (7, N m, without
                 gravity), handled as drake-franka-driver does in torque mode
                 (systems/franka/franka_driver_rules.py): a command whose utime is more
                 than --expire-sec (0.1 s) from the driver's clock is dropped and the arm
                 held by gravity compensation + joint damping; a command in another
                 control mode or with wrong field counts stops the driver; torques are
                 low-passed at --low-pass-hz (30 Hz) and rate limited (1000 N m/s).
                 The newest command is taken at every 1 ms tick; a message that does
                 not decode is counted (summary: commands_undecodable), never used.

The simulator runs in real time by default (a robot process); `build_sim_driver` is
also used in lock-step by tools/hardware/bridge.py's loopback run (one process, memq://).
"""
from __future__ import annotations

import json
import math
import signal
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
    command: object         # FrankaTorqueDriver
    command_health: object  # PANDA_COMMAND's ChannelHealth (undecodable commands)
    unsafe: object          # ArmUnsafeMonitor
    logs: dict              # name -> VectorLogSink: ball_true (13), panda_state (14), tau (7),
                            # unsafe (3: ArmUnsafeMonitor's output)
    true_radius: float      # m, the true ball
    ball_start: np.ndarray
    ee_radius: float        # m, the EE tip sphere
    target: tuple = ((0.55, 0.0), 0.1)   # the task's circle: centre (m, W), radius (m)


def build_sim_driver(s, lcm, *, status_period: float = 1e-3, expire_sec: float = 0.1,
                     low_pass_hz: float = 30.0, clock=None,
                     log_period: float = 0.01) -> SimDriver:
    """The true plant speaking LCM through `lcm` (a DrakeLcm). See the module doc.
    clock: t -> microseconds since the epoch (tools/hardware/driver_clock.py); default
    a SimEpochClock (lock-step runs); a real-time driver passes wall_clock_us."""
    from drake import lcmt_panda_command, lcmt_robot_state
    from pydrake.systems.lcm import LcmInterfaceSystem, LcmPublisherSystem

    from adaptive_c3.diagrams.ball_rolling import (_set_panda_start, ball_start_xy,
                                                   make_gait, true_mass, true_radius)
    from adaptive_c3.diagrams.ball_rolling_world import apply_true_ee_friction
    from adaptive_c3.models.ball_rolling_controller_model import default_state
    from adaptive_c3.models.ball_rolling_scene import add_ball_rolling_scene
    from adaptive_c3.systems.perception.ball_pose_sensor import BallPoseSensor
    from adaptive_c3.systems.franka.arm_unsafe_monitor import ArmUnsafeMonitor
    from adaptive_c3.systems.franka.franka_driver_rules import TICK_S
    from adaptive_c3.systems.franka.franka_torque_driver import FrankaTorqueDriver
    from adaptive_c3.tools.hardware.sampled_subscriber import SampledLcmSubscriber
    from adaptive_c3.systems.franka.panda_sim_driver import GravityCompensatedDriver
    from adaptive_c3.tools.hardware.driver_clock import SimEpochClock
    from adaptive_c3.tools.hardware.status_sender import StatusSender

    if s.robot != "panda":
        raise ValueError("the simulated driver needs robot: panda")
    if s.model.object != "ball":
        from adaptive_c3.scenarios.schema import ScenarioError
        raise ScenarioError("the simulated driver simulates a ball (model.object: ball), "
                            f"got '{s.model.object}'")
    fast_drake_lcm_copies()
    m = s.model
    R_true = true_radius(s)
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlant(MultibodyPlantConfig(
        time_step=s.sim_time_step, discrete_contact_approximation="sap"), builder)
    start_xy = ball_start_xy(s)
    scene = add_ball_rolling_scene(plant, ball_radius=R_true, ball_mass=true_mass(s),
                                   ball_position=tuple(start_xy), mu=m.true_friction,
                                   with_arm=True)
    plant.Finalize()
    apply_true_ee_friction(plant, scene_graph, s, scene.panda)
    x_start = default_state(tuple(start_xy), ball_radius=m.ball_radius,
                            ee_radius=m.ee_radius)
    ee_start = make_gait(s).ee_target("settle", x_start)
    _set_panda_start(plant, scene.panda, ee_start, s)

    builder.AddSystem(LcmInterfaceSystem(lcm))
    # the newest command at each 1 kHz tick, as libfranka's control callback takes it; a
    # message that does not decode is counted (sub.health) and never used
    sub = builder.AddSystem(SampledLcmSubscriber(COMMAND_CHANNEL, lcmt_panda_command, lcm,
                                                 TICK_S))
    clock = clock if clock is not None else SimEpochClock()
    cmd = builder.AddSystem(FrankaTorqueDriver(clock, expire_sec, low_pass_hz, TICK_S))
    builder.Connect(sub.get_output_port(), cmd.GetInputPort("lcmt_panda_command"))
    driver = builder.AddSystem(GravityCompensatedDriver())
    state = plant.get_state_output_port(scene.panda)
    builder.Connect(state, cmd.GetInputPort("panda.state"))
    builder.Connect(cmd.GetOutputPort("panda.torque_command"), driver.GetInputPort("panda.torque_command"))
    builder.Connect(state, driver.GetInputPort("panda.state"))
    builder.Connect(driver.GetOutputPort("panda.actuation"),
                    plant.get_actuation_input_port(scene.panda))

    # status: q, v measured; the applied torque (without gravity); the driver's clock
    from drake import lcmt_panda_status
    status = builder.AddSystem(StatusSender(clock))
    builder.Connect(state, status.GetInputPort("panda.state"))
    builder.Connect(cmd.GetOutputPort("panda.torque_command"), status.GetInputPort("panda.torque_command"))
    pub = builder.AddSystem(LcmPublisherSystem.Make(
        STATUS_CHANNEL, lcmt_panda_status, lcm, status_period))
    builder.Connect(status.get_output_port(), pub.get_input_port())

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

    # the driver's own record of the robot being unsafe (torque at its limit, a joint
    # at its limit, the ball off the table), in its clock
    unsafe = builder.AddSystem(ArmUnsafeMonitor(clock, R_true))
    builder.Connect(state, unsafe.GetInputPort("panda.state"))
    builder.Connect(cmd.GetOutputPort("panda.torque_command"), unsafe.GetInputPort("panda.torque"))
    builder.Connect(plant.get_state_output_port(scene.ball), unsafe.GetInputPort("ball.state"))
    builder.Connect(cmd.GetOutputPort("driver.ticks_held"),
                    unsafe.GetInputPort("driver.ticks_held"))

    logs = {}
    for name, port in (("ball_true", plant.get_state_output_port(scene.ball)),
                       ("panda_state", state), ("tau", cmd.GetOutputPort("panda.torque_command")),
                       ("unsafe", unsafe.get_output_port())):
        sink = builder.AddSystem(VectorLogSink(port.size(), log_period))
        builder.Connect(port, sink.get_input_port())
        logs[name] = sink
    diagram = builder.Build()
    diagram.set_name(f"sim_driver[{s.name}]")
    return SimDriver(diagram, plant, cmd, sub.health, unsafe, logs, R_true, np.r_[start_xy, R_true], m.ee_radius,
                     (tuple(s.target.center), s.target.radius))


def driver_summary(drv: SimDriver, context) -> dict:
    """Ball displacement, EE-ball approach, first contact (driver time, s: the true
    EE-ball gap within CONTACT_TOL_M) and turns about the task's circle, from the
    driver's logs (the truth, not an estimate)."""
    from adaptive_c3.systems.franka.impedance_controller import ArmModel
    from adaptive_c3.tools.run_ball_rolling import CONTACT_TOL_M, circle_progress
    ball = drv.logs["ball_true"].FindLog(context)
    arm = drv.logs["panda_state"].FindLog(context)
    b = ball.data().T
    qs = arm.data().T
    model = ArmModel()
    gaps = []
    for q, p in zip(qs[::5], b[::5, 4:7]):
        model.set_state(q[:NQ], q[NQ:])
        gaps.append(np.linalg.norm(model.tip_pose()[0] - p))
    touch = drv.true_radius + drv.ee_radius
    first = next((i for i, g in enumerate(gaps) if g - touch <= CONTACT_TOL_M), None)
    dctx = drv.diagram.GetSubsystemContext(drv.command, context)
    return {"sim_time_s": float(context.get_time()),
            "ball_displacement_m": float(np.linalg.norm(b[-1, 4:6] - b[0, 4:6])),
            "ball_final": b[-1, 4:7].tolist(),
            "min_ee_ball_distance_m": float(min(gaps)) if gaps else None,
            "first_contact_s": None if first is None else float(ball.sample_times()[5 * first]),
            "circle_turns": max(circle_progress(b[:, 4:6], *drv.target), 0.0),
            **drv.command.counts(dctx),
            "commands_undecodable": drv.command_health.undecodable,
            **drv.unsafe.report(drv.diagram.GetSubsystemContext(drv.unsafe, context)),
            "unsafe_episodes": unsafe_episodes(drv.logs["unsafe"].FindLog(context).data())}


def unsafe_episodes(log, limit: int = 100) -> list:
    """[start, end (the driver's clock, s since the epoch), unsafe s accrued, reasons] for
    each stretch of the unsafe log (ArmUnsafeMonitor's output, one column per sample)
    in which unsafe_s grew; the first `limit`."""
    from adaptive_c3.systems.franka.arm_unsafe_tally import reasons
    out, cur = [], None
    for k in range(1, log.shape[1]):
        grew = log[1, k] > log[1, k - 1]
        if grew and cur is None:
            cur = [float(log[0, k - 1]), float(log[0, k]), 0.0, 0]
        if grew:
            cur[1], cur[2], cur[3] = float(log[0, k]), cur[2] + float(log[1, k] - log[1, k - 1]), \
                cur[3] | int(log[2, k])
        elif cur is not None:
            out.append(cur[:3] + [reasons(cur[3])])
            cur = None
        if len(out) >= limit:
            break
    if cur is not None and len(out) < limit:
        out.append(cur[:3] + [reasons(cur[3])])
    return out


def unsafe_before(episodes, epoch_s: float | None) -> float:
    """Unsafe seconds (unsafe_episodes) accrued before epoch_s (None: all), spreading
    each episode's time evenly over it."""
    total = 0.0
    for start, end, secs, _ in episodes:
        if epoch_s is None or end <= epoch_s:
            total += secs
        elif start < epoch_s:
            total += secs * (epoch_s - start) / (end - start)
    return total


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
    from adaptive_c3.systems.franka.franka_driver_rules import DriverContractError
    from adaptive_c3.tools.hardware.driver_clock import wall_clock_us
    if not (math.isfinite(args.expire_sec) and args.expire_sec >= 0):
        raise UserError(f"--expire-sec must be >= 0, got {args.expire_sec}")
    if not (math.isfinite(args.low_pass_hz) and args.low_pass_hz > 0):
        raise UserError(f"--low-pass-hz must be > 0, got {args.low_pass_hz}")
    drv = build_sim_driver(s, lcm, status_period=args.status_period,
                           expire_sec=args.expire_sec, low_pass_hz=args.low_pass_hz,
                           clock=wall_clock_us)
    from adaptive_c3.tools.hardware.realtime_priority import request_fifo
    from adaptive_c3.tools.process_tuning import freeze_heap
    scheduling = request_fifo(args.rt_priority)
    sim = Simulator(drv.diagram)
    sim.set_target_realtime_rate(1.0)
    sim.Initialize()
    freeze_heap()
    start_epoch_s = time.time()
    print(f"sim-driver: publishing {STATUS_CHANNEL}, {BALL_CHANNEL}; listening on "
          f"{COMMAND_CHANNEL} at {args.lcm_url} for {duration:g} s", flush=True)
    start = time.perf_counter()
    t = 0.0

    def on_term(_signum, _frame):      # SIGTERM ends the run like Ctrl-C: with the summary
        raise KeyboardInterrupt
    signal.signal(signal.SIGTERM, on_term)
    try:
        while t < duration - 1e-12:
            t = min(t + 0.1, duration)
            sim.AdvanceTo(t)
    except KeyboardInterrupt:
        pass
    except DriverContractError as e:     # the real driver throws and stops here too
        raise UserError(f"stopped at t = {sim.get_context().get_time():.3f} s: {e}")
    summary = driver_summary(drv, sim.get_context())
    summary["wall_s"] = time.perf_counter() - start
    summary["cpu_s"] = time.process_time()
    summary["start_epoch_s"] = start_epoch_s
    summary["scheduling"] = scheduling
    print(json.dumps(summary), flush=True)
    return 0


__all__ = ["build_sim_driver", "cmd_sim_driver", "SimDriver",
           "BallEstimateEncoder", "driver_summary"]
