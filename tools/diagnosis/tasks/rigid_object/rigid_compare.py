"""Both backends diagnosed on one recording, compared on the same held-out episodes:
nominal LCS, diagnosed LCS, Drake's default and diagnosed Drake, each rolled out from
the same starts, under every initial-state method (the effects are fitted once, with
the `fit_start` method). The figures issue 30 asks for on the real cube tosses:

    python -m adaptive_c3.tools.diagnosis.tasks.rigid_object.rigid_compare RECORDING SCENARIO OUT.json [drake|lcs]

(a fourth argument: that backend only, its nominal and diagnosed models).

Per model and start: the held-out summary (median / mean / p90 of the per-episode
mean-over-time position error, % of size); per start: the paired per-episode difference
diagnosed Drake - Drake's default and diagnosed LCS - nominal LCS (median and mean, with
bootstrap 95 % intervals; `below`: the diagnosed model is lower by more than the median's
interval), the paired drop (the engine's statistic) and the difference of the medians.
"""
from __future__ import annotations

import json
import sys
import time

import numpy as np

from adaptive_c3.models.rigid_object import RigidObjectParams
from adaptive_c3.tools.diagnosis.tasks.rigid_object.episodes import recording_episodes
from adaptive_c3.tools.diagnosis.tasks.rigid_object.initial_state import METHODS, initial_states
from adaptive_c3.tools.diagnosis.tasks.rigid_object.rigid_diagnose import (
    DEFAULT_FIT_EPISODES, diagnose_rigid, held_out_runs, paired_gain)

BOOTSTRAP = 2000


def median_difference(before: np.ndarray, after: np.ndarray, rng) -> dict:
    """median(before) - median(after) over paired episodes, with a bootstrap 95 % interval
    (episodes resampled together)."""
    b, a = np.asarray(before, float), np.asarray(after, float)
    picks = rng.integers(0, len(b), size=(BOOTSTRAP, len(b)))
    d = np.median(b[picks], axis=1) - np.median(a[picks], axis=1)
    lo, hi = np.percentile(d, [2.5, 97.5])
    return dict(value=float(np.median(b) - np.median(a)), ci95=[float(lo), float(hi)])


def paired_difference(before: np.ndarray, after: np.ndarray, rng) -> dict:
    """The per-episode difference after - before (% of size; < 0: the second model is
    better): its median and mean with bootstrap 95 % intervals (episodes resampled), and
    whether the second model is below the first by more than the median's interval
    (`below`: the interval's upper end < 0)."""
    d = np.asarray(after, float) - np.asarray(before, float)
    picks = rng.integers(0, len(d), size=(BOOTSTRAP, len(d)))
    med = np.percentile(np.median(d[picks], axis=1), [2.5, 97.5])
    mean = np.percentile(np.mean(d[picks], axis=1), [2.5, 97.5])
    return dict(median=float(np.median(d)), median_ci95=[float(med[0]), float(med[1])],
                mean=float(np.mean(d)), mean_ci95=[float(mean[0]), float(mean[1])],
                below=bool(med[1] < 0), statistic="after - before per episode")


LCS_EFFECTS = ("friction_cone", "friction", "table_offset", "restitution", "inertia_scale")


