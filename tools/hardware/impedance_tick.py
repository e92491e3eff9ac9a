"""ImpedanceTick: one step of the 1 kHz impedance loop, without a Drake diagram.

  receive_status / receive_plan / receive_ball: each message as it arrives (None = it
  did not decode); a malformed one is counted and never used (SafetyMonitor.message)
  step(t): newest PANDA_STATUS -> arm state -> the scenario's impedance law tracking the
  held EE plan (PlanHold) -> zero unless robot_mode is kMove or kIdle (guiding, reflex,
  user stop, error recovery, other: a human or the robot's own safety has the arm) ->
  SafetyMonitor (the scenario's `safety:` limits) -> WatchdogCore (torque and rate
  limits) -> PANDA_COMMAND in torque mode, stamped with the latest status utime.

Modes (SafetyMonitor): WAITING sends nothing until there is a status and a plan at most
plan_hold_s older than it (the driver holds the arm meanwhile). ACTIVE commands the law.
A breach (or a requested stop) -> STOPPING: damping -kd v on each new status for
safety.stop_ramp_s, then STOPPED: nothing more is ever sent, `finished` is True and the
process ends (exit code SAFE_STOP_EXIT after a breach). There is no resuming: a status
gap is a breach, so after a driver restart the impedance process must be started again,
and it then waits for a fresh status and a plan made from one.

The stamp is the latest status utime, not our wall clock: the status utime IS the
driver's clock, so no clock synchronisation between two PCs is needed, and a command
built on a status that went stale carries that age, so the driver drops it after its
--expire_sec (the reference controllers stamp the same way).

Every piece is a shared core: ImpedanceLaw (also inside the simulation's
ImpedanceController), WatchdogCore (PandaWatchdog), torque_command_message
(TorqueCommandSender). Without the framework a tick costs the law's kinematics and
little else: ~0.1 ms, against ~0.5 ms as a Simulator tick (docs/hardware.md).
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np

from adaptive_c3.systems.franka.panda_watchdog import (StatusSample, WatchdogConfig,
                                                       WatchdogCore)
from adaptive_c3.systems.franka.safety_monitor import SafetyMonitor
from adaptive_c3.tools.hardware.lcm_channels import (BALL_CHANNEL, PLAN_CHANNEL,
                                                     STATUS_CHANNEL, decode_ball_estimate)
from adaptive_c3.tools.hardware.plan_hold import PlanHold
from adaptive_c3.tools.hardware.torque_command_sender import torque_command_message

NQ = 7
PLAN_HOLD_S = 0.1       # s: a plan older than this is held at rest (PlanHold)


def usable_status(msg) -> bool:
    """A status with 7 joints and finite q, v (anything else is malformed)."""
    try:
        if msg.num_joints != NQ or msg.utime <= 0:
            return False
        x = np.asarray([*msg.joint_position, *msg.joint_velocity], float)
    except (TypeError, ValueError, AttributeError):
        return False
    return x.shape == (2 * NQ,) and math.isfinite(x @ x)


class ImpedanceTick:
    def __init__(self, s, *, stale_s: float = 0.05, rate_limit: float = 1000.0,
                 plan_hold_s: float = PLAN_HOLD_S, say=None):
        from drake import lcmt_panda_status

        from adaptive_c3.diagrams.ball_rolling import make_impedance_law
        self.law = make_impedance_law(s)
        # one status gap limit: the scenario's, or --stale-ms where that is tighter (the
        # safety layer checks it before the watchdog, which keeps its torque limits)
        lim = dataclasses.replace(s.safety, status_gap_s=min(stale_s, s.safety.status_gap_s))
        stale_s = lim.status_gap_s
        self.plan = PlanHold(min(plan_hold_s, lim.plan_max_age_s), lim.plan_max_age_s)
        self._ready_us = 1e6 * min(plan_hold_s, lim.plan_max_age_s)
        self.watchdog = WatchdogCore(WatchdogConfig(stale_s=stale_s, rate_limit=rate_limit))
        self.watchdog_state = self.watchdog.new_state()
        self.safety = SafetyMonitor(lim, **({} if say is None else {"say": say}))
        self._modes = (lcmt_panda_status.kMove, lcmt_panda_status.kIdle)
        self.status = None                  # the newest usable PANDA_STATUS
        self._new = self._plans_seen = 0    # statuses since the last tick; plans taken
        self._gap_us = 0.0                  # largest utime step among them
        self._ball = False

    # ------------------------------------------------------------ arrivals
    def receive_status(self, msg) -> None:
        ok = msg is not None and usable_status(msg)
        self.safety.message(STATUS_CHANNEL, ok)
        if not ok or (self.status is not None and msg.utime <= self.status.utime):
            return                          # bad, a repeat or out of order: not used
        if self.status is not None:
            self._gap_us = max(self._gap_us, float(msg.utime - self.status.utime))
        self.status = msg
        self._new += 1

    def receive_plan(self, msg) -> None:
        taken = None if msg is None else self.plan.take(msg)
        if msg is not None and taken is None:
            return                          # a repeat of the held plan
        self.safety.message(PLAN_CHANNEL, bool(taken))

    def receive_ball(self, msg) -> None:
        ok = msg is not None and bool(np.isfinite(decode_ball_estimate(msg)).all())
        self.safety.message(BALL_CHANNEL, ok)
        self._ball |= ok

    @property
    def finished(self) -> bool:
        """True once the stop is over: nothing will be sent again."""
        return self.safety.mode == "stopped"

    def request_stop(self, t: float, reason: str) -> None:
        """An orderly end (run over, SIGINT/SIGTERM): the same damping, no breach."""
        self.safety.stop(t, reason, "requested", breach=False)

    # ------------------------------------------------------------ the tick
    def step(self, t: float, status=None):
        """The command for the newest status at the loop's time t (s), or None (nothing
        to send). `status`: a message that arrived just now (as receive_status)."""
        if status is not None:
            self.receive_status(status)
        mon, st = self.safety, self.status
        new, gap, ball = self._new, self._gap_us, self._ball
        plans, self._plans_seen = self.plan.used - self._plans_seen, self.plan.used
        self._new, self._gap_us, self._ball = 0, 0.0, False
        mon.tick(t)
        mon.statuses(t, new, gap)           # (all three: only counted while active)
        mon.plans(plans)
        if ball:
            mon.ball(t)
        if (mon.mode == "waiting" and st is not None
                and self.plan.age_us(st.utime) <= self._ready_us):
            mon.start(t)                    # a status and a plan made from a recent one
        age_s = math.inf if st is None else 1e-6 * self.plan.age_us(st.utime)
        mon.check_timing(t, age_s)
        if mon.mode == "active":
            cmd = self._control(t, st)
            if cmd is not None:
                return cmd
        tau = mon.stop_torque(t, st.joint_velocity) if (new and st is not None) else None
        if tau is None:
            mon.stop_torque(t, None)        # (ends the ramp on time without a status)
            return None
        return torque_command_message(tau, st.utime)

    def _control(self, t, st):
        x = np.array([*st.joint_position, *st.joint_velocity])
        desired, feedforward, _ = self.plan.target(st.utime)
        arm = self.law.arm
        if st.robot_mode in self._modes:
            tau = self.law.torque(x, desired, feedforward)     # (leaves arm at x)
            tip = (*arm.tip_pose()[0], *(arm.tip_jacobian()[3:] @ x[NQ:]))
        else:
            tau = np.zeros(NQ)
            tip = self.law.tip_state(x)
        mon = self.safety
        mon.check_state(t, st.joint_position, tip)
        if mon.mode != "active":
            return None
        tau = self.watchdog.step(self.watchdog_state, t, StatusSample.from_lcm(st), tau)
        if self.watchdog_state.mode != "ok":
            mon.stop(t, "watchdog", self.watchdog_state.first_fault or self.watchdog_state.mode)
            return None
        mon.check_torque(t, tau, self.watchdog.config.torque_limits)
        if mon.mode != "active":
            return None
        return torque_command_message(tau, st.utime)

    def report(self) -> dict:
        return {"watchdog": self.watchdog_state.report(), **self.plan.counts(),
                "safety": self.safety.report()}
