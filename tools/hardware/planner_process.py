"""`adaptive-c3 planner SCENARIO --lcm-url URL`: estimator, Anitescu LCS, residual learner
and C3, apart from the 1 kHz loop.

  PANDA_STATUS -> arm state -> EE state (the impedance controller's kinematics; its
  commanded force, computed from the plan as the impedance process does, is the
  learner's applied-force input when the scenario asks for it)
  BALL_ESTIMATE -> ball position, velocity
  -> add_ball_rolling_controller (as in simulation) -> PlanEncoder -> EE_PLAN every
  plan_period (the EE target, its velocity and the feed-forward force, stamped with the
  status utime it was planned from).
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from pydrake.systems.framework import DiagramBuilder


@dataclass
class PlannerProcess:
    diagram: object
    controller: object       # BallRollingController
    ball: object             # BallEstimateDecoder (its .health: BALL_ESTIMATE's ChannelHealth)
    gait: object             # the planner's Gait (its phase schedule, diagram time)
    status_health: object = None   # PANDA_STATUS's ChannelHealth

    def roll_starts(self, t: float) -> list:
        """The gait's roll-phase starts (diagram time, s) up to diagram time t."""
        g = self.gait
        starts = []
        while g.t0 + g.s.settle_s + len(starts) * g.period <= t:
            starts.append(g.t0 + g.s.settle_s + len(starts) * g.period)
        return starts

    def learner_steps(self, context) -> int:
        c = self.controller
        return int(c.learner.num_steps(c.learner.GetMyContextFromRoot(context)))

    def summary(self, context, planned_s: float | None = None, learner_steps: int | None = None,
                roll_starts=None) -> dict:
        """C3 solve times (ms), learner steps and rate, and the gait's roll-phase starts
        (diagram time, s) up to the context's time. planned_s, learner_steps, roll_starts:
        the totals over several planning segments (planner_run.py), if there were."""
        c = self.controller
        solve_ms = np.asarray(c.planner.solve_times, float) * 1e3
        t = float(context.get_time()) if planned_s is None else planned_s
        steps = self.learner_steps(context) if learner_steps is None else learner_steps
        starts = self.roll_starts(t) if roll_starts is None else roll_starts
        return {"c3_solves": int(solve_ms.size),
                "c3_solve_ms": {"p50": float(np.median(solve_ms)) if solve_ms.size else None,
                                "p99": (float(np.percentile(solve_ms, 99))
                                        if solve_ms.size else None)},
                "plan_rate_hz": solve_ms.size / t if t > 0 else 0.0,
                "learner_steps": int(steps),
                "learner_rate_hz": steps / t if t > 0 else 0.0,
                "roll_starts_s": starts, **self.ball.counts(self.ball.GetMyContextFromRoot(context))}


def build_planner_process(s, lcm, *, plan_period: float = 0.005, ball_period: float = 2e-3,
                          delay_s: float = 0.0, transport_s: float = 1e-3) -> PlannerProcess:
    """delay_s: an injected latency on every plan (`--delay-ms`); transport_s: the rest of
    the way to the impedance loop (LCM), for c3.predict_state's measured lead."""
    from adaptive_c3.diagrams.ball_rolling import make_gait, make_impedance_controller
    from adaptive_c3.tools.hardware.controller_pieces import (add_ball_input, add_lcm,
                                                              add_planner, add_status_input)
    from adaptive_c3.tools.hardware.plan_encoder import PlanEncoder
    # C3's warm start moves by the time between plans (the diagram clock follows the
    # wall clock here), not by one LCS step per solve
    s = dataclasses.replace(s, c3=dataclasses.replace(s.c3, warm_start_shift="elapsed"))
    builder = DiagramBuilder()
    add_lcm(builder, lcm)
    # the planner's systems run at 80 Hz (C3, LCS) and 200 Hz (learner samples): the
    # newest status every 2.5 ms, not a simulator step per 1 kHz status
    status = add_status_input(builder, lcm, s, sample_period=2.5e-3)
    kin = builder.AddSystem(make_impedance_controller(s))     # for ee.state / commanded force
    builder.Connect(status.arm_state, kin.GetInputPort("panda.state"))
    ball = add_ball_input(builder, lcm, s, period=ball_period)
    c = add_planner(builder, s, kin, ball, transport_s=delay_s + transport_s)
    # (the encoder publishes EE_PLAN itself: never the empty message --delay-ms has
    # before its first plan is old enough)
    enc = builder.AddSystem(PlanEncoder(delay_s, lcm=lcm, publish_period=plan_period))
    builder.Connect(c.ee_desired_state, enc.GetInputPort("ee.desired_state"))
    builder.Connect(c.ee_feedforward_force, enc.GetInputPort("ee.feedforward_force"))
    builder.Connect(status.status, enc.GetInputPort("lcmt_panda_status"))
    diagram = builder.Build()
    diagram.set_name(f"planner[{s.name}]")
    # (make_gait: the schedule the planner's gait keeps)
    return PlannerProcess(diagram, c, ball, make_gait(s), status.health)
