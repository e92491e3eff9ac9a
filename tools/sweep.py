"""`adaptive-c3 sweep`: many independent trials of a scenario, on one machine or a cluster.

A sweep file:

    scenario: ball_rolling.yaml        # relative to the sweep file, or a shipped name
    trials: 20                         # per cell
    base_seed: 0
    set: {sim_duration_s: 60}          # fixed overrides for every trial
    factors:                           # the cells are the product of the `values` factors
      learner.enabled: {values: [true, false]}
      model.object: {values: [ball, orange, lime]}
      model.ball_radius_error: {uniform: [0.0, 0.008]}   # drawn per trial from its seed
    success: [initiated, one_circle, four_circles]     # boolean summary keys to rate

Every trial runs in its own folder `OUT/trials/<cell>/<trial>/` and is done when
its `summary.json` exists (written last, atomically) and does not say `interrupted`,
so an interrupted sweep restarted with the same folder runs only what is missing.
Ctrl-C cancels the queued trials, ends the running ones (each writes what it simulated,
marked interrupted) and writes results.csv and summary.json for what finished. `results.csv` (one row
per trial) and `summary.json` (per-cell success rates with 95% Wilson intervals)
are rebuilt from the trial folders after every run.

Dask distributed is the cluster engine: it is pure Python, its LocalCluster runs in
a test, and `Client(address).submit` maps one-to-one onto independent trials
(Ray would bring a heavier runtime for the same job).
"""
from __future__ import annotations

import csv
import hashlib
import itertools
import json
import math
import os
import random
import signal
import sys
import time
import traceback
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path

import yaml

from adaptive_c3.tools.progress import Progress


class SweepError(ValueError):
    """A malformed sweep file; one line for the user."""


# ------------------------------------------------------------------ the plan
def load_sweep(path, overrides=()) -> dict:
    path = Path(path)
    if not path.is_file():
        raise SweepError(f"sweep file not found: {path}")
    try:
        data = yaml.safe_load(path.read_text()) or {}
    except yaml.YAMLError as e:
        raise SweepError(f"{path}: not valid YAML ({getattr(e, 'problem', e)})")
    from adaptive_c3.scenarios.schema import apply_override, parse_override
    for text in overrides:
        key, value = parse_override(text)
        apply_override(data, key, value)
    allowed = {"scenario", "trials", "base_seed", "set", "factors", "success", "name"}
    unknown = set(data) - allowed
    if unknown:
        raise SweepError(f"unknown sweep key(s) {sorted(unknown)} (allowed: {sorted(allowed)})")
    if "scenario" not in data:
        raise SweepError("sweep file needs a 'scenario'")
    scenario = Path(str(data["scenario"]))
    if not scenario.is_absolute():
        local = path.parent / scenario
        from adaptive_c3.scenarios.schema import SCENARIO_DIR
        scenario = local if local.is_file() else SCENARIO_DIR / scenario
    if not scenario.is_file():
        raise SweepError(f"sweep scenario not found: {data['scenario']}")
    trials = data.get("trials", 1)
    if not isinstance(trials, int) or isinstance(trials, bool) or trials < 1:
        raise SweepError(f"trials must be a positive integer, got {trials!r}")
    factors = data.get("factors") or {}
    if not isinstance(factors, dict):
        raise SweepError("factors must map scenario keys to {values: [...]} or {uniform: [lo, hi]}")
    grid, draws = {}, {}
    for key, spec in factors.items():
        if not isinstance(spec, dict) or len(spec) != 1 or not ({"values", "uniform"} & set(spec)):
            raise SweepError(f"factor {key}: expected {{values: [...]}} or {{uniform: [lo, hi]}}")
        if "values" in spec:
            if not isinstance(spec["values"], list) or not spec["values"]:
                raise SweepError(f"factor {key}: values must be a non-empty list")
            grid[key] = spec["values"]
        else:
            lo_hi = spec["uniform"]
            if (not isinstance(lo_hi, list) or len(lo_hi) != 2
                    or not all(isinstance(v, (int, float)) for v in lo_hi) or lo_hi[0] > lo_hi[1]):
                raise SweepError(f"factor {key}: uniform needs [lo, hi] with lo <= hi")
            draws[key] = [float(v) for v in lo_hi]
    fixed = data.get("set") or {}
    if not isinstance(fixed, dict):
        raise SweepError("set must map scenario keys to values")
    success = data.get("success") or []
    return dict(name=data.get("name", path.stem), scenario=str(scenario.resolve()),
                trials=trials, base_seed=int(data.get("base_seed", 0)), fixed=fixed,
                grid=grid, draws=draws, success=list(success))


