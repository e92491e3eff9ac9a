"""Ball detection and tracking core (numpy + OpenCV, no Drake): testable on synthetic
images.

Pipeline per frame:
 1. ball_mask: colour threshold in HSV around the ball's known hue (the table and the
    arm are unsaturated grey/white, so the mask is clean; shading keeps the hue).
 2. find_circles: OpenCV HoughCircles (HOUGH_GRADIENT) on the blurred mask, then each
    circle is refined by a least-squares circle fit to the mask's contour points that
    lie near it (points on an occluder's edge are not near the circle and drop out, so
    a partly hidden ball still gives its true centre).
 3. ball_centre_from_circle: the image circle centre -> the ball centre in the world,
    intersecting the pixel's ray with the plane z = table_top + radius, with a
    correction for perspective (a sphere off the optical axis images as an ellipse
    whose centre is not the projection of the sphere's centre).
 4. tracker_step: gate the candidates (radius consistent with the distance, within a
    gate around the prediction), alpha-beta filter (low-pass position, velocity
    estimate), hold the last estimate and flag when nothing acceptable is seen.

Camera conventions as in systems/perception/camera.py: K = [[fx,0,cx],[0,fy,cy],[0,0,1]], pixel
(u, v) = (column, row), camera frame +z forward, +x right, +y down; R_WC, p_WC the
camera's orientation and position in the world W. Units: m, s, pixels.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np


# ------------------------------------------------------------------ image side
def ball_mask(rgb: np.ndarray, target_rgb, hue_tol_deg: float = 20.0,
              min_saturation: float = 0.45, min_value: float = 0.2) -> np.ndarray:
    """uint8 mask (255 = ball colour) of an RGB(A) uint8 image: hue within
    hue_tol_deg / 2 OpenCV hue units (2 degrees each) of the target's, circularly;
    saturation and value at least the given fractions of 255."""
    rgb = (cv2.cvtColor(rgb, cv2.COLOR_RGBA2RGB) if rgb.shape[-1] == 4
           else np.ascontiguousarray(rgb))
    hsv = cv2.cvtColor(rgb, cv2.COLOR_RGB2HSV)
    target = np.uint8([[np.clip(np.asarray(target_rgb[:3], float) * 255, 0, 255)]])
    hue = int(cv2.cvtColor(target, cv2.COLOR_RGB2HSV)[0, 0, 0])   # 0..179 (2 deg)
    tol = int(np.floor(hue_tol_deg / 2.0))
    s_min, v_min = int(np.ceil(min_saturation * 255)), int(np.ceil(min_value * 255))
    # cv2.inRange (inclusive bounds) per hue interval; the hue circle wraps at 180
    mask = cv2.inRange(hsv, (max(hue - tol, 0), s_min, v_min), (min(hue + tol, 179), 255, 255))
    for lo, hi in ((hue - tol + 180, 179), (0, hue + tol - 180)):
        if lo <= hi and (hue - tol < 0 or hue + tol > 179):
            mask |= cv2.inRange(hsv, (max(lo, 0), s_min, v_min), (min(hi, 179), 255, 255))
    return mask


def fit_circle(points: np.ndarray):
    """Algebraic (Kasa) least-squares circle through N x 2 points: (u, v, r) or None."""
    if len(points) < 3:
        return None
    x, y = points[:, 0].astype(float), points[:, 1].astype(float)
    A = np.column_stack([x, y, np.ones_like(x)])
    b = -(x * x + y * y)
    sol, *_ = np.linalg.lstsq(A, b, rcond=None)
    u, v = -sol[0] / 2.0, -sol[1] / 2.0
    r2 = u * u + v * v - sol[2]
    if not np.isfinite(r2) or r2 <= 0:
        return None
    return u, v, np.sqrt(r2)


def refine_circle(contour_pts: np.ndarray, u: float, v: float, r: float,
                  band: float | None = None, min_arc: float = 0.3):
    """Refit (u, v, r) to the contour points within `band` px of the circle.

    Needs points covering at least min_arc of the circumference; otherwise returns the
    input. Contour points are the mask's boundary pixels (inside the edge), so 0.5 px
    is added to the fitted radius.
    """
    if contour_pts is None or len(contour_pts) == 0:
        return u, v, r
    band = max(2.0, 0.15 * r) if band is None else band
    for _ in range(2):
        d = np.hypot(contour_pts[:, 0] - u, contour_pts[:, 1] - v)
        near = contour_pts[np.abs(d - r) < band]
        if len(near) < min_arc * 2 * np.pi * r:
            break
        fit = fit_circle(near)
        if fit is None:
            break
        u, v, r = fit[0], fit[1], fit[2] + 0.5
        band = max(1.5, 0.5 * band)
    return u, v, r


def find_circles(rgb: np.ndarray, target_rgb, min_radius_px: float,
                 max_radius_px: float, accumulator_threshold: float | None = None,
                 max_circles: int = 5) -> np.ndarray:
    """Candidate ball circles in an image: array (n, 3) of [u, v, r] in pixels."""
    mask = ball_mask(rgb, target_rgb)
    if cv2.countNonZero(mask) < np.pi * min_radius_px ** 2 * 0.25:
        return np.zeros((0, 3))
    blurred = cv2.GaussianBlur(mask, (5, 5), 1.5)
    if accumulator_threshold is None:
        # Votes scale with the visible arc: ask for ~40% of the smallest circumference.
        accumulator_threshold = max(8.0, 0.4 * np.pi * min_radius_px)
    circles = cv2.HoughCircles(blurred, cv2.HOUGH_GRADIENT, dp=1,
                               minDist=max(2.0, 1.5 * min_radius_px), param1=100,
                               param2=accumulator_threshold,
                               minRadius=int(np.floor(min_radius_px)),
                               maxRadius=int(np.ceil(max_radius_px)))
    if circles is None:
        return np.zeros((0, 3))
    contours, _ = cv2.findContours(mask, cv2.RETR_LIST, cv2.CHAIN_APPROX_NONE)
    pts = (np.concatenate([c.reshape(-1, 2) for c in contours]) if contours
           else np.zeros((0, 2)))
    out = [refine_circle(pts, *c) for c in circles[0][:max_circles]]
    return np.array(out, float).reshape(-1, 3)


# --------------------------------------------------------------- geometry side
def project(p_W, K, R_WC, p_WC) -> np.ndarray:
    """Pixel (u, v) of a world point."""
    p_C = R_WC.T @ (np.asarray(p_W, float) - p_WC)
    return np.array([K[0, 0] * p_C[0] / p_C[2] + K[0, 2],
                     K[1, 1] * p_C[1] / p_C[2] + K[1, 2]])


def pixel_ray_W(u, v, K, R_WC) -> np.ndarray:
    """Unit direction, in W, of the ray through pixel (u, v)."""
    d_C = np.array([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], 1.0])
    d = R_WC @ d_C
    return d / np.linalg.norm(d)


def ray_plane_point(u, v, K, R_WC, p_WC, plane_z: float):
    """World point where the ray of pixel (u, v) meets the plane z = plane_z (or None)."""
    d = pixel_ray_W(u, v, K, R_WC)
    if abs(d[2]) < 1e-9:
        return None
    s = (plane_z - p_WC[2]) / d[2]
    return None if s <= 0 else p_WC + s * d


def silhouette_circle_px(P_W, radius, K, R_WC, p_WC):
    """(u, v, r): centre and mean radius (px) of a sphere's image (an ellipse).

    The ellipse's major axis lies along the line from the principal point through the
    projected centre; its end points are the images of the two silhouette-cone rays in
    the plane of the optical axis and the sphere's centre.
    """
    P_C = R_WC.T @ (np.asarray(P_W, float) - p_WC)
    D = np.linalg.norm(P_C)
    a = P_C / D
    beta = np.arcsin(min(radius / D, 0.999))
    e = np.array([0.0, 0.0, 1.0]) - a[2] * a            # in the (z, a) plane, _|_ a
    ne = np.linalg.norm(e)
    e = np.array([1.0, 0.0, 0.0]) - a[0] * a if ne < 1e-9 else e / ne
    e /= np.linalg.norm(e)
    ends = []
    for s in (1.0, -1.0):
        r_ = np.cos(beta) * a + s * np.sin(beta) * e
        ends.append(np.array([K[0, 0] * r_[0] / r_[2] + K[0, 2],
                              K[1, 1] * r_[1] / r_[2] + K[1, 2]]))
    centre = 0.5 * (ends[0] + ends[1])
    semi_major = 0.5 * np.linalg.norm(ends[0] - ends[1])
    # Semi-minor axis (approximately): the cone's half-width perpendicular to that
    # plane, f tan(beta) |m| with m = (x/z, y/z, 1) the centre's normalised ray.
    m = np.array([(centre[0] - K[0, 2]) / K[0, 0], (centre[1] - K[1, 2]) / K[1, 1], 1.0])
    semi_minor = K[0, 0] * np.tan(beta) * np.linalg.norm(m)
    return centre[0], centre[1], 0.5 * (semi_major + semi_minor)


def ball_centre_from_circle(u, v, K, R_WC, p_WC, centre_z: float, radius: float,
                            iterations: int = 3):
    """World centre of a ball resting with its centre at z = centre_z, from the image
    circle centre (u, v). Fixed-point correction of the perspective offset."""
    P = ray_plane_point(u, v, K, R_WC, p_WC, centre_z)
    if P is None:
        return None
    target = np.array([u, v])
    uv = target.copy()
    for _ in range(iterations):
        su, sv, _ = silhouette_circle_px(P, radius, K, R_WC, p_WC)
        uv = uv + (target - np.array([su, sv]))
        P_new = ray_plane_point(uv[0], uv[1], K, R_WC, p_WC, centre_z)
        if P_new is None:
            return P
        P = P_new
    return P


# ----------------------------------------------------------------- tracker
@dataclass(frozen=True)
class TrackerParams:
    """Gating and filter settings of tracker_step (m, s)."""
    ball_radius: float = 0.0315
    table_top_z: float = 0.0
    alpha: float = 0.5                 # position gain of the alpha-beta filter
    beta: float = 0.5 ** 2 / 1.5       # velocity gain (alpha^2 / (2 - alpha))
    gate: float = 0.03                 # accepted distance from the prediction, m
    max_speed: float = 1.0             # gate growth per second without detection, m/s
    max_gate: float = 0.15             # m
    radius_tolerance: float = 0.25     # |r_px / r_expected - 1| allowed
    workspace_min: tuple = (0.2, -0.4)     # xy box where a ball may be, m
    workspace_max: tuple = (0.9, 0.4)

    @property
    def centre_z(self) -> float:
        return self.table_top_z + self.ball_radius


# State vector layout of the tracker.
P, V, OK, INIT, T_MEAS = slice(0, 3), slice(3, 6), 6, 7, 8
STATE_SIZE = 9


def initial_tracker_state(params: TrackerParams, position_xy=(0.55, 0.0)) -> np.ndarray:
    x = np.zeros(STATE_SIZE)
    x[P] = [position_xy[0], position_xy[1], params.centre_z]
    return x


def tracker_prediction(x: np.ndarray, t: float, params: TrackerParams):
    """(predicted centre P_W (3,), gate radius m) at time t: where tracker_step looks
    for the ball, or None before the first acquisition (it then looks everywhere)."""
    if x[INIT] < 0.5:
        return None
    dt = t - x[T_MEAS]
    return x[P] + x[V] * dt, min(params.gate + params.max_speed * dt, params.max_gate)


def tracker_step(x: np.ndarray, t: float, candidates, params: TrackerParams) -> np.ndarray:
    """One 80 Hz update. candidates: iterable of (P_W (3,), radius_ratio) where
    radius_ratio = measured / expected pixel radius. Returns the new state."""
    x = np.array(x, float)
    lo, hi = np.asarray(params.workspace_min), np.asarray(params.workspace_max)
    good = [np.asarray(Pw, float) for Pw, ratio in candidates
            if Pw is not None and np.isfinite(Pw).all()
            and abs(ratio - 1.0) <= params.radius_tolerance
            and np.all(Pw[:2] >= lo) and np.all(Pw[:2] <= hi)]
    x[OK] = 0.0
    if x[INIT] < 0.5:
        if good:                       # first acquisition: nearest to the initial guess
            Pw = min(good, key=lambda c: np.linalg.norm(c[:2] - x[P][:2]))
            x[P], x[V] = Pw, 0.0
            x[OK], x[INIT], x[T_MEAS] = 1.0, 1.0, t
    else:
        dt = t - x[T_MEAS]
        pred, gate = tracker_prediction(x, t, params)
        dist = [np.linalg.norm(c[:2] - pred[:2]) for c in good]
        if dist and min(dist) <= gate and dt > 0:
            z = good[int(np.argmin(dist))]
            resid = z - pred
            x[P] = pred + params.alpha * resid
            x[V] = x[V] + params.beta / dt * resid
            x[OK], x[T_MEAS] = 1.0, t
    x[2], x[5] = params.centre_z, 0.0           # the ball stays on the table
    return x


def rolling_angular_velocity(v, radius: float) -> np.ndarray:
    """omega = r x v / |r|^2 with r = radius * z_hat (contact to centre): rolling
    without slip, omega = (1 / radius) z_hat x v."""
    v = np.asarray(v, float)
    return np.array([-v[1], v[0], 0.0]) / radius
