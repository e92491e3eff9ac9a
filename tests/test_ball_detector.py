"""Camera + Hough ball detector: synthetic images, then images rendered by Drake."""
import time

import cv2
import numpy as np
import pytest
from pydrake.math import RigidTransform
from pydrake.multibody.math import SpatialVelocity
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import LogVectorOutput
from pydrake.systems.sensors import ImageRgba8U

from adaptive_c3.models.ball_rolling_scene import (BALL_COLOR, BALL_RADIUS,
                                                   add_ball_rolling_scene)
from adaptive_c3.models.panda_kinematics import solve_ik
from adaptive_c3.systems.perception import hough_ball as hb
from adaptive_c3.systems.perception.ball_detector import BallDetector
from adaptive_c3.systems.perception.camera import add_overhead_camera, overhead_camera_spec
from adaptive_c3.systems.franka.impedance_law import tilted_ee_rotation

ORANGE = (255, 102, 0)       # BALL_COLOR in 8 bit
GREY = (140, 140, 133)
R = BALL_RADIUS
ZC = R                       # ball centre height on the table (table top z = 0)


# ------------------------------------------------------------ synthetic images
def disc_image(centres, radius=18.0, size=(240, 320), color=ORANGE, bg=GREY):
    img = np.full((*size, 3), bg, np.uint8)
    s = 16                                              # 4 bits of sub-pixel precision
    for (u, v) in centres:
        cv2.circle(img, (int(round(u * s)), int(round(v * s))), int(round(radius * s)),
                   color, -1, cv2.LINE_AA, shift=4)
    return img


def test_hough_finds_subpixel_centre():
    rng = np.random.default_rng(0)
    for _ in range(10):
        u, v = rng.uniform(60, 260), rng.uniform(50, 190)
        c = hb.find_circles(disc_image([(u, v)]), BALL_COLOR, 12, 26)
        assert len(c) == 1
        assert np.hypot(c[0, 0] - u, c[0, 1] - v) < 0.3
        assert abs(c[0, 2] - 18.0) < 1.0


def test_hough_partial_occlusion_keeps_centre():
    u, v = 151.3, 117.6
    img = disc_image([(u, v)])
    img[:, 158:175] = (60, 60, 60)                      # a dark rod across the ball
    img[95:112, 130:175] = (235, 235, 235)              # and a white link edge
    c = hb.find_circles(img, BALL_COLOR, 12, 26)
    assert len(c) >= 1
    assert np.hypot(c[0, 0] - u, c[0, 1] - v) < 1.0


def test_hough_ignores_other_colours_and_empty_frames():
    assert len(hb.find_circles(disc_image([]), BALL_COLOR, 12, 26)) == 0
    white = disc_image([(160, 120)], color=(240, 240, 240))
    assert len(hb.find_circles(white, BALL_COLOR, 12, 26)) == 0


# ------------------------------------------------------------------ geometry
SPEC = overhead_camera_spec()


def test_camera_pose_and_projection_roundtrip():
    Rwc, p = SPEC.R_WC, SPEC.p_WC
    assert np.isclose(np.linalg.det(Rwc), 1.0)
    # The optical axis goes through the workspace centre.
    assert np.allclose(hb.project([0.55, 0.0, 0.0], SPEC.K, Rwc, p),
                       SPEC.K[:2, 2], atol=1e-9)
    P = np.array([0.62, -0.07, ZC])
    u, v = hb.project(P, SPEC.K, Rwc, p)
    assert np.allclose(hb.ray_plane_point(u, v, SPEC.K, Rwc, p, ZC), P, atol=1e-12)


def test_sphere_centre_from_brute_force_silhouette():
    # Rasterise the sphere's image exactly (a pixel is in if its ray passes within R of
    # the centre) with a long focal length; the region's centroid is the ellipse centre.
    from adaptive_c3.systems.perception.camera import CameraSpec
    spec = CameraSpec(1600, 1200, 0.45, SPEC.X_WC)
    K, Rwc, p = spec.K, spec.R_WC, spec.p_WC
    for P in ([0.66, 0.09, ZC], [0.45, -0.1, ZC]):
        P = np.array(P)
        u0, v0 = hb.project(P, K, Rwc, p)
        uu, vv = np.meshgrid(np.arange(u0 - 120, u0 + 120, 0.5),
                             np.arange(v0 - 120, v0 + 120, 0.5))
        d = np.stack([(uu - K[0, 2]) / K[0, 0], (vv - K[1, 2]) / K[1, 1],
                      np.ones_like(uu)], -1) @ Rwc.T
        d /= np.linalg.norm(d, axis=-1, keepdims=True)
        w = P - p
        miss = np.linalg.norm(w - (d @ w)[..., None] * d, axis=-1)
        inside = miss < R
        uc, vc = uu[inside].mean(), vv[inside].mean()
        assert np.hypot(uc - u0, vc - v0) > 0.3       # perspective offset is real
        est = hb.ball_centre_from_circle(uc, vc, K, Rwc, p, ZC, R)
        assert np.linalg.norm(est - P) < 2e-5


