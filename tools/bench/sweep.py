"""Sweep throughput: trials per hour with 1 and 2 worker processes, in one run.

The trials are short ball-rolling runs (Panda, camera off: the trials of the shipped
sweeps, shortened); the same trial list is run by both pools in fresh folders.
"""
from __future__ import annotations

import tempfile
from pathlib import Path

from adaptive_c3.scenarios.schema import SCENARIO_DIR
from adaptive_c3.tools.sweep import load_sweep, run_sweep


def _plan(tmp: Path, trials: int, duration: float) -> dict:
    path = tmp / "bench_sweep.yaml"
    path.write_text(f"""
scenario: {SCENARIO_DIR / 'ball_rolling.yaml'}
trials: {trials}
set: {{sim_duration_s: {duration}, camera.enabled: false}}
factors:
  learner.enabled: {{values: [true, false]}}
success: [initiated]
""")
    return load_sweep(path)


def run_bench(quick: bool = False) -> list[dict]:
    trials, duration = (1, 1.0) if quick else (3, 4.0)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        plan = _plan(tmp, trials, duration)
        for workers in (1, 2):
            res = run_sweep(plan, tmp / f"w{workers}", workers=workers, show_progress=False)
            n = res["ran_now"]
            rows.append({"name": f"sweep/workers{workers}",
                         "median_ms": res["wall_s"] / n * 1000.0,   # wall time per trial
                         "trials": n, "trials_per_hour": res["trials_per_hour"],
                         "wall_s": res["wall_s"]})
    rows[1]["baseline"] = "sweep/workers1"
    rows[1]["speedup"] = rows[1]["trials_per_hour"] / rows[0]["trials_per_hour"]
    return rows
