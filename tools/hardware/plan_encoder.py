"""PlanEncoder: the planner's EE target as an EE_PLAN message (layout in lcm_channels.py).

input  "ee.desired_state"     (6) desired EE tip position (m) and velocity (m/s), base frame
input  "ee.feedforward_force" (3) N, at the tip, base frame
input  "lcmt_panda_status"    abstract: the latest PANDA_STATUS (its utime stamps the plan)
output "lcmt_robot_state"     abstract: the EE_PLAN message
"""
from __future__ import annotations

from pydrake.common.value import AbstractValue
from pydrake.systems.framework import LeafSystem

from adaptive_c3.tools.hardware.lcm_channels import encode_plan


class PlanEncoder(LeafSystem):
    def __init__(self):
        super().__init__()
        from drake import lcmt_panda_status, lcmt_robot_state
        self._desired = self.DeclareVectorInputPort("ee.desired_state", 6)
        self._ff = self.DeclareVectorInputPort("ee.feedforward_force", 3)
        self._status = self.DeclareAbstractInputPort("lcmt_panda_status",
                                                     AbstractValue.Make(lcmt_panda_status()))
        self.DeclareAbstractOutputPort("lcmt_robot_state",
                                       lambda: AbstractValue.Make(lcmt_robot_state()),
                                       self._calc)

    def _calc(self, context, output):
        output.set_value(encode_plan(self._status.Eval(context).utime,
                                     self._desired.Eval(context), self._ff.Eval(context)))
