"""Tuning Drake's contact knobs to recordings: `tune_drake` fits the `drake` knobs of a
rigid_object scenario (friction, point stiffness, relaxation time) to recorded episodes
(coarse log grid, then Nelder-Mead) by the median over episodes of the mean position
error. The simulator itself is tools/diagnosis/backends/drake_backend.py's (the `drake` model
backend); it is imported here under its old name for the callers of this module.
At the cube's dt of 1/148 s the default point stiffness sits in SAP's near-rigid regime.
"""
from __future__ import annotations

import copy
import dataclasses
import math

import numpy as np

from adaptive_c3.tools.diagnosis.backends.drake_backend import DrakeRigidSimulator  # noqa: F401
from adaptive_c3.tools.diagnosis.backends.model_backend import mean_position_error_pct

KNOBS = ("friction", "point_stiffness", "relaxation_time")
# search ranges of the knobs (schema units), searched on a log scale
KNOB_RANGES = {"friction": (0.02, 1.0),                   # mu
               "point_stiffness": (3.0e2, 1.0e5),         # N/m
               "relaxation_time": (1.0e-3, 1.0)}          # s
MAX_TUNE_EPISODES = 40


# ---------------------------------------------------------------------- tuning
def score_episodes(sim: DrakeRigidSimulator, episodes) -> float:
    """Median over episodes of the mean-over-time position error (% of size)."""
    return float(np.median([mean_position_error_pct(sim.rollout(x[0], len(x) - 1), x, sim.size)
                            for x in episodes]))


def with_drake(scenario, **values):
    """A copy of the scenario with these `drake` fields replaced (the original untouched)."""
    s = copy.deepcopy(scenario)
    return dataclasses.replace(s, drake=dataclasses.replace(s.drake, **values))


def tune_drake(scenario, episodes, dt: float, knobs=KNOBS, max_evals: int = 80,
               grid_points: int = 7, max_episodes: int = MAX_TUNE_EPISODES,
               info: dict | None = None) -> tuple[dict, float]:
    """Fit `knobs` of scenario.drake to recorded episodes (recording-layout arrays
    [T_i, 13]) by minimising the median over episodes of the mean-over-time position
    error (% of the object's size). Returns ({knob: value in the schema's units}, that
    score); the caller's scenario is not changed.

    Search, on log10 of each knob within KNOB_RANGES, at most max_evals simulations of
    the episode set (each ~0.5 s for 40 episodes of ~100 rows, one core):
    1. the scenario's own values (a knob may be its "Drake default" sentinel: friction
       < 0, point_stiffness 0, relaxation_time 0 - the value returned when it stays best);
    2. a coarse grid, one knob at a time in the order given (grid_points log-spaced
       values, the others at their best so far). A knob whose grid leaves the score
       unchanged to 1e-12 has no effect here (e.g. point_stiffness on a body that never
       touches) and keeps its value;
    3. Nelder-Mead (scipy, bounded) from the best point so far over the knobs that have
       an effect (a sentinel starts from its numeric stand-in, see _numeric), with the
       remaining evaluations; the best point evaluated is returned.
    More than max_episodes episodes are subsampled evenly (every k-th) to keep the
    run time under a minute (measured: 80 evaluations on 39 cube tosses, 35 s). `info`, if given, receives the details (default score,
    evaluations, episodes used, knobs without effect)."""
    from scipy.optimize import minimize

    knobs = tuple(knobs)
    unknown = [k for k in knobs if k not in KNOB_RANGES]
    if unknown or not knobs:
        raise ValueError(f"unknown knobs {unknown} (known: {list(KNOB_RANGES)})")
    episodes = [np.asarray(x, float) for x in episodes]
    if not episodes or any(x.ndim != 2 or x.shape[1] != 13 or len(x) < 2 for x in episodes):
        raise ValueError("episodes must be a non-empty list of [T >= 2, 13] arrays")
    if len(episodes) > max_episodes:
        idx = np.unique(np.linspace(0, len(episodes) - 1, max_episodes).round().astype(int))
        episodes = [episodes[i] for i in idx]

    cache: dict = {}

    def evaluate(values: dict) -> float:
        key = tuple(round(float(values[k]), 12) for k in knobs)
        if key not in cache:
            if len(cache) >= max_evals:
                raise _Budget
            cache[key] = score_episodes(DrakeRigidSimulator(with_drake(scenario, **values), dt),
                                        episodes)
        return cache[key]

    best = {k: float(getattr(scenario.drake, k)) for k in knobs}
    default_score = evaluate(best)
    no_effect = []
    try:
        for k in knobs:
            lo, hi = KNOB_RANGES[k]
            here = evaluate(best)
            grid = np.geomspace(lo, hi, grid_points)
            scores = [evaluate({**best, k: float(v)}) for v in grid]
            if max(abs(s - here) for s in scores) <= 1e-12:
                no_effect.append(k)
                continue
            i = int(np.argmin(scores))
            if scores[i] < here:
                best[k] = float(grid[i])
        free = [k for k in knobs if k not in no_effect]
        if free and len(cache) < max_evals:
            lo = np.log10([KNOB_RANGES[k][0] for k in free])
            hi = np.log10([KNOB_RANGES[k][1] for k in free])
            u0 = np.clip(np.log10([_numeric(scenario, k, best[k]) for k in free]), lo, hi)
            step = 0.5 * (hi - lo) / max(grid_points - 1, 1)    # half a grid spacing
            step = np.where(u0 + step <= hi, step, -step)
            simplex = np.vstack([u0, u0 + np.diag(step)])

            def f(u):
                u = np.clip(u, lo, hi)
                return evaluate({**best, **{k: float(10 ** ui) for k, ui in zip(free, u)}})

            minimize(f, u0, method="Nelder-Mead", bounds=list(zip(lo, hi)),
                     options={"initial_simplex": simplex, "xatol": 0.01, "fatol": 1e-3,
                              "maxfev": max_evals})
    except _Budget:
        pass
    # the best point evaluated (the scenario's own values on a tie)
    best_key = min(cache, key=cache.get)
    best_score = cache[best_key]
    values = dict(zip(knobs, best_key))
    if info is not None:
        info.update(default_score=default_score, evaluations=len(cache),
                    episodes=len(episodes), no_effect=no_effect)
    return values, best_score


def _numeric(scenario, knob: str, value: float) -> float:
    """A start value for Nelder-Mead standing in for a knob's "default" sentinel:
    contact.friction for friction (the same plant), the top of the range for
    point_stiffness (Drake's default is near-rigid under SAP at the cube's dt), the
    range's geometric middle for the relaxation time."""
    if knob == "friction" and value < 0:
        return float(scenario.contact.friction)
    if knob == "point_stiffness" and value <= 0:
        return KNOB_RANGES[knob][1]
    if knob == "relaxation_time" and value <= 0:
        return math.sqrt(KNOB_RANGES[knob][0] * KNOB_RANGES[knob][1])
    return value


class _Budget(Exception):
    """max_evals reached."""
