"""The drake ball backend's batched rollouts (drake_ball_rollout.py): one plant built per
process serves every parameter set through its context, with the results of a plant built
for that world."""
from dataclasses import replace

import numpy as np

from adaptive_c3.tools.diagnosis.tasks.ball_rolling import drake_ball_rollout as R
from adaptive_c3.tools.diagnosis.tasks.ball_rolling.ball_forces import (BallForceCoefficients,
                                                                        add_ball_forces)
from adaptive_c3.tools.diagnosis.tasks.ball_rolling.ball_plant import BallWorld, build_ball_plant

SUBSTEPS = 4
NOMINAL = BallWorld(time_step=0.0025)


def _starts(n: int, seed: int = 0):
    """n starts [n, 19] with the ball resting on a table at z = 0 under a pressing EE (the
    EE 0.5-1.5 mm into the ball, pushing sideways), and 3 steps of EE force [n, 3, 3]."""
    rng = np.random.default_rng(seed)
    w = NOMINAL
    X = np.zeros((n, 19))
    X[:, 3] = 1.0                                        # ball quaternion
    X[:, 7:9] = rng.uniform(-0.02, 0.02, (n, 2))
    X[:, 9] = w.ball_radius - 2e-4                       # slightly into the table
    d = rng.normal(size=(n, 3)) * [1, 1, 0] + [0, 0, 3]
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    gap = rng.uniform(-1.5e-3, -0.5e-3, (n, 1))
    X[:, 0:3] = X[:, 7:10] + d * (w.ee_radius + w.ball_radius + gap)
    X[:, 16:18] = rng.uniform(-0.2, 0.2, (n, 2))         # ball rolling
    U = rng.uniform(-3, 3, (n, 3, 3)) + [0, 0, 9.81 * w.ee_mass - 2]
    return X, U


def _reference(world, forces, X0, U):
    """The plain way: a plant built for this world (its table at table_z), simulated with
    Drake's Simulator."""
    from pydrake.systems.analysis import Simulator
    bp = build_ball_plant(world, len(X0), add_systems=add_ball_forces(world, forces)
                          if forces.any() else None)
    sim = Simulator(bp.diagram)
    ctx = sim.get_mutable_context()
    pctx = bp.plant.GetMyMutableContextFromRoot(ctx)
    bp.plant.SetPositionsAndVelocities(pctx, bp.to_plant(X0))
    sim.Initialize()
    out = np.zeros(U.shape[:2] + (19,))
    for k in range(U.shape[1]):
        bp.plant.get_actuation_input_port().FixValue(pctx, U[:, k].ravel())
        sim.AdvanceTo(((k + 1) * SUBSTEPS - 0.5) * world.time_step)
        out[:, k] = bp.from_plant(bp.plant.GetPositionsAndVelocities(pctx))
    return out


def test_one_built_plant_serves_each_parameter_set_as_a_plant_built_for_it():
    """The same batch (one plant of 4 copies, with the force elements) runs the nominal
    world, then a world with every parameter changed (friction, stiffness, relaxation,
    EE radius, table 2 mm lower, ball mass, forces), then the nominal again: each equals a
    plant built for that world to rounding, and the changed world differs visibly."""
    R._BATCHES.clear()
    X0, U = _starts(4)
    forces = BallForceCoefficients(rolling=0.003, torsional=0.002, drag=0.2, force=(0.03, -0.02))
    changed = replace(NOMINAL, mu_ee=0.4, mu_table=0.7, stiffness=3e4, relaxation_time=5e-3,
                      ee_radius=0.0185, table_z=-0.002, ball_mass=0.2)
    X0c = X0.copy()
    X0c[:, [2, 9]] -= 0.002                       # the same starts on the lower table
    small = BallForceCoefficients(drag=1e-9)      # the batch with the force elements
    runs = [(NOMINAL, small, X0), (changed, forces, X0c), (NOMINAL, small, X0)]
    outs = []
    for world, f, X in runs:
        got = R.simulate(world, f, X, U, SUBSTEPS)
        ref = _reference(world, f, X, U)
        assert np.all(np.isfinite(got))
        np.testing.assert_allclose(got, ref, rtol=0, atol=1e-9)
        outs.append(got)
    assert len(R._BATCHES) == 1                   # one plant built for all three
    moved = np.abs((outs[1] - X0c[:, None]) - (outs[0] - X0[:, None]))[..., 7:9].max()
    assert moved > 1e-4, moved                    # the changed world rolls the ball otherwise
    np.testing.assert_array_equal(outs[0], outs[2])


def test_a_batch_without_force_elements_is_shared_by_worlds_and_matches_a_built_plant():
    R._BATCHES.clear()
    X0, U = _starts(3, seed=1)
    none = BallForceCoefficients()
    for world in (replace(NOMINAL, mu_ee=0.3), replace(NOMINAL, ee_radius=0.021)):
        np.testing.assert_allclose(R.simulate(world, none, X0, U, SUBSTEPS),
                                   _reference(world, none, X0, U), rtol=0, atol=1e-9)
    assert len(R._BATCHES) == 1                   # both on one 3-copy plant


def test_windows_are_chunked_evenly_over_the_workers():
    for W in (1, 3, 13, 40, 104, 1203):
        for workers in (1, 2):
            chunks = R._chunks(W, workers)
            np.testing.assert_array_equal(np.concatenate(chunks), np.arange(W))
            sizes = [len(c) for c in chunks]
            assert max(sizes) <= R.COPIES and max(sizes) - min(sizes) <= 1
            if W >= workers:
                assert len(chunks) % workers == 0
