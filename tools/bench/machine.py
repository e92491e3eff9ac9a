"""The machine reference every bench JSON carries: two fixed workloads, timed here, so that
absolute times from different machines can be compared (divide by the same row's median).

  machine/python  a fixed pure-Python loop (integer arithmetic, 1 000 000 iterations)
  machine/drake   a fixed Drake workload: building a MultibodyPlant here (a 7-link
                  revolute chain under gravity and a ball dropped on a box, SAP contact,
                  1 ms steps) and simulating 1 s of it (1000 steps) through a Simulator

Both are frozen: changing either makes older JSON files incomparable. Rows: name,
median_ms (median of `repeats` runs), and runs, min_ms.
"""
from __future__ import annotations

import statistics
import time


def _python_workload() -> int:
    acc = 0
    for i in range(1_000_000):
        acc = (acc + i * i) % 1_000_003
    return acc


def _drake_simulator():
    import numpy as np
    from pydrake.geometry import Box, Sphere
    from pydrake.math import RigidTransform
    from pydrake.multibody.plant import (AddMultibodyPlant, CoulombFriction,
                                         MultibodyPlantConfig)
    from pydrake.multibody.tree import RevoluteJoint, SpatialInertia
    from pydrake.systems.analysis import Simulator
    from pydrake.systems.framework import DiagramBuilder
    builder = DiagramBuilder()
    plant, _ = AddMultibodyPlant(MultibodyPlantConfig(
        time_step=1e-3, discrete_contact_approximation="sap"), builder)
    parent = plant.world_body()
    for k in range(7):
        body = plant.AddRigidBody(f"link{k}", SpatialInertia.SolidBoxWithMass(
            1.0, 0.05, 0.05, 0.3))
        plant.AddJoint(RevoluteJoint(f"joint{k}", parent.body_frame(), body.body_frame(),
                                     [0.0, 1.0, 0.0] if k % 2 else [1.0, 0.0, 0.0]))
        parent = body
    ball = plant.AddRigidBody("ball", SpatialInertia.SolidSphereWithMass(0.1, 0.03))
    plant.RegisterCollisionGeometry(ball, RigidTransform(), Sphere(0.03), "ball",
                                    CoulombFriction(0.5, 0.5))
    plant.RegisterCollisionGeometry(plant.world_body(), RigidTransform([0, 0, -1.05]),
                                    Box(2.0, 2.0, 0.1), "ground", CoulombFriction(0.5, 0.5))
    plant.Finalize()
    diagram = builder.Build()
    sim = Simulator(diagram)
    ctx = plant.GetMyMutableContextFromRoot(sim.get_mutable_context())
    q = plant.GetPositions(ctx)
    q[:7] = 0.3
    q[7:] = [1.0, 0.0, 0.0, 0.0, 0.5, 0.0, -0.9]      # ball: quaternion, position
    plant.SetPositions(ctx, np.asarray(q))
    return sim


def _drake_workload() -> None:
    sim = _drake_simulator()
    sim.Initialize()
    sim.AdvanceTo(1.0)


def _timed(fn, repeats: int) -> list:
    out = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        out.append(1e3 * (time.perf_counter() - t))
    return out


def machine_rows(repeats: int = 5) -> list:
    rows = []
    for name, fn in (("machine/python", _python_workload), ("machine/drake", _drake_workload)):
        fn()                                   # warm-up (imports, first allocation)
        ms = _timed(fn, repeats)
        rows.append({"name": name, "median_ms": statistics.median(ms), "min_ms": min(ms),
                     "runs": repeats})
    return rows
