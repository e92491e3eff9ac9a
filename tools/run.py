"""`adaptive-c3 run`: load a scenario, run its task, write the results folder."""
from __future__ import annotations

import json
import time
from pathlib import Path

from adaptive_c3.scenarios.schema import load_scenario

TASK_RUNNERS = {   # task -> (module, function(scenario, text, out, **kw) -> summary)
    "cartpole": ("adaptive_c3.tools.run_cartpole", "run_cartpole"),
    "ball_rolling": ("adaptive_c3.tools.run_ball_rolling", "run_ball_rolling"),
}


def default_out_dir(scenario_name: str) -> Path:
    return Path("runs") / f"{scenario_name}-{time.strftime('%Y%m%d-%H%M%S')}"


def run_scenario(path, out=None, overrides=(), meshcat: bool = False):
    """Run one scenario; returns (summary dict, output folder)."""
    import importlib
    scenario, text = load_scenario(path, overrides)
    out = Path(out) if out else default_out_dir(scenario.name)
    out.mkdir(parents=True, exist_ok=True)
    (out / "scenario.yaml").write_text(text)
    module, func = TASK_RUNNERS[scenario.task]
    runner = getattr(importlib.import_module(module), func)
    kwargs = {"meshcat": True} if meshcat else {}
    summary = runner(scenario, text, out, **kwargs)
    # written last and atomically: its presence means the run completed (sweeps rely on it)
    tmp = out / "summary.json.tmp"
    tmp.write_text(json.dumps(summary, indent=2, default=_json_default))
    tmp.replace(out / "summary.json")
    return summary, out


def _json_default(o):
    import numpy as np
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")
