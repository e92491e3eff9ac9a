"""The run loop every `adaptive-c3 run` task shares: advance a Drake Simulator in chunks
to the scenario's duration, and say how far it got and why it ended.

A run ends "completed" (the scenario's sim_duration_s reached), "stopped" (Meshcat's
Stop button) or "interrupted" (Ctrl-C). For `run` (keep_partial) Ctrl-C ends the loop
instead of the process, so the runner still writes log.npz and summary.json for what
was simulated; the summary's `sim_duration_s` is the simulated time reached, not the
scenario's request.
"""
from __future__ import annotations

from dataclasses import dataclass

ENDINGS = ("completed", "stopped", "interrupted")


@dataclass
class SimEnd:
    """How a simulation loop ended: `t` the simulated time reached (s), `reason` one of
    ENDINGS."""
    t: float
    reason: str = "completed"


def advance(simulator, duration: float, chunk: float, after_chunk=None, bar=None,
            keep_partial: bool = False) -> SimEnd:
    """AdvanceTo(duration) in steps of `chunk` seconds; `bar.update(t)` after each.
    `after_chunk(t)` may return a reason ("stopped", or anything the caller handles, e.g.
    "restart") to end early. With keep_partial, Ctrl-C ends the loop with reason
    "interrupted" (the simulator's logs then hold what was simulated up to that point);
    without it, KeyboardInterrupt propagates (studies and benchmarks must not go on with
    a cut-short simulation)."""
    t = simulator.get_context().get_time()
    if not keep_partial:
        return _advance(simulator, t, duration, chunk, after_chunk, bar)
    try:
        return _advance(simulator, t, duration, chunk, after_chunk, bar)
    except KeyboardInterrupt:
        return SimEnd(float(simulator.get_context().get_time()), "interrupted")


def _advance(simulator, t, duration, chunk, after_chunk, bar) -> SimEnd:
    reason = "completed"
    while t < duration - 1e-12:
        t = min(t + chunk, duration)
        simulator.AdvanceTo(t)
        if bar is not None:
            bar.update(t)
        if after_chunk is not None:
            request = after_chunk(t)
            if request:
                reason = request
                break
    return SimEnd(float(simulator.get_context().get_time()), reason)


def read_logs(sinks: dict, context, end: SimEnd | None = None) -> dict:
    """Drake log sinks {name: VectorLogSink} as {name: (t [T], data [T, n])}. Raises
    KeyboardInterrupt when a Ctrl-C (end.reason "interrupted") came before every sink had
    a sample: there is nothing to write."""
    logs = {}
    for name, sink in sinks.items():
        log = sink.FindLog(context)
        logs[name] = (log.sample_times().copy(), log.data().T.copy())
    if end is not None and end.reason == "interrupted" and any(
            len(t) == 0 for t, _ in logs.values()):
        raise KeyboardInterrupt
    return logs


def ending_fields(end: SimEnd | None, requested_s: float, wall_s: float) -> dict:
    """The summary.json fields that say how long the run simulated and how it ended:
    sim_duration_s (reached), sim_duration_requested_s, ended, interrupted,
    real_time_factor (reached / wall)."""
    reached = float(requested_s if end is None else end.t)
    reason = "completed" if end is None else end.reason
    return {"sim_duration_s": reached, "sim_duration_requested_s": float(requested_s),
            "ended": reason, "interrupted": reason == "interrupted",
            "wall_s": wall_s, "real_time_factor": reached / wall_s if wall_s > 0 else None}


__all__ = ["ENDINGS", "SimEnd", "advance", "ending_fields", "read_logs"]