# ------------------------------------------------------------------- tracker
def test_tracker_gates_holds_and_estimates_velocity():
    prm = hb.TrackerParams()
    x = hb.initial_tracker_state(prm, (0.6, 0.0))
    x = hb.tracker_step(x, 0.0, [], prm)
    assert x[hb.OK] == 0 and x[hb.INIT] == 0
    vel = np.array([0.1, -0.05, 0.0])
    p0 = np.array([0.6, 0.05, ZC])
    dt = 1 / 80
    for k in range(81):
        t = k * dt
        x = hb.tracker_step(x, t, [(p0 + vel * t, 1.02)], prm)
    assert x[hb.OK] == 1
    assert np.linalg.norm(x[hb.P] - (p0 + vel * t)) < 1e-4
    assert np.linalg.norm(x[hb.V] - vel) < 1e-3
    held = x.copy()
    t += dt
    far = p0 + vel * t + np.array([0.2, 0.0, 0.0])      # false circle 20 cm away
    near_wrong_size = p0 + vel * t
    x = hb.tracker_step(x, t, [(far, 1.0), (near_wrong_size, 1.6)], prm)
    assert x[hb.OK] == 0
    assert np.array_equal(x[hb.P], held[hb.P]) and np.array_equal(x[hb.V], held[hb.V])
    # With the true ball and a false circle, it picks the true ball.
    t += dt
    x = hb.tracker_step(x, t, [(far, 1.0), (p0 + vel * t, 0.97)], prm)
    assert x[hb.OK] == 1 and np.linalg.norm(x[hb.P] - (p0 + vel * t)) < 1e-3


def test_rolling_angular_velocity():
    w = hb.rolling_angular_velocity([0.2, 0.0, 0.0], 0.04)
    assert np.allclose(w, [0.0, 5.0, 0.0])          # rolling along +x spins about +y
    r = np.array([0.0, 0.0, 0.04])
    v = np.array([0.03, -0.07, 0.0])
    assert np.allclose(hb.rolling_angular_velocity(v, 0.04), np.cross(r, v) / (r @ r))


# ------------------------------------------------------------ Drake rendering
def render_scene(with_arm=False):
    b = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlantSceneGraph(b, 1e-3)
    scene = add_ball_rolling_scene(plant, with_arm=with_arm)
    plant.Finalize()
    camera, spec = add_overhead_camera(b, scene_graph)
    detector = b.AddSystem(BallDetector(spec, initial_position_xy=(0.65, 0.0)))
    b.Connect(camera.GetOutputPort("color_image"),
              detector.GetInputPort("camera.color_image"))
    return b, plant, scene, camera, spec, detector


@pytest.fixture(scope="module")
def rendered():
    """Rendered images (table + ball, no arm) and the detector that saw them."""
    b, plant, _, camera, spec, detector = render_scene()
    diagram = b.Build()
    ctx = diagram.CreateDefaultContext()
    pctx = plant.GetMyMutableContextFromRoot(ctx)
    cctx = camera.GetMyContextFromRoot(ctx)
    ball = plant.GetBodyByName("ball")
    ang = np.radians(np.arange(0, 360, 60))
    truths = [np.array([0.55 + 0.1 * np.cos(a), 0.1 * np.sin(a), ZC]) for a in ang]
    truths += [np.array([0.55, 0.0, ZC]), np.array([0.72, -0.16, ZC])]
    images, times = [], []
    for P in truths:
        plant.SetFreeBodyPose(pctx, ball, RigidTransform(P))
        t0 = time.perf_counter()
        images.append(camera.GetOutputPort("color_image").Eval(cctx).data.copy())
        times.append(time.perf_counter() - t0)
    plant.SetFreeBodyPose(pctx, ball, RigidTransform([5.0, 0.0, ZC]))   # out of view
    empty = camera.GetOutputPort("color_image").Eval(cctx).data.copy()
    return dict(images=images, truths=truths, empty=empty, spec=spec,
                detector=detector, render_ms=1000 * np.median(times[1:]))


