"""SafetyMonitor: the 1 kHz impedance loop's safety layer (pure numpy, no Drake).

Limits come from the scenario's `safety:` block (scenarios/ball_rolling_schema.py,
SafetyLimits). The loop (tools/hardware/impedance_tick.py) tells it what arrived and
what it is about to command; the monitor decides whether the run may go on.

Modes: waiting (nothing commanded yet) -> active (commanding) -> stopping (damping
commands for stop_ramp_s) -> stopped (no more commands, ever; the driver then holds the
arm with its own damping once our last command expires).

A BREACH (-> stopping; one line on stderr naming it and its numbers; `report()["state"]`
= "safe_stop", the process exits with SAFE_STOP_EXIT):
  status_stale       no new PANDA_STATUS for > status_gap_s (loop clock)
  loop_stall         the loop itself did not tick for > status_gap_s (starved)
  status_gap         two successive statuses > status_gap_s apart (their utime)
  status_rate        PANDA_STATUS < status_min_rate_hz in two rate_window_s windows
                     running (one alone is a warning: a simulated driver starting up
                     gave 378 Hz over its first 200 ms)
  plan_stale         the plan's utime > plan_max_age_s behind the newest status's
  ball_stale         no usable BALL_ESTIMATE for > ball_max_age_s (once one came)
  torque_saturation  a joint's commanded torque (after the watchdog's limits) at its
                     limit for > saturation_s (each joint's own run, as the driver-side
                     tally counts it)
  joint_limit        a joint within joint_margin_deg of the Panda's limit
  ee_speed           EE tip speed > ee_speed_max (m/s)
  workspace          EE tip outside [workspace_min, workspace_max] (m, base frame)
  malformed_input    malformed_run bad messages in a row on one channel, or at least
                     that many and at least half of a channel's over a rate window
  watchdog           the torque watchdog refused the command (e.g. non-finite request)
A requested stop (end of the run, SIGINT/SIGTERM) damps the same way; its state is
"stopped". So does a status stream that ends within END_GRACE_S of end_t (the run's
planned end; stop reason "driver_ended"): a simulated driver given the same --duration
stops publishing about then. WARNINGS (one line per kind every warn_interval_s at most, all counted):
status_rate (< status_warn_rate_hz), plan_rate (< plan_warn_rate_hz).
The stop's torque is -kd v, kd = stop_damping_scale x the driver's DRIVER_KD, clipped to
the torque limits; a fresh zero torque would leave a torque-mode Panda undamped.
"""
from __future__ import annotations

import math
import sys

import numpy as np

from adaptive_c3.models.panda_kinematics import Q_MAX, Q_MIN, TAU_MAX
from adaptive_c3.systems.franka.franka_driver_rules import DAMPING

DRIVER_KD = DAMPING            # N m s/rad: the driver's own joint damping
SAFE_STOP_EXIT = 3      # exit code of a process that ended in a safe stop
END_GRACE_S = 1.0       # statuses that stop this close to end_t: the driver's run ended


def _stderr(line: str) -> None:
    print(line, file=sys.stderr, flush=True)


