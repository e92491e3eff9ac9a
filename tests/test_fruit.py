"""Fruit objects (models/fruit.py): sampling, mesh, inertia, and contact behaviour.

The simulations use the project's table (add_table) made rigid-hydroelastic, a SAP
plant with time step 1e-3, and the fruit's compliant-hydroelastic convex hull.
"""
import numpy as np
import pytest
from pydrake.geometry import Mesh, Sphere
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.multibody.math import SpatialForce
from pydrake.multibody.plant import (AddMultibodyPlant, CoulombFriction,
                                     ExternallyAppliedSpatialForce,
                                     MultibodyPlantConfig)
from pydrake.multibody.tree import CalcSpatialInertia
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

from adaptive_c3.models.ball_rolling_scene import add_ball, add_table
from adaptive_c3.models.fruit import (FRUIT_KINDS, _RANGES, add_fruit, cached_mesh_path,
                                      fruit_mesh, make_rigid_hydroelastic,
                                      mass_properties, sample_fruit, write_fruit_mesh)

XY = (0.5, 0.0)


@pytest.fixture(scope="module")
def mesh_dir(tmp_path_factory):
    return tmp_path_factory.mktemp("fruit_meshes")


def read_obj(path):
    v, f = [], []
    for line in open(path):
        if line.startswith("v "):
            v.append([float(x) for x in line.split()[1:]])
        elif line.startswith("f "):
            f.append([int(x) - 1 for x in line.split()[1:]])
    return np.array(v), np.array(f)


def test_sampling_is_reproducible_varied_and_in_range():
    for kind in FRUIT_KINDS:
        assert sample_fruit(kind, 7) == sample_fruit(kind, 7)
        specs = [sample_fruit(kind, s) for s in range(20)]
        assert len({s.radius for s in specs}) == 20
        r = _RANGES[kind]
        for s in specs:
            assert r["radius"][0] <= s.radius <= r["radius"][1]
            assert r["mass"][0] <= s.mass <= r["mass"][1]
            assert r["elongation"][0] <= s.elongation <= r["elongation"][1]
            assert 1e-3 <= s.bump_amplitude <= 3e-3
        v0, _ = fruit_mesh(specs[0])
        v1, _ = fruit_mesh(specs[1])
        assert np.abs(v0 - v1).max() > 1e-3          # shapes differ across seeds
    with pytest.raises(ValueError):
        sample_fruit("banana", 0)


@pytest.mark.parametrize("kind", FRUIT_KINDS)
def test_mesh_is_closed_out_of_round_and_reproducible(kind, tmp_path):
    spec = sample_fruit(kind, 3)
    p1 = write_fruit_mesh(spec, tmp_path / "a.obj")
    p2 = write_fruit_mesh(sample_fruit(kind, 3), tmp_path / "b.obj")
    assert p1.read_text().splitlines()[1:] == p2.read_text().splitlines()[1:]
    v, f = read_obj(p1)
    edges = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    assert np.all(counts == 2)                        # closed, manifold
    volume, centroid, _ = mass_properties(v, f)
    assert volume == pytest.approx(4 / 3 * np.pi * spec.radius ** 3, rel=1e-4)
    assert np.linalg.norm(centroid) < 1e-6
    radii = np.linalg.norm(v, axis=1)
    assert radii.std() / radii.mean() > 0.01          # out of round
    evals = np.linalg.eigvalsh(np.cov(v.T))           # principal extents
    ratio = np.sqrt(evals[-1] / evals[0])
    if kind == "lime":
        assert ratio == pytest.approx(spec.elongation, rel=0.12)
    else:
        assert ratio < 1.15