def _flatten(prefix, value, out):
    if isinstance(value, dict):
        for k, v in value.items():
            _flatten(f"{prefix}.{k}" if prefix else k, v, out)
    else:
        out[prefix] = value
    return out


def cell_id(cell: dict) -> str:
    text = ",".join(f"{k}={json.dumps(v)}" for k, v in cell.items()) or "all"
    slug = "".join(ch if ch.isalnum() or ch in "._-=" else "_" for ch in text)[:60]
    return f"{slug}-{hashlib.sha1(text.encode()).hexdigest()[:6]}"


def plan_trials(plan: dict) -> list:
    """The deterministic list of trials: each a dict with its folder name and overrides."""
    keys = list(plan["grid"])
    trials = []
    for values in itertools.product(*(plan["grid"][k] for k in keys)):
        cell = dict(zip(keys, values))
        cid = cell_id(cell)
        for i in range(plan["trials"]):
            seed = plan["base_seed"] + i
            rng = random.Random(f"{cid}/{seed}")
            drawn = {k: rng.uniform(lo, hi) for k, (lo, hi) in plan["draws"].items()}
            overrides = {**_flatten("", plan["fixed"], {}), **cell, **drawn, "seed": seed}
            trials.append(dict(cell=cell, cell_id=cid, trial=i, seed=seed, drawn=drawn,
                               overrides=[f"{k}={json.dumps(v)}" for k, v in overrides.items()],
                               folder=f"trials/{cid}/{i:03d}"))
    return trials


# ------------------------------------------------------------------ one trial
_worker = {"running": False, "stop": False}   # a pool worker's Ctrl-C state


def _worker_init():
    """A pool worker: Ctrl-C interrupts the trial it is running (once; the trial then
    writes its partial results) and makes an idle worker refuse further trials."""
    from adaptive_c3.tools.process_tuning import tune_allocator
    tune_allocator()
    signal.signal(signal.SIGINT, _worker_sigint)


def _worker_sigint(signum, frame):
    _worker["stop"] = True
    if _worker["running"]:
        _worker["running"] = False
        raise KeyboardInterrupt


def run_trial(scenario: str, trial: dict, out_dir: str) -> dict:
    """Run one trial in its folder (in whatever process or cluster worker this is)."""
    from adaptive_c3.tools.run import run_scenario
    if _worker["stop"]:
        return {"status": "cancelled"}
    folder = Path(out_dir) / trial["folder"]
    folder.mkdir(parents=True, exist_ok=True)
    os.environ.setdefault("ADAPTIVE_C3_PROGRESS", "0")
    _worker["running"] = True
    try:
        summary, _ = run_scenario(scenario, folder, trial["overrides"])
        (folder / "error.txt").unlink(missing_ok=True)
        if summary.get("interrupted"):
            return {"status": "interrupted"}
        return {"status": "ok", "summary": summary}
    except KeyboardInterrupt:
        return {"status": "interrupted"}
    except Exception as e:  # recorded, the sweep goes on; the trial reruns on resume
        (folder / "error.txt").write_text(traceback.format_exc())
        return {"status": "error", "error": f"{type(e).__name__}: {e}"}
    finally:
        _worker["running"] = False


