"""`bench bridge --overload N`, and whether a `bench bridge` run was valid.

Overload: the three processes (bridge.py) without real-time priority (the driver and the
impedance loop under the ordinary scheduler, the planner at nice 0) and N busy processes
beside them (pure-Python spin loops, `Spinners`) - what a user gets on a shared machine
without the hardware checklist. Rows, each with a `value`:
  bridge/overload/unsafe_s   seconds (of the simulated driver's time) in which the driver
                             saw the arm unsafe - a torque at its limit for over 50 ms, a
                             joint within 2 deg of its limit, the ball off the table
                             (systems/franka/arm_unsafe_tally.py) - under the controller's
                             commands and before the impedance loop's safe stop began
  bridge/overload/outcome    "safe_stop" (with the breach the impedance loop named) or
                             "rolled" (the run reached its end; circle_turns says how far)
and the ordinary bridge rows under bridge/overload/ (marked invalid: no real-time
priority).

Validity (every bridge run): the run's timing assumptions are that PANDA_STATUS arrives at
>= 900 Hz (the safety layer's status_warn_rate_hz), that the driver and the impedance loop
run under SCHED_FIFO, and that EE_PLAN arrives at >= the safety layer's plan_warn_rate_hz
(180 Hz; the planner sends one every 5 ms) - on the wire over the whole run, and in every
200 ms window of the impedance loop's own view (no rate warnings; no plan older than the
plan hold) - and that the status -> command and planner latency p99 are within what the
controller was shown to tolerate (STATUS_TO_COMMAND_P99_MAX_MS, PLANNER_LATENCY_P99_MAX_MS). A run that misses any is marked `valid: false`
with the reasons, in its rows and on stdout.
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys

SPIN = "while True:\n    pass\n"


def ordinary_scheduling() -> None:
    """(A Popen preexec_fn.) The child under SCHED_OTHER, not the SCHED_FIFO the bench's
    listener runs at: a child inherits its parent's policy, so the planner and
    `--rt-priority 0` processes would otherwise run at SCHED_FIFO 90, and a busy
    spinner there would take a core from everything else."""
    if hasattr(os, "sched_setscheduler"):
        os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))


def _spinner_setup() -> None:
    ordinary_scheduling()
    try:                               # die with the bench, whatever ends it (Linux)
        import ctypes
        ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGKILL)   # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass


class Spinners:
    """`count` busy pure-Python processes (ordinary scheduling) until stop()."""

    def __init__(self, count: int):
        self.count = int(count)
        self._procs = [subprocess.Popen([sys.executable, "-c", SPIN], preexec_fn=_spinner_setup)
                       for _ in range(self.count)]

    def stop(self) -> None:
        for p in self._procs:
            if p.poll() is None:
                p.kill()
            p.wait()
        self._procs = []


# p99 of EE_PLAN's age on arrival (status utime -> plan received) that the controller
# tolerates. Lock-step, 30 s, every plan held back d ms (planner --delay-ms): circle turns
# 1.22 / 1.06 / 0.91 at d = 0 / 50 / 75 ms (3.7 / 3.2 / 2.7 per 90 s; the wrist's
# longest saturation 13 ms at 75), and at 100 ms the impedance loop never starts (no
# plan within its 100 ms plan hold). 50 ms keeps the >= 3 turns per 90 s
PLANNER_LATENCY_P99_MAX_MS = 50.0
# p99 of a command's age on arrival (status utime -> PANDA_COMMAND on the wire) that the
# 1 kHz loop tolerates. The wrist's rotational impedance (900 N m/rad, 20 N m s/rad on
# ~0.21 kg m2 with the motors' reflected inertia) behind the driver's 30 Hz torque filter
# has little delay margin. Lock-step, 6 s, the loop answering each status d ms late
# (`python -m adaptive_c3.tools.studies.latency_table --loop-delays-ms 0,2,3,4,5,10
# --duration 6`): joint 7's longest saturation 1, 3, 9, 30 ms at d = 0, 2, 3, 4 ms; a
# safe stop (joint 7 at 12 N m for 50 ms; the wrist in a growing 7-10 Hz swing) at 1.24 s for
# 5 ms and 0.59 s for 10 ms. Wall-clock runs agree: p99 3.4 ms rolled for 20 s; 5.8,
# 6.1 and 14.4 ms saturated the wrist at 7.6, 4.9 and 1.5 s
STATUS_TO_COMMAND_P99_MAX_MS = 3.0


def validity(r: dict, safety) -> list:
    """The reasons the run `r` (run_three_processes) is not valid (empty: valid).
    safety: the scenario's SafetyLimits (the rates). Checked: the whole run's status and
    plan rates on the wire; the driver and the impedance loop under SCHED_FIFO; what the
    impedance loop itself saw (its summary's `safety`: a timing breach; in its 200 ms
    windows the lowest status and plan rate and its rate warnings; the oldest plan it
    held - beyond the plan hold the arm is held at rest, not driven by the plan); the
    status -> command and the planner latency p99."""
    from adaptive_c3.tools.hardware.impedance_tick import PLAN_HOLD_S
    reasons = []
    if r["status_rate_hz"] < safety.status_warn_rate_hz:
        reasons.append(f"PANDA_STATUS at {r['status_rate_hz']:.0f} Hz < "
                       f"{safety.status_warn_rate_hz:.0f} Hz")
    for name in ("sim-driver", "impedance"):
        sched = str(r["processes"].get(name, {}).get("scheduling", "unknown"))
        if not sched.startswith("SCHED_FIFO"):
            reasons.append(f"{name} without real-time priority ({sched})")
    if r["plan_rate_hz"] < safety.plan_warn_rate_hz:
        reasons.append(f"EE_PLAN at {r['plan_rate_hz']:.0f} Hz < "
                       f"{safety.plan_warn_rate_hz:.0f} Hz")
    reasons += _loop_view(r["processes"].get("impedance", {}).get("safety"), safety,
                          1e3 * min(PLAN_HOLD_S, safety.plan_max_age_s))
    p99 = (r.get("status_to_command_ms") or {}).get("p99")
    if p99 is None or not p99 <= STATUS_TO_COMMAND_P99_MAX_MS:
        reasons.append(f"status -> command p99 {_ms(p99, 1)} > "
                       f"{STATUS_TO_COMMAND_P99_MAX_MS:g} ms (the wrist's delay margin)")
    p99 = (r.get("planner_latency_ms") or {}).get("p99")
    if p99 is None or not p99 <= PLANNER_LATENCY_P99_MAX_MS:
        reasons.append(f"planner latency p99 {_ms(p99)} > {PLANNER_LATENCY_P99_MAX_MS:.0f} ms")
    return reasons


def _ms(x, digits: int = 0) -> str:
    return "unknown" if x is None else f"{x:.{digits}f} ms"


# the safety layer's breaches that are the machine's timing, not the arm's state
TIMING_BREACHES = ("status_stale", "loop_stall", "status_gap", "status_rate", "plan_stale",
                   "ball_stale")


def _loop_view(ls, safety, hold_ms: float) -> list:
    """Reasons from the impedance loop's own summary `safety` block (None: it wrote none)."""
    if not ls:
        return ["the impedance loop wrote no safety summary"]
    out = []
    if ls.get("breach") in TIMING_BREACHES:
        out.append(f"impedance loop safe-stopped on timing: {ls['breach']}: "
                   f"{ls.get('breach_detail')}")
    warns = ls.get("warnings") or {}
    for key, kind, floor, what in (
            ("min_status_rate_hz", "status_rate", safety.status_warn_rate_hz, "PANDA_STATUS"),
            ("min_plan_rate_hz", "plan_rate", safety.plan_warn_rate_hz, "EE_PLAN")):
        hz, n = ls.get(key), int(warns.get(kind, 0))
        if (hz is not None and hz < floor) or n:
            low = "" if hz is None else f" down to {hz:.0f} Hz"
            out.append(f"impedance loop: {what}{low} in a 200 ms window (< {floor:.0f} Hz; "
                       f"{n} {kind} warnings)")
    age = ls.get("max_plan_age_ms")
    if age is not None and age > hold_ms:
        out.append(f"impedance loop: a plan {age:.0f} ms old (planner stalled; beyond "
                   f"{hold_ms:.0f} ms the target is held at rest)")
    return out


