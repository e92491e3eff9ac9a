"""Bench rows of C3 on the real ball-rolling model's LCSs (not a random LCS of that size).

`c3/ballroll_model/c3plus/kkt`: this project's C3 with the shipped scenario's roll-phase
options, solving on Anitescu LCSs of the controller model (models/ball_rolling_controller_
model.py, planning dt 0.1 s, m = 8) linearised at EE-on-the-ball states around the target
circle, towards the gait's roll target. `c3/ballroll_model/baseline_fresh_mathprog_c3plus`:
the same ADMM with a fresh Drake MathematicalProgram per QP step (tools/bench/c3.py).
Each row also reports the C3 fall-back counts of its solves.
"""
from __future__ import annotations

import time

import numpy as np

from adaptive_c3.models.ball_rolling_controller_model import (EE_POS, EE_VEL, BALL_VEL,
                                                              ball_rolling_linearizer,
                                                              default_state)

__all__ = ["ball_model_problems", "run_ball_model_rows"]

GRAVITY = 9.81


def ball_model_problems(count: int, seed: int = 0):
    """[(lcs, x, x_target)] at `count` states: the ball on the shipped scenario's circle,
    the EE resting on its top, small random EE and ball velocities (seeded); the
    scenario's model (5 mm too large) and its roll-phase target. Also returns the
    roll-phase C3Options."""
    from adaptive_c3.diagrams.ball_rolling import c3_options, make_gait
    from adaptive_c3.scenarios.schema import SCENARIO_DIR, load_scenario
    s, _ = load_scenario(SCENARIO_DIR / "ball_rolling.yaml")
    m = s.model
    lin = ball_rolling_linearizer(dt=m.planning_dt, num_edges=m.friction_edges,
                                  eps_c=m.eps_c, ball_radius=m.ball_radius,
                                  ball_mass=m.ball_mass, ee_radius=m.ee_radius,
                                  ee_mass=m.ee_mass, mu=m.friction)
    gait = make_gait(s)
    rng = np.random.default_rng(seed)
    u_rest = np.array([0.0, 0.0, m.ee_mass * GRAVITY])
    out = []
    for a in np.linspace(0.0, 2 * np.pi, count, endpoint=False):
        xy = np.asarray(s.target.center) + s.target.radius * np.array([np.cos(a), np.sin(a)])
        x = default_state(tuple(xy), ee_offset=(0.0, 0.0, m.ball_radius + m.ee_radius),
                          ball_radius=m.ball_radius, ee_radius=m.ee_radius)
        x[EE_VEL] = 0.02 * rng.normal(size=3)
        x[BALL_VEL] = 0.02 * rng.normal(size=3)
        lcs = lin.linearize(x, u_rest)
        out.append((lcs, x, gait.target_state("roll", x)))
    return out, c3_options(s, "roll", len(lin.lambda_names()))


def _timed_solves(solve, problems):
    times = []
    for lcs, x, xt in problems:
        t0 = time.perf_counter()
        solve(lcs, x, xt)
        times.append(time.perf_counter() - t0)
    return np.asarray(times) * 1e3


def run_ball_model_rows(baseline, quick: bool = False) -> list[dict]:
    """The two rows; baseline: the fresh-MathematicalProgram C3 class
    (tools/bench/c3.FreshMathProgC3, passed in so that module can call this one)."""
    from adaptive_c3.systems.c3.solver import C3Solver
    problems, options = ball_model_problems(8 if quick else 24)
    solver = C3Solver(options)           # warm-started from solve to solve, as in a run
    ours = _timed_solves(lambda lcs, x, xt: solver.solve(lcs, x, xt), problems)
    fresh = baseline(options)
    base = _timed_solves(fresh.solve, problems[: 4 if quick else 8])
    base_name = "c3/ballroll_model/baseline_fresh_mathprog_c3plus"
    note = f"{len(problems)} Anitescu LCSs of the ball-rolling model (EE on the ball)"
    return [{"name": "c3/ballroll_model/c3plus/kkt", "median_ms": float(np.median(ours)),
             "max_ms": float(ours.max()), "solves": int(ours.size), "baseline": base_name,
             "speedup": float(np.median(base) / np.median(ours)), "note": note,
             "fallbacks": dict(solver.fallbacks)},
            {"name": base_name, "median_ms": float(np.median(base)),
             "max_ms": float(base.max()), "solves": int(base.size), "note": note}]
