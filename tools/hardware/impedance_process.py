"""`adaptive-c3 impedance SCENARIO --lcm-url URL`: the 1 kHz loop alone, as the reference
system runs it beside the Franka driver.

  PANDA_STATUS -> arm state -> ImpedanceController (the scenario's gains) tracking the
  newest EE_PLAN from the planner process (PlanDecoder: hold the last target at rest when
  the plan is older than --plan-hold-ms, zero torque after --plan-timeout-ms or before
  the first plan) -> TorqueGate (also zero unless robot_mode is kMove / kIdle) ->
  PandaWatchdog (stale status, malformed, torque and rate limits, latched stop on
  non-finite) -> PANDA_COMMAND, torque mode, stamped with the latest status utime.
Nothing here waits for C3 or the learner: they run in the planner process.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from pydrake.systems.framework import DiagramBuilder


@dataclass
class ImpedanceProcess:
    diagram: object
    watchdog: object
    plan: object              # PlanDecoder


def build_impedance_process(s, lcm, *, command_period: float = 1e-3, stale_s: float = 0.05,
                            rate_limit: float = 1000.0, plan_hold_s: float = 0.1,
                            plan_timeout_s: float = 0.5,
                            max_lag_s: float = math.inf) -> ImpedanceProcess:
    from drake import lcmt_robot_state
    from pydrake.systems.lcm import LcmSubscriberSystem

    from adaptive_c3.diagrams.ball_rolling import make_impedance_controller
    from adaptive_c3.tools.hardware.controller_pieces import (add_command_output, add_lcm,
                                                              add_status_input)
    from adaptive_c3.tools.hardware.lcm_channels import PLAN_CHANNEL
    from adaptive_c3.tools.hardware.plan_decoder import PlanDecoder
    from adaptive_c3.tools.hardware.torque_gate import TorqueGate
    builder = DiagramBuilder()
    add_lcm(builder, lcm)
    status = add_status_input(builder, lcm, s)
    plan_sub = builder.AddSystem(LcmSubscriberSystem.Make(PLAN_CHANNEL, lcmt_robot_state, lcm))
    plan = builder.AddSystem(PlanDecoder(command_period, plan_hold_s, plan_timeout_s))
    builder.Connect(plan_sub.get_output_port(), plan.GetInputPort("lcmt_robot_state"))
    builder.Connect(status.status, plan.GetInputPort("lcmt_panda_status"))
    ctrl = builder.AddSystem(make_impedance_controller(s))
    builder.Connect(status.arm_state, ctrl.GetInputPort("panda.state"))
    builder.Connect(plan.GetOutputPort("ee.desired_state"), ctrl.GetInputPort("ee.desired_state"))
    builder.Connect(plan.GetOutputPort("ee.feedforward_force"),
                    ctrl.GetInputPort("ee.feedforward_force"))
    gate = builder.AddSystem(TorqueGate())
    builder.Connect(ctrl.GetOutputPort("panda.torque_command"),
                    gate.GetInputPort("panda.torque_request"))
    builder.Connect(plan.GetOutputPort("plan.ok"), gate.GetInputPort("plan.ok"))
    builder.Connect(status.status, gate.GetInputPort("lcmt_panda_status"))
    wd = add_command_output(builder, lcm, status.status, gate.get_output_port(),
                            command_period=command_period, stale_s=stale_s,
                            rate_limit=rate_limit, max_lag_s=max_lag_s)
    diagram = builder.Build()
    diagram.set_name(f"impedance[{s.name}]")
    return ImpedanceProcess(diagram, wd, plan)
