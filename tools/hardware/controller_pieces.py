"""The pieces the LCM controllers are built from, each added to a DiagramBuilder:

  add_status_input    PANDA_STATUS -> the arm state (14, finite) and the Python message
  add_ball_input      BALL_ESTIMATE -> ball.position, ball.velocity
  add_planner         the ball-rolling controller on the EE state and the ball
  add_command_output  a torque request -> PandaWatchdog -> TorqueCommandSender -> PANDA_COMMAND
The single-process bridge (bridge.py) and the two processes (impedance_process.py,
planner_process.py) are recipes of these and the controller systems.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from adaptive_c3.tools.hardware.lcm_channels import (BALL_CHANNEL, COMMAND_CHANNEL, NQ,
                                                     STATUS_CHANNEL, fast_drake_lcm_copies)


@dataclass
class StatusInput:
    status: object          # output port: the newest lcmt_panda_status (Python message)
    arm_state: object       # output port: (14) q, v, with q_null / 0 for non-finite values
    health: object = None   # ChannelHealth of PANDA_STATUS


def add_lcm(builder, lcm):
    from pydrake.systems.lcm import LcmInterfaceSystem
    fast_drake_lcm_copies()
    builder.AddSystem(LcmInterfaceSystem(lcm))


def add_status_input(builder, lcm, s, sample_period: float | None = None) -> StatusInput:
    """PANDA_STATUS decoded once (Python), and as the arm state. sample_period: take the
    newest status every sample_period s (SampledLcmSubscriber) instead of at every
    message - for a diagram that does not need the driver's 1 kHz. Either way an
    undecodable message is counted (StatusInput.health) and never used."""
    from drake import lcmt_panda_status
    from pydrake.systems.lcm import LcmSubscriberSystem

    from adaptive_c3.tools.hardware.channel_health import ChannelHealth, tolerant_type
    from adaptive_c3.tools.hardware.sampled_subscriber import SampledLcmSubscriber
    from adaptive_c3.tools.hardware.status_arm_state import StatusArmState
    if sample_period is None:
        health = ChannelHealth(STATUS_CHANNEL, lcmt_panda_status)
        sub = builder.AddSystem(LcmSubscriberSystem.Make(STATUS_CHANNEL, tolerant_type(health),
                                                         lcm))
    else:
        sub = builder.AddSystem(SampledLcmSubscriber(STATUS_CHANNEL, lcmt_panda_status, lcm,
                                                     sample_period))
        health = sub.health
    arm = builder.AddSystem(StatusArmState(np.r_[np.asarray(s.impedance.q_null, float),
                                                 np.zeros(NQ)]))
    builder.Connect(sub.get_output_port(), arm.get_input_port())
    return StatusInput(sub.get_output_port(), arm.get_output_port(), health)


def add_ball_input(builder, lcm, s, period: float):
    """BALL_ESTIMATE sampled every `period` s; an undecodable message is counted (the
    decoder's counts) and never used."""
    from drake import lcmt_robot_state

    from adaptive_c3.diagrams.ball_rolling import ball_start_xy
    from adaptive_c3.tools.hardware.ball_estimate_decoder import BallEstimateDecoder
    from adaptive_c3.tools.hardware.sampled_subscriber import SampledLcmSubscriber
    sub = builder.AddSystem(SampledLcmSubscriber(BALL_CHANNEL, lcmt_robot_state, lcm, period))
    ball = builder.AddSystem(BallEstimateDecoder(np.r_[ball_start_xy(s), s.model.ball_radius],
                                                 period=period, health=sub.health))
    builder.Connect(sub.get_output_port(), ball.get_input_port())
    return ball


def add_planner(builder, s, ctrl, ball, transport_s: float = 0.0):
    """The ball-rolling controller (estimator, Anitescu LCS, learner, C3) on the impedance
    controller's EE state and the decoded ball, its EE target fed back to `ctrl` (whose
    commanded force is then the learner's applied-force input). Returns the controller."""
    from adaptive_c3.diagrams.ball_rolling import add_ball_rolling_controller
    c = add_ball_rolling_controller(builder, s, ctrl.GetOutputPort("ee.state"),
                                    ctrl.GetOutputPort("ee.commanded_force"),
                                    ball.GetOutputPort("ball.position"),
                                    ball.GetOutputPort("ball.velocity"),
                                    transport_s=transport_s)
    builder.Connect(c.ee_desired_state, ctrl.GetInputPort("ee.desired_state"))
    builder.Connect(c.ee_feedforward_force, ctrl.GetInputPort("ee.feedforward_force"))
    return c


def add_command_output(builder, lcm, status_port, torque_port, *, command_period: float,
                       stale_s: float, rate_limit: float, max_lag_s: float = math.inf):
    """Watchdog, then the torque-mode command stamped with the latest status utime (the
    driver's clock; Drake's PandaCommandSender stamps the diagram time, which the driver
    would drop). Returns the watchdog."""
    from drake import lcmt_panda_command
    from pydrake.systems.lcm import LcmPublisherSystem

    from adaptive_c3.systems.franka.panda_watchdog import PandaWatchdog, WatchdogConfig
    from adaptive_c3.tools.hardware.torque_command_sender import TorqueCommandSender
    wd = builder.AddSystem(PandaWatchdog(
        WatchdogConfig(stale_s=stale_s, rate_limit=rate_limit, max_lag_s=max_lag_s),
        period=command_period, wall_clock=math.isfinite(max_lag_s)))
    builder.Connect(status_port, wd.GetInputPort("panda.status"))
    builder.Connect(torque_port, wd.GetInputPort("panda.torque_request"))
    sender = builder.AddSystem(TorqueCommandSender())
    builder.Connect(wd.GetOutputPort("panda.torque_command"),
                    sender.GetInputPort("panda.torque_command"))
    builder.Connect(status_port, sender.GetInputPort("lcmt_panda_status"))
    pub = builder.AddSystem(LcmPublisherSystem.Make(
        COMMAND_CHANNEL, lcmt_panda_command, lcm, command_period))
    builder.Connect(sender.get_output_port(), pub.get_input_port())
    return wd
