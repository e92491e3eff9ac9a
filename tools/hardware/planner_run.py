"""PlannerRun: the planner process's run, in segments of planning between waits for the robot.

  waiting   for a message on PANDA_STATUS and on BALL_ESTIMATE (first_messages.py), then
            a fresh start: the diagram from its defaults (the gait from its settle
            phase, C3's warm start, the learner), the newest messages in its context
  planning  in real time, EE_PLAN every plan period, until one of:
    - no PANDA_STATUS with a newer utime for > stale_s (the planner's clock): one line
      on stderr, no more EE_PLAN, and back to `waiting` (a killed or restarted driver:
      the plan would be built on a robot state that is no longer true)
    - malformed_run undecodable messages in a row on PANDA_STATUS or BALL_ESTIMATE: a
      SAFE STOP - one line naming it, no more EE_PLAN, ever; the summary's
      safety.state = "safe_stop" and the process exits with SAFE_STOP_EXIT (3, the
      impedance process's code)
  A message that does not decode is counted (ChannelHealth) and never used.

The checks run in a Simulator monitor after every step (<= 2.5 ms apart: the status
sampling), after a non-blocking LCM poll, so a stale status stops the plans within a
step. `tick(dt)` is one piece of work (a poll while waiting, dt of diagram time while
planning), so a lock-step test can drive it; `run(duration)` is the real-time process.
"""
from __future__ import annotations

import sys
import time

from pydrake.systems.framework import EventStatus

from adaptive_c3.systems.franka.safety_monitor import SAFE_STOP_EXIT   # the impedance's: 3
from adaptive_c3.tools.hardware.first_messages import (FirstMessages,
                                                       initialise_from_messages,
                                                       wait_for_channels)
from adaptive_c3.tools.hardware.lcm_channels import BALL_CHANNEL, STATUS_CHANNEL

__all__ = ["PlannerRun", "SAFE_STOP_EXIT"]


def _stderr(line: str) -> None:
    print(line, file=sys.stderr, flush=True)


class PlannerRun:
    def __init__(self, proc, lcm, *, stale_s: float = 0.1, malformed_run: int = 10,
                 realtime: bool = True, clock=time.monotonic, pump=None, say=_stderr):
        self.proc, self.lcm = proc, lcm
        self.stale_s, self.malformed_run = float(stale_s), int(malformed_run)
        self.realtime, self.clock, self.say = realtime, clock, say
        self.pump = pump or (lambda: lcm.HandleSubscriptions(50))
        self.healths = [proc.status_health, proc.ball.health]
        for h in self.healths:
            h.clock = clock
        self.first = FirstMessages(lcm, [STATUS_CHANNEL, BALL_CHANNEL])
        self.state = "waiting"
        self.sim = None
        self.segments = []            # (start on the clock, diagram s planned, learner steps)
        self.stale_stops = 0
        self.breach = None            # "malformed_input: ..." after a safe stop
        self._fault = None
        self.on_start = None          # called at each segment's start (diagram time 0)

    # ------------------------------------------------------------------ the two states
    def _monitor(self, context):
        self.lcm.HandleSubscriptions(0)
        for h in self.healths:
            if h.bad_run >= self.malformed_run:
                self._fault = ("malformed_input", f"{h.bad_run} undecodable messages in a row "
                               f"on {h.channel}")
                return EventStatus.ReachedTermination(None, self._fault[1])
        stale = self.proc.status_health.stale_s()
        if stale > self.stale_s:
            self._fault = ("status_stale", f"no new {STATUS_CHANNEL} for {1e3 * stale:.0f} ms "
                           f"(limit {1e3 * self.stale_s:.0f} ms)")
            return EventStatus.ReachedTermination(None, self._fault[1])
        return EventStatus.Succeeded()

    def _start(self) -> None:
        from pydrake.systems.analysis import Simulator
        self.sim = sim = Simulator(self.proc.diagram)
        if self.realtime:
            sim.set_target_realtime_rate(1.0)
        initialise_from_messages(sim)
        sim.set_monitor(self._monitor)
        self._seg_start = self.clock()
        self.state = "planning"
        if self.segments:
            self.say(f"planner: {STATUS_CHANNEL} and {BALL_CHANNEL} back: planning again "
                     "from a fresh start")
        if self.on_start:
            self.on_start()

    def _segment(self):
        ctx = self.sim.get_context()
        return self._seg_start, float(ctx.get_time()), self.proc.learner_steps(ctx)

    def _end_segment(self) -> None:
        self.segments.append(self._segment())

    def all_segments(self) -> list:
        """(start on the clock, diagram s planned, learner steps) of every planning
        segment, the one under way included."""
        return self.segments + ([self._segment()] if self.state == "planning" else [])

    def tick(self, dt: float) -> str:
        """One piece of work: waiting, one poll (and the start once both channels spoke);
        planning, advance dt of diagram time (less if a check stops it). Returns the
        state after it: "waiting", "planning" or "safe_stop"."""
        if self.state == "waiting":
            self.pump()
            if self.first.ready():
                self._start()
        elif self.state == "planning":
            self.sim.AdvanceTo(self.sim.get_context().get_time() + dt)
            if self._fault is not None:
                self._end_segment()
                name, detail = self._fault
                self._fault = None
                if name == "status_stale":
                    self.stale_stops += 1
                    self.say(f"planner: {detail}: stopped planning (no EE_PLAN); waiting for "
                             f"{STATUS_CHANNEL} and {BALL_CHANNEL} again")
                    self.first.reset()
                    self.proc.status_health.restart()
                    self.state = "waiting"
                else:
                    self.breach = f"{name}: {detail}"
                    self.say(f"planner: SAFE STOP ({self.breach}): no more EE_PLAN")
                    self.state = "safe_stop"
        return self.state

    # ------------------------------------------------------------------ the process
    def run(self, duration, *, wait_s: float = 10.0) -> None:
        """The real-time process: the first wait (FirstMessagesTimeout after wait_s), then
        planning and waiting until `duration` s of the clock from the first start (None:
        until Ctrl-C / SIGTERM) or a safe stop."""
        wait_for_channels(self.lcm, self.first.channels, pump=self.pump, timeout_s=wait_s,
                          clock=self.clock, first=self.first)
        self._start()
        start = self.clock()
        try:
            while self.state != "safe_stop":
                left = None if duration is None else duration - (self.clock() - start)
                if left is not None and left <= 0:
                    break
                self.tick(0.1 if left is None else min(0.1, left))
        except KeyboardInterrupt:
            pass

    def summary(self) -> dict:
        """The planner's report over all segments, with what it received and why it
        stopped."""
        ctx = self.sim.get_context() if self.sim is not None else self.proc.diagram.CreateDefaultContext()
        segments = self.all_segments()
        first = segments[0][0] if segments else 0.0
        starts = [round(seg0 - first, 6) + t for seg0, dur, _ in segments
                  for t in self.proc.roll_starts(dur)]
        out = self.proc.summary(ctx, planned_s=sum(d for _, d, _ in segments),
                                learner_steps=sum(n for _, _, n in segments),
                                roll_starts=starts)
        out.update(planning_segments=len(segments), planned_s=sum(d for _, d, _ in segments),
                   stale_stops=self.stale_stops,
                   undecodable_messages={h.channel: h.undecodable for h in self.healths},
                   messages_received={h.channel: h.received for h in self.healths},
                   safety={"state": "safe_stop" if self.breach else "ok",
                           "breach": self.breach, "exit_code": self.exit_code()})
        return out

    def exit_code(self) -> int:
        return SAFE_STOP_EXIT if self.breach else 0
