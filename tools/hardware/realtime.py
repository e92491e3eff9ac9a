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


def _started_simulator(diagram, wait_for, wait_s: float):
    """A Simulator of `diagram`, initialised (after the robot's first messages when
    wait_for = (lcm, channels) is given), with the start-up heap frozen."""
    from pydrake.systems.analysis import Simulator

    from adaptive_c3.tools.hardware.first_messages import start_from_first_messages
    from adaptive_c3.tools.process_tuning import freeze_heap
    sim = Simulator(diagram)
    if wait_for is None:
        sim.Initialize()
    else:
        print(f"waiting for {', '.join(wait_for[1])} ...", flush=True)
        start_from_first_messages(sim, *wait_for, timeout_s=wait_s)
    freeze_heap()
    return sim


def run_realtime(diagram, duration, label: str, on_stop=None, wait_for=None, on_start=None,
                 wait_s: float = 10.0):
    """Advance in real time until `duration` (None: Ctrl-C); returns (context, wall s).
    wait_for = (lcm, channels): initialise only once each channel has delivered a
    message (within wait_s, else a one-line FirstMessagesTimeout), with those messages in
    the context (first_messages.py). on_start(): called right after initialisation
    (diagram time 0)."""
    sim = _started_simulator(diagram, wait_for, wait_s)
    sim.set_target_realtime_rate(1.0)
    if on_start:
        on_start()
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
