"""ImpedanceTick: one step of the 1 kHz impedance loop, without a Drake diagram.

  PANDA_STATUS -> arm state (q_null at rest for a status whose values are not all
  finite: the watchdog below latches the stop on it) -> the scenario's impedance law
  tracking the held EE plan (PlanHold) -> zero unless the plan may be used and
  robot_mode is kMove or kIdle (guiding, reflex, user stop, error recovery, other: a
  human or the robot's own safety has the arm) -> WatchdogCore (stale status, malformed,
  torque and rate limits, latched stop on non-finite) -> PANDA_COMMAND in torque mode,
  stamped with the latest status utime.

The stamp is the latest status utime, not our wall clock: the status utime IS the
driver's clock, so no clock synchronisation between two PCs is needed, and a command
built on a status that went stale carries that age, so the driver drops it after its
--expire_sec (the reference controllers stamp the same way).

Every piece is a shared core: ImpedanceLaw (also inside the simulation's
ImpedanceController), WatchdogCore (PandaWatchdog), torque_command_message
(TorqueCommandSender). Without the framework a tick costs the law's kinematics and
little else: ~0.1 ms, against ~0.5 ms as a Simulator tick (README, Hardware over LCM).
"""
from __future__ import annotations

import numpy as np

from adaptive_c3.systems.franka.panda_watchdog import (StatusSample, WatchdogConfig,
                                                       WatchdogCore)
from adaptive_c3.tools.hardware.plan_hold import PlanHold
from adaptive_c3.tools.hardware.status_arm_state import arm_state_from_status
from adaptive_c3.tools.hardware.torque_command_sender import torque_command_message

NQ = 7
_ZERO = np.zeros(NQ)


class ImpedanceTick:
    def __init__(self, s, *, stale_s: float = 0.05, rate_limit: float = 1000.0,
                 plan_hold_s: float = 0.1, plan_timeout_s: float = 0.5):
        from drake import lcmt_panda_status

        from adaptive_c3.diagrams.ball_rolling import make_impedance_law
        self.law = make_impedance_law(s)
        self.plan = PlanHold(plan_hold_s, plan_timeout_s)
        self.watchdog = WatchdogCore(WatchdogConfig(stale_s=stale_s, rate_limit=rate_limit))
        self.watchdog_state = self.watchdog.new_state()
        self._fallback = np.r_[self.law.q_null, np.zeros(NQ)]
        self._modes = (lcmt_panda_status.kMove, lcmt_panda_status.kIdle)

    def step(self, t: float, status):
        """The command for the newest status (None before the first one: nothing is sent,
        since a command needs the driver's clock) at the loop's time t (s)."""
        sample = StatusSample.from_lcm(status)
        if sample is None:
            self.watchdog.step(self.watchdog_state, t, None, _ZERO)
            return None
        tau = _ZERO
        desired, feedforward, ok = self.plan.target(sample.utime)
        if ok and status.robot_mode in self._modes:
            tau = self.law.torque(arm_state_from_status(status, self._fallback), desired,
                                  feedforward)
        tau = self.watchdog.step(self.watchdog_state, t, sample, tau)
        return torque_command_message(tau, sample.utime)

    def report(self) -> dict:
        return {"watchdog": self.watchdog_state.report(), **self.plan.counts()}