def compare(rec, scenario, fit_episodes: dict | None = None, workers: int = 2, seed: int = 0,
            fit_start: str = "ballistic", lcs_effects=LCS_EFFECTS, drake_effects=None,
            progress: bool | None = None, checkpoint=None, models=("drake", "lcs")) -> dict:
    """The comparison dict; checkpoint(out), if given, is called after each diagnosis.
    The LCS library is cut to LCS_EFFECTS by default (the LCS rollouts cost ~30x Drake's:
    the effects the full library never kept on these tosses - README - are left out)."""
    fit_episodes = fit_episodes or DEFAULT_FIT_EPISODES
    out = {"fit_start": fit_start, "diagnoses": {}, "held_out": {}, "comparisons": {}}
    patched = {}
    for model, effects in (("drake", drake_effects), ("lcs", lcs_effects)):
        if model not in models:
            continue
        t0 = time.perf_counter()
        r = diagnose_rigid(rec, scenario, max_fit_episodes=fit_episodes[model], workers=workers,
                           seed=seed, progress=progress, effects=effects, model=model,
                           initial_state=fit_start)
        patched[model] = r["patched"]
        out["diagnoses"][model] = dict(
            chosen=r["chosen"], seconds=time.perf_counter() - t0,
            fit_episodes=len(r["fit_episodes"]),
            selected=[{k: s.get(k) for k in ("name", "key", "value", "ci95", "refitted", "kind",
                                             "lcs")}
                      for s in r["selected"]],
            rounds=[dict(tried=x["tried"], accepted=x["accepted"],
                         tries=[(t["name"], t["accepted"], t["validation_gain"]["relative"])
                                for t in x["tries"]],
                         candidates=[(c["name"], c["value"], c["refitted"], c["fit_mean"])
                                     for c in x["candidates"]]) for x in r["rounds"]],
            held_out={k: v["summary"] for k, v in r["held_out"].items()})
        split = r["split"]
        if checkpoint:
            checkpoint(out)
    episodes, dt = recording_episodes(rec)
    params = RigidObjectParams.from_scenario(scenario)
    held = split["held_out"]
    out["held_out_episodes"] = len(held)
    rng = np.random.default_rng(seed)
    runs = [(tag, model, scen) for tag, model, scen in (
        ("lcs_nominal", "lcs", scenario), ("lcs_diagnosed", "lcs", patched.get("lcs")),
        ("drake_default", "drake", scenario), ("drake_diagnosed", "drake", patched.get("drake")))
        if model in models]
    for method in METHODS:
        x0s = initial_states({e: episodes[e][1] for e in held}, dt, method, params.half_size,
                             params.table_height)
        res, _ = held_out_runs(runs, held, episodes, x0s, dt, params.size, workers, show=0)
        out["held_out"][method] = {k: v["summary"] for k, v in res.items()}
        per = {k: np.array([r["position_pct_mean"] for r in v["per_episode"]])
               for k, v in res.items()}
        out["comparisons"][method] = {
            f"{ref}_to_diagnosed": dict(
                paired_drop=paired_gain(per[ref], per[diag], rng),
                paired_difference=paired_difference(per[ref], per[diag], rng),
                median_difference=median_difference(per[ref], per[diag], rng))
            for ref, diag in (("drake_default", "drake_diagnosed"),
                              ("lcs_nominal", "lcs_diagnosed")) if ref in per}
    return out


def main(argv=None) -> int:
    from adaptive_c3.scenarios.schema import load_scenario
    from adaptive_c3.tools.recording import load_recording
    args = list(argv or sys.argv[1:])
    recording, scenario_path, out_path = args[:3]
    models = tuple(args[3:4]) or ("drake", "lcs")
    scenario, _ = load_scenario(scenario_path, [])
    t0 = time.perf_counter()

    def save(result):
        with open(out_path, "w") as f:
            json.dump(result, f, indent=1, default=float)

    result = compare(load_recording(recording), scenario, checkpoint=save, models=models)
    result["wall_s"] = time.perf_counter() - t0
    save(result)
    for method, models in result["held_out"].items():
        print(method, {k: round(v["position_pct_mean_median"], 2) for k, v in models.items()})
        for name, c in result["comparisons"][method].items():
            d = c["paired_difference"]
            print(f"  {name}: paired per-episode difference (diagnosed - reference) median "
                  f"{d['median']:.2f} [{d['median_ci95'][0]:.2f}, {d['median_ci95'][1]:.2f}], "
                  f"mean {d['mean']:.2f} [{d['mean_ci95'][0]:.2f}, {d['mean_ci95'][1]:.2f}] "
                  f"% of size; below by more than the interval: {d['below']}")
    print("wall", round(result["wall_s"]), "s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
