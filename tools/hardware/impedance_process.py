"""`adaptive-c3 impedance SCENARIO --lcm-url URL`: the 1 kHz loop alone, as the reference
system runs it beside the Franka driver.

  PANDA_STATUS + EE_PLAN (the planner process) + BALL_ESTIMATE (its age only)
      -> ImpedanceTick (law, safety layer, watchdog) -> PANDA_COMMAND

One tick per PANDA_STATUS, answered at once from that status (libfranka's callback;
dairlib's LcmDrivenLoop), with no pacing clock of ours between them. Without a status
the loop still ticks every tick_s of wall clock, so the safety layer sees the silence.
Nothing here waits for C3 or the learner: they run in the planner process. No Drake
diagram either: a Simulator tick of the same law cost ~0.5 ms of CPU, half of it
framework, which two cores shared with the driver and the planner could not always give
within 1 ms (docs/hardware.md).

A message that does not decode, or does not fit its layout, is counted and never used
(a run of them is a safe stop). The run ends on a safe stop (exit code 3, the summary's
safety.state = "safe_stop" and safety.breach naming it), at the end of --duration, or
on SIGINT / SIGTERM; the two orderly ends damp the arm the same way before going quiet,
and every end returns the summary.
"""
from __future__ import annotations

import signal
import threading
import time

import numpy as np

from adaptive_c3.tools.hardware.impedance_tick import ImpedanceTick
from adaptive_c3.tools.hardware.lcm_channels import (BALL_CHANNEL, COMMAND_CHANNEL,
                                                     PLAN_CHANNEL, STATUS_CHANNEL)


class ImpedanceProcess:
    def __init__(self, s, lcm, **tick_settings):
        from drake import lcmt_panda_status, lcmt_robot_state
        self.tick = ImpedanceTick(s, **tick_settings)
        self.lcm = lcm
        self._fresh = 0
        self.ticks = self.status_ticks = self.commands = self.undecodable = 0
        self._signal = None
        status_t, state_t = lcmt_panda_status, lcmt_robot_state
        lcm.Subscribe(STATUS_CHANNEL, lambda d: self._on_status(self._decode(status_t, d)))
        lcm.Subscribe(PLAN_CHANNEL, lambda d: self.tick.receive_plan(self._decode(state_t, d)))
        lcm.Subscribe(BALL_CHANNEL, lambda d: self.tick.receive_ball(self._decode(state_t, d)))

    @property
    def status(self):
        """The newest usable PANDA_STATUS (None before the first)."""
        return self.tick.status

    def _decode(self, kind, data):
        try:
            return kind.decode(data)
        except Exception:           # wrong fingerprint, truncated: not ours to trust
            self.undecodable += 1
            return None

    def _on_status(self, msg):
        before = self.tick.status
        self.tick.receive_status(msg)
        self._fresh += self.tick.status is not before

    def step(self, t: float) -> None:
        """One tick at the loop's time t (s): the command for the newest status, sent."""
        cmd = self.tick.step(t)
        self.ticks += 1
        self.status_ticks += self._fresh > 0
        self._fresh = 0
        if cmd is not None:
            self.commands += 1
            self.lcm.Publish(COMMAND_CHANNEL, cmd.encode())

    def _on_signal(self, signum, _frame):
        if self._signal is not None:             # a second one: stop at once
            raise KeyboardInterrupt
        self._signal = signal.Signals(signum).name

    def run(self, duration, *, tick_s: float = 1e-3, wait_s: float = 10.0,
            clock=time.monotonic, handle=None) -> dict:
        """Wait for the first status (FirstMessagesTimeout after wait_s), then tick per
        status or per tick_s of `clock` without one, until a safe stop, `duration` s
        (None: no limit) or SIGINT / SIGTERM (main thread only; a second one ends at
        once). handle() (default lcm.HandleSubscriptions(1): returns on a message or
        after 1 ms) is injectable for tests. Returns the run's report."""
        from adaptive_c3.tools.hardware.first_messages import wait_for_channels
        from adaptive_c3.tools.process_tuning import freeze_heap
        handle = handle or (lambda: self.lcm.HandleSubscriptions(1))
        freeze_heap()      # (before the wait: a collection after it dropped statuses)
        wait_for_channels(self.lcm, [STATUS_CHANNEL], pump=handle, timeout_s=wait_s,
                          clock=clock)
        start = last = clock()
        start_epoch_s = time.time()     # the wall clock at loop time 0 (as the others report)
        self.tick.safety.end_t = duration
        k = 0
        stamps = np.empty(int(duration / tick_s * 1.5) + 10 if duration else 1_000_000)
        saved = self._catch_signals()
        try:
            while not self.tick.finished:
                handle()
                now = clock()
                if not self._fresh and now - last < tick_s:
                    continue
                last = now
                if k < stamps.size:
                    stamps[k] = now
                k += 1
                if self._signal or (duration is not None and now - start >= duration):
                    self.tick.request_stop(now - start, self._signal or "end of the run")
                self.step(now - start)
        except KeyboardInterrupt:
            pass
        finally:
            for sig, handler in saved.items():     # (None: one not set from Python)
                signal.signal(sig, signal.SIG_DFL if handler is None else handler)
        periods = 1e3 * np.diff(stamps[:min(k, stamps.size)])
        tick_ms = ({"p50": float(np.median(periods)), "p99": float(np.percentile(periods, 99)),
                    "max": float(periods.max())} if periods.size else {})
        return {"wall_s": clock() - start, "start_epoch_s": start_epoch_s, "ticks": self.ticks,
                "status_ticks": self.status_ticks, "commands": self.commands,
                "tick_period_ms": tick_ms, "undecodable_messages": self.undecodable,
                "signal": self._signal, **self.tick.report()}

    def _catch_signals(self) -> dict:
        """SIGINT and SIGTERM -> an orderly stop (the summary is written either way)."""
        if threading.current_thread() is not threading.main_thread():
            return {}
        return {sig: signal.signal(sig, self._on_signal)
                for sig in (signal.SIGINT, signal.SIGTERM)}