def test_rendered_ball_positions_are_recovered(rendered):
    det = rendered["detector"]
    errors = []
    for img, P in zip(rendered["images"], rendered["truths"]):
        cands = det.detect(img)
        assert len(cands) == 1
        est, ratio = cands[0]
        assert abs(ratio - 1) < 0.1
        errors.append(np.linalg.norm(est - P))
    print(f"rendered detection error: max {1000 * max(errors):.3f} mm, "
          f"mean {1000 * np.mean(errors):.3f} mm; render "
          f"{rendered['render_ms']:.1f} ms/frame (320x240)")
    assert max(errors) < 1e-3                        # stated accuracy: 1 mm
    assert det.detect(rendered["empty"]) == []


def test_search_window_finds_what_the_whole_frame_finds(rendered):
    """Issue 18: the detector looks first in the window around the tracker's prediction;
    for a ball within the gate it finds the same circle as in the whole frame, and a
    ball outside the window is still found (the whole frame is searched then)."""
    det = rendered["detector"]
    for img, P in zip(rendered["images"], rendered["truths"]):
        full = det.detect(img)
        for offset in ([0.0, 0.0, 0.0], [0.02, -0.015, 0.0]):     # inside the 3 cm gate
            window = det.finder._search_window(P + offset, 0.03, img.shape[1], img.shape[0])
            assert window is not None
            u0, v0, u1, v1 = window
            assert (u1 - u0) * (v1 - v0) < 0.35 * img.shape[0] * img.shape[1]
            near = det.detect(img, near=(P + offset, 0.03))
            assert len(near) == len(full) == 1
            np.testing.assert_allclose(near[0][0], full[0][0], atol=1e-12)
            assert near[0][1] == pytest.approx(full[0][1], abs=1e-12)
        far = det.detect(img, near=(P + [0.2, 0.0, 0.0], 0.03))      # window misses it
        np.testing.assert_allclose(far[0][0], full[0][0], atol=1e-12)
    assert det.detect(rendered["empty"], near=(rendered["truths"][0], 0.03)) == []


def _image_value(rgb):
    img = ImageRgba8U(rgb.shape[1], rgb.shape[0])
    img.mutable_data[:, :, :3] = rgb[:, :, :3]
    img.mutable_data[:, :, 3] = 255
    return img


def test_detector_holds_and_flags_on_empty_and_false_frames(rendered):
    spec = rendered["spec"]
    det = BallDetector(spec, initial_position_xy=(0.65, 0.0))
    sim = Simulator(det)
    ctx = sim.get_mutable_context()
    port = det.GetInputPort("camera.color_image")
    true_img, P = rendered["images"][0], rendered["truths"][0]      # ball at (0.65, 0)
    ball_rgb = true_img[hb.ball_mask(true_img, BALL_COLOR) > 0][:, :3].mean(0)
    # A false ball: right colour and a plausible size, 0.2 m from the true one.
    P_false = P + np.array([-0.05, 0.2, 0.0])
    u, v, r = hb.silhouette_circle_px(P_false, R, spec.K, spec.R_WC, spec.p_WC)
    false_img = disc_image([(u - 0.5, v - 0.5)], radius=r, size=true_img.shape[:2],
                           color=tuple(int(c) for c in ball_rgb), bg=(0, 0, 0))
    false_img = np.where(false_img.any(-1, keepdims=True), false_img,
                         rendered["empty"][:, :, :3])
    # A circle of the wrong size right where the ball is (a reflection, a different ball).
    u, v, r = hb.silhouette_circle_px(P, R, spec.K, spec.R_WC, spec.p_WC)
    big_img = disc_image([(u - 0.5, v - 0.5)], radius=1.8 * r, size=true_img.shape[:2],
                         color=tuple(int(c) for c in ball_rgb), bg=(0, 0, 0))
    big_img = np.where(big_img.any(-1, keepdims=True), big_img, rendered["empty"][:, :, :3])
    both_img = np.where(hb.ball_mask(false_img, BALL_COLOR)[..., None] > 0, false_img,
                        true_img[:, :, :3])

    def run(image, t_end):
        port.FixValue(ctx, _image_value(image))
        positions, oks = [], []
        while ctx.get_time() < t_end - 1e-9:
            sim.AdvanceTo(min(ctx.get_time() + 1 / 80, t_end))
            positions.append(det.GetOutputPort("ball.position").Eval(ctx).copy())
            oks.append(det.GetOutputPort("ball.detection_ok").Eval(ctx)[0])
        return np.array(positions), np.array(oks)

    pos, ok = run(true_img, 0.1)
    assert ok[-1] == 1 and np.linalg.norm(pos[-1] - P) < 1e-3
    held = pos[-1]
    for image, t_end in ((rendered["empty"], 0.2), (false_img, 0.3), (big_img, 0.35)):
        pos, ok = run(image, t_end)
        assert np.all(ok == 0)
        assert np.allclose(pos, held, atol=1e-12)          # held exactly, no jump
    pos, ok = run(both_img, 0.45)                          # true ball + false circle
    assert np.all(ok == 1) and np.max(np.linalg.norm(pos - P, axis=1)) < 1e-3
    v = det.GetOutputPort("ball.velocity").Eval(ctx)
    assert np.linalg.norm(v) < 0.02


