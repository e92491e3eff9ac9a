"""Ball detector: camera image -> filtered ball state at 80 Hz (Drake LeafSystem).

Wraps systems/perception/hough_ball.py. Every `period` seconds (default 1/80 s; a periodic
discrete update, so the image is rendered only then) it reads the colour image, finds
Hough circles of the ball's colour and plausible size, turns each into a ball centre on
the plane z = table_top + radius with the camera intrinsics and pose, gates them
(radius consistent with the distance, close enough to the prediction) and updates an
alpha-beta filter. With no acceptable circle it holds the last estimate and clears
"ball.detection_ok"; the estimate never jumps to a rejected circle.

Ports (world frame W = robot base frame; m, m/s, rad/s):
  input  "camera.color_image"     ImageRgba8U (e.g. RgbdSensor "color_image"); if
                                  unconnected every update counts as "no detection"
  output "ball.position"          (3) filtered ball centre in W (z = table + radius)
  output "ball.velocity"          (3) filtered ball velocity in W (z component 0)
  output "ball.angular_velocity"  (3) rolling assumption omega = (1/r) z_hat x v
  output "ball.detection_ok"      (1) 1.0 if the latest frame gave an accepted
                                  detection, else 0.0 (estimate held)
Before the first accepted detection the outputs hold `initial_position_xy` and zero
velocity, with detection_ok = 0.
"""
from __future__ import annotations

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import LeafSystem
from pydrake.systems.sensors import ImageRgba8U

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


class BallDetector(LeafSystem):
    """Hough-circle ball detector with gating, hold-on-miss and alpha-beta filtering."""

    def __init__(self, camera: CameraSpec, *, ball_radius: float = BALL_RADIUS,
                 table_top_z: float = TABLE_TOP_Z, ball_color=BALL_COLOR,
                 period: float = 1.0 / 80.0, params: hb.TrackerParams | None = None,
                 initial_position_xy=(0.55, 0.0),
                 pixel_offset: float = VTK_PIXEL_OFFSET):
        super().__init__()
        self._cam = camera
        self._K, self._R, self._p = camera.K, camera.R_WC, camera.p_WC
        self._color = tuple(ball_color)
        self._offset = float(pixel_offset)
        self._params = params if params is not None else hb.TrackerParams(
            ball_radius=ball_radius, table_top_z=table_top_z)
        self._radius = self._params.ball_radius
        self._r_min, self._r_max = self._pixel_radius_range()
        self._image = self.DeclareAbstractInputPort(
            "camera.color_image", AbstractValue.Make(ImageRgba8U()))
        x0 = hb.initial_tracker_state(self._params, initial_position_xy)
        self._xd = self.DeclareDiscreteState(x0)
        self.DeclarePeriodicDiscreteUpdateEvent(period, 0.0, self._update)
        ticket = {self.xd_ticket()}
        self.DeclareVectorOutputPort("ball.position", 3, self._out_position,
                                     prerequisites_of_calc=ticket)
        self.DeclareVectorOutputPort("ball.velocity", 3, self._out_velocity,
                                     prerequisites_of_calc=ticket)
        self.DeclareVectorOutputPort("ball.angular_velocity", 3, self._out_omega,
                                     prerequisites_of_calc=ticket)
        self.DeclareVectorOutputPort("ball.detection_ok", 1, self._out_ok,
                                     prerequisites_of_calc=ticket)

    @property
    def pixel_radius_range(self):
        """(min, max) circle radius in pixels searched by the Hough transform."""
        return self._r_min, self._r_max

    def _pixel_radius_range(self):
        p = self._params
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
                                           self._R, self._p, self._params.centre_z,
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

    def _update(self, context, discrete_state):
        x = context.get_discrete_state_vector().CopyToVector()
        candidates = []
        if self._image.HasValue(context):
            img = self._image.Eval(context)
            if img.width() > 0 and img.height() > 0:
                candidates = self.detect(
                    img.data, hb.tracker_prediction(x, context.get_time(), self._params))
        x_new = hb.tracker_step(x, context.get_time(), candidates, self._params)
        discrete_state.get_mutable_vector().SetFromVector(x_new)

    def _state(self, context):
        return context.get_discrete_state_vector().CopyToVector()

    def _out_position(self, context, out):
        out.SetFromVector(self._state(context)[hb.P])

    def _out_velocity(self, context, out):
        out.SetFromVector(self._state(context)[hb.V])

    def _out_omega(self, context, out):
        out.SetFromVector(hb.rolling_angular_velocity(self._state(context)[hb.V],
                                                      self._radius))

    def _out_ok(self, context, out):
        out.SetFromVector([self._state(context)[hb.OK]])
