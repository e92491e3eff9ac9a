"""`adaptive-c3 bench diagnose`: wall time of one ball-rolling diagnosis.

Rows
  diagnose/ball/15ep               `diagnose` + its report (report.json, report.html,
                                   plots) on a 15-episode, 1.6 s-per-episode concealed-draw
                                   recording (2400 samples at 100 Hz, made by the SAP harness,
                                   not timed), as the CLI runs it; median of the repeats.
  diagnose/ball/15ep/exact_refits  the same with the earlier fit settings, measured in the
                                   same run (full only): every fold / jackknife / half-horizon
                                   refit by Levenberg-Marquardt, tolerances 1e-10 / 1e-9.
                                   The first row carries baseline/speedup against it.
  diagnose/ball/drake/15ep         the same recording diagnosed with `--model drake` (Drake's
                                   SAP plant of the scenario's world, 2 worker processes; one
                                   run), with baseline/speedup against diagnose/ball/15ep
                                   (speedup < 1: the drake diagnosis is that much slower);
                                   cpu_s: the CPU time of the process and its workers
                                   (cpu_main_s + cpu_workers_s); two_free_cores_s =
                                   cpu_main_s + cpu_workers_s / 2, its wall time were the
                                   2 cores its own (the main process waits on the workers).
  diagnose/cube/lcs/24tosses       `diagnose_rigid` of 24 synthetic cube tosses (40 steps,
  diagnose/cube/drake/24tosses     made by the drake backend with mu 0.3; not timed), fit on
                                   10, effects friction and table_offset, 2 workers, with the
                                   lcs and the drake backend; the drake row carries
                                   baseline/speedup against the lcs row.
The two ball rows carry `load`, the 1-minute load average as the row started: other work
shares the 2 cores, and the drake/lcs ratio of one run is the figure that travels.
"""
from __future__ import annotations

import os
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

SEED = 5001                 # a contact_offset[ball_table] draw, with the second-engine variation


def _timed(rec, spec) -> tuple[float, float, str]:
    """(wall s of diagnose + report, of diagnose alone, selected label)."""
    from adaptive_c3.tools.diagnosis.diagnose import diagnose
    from adaptive_c3.tools.diagnosis.engine.report import write_report
    t0 = time.perf_counter()
    result = diagnose(rec, spec, progress=False)
    t1 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        write_report(Path(tmp), rec, result)
    t2 = time.perf_counter()
    chosen = result["chosen"]
    return t2 - t0, t1 - t0, chosen.label() if chosen is not None else "none"


def run_bench(quick: bool = False) -> list[dict]:
    from adaptive_c3.scenarios.schema import SCENARIO_DIR, load_scenario
    from adaptive_c3.tools.diagnosis.harness.concealed_ball_data import concealed_draw
    from adaptive_c3.tools.diagnosis.tasks.ball_rolling.effects_ball import ModelParams, ball_spec
    scenario, _ = load_scenario(SCENARIO_DIR / "ball_rolling.yaml")
    rec, truth, _ = concealed_draw(SEED, params=ModelParams.from_scenario(scenario))
    load = os.getloadavg()[0]
    runs = [_timed(rec, ball_spec(scenario)) for _ in range(1 if quick else 3)]
    wall = float(np.median([r[0] for r in runs]))
    row = {"name": "diagnose/ball/15ep", "median_ms": wall * 1e3, "wall_s": wall,
           "diagnose_s": float(np.median([r[1] for r in runs])), "samples": len(rec.t),
           "episodes": int(len(np.unique(rec.episode))), "truth": truth.name, "selected": runs[0][2],
           "load": load}
    rows = [row]
    if not quick:
        slow = replace(ball_spec(scenario), linear_refits=False, fit_tolerance=(1e-10, 1e-9))
        s_wall, s_diag, s_sel = _timed(rec, slow)
        rows.append({"name": "diagnose/ball/15ep/exact_refits", "median_ms": s_wall * 1e3,
                     "wall_s": s_wall, "diagnose_s": s_diag, "selected": s_sel})
        row.update(baseline=rows[1]["name"], speedup=s_wall / wall)
    return rows + [_drake_ball_row(rec, scenario, row)] + _rigid_rows()


def _drake_ball_row(rec, scenario, lcs_row: dict) -> dict:
    """The ball diagnosis with the drake backend, against the lcs row."""
    import resource
    from adaptive_c3.tools.diagnosis.tasks.ball_rolling.drake_ball import drake_ball_spec

    def cpu():
        a, b = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
        return np.array([a.ru_utime + a.ru_stime, b.ru_utime + b.ru_stime])
    spec = drake_ball_spec(scenario, workers=2)
    load = os.getloadavg()[0]
    c0 = cpu()
    try:
        wall, diag, sel = _timed(rec, spec)
    finally:
        spec.close()           # its workers' CPU time counts once they are waited for
    main, workers = cpu() - c0
    # the main process waits while its 2 workers roll out: on 2 cores of its own the
    # diagnosis would take about main + workers / 2
    return {"name": "diagnose/ball/drake/15ep", "median_ms": wall * 1e3, "wall_s": wall,
            "diagnose_s": diag, "cpu_s": main + workers, "cpu_main_s": main,
            "cpu_workers_s": workers, "two_free_cores_s": main + workers / 2,
            "selected": sel, "load": load,
            "baseline": lcs_row["name"], "speedup": lcs_row["wall_s"] / wall}


def _rigid_rows() -> list[dict]:
    """One rigid-object diagnosis per model backend on the same synthetic tosses."""
    from adaptive_c3.scenarios.schema import SCENARIO_DIR, load_scenario
    from adaptive_c3.tools.diagnosis.harness.concealed_rigid_data import concealed_tosses
    from adaptive_c3.tools.diagnosis.tasks.rigid_object.rigid_diagnose import diagnose_rigid
    scenario, _ = load_scenario(SCENARIO_DIR / "cube_toss.yaml")
    rec = concealed_tosses(scenario, episodes=24, steps=40, seed=5, friction=0.3)
    rows = []
    for model in ("lcs", "drake"):
        t0 = time.perf_counter()
        r = diagnose_rigid(rec, scenario, max_fit_episodes=10, workers=2, progress=False,
                           effects=("friction", "table_offset"), model=model)
        wall = time.perf_counter() - t0
        rows.append({"name": f"diagnose/cube/{model}/24tosses", "median_ms": wall * 1e3,
                     "wall_s": wall, "selected": ",".join(s["name"] for s in r["selected"])})
    rows[1].update(baseline=rows[0]["name"], speedup=rows[0]["wall_s"] / rows[1]["wall_s"])
    return rows


if __name__ == "__main__":
    for r in run_bench(quick=True):
        print(r)