def _trial_status(folder: Path) -> str:
    """ok (summary.json of a run that finished), interrupted, error or missing."""
    summary = folder / "summary.json"
    if summary.is_file():
        try:
            interrupted = json.loads(summary.read_text()).get("interrupted", False)
        except (OSError, ValueError):
            return "error"
        return "interrupted" if interrupted else "ok"
    return "error" if (folder / "error.txt").is_file() else "missing"


def trial_done(out: Path, trial: dict) -> bool:
    return _trial_status(out / trial["folder"]) == "ok"


# ------------------------------------------------------------------ running
RESUME_KEYS = ("fixed", "grid", "draws", "base_seed")   # what a trial's result depends on


def _check_same_sweep(plan: dict, stored_path: Path) -> None:
    """Resuming into a folder whose trials ran with other settings would mix results
    (trials are found by cell and index): refuse. The trial count may change."""
    if not stored_path.is_file():
        return
    try:
        stored = json.loads(stored_path.read_text())
    except (OSError, ValueError):
        raise SweepError(f"{stored_path} is unreadable; use a new --out")
    new = json.loads(json.dumps(plan))
    differ = [k for k in RESUME_KEYS if stored.get(k) != new.get(k)]
    if differ:
        raise SweepError(f"{stored_path.parent} holds trials of a different sweep (differs "
                         f"in {', '.join(differ)}); resume with the same sweep or use a new --out")


def run_sweep(plan: dict, out, workers: int = 1, cluster: str | None = None,
              show_progress: bool | None = None) -> dict:
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    _check_same_sweep(plan, out / "sweep_plan.json")
    (out / "sweep_plan.json").write_text(json.dumps(plan, indent=2))
    trials = plan_trials(plan)
    todo = [t for t in trials if not trial_done(out, t)]
    bar = Progress(len(trials), f"sweep {plan['name']}", unit="trials", enabled=show_progress)
    done = len(trials) - len(todo)
    bar.update(done)
    start = time.perf_counter()
    errors, ran, interrupted = [], 0, False
    try:
        for result in _execute(plan["scenario"], todo, out, workers, cluster):
            if result["status"] in ("interrupted", "cancelled"):
                interrupted = True
                break
            done += 1
            ran += 1
            bar.update(done)
            if result["status"] != "ok":
                errors.append(result["error"])
    except KeyboardInterrupt:
        interrupted = True
    bar.close(done)
    wall = time.perf_counter() - start
    summary = collect(plan, out)
    summary.update(ran_now=ran, errors_now=len(errors), wall_s=wall,
                   trials_per_hour=(ran / wall * 3600 if ran and wall > 0 else None),
                   workers=workers, cluster=cluster, interrupted=interrupted)
    (out / "summary.json").write_text(json.dumps(summary, indent=2, default=float))
    return summary


def _execute(scenario, todo, out: Path, workers: int, cluster):
    if cluster:
        try:
            from dask.distributed import Client, as_completed as dask_completed
        except ImportError:
            raise SweepError("--cluster needs dask[distributed] installed")
        client = Client(cluster)
        futures = []
        try:
            futures = [client.submit(run_trial, scenario, t, str(out), pure=False) for t in todo]
            for fut in dask_completed(futures):
                yield fut.result()
        finally:
            client.cancel([f for f in futures if not f.done()])
            client.close()
    elif workers <= 1:
        for t in todo:
            yield run_trial(scenario, t, str(out))
    else:
        import multiprocessing as mp
        pool = ProcessPoolExecutor(max_workers=workers, mp_context=mp.get_context("spawn"),
                                   initializer=_worker_init)
        futures, finished = [], False
        try:
            futures = [pool.submit(run_trial, scenario, t, str(out)) for t in todo]
            for fut in as_completed(futures):
                yield fut.result()
            finished = True
        finally:
            if not finished:   # Ctrl-C (or the caller stopped): queued trials never start
                for f in futures:
                    f.cancel()
                _interrupt_workers(pool)
            pool.shutdown(wait=True, cancel_futures=True)