def safe_stop(r: dict):
    """(breach text, its wall-clock time) of the impedance loop's safe stop, or None.
    The time is the loop's start_epoch_s + breach_t_s; without start_epoch_s, when the
    loop's summary was read minus the loop's own time from the breach to its end (late
    by the summary's way to this process, so the unsafe time before it errs high)."""
    imp = r["processes"].get("impedance", {})
    safety = imp.get("safety") or {}
    if safety.get("state") != "safe_stop":
        return None
    at = None
    read = r.get("read_at", {}).get("impedance")
    if safety.get("breach_t_s") is not None and imp.get("start_epoch_s") is not None:
        at = float(imp["start_epoch_s"]) + float(safety["breach_t_s"])
    elif read is not None and imp.get("wall_s") is not None and safety.get("breach_t_s") is not None:
        at = read - (float(imp["wall_s"]) - float(safety["breach_t_s"]))
    text = f"{safety.get('breach')}: {safety.get('breach_detail', '')}".strip(": ")
    return text, at


def overload_rows(r: dict, base_rows: list) -> list:
    """The overload rows from run `r`, then `base_rows` (bridge.py's) renamed under
    bridge/overload/."""
    from adaptive_c3.tools.hardware.sim_driver import unsafe_before
    drv = r["processes"].get("sim-driver", {})
    stop = safe_stop(r)
    episodes = drv.get("unsafe_episodes")
    unsafe = (unsafe_before(episodes, stop[1] if stop else None)
              if episodes is not None else float("nan"))
    per = r["command_period_ms"]
    common = {"overload": r["overload"], "realtime": r["realtime"],
              "duration_s": r["duration_s"], "valid": r.get("valid", False),
              "invalid_reasons": r.get("invalid_reasons", [])}
    if stop:
        outcome, reason = "safe_stop", stop[0]
    elif "error" in drv or "unsafe_s" not in drv:
        outcome, reason = "no_result", "the driver wrote no summary"
    else:
        outcome, reason = "rolled", f"ran to the end: {r['circle_turns']:.2f} circle turns"
    rows = [
        {"name": "bridge/overload/unsafe_s", "median_ms": per["p50"], "value": unsafe,
         "driver_unsafe_s": drv.get("unsafe_s"), "driver_unsafe_total_s": drv.get("unsafe_total_s"),
         "unsafe_by_reason_s": drv.get("unsafe_by_reason_s"), **common},
        {"name": "bridge/overload/outcome", "median_ms": per["p50"], "value": outcome,
         "reason": reason, "circle_turns": r["circle_turns"],
         "exit_codes": r.get("exit_codes"), **common},
    ]
    for row in base_rows:
        rows.append({**row, "name": row["name"].replace("bridge/", "bridge/overload/", 1)})
    return rows
