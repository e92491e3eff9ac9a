"""`adaptive-c3 run`: load a scenario, run its task, write the results folder."""
from __future__ import annotations

import json
import time
from pathlib import Path

from adaptive_c3.scenarios.schema import load_scenario
from adaptive_c3.tools.user_input import UserError

TASK_RUNNERS = {   # task -> (module, function(scenario, text, out, **kw) -> summary)
    "cartpole": ("adaptive_c3.tools.run_cartpole", "run_cartpole"),
    "ball_rolling": ("adaptive_c3.tools.run_ball_rolling", "run_ball_rolling"),
}
MESHCAT_TASKS = ("ball_rolling",)   # tasks whose runner takes meshcat / meshcat_port


def default_out_dir(scenario_name: str) -> Path:
    return Path("runs") / f"{scenario_name}-{time.strftime('%Y%m%d-%H%M%S')}"


def run_scenario(path, out=None, overrides=(), meshcat: bool = False,
                 meshcat_port: int | None = None):
    """Run one scenario; returns (summary dict, output folder). A run ended by Ctrl-C
    still writes its results for the time simulated, with summary["interrupted"] true."""
    import importlib
    scenario, text = load_scenario(path, overrides)
    if scenario.task not in TASK_RUNNERS:
        raise UserError(f"'{scenario.task}' scenarios have no controller to run: compare them "
                        f"with a recording (adaptive-c3 evaluate RECORDING --scenario {path} "
                        "[--model drake], or diagnose)")
    if (meshcat or meshcat_port is not None) and scenario.task not in MESHCAT_TASKS:
        raise UserError(f"--meshcat is available for the {', '.join(MESHCAT_TASKS)} task, "
                        f"not '{scenario.task}'")
    out = Path(out) if out else default_out_dir(scenario.name)
    out.mkdir(parents=True, exist_ok=True)
    (out / "scenario.yaml").write_text(text)
    module, func = TASK_RUNNERS[scenario.task]
    runner = getattr(importlib.import_module(module), func)
    kwargs = ({"meshcat": True, "meshcat_port": meshcat_port}
              if meshcat or meshcat_port is not None else {})
    summary = runner(scenario, text, out, **kwargs)
    # written last and atomically: its presence means the run ended; a sweep counts a
    # trial done when it is here and not "interrupted" (a Ctrl-C'd run's partial results)
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