@pytest.mark.parametrize("kind", FRUIT_KINDS)
def test_mass_and_inertia(kind, mesh_dir):
    spec = sample_fruit(kind, 1)
    builder = DiagramBuilder()
    plant, _ = AddMultibodyPlant(MultibodyPlantConfig(time_step=1e-3), builder)
    body = add_fruit(plant, spec, mesh_dir=mesh_dir, settle=False)
    plant.Finalize()
    M = body.default_spatial_inertia()
    assert M.get_mass() == pytest.approx(spec.mass)
    assert np.allclose(M.get_com(), 0.0)
    I = M.CalcRotationalInertia().CopyToFullMatrix3()
    assert np.all(np.linalg.eigvalsh(I) > 0)
    # Drake's own mesh integration at the same density agrees.
    ref = CalcSpatialInertia(Mesh(str(cached_mesh_path(spec, mesh_dir))), spec.density)
    assert ref.get_mass() == pytest.approx(spec.mass, rel=1e-4)
    assert np.allclose(ref.CalcRotationalInertia().CopyToFullMatrix3(), I,
                       rtol=1e-4, atol=1e-10)
    sphere = 0.4 * spec.mass * spec.radius ** 2        # solid sphere, same volume
    assert np.trace(I) / 3 == pytest.approx(sphere, rel=0.1)


def make_sim(kind, seed, mesh_dir, *, settle=True, ball=False):
    builder = DiagramBuilder()
    plant, sg = AddMultibodyPlant(MultibodyPlantConfig(
        time_step=1e-3, discrete_contact_approximation="sap"), builder)
    add_table(plant)
    spec = sample_fruit(kind, seed)
    if ball:   # the rigid ball of the same size and mass, as the scene adds it
        inst = add_ball(plant, radius=spec.radius, mass=spec.mass)
        body = plant.GetBodyByName("ball", inst)
        plant.SetDefaultFloatingBaseBodyPose(body, RigidTransform([*XY, spec.radius]))
    else:
        body = add_fruit(plant, spec, position=XY, mesh_dir=mesh_dir, settle=settle)
    plant.Finalize()
    make_rigid_hydroelastic(plant, sg)
    sim = Simulator(builder.Build())
    return sim, plant, body, spec


def advance(sim, plant, body, t):
    sim.AdvanceTo(t)
    ctx = plant.GetMyContextFromRoot(sim.get_context())
    V = plant.EvalBodySpatialVelocityInWorld(ctx, body)
    return (plant.EvalBodyPoseInWorld(ctx, body).translation().copy(),
            np.linalg.norm(V.translational()))


@pytest.mark.parametrize("kind", FRUIT_KINDS)
def test_dropped_fruit_settles_at_about_its_radius(kind, mesh_dir):
    sim, plant, body, spec = make_sim(kind, 2, mesh_dir, settle=False)
    ctx = plant.GetMyMutableContextFromRoot(sim.get_mutable_context())
    plant.SetFreeBodyPose(ctx, body, RigidTransform(
        RollPitchYaw(0.7, -1.1, 0.3), [*XY, spec.radius * 1.3 + 0.01]))
    p, speed = advance(sim, plant, body, 2.5)
    results = plant.get_contact_results_output_port().Eval(ctx)
    assert results.num_hydroelastic_contacts() == 1    # a pressure patch, not a point
    assert speed < 5e-3   # measured 2.5e-3 (orange, slow creep into its dent)
    h = p[2] / spec.radius
    print(f"{kind}: rest height {p[2] * 1e3:.2f} mm = {h:.3f} R, speed {speed:.1e}")
    if kind == "orange":
        assert 0.88 < h < 1.05
    else:   # a lime lies on its side: about R e^(-1/3), minus the squash
        assert 0.8 < h < 1.0


@pytest.mark.parametrize("kind", FRUIT_KINDS)
def test_starts_at_rest(kind, mesh_dir):
    sim, plant, body, spec = make_sim(kind, 0, mesh_dir)
    p0, _ = advance(sim, plant, body, 0.0)
    p, speed = advance(sim, plant, body, 0.5)
    assert np.linalg.norm(p - p0) < 5e-4 and speed < 2e-3


