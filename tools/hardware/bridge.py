"""`adaptive-c3 hardware SCENARIO --lcm-url URL`: the LCM bridge to a Franka driver.

The controller side of the real experiment as its own diagram (the robot and the vision
process are other processes on the LCM network):

  PANDA_STATUS (lcmt_panda_status) -> PandaStatusReceiver -> q, v -> ImpedanceController
      (-> ee.state, ee.commanded_force)
  BALL_ESTIMATE (lcmt_robot_state) -> BallEstimateDecoder -> ball.position, ball.velocity
  add_ball_rolling_controller (estimator, Anitescu LCS, residual learner, C3 planner)
      -> ee.desired_state, ee.feedforward_force -> ImpedanceController
  ImpedanceController.panda.torque_command -> PandaWatchdog (stale status > 50 ms,
      malformed, torque + rate limits, latched stop on non-finite)
      -> TorqueCommandSender (torque mode, utime = the latest PANDA_STATUS utime: the
      driver's clock) -> PANDA_COMMAND (lcmt_panda_command), every 1 ms

Channels and types (the vision process must follow the BALL_ESTIMATE layout):
  PANDA_STATUS   drake.lcmt_panda_status   from the Franka driver (7 joints)
  PANDA_COMMAND  drake.lcmt_panda_command  torque mode: joint_torque (7, N m) WITHOUT
                 gravity (the robot adds its own gravity compensation); utime = the
                 latest status's utime (the driver drops commands > --expire_sec off
                 its clock)
  BALL_ESTIMATE  drake.lcmt_robot_state    num_joints = 6, joint_name = [ball_x, ball_y,
                 ball_z, ball_vx, ball_vy, ball_vz], joint_position = the ball centre (m)
                 and velocity (m/s) in the robot base frame (table top z = 0); utime =
                 time of the estimate (us). Any other layout (names, count, non-finite)
                 is ignored (NaN to the estimator, which then holds the plan).

The simulator advances in real time (the diagram clock is the wall clock since start);
the watchdog judges the status by its receive time on that clock, and also zeroes the
command while the diagram clock lags the wall clock by more than --max-lag-ms (100 ms):
a controller that cannot keep up would send late commands. --period (1 ms) is the
command / watchdog period.

Real-time caveat (measured on the 2 shared cores here): with the reference wrist gains
(rotational stiffness 900, damping 20) the closed loop over LCM is sensitive to the
command delay of a Python bridge (a few ms, more under CPU load): it oscillated and threw
the ball off; with rotational damping 5 / stiffness 200 it rolled the ball 0.13 m. The
reference runs the 1 kHz impedance loop in its own (C++) process and C3 apart from it. `--log FILE` writes
every LCM message seen (an LCM event log, readable by `adaptive-c3 record convert`).

`run_loopback` runs this bridge and tools/hardware/sim_driver.py in ONE process over memq://,
advancing both in lock-step (as fast as the CPU allows, deterministic): the end-to-end
test of the bridge through LCM alone (`--loopback` on the command line).
"""
from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass

import numpy as np
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import VectorLogSink

from adaptive_c3.tools.hardware.lcm_channels import (BALL_CHANNEL, COMMAND_CHANNEL,
                                                     STATUS_CHANNEL, open_lcm)


@dataclass
class HardwareBridge:
    diagram: object
    watchdog: object
    controller: object       # BallRollingController
    logs: dict               # name -> VectorLogSink
    ball: object             # BallEstimateDecoder (its .health: BALL_ESTIMATE's)
    status_health: object = None   # PANDA_STATUS's ChannelHealth (undecodable messages)

    def undecodable(self) -> dict:
        return {"PANDA_STATUS": self.status_health.undecodable,
                "BALL_ESTIMATE": self.ball.health.undecodable}


