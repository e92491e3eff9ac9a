"""`adaptive-c3 impedance SCENARIO --lcm-url URL`: the 1 kHz loop alone, as the reference
system runs it beside the Franka driver.

  PANDA_STATUS + EE_PLAN (the planner process) -> ImpedanceTick -> PANDA_COMMAND

One tick per PANDA_STATUS, answered at once from that status (libfranka's callback;
dairlib's LcmDrivenLoop), with no pacing clock of ours between them. Without a status
the loop still ticks every tick_s of wall clock, so the watchdog sees the silence and
zeroes the torque after its stale limit. Nothing here waits for C3 or the learner: they
run in the planner process. No Drake diagram either: a Simulator tick of the same law
cost ~0.5 ms of CPU, half of it framework, which two cores shared with the driver and
the planner could not always give within 1 ms (README, Hardware over LCM).

A message that does not decode is counted and dropped (a status: the watchdog then sees
no new status and stops on the stale limit).
"""
from __future__ import annotations

import time

import numpy as np

from adaptive_c3.tools.hardware.impedance_tick import ImpedanceTick
from adaptive_c3.tools.hardware.lcm_channels import COMMAND_CHANNEL, PLAN_CHANNEL, STATUS_CHANNEL


class ImpedanceProcess:
    def __init__(self, s, lcm, **tick_settings):
        from drake import lcmt_panda_status, lcmt_robot_state
        self.tick = ImpedanceTick(s, **tick_settings)
        self.lcm = lcm
        self.status = None          # the newest PANDA_STATUS
        self._fresh = 0
        self.ticks = self.status_ticks = self.undecodable = 0
        self._status_type, self._plan_type = lcmt_panda_status, lcmt_robot_state
        lcm.Subscribe(STATUS_CHANNEL, self._on_status)
        lcm.Subscribe(PLAN_CHANNEL, self._on_plan)

    def _decode(self, kind, data):
        try:
            return kind.decode(data)
        except Exception:           # wrong fingerprint, truncated: not ours to trust
            self.undecodable += 1
            return None

    def _on_status(self, data):
        msg = self._decode(self._status_type, data)
        if msg is not None:
            self.status, self._fresh = msg, self._fresh + 1

    def _on_plan(self, data):
        msg = self._decode(self._plan_type, data)
        if msg is not None:
            self.tick.plan.take(msg)

    def step(self, t: float) -> None:
        """One tick at the loop's time t (s): the command for the newest status, sent."""
        cmd = self.tick.step(t, self.status)
        self.ticks += 1
        self.status_ticks += self._fresh > 0
        self._fresh = 0
        if cmd is not None:
            self.lcm.Publish(COMMAND_CHANNEL, cmd.encode())

    def run(self, duration, *, tick_s: float = 1e-3, wait_s: float = 10.0,
            clock=time.monotonic, handle=None) -> dict:
        """Wait for the first status (FirstMessagesTimeout after wait_s), then tick per
        status or per tick_s of `clock` without one, for `duration` s (None: until
        Ctrl-C). handle() (default lcm.HandleSubscriptions(1): returns on a message or
        after 1 ms) is injectable for tests. Returns the run's report."""
        from adaptive_c3.tools.hardware.first_messages import wait_for_channels
        from adaptive_c3.tools.process_tuning import freeze_heap
        handle = handle or (lambda: self.lcm.HandleSubscriptions(1))
        wait_for_channels(self.lcm, [STATUS_CHANNEL], pump=handle, timeout_s=wait_s,
                          clock=clock)
        freeze_heap()
        start = last = clock()
        k = 0
        stamps = np.empty(int(duration / tick_s * 1.5) + 10 if duration else 1_000_000)
        try:
            while duration is None or last - start < duration:
                handle()
                now = clock()
                if not self._fresh and now - last < tick_s:
                    continue
                last = now
                if k < stamps.size:
                    stamps[k] = now
                k += 1
                self.step(now - start)
        except KeyboardInterrupt:
            pass
        periods = 1e3 * np.diff(stamps[:min(k, stamps.size)])
        tick_ms = ({"p50": float(np.median(periods)), "p99": float(np.percentile(periods, 99)),
                    "max": float(periods.max())} if periods.size else {})
        return {"wall_s": clock() - start, "ticks": self.ticks,
                "status_ticks": self.status_ticks, "tick_period_ms": tick_ms,
                "undecodable_messages": self.undecodable, **self.tick.report()}