class SafetyMonitor:
    def __init__(self, limits, *, say=_stderr, name: str = "impedance"):
        self.lim = limits
        self._say, self._name = say, name
        self._kd = limits.stop_damping_scale * DRIVER_KD
        self._margin = math.radians(limits.joint_margin_deg)
        self._box = ([float(a) for a in limits.workspace_min],
                     [float(a) for a in limits.workspace_max])
        self._q = (Q_MIN.tolist(), Q_MAX.tolist())
        self.mode = "waiting"
        self.breach = None                 # (name, detail, t) of the first breach
        self.stop_reason, self.stop_t = None, None
        self.damping_commands = 0
        self.malformed = {}                # channel -> count
        self._run = {}                     # channel -> bad messages in a row
        self._window = {}                  # channel -> [good, bad] in the rate window
        self._pending = None               # a breach found between ticks (name, detail)
        self.warnings = {"status_rate": 0, "plan_rate": 0}
        self._warned_t = {}
        self._sat_since = [None] * len(TAU_MAX)   # loop time each joint reached its limit
        self._tick_t = None
        self._slow = None                  # the last window's status rate if below the limit
        self.end_t = None                  # loop time the run is to end (None: open)
        self.extremes = {"min_status_rate_hz": None, "min_plan_rate_hz": None,
                         "max_status_gap_ms": 0.0, "max_plan_age_ms": 0.0,
                         "max_saturation_ms": 0.0, "min_joint_margin_deg": None,
                         "max_ee_speed_m_s": 0.0}

    # ------------------------------------------------------------ what arrived
    def message(self, channel: str, ok: bool) -> None:
        """One message on `channel`: ok = it decoded and fits its layout (a bad one is
        counted and never used; malformed_run of them in a row is a breach)."""
        tally = self._window.setdefault(channel, [0, 0])     # [good, bad] this window
        tally[not ok] += 1
        if ok:
            self._run[channel] = 0
            return
        self.malformed[channel] = self.malformed.get(channel, 0) + 1
        run = self._run[channel] = self._run.get(channel, 0) + 1
        if run >= self.lim.malformed_run and self._pending is None:
            self._pending = ("malformed_input",
                             f"{run} malformed {channel} messages in a row "
                             f"(limit {self.lim.malformed_run})")

    def start(self, t: float) -> None:
        """waiting -> active at loop time t (s): the clocks and rate windows start."""
        self.mode = "active"
        self._status_t = self._ball_t = self._win_t0 = t
        self._ball_seen = False
        self._n_status = self._n_plan = 0

    def tick(self, t: float) -> None:
        """Every tick first: a loop that did not run for > status_gap_s (the process
        was starved) is a breach, whatever arrived meanwhile."""
        last, self._tick_t = self._tick_t, t
        if self.mode == "active" and last is not None and t - last > self.lim.status_gap_s:
            self.stop(t, "loop_stall", f"the loop did not run for {1e3 * (t - last):.1f} ms "
                      f"(limit {1e3 * self.lim.status_gap_s:.0f} ms)")

    def statuses(self, t: float, count: int, max_gap_us: float) -> None:
        """`count` new statuses since the last tick, at most max_gap_us apart (utime)."""
        if self.mode != "active" or count == 0:
            return
        self._status_t = t
        self._n_status += count
        gap_ms = 1e-3 * max_gap_us
        self._peak("max_status_gap_ms", gap_ms)
        if gap_ms > 1e3 * self.lim.status_gap_s:
            self.stop(t, "status_gap", f"two PANDA_STATUS {gap_ms:.1f} ms apart in the "
                      f"driver's clock (limit {1e3 * self.lim.status_gap_s:.0f} ms)")

    def plans(self, count: int) -> None:
        if self.mode == "active":
            self._n_plan += count

    def ball(self, t: float) -> None:
        if self.mode == "active":
            self._ball_t, self._ball_seen = t, True

    # ------------------------------------------------------------ checks
    def check_timing(self, t: float, plan_age_s: float) -> None:
        """Status silence, rates, plan and ball age, pending breaches, at loop time t."""
        lim = self.lim
        if self._pending is not None:
            self.stop(t, *self._pending)
        if self.mode != "active":
            return
        silent = t - self._status_t
        if silent > lim.status_gap_s:
            ending = self.end_t is not None and t >= self.end_t - END_GRACE_S
            return self.stop(t, "driver_ended" if ending else "status_stale",
                             f"no PANDA_STATUS for {1e3 * silent:.1f} ms (limit "
                             f"{1e3 * lim.status_gap_s:.0f} ms)", breach=not ending)
        self._peak("max_plan_age_ms", 1e3 * plan_age_s)
        if plan_age_s > lim.plan_max_age_s:
            return self.stop(t, "plan_stale", f"EE_PLAN {1e3 * plan_age_s:.0f} ms older than "
                             f"the status (limit {1e3 * lim.plan_max_age_s:.0f} ms)")
        if self._ball_seen and t - self._ball_t > lim.ball_max_age_s:
            return self.stop(t, "ball_stale", f"no usable BALL_ESTIMATE for "
                             f"{1e3 * (t - self._ball_t):.0f} ms (limit "
                             f"{1e3 * lim.ball_max_age_s:.0f} ms)")
        span = t - self._win_t0
        if span >= lim.rate_window_s:
            self._rates(t, self._n_status / span, self._n_plan / span, span)
            self._garbage(t, span)
            self._win_t0, self._n_status, self._n_plan = t, 0, 0
            self._window = {}

    def _garbage(self, t, span):
        for channel, (good, bad) in self._window.items():
            if bad >= self.lim.malformed_run and bad >= good:
                return self.stop(t, "malformed_input", f"{bad} of {good + bad} {channel} "
                                 f"messages malformed over {1e3 * span:.0f} ms")

    def _rates(self, t, status_hz, plan_hz, span):
        lim, ex = self.lim, self.extremes
        for key, hz in (("min_status_rate_hz", status_hz), ("min_plan_rate_hz", plan_hz)):
            ex[key] = hz if ex[key] is None else min(ex[key], hz)
        over = f"over {1e3 * span:.0f} ms"
        slow, self._slow = self._slow, (status_hz if status_hz < lim.status_min_rate_hz else None)
        if slow is not None and self._slow is not None:
            return self.stop(t, "status_rate", f"PANDA_STATUS at {slow:.0f} Hz, then "
                             f"{status_hz:.0f} Hz {over} (limit {lim.status_min_rate_hz:.0f} Hz "
                             "in two windows running)")
        if status_hz < lim.status_warn_rate_hz:
            self._warn(t, "status_rate", f"PANDA_STATUS at {status_hz:.0f} Hz {over} (below "
                       f"{lim.status_warn_rate_hz:.0f} Hz: commands come late)")
        if plan_hz < lim.plan_warn_rate_hz:
            self._warn(t, "plan_rate", f"EE_PLAN at {plan_hz:.0f} Hz {over} (below "
                       f"{lim.plan_warn_rate_hz:.0f} Hz: the planner runs behind)")

    def check_state(self, t: float, q, tip) -> None:
        """Joint margins (q (7) rad), EE tip speed and box (tip (6): m, m/s, base frame)."""
        if self.mode != "active":
            return
        # scalar Python on 7 values: numpy's per-call cost on arrays this small is most
        # of the work, and this runs every tick
        lim, ex = self.lim, self.extremes
        q = list(q)
        m, j = min((min(a - lo, hi - a), i) for i, (a, lo, hi) in enumerate(zip(q, *self._q)))
        m_deg = math.degrees(m)
        if ex["min_joint_margin_deg"] is None or m_deg < ex["min_joint_margin_deg"]:
            ex["min_joint_margin_deg"] = m_deg
        if m < self._margin:
            return self.stop(t, "joint_limit", f"joint {j + 1} at {q[j]:.4f} rad, {m_deg:.2f} "
                             f"deg from its limit (margin {lim.joint_margin_deg:g} deg)")
        px, py, pz, vx, vy, vz = (float(a) for a in tip)
        speed = math.sqrt(vx * vx + vy * vy + vz * vz)
        self._peak("max_ee_speed_m_s", speed)
        if not speed <= lim.ee_speed_max:
            return self.stop(t, "ee_speed", f"EE tip at {speed:.2f} m/s "
                             f"(limit {lim.ee_speed_max:g} m/s)")
        lo, hi = self._box
        if not all(a <= b <= c for a, b, c in zip(lo, (px, py, pz), hi)):
            return self.stop(t, "workspace", f"EE tip at [{px:.3f}, {py:.3f}, {pz:.3f}] m, "
                             f"outside the box {lo} .. {hi}")

    def check_torque(self, t: float, tau, torque_limits=TAU_MAX) -> None:
        """Saturation of the command about to be sent (tau (7) N m, at most its limits):
        one joint at its limit for longer than saturation_s is a breach."""
        if self.mode != "active":
            return
        lim = self.lim
        since, first = self._sat_since, None
        for i, (a, cap) in enumerate(zip(list(tau), list(torque_limits))):
            if abs(a) < cap * (1 - 1e-9):
                since[i] = None
                continue
            if since[i] is None:
                since[i] = t
            if first is None or since[i] < since[first]:
                first = i
        if first is None:
            return
        held = t - since[first]
        self._peak("max_saturation_ms", 1e3 * held)
        if held > lim.saturation_s:
            self.stop(t, "torque_saturation", f"joint {first + 1} torque at "
                      f"{tau[first]:+.1f} N m (limit {torque_limits[first]:g}) for "
                      f"{1e3 * held:.0f} ms (limit {1e3 * lim.saturation_s:.0f} ms)")

    # ------------------------------------------------------------ the stop
    def stop(self, t: float, name: str, detail: str, *, breach: bool = True) -> None:
        """Begin the stop (a breach, or a requested stop with breach=False)."""
        if self.mode in ("stopping", "stopped"):
            return
        self._pending = None
        if breach:
            self.breach = (name, detail, float(t))
        self.stop_reason, self.stop_t = name, float(t)
        if self.mode == "waiting":           # nothing was commanded: nothing to damp
            self.mode = "stopped"
        else:
            self.mode = "stopping"
        what = "SAFE STOP" if breach else "stop"
        self._say(f"{self._name}: {what} at t={t:.3f} s: {name}: {detail}; "
                  + (f"damping for {1e3 * self.lim.stop_ramp_s:.0f} ms, then no commands"
                     if self.mode == "stopping" else "no commands"))

    def stop_torque(self, t: float, v) -> np.ndarray | None:
        """The damping command (7, N m) for joint velocities v (rad/s) while stopping at
        loop time t; None after the ramp (mode -> stopped), for v None (no new status:
        nothing to send) or a non-finite v."""
        if self.mode != "stopping":
            return None
        if t - self.stop_t >= self.lim.stop_ramp_s:
            self.mode = "stopped"
            return None
        if v is None:
            return None
        v = np.asarray(v, float)
        if not np.isfinite(v).all():
            return None
        self.damping_commands += 1
        return np.clip(-self._kd * v, -TAU_MAX, TAU_MAX)

    # ------------------------------------------------------------ output
    def _peak(self, key, value):
        if value > self.extremes[key]:
            self.extremes[key] = float(value)

    def _warn(self, t, kind, text):
        self.warnings[kind] += 1
        last = self._warned_t.get(kind)
        if last is None or t - last >= self.lim.warn_interval_s:
            self._warned_t[kind] = t
            self._say(f"{self._name}: warning at t={t:.3f} s: {text} "
                      f"({self.warnings[kind]} so far)")

    def report(self) -> dict:
        """state: waiting | active | safe_stop | stopped; the breach (name, numbers, loop
        time s); warnings and malformed counts; the extremes seen while active."""
        state = ("safe_stop" if self.breach else
                 "stopped" if self.mode in ("stopping", "stopped") else self.mode)
        name, detail, t = self.breach or (None, None, None)
        return {"state": state, "breach": name, "breach_detail": detail, "breach_t_s": t,
                "stop_reason": self.stop_reason, "stop_t_s": self.stop_t,
                "damping_commands": self.damping_commands,
                "exit_code": SAFE_STOP_EXIT if self.breach else 0,
                "warnings": dict(self.warnings), "malformed": dict(self.malformed),
                **self.extremes}