def push(sim, plant, body, force, t_push, t_end):
    """Constant horizontal force at the centroid for t_push, then free until t_end.
    Returns the x travel at release and at the end."""
    ctx = plant.GetMyMutableContextFromRoot(sim.get_mutable_context())
    port = plant.get_applied_spatial_force_input_port()
    f = ExternallyAppliedSpatialForce()
    f.body_index, f.p_BoBq_B = body.index(), np.zeros(3)
    f.F_Bq_W = SpatialForce(np.zeros(3), np.array([force, 0.0, 0.0]))
    port.FixValue(ctx, [f])
    x_release = advance(sim, plant, body, t_push)[0][0] - XY[0]
    f.F_Bq_W = SpatialForce(np.zeros(3), np.zeros(3))
    port.FixValue(ctx, [f])
    p, speed = advance(sim, plant, body, t_end)
    return x_release, p[0] - XY[0], speed


@pytest.mark.parametrize("kind", FRUIT_KINDS)
def test_small_push_rolls_back_where_a_ball_rolls_away(kind, mesh_dir):
    force = 0.3 * sample_fruit(kind, 0).mass   # ~3 % of the weight, for 0.5 s
    sim, plant, body, _ = make_sim(kind, 0, mesh_dir)
    x_rel, x_end, speed = push(sim, plant, body, force, 0.5, 1.3)
    print(f"{kind}: push {force:.3f} N: x at release {x_rel * 1e3:.2f} mm, "
          f"end {x_end * 1e3:.2f} mm, speed {speed:.1e}")
    assert x_rel > 3e-4                     # the push moved it ...
    assert abs(x_end) < 0.5 * x_rel         # ... and it rolled (at least half) back
    assert speed < 3e-3
    sim, plant, ball, _ = make_sim(kind, 0, mesh_dir, ball=True)
    _, x_ball, _ = push(sim, plant, ball, force, 0.5, 1.3)
    print(f"  rigid ball: end {x_ball * 1e3:.1f} mm")
    assert x_ball > 20 * abs(x_end) and x_ball > 0.02


def test_strong_push_rolls_the_orange_away(mesh_dir):
    sim, plant, body, spec = make_sim("orange", 0, mesh_dir)
    x_rel, x_end, _ = push(sim, plant, body, 0.33 * spec.mass * 9.81, 0.5, 1.0)
    print(f"orange strong push: release {x_rel * 1e3:.1f} mm, end {x_end * 1e3:.1f} mm")
    assert x_end > 0.03


@pytest.mark.parametrize("half_space", [False, True])
def test_tip_sphere_touches_fruit_by_point_contact(mesh_dir, half_space):
    """The Panda tip (a sphere without hydroelastic properties) meets the fruit with
    fallback point contact; the fruit meets the table (box or the half space the fruit
    scenes use) with hydroelastic contact."""
    builder = DiagramBuilder()
    plant, sg = AddMultibodyPlant(MultibodyPlantConfig(
        time_step=1e-3, discrete_contact_approximation="sap"), builder)
    add_table(plant, half_space=half_space)
    spec = sample_fruit("orange", 0)
    body = add_fruit(plant, spec, position=XY, mesh_dir=mesh_dir)
    X = plant.GetDefaultFloatingBaseBodyPose(body)
    v_W = X.multiply(fruit_mesh(spec)[0].T).T       # fruit vertices in the world
    back = v_W[np.argmin(v_W[:, 0])]                 # its rearmost point
    tip_center = back + [-0.0195 + 0.001, 0, 0]      # tip sphere 1 mm into it
    plant.RegisterCollisionGeometry(plant.world_body(), RigidTransform(tip_center),
                                    Sphere(0.0195), "tip", CoulombFriction(1.0, 1.0))
    plant.Finalize()
    make_rigid_hydroelastic(plant, sg)
    sim = Simulator(builder.Build())
    sim.AdvanceTo(2e-3)                  # contact results are sampled at the steps
    ctx = plant.GetMyContextFromRoot(sim.get_context())
    results = plant.get_contact_results_output_port().Eval(ctx)
    assert results.num_point_pair_contacts() == 1
    assert results.num_hydroelastic_contacts() == 1          # fruit on the table
    f = results.point_pair_contact_info(0).contact_force()
    bodies = {results.point_pair_contact_info(0).bodyA_index(),
              results.point_pair_contact_info(0).bodyB_index()}
    assert body.index() in bodies and np.linalg.norm(f) > 0