def build_hardware_bridge(s, lcm, *, command_period: float = 1e-3, stale_s: float = 0.05,
                          rate_limit: float = 1000.0, log_period: float = 0.01,
                          max_lag_s: float = math.inf) -> HardwareBridge:
    """The bridge diagram (module doc). max_lag_s < inf: the watchdog also compares the
    diagram clock with the wall clock (real-time runs) and zeroes the command while the
    controller lags by more than that."""
    from adaptive_c3.diagrams.ball_rolling import make_impedance_controller
    from adaptive_c3.tools.hardware.controller_pieces import (add_ball_input,
                                                              add_command_output, add_lcm,
                                                              add_planner, add_status_input)
    builder = DiagramBuilder()
    add_lcm(builder, lcm)
    status = add_status_input(builder, lcm, s)
    ctrl = builder.AddSystem(make_impedance_controller(s))
    builder.Connect(status.arm_state, ctrl.GetInputPort("panda.state"))
    ball = add_ball_input(builder, lcm, s, period=max(command_period, 2e-3))
    c = add_planner(builder, s, ctrl, ball)
    wd = add_command_output(builder, lcm, status.status, ctrl.GetOutputPort("panda.torque_command"),
                            command_period=command_period, stale_s=stale_s,
                            rate_limit=rate_limit, max_lag_s=max_lag_s)

    logs = {}
    for name, port in (("lcs_state", c.lcs_state), ("ee_force", ctrl.GetOutputPort("ee.commanded_force")),
                       ("tau", wd.GetOutputPort("panda.torque_command")),
                       ("fault", wd.GetOutputPort("watchdog.fault")),
                       ("r_comp", c.r_comp)):   # at the planning dt, as in simulation
        sink = builder.AddSystem(VectorLogSink(port.size(), log_period))
        sink.set_name(f"log_{name}")
        builder.Connect(port, sink.get_input_port())
        logs[name] = sink
    diagram = builder.Build()
    diagram.set_name(f"lcm_bridge[{s.name}]")
    return HardwareBridge(diagram, wd, c, logs, ball, status.health)


class LcmRecorder:
    """Writes every message seen on `lcm` to an LCM event log (tools/hardware/record_convert.py).
    `clock()` gives the event timestamps in seconds (wall clock by default)."""

    def __init__(self, lcm, path, clock=None):
        from adaptive_c3.tools.user_input import UserError
        from adaptive_c3.tools.hardware.record_convert import LcmLogWriter
        try:
            self._writer = LcmLogWriter(path)
        except OSError as e:
            raise UserError(f"cannot write the LCM log {path}: {e.strerror}")
        self._clock = clock or time.time
        lcm.SubscribeAllChannels(self._on)

    def _on(self, channel, data):
        self._writer.write(int(round(self._clock() * 1e6)), channel, bytes(data))

    def close(self):
        self._writer.close()


