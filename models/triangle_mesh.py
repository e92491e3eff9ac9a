"""Triangle meshes in numpy: tessellated spheres, cylinders and boxes, OBJ text in and out.

The shapes the camera's renderer draws (systems/perception/merged_visuals.py merges a
body's pieces into one of these) and the unit sphere of the Panda's visuals
(models/unit_sphere.py). Counter-clockwise faces seen from outside, outward normals.
"""
from __future__ import annotations

import numpy as np

CYLINDER_SEGMENTS = 48   # side error r (1 - cos(pi / 48)) = 0.002 r: 0.15 mm at r = 0.075 m
SPHERE_SEGMENTS = 24     # as models/unit_sphere.obj


class Triangles:
    """A triangle mesh: vertices V (n, 3), vertex normals N (n, 3), faces F (m, 3),
    0-based indices, counter-clockwise seen from outside."""

    def __init__(self, V, N, F):
        self.V, self.N, self.F = (np.asarray(V, float).reshape(-1, 3),
                                  np.asarray(N, float).reshape(-1, 3),
                                  np.asarray(F, int).reshape(-1, 3))

    def transformed(self, R: np.ndarray, p: np.ndarray) -> "Triangles":
        return Triangles(self.V @ R.T + p, self.N @ R.T, self.F)


def read_obj(text: str) -> Triangles:
    """Triangles of an OBJ text with `v`, `vn` and triangular `f a//n` or `f a/t/n` lines.
    A vertex is a (position, normal) pair, as OBJ gives normals per face corner."""
    pos, nrm, corners_of, V, N, F = [], [], {}, [], [], []
    for line in text.splitlines():
        head, _, rest = line.partition(" ")
        if head == "v":
            pos.append([float(a) for a in rest.split()[:3]])
        elif head == "vn":
            nrm.append([float(a) for a in rest.split()[:3]])
        elif head == "f":
            corners = rest.split()
            if len(corners) != 3:
                raise ValueError("only triangular OBJ faces are supported")
            face = []
            for c in corners:
                idx = c.split("/")
                if len(idx) < 3 or not idx[2]:
                    raise ValueError("OBJ faces need vertex normals (f v//n)")
                key = (int(idx[0]) - 1, int(idx[2]) - 1)
                if key not in corners_of:
                    corners_of[key] = len(V)
                    V.append(pos[key[0]])
                    N.append(nrm[key[1]])
                face.append(corners_of[key])
            F.append(face)
    return Triangles(V, N, F)


def uv_sphere(radius: float, segments: int = SPHERE_SEGMENTS) -> Triangles:
    """UV sphere: `segments` meridians, segments / 2 parallels, outward normals."""
    rings = segments // 2
    phi = np.pi * np.arange(1, rings) / rings
    th = 2 * np.pi * np.arange(segments) / segments
    ring = np.stack([np.outer(np.sin(phi), np.cos(th)), np.outer(np.sin(phi), np.sin(th)),
                     np.outer(np.cos(phi), np.ones(segments))], axis=-1).reshape(-1, 3)
    unit = np.vstack([[0, 0, 1.0], ring, [0, 0, -1.0]])
    j = np.arange(segments)
    k = (j + 1) % segments
    faces = [np.stack([np.zeros(segments, int), 1 + j, 1 + k], 1)]
    for i in range(rings - 2):
        a, b = 1 + i * segments, 1 + (i + 1) * segments
        faces += [np.stack([a + j, b + j, b + k], 1), np.stack([a + j, b + k, a + k], 1)]
    a, last = 1 + (rings - 2) * segments, len(unit) - 1
    faces.append(np.stack([a + j, np.full(segments, last), a + k], 1))
    return Triangles(radius * unit, unit, np.vstack(faces))


def cylinder(radius: float, length: float, segments: int = CYLINDER_SEGMENTS) -> Triangles:
    """Closed cylinder about z, centred at the origin: side with radial normals, two flat
    caps with axial normals (separate vertices, so the edges stay sharp)."""
    th = 2 * np.pi * np.arange(segments) / segments
    c, s = np.cos(th), np.sin(th)
    h = length / 2
    j = np.arange(segments)
    k = (j + 1) % segments
    radial = np.stack([c, s, np.zeros(segments)], 1)
    side_V = np.vstack([radial * radius + [0, 0, -h], radial * radius + [0, 0, h]])
    side_F = np.vstack([np.stack([j, k, segments + k], 1), np.stack([j, segments + k, segments + j], 1)])
    parts = [Triangles(side_V, np.vstack([radial, radial]), side_F)]
    for z, sign in ((h, 1.0), (-h, -1.0)):
        V = np.vstack([[0, 0, z], radial * radius + [0, 0, z]])
        F = (np.stack([np.zeros(segments, int), 1 + j, 1 + k], 1) if sign > 0
             else np.stack([np.zeros(segments, int), 1 + k, 1 + j], 1))
        parts.append(Triangles(V, np.tile([0, 0, sign], (len(V), 1)), F))
    return merge(parts)


def box(size) -> Triangles:
    """Box of size (x, y, z) centred at the origin, flat faces."""
    half = np.asarray(size, float) / 2
    parts = []
    for axis in range(3):
        u, v = np.eye(3)[(axis + 1) % 3], np.eye(3)[(axis + 2) % 3]   # u x v = e_axis
        hu, hv = half[(axis + 1) % 3], half[(axis + 2) % 3]
        for sign in (1.0, -1.0):
            n = sign * np.eye(3)[axis]
            corners = [n * half[axis] + a * hu * u + b * hv * v
                       for a, b in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
            F = np.array([[0, 1, 2], [0, 2, 3]]) if sign > 0 else np.array([[0, 2, 1], [0, 3, 2]])
            parts.append(Triangles(corners, np.tile(n, (4, 1)), F))
    return merge(parts)


def merge(parts) -> Triangles:
    """One mesh of several (indices shifted)."""
    V, N, F, n = [], [], [], 0
    for t in parts:
        V.append(t.V)
        N.append(t.N)
        F.append(t.F + n)
        n += len(t.V)
    return Triangles(np.vstack(V), np.vstack(N), np.vstack(F))


def obj_text(t: Triangles) -> str:
    lines = ["v %.7g %.7g %.7g" % tuple(v) for v in t.V]
    lines += ["vn %.6f %.6f %.6f" % tuple(n) for n in t.N]
    lines += ["f %d//%d %d//%d %d//%d" % (a, a, b, b, c, c) for a, b, c in t.F + 1]
    return "\n".join(lines) + "\n"