def test_rolling_ball_state_in_closed_simulation():
    """Ball rolling on the table (no arm): estimated position, velocity and angular
    velocity against the plant's truth, through RgbdSensor -> BallDetector at 80 Hz."""
    b, plant, _, camera, spec, detector = render_scene()
    period = 1 / 80
    logs = {n: LogVectorOutput(detector.GetOutputPort(n), b, period) for n in (
        "ball.position", "ball.velocity", "ball.angular_velocity", "ball.detection_ok")}
    truth = LogVectorOutput(plant.get_state_output_port(), b, period)
    diagram = b.Build()
    sim = Simulator(diagram)
    ctx = sim.get_mutable_context()
    pctx = plant.GetMyMutableContextFromRoot(ctx)
    ball = plant.GetBodyByName("ball")
    v0 = np.array([-0.12, 0.08, 0.0])
    plant.SetFreeBodyPose(pctx, ball, RigidTransform([0.63, -0.05, ZC]))
    plant.SetFreeBodySpatialVelocity(
        pctx, ball, SpatialVelocity(hb.rolling_angular_velocity(v0, R), v0))
    t0 = time.perf_counter()
    sim.AdvanceTo(0.6)
    wall = time.perf_counter() - t0
    est = {n: log.FindLog(ctx).data() for n, log in logs.items()}
    X = truth.FindLog(ctx).data()         # [q (wxyz, xyz), v (w, v)] of the ball
    # A logger sample at t_k is published before the detector's update at t_k, so it
    # shows the estimate from the image at t_(k-1): compare sample k with truth k - 1,
    # after 0.1 s for the filter's start (it starts from zero velocity).
    k = np.arange(9, X.shape[1])
    pos_err = np.linalg.norm(est["ball.position"][:, k] - X[4:7, k - 1], axis=0)
    vel_err = np.linalg.norm(est["ball.velocity"][:, k] - X[10:13, k - 1], axis=0)
    w_err = np.linalg.norm(est["ball.angular_velocity"][:, k] - X[7:10, k - 1], axis=0)
    print(f"rolling ball ({np.linalg.norm(X[10:13, -1]):.3f} m/s): position error max "
          f"{1000 * pos_err.max():.2f} mm, velocity error max {1000 * vel_err.max():.1f}"
          f" mm/s, angular velocity error max {w_err.max():.2f} rad/s; 0.6 s with 48 "
          f"frames took {wall:.2f} s")
    assert np.all(est["ball.detection_ok"][0, 1:] == 1)
    assert np.linalg.norm(X[10:13, -1]) > 0.1                # still rolling
    assert pos_err.max() < 1e-3
    assert vel_err.max() < 0.01
    assert w_err.max() < 0.01 / R


def test_detection_with_the_arm_next_to_the_ball():
    b, plant, scene, camera, spec, detector = render_scene(with_arm=True)
    diagram = b.Build()
    ctx = diagram.CreateDefaultContext()
    pctx = plant.GetMyMutableContextFromRoot(ctx)
    P = np.array([0.55, 0.1, ZC])                          # far side of the circle
    # EE trailing the ball (pushing it along -x), tip 5 cm behind at ball height.
    q = solve_ik(P + np.array([0.052, 0.0, 0.005]), tilted_ee_rotation(15.0))
    plant.SetPositions(pctx, scene.panda, q)
    plant.SetFreeBodyPose(pctx, plant.GetBodyByName("ball"), RigidTransform(P))
    img = camera.GetOutputPort("color_image").Eval(camera.GetMyContextFromRoot(ctx)).data
    cands = detector.detect(img)
    assert len(cands) == 1 and np.linalg.norm(cands[0][0] - P) < 1e-3
