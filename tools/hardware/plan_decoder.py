"""PlanDecoder: the impedance process's view of the planner's EE plan (EE_PLAN).

input  "lcmt_robot_state"     abstract: the newest EE_PLAN message
input  "lcmt_panda_status"    abstract: the newest PANDA_STATUS (the driver's clock)
output "ee.desired_state"     (6) m, m/s, base frame
output "ee.feedforward_force" (3) N
output "plan.ok"              (1) 1 while the plan may be used, 0 = command zero torque
Every `period` it takes the newest plan that fits the layout. A plan's age is the
driver's clock (latest status utime) minus the plan's utime. Older than hold_s: the last
target is held at rest (zero velocity, zero feed-forward) - the arm stays where the
planner last wanted it; older than timeout_s, or no plan yet: plan.ok = 0.
"""
from __future__ import annotations

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import LeafSystem

from adaptive_c3.tools.hardware.lcm_channels import decode_plan

# state: [p (3), v (3), f (3), plan utime, plans used, plans ignored]
UTIME, USED, IGNORED = 9, 10, 11


class PlanDecoder(LeafSystem):
    def __init__(self, period: float = 1e-3, hold_s: float = 0.1, timeout_s: float = 0.5):
        super().__init__()
        from drake import lcmt_panda_status, lcmt_robot_state
        self._hold_us, self._timeout_us = hold_s * 1e6, timeout_s * 1e6
        self._plan = self.DeclareAbstractInputPort("lcmt_robot_state",
                                                   AbstractValue.Make(lcmt_robot_state()))
        self._status = self.DeclareAbstractInputPort("lcmt_panda_status",
                                                     AbstractValue.Make(lcmt_panda_status()))
        s0 = np.zeros(12)
        s0[UTIME] = -1.0
        self._xd = self.DeclareDiscreteState(s0)
        self.DeclarePeriodicDiscreteUpdateEvent(period, 0.0, self._update)
        ticket = {self.xd_ticket(), self._status.ticket()}
        self.DeclareVectorOutputPort("ee.desired_state", 6, self._calc_desired,
                                     prerequisites_of_calc=ticket)
        self.DeclareVectorOutputPort("ee.feedforward_force", 3, self._calc_ff,
                                     prerequisites_of_calc=ticket)
        self.DeclareVectorOutputPort("plan.ok", 1, self._calc_ok, prerequisites_of_calc=ticket)

    def _update(self, context, discrete_state):
        s = context.get_discrete_state(self._xd).get_value().copy()
        msg = self._plan.Eval(context)
        if msg.num_joints and float(msg.utime) != s[UTIME]:
            v = decode_plan(msg)
            if v is None:
                s[IGNORED] += 1
            else:
                s[:9], s[UTIME], s[USED] = v, float(msg.utime), s[USED] + 1
        discrete_state.get_mutable_vector(self._xd).set_value(s)

    def _age_us(self, context, s) -> float:
        if s[UTIME] < 0:
            return np.inf
        return float(self._status.Eval(context).utime) - s[UTIME]

    def _calc_desired(self, context, output):
        s = context.get_discrete_state(self._xd).get_value()
        fresh = self._age_us(context, s) <= self._hold_us
        output.SetFromVector(np.r_[s[0:3], s[3:6] if fresh else np.zeros(3)])

    def _calc_ff(self, context, output):
        s = context.get_discrete_state(self._xd).get_value()
        fresh = self._age_us(context, s) <= self._hold_us
        output.SetFromVector(s[6:9] if fresh else np.zeros(3))

    def _calc_ok(self, context, output):
        s = context.get_discrete_state(self._xd).get_value()
        output.SetFromVector([1.0 if self._age_us(context, s) <= self._timeout_us else 0.0])

    def counts(self, context) -> dict:
        s = context.get_discrete_state(self._xd).get_value()
        return {"plans_used": int(s[USED]), "plans_ignored": int(s[IGNORED])}
