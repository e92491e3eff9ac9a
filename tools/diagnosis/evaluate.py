"""`adaptive-c3 evaluate RECORDING --scenario S`: how well the scenario's model predicts
a recording, open loop.

For every episode the model is rolled out from the episode's first state for the
episode's whole length (re-linearised every step, at the recording's step) and
compared with the recording sample by sample:
  position_pct_mean / _final   |p_model - p_data| as % of the object's size (its longest
                               edge), averaged over the episode / at its last sample
  orientation_deg_mean / _final  the angle of the rotation between the two orientations
Each is summarised over episodes as median, mean and 90th percentile
(`summary.<model>.<metric>_median`, `_mean`, `_p90`). `--baseline drake` adds Drake's
own simulation of the same scenario (tools/diagnosis/drake_baseline.py) under
`summary.drake`. Writes DIR/evaluate.json and DIR/evaluate.png.

Supports `task: rigid_object` scenarios (models/rigid_object.py's recording layout).
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from adaptive_c3.models.rigid_object import RECORDING_STATE_NAMES, orientation_error_deg
from adaptive_c3.tools.progress import Progress
from adaptive_c3.tools.user_input import UserError

METRICS = ("position_pct_mean", "position_pct_final", "orientation_deg_mean",
           "orientation_deg_final")
DT_TOLERANCE = 0.05      # relative spread of sample steps allowed within a recording


def recording_episodes(rec, episode_ids=None) -> tuple[dict, float]:
    """({episode id: (t [T], x [T, 13])}, dt) after checking the recording fits a
    rigid-object model: state names, at least two rows per episode, a uniform step."""
    if list(rec.state_names) != list(RECORDING_STATE_NAMES):
        raise UserError(f"recording state names {list(rec.state_names)} do not match the "
                        f"rigid object's {list(RECORDING_STATE_NAMES)}")
    episodes = {int(e): idx for e, idx in rec.episodes()}
    if episode_ids is not None:
        missing = sorted(set(episode_ids) - set(episodes))
        if missing:
            raise UserError(f"episodes not in the recording: {missing[:10]}")
        episodes = {e: episodes[e] for e in episode_ids}
    steps = []
    for e, idx in episodes.items():
        if len(idx) < 2:
            raise UserError(f"episode {e} has {len(idx)} row; an episode needs at least 2")
        steps.append(np.diff(rec.t[idx]))
    steps = np.concatenate(steps)
    dt = float(np.median(steps))
    if np.max(np.abs(steps - dt)) > DT_TOLERANCE * dt:
        raise UserError(f"the recording's time step is not uniform (median {dt:g} s, "
                        f"range {steps.min():g}-{steps.max():g} s); resample it first")
    return {e: (rec.t[idx], rec.x[idx]) for e, idx in episodes.items()}, dt


def episode_errors(x_model: np.ndarray, x_data: np.ndarray, size: float) -> dict:
    """The per-episode metrics of METRICS for two [T, 13] recording-layout arrays."""
    pos = np.linalg.norm(x_model[:, 0:3] - x_data[:, 0:3], axis=1) / size * 100.0
    ori = orientation_error_deg(x_model[:, 3:7], x_data[:, 3:7])
    return {"position_pct_mean": float(pos.mean()), "position_pct_final": float(pos[-1]),
            "orientation_deg_mean": float(ori.mean()), "orientation_deg_final": float(ori[-1])}


def summarise(per_episode: list[dict]) -> dict:
    out = {"episodes": len(per_episode)}
    for key in METRICS:
        v = np.array([e[key] for e in per_episode])
        out[f"{key}_median"] = float(np.median(v))
        out[f"{key}_mean"] = float(np.mean(v))
        out[f"{key}_p90"] = float(np.percentile(v, 90))
    return out


def make_predictor(name: str, scenario, dt: float):
    """rollout(x0, num_steps) -> [num_steps + 1, 13] for 'model' (the LCS) or 'drake'."""
    if name == "model":
        from adaptive_c3.tools.diagnosis.rigid_model import RigidObjectModel
        sim = RigidObjectModel(scenario, dt)
    elif name == "drake":
        from adaptive_c3.tools.diagnosis.drake_baseline import DrakeRigidSimulator
        sim = DrakeRigidSimulator(scenario, dt)
    else:
        raise UserError(f"unknown baseline '{name}' (known: drake)")
    return sim.rollout


def evaluate(rec, scenario, baselines=(), episode_ids=None, progress: bool = True,
             keep_rollouts: int = 4) -> dict:
    """The evaluation dict (per episode, summary, a few rollouts for the figure)."""
    if scenario.task != "rigid_object":
        raise UserError(f"evaluate supports task rigid_object scenarios, not '{scenario.task}'")
    episodes, dt = recording_episodes(rec, episode_ids)
    result = {"recording_dt_s": dt, "episodes": list(episodes), "per_episode": {},
              "summary": {}, "rollouts": {}}
    from adaptive_c3.models.rigid_object import RigidObjectParams
    size = RigidObjectParams.from_scenario(scenario).size
    shown = list(episodes)[:keep_rollouts]
    for name in ("model", *baselines):
        rollout = make_predictor(name, scenario, dt)
        bar = Progress(len(episodes), label=f"evaluate {name}", unit="episodes",
                       enabled=None if progress else False)
        rows = []
        for i, (e, (t, x)) in enumerate(episodes.items()):
            x_hat = rollout(x[0], len(x) - 1)
            rows.append({"episode": e, **episode_errors(x_hat, x, size)})
            if e in shown:
                result["rollouts"].setdefault(str(e), {"t": t.tolist(), "data": x[:, :7].tolist()})
                result["rollouts"][str(e)][name] = x_hat[:, :7].tolist()
            bar.update(i + 1)
        bar.close()
        result["per_episode"][name] = rows
        result["summary"][name] = summarise(rows)
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
            ax.plot(t, np.asarray(r[name])[:, 2], label=name)
        ax.set_title(f"episode {e}: centre height")
        ax.set_xlabel("t [s]")
        ax.set_ylabel("z [m]")
        ax.legend(fontsize=7)
    for j in range(len(shown), axes.shape[1]):
        axes[0, j].axis("off")
    ax = axes[1, 0]
    data = [[row["position_pct_mean"] for row in result["per_episode"][n]] for n in names]
    ax.boxplot(data, tick_labels=names)
    ax.set_ylabel("mean position error [% of size]")
    ax = axes[1, 1]
    data = [[row["orientation_deg_mean"] for row in result["per_episode"][n]] for n in names]
    ax.boxplot(data, tick_labels=names)
    ax.set_ylabel("mean orientation error [deg]")
    for j in range(2, axes.shape[1]):
        axes[1, j].axis("off")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


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
    baselines = [args.baseline] if args.baseline else []
    result = evaluate(rec, scenario, baselines, parse_episodes(args.episodes))
    out = Path(args.out or "runs/evaluate")
    out.mkdir(parents=True, exist_ok=True)
    result.update(recording=str(args.recording), scenario=str(args.scenario))
    (out / "evaluate.json").write_text(json.dumps(result, indent=1))
    plot_evaluation(result, out / "evaluate.png")
    line = "; ".join(f"{n}: position {s['position_pct_mean_median']:.1f} % of size (median of "
                     f"episode means), final {s['position_pct_final_median']:.1f} %, orientation "
                     f"{s['orientation_deg_mean_median']:.1f} deg"
                     for n, s in result["summary"].items())
    print(f"{len(result['episodes'])} episodes - {line}")
    print(f"results in {out}: evaluate.json, evaluate.png")
    return 0
