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
from adaptive_c3.systems.perception.circle_finder import VTK_PIXEL_OFFSET, CircleFinder


class BallDetector(LeafSystem):
    """Hough-circle ball detector with gating, hold-on-miss and alpha-beta filtering."""

    def __init__(self, camera: CameraSpec, *, ball_radius: float = BALL_RADIUS,
                 table_top_z: float = TABLE_TOP_Z, ball_color=BALL_COLOR,
                 period: float = 1.0 / 80.0, params: hb.TrackerParams | None = None,
                 initial_position_xy=(0.55, 0.0),
                 pixel_offset: float = VTK_PIXEL_OFFSET):
        super().__init__()
        self.finder = CircleFinder(camera, ball_radius=ball_radius, table_top_z=table_top_z,
                                   ball_color=ball_color, params=params,
                                   pixel_offset=pixel_offset)
        self._params = self.finder.params
        self._radius = self._params.ball_radius
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
        return self.finder.pixel_radius_range

    def detect(self, rgba: np.ndarray, near=None):
        """Candidates of one image (CircleFinder.detect)."""
        return self.finder.detect(rgba, near)

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
