"""TorqueGate: zero torque unless the plan may be used and the robot is in a mode that
takes commands.

input  "panda.torque_request" (7) N m, without gravity
input  "plan.ok"              (1) from PlanDecoder
input  "lcmt_panda_status"    abstract: the latest PANDA_STATUS
output "panda.torque_command" (7) the request, or zeros when plan.ok is 0 or robot_mode
                              is not kMove / kIdle (guiding, reflex, user stop, error
                              recovery, other: a human or the robot's own safety has it)
"""
from __future__ import annotations

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import LeafSystem

NQ = 7


class TorqueGate(LeafSystem):
    def __init__(self):
        super().__init__()
        from drake import lcmt_panda_status
        self._modes = (lcmt_panda_status.kMove, lcmt_panda_status.kIdle)
        self._tau = self.DeclareVectorInputPort("panda.torque_request", NQ)
        self._ok = self.DeclareVectorInputPort("plan.ok", 1)
        self._status = self.DeclareAbstractInputPort("lcmt_panda_status",
                                                     AbstractValue.Make(lcmt_panda_status()))
        self.DeclareVectorOutputPort("panda.torque_command", NQ, self._calc)

    def _calc(self, context, output):
        ok = self._ok.Eval(context)[0] > 0.5
        mode_ok = self._status.Eval(context).robot_mode in self._modes
        output.SetFromVector(self._tau.Eval(context) if ok and mode_ok else np.zeros(NQ))
