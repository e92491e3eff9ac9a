"""What the hardware commands share: loading their scenario and flags, and running a
controller diagram held to real time."""
from __future__ import annotations

import math
import time


def load_hardware_scenario(args):
    """(scenario, YAML text, duration or None) for the hardware commands, flags checked."""
    from adaptive_c3.scenarios.schema import ScenarioError, load_scenario
    from adaptive_c3.tools.user_input import UserError, resolve_scenario_path
    s, text = load_scenario(resolve_scenario_path(args.scenario), list(getattr(args, "set", None) or []))
    if s.task != "ball_rolling":
        raise ScenarioError(f"hardware needs a ball_rolling scenario, got task '{s.task}'")
    if s.robot != "panda":
        raise ScenarioError("hardware needs robot: panda (the bridge speaks lcmt_panda_*)")
    duration = args.duration if args.duration is not None else None
    if duration is not None and not (math.isfinite(duration) and duration > 0):
        raise UserError(f"--duration must be > 0, got {duration}")
    stale_ms = getattr(args, "stale_ms", 50.0)
    if not (math.isfinite(stale_ms) and stale_ms > 0):
        raise UserError(f"--stale-ms must be > 0, got {stale_ms}")
    if not (getattr(args, "max_lag_ms", 100.0) > 0):
        raise UserError(f"--max-lag-ms must be > 0, got {args.max_lag_ms}")
    period = getattr(args, "period", 1e-3)
    if not (math.isfinite(period) and 1e-4 <= period <= 0.01):
        raise UserError(f"--period must be in [0.0001, 0.01] s, got {period}")
    return s, text, duration


def run_realtime(diagram, duration, label: str, on_stop=None):
    """Advance in real time until `duration` (None: Ctrl-C); returns (context, wall s)."""
    from pydrake.systems.analysis import Simulator
    sim = Simulator(diagram)
    sim.set_target_realtime_rate(1.0)
    sim.Initialize()
    print(label + (f" for {duration:g} s" if duration else "; Ctrl-C to stop"), flush=True)
    start, t = time.perf_counter(), 0.0
    try:
        while duration is None or t < duration - 1e-12:
            t = t + 0.1 if duration is None else min(t + 0.1, duration)
            sim.AdvanceTo(t)
    except KeyboardInterrupt:
        pass
    finally:
        if on_stop:
            on_stop()
    return sim.get_context(), time.perf_counter() - start
