"""BallEstimateDecoder: BALL_ESTIMATE messages as the controller's ball position and velocity."""
from __future__ import annotations

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import LeafSystem

from adaptive_c3.tools.hardware.lcm_channels import decode_ball_estimate


class BallEstimateDecoder(LeafSystem):
    """lcmt_robot_state (BALL_ESTIMATE layout) -> ball.position (3), ball.velocity (3).

    Every `period` s it takes the subscriber's newest message if it fits the layout
    (finite, 6 named values) and holds it; before the first valid message it outputs
    `prior` (the scenario's start position, at rest). Messages of another layout are
    counted and ignored; messages that did not decode at all are counted in `health`
    (the channel's ChannelHealth, or None). (The controller's LCS refuses non-finite states, so the
    decoder never outputs NaN.)"""

    def __init__(self, prior, period: float = 1e-3, health=None):
        super().__init__()
        self.health = health
        from drake import lcmt_robot_state
        self._in = self.DeclareAbstractInputPort("lcmt_robot_state",
                                                 AbstractValue.Make(lcmt_robot_state()))
        # [p (3), v (3), valid messages, ignored messages, last utime]
        self._xd = self.DeclareDiscreteState(np.r_[np.asarray(prior, float), np.zeros(3),
                                                   0.0, 0.0, -1.0])
        self.DeclarePeriodicDiscreteUpdateEvent(period, 0.0, self._update)
        ticket = {self.xd_ticket()}
        self.DeclareVectorOutputPort("ball.position", 3, lambda c, o: o.SetFromVector(self._s(c)[:3]),
                                     prerequisites_of_calc=ticket)
        self.DeclareVectorOutputPort("ball.velocity", 3, lambda c, o: o.SetFromVector(self._s(c)[3:6]),
                                     prerequisites_of_calc=ticket)

    def _s(self, context):
        return context.get_discrete_state(self._xd).get_value()

    def _update(self, context, discrete_state):
        s = self._s(context).copy()
        msg = self._in.Eval(context)
        if msg.num_joints > 0 and float(msg.utime) != s[8]:
            s[8] = float(msg.utime)
            v = decode_ball_estimate(msg)
            if np.all(np.isfinite(v)):
                s[:6], s[6] = v, s[6] + 1
            else:
                s[7] += 1
        discrete_state.get_mutable_vector(self._xd).set_value(s)

    def counts(self, context) -> dict:
        s = self._s(context)
        return {"ball_messages": int(s[6]), "ball_messages_ignored": int(s[7])}
