"""One render mesh per body and colour, for the camera's own SceneGraph.

Why (issue 18): RenderEngineVtk draws every geometry as its own VTK actor, and on Mesa's
CPU rasteriser each actor costs tens of microseconds a frame whether or not it is in
view. The Panda has 42 visual pieces (spheres and cylinders over 9 links); the camera
sees at most the last links. Drawn as one mesh per link and colour they cost a fraction
of that, and the triangles are the same: spheres given as meshes keep their triangles,
cylinders and boxes are tessellated (models/triangle_mesh.py, CYLINDER_SEGMENTS sides).

The numpy core (tessellate, merge, OBJ text) is models/triangle_mesh.py; here the Drake
side: `shape_triangles` and `merge_body_visuals`, applied to a plant that is not
finalized yet.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from adaptive_c3.models.triangle_mesh import (Triangles, box, cylinder, merge, obj_text,
                                              read_obj, uv_sphere)


def shape_triangles(shape) -> Triangles | None:
    """The shape's triangles in its geometry frame, or None for a shape not handled
    here (it is then left as its own geometry)."""
    from pydrake.geometry import Box, Cylinder, Mesh, Sphere
    if isinstance(shape, Sphere):
        return uv_sphere(shape.radius())
    if isinstance(shape, Cylinder):
        return cylinder(shape.radius(), shape.length())
    if isinstance(shape, Box):
        return box(shape.size())
    if isinstance(shape, Mesh):
        source = shape.source()
        if source.extension() != ".obj":
            return None
        text = (source.in_memory().mesh_file.contents().decode() if source.is_in_memory()
                else Path(source.path()).read_text())
        t = read_obj(text)
        scale = np.asarray(shape.scale3(), float)
        N = t.N / scale                      # normals of a scaled mesh
        return Triangles(t.V * scale, N / np.linalg.norm(N, axis=1, keepdims=True), t.F)
    return None


def merge_body_visuals(plant, scene_graph) -> int:
    """Replaces, in `scene_graph`, each body's perception geometries of one diffuse colour
    by a single mesh (the same triangles). `plant` is registered with scene_graph as a
    source and not finalized yet. Only the perception role of the originals is removed,
    so anything else (collision, illustration) is untouched. Returns how many geometries
    were merged away."""
    from pydrake.common import MemoryFile
    from pydrake.geometry import InMemoryMesh, Mesh, Role
    from pydrake.math import RigidTransform
    from pydrake.multibody.tree import BodyIndex
    if plant.is_finalized():
        raise ValueError("merge_body_visuals needs a plant that is not finalized")
    source = plant.get_source_id()
    insp = scene_graph.model_inspector()
    removed = 0
    for i in range(plant.num_bodies()):
        body = plant.get_body(BodyIndex(i))
        groups: dict = {}
        for gid in plant.GetVisualGeometriesForBody(body):
            props = insp.GetPerceptionProperties(gid)
            if props is None:
                continue
            tri = shape_triangles(insp.GetShape(gid))
            if tri is None:
                continue
            rgba = props.GetPropertyOrDefault("phong", "diffuse", None)
            key = None if rgba is None else tuple(np.round(rgba.rgba, 6))
            X = insp.GetPoseInFrame(gid)
            groups.setdefault(key, []).append((gid, tri.transformed(X.rotation().matrix(),
                                                                    X.translation())))
        for n, (key, members) in enumerate(groups.items()):
            if key is None or len(members) < 2:
                continue
            mesh = merge([t for _, t in members])
            name = f"{body.name()}_merged_visual_{n}"
            for gid, _ in members:
                scene_graph.RemoveRole(source, gid, Role.kPerception)
            shape = Mesh(InMemoryMesh(mesh_file=MemoryFile(obj_text(mesh), ".obj", name)), 1.0)
            plant.RegisterVisualGeometry(body, RigidTransform(), shape, name, np.array(key))
            removed += len(members) - 1
    return removed
