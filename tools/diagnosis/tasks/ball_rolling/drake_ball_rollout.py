"""Rollouts of many ball-rolling windows through Drake's plant (ball_plant.py), batched
as copies of the world in one plant and spread over worker processes.

`simulate(world, forces, X0, inputs, substeps, dt)`: states [W, H, 19] (recording
layout) after each of the H recording steps from the starts X0 [W, 19] with the EE
force inputs [W, H, 3] (N, world, held over a step), SAP stepping world.time_step =
dt / substeps. `Roller` splits the windows into chunks of at most COPIES (one plant of
that many copies per chunk, built once per parameter set and process) and maps them
over a fork pool.
"""
from __future__ import annotations

import multiprocessing
from collections import OrderedDict

import numpy as np

from adaptive_c3.tools.diagnosis.tasks.ball_rolling.ball_forces import (
    BallForceCoefficients, add_ball_forces)
from adaptive_c3.tools.diagnosis.tasks.ball_rolling.ball_plant import (BallWorld,
                                                                      build_ball_plant)

COPIES = 64               # at most this many windows per plant (a job): ~55-65 us per
                          # window and SAP step (one world alone: ~270 us)
PAD = 4                   # plants have a multiple of PAD copies
_PLANTS: OrderedDict = OrderedDict()     # per process: (world, forces, copies) -> sim
_KEEP_PLANTS = 8


def _plant(world: BallWorld, forces: BallForceCoefficients, copies: int):
    from pydrake.systems.analysis import Simulator
    key = (world, forces, copies)
    if key in _PLANTS:
        _PLANTS.move_to_end(key)
        return _PLANTS[key]
    bp = build_ball_plant(world, copies,
                          add_systems=add_ball_forces(world, forces) if forces.any() else None)
    sim = Simulator(bp.diagram)
    ctx = sim.get_mutable_context()
    pctx = bp.plant.GetMyMutableContextFromRoot(ctx)
    entry = (bp, sim, ctx, pctx, ctx.Clone())
    _PLANTS[key] = entry
    while len(_PLANTS) > _KEEP_PLANTS:
        _PLANTS.popitem(last=False)
    return entry


def simulate(world: BallWorld, forces: BallForceCoefficients, X0: np.ndarray,
             inputs: np.ndarray, substeps: int) -> np.ndarray:
    """States [W, H, 19] (see the module doc); a window whose rollout fails is NaN."""
    W, H = inputs.shape[:2]
    out = np.full((W, H, 19), np.nan)
    if W == 0:
        return out
    bp, sim, ctx, pctx, initial = _plant(world, forces, W)
    plant, h = bp.plant, world.time_step
    port = plant.get_actuation_input_port()
    try:
        ctx.SetTimeStateAndParametersFrom(initial)
        plant.SetPositionsAndVelocities(pctx, bp.to_plant(X0))
        sim.Initialize()
        for k in range(H):
            port.FixValue(pctx, np.ascontiguousarray(inputs[:, k]).ravel())
            sim.AdvanceTo(((k + 1) * substeps - 0.5) * h)   # (k + 1) substeps updates
            out[:, k] = bp.from_plant(plant.GetPositionsAndVelocities(pctx))
    except RuntimeError:
        pass
    return out


def _padded(world, forces, X0, inputs, substeps):
    """simulate() on a plant of the next multiple of PAD copies (windows repeated), so
    that calls with slightly different window counts share plants."""
    W = len(X0)
    size = -(-W // PAD) * PAD
    idx = np.concatenate([np.arange(W), np.zeros(size - W, int)])
    return simulate(world, forces, X0[idx], inputs[idx], substeps)[:W]


def _job(job):
    return _padded(*job)


class Roller:
    """Runs `simulate` over chunks of windows on `workers` processes (fork, created on
    first use; close() ends them)."""

    def __init__(self, workers: int = 2):
        self.workers = max(1, int(workers))
        self._pool = None

    def __call__(self, world, forces, X0, inputs, substeps) -> np.ndarray:
        W = len(X0)
        n = self.workers * -(-W // (COPIES * self.workers))   # a multiple of the workers
        n = min(n, max(W, 1))
        if n <= 1 or self.workers <= 1:
            return np.concatenate([_padded(world, forces, X0[c], inputs[c], substeps)
                                   for c in np.array_split(np.arange(W), max(n, 1))], 0)
        if self._pool is None:
            self._pool = multiprocessing.get_context("fork").Pool(self.workers)
        chunks = np.array_split(np.arange(W), n)
        parts = self._pool.map(_job, [(world, forces, X0[c], inputs[c], substeps)
                                      for c in chunks])
        return np.concatenate(parts, 0)

    def close(self):
        if self._pool is not None:
            self._pool.terminate()
            self._pool.join()
            self._pool = None
