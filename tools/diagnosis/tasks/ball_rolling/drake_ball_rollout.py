"""Rollouts of many ball-rolling windows through Drake's plant (ball_plant.py), batched
as copies of the world in one plant and spread over worker processes.

`simulate(world, forces, X0, inputs, substeps)`: states [W, H, 19] (recording layout)
after each of the H recording steps from the starts X0 [W, 19] with the EE force inputs
[W, H, 3] (N, world, held over a step), SAP stepping world.time_step = dt / substeps.
`Roller` splits the windows into chunks of at most COPIES and maps them over a fork pool.

A plant of N copies is built once per process (`Batch`) and serves every parameter set:
the world's parameters are written into its context (SceneGraph's proximity properties
and EE shape, the ball's spatial inertia, BallForces' parameter), and the table height
is a shift of the z states (the plant's table top stays at z = 0, so the starts go in at
z - table_z and come out at z + table_z). Each step is the plant's forced discrete update
(no Simulator). The results equal a plant built for that world (tests).
"""
from __future__ import annotations

import multiprocessing
from collections import OrderedDict
from dataclasses import replace

import numpy as np

from adaptive_c3.tools.diagnosis.tasks.ball_rolling.ball_forces import (
    BallForceCoefficients, add_ball_forces)
from adaptive_c3.tools.diagnosis.tasks.ball_rolling.ball_plant import (
    BallWorld, build_ball_plant, proximity_properties)

COPIES = 16               # at most this many windows per plant (a job): ~34 us CPU per
                          # window and SAP step with sampled output ports, ~24-27 us
                          # without (52 copies: ~41 us, SAP iterates one problem until
                          # its worst window converges; 4 copies: ~37 us; both sampled)
Z_ROWS = (2, 9)           # recording rows of the EE and ball z (shifted by the table height)
_BATCHES: OrderedDict = OrderedDict()    # per process: Batch.key -> Batch
_KEEP_BATCHES = 2 * COPIES   # every chunk size 1..COPIES, with and without forces


class Batch:
    """A plant of `copies` worlds built once (table top at z = 0), its context, and the
    world and forces presently written into that context."""

    def __init__(self, world: BallWorld, copies: int, with_forces: bool):
        from pydrake.geometry import RoleAssign
        self._replace = RoleAssign.kReplace
        built = replace(world, table_z=0.0)
        hook = add_ball_forces(built, BallForceCoefficients()) if with_forces else None
        self.bp = bp = build_ball_plant(built, copies, add_systems=hook,
                                        sampled_outputs=False)     # only states are read
        self.ctx = bp.diagram.CreateDefaultContext()
        self.pctx = bp.plant.GetMyMutableContextFromRoot(self.ctx)
        self.sg = bp.diagram.GetSubsystemByName("scene_graph")
        self.sgctx = self.sg.GetMyMutableContextFromRoot(self.ctx)
        self.forces_sys = bp.diagram.GetSubsystemByName("ball_forces") if with_forces else None
        self.fctx = (self.forces_sys.GetMyMutableContextFromRoot(self.ctx)
                     if with_forces else None)
        inspector = self.sg.model_inspector()
        self.source = bp.plant.get_source_id()
        self.geometries = {"ee": [], "ball": [], "table": []}
        for gid in inspector.GetAllGeometryIds():
            self.geometries[inspector.GetName(gid).split("::")[-1]].append(gid)
        plant = bp.plant
        self.ees = [plant.GetBodyByName("ee", plant.GetModelInstanceByName(
            "ee" + ("" if i == 0 else f"_{i}"))) for i in range(copies)]
        self.balls = [plant.get_body(b) for b in bp.ball_bodies]
        self.world, self.forces = built, BallForceCoefficients()

    @staticmethod
    def key(world: BallWorld, copies: int, with_forces: bool) -> tuple:
        """What a built plant fixes: the SAP step, the EE mass, the ball radius, N."""
        return (world.time_step, world.ee_mass, world.ball_radius, copies, with_forces)

    def set_world(self, world: BallWorld, forces: BallForceCoefficients) -> None:
        """Write the parameters that differ from the context's present ones."""
        from pydrake.geometry import Sphere
        from pydrake.multibody.tree import SpatialInertia
        old = self.world
        for group, mu in (("ee", "mu_ee"), ("ball", "mu_ball"), ("table", "mu_table")):
            new = (world.stiffness, world.relaxation_time, getattr(world, mu))
            if new != (old.stiffness, old.relaxation_time, getattr(old, mu)):
                props = proximity_properties(*new)
                for gid in self.geometries[group]:
                    self.sg.AssignRole(self.sgctx, self.source, gid, props, self._replace)
        if world.ee_radius != old.ee_radius:
            inertia = SpatialInertia.SolidSphereWithMass(world.ee_mass, world.ee_radius)
            for gid in self.geometries["ee"]:
                self.sg.ChangeShape(self.sgctx, self.source, gid, Sphere(world.ee_radius))
            for body in self.ees:
                body.SetSpatialInertiaInBodyFrame(self.pctx, inertia)
        if world.ball_mass != old.ball_mass:
            inertia = SpatialInertia.SolidSphereWithMass(world.ball_mass, world.ball_radius)
            for body in self.balls:
                body.SetSpatialInertiaInBodyFrame(self.pctx, inertia)
        if self.forces_sys is not None and (forces, world.ball_mass) != (self.forces,
                                                                         old.ball_mass):
            self.forces_sys.set_coefficients(self.fctx, forces, world.ball_mass)
        self.world, self.forces = world, forces

    def run(self, X0: np.ndarray, inputs: np.ndarray, substeps: int) -> np.ndarray:
        """States [N, H, 19] from the starts X0 [N, 19] under inputs [N, H, 3] (the
        world set by set_world)."""
        bp, plant, ctx, pctx = self.bp, self.bp.plant, self.ctx, self.pctx
        W, H = inputs.shape[:2]
        shift = np.zeros(19)
        shift[list(Z_ROWS)] = self.world.table_z
        out = np.full((W, H, 19), np.nan)
        port = plant.get_actuation_input_port()
        try:
            ctx.SetTime(0.0)
            plant.SetPositionsAndVelocities(pctx, bp.to_plant(X0 - shift))
            for k in range(H):
                port.FixValue(pctx, np.ascontiguousarray(inputs[:, k]).ravel())
                for _ in range(substeps):
                    bp.diagram.ExecuteForcedEvents(ctx, False)
                out[:, k] = bp.from_plant(plant.GetPositionsAndVelocities(pctx)) + shift
        except RuntimeError:
            pass                                   # the steps not reached stay NaN
        return out


