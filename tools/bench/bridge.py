"""`bench bridge`: the hardware run as three OS processes over LCM in wall-clock time.

sim-driver (the true plant with the real driver's rules, real time) + impedance (1 kHz)
+ planner, on udpm on this machine's loopback (`udpm://239.255.76.67:PORT?ttl=0`), the
ball-rolling scenario with the camera off (the scenario's reference gains, 5 mm radius
error, adaptation on). A listener in this process records, in the wall clock, at the
time the kernel received each message (lcm_wire_listener.py: what the driver's socket
sees, not when this Python process got round to reading it):
- every PANDA_COMMAND: its period (row `bridge/command_period_p99_ms`, field `value`,
  with `median_ms` = the p50 and `max_ms`);
- every EE_PLAN: its age on arrival, wall clock minus the status utime it was planned
  from (`bridge/planner_latency_p99_ms`: status -> estimator, LCS, C3 -> plan received);
  and the plan rate;
- every BALL_ESTIMATE: the ball's angle about the target circle's centre, whose unwrapped
  total, counted only while the ball is on the circle's band, gives `bridge/circles_90s`
  (circle turns per 90 s of run).
The driver reports how many commands it expired (`bridge/expired_fraction`). Full: 90 s;
quick: 10 s.
"""
from __future__ import annotations

import json
import os
import struct
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np

SETS = ["camera.enabled=false"]


