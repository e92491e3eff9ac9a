"""`adaptive-c3 evaluate RECORDING --scenario S [--model lcs|drake]`: how well a model of
the scenario predicts a recording, open loop.

`--model` picks the backend (tools/diagnosis/backends/model_backend.py): `lcs`, the controller's
Anitescu LCS re-linearised every step at the recording's step (default), or `drake`,
Drake's SAP MultibodyPlant of the scenario's true world at a finer step. Every episode is
rolled out for its whole length from a start estimated from its first rows
(`--initial-state`, tools/diagnosis/tasks/rigid_object/initial_state.py: `ballistic`, a fit of the
free-flight prefix, default; `first-row`, the recorded first row), the same start for
every model compared, and compared with the recording sample by sample:
  position_pct_mean / _final   |p_model - p_data| as % of the object's size (its longest
                               edge), averaged over the episode / at its last sample
  orientation_deg_mean / _final  the angle of the rotation between the two orientations
Each is summarised over episodes as median, mean and 90th percentile
(`summary.model.<metric>_median`, `_mean`, `_p90`; `model` names the backend).
An episode the model cannot roll out (an LCP without a solution, a state gone
non-finite) is scored FAILED_SCORE % and 180 deg, as the diagnosis scores it, marked
`failed` in `per_episode`, counted in `summary.<name>.failed` and listed on the console;
a model that rolls out no episode at all is a one-line error (exit 2).
`--baseline lcs|drake` adds the other backend under `summary.<name>`. Rollouts run on
`--workers` processes. Writes DIR/evaluate.json and DIR/evaluate.png.

Supports `task: rigid_object` scenarios (models/rigid_object.py's recording layout).
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from adaptive_c3.tools.progress import Progress
from adaptive_c3.tools.user_input import UserError
from adaptive_c3.tools.diagnosis.tasks.rigid_object.episodes import (METRICS, episode_errors,
                                                                recording_episodes, summarise)

def evaluate(rec, scenario, baselines=(), episode_ids=None, progress: bool = True,
             keep_rollouts: int = 4, model: str = "lcs", initial_state: str = "ballistic",
             workers: int = 2) -> dict:
    """The evaluation dict (per episode, summary, a few rollouts for the figure): the
    scenario's `model` backend under summary key "model", each baseline backend under its
    name, every one rolled out from the same estimated start of each episode."""
    from adaptive_c3.models.rigid_object import RigidObjectParams
    from adaptive_c3.tools.diagnosis.tasks.rigid_object.initial_state import METHODS, initial_states
    from adaptive_c3.tools.diagnosis.backends.model_backend import Scorer, check_model
    if scenario.task != "rigid_object":
        raise UserError(f"evaluate supports task rigid_object scenarios, not '{scenario.task}'")
    check_model(model)
    for b in baselines:
        check_model(b)
    if initial_state not in METHODS:
        raise UserError(f"unknown --initial-state '{initial_state}' (known: {', '.join(METHODS)})")
    episodes, dt = recording_episodes(rec, episode_ids)
    params = RigidObjectParams.from_scenario(scenario)
    size = params.size
    ids = list(episodes)
    xs = [episodes[e][1] for e in ids]
    starts = initial_states(dict(zip(ids, xs)), dt, initial_state, params.half_size,
                            params.table_height)
    result = {"recording_dt_s": dt, "episodes": ids, "per_episode": {}, "summary": {},
              "rollouts": {}, "model": model, "baselines": list(baselines),
              "initial_state": initial_state}
    shown = ids[:keep_rollouts]
    for tag, name in [("model", model)] + [(b, b) for b in baselines if b != model]:
        scorer = Scorer(xs, dt, size, workers, name, [starts[e] for e in ids])
        bar = Progress(len(ids), label=f"evaluate {name}", unit="episodes",
                       enabled=None if progress else False)
        try:
            _, (x_hats,) = scorer.run([scenario], keep=True,
                                      progress=lambda i, n: bar.update(len(ids) * i / n))
        finally:
            bar.close()
            scorer.close()
        rows = []
        if all(x_hat is None for x_hat in x_hats):
            raise UserError(f"the {name} model failed to roll out every episode (its LCP "
                            f"had no solution or the state went non-finite)")
        for e, x, x_hat in zip(ids, xs, x_hats):
            rows.append({"episode": e, **episode_errors(x_hat, x, size)})
            if e in shown and x_hat is not None:
                result["rollouts"].setdefault(str(e), {"t": episodes[e][0].tolist(),
                                                       "data": x[:, :7].tolist()})
                result["rollouts"][str(e)][tag] = x_hat[:, :7].tolist()
        result["per_episode"][tag] = rows
        result["summary"][tag] = summarise(rows)
    result["object_size_m"] = size
    return result


def plot_evaluation(result: dict, path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    names = list(result["summary"])
    shown = list(result["rollouts"])
    fig, axes = plt.subplots(2, max(2, len(shown)), figsize=(4 * max(2, len(shown)), 7),
                             squeeze=False)
    for j, e in enumerate(shown):
        r = result["rollouts"][e]
        t = np.asarray(r["t"])
        ax = axes[0, j]
        ax.plot(t, np.asarray(r["data"])[:, 2], "k.", ms=3, label="data")
        for name in names:
            ax.plot(t, np.asarray(r[name])[:, 2], label=_label(result, name))
        ax.set_title(f"episode {e}: centre height")
        ax.set_xlabel("t [s]")
        ax.set_ylabel("z [m]")
        ax.legend(fontsize=7)
    for j in range(len(shown), axes.shape[1]):
        axes[0, j].axis("off")
    ax = axes[1, 0]
    data = [[row["position_pct_mean"] for row in result["per_episode"][n]] for n in names]
    ax.boxplot(data, tick_labels=[_label(result, n) for n in names])
    ax.set_ylabel("mean position error [% of size]")
    ax = axes[1, 1]
    data = [[row["orientation_deg_mean"] for row in result["per_episode"][n]] for n in names]
    ax.boxplot(data, tick_labels=[_label(result, n) for n in names])
    ax.set_ylabel("mean orientation error [deg]")
    for j in range(2, axes.shape[1]):
        axes[1, j].axis("off")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _label(result: dict, tag: str) -> str:
    return f"{result.get('model', 'lcs')} (model)" if tag == "model" else tag


def parse_episodes(spec: str | None) -> list[int] | None:
    """'0-9,20,30-31' -> [0..9, 20, 30, 31]; None -> every episode."""
    if not spec:
        return None
    ids = []
    try:
        for part in spec.split(","):
            a, _, b = part.strip().partition("-")
            ids.extend(range(int(a), int(b) + 1) if b else [int(a)])
    except ValueError:
        raise UserError(f"bad --episodes '{spec}': expected e.g. 0-9,20")
    return ids


def cmd_evaluate(args) -> int:
    from adaptive_c3.scenarios.schema import load_scenario
    from adaptive_c3.tools.recording import load_recording
    from adaptive_c3.tools.user_input import resolve_scenario_path
    scenario, _ = load_scenario(resolve_scenario_path(args.scenario), list(args.set or []))
    rec = load_recording(args.recording)
    from adaptive_c3.tools.diagnosis.backends.model_backend import FAILED_SCORE, check_model
    model = check_model(getattr(args, "model", None) or "lcs")
    baselines = [check_model(args.baseline)] if args.baseline else []
    workers = int(getattr(args, "workers", None) or 2)
    if workers < 1:
        raise UserError(f"--workers must be >= 1, got {workers}")
    result = evaluate(rec, scenario, baselines, parse_episodes(args.episodes), model=model,
                      initial_state=getattr(args, "initial_state", None) or "ballistic",
                      workers=workers)
    out = Path(args.out or "runs/evaluate")
    out.mkdir(parents=True, exist_ok=True)
    result.update(recording=str(args.recording), scenario=str(args.scenario))
    (out / "evaluate.json").write_text(json.dumps(result, indent=1))
    plot_evaluation(result, out / "evaluate.png")
    line = "; ".join(f"{n}: position {s['position_pct_mean_median']:.1f} % of size (median of "
                     f"episode means), final {s['position_pct_final_median']:.1f} %, orientation "
                     f"{s['orientation_deg_mean_median']:.1f} deg"
                     for n, s in result["summary"].items())
    print(f"{len(result['episodes'])} episodes, model {result['model']}, start "
          f"{result['initial_state']} - {line}")
    for n, rows in result["per_episode"].items():
        failed = [r["episode"] for r in rows if r.get("failed")]
        if failed:
            print(f"{n}: {len(failed)} episodes failed to roll out (the model's LCP had no "
                  f"solution or the state went non-finite), scored {FAILED_SCORE:.0f} % of "
                  f"size as the diagnosis scores them: {', '.join(map(str, failed))}")
    print(f"results in {out}: evaluate.json, evaluate.png")
    return 0
