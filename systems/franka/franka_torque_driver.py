"""FrankaTorqueDriver: the real torque driver's handling of PANDA_COMMAND, as a LeafSystem
(the rules and their facts are in franka_driver_rules.py).

input  "lcmt_panda_command"    abstract: the latest drake.lcmt_panda_command
input  "panda.state"           (14) q (rad), v (rad/s)
output "panda.torque_command"  (7) N m, WITHOUT gravity: what the robot applies on top of
                               its own gravity compensation (after expiry: joint damping)
output "driver.ticks_held"     (1) ticks so far in which the driver held the arm itself
                               (no command, or it expired)
Every `period` (1 ms) it ticks the rules with now = clock(t) (microseconds since the
epoch: the wall clock in a real-time process, a fixed epoch + simulation time in a
lock-step one). A command the real driver would throw on raises DriverContractError
out of the simulator: the driver stops.
"""
from __future__ import annotations

from pydrake.common.value import AbstractValue
from pydrake.systems.framework import LeafSystem

from adaptive_c3.systems.franka.franka_driver_rules import (EXPIRED, NQ, RECEIVED, TAU,
                                                            TICKS_HELD, DriverRules,
                                                            initial_state)


class FrankaTorqueDriver(LeafSystem):
    def __init__(self, clock, expire_sec: float = 0.1, low_pass_hz: float = 30.0,
                 period: float = 1e-3):
        super().__init__()
        from drake import lcmt_panda_command
        self._rules = DriverRules(expire_sec, low_pass_hz, period)
        self._clock = clock
        self._cmd = self.DeclareAbstractInputPort("lcmt_panda_command",
                                                  AbstractValue.Make(lcmt_panda_command()))
        self._state = self.DeclareVectorInputPort("panda.state", 2 * NQ)
        self._xd = self.DeclareDiscreteState(initial_state())
        self.DeclarePeriodicDiscreteUpdateEvent(period, 0.0, self._update)
        self.DeclareVectorOutputPort("panda.torque_command", NQ, self._calc,
                                     prerequisites_of_calc={self.xd_ticket()})
        self.DeclareVectorOutputPort(
            "driver.ticks_held", 1,
            lambda c, o: o.SetAtIndex(0, c.get_discrete_state(self._xd).get_value()[TICKS_HELD]),
            prerequisites_of_calc={self.xd_ticket()})

    def _update(self, context, discrete_state):
        s = context.get_discrete_state(self._xd).get_value()
        v = self._state.Eval(context)[NQ:]
        now = int(self._clock(context.get_time()))
        new = self._rules.tick(s, self._cmd.Eval(context), now, v)
        discrete_state.get_mutable_vector(self._xd).set_value(new)

    def _calc(self, context, output):
        output.SetFromVector(context.get_discrete_state(self._xd).get_value()[TAU])

    def counts(self, context) -> dict:
        """Commands received, commands expired, ticks held by damping (none to use)."""
        s = context.get_discrete_state(self._xd).get_value()
        return {"commands_received": int(s[RECEIVED]), "commands_expired": int(s[EXPIRED]),
                "ticks_without_command": int(s[TICKS_HELD])}
