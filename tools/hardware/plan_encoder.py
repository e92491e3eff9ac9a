"""PlanEncoder: the planner's EE target as an EE_PLAN message (layout in lcm_channels.py).

input  "ee.desired_state"     (6) desired EE tip position (m) and velocity (m/s), base frame
input  "ee.feedforward_force" (3) N, at the tip, base frame
input  "lcmt_panda_status"    abstract: the latest PANDA_STATUS (its utime stamps the plan)
output "lcmt_robot_state"     abstract: the EE_PLAN message
delay_s > 0 (`planner --delay-ms`) holds every plan back by that long before it is sent:
an injected planner latency, in the diagram's clock (plans are sampled every period);
until the first plan is that old the output is an empty message (num_joints = 0).
lcm (a DrakeLcm) and publish_period (s): the encoder publishes EE_PLAN itself every
publish_period, and only a plan: an empty message would be a malformed EE_PLAN to the
impedance loop, whose safety layer stops after safety.malformed_run of them in a row
(`--delay-ms 50` sent ten at 200 Hz: a safe stop at t = 0.045 s).
"""
from __future__ import annotations

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import LeafSystem

from adaptive_c3.tools.hardware.lcm_channels import encode_plan


class PlanEncoder(LeafSystem):
    def __init__(self, delay_s: float = 0.0, period: float = 1e-3, *, lcm=None,
                 publish_period: float | None = None):
        super().__init__()
        self._delay = float(delay_s)
        from drake import lcmt_panda_status, lcmt_robot_state
        self._desired = self.DeclareVectorInputPort("ee.desired_state", 6)
        self._ff = self.DeclareVectorInputPort("ee.feedforward_force", 3)
        self._status = self.DeclareAbstractInputPort("lcmt_panda_status",
                                                     AbstractValue.Make(lcmt_panda_status()))
        # ((time, utime, [p, v, f]) not yet old enough, ...), and (utime, [p, v, f]) being sent
        self._queue = self.DeclareAbstractState(AbstractValue.Make(((), None)))
        if self._delay > 0:
            self.DeclarePeriodicUnrestrictedUpdateEvent(period, 0.0, self._update)
        self.DeclareAbstractOutputPort("lcmt_robot_state",
                                       lambda: AbstractValue.Make(lcmt_robot_state()),
                                       self._calc)
        self._lcm = lcm
        if lcm is not None:
            self.DeclarePeriodicPublishEvent(publish_period, 0.0, self._publish)

    def _publish(self, context):
        from adaptive_c3.tools.hardware.lcm_channels import PLAN_CHANNEL
        msg = self.get_output_port().Eval(context)
        if msg.num_joints:                           # a plan, not the empty message
            self._lcm.Publish(PLAN_CHANNEL, msg.encode())

    def _plan_now(self, context):
        return (int(self._status.Eval(context).utime),
                np.r_[self._desired.Eval(context), self._ff.Eval(context)])

    def _update(self, context, state):
        queue, sending = context.get_abstract_state(int(self._queue)).get_value()
        t = context.get_time()
        queue = list(queue) + [(t, *self._plan_now(context))]
        while queue and queue[0][0] <= t - self._delay + 1e-9:
            sending = queue.pop(0)[1:]
        state.get_mutable_abstract_state(int(self._queue)).set_value((tuple(queue), sending))

    def _calc(self, context, output):
        from drake import lcmt_robot_state
        if self._delay > 0:
            sending = context.get_abstract_state(int(self._queue)).get_value()[1]
            if sending is None:                      # nothing old enough yet: an empty message
                output.set_value(lcmt_robot_state())
                return
        else:
            sending = self._plan_now(context)
        output.set_value(encode_plan(sending[0], sending[1][:6], sending[1][6:]))
