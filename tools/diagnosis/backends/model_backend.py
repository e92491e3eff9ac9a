"""The model protocol the rigid-object diagnosis and `evaluate` work against, its two
backends, and parallel rollouts.

A model is made from a scenario and the recording's step: `make_model(name, scenario,
dt)`, and offers
    name                         the backend's name (MODELS)
    size                         the object's size for error percentages, m
    rollout(x0, num_steps)       states [num_steps + 1, 13], recording layout, sampled
                                 every dt from the recording-layout start x0 (the bodies
                                 here have no input: recorded inputs are empty)
    step(x_plant)                one recording step from a plant-layout state:
                                 (next plant-layout state, contact impulses or counts)
Effects are parameter changes: a scenario with some keys changed is another model.
Backends:
  lcs    the controller's Anitescu LCS (tools/diagnosis/backends/rigid_model.py) - what C3 plans with
  drake  Drake's MultibodyPlant of the scenario's true world, SAP at a finer step
         (tools/diagnosis/backends/drake_backend.py) - what the user simulates

`Scorer` rolls one episode set out for lists of scenarios on worker processes (fork),
each chunk of episodes one job (at least one per worker, at most CHUNK episodes), with
a progress callback.
"""
from __future__ import annotations

import multiprocessing

import numpy as np

from adaptive_c3.tools.user_input import UserError

MODELS = ("lcs", "drake")
FAILED_SCORE = 500.0     # % of size scored for an episode whose rollout failed
CHUNK = 32               # at most this many episodes per job, at least `workers` jobs (a job
                         # builds its model once: an LCS build costs ~0.1-0.5 s)


def check_model(name: str) -> str:
    if name not in MODELS:
        raise UserError(f"unknown --model '{name}' (known: {', '.join(MODELS)})")
    return name


def make_model(name: str, scenario, dt: float):
    """The backend `name` of MODELS for this scenario at recording step dt (s)."""
    check_model(name)
    if name == "lcs":
        from adaptive_c3.tools.diagnosis.backends.rigid_model import RigidObjectModel
        return RigidObjectModel(scenario, dt)
    from adaptive_c3.tools.diagnosis.backends.drake_backend import DrakeRigidSimulator
    return DrakeRigidSimulator(scenario, dt)


def mean_position_error_pct(x_hat: np.ndarray, x: np.ndarray, size: float) -> float:
    """Mean over time of |p_hat - p| as % of size (evaluate's position_pct_mean)."""
    return float(np.mean(np.linalg.norm(x_hat[:, 0:3] - x[:, 0:3], axis=1)) / size * 100.0)


def _job(job):
    """(scores, rollouts or None) of one scenario on a chunk of episodes; a failed or
    non-finite rollout scores FAILED_SCORE (its rollout: None)."""
    name, scenario, dt, size, starts, episodes, keep = job
    model = make_model(name, scenario, dt)
    scores, rollouts = [], []
    for x0, x in zip(starts, episodes):
        try:
            with np.errstate(all="ignore"):
                x_hat = model.rollout(x0, len(x) - 1)
            score = mean_position_error_pct(x_hat, x, size)
            ok = np.isfinite(score)
        except (ValueError, RuntimeError, np.linalg.LinAlgError):
            x_hat, ok = None, False
        scores.append(score if ok else FAILED_SCORE)
        rollouts.append(x_hat if ok and keep else None)
    return scores, (rollouts if keep else None)


class Scorer:
    """Scores lists of scenarios of model `model` on a fixed episode set (recording-layout
    arrays [T_i, 13]) from the given starts (default: each episode's first row), on
    `workers` processes."""

    def __init__(self, episodes: list, dt: float, size: float, workers: int = 2,
                 model: str = "lcs", starts: list | None = None):
        self.episodes, self.dt, self.size = list(episodes), dt, size
        self.model = check_model(model)
        self.starts = ([np.asarray(x[0], float) for x in self.episodes] if starts is None
                       else [np.asarray(s, float) for s in starts])
        self.workers = max(1, int(workers))
        self._pool = None
        if self.workers > 1:
            self._pool = multiprocessing.get_context("fork").Pool(self.workers)

    def _chunks(self) -> list:
        n = len(self.episodes)
        count = max(self.workers, -(-n // CHUNK)) if self.workers > 1 else 1
        return [c for c in np.array_split(np.arange(n), min(count, max(n, 1))) if len(c)]

    def run(self, scenarios: list, progress=None, keep: bool = False):
        """([len(scenarios), episodes] scores, rollouts per scenario or None)."""
        chunks = self._chunks()
        jobs = [(self.model, s, self.dt, self.size, [self.starts[i] for i in c],
                 [self.episodes[i] for i in c], keep) for s in scenarios for c in chunks]
        mapper = self._pool.imap if self._pool else map
        parts = []
        for i, part in enumerate(mapper(_job, jobs)):
            parts.append(part)
            if progress:
                progress(i + 1, len(jobs))
        per = len(chunks)
        scores = np.array([sum((parts[k * per + j][0] for j in range(per)), [])
                           for k in range(len(scenarios))])
        rollouts = ([sum((parts[k * per + j][1] for j in range(per)), [])
                     for k in range(len(scenarios))] if keep else None)
        return scores, rollouts

    def __call__(self, scenarios: list, progress=None) -> np.ndarray:
        """[len(scenarios), episodes] scores."""
        return self.run(scenarios, progress)[0]

    def close(self):
        if self._pool:
            self._pool.terminate()
            self._pool = None