def _batch(world: BallWorld, forces: BallForceCoefficients, copies: int) -> Batch:
    key = Batch.key(world, copies, forces.any())
    if key in _BATCHES:
        _BATCHES.move_to_end(key)
    else:
        _BATCHES[key] = Batch(world, copies, forces.any())
        while len(_BATCHES) > _KEEP_BATCHES:
            _BATCHES.popitem(last=False)
    batch = _BATCHES[key]
    batch.set_world(world, forces)
    return batch


def simulate(world: BallWorld, forces: BallForceCoefficients, X0: np.ndarray,
             inputs: np.ndarray, substeps: int) -> np.ndarray:
    """States [W, H, 19] (see the module doc); the steps a failed rollout did not reach
    are NaN."""
    W, H = inputs.shape[:2]
    if W == 0:
        return np.full((0, H, 19), np.nan)
    return _batch(world, forces, W).run(np.asarray(X0, float), inputs, substeps)


def _job(job):
    return simulate(*job)


def _chunks(W: int, workers: int) -> list:
    """Window index chunks of at most COPIES windows, a multiple of the workers in
    number (when W allows) and of equal size within one window, so that the workers
    finish together."""
    n = max(1, min(W, workers * -(-W // (COPIES * workers))))
    return np.array_split(np.arange(W), n)


class Roller:
    """Runs `simulate` over chunks of windows on `workers` processes (fork, created on
    first use; close() ends them)."""

    def __init__(self, workers: int = 2):
        self.workers = max(1, int(workers))
        self._pool = None

    def __call__(self, world, forces, X0, inputs, substeps) -> np.ndarray:
        W = len(X0)
        chunks = _chunks(W, self.workers)
        if len(chunks) <= 1 or self.workers <= 1:
            return np.concatenate([simulate(world, forces, X0[c], inputs[c], substeps)
                                   for c in chunks], 0)
        if self._pool is None:
            self._pool = multiprocessing.get_context("fork").Pool(self.workers)
        parts = self._pool.map(_job, [(world, forces, X0[c], inputs[c], substeps)
                                      for c in chunks], chunksize=1)
        return np.concatenate(parts, 0)

    def close(self):
        if self._pool is not None:
            self._pool.terminate()
            self._pool.join()
            self._pool = None