def run_loopback(s, duration: float, *, stop_driver_at: float | None = None,
                 log_path=None, step: float = 1e-3, command_period: float = 1e-3,
                 stale_s: float = 0.05, low_pass_hz: float = 30.0) -> dict:
    """Bridge + simulated driver in one process over memq://, in lock-step.

    Every `step` of simulated time: advance the driver (it publishes the status /
    ball estimate), then the bridge (it reads them and publishes its command), so each
    side sees the other's newest message. From `stop_driver_at` on, the driver is no
    longer advanced (as if killed) while the bridge goes on: the result tells when the
    bridge's command became zero. The driver keeps the real driver's rules
    (low_pass_hz: its torque low-pass, 30 Hz as drake-franka-driver's default) on a
    clock of simulation time from a fixed epoch. Returns a summary dict (and the
    handles under "_")."""
    from pydrake.lcm import DrakeLcm
    from pydrake.systems.analysis import Simulator

    from adaptive_c3.tools.hardware.first_messages import start_from_first_messages
    from adaptive_c3.tools.hardware.sim_driver import build_sim_driver, driver_summary

    lcm = DrakeLcm("memq://")
    drv = build_sim_driver(s, lcm, low_pass_hz=low_pass_hz)
    bridge = build_hardware_bridge(s, lcm, command_period=command_period, stale_s=stale_s)
    clock = {"t": 0.0}
    rec = LcmRecorder(lcm, log_path, clock=lambda: clock["t"]) if log_path else None
    sim_d, sim_b = Simulator(drv.diagram), Simulator(bridge.diagram)
    sim_d.Initialize()                  # publishes the first status and ball estimate
    start_from_first_messages(sim_b, lcm, [STATUS_CHANNEL, BALL_CHANNEL],
                              pump=lambda: lcm.HandleSubscriptions(0), timeout_s=0.0)
    cmds = []   # (t, |tau|_inf) of each command the bridge published, seen from outside

    def on_cmd(data):
        from drake import lcmt_panda_command
        msg = lcmt_panda_command.decode(data)
        cmds.append((clock["t"], float(np.max(np.abs(msg.joint_torque))) if msg.joint_torque else 0.0))
    lcm.Subscribe(COMMAND_CHANNEL, on_cmd)
    n = int(round(duration / step))
    wall = time.perf_counter()
    driver_alive = True
    for k in range(1, n + 1):
        t = k * step
        clock["t"] = t
        if stop_driver_at is not None and t > stop_driver_at + 1e-12:
            driver_alive = False
        if driver_alive:
            sim_d.AdvanceTo(t)
        sim_b.AdvanceTo(t)
        lcm.HandleSubscriptions(0)
    wall = time.perf_counter() - wall
    if rec:
        rec.close()
    ctx_b = sim_b.get_context()
    wd_ctx = bridge.watchdog.GetMyContextFromRoot(ctx_b)
    out = {"sim_duration_s": duration, "wall_s": wall,
           "driver": driver_summary(drv, sim_d.get_context()),
           "watchdog": bridge.watchdog.report(wd_ctx),
           **bridge.ball.counts(bridge.ball.GetMyContextFromRoot(ctx_b))}
    if stop_driver_at is not None:
        after = [(t, a) for t, a in cmds if t > stop_driver_at]
        zero_t = next((t for t, a in after if a == 0.0), None)
        out["driver_stopped_at_s"] = stop_driver_at
        out["command_zero_after_s"] = None if zero_t is None else zero_t - stop_driver_at
        out["nonzero_commands_after_zero"] = sum(1 for t, a in after
                                                 if zero_t is not None and t > zero_t and a != 0)
    out["commands_published"] = len(cmds)
    out["_"] = {"driver": drv, "bridge": bridge, "sim_driver": sim_d, "sim_bridge": sim_b}
    return out


def cmd_hardware(args) -> int:
    from adaptive_c3.tools.hardware.realtime import load_hardware_scenario, run_realtime
    s, _, duration = load_hardware_scenario(args)
    stale_s = args.stale_ms * 1e-3
    if args.loopback:
        if args.split:
            from adaptive_c3.tools.hardware.split_loopback import run_split_loopback
            out = run_split_loopback(s, duration or s.sim_duration_s, stale_s=stale_s)
        else:
            out = run_loopback(s, duration or s.sim_duration_s, log_path=args.log, stale_s=stale_s)
        out.pop("_")
        print(json.dumps(out, default=float), flush=True)
        return 0
    if not args.lcm_url:
        from adaptive_c3.tools.user_input import UserError
        raise UserError("--lcm-url is required (or --loopback)")
    if args.split:
        from adaptive_c3.tools.hardware.process_commands import run_split
        open_lcm(args.lcm_url)           # a bad URL: one line here, not two tracebacks
        return run_split(args)
    lcm = open_lcm(args.lcm_url)
    bridge = build_hardware_bridge(s, lcm, stale_s=stale_s, command_period=args.period,
                                   max_lag_s=args.max_lag_ms * 1e-3)
    rec = LcmRecorder(lcm, args.log) if args.log else None
    ctx, wall = run_realtime(
        bridge.diagram, duration,
        f"hardware: bridge on {args.lcm_url}: {STATUS_CHANNEL} + {BALL_CHANNEL} -> "
        f"{COMMAND_CHANNEL}; watchdog {args.stale_ms:g} ms", on_stop=rec.close if rec else None,
        wait_for=(lcm, [STATUS_CHANNEL, BALL_CHANNEL]))
    wd_ctx = bridge.watchdog.GetMyContextFromRoot(ctx)
    out = {"sim_time_s": float(ctx.get_time()), "wall_s": wall,
           "watchdog": bridge.watchdog.report(wd_ctx),
           "undecodable_messages": bridge.undecodable()}
    print(json.dumps(out, default=float), flush=True)
    return 0


__all__ = ["build_hardware_bridge", "cmd_hardware", "run_loopback", "HardwareBridge",
           "LcmRecorder"]
