"""Ball candidates in one camera image: Hough circles of the ball's colour, each turned
into a ball centre in the world and a radius check (numpy + OpenCV, no Drake system).

`CircleFinder` holds what the image-to-world step needs (intrinsics, camera pose, the
ball's radius and colour, the tracker's settings); the BallDetector LeafSystem wraps it
with the tracker.
"""
from __future__ import annotations

import numpy as np

from adaptive_c3.models.ball_rolling_scene import BALL_COLOR, BALL_RADIUS, TABLE_TOP_Z
from adaptive_c3.systems.perception import hough_ball as hb
from adaptive_c3.systems.perception.camera import CameraSpec

# Drake 1.51's RenderEngineVtk draws the optical axis at pixel index (cx - 0.5, cy - 0.5)
# of CameraInfo's (cx, cy): image coordinates = array indices + 0.5 (measured; the
# rendering test checks the whole chain). A calibrated real camera would use 0.
VTK_PIXEL_OFFSET = 0.5
# beyond a circle's radius, what find_circles' filters read: the 5 x 5 blur (2 px), the
# Hough transform's 3 x 3 Sobel (1 px) and one pixel of the mask's contour
WINDOW_MARGIN_PX = 4


class CircleFinder:
    """Image -> candidates [(P_W (3,), radius_ratio), ...] (see the module docstring)."""

    def __init__(self, camera: CameraSpec, *, ball_radius: float = BALL_RADIUS,
                 table_top_z: float = TABLE_TOP_Z, ball_color=BALL_COLOR,
                 params: hb.TrackerParams | None = None,
                 pixel_offset: float = VTK_PIXEL_OFFSET):
        self.camera = camera
        self._K, self._R, self._p = camera.K, camera.R_WC, camera.p_WC
        self._color = tuple(ball_color)
        self._offset = float(pixel_offset)
        self.params = params if params is not None else hb.TrackerParams(
            ball_radius=ball_radius, table_top_z=table_top_z)
        self._radius = self.params.ball_radius
        self.pixel_radius_range = self._pixel_radius_range()
        self._r_min, self._r_max = self.pixel_radius_range

    def _pixel_radius_range(self):
        """(min, max) circle radius in pixels searched by the Hough transform."""
        p = self.params
        radii = []
        for x in np.linspace(p.workspace_min[0], p.workspace_max[0], 5):
            for y in np.linspace(p.workspace_min[1], p.workspace_max[1], 5):
                P = np.array([x, y, p.centre_z])
                if (self._R.T @ (P - self._p))[2] > self._radius:   # in front
                    radii.append(hb.silhouette_circle_px(P, self._radius, self._K,
                                                         self._R, self._p)[2])
        lo, hi = min(radii), max(radii)
        return max(3.0, (1 - p.radius_tolerance) * lo), (1 + p.radius_tolerance) * hi

    def detect(self, rgba: np.ndarray, near=None):
        """Candidates [(P_W, radius_ratio), ...] of one image (H x W x 3|4 uint8).

        near = (P_W, gate_m): look first in the image window that holds every circle
        whose centre is within gate_m of P_W (plus the largest radius and the filters'
        reach), and in the whole image only if nothing is found there. The mask, blur
        and Hough transform cost in proportion to the pixels; the window is about a
        quarter of the frame, and the ball is the only object of its colour, so a
        circle the tracker can accept is found the same either way.
        """
        circles = None
        if near is not None:
            window = self._search_window(*near, rgba.shape[1], rgba.shape[0])
            if window is not None:
                u0, v0, u1, v1 = window
                found = hb.find_circles(rgba[v0:v1, u0:u1], self._color, self._r_min,
                                        self._r_max)
                if len(found):
                    circles = found + [u0, v0, 0.0]
        if circles is None:
            circles = hb.find_circles(rgba, self._color, self._r_min, self._r_max)
        out = []
        for u, v, r in circles:
            P = hb.ball_centre_from_circle(u + self._offset, v + self._offset, self._K,
                                           self._R, self._p, self.params.centre_z,
                                           self._radius)
            if P is None:
                continue
            r_exp = hb.silhouette_circle_px(P, self._radius, self._K, self._R, self._p)[2]
            out.append((P, r / r_exp))
        return out

    def _search_window(self, P_W, gate: float, width: int, height: int):
        """(u0, v0, u1, v1) pixel window holding every circle centred within gate of
        P_W on the ball's plane, or None if it is (nearly) the whole image."""
        corners = [np.asarray(P_W, float) + [dx, dy, 0.0]
                   for dx in (-gate, gate) for dy in (-gate, gate)]
        uv = np.array([hb.project(c, self._K, self._R, self._p) for c in corners])
        if not np.isfinite(uv).all():
            return None
        pad = np.ceil(self._r_max) + WINDOW_MARGIN_PX
        u0, v0 = np.floor(uv.min(axis=0) - pad).astype(int)
        u1, v1 = np.ceil(uv.max(axis=0) + pad).astype(int)
        u0, v0, u1, v1 = max(u0, 0), max(v0, 0), min(u1, width), min(v1, height)
        if u1 <= u0 or v1 <= v0 or (u1 - u0) * (v1 - v0) > 0.6 * width * height:
            return None
        return u0, v0, u1, v1
