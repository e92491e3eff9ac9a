"""The unit sphere mesh the Panda's visuals use (models/unit_sphere.obj).

`python -m adaptive_c3.models.unit_sphere` writes it; a test checks the file against
this generator. A UV sphere of radius 1 with SEGMENTS meridians and SEGMENTS / 2
parallels, outward vertex normals. The URDF scales it to each link sphere's radius.

Why (issue 18): the renderer tessellates a Drake Sphere into ~4,800 triangles, and the
arm's 28 spheres, in view of the camera while the arm works over the table, were about a
third of a camera frame on Mesa's CPU rasteriser (3.5 -> 2.5 ms a frame, measured on the
ball-rolling diagram). With 24 meridians the silhouette lies within r (1 - cos(pi / 24))
= 0.009 r of the true sphere: 0.6 mm for the largest link sphere (r = 0.075 m), about
0.2 pixel at the camera's 3.4 mm per pixel. Collision geometry is unchanged, and the
ball the detector looks for is still a Drake Sphere.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

SEGMENTS = 24
OBJ_PATH = Path(__file__).with_name("unit_sphere.obj")


def unit_sphere_obj(segments: int = SEGMENTS) -> str:
    rings = segments // 2
    verts = [(0.0, 0.0, 1.0)]
    for i in range(1, rings):
        phi = np.pi * i / rings
        for j in range(segments):
            th = 2 * np.pi * j / segments
            verts.append((np.sin(phi) * np.cos(th), np.sin(phi) * np.sin(th), np.cos(phi)))
    verts.append((0.0, 0.0, -1.0))
    faces = [(1, 2 + j, 2 + (j + 1) % segments) for j in range(segments)]
    for i in range(rings - 2):
        a, b = 2 + i * segments, 2 + (i + 1) * segments
        for j in range(segments):
            k = (j + 1) % segments
            faces += [(a + j, b + j, b + k), (a + j, b + k, a + k)]
    a, last = 2 + (rings - 2) * segments, len(verts)
    faces += [(a + j, last, a + (j + 1) % segments) for j in range(segments)]
    lines = [f"# unit sphere, {segments} x {rings} UV, written by "
             "`python -m adaptive_c3.models.unit_sphere`"]
    lines += ["v %.6f %.6f %.6f" % v for v in verts]
    lines += ["vn %.6f %.6f %.6f" % v for v in verts]
    lines += ["f %d//%d %d//%d %d//%d" % (a, a, b, b, c, c) for a, b, c in faces]
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    OBJ_PATH.write_text(unit_sphere_obj())
    print(f"wrote {OBJ_PATH}")
