"""A simulated overhead RGB-D camera (Drake RgbdSensor rendered with RenderEngineVtk).

RenderEngineVtk renders headless here (EGL); RenderEngineGl does not. Geometry is
rendered if it has the perception role: URDF/SDF visuals and
MultibodyPlant.RegisterVisualGeometry both give it.

Camera frame C (Drake's convention): origin at the optical centre, +z along the optical
axis (into the scene), +x to the image's right, +y down the image. A pixel (u, v) with
u = column, v = row sees the ray C-direction ((u - cx) / fx, (v - cy) / fy, 1).

Default placement: above the table, 0.9 m from the centre of the ball's workspace (the
circle of radius 0.1 m about (0.55, 0)), looking down at it at 55 degrees from the
-y side. Straight down (elevation 90) is available but a poor default: there the arm's
wrist and forearm sit between the camera and the ball whenever the EE is near it. From
the side at 55 degrees the links above the EE project well behind the ball; only the
thin rod/tip can hide it. Vertical field of view 0.45 rad: about 0.54 m (along x) x
0.5 m (along y) of table in view; at the scenarios' 160 x 120 pixels ~3.4 mm per pixel
at the target and the ball (radius 0.0315 m) about 9 pixels in radius (at this
function's default 320 x 240: ~1.7 mm, 18 pixels).
"""
from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np
from pydrake.geometry import (ClippingRange, ColorRenderCamera, DepthRange,
                              DepthRenderCamera, LightParameter, MakeRenderEngineVtk,
                              RenderCameraCore, RenderEngineVtkParams)
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.systems.sensors import CameraInfo, RgbdSensor

DEFAULT_RENDERER = "vtk_renderer"


@dataclass(frozen=True)
class CameraSpec:
    """Intrinsics and pose of a pinhole camera (what the detector needs)."""
    width: int
    height: int
    fov_y: float              # rad
    X_WC: RigidTransform      # camera frame C in the world frame W

    @property
    def info(self) -> CameraInfo:
        return CameraInfo(self.width, self.height, self.fov_y)

    @property
    def K(self) -> np.ndarray:
        """3x3 intrinsic matrix [[fx, 0, cx], [0, fy, cy], [0, 0, 1]] (pixels)."""
        i = self.info
        return np.array([[i.focal_x(), 0.0, i.center_x()],
                         [0.0, i.focal_y(), i.center_y()],
                         [0.0, 0.0, 1.0]])

    @property
    def R_WC(self) -> np.ndarray:
        return self.X_WC.rotation().matrix()

    @property
    def p_WC(self) -> np.ndarray:
        return self.X_WC.translation()


def look_at(position, target, image_up_hint=(1.0, 0.0, 0.0)) -> RigidTransform:
    """Pose X_WC of a camera at `position` whose optical axis points at `target`.

    The image's "up" (-y_C) is the component of image_up_hint orthogonal to the axis
    (world +y is used if the hint is parallel to the axis).
    """
    p = np.asarray(position, float)
    z = np.asarray(target, float) - p
    z /= np.linalg.norm(z)
    up = np.asarray(image_up_hint, float)
    if np.linalg.norm(np.cross(up, z)) < 1e-6:
        up = np.array([0.0, 1.0, 0.0])
    y = -(up - (up @ z) * z)
    y /= np.linalg.norm(y)
    x = np.cross(y, z)
    return RigidTransform(RotationMatrix(np.column_stack([x, y, z])), p)


def overhead_camera_spec(*, target=(0.55, 0.0, 0.0), distance: float = 0.9,
                         elevation_deg: float = 55.0, azimuth_deg: float = -90.0,
                         width: int = 320, height: int = 240,
                         fov_y: float = 0.45) -> CameraSpec:
    """Camera `distance` m from `target`, above the table, looking at the target.

    elevation_deg: angle of the line of sight above the table (90 = straight down);
    azimuth_deg: direction, in the table plane, from the target to the camera
    (-90 = from the -y side). The image's up is world +z projected (for a straight-down
    view, world +x).
    """
    t = np.asarray(target, float)
    e, a = np.radians(elevation_deg), np.radians(azimuth_deg)
    position = t + distance * np.array([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a),
                                        np.sin(e)])
    hint = (1.0, 0.0, 0.0) if elevation_deg > 89.9 else (0.0, 0.0, 1.0)
    return CameraSpec(width, height, fov_y, look_at(position, t, hint))


def add_overhead_camera(builder, scene_graph, spec: CameraSpec | None = None, *,
                        renderer_name: str = DEFAULT_RENDERER,
                        name: str = "overhead_camera",
                        clear_color=(0.8, 0.9, 1.0)):
    """Adds an RgbdSensor (and a RenderEngineVtk renderer if needed) to `builder`.

    Connects scene_graph's query output to the sensor. Returns (sensor, spec); the
    sensor's "color_image" output port (ImageRgba8U) is what BallDetector reads.
    Rendering happens on demand when that port is evaluated.
    """
    spec = spec if spec is not None else overhead_camera_spec()
    # Mesa's CPU rasteriser (llvmpipe) renders on worker threads, one per core, by
    # default. For a 160 x 120 frame every 12.5 ms their wake-ups cost more than they
    # share: rendering in the calling thread took the camera-on loop from a real-time
    # factor of 0.67 to 0.88 on 2 cores (`bench loop`). Read when the first GL context
    # is made, so it must be set before; a value the user exported is kept.
    os.environ.setdefault("LP_NUM_THREADS", "0")
    if not scene_graph.HasRenderer(renderer_name):
        params = RenderEngineVtkParams()
        params.default_clear_color = list(clear_color)
        # A point light AT the camera (VTK's default is a directional light along the
        # optical axis): then every sphere is shaded symmetrically about its own
        # viewing ray, and the colour mask's edge is not pulled off-centre by a dark
        # limb on the side facing the image centre (a ~1 px bias otherwise).
        params.lights = [LightParameter(type="point", frame="camera",
                                        position=[0.0, 0.0, 0.0], intensity=1.0)]
        scene_graph.AddRenderer(renderer_name, MakeRenderEngineVtk(params))
    core = RenderCameraCore(renderer_name, spec.info, ClippingRange(0.05, 5.0),
                            RigidTransform())
    color = ColorRenderCamera(core, False)
    depth = DepthRenderCamera(core, DepthRange(0.06, 4.5))
    sensor = RgbdSensor(scene_graph.world_frame_id(), spec.X_WC, color, depth)
    sensor.set_name(name)
    builder.AddSystem(sensor)
    builder.Connect(scene_graph.get_query_output_port(), sensor.query_object_input_port())
    return sensor, spec
