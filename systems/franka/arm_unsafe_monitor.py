"""ArmUnsafeMonitor: the simulated driver's own record of when the robot was unsafe
(the conditions and the tally: arm_unsafe_tally.py).

input  "panda.state"        (14) q (rad), v (rad/s), the true arm
input  "panda.torque"       (7) N m, the torque the driver applies (without gravity)
input  "ball.state"         (13) the true ball: quaternion, position (m, W), w, v
input  "driver.ticks_held"  (1) the driver's count of ticks it held the arm itself
output "unsafe"             (3) [the driver's clock (s since the epoch), unsafe_s (s of
                            simulation, unsafe while commanded), condition bits]
Updated every `period` (2 ms); the output, logged, gives when (in the driver's clock,
which is the wall clock in a real-time run) the unsafe time accrued.
"""
from __future__ import annotations

import numpy as np
from pydrake.systems.framework import LeafSystem

from adaptive_c3.systems.franka.arm_unsafe_tally import NOW, NQ, UNSAFE, UnsafeTally


class ArmUnsafeMonitor(LeafSystem):
    def __init__(self, clock, ball_radius: float, period: float = 2e-3, **limits):
        super().__init__()
        self._tally = UnsafeTally(ball_radius, **limits)
        self._clock, self._dt = clock, float(period)
        self._state = self.DeclareVectorInputPort("panda.state", 2 * NQ)
        self._tau = self.DeclareVectorInputPort("panda.torque", NQ)
        self._ball = self.DeclareVectorInputPort("ball.state", 13)
        self._held = self.DeclareVectorInputPort("driver.ticks_held", 1)
        self._xd = self.DeclareDiscreteState(self._tally.initial_state())
        self.DeclarePeriodicDiscreteUpdateEvent(period, 0.0, self._update)
        self.DeclareVectorOutputPort("unsafe", 3, self._calc,
                                     prerequisites_of_calc={self.xd_ticket()})

    def _update(self, context, discrete_state):
        s = context.get_discrete_state(self._xd).get_value()
        new = self._tally.step(s, self._dt, self._state.Eval(context)[:NQ],
                               self._tau.Eval(context), self._ball.Eval(context)[4:7],
                               self._held.Eval(context)[0])
        discrete_state.get_mutable_vector(self._xd).set_value(new)

    def _calc(self, context, output):
        s = context.get_discrete_state(self._xd).get_value()
        output.SetFromVector([1e-6 * self._clock(context.get_time()), s[UNSAFE], s[NOW]])

    def report(self, context) -> dict:
        return self._tally.report(context.get_discrete_state(self._xd).get_value())
