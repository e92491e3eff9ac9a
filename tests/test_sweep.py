"""Sweeps: plan, run, resume without losing anything, Wilson intervals, a local Dask cluster."""
import csv
import json
import shutil

import pytest

from adaptive_c3.scenarios.schema import SCENARIO_DIR
from adaptive_c3.tools.cli import main
from adaptive_c3.tools.sweep import (SweepError, _check_same_sweep, load_sweep, plan_trials, run_sweep,
                                     wilson_interval)


def _sweep_file(tmp_path, trials=2, extra=""):
    path = tmp_path / "sweep.yaml"
    path.write_text(f"""
scenario: {SCENARIO_DIR / 'cartpole_softwalls.yaml'}
trials: {trials}
set: {{controller: lqr, sim_duration_s: 1.0}}
factors:
  initial_state: {{values: [[0.1, -0.3, 0, 0], [0.05, 0.0, 0.1, 0]]}}
  model.wall_stiffness: {{uniform: [40.0, 60.0]}}
success: [stabilised]
{extra}""")
    return path


def test_plan_is_deterministic_and_draws_per_trial(tmp_path):
    plan = load_sweep(_sweep_file(tmp_path, trials=3))
    a, b = plan_trials(plan), plan_trials(plan)
    assert a == b and len(a) == 6
    ks = [t["drawn"]["model.wall_stiffness"] for t in a]
    assert len(set(ks)) == 6 and all(40 <= k <= 60 for k in ks)


def test_run_and_resume_loses_nothing(tmp_path):
    plan = load_sweep(_sweep_file(tmp_path))
    out = tmp_path / "out"
    first = run_sweep(plan, out, show_progress=False)
    assert first["ran_now"] == 4 and first["completed"] == 4
    rows = list(csv.DictReader(open(out / "results.csv")))
    assert len(rows) == 4 and all(r["status"] == "ok" for r in rows)
    # simulate an interruption: one trial lost its summary, another never started
    trials = plan_trials(plan)
    (out / trials[1]["folder"] / "summary.json").unlink()
    shutil.rmtree(out / trials[3]["folder"])
    untouched = (out / trials[0]["folder"] / "summary.json").stat().st_mtime_ns
    second = run_sweep(plan, out, show_progress=False)
    assert second["ran_now"] == 2 and second["completed"] == 4
    assert (out / trials[0]["folder"] / "summary.json").stat().st_mtime_ns == untouched
    cells = second["cells"]
    assert len(cells) == 2
    for c in cells.values():
        r = c["rates"]["stabilised"]
        assert r["n"] == 2 and r["wilson95"][0] <= r["rate"] <= r["wilson95"][1]


def test_resume_refuses_a_folder_of_a_different_sweep(tmp_path):
    plan = load_sweep(_sweep_file(tmp_path))
    out = tmp_path / "out"
    out.mkdir()
    (out / "sweep_plan.json").write_text(json.dumps({**plan, "fixed": {"sim_duration_s": 99}}))
    with pytest.raises(SweepError, match="different sweep.*fixed"):
        run_sweep(plan, out, show_progress=False)
    more = {**plan, "trials": plan["trials"] + 1}          # more trials: same sweep
    (out / "sweep_plan.json").write_text(json.dumps(plan))
    _check_same_sweep(more, out / "sweep_plan.json")


def test_wilson_interval_known_values():
    lo, hi = wilson_interval(18, 20)   # 90 %
    assert lo == pytest.approx(0.699, abs=2e-3) and hi == pytest.approx(0.972, abs=2e-3)
    assert wilson_interval(0, 20)[0] == 0.0 and wilson_interval(20, 20)[1] == 1.0


def test_bad_sweep_file_exits_2(tmp_path, capsys):
    bad = _sweep_file(tmp_path, extra="colour: red\n")
    assert main(["sweep", str(bad), "--out", str(tmp_path / "o")]) == 2
    assert "unknown sweep key" in capsys.readouterr().err
    with pytest.raises(SweepError, match="trials must be"):
        load_sweep(_sweep_file(tmp_path, trials=0))


def test_two_workers_and_local_dask_cluster(tmp_path):
    pytest.importorskip("dask.distributed")
    from dask.distributed import LocalCluster
    plan = load_sweep(_sweep_file(tmp_path, trials=1))
    par = run_sweep(plan, tmp_path / "par", workers=2, show_progress=False)
    assert par["completed"] == 2
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=True,
                      dashboard_address=None) as cluster:
        res = run_sweep(plan, tmp_path / "dask", cluster=cluster.scheduler_address,
                        show_progress=False)
    assert res["completed"] == 2 and res["errors_now"] == 0
    a = json.loads((tmp_path / "par" / plan_trials(plan)[0]["folder"] / "summary.json").read_text())
    b = json.loads((tmp_path / "dask" / plan_trials(plan)[0]["folder"] / "summary.json").read_text())
    assert a["final_state"] == b["final_state"]   # same trial, same result, wherever it ran


def test_sweep_paths_figure_has_a_panel_per_cell_with_ball_logs(tmp_path):
    import numpy as np
    from adaptive_c3.tools.sweep_paths import plot_sweep_paths
    plan = load_sweep(SCENARIO_DIR / "error_sweep.yaml")
    trials = plan_trials(plan)
    assert plot_sweep_paths(plan, tmp_path, trials) is None      # no trial logs yet
    a = np.linspace(0, 2 * np.pi, 50)
    ball = np.zeros((50, 13))
    ball[:, 4], ball[:, 5] = 0.55 + 0.1 * np.cos(a), 0.1 * np.sin(a)
    for t in trials[:2]:
        folder = tmp_path / t["folder"]
        folder.mkdir(parents=True)
        np.savez(folder / "log.npz", ball_true=ball)
        (folder / "summary.json").write_text(json.dumps({"one_circle": True}))
    path = plot_sweep_paths(plan, tmp_path, trials)
    assert path == tmp_path / "paths.png" and path.stat().st_size > 1000