def run_three_processes(duration: float, scenario: str = "ball_rolling", sets=SETS,
                        port: int | None = None, planner_nice: int = -10,
                        planner_args=(), realtime: bool = True, overload: int = 0,
                        inject_garbage_s: float | None = None) -> dict:
    """The three processes for `duration` s of wall clock (module doc). planner_nice:
    the planner's nice value (-10: ahead of ordinary work on the machine, behind the
    SCHED_FIFO driver and impedance loop); planner_args: extra planner flags (e.g.
    --delay-ms). realtime=False: the driver and the impedance loop under the ordinary
    scheduler (--rt-priority 0) and the planner at nice 0; overload: that many busy
    processes beside them (bridge_overload.Spinners). Messages are timed by the kernel
    (WireListener); the listener runs at SCHED_FIFO 90 when it may all the same, so
    that its socket never overflows. Every output line is kept with the wall-clock
    time it was read (`read_at`: when each process's summary arrived). inject_garbage_s:
    every that many seconds, one undecodable message on each of the four channels (a
    check that all three processes survive it; `not_ours` counts what the listener saw)."""
    from drake import lcmt_robot_state

    from adaptive_c3.scenarios.schema import load_scenario
    from adaptive_c3.tools.bench.lcm_wire_listener import WireListener
    from adaptive_c3.tools.hardware.lcm_channels import PLAN_CHANNEL, decode_ball_estimate
    from adaptive_c3.tools.run_ball_rolling import circle_progress
    from adaptive_c3.tools.user_input import resolve_scenario_path
    s, _ = load_scenario(resolve_scenario_path(scenario), list(sets))
    port = port or 7600 + os.getpid() % 300
    url = f"udpm://239.255.76.67:{port}?ttl=0"
    exe = [sys.executable, "-m", "adaptive_c3.tools.cli"]
    args = [scenario, "--lcm-url", url, "--duration", str(duration)]
    for kv in sets:
        args += ["--set", kv]
    from drake import lcmt_panda_command, lcmt_panda_status
    wire = WireListener(url)
    cmd_t, cmd_age, plan_age, ball, status_t = [], [], [], [], []
    not_ours = {}               # channel -> messages with another type's fingerprint

    def typed(channel, lcm_type, callback):
        # an LCM message is an 8-byte fingerprint, then its fields; all three types here
        # start with int64 utime. Reading just that keeps the listener light
        fingerprint = lcm_type._get_packed_fingerprint()

        def on_message(arrival, d):
            if len(d) < 16 or d[:8] != fingerprint:
                not_ours[channel] = not_ours.get(channel, 0) + 1
                return
            callback(arrival, d, struct.unpack_from(">q", d, 8)[0])
        wire.subscribe(channel, on_message)

    def on_command(arrival, d, utime):
        cmd_t.append(arrival)
        cmd_age.append(arrival - 1e-6 * utime)
    typed("PANDA_COMMAND", lcmt_panda_command, on_command)
    typed("PANDA_STATUS", lcmt_panda_status, lambda arrival, d, _u: status_t.append(arrival))
    typed(PLAN_CHANNEL, lcmt_robot_state,
          lambda arrival, d, utime: plan_age.append(arrival - 1e-6 * utime))

    def on_ball(arrival, d, _utime):
        try:
            b = decode_ball_estimate(lcmt_robot_state.decode(d))
        except Exception:       # the right fingerprint, a broken body
            not_ours["BALL_ESTIMATE"] = not_ours.get("BALL_ESTIMATE", 0) + 1
            return
        if np.all(np.isfinite(b)):
            ball.append(b[:2])
    typed("BALL_ESTIMATE", lcmt_robot_state, on_ball)
    garbage = _GarbageSender(url, inject_garbage_s) if inject_garbage_s else None
    from adaptive_c3.tools.hardware.realtime_priority import request_fifo
    from adaptive_c3.tools.process_tuning import freeze_heap
    from adaptive_c3.tools.bench.bridge_overload import Spinners, ordinary_scheduling
    extra = {"planner": [f"--nice={planner_nice if realtime else 0}", *planner_args]}
    if not realtime:
        extra.update({"sim-driver": ["--rt-priority", "0"], "impedance": ["--rt-priority", "0"]})
    listener_scheduling = request_fifo(90)
    freeze_heap()
    procs, lines, read_at = {}, {}, {}

    def read(name):
        for ln in procs[name].stdout:
            lines[name].append(ln)
            if ln.startswith("{"):
                read_at[name] = time.time()

    def start(name):
        procs[name] = subprocess.Popen(exe + [name, *args, *extra.get(name, [])],
                                       stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                       text=True, preexec_fn=ordinary_scheduling)
        lines[name] = []
        reader = threading.Thread(target=read, args=(name,), daemon=True)
        reader.start()
        return reader
    spinners = Spinners(overload)
    # The controllers start first and wait, built, for the robot's first messages (as
    # they would beside a running robot, but without three processes importing and
    # building at once on two cores: that start-up alone made 50-100 ms gaps)
    readers = [start("planner"), start("impedance")]
    ready_by = time.monotonic() + 120
    while time.monotonic() < ready_by and not all(
            any("waiting for" in ln for ln in lines[n]) or procs[n].poll() is not None
            for n in ("planner", "impedance")):
        time.sleep(0.05)
    readers.append(start("sim-driver"))
    try:
        # the controllers end on the wall clock; the driver, which may run behind real
        # time, is then ended (SIGTERM: it writes its summary) once both have
        deadline = time.monotonic() + duration + 60
        while time.monotonic() < deadline and any(procs[n].poll() is None
                                                  for n in ("planner", "impedance")):
            wire.handle(0.005)
            if garbage:
                garbage.maybe_send()
        quiet = time.monotonic() + 1.0        # the driver's hold after the last command
        while time.monotonic() < quiet and procs["sim-driver"].poll() is None:
            wire.handle(0.005)
    finally:
        wire.close()
        spinners.stop()
        for p in procs.values():
            if p.poll() is None:
                p.terminate()
    for p in procs.values():
        try:
            p.wait(30)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait()
    for r in readers:
        r.join(timeout=5)
    outputs = {n: "".join(ln) for n, ln in lines.items()}
    summaries = {}
    for n, text in outputs.items():
        lines = [ln for ln in text.strip().splitlines() if ln.startswith("{")]
        summaries[n] = json.loads(lines[-1]) if lines else {"error": text.strip()[-500:]}
    periods = np.diff(cmd_t) * 1e3 if len(cmd_t) > 1 else np.array([np.nan])
    status_periods = np.diff(status_t) * 1e3 if len(status_t) > 1 else np.array([np.nan])
    age = np.asarray(plan_age) * 1e3 if plan_age else np.array([np.nan])
    status_to_command = np.asarray(cmd_age) * 1e3 if cmd_age else np.array([np.nan])
    drv = summaries.get("sim-driver", {})
    plan = summaries.get("planner", {})
    received = drv.get("commands_received", 0)
    tgt = s.target
    first = drv.get("first_contact_s")
    pushes = None
    if "start_epoch_s" in drv and "start_epoch_s" in plan:
        # roll starts in the driver's time: the planner's clock began later, once the
        # driver's first status and ball estimate had arrived
        shift = plan["start_epoch_s"] - drv["start_epoch_s"]
        starts = [shift + t for t in plan.get("roll_starts_s", [])]
        pushes = sum(1 for t in starts if first is None or t <= first)
    return dict(duration_s=duration, url=url, commands=len(cmd_t),
                command_period_ms=dict(p50=float(np.median(periods)),
                                       p99=float(np.percentile(periods, 99)),
                                       max=float(np.max(periods))),
                expired_fraction=(drv.get("commands_expired", 0) / received) if received else 1.0,
                status_period_ms=dict(p50=float(np.median(status_periods)),
                                      p99=float(np.percentile(status_periods, 99)),
                                      max=float(np.max(status_periods))),
                statuses=len(status_t),
                status_to_command_ms=dict(p50=float(np.median(status_to_command)),
                                          p99=float(np.percentile(status_to_command, 99))),
                plan_rate_hz=len(plan_age) / duration,
                planner_latency_ms=dict(p50=float(np.median(age)), p99=float(np.percentile(age, 99))),
                impedance_tick_ms=summaries.get("impedance", {}).get("tick_period_ms"),
                c3_solve_ms=plan.get("c3_solve_ms"),
                learner_rate_hz=plan.get("learner_rate_hz"),
                first_contact_s=first, pushes_before_contact=pushes,
                circle_turns=max(circle_progress(ball, tgt.center, tgt.radius), 0.0),
                listener_scheduling=listener_scheduling, processes=summaries,
                exit_codes={n: p.returncode for n, p in procs.items()}, read_at=read_at,
                status_rate_hz=(len(status_t) / (status_t[-1] - status_t[0])
                                if len(status_t) > 1 else 0.0),
                realtime=realtime, overload=overload, spinners=spinners.count,
                not_ours=not_ours, garbage_sent=garbage.sent if garbage else 0)


