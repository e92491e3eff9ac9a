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

SEGMENTS = 24
OBJ_PATH = Path(__file__).with_name("unit_sphere.obj")


def unit_sphere_obj(segments: int = SEGMENTS) -> str:
    from adaptive_c3.models.triangle_mesh import obj_text, uv_sphere
    return (f"# unit sphere, {segments} x {segments // 2} UV, written by "
            "`python -m adaptive_c3.models.unit_sphere`\n" + obj_text(uv_sphere(1.0, segments)))


if __name__ == "__main__":
    OBJ_PATH.write_text(unit_sphere_obj())
    print(f"wrote {OBJ_PATH}")
