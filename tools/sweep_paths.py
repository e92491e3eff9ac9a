"""The tracked paths of a ball-rolling sweep (the paper's Fig. 5): one panel per cell,
every completed trial's ball path against the target circle. Written as paths.png in the
sweep's folder; sweeps whose trials carry no ball path (other tasks) write nothing.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np


def _trial_path(folder: Path):
    """(ball xy [T, 2], summary) of one finished trial, or None when it has no ball-rolling
    log or was interrupted."""
    log, summ = folder / "log.npz", folder / "summary.json"
    if not (log.is_file() and summ.is_file()):
        return None
    with np.load(log, allow_pickle=False) as d:
        if "ball_true" not in d.files:
            return None
        ball = np.asarray(d["ball_true"], float)
    summary = json.loads(summ.read_text())
    return None if summary.get("interrupted") else (ball[:, 4:6], summary)


def plot_sweep_paths(plan: dict, out: Path, trials: list) -> Path | None:
    """paths.png: a panel per cell of the sweep (cells in plan order)."""
    cells: dict = {}
    for t in trials:
        got = _trial_path(Path(out) / t["folder"])
        if got is not None:
            cells.setdefault(t["cell_id"], (t["cell"], []))[1].append(got)
    if not cells:
        return None
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from adaptive_c3.scenarios.schema import load_scenario
    scenario, _ = load_scenario(plan["scenario"])
    c, R = np.asarray(scenario.target.center, float), scenario.target.radius
    n = len(cells)
    cols = min(n, 2 if n <= 4 else 4)
    rows = int(np.ceil(n / cols))
    fig, axes = plt.subplots(rows, cols, figsize=(3.6 * cols, 3.6 * rows), squeeze=False)
    a = np.linspace(0, 2 * np.pi, 200)
    for ax, (cid, (cell, paths)) in zip(axes.flat, cells.items()):
        ax.plot(c[0] + R * np.cos(a), c[1] + R * np.sin(a), "k--", lw=1)
        for xy, summary in paths:
            ax.plot(xy[:, 0], xy[:, 1], lw=0.8,
                    color="tab:green" if summary.get("one_circle") else "tab:orange")
        ax.set_xlim(c[0] - 2.2 * R, c[0] + 2.2 * R)
        ax.set_ylim(c[1] - 2.2 * R, c[1] + 2.2 * R)
        ax.set_aspect("equal")
        circles = sum(bool(s.get("one_circle")) for _, s in paths)
        label = ", ".join(f"{k.split('.')[-1]}={v}" for k, v in cell.items())
        ax.set_title(f"{label}\n{circles}/{len(paths)} >= one circle", fontsize=8)
        ax.tick_params(labelsize=7)
    for ax in list(axes.flat)[n:]:
        ax.axis("off")
    fig.suptitle(f"{plan['name']}: ball paths (green: at least one circle)", fontsize=9)
    path = Path(out) / "paths.png"
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)
    return path


__all__ = ["plot_sweep_paths"]
