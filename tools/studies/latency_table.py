"""Planner latency with and without planning from the predicted state, in lock-step.

`python -m adaptive_c3.tools.studies.latency_table [--duration S] [--out FILE]`: the three
hardware parts (simulated driver, impedance, planner; tools/hardware/split_loopback.py)
in lock-step over memq://, every plan held back by 0, 25 or 50 ms of simulated time
(`planner --delay-ms`), C3 planning from the measured state or from the state predicted
at the plan's effect time (`c3.predict_state`, lead = the injected delay + 1 ms). Ball
rolling, camera off, the scenario's 5 mm radius error, adaptation on, the driver's rules
with the driver's 30 Hz torque filter. Lock-step: simulated time, no wall-clock
jitter - it isolates the latency itself. Writes a JSON table and prints it.

`--loop-delays-ms 0,2,3,4,5,10`: instead, the 1 kHz impedance loop answers each
PANDA_STATUS that many ms late (planner on time; split_loopback's status_delay_s), and
the table gives the wrist's longest torque saturation and any safe stop - the delay
margin behind `bench bridge`'s status -> command bound (tools/bench/bridge_overload.py).

`--wall-clock`: the same cases as three OS processes over LCM in wall-clock time
(tools/bench/bridge.py `run_three_processes`: the driver's 30 Hz cutoff, the reference
gains, SCHED_FIFO driver and impedance loop), one after the other; the predicted state's
lead is then measured (median solve time + the delay + 1 ms).
"""
from __future__ import annotations

import argparse
import json
import multiprocessing

SETS = ["camera.enabled=false"]
CASES = [(0.0, False), (0.025, False), (0.025, True), (0.05, False), (0.05, True)]


def run_case(args):
    delay, predict, duration = args
    from adaptive_c3.scenarios.schema import SCENARIO_DIR, load_scenario
    from adaptive_c3.tools.hardware.split_loopback import run_split_loopback
    from adaptive_c3.tools.run_ball_rolling import circle_progress
    sets = SETS + [f"c3.predict_state={'true' if predict else 'false'}",
                   f"c3.predict_latency_s={delay + 0.001 if predict else -1}"]
    s, _ = load_scenario(SCENARIO_DIR / "ball_rolling.yaml", sets)
    out = run_split_loopback(s, duration, low_pass_hz=30.0, delay_s=delay)
    drv = out["_"]["driver"]
    ball = drv.logs["ball_true"].FindLog(out["_"]["sims"][0].get_context()).data().T
    return {"delay_ms": 1e3 * delay, "predicted_state": predict, "duration_s": duration,
            "circle_turns": circle_progress(ball[:, 4:6], s.target.center, s.target.radius),
            "ball_displacement_m": out["driver"]["ball_displacement_m"],
            "commands_expired": out["driver"]["commands_expired"],
            "wall_s": out["wall_s"]}


def run_loop_delay_case(args):
    delay, duration = args
    from adaptive_c3.scenarios.schema import SCENARIO_DIR, load_scenario
    from adaptive_c3.tools.hardware.split_loopback import run_split_loopback
    s, _ = load_scenario(SCENARIO_DIR / "ball_rolling.yaml", SETS)
    out = run_split_loopback(s, duration, low_pass_hz=30.0, status_delay_s=delay)
    safety = out["safety"]
    return {"loop_delay_ms": 1e3 * delay, "duration_s": duration,
            "circle_turns": out["driver"]["circle_turns"],
            "max_saturation_ms": safety["max_saturation_ms"], "breach": safety["breach"],
            "breach_detail": safety["breach_detail"], "breach_t_s": safety["breach_t_s"],
            "wall_s": out["wall_s"]}


def run_wall_clock_case(delay: float, predict: bool, duration: float) -> dict:
    from adaptive_c3.tools.bench.bridge import SETS as BRIDGE_SETS, run_three_processes
    sets = list(BRIDGE_SETS) + [f"c3.predict_state={'true' if predict else 'false'}"]
    r = run_three_processes(duration, sets=sets, planner_args=["--delay-ms", str(1e3 * delay)])
    drv = r["processes"].get("sim-driver", {})
    return {"delay_ms": 1e3 * delay, "predicted_state": predict, "duration_s": duration,
            "clock": "wall", "circle_turns": r["circle_turns"],
            "ball_displacement_m": drv.get("ball_displacement_m"),
            "commands_expired": drv.get("commands_expired"),
            "first_contact_s": r["first_contact_s"],
            "command_period_p99_ms": r["command_period_ms"]["p99"],
            "plan_age_p99_ms": r["planner_latency_ms"]["p99"]}


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--duration", type=float, default=30.0)
    p.add_argument("--out", default="runs/latency_table.json")
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--wall-clock", action="store_true",
                   help="three OS processes in wall-clock time instead of lock-step")
    p.add_argument("--loop-delays-ms", default=None,
                   help="comma-separated: the impedance loop answers each status this late")
    a = p.parse_args(argv)
    if a.loop_delays_ms is not None:
        try:
            delays = [1e-3 * float(x) for x in a.loop_delays_ms.split(",")]
        except ValueError:
            delays = None
        if not delays or not all(0 <= d < 1 for d in delays):
            import sys
            print(f"latency_table: --loop-delays-ms wants ms in [0, 1000) separated by "
                  f"commas, got {a.loop_delays_ms!r}", file=sys.stderr)
            return 2
        with multiprocessing.get_context("fork").Pool(a.workers) as pool:
            rows = pool.map(run_loop_delay_case, [(d, a.duration) for d in delays])
        _write(a.out, rows)
        for r in rows:
            print(f"loop delay {r['loop_delay_ms']:4.1f} ms  longest saturation "
                  f"{r['max_saturation_ms']:5.1f} ms  turns {r['circle_turns']:.2f}  "
                  + (f"SAFE STOP at {r['breach_t_s']:.2f} s: {r['breach_detail']}"
                     if r["breach"] else "no stop"))
        return 0
    if a.wall_clock:
        rows = [run_wall_clock_case(d, pr, a.duration) for d, pr in CASES]
    else:
        jobs = [(d, pr, a.duration) for d, pr in CASES]
        with multiprocessing.get_context("fork").Pool(a.workers) as pool:
            rows = pool.map(run_case, jobs)
    _write(a.out, rows)
    for r in rows:
        print(f"delay {r['delay_ms']:4.0f} ms  predicted {str(r['predicted_state']):5s}  "
              f"turns {r['circle_turns']:.2f}  displacement {r['ball_displacement_m']:.3f} m")


def _write(out, rows) -> None:
    from pathlib import Path
    Path(out).parent.mkdir(parents=True, exist_ok=True)
    Path(out).write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    raise SystemExit(main())
