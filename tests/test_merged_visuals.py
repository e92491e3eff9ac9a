"""merged_visuals: the tessellations are closed, outward and the right size; merging keeps
every triangle; a body's pieces become one mesh per colour (issue 18)."""
import numpy as np
import pytest

from adaptive_c3.models import triangle_mesh as tm
from adaptive_c3.systems.perception import merged_visuals as mv


def _volume(t: tm.Triangles) -> float:
    a, b, c = t.V[t.F[:, 0]], t.V[t.F[:, 1]], t.V[t.F[:, 2]]
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6)


def _normals_outward(t: tm.Triangles) -> bool:
    a, b, c = t.V[t.F[:, 0]], t.V[t.F[:, 1]], t.V[t.F[:, 2]]
    face_n = np.cross(b - a, c - a)
    vertex_n = t.N[t.F[:, 0]] + t.N[t.F[:, 1]] + t.N[t.F[:, 2]]
    return bool(np.all(np.einsum("ij,ij->i", face_n, vertex_n) > 0))


@pytest.mark.parametrize("shape, volume, rtol", [
    (tm.uv_sphere(0.5, 24), 4 / 3 * np.pi * 0.125, 0.03),
    (tm.cylinder(0.2, 0.7, 48), np.pi * 0.04 * 0.7, 0.005),
    (tm.box([0.1, 0.2, 0.3]), 0.006, 1e-12),
])
def test_tessellations_are_closed_outward_and_the_right_size(shape, volume, rtol):
    assert _volume(shape) == pytest.approx(volume, rel=rtol)
    assert _normals_outward(shape)
    assert np.allclose(np.linalg.norm(shape.N, axis=1), 1.0)
    edges = np.sort(np.vstack([shape.F[:, [0, 1]], shape.F[:, [1, 2]], shape.F[:, [2, 0]]]), 1)
    _, n = np.unique(edges, axis=0, return_counts=True)
    if len(shape.V) == len(np.unique(np.round(shape.V, 12), axis=0)):   # no split vertices
        assert np.all(n == 2)       # closed: every edge in exactly two triangles


def test_obj_round_trip_and_merge_keep_every_triangle():
    parts = [tm.uv_sphere(0.1, 8), tm.box([1, 1, 1]).transformed(np.eye(3), np.array([2.0, 0, 0]))]
    merged = tm.merge(parts)
    assert len(merged.F) == sum(len(p.F) for p in parts)
    back = tm.read_obj(tm.obj_text(merged))
    assert len(back.V) == len(merged.V) and len(back.F) == len(merged.F)
    assert np.allclose(back.V[back.F], merged.V[merged.F], atol=1e-6)     # same corners
    assert np.allclose(back.N[back.F], merged.N[merged.F], atol=1e-6)
    assert _volume(back) == pytest.approx(_volume(parts[0]) + 1.0, rel=1e-5)


def test_read_obj_rejects_what_it_cannot_draw():
    with pytest.raises(ValueError, match="triangular"):
        tm.read_obj("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvn 0 0 1\nf 1//1 2//1 3//1 4//1\n")
    with pytest.raises(ValueError, match="normals"):
        tm.read_obj("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")


def test_a_body_s_pieces_become_one_mesh_per_colour():
    from pydrake.geometry import Cylinder, Role, SceneGraph, Sphere
    from pydrake.math import RigidTransform
    from pydrake.multibody.plant import MultibodyPlant
    from pydrake.multibody.tree import SpatialInertia
    plant, sg = MultibodyPlant(1e-3), SceneGraph()
    plant.RegisterAsSourceForSceneGraph(sg)
    body = plant.AddRigidBody("link", SpatialInertia.SolidSphereWithMass(1.0, 0.1))
    white, grey = np.array([0.9, 0.9, 0.9, 1.0]), np.array([0.2, 0.2, 0.2, 1.0])
    for k in range(3):
        plant.RegisterVisualGeometry(body, RigidTransform([0.1 * k, 0, 0]), Sphere(0.05),
                                     f"s{k}", white)
    plant.RegisterVisualGeometry(body, RigidTransform(), Cylinder(0.01, 0.2), "rod", grey)
    single = plant.AddRigidBody("ball", SpatialInertia.SolidSphereWithMass(1.0, 0.1))
    plant.RegisterVisualGeometry(single, RigidTransform(), Sphere(0.03), "ball", white)
    assert mv.merge_body_visuals(plant, sg) == 2          # three white spheres -> one
    plant.Finalize()
    insp = sg.model_inspector()
    names = sorted(insp.GetName(g) for g in insp.GetAllGeometryIds(Role.kPerception))
    assert names == ["ball", "link_merged_visual_0", "rod"]
    # the originals keep their other roles
    assert len(insp.GetAllGeometryIds(Role.kIllustration)) == 6
    with pytest.raises(ValueError, match="finalized"):
        mv.merge_body_visuals(plant, sg)