class _GarbageSender:
    """One undecodable message on each channel every `every_s` seconds."""
    CHANNELS = ("PANDA_STATUS", "PANDA_COMMAND", "BALL_ESTIMATE", "EE_PLAN")

    def __init__(self, url: str, every_s: float):
        from pydrake.lcm import DrakeLcm
        self._lcm, self._every, self._next, self.sent = DrakeLcm(url), every_s, None, 0

    def maybe_send(self) -> None:
        now = time.monotonic()
        if self._next is None:
            self._next = now + self._every
        if now >= self._next:
            for ch in self.CHANNELS:
                self._lcm.Publish(ch, b"\x00not an LCM message of this channel's type")
            self.sent += 1
            self._next = now + self._every


def run_bench(quick: bool = False, overload: int | None = None) -> list[dict]:
    """overload None: the ordinary run (real-time priority); N >= 0: --overload N
    (bridge_overload.py). Either way each row says whether the run was valid."""
    from adaptive_c3.scenarios.schema import load_scenario
    from adaptive_c3.tools.bench.bridge_overload import overload_rows, validity
    from adaptive_c3.tools.user_input import resolve_scenario_path
    duration = 10.0 if quick else 90.0
    if overload is not None and not (0 <= overload <= 64):
        from adaptive_c3.tools.user_input import UserError
        raise UserError(f"--overload must be in [0, 64], got {overload}")
    loaded = overload is not None
    r = run_three_processes(duration, realtime=not loaded, overload=overload or 0)
    s, _ = load_scenario(resolve_scenario_path("ball_rolling"), list(SETS))
    reasons = validity(r, s.safety)
    r["valid"], r["invalid_reasons"] = not reasons, reasons
    out = Path("runs/bridge")
    out.mkdir(parents=True, exist_ok=True)
    name = f"overload{overload}.json" if loaded else "three_processes.json"
    (out / name).write_text(json.dumps(r, indent=1, default=float))
    print(f"bench bridge: run {'VALID' if not reasons else 'INVALID: ' + '; '.join(reasons)}"
          f" (status {r['status_rate_hz']:.0f} Hz, EE_PLAN {r['plan_rate_hz']:.0f} Hz, exit "
          f"codes {r['exit_codes']})", flush=True)
    per = r["command_period_ms"]
    valid = {"valid": not reasons, "invalid_reasons": reasons}
    rows = [
        {"name": "bridge/command_period_p99_ms", "median_ms": per["p50"], "value": per["p99"],
         "max_ms": per["max"], "commands": r["commands"], "duration_s": duration,
         "impedance_tick_ms": r["impedance_tick_ms"], "status_period_ms": r["status_period_ms"],
         "status_rate_hz": r["status_rate_hz"], **valid},
        {"name": "bridge/expired_fraction", "median_ms": per["p50"],
         "value": r["expired_fraction"], **valid},
        {"name": "bridge/circles_90s", "median_ms": per["p50"],
         "value": r["circle_turns"] * 90.0 / duration, "circle_turns": r["circle_turns"],
         "first_contact_s": r["first_contact_s"],
         "pushes_before_contact": r["pushes_before_contact"], **valid},
        {"name": "bridge/planner_latency_p99_ms", "median_ms": r["planner_latency_ms"]["p50"],
         "value": r["planner_latency_ms"]["p99"], "plan_rate_hz": r["plan_rate_hz"],
         "c3_solve_ms": r["c3_solve_ms"], "learner_rate_hz": r["learner_rate_hz"], **valid},
    ]
    if loaded:
        rows = overload_rows(r, rows)
        print(f"bench bridge --overload {overload}: unsafe_s = {rows[0]['value']:.3f}, "
              f"outcome {rows[1]['value']} ({rows[1]['reason']})", flush=True)
    return rows