def _interrupt_workers(pool) -> None:
    """Ctrl-C for the pool's workers (a terminal sends it to them too; `kill -INT` of
    the sweep alone does not): each ends its trial, writing what it simulated."""
    for proc in list((getattr(pool, "_processes", None) or {}).values()):
        try:
            os.kill(proc.pid, signal.SIGINT)
        except (ProcessLookupError, OSError):
            pass


# ------------------------------------------------------------------ results
def wilson_interval(successes: int, n: int, z: float = 1.959964) -> tuple:
    if n == 0:
        return (0.0, 1.0)
    p = successes / n
    denom = 1 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    return (max(0.0, centre - half), min(1.0, centre + half))


def _scalar_fields(summary: dict) -> dict:
    return {k: v for k, v in summary.items()
            if isinstance(v, (int, float, str, bool)) or v is None}


def collect(plan: dict, out: Path) -> dict:
    """Rebuild results.csv and the per-cell rates from the trial folders."""
    rows = []
    for t in plan_trials(plan):
        folder = out / t["folder"]
        row = {"cell": t["cell_id"], "trial": t["trial"], "seed": t["seed"], **t["cell"],
               **{f"drawn.{k}": v for k, v in t["drawn"].items()}}
        status = _trial_status(folder)
        if status in ("ok", "interrupted"):
            row.update(_scalar_fields(json.loads((folder / "summary.json").read_text())))
        row["status"] = status
        rows.append(row)
    columns = list(dict.fromkeys(k for r in rows for k in r))
    with open(out / "results.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=columns)
        writer.writeheader()
        writer.writerows(rows)
    cells = {}
    for r in rows:
        c = cells.setdefault(r["cell"], {"factors": {k: r[k] for k in plan["grid"]},
                                         "trials": 0, "completed": 0, "errors": 0, "rates": {}})
        c["trials"] += 1
        c["completed"] += r["status"] == "ok"
        c["errors"] += r["status"] == "error"
    for key in plan["success"]:
        for cid, c in cells.items():
            ok = [r for r in rows if r["cell"] == cid and r["status"] == "ok"]
            hits = sum(bool(r.get(key)) for r in ok)
            lo, hi = wilson_interval(hits, len(ok))
            c["rates"][key] = {"successes": hits, "n": len(ok),
                               "rate": hits / len(ok) if ok else None, "wilson95": [lo, hi]}
    return {"sweep": plan["name"], "scenario": plan["scenario"], "cells": cells,
            "total_trials": len(rows), "completed": sum(r["status"] == "ok" for r in rows)}


def cmd_sweep(args) -> int:
    from adaptive_c3.tools.user_input import UserError
    try:
        plan = load_sweep(args.sweep_file, args.set or [])
    except SweepError as e:
        raise UserError(str(e))
    if args.workers < 1:
        raise UserError(f"--workers must be >= 1, got {args.workers}")
    out = Path(args.out) if args.out else Path("runs") / f"sweep-{plan['name']}"
    summary = run_sweep(plan, out, workers=args.workers, cluster=args.cluster)
    if summary["interrupted"]:
        print(f"adaptive-c3 sweep: interrupted; {summary['completed']}/{summary['total_trials']} "
              f"trials finished, results.csv and summary.json in {out} (run the same command "
              "again to resume)", file=sys.stderr)
        return 130
    from adaptive_c3.tools.sweep_paths import plot_sweep_paths
    figure = plot_sweep_paths(plan, out, plan_trials(plan))
    for cid, c in summary["cells"].items():
        rates = ", ".join(f"{k} {v['successes']}/{v['n']}" for k, v in c["rates"].items())
        print(f"{cid}: {c['completed']}/{c['trials']} done" + (f"; {rates}" if rates else ""))
    print(f"results in {out}: results.csv, summary.json" + (", paths.png" if figure else ""))
    return 0 if summary["errors_now"] == 0 else 1
