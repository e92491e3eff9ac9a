"""The state a rollout starts from, estimated from an episode's first rows.

A recorded first row is noisy: the tosses' velocity is a backward difference of camera
positions at 148 Hz (about 0.2 mm of position noise gives ~0.04 m/s of velocity noise),
and a rollout carries that error for its whole length. `ballistic` fits the free-flight
prefix instead (the rows before the lowest corner first comes within CONTACT_GAP of the
table, at most MAX_ROWS of them, at least MIN_ROWS):
- position: p(t) = p0 + v0 t - g t^2 / 2 (world z up) by least squares;
- orientation: the body-frame rate w from the mean rotation between successive rows (a
  torque-free cube spins at a constant body rate), q0 the mean of the rows rotated back
  to t0 with it.
The estimate is returned in the recording layout and convention: the linear velocity is
the one a backward difference over one recording step would give at t0 (v(t0 - dt/2) in
flight), so a model stepping at the recording's dt can start from it directly (backends
stepping finer shift it themselves, see drake_backend.py). Episodes without MIN_ROWS of
free flight keep their first row. Every model compared starts from the same estimate.
Pure numpy.
"""
from __future__ import annotations

import numpy as np

METHODS = ("first-row", "ballistic")
CONTACT_GAP = 0.004      # m, lowest corner above the table that still counts as free flight
MAX_ROWS = 12
MIN_ROWS = 4
GRAVITY = 9.81           # m/s^2


def quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product of [..., 4] quaternions (w, x, y, z)."""
    aw, ax, ay, az = np.moveaxis(np.asarray(a, float), -1, 0)
    bw, bx, by, bz = np.moveaxis(np.asarray(b, float), -1, 0)
    return np.stack([aw * bw - ax * bx - ay * by - az * bz,
                     aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw], -1)


def quat_conj(q: np.ndarray) -> np.ndarray:
    return np.asarray(q, float) * np.array([1.0, -1.0, -1.0, -1.0])


def quat_log(q: np.ndarray) -> np.ndarray:
    """[..., 4] unit quaternions -> [..., 3] rotation vectors (rad), the short way round."""
    q = np.asarray(q, float)
    q = q * np.where(q[..., :1] < 0, -1.0, 1.0)
    s = np.linalg.norm(q[..., 1:], axis=-1, keepdims=True)
    angle = 2.0 * np.arctan2(s, q[..., :1])
    return q[..., 1:] * np.where(s > 1e-12, angle / np.maximum(s, 1e-300), 2.0)


def quat_exp(r: np.ndarray) -> np.ndarray:
    """[..., 3] rotation vectors (rad) -> [..., 4] unit quaternions."""
    r = np.asarray(r, float)
    a = np.linalg.norm(r, axis=-1, keepdims=True)
    k = np.where(a > 1e-12, np.sin(a / 2) / np.maximum(a, 1e-300), 0.5)
    return np.concatenate([np.cos(a / 2), r * k], axis=-1)


def free_flight_rows(x: np.ndarray, half_size, table_height: float) -> int:
    """How many leading rows of x [T, 13] have every corner above the table by CONTACT_GAP
    (capped at MAX_ROWS)."""
    from adaptive_c3.tools.diagnosis.tasks.rigid_object.rigid_locate import lowest_corner
    n = min(len(x), MAX_ROWS)
    touching = lowest_corner(x[:n], half_size, table_height) < CONTACT_GAP
    return int(np.argmax(touching)) if touching.any() else n


def ballistic_start(x: np.ndarray, dt: float, half_size, table_height: float) -> np.ndarray:
    """The recording-layout start state fitted to x's free-flight prefix (the first row
    when the prefix is shorter than MIN_ROWS)."""
    x = np.asarray(x, float)
    n = free_flight_rows(x, half_size, table_height)
    if n < MIN_ROWS:
        return x[0].copy()
    t = np.arange(n) * dt
    A = np.column_stack([np.ones(n), t])
    gravity = np.zeros((n, 3))
    gravity[:, 2] = -0.5 * GRAVITY * t ** 2
    coef, *_ = np.linalg.lstsq(A, x[:n, 0:3] - gravity, rcond=None)
    p0, v0 = coef
    q = x[:n, 3:7] / np.linalg.norm(x[:n, 3:7], axis=1, keepdims=True)
    q = q * np.where(np.sum(q * q[0], axis=1, keepdims=True) < 0, -1.0, 1.0)
    w_body = quat_log(quat_mul(quat_conj(q[:-1]), q[1:])).mean(axis=0) / dt
    back = quat_mul(q, quat_exp(-np.outer(t, w_body)))       # each row rotated back to t0
    q0 = back.mean(axis=0)
    out = x[0].copy()
    out[0:3] = p0
    out[3:7] = q0 / np.linalg.norm(q0)
    out[7:10] = v0 + np.array([0.0, 0.0, 0.5 * GRAVITY * dt])     # v(t0 - dt/2)
    out[10:13] = w_body
    return out


def initial_states(episodes: dict, dt: float, method: str, half_size,
                   table_height: float) -> dict:
    """{episode id: recording-layout start state} for {id: x [T, 13]} by METHODS' method."""
    if method == "first-row":
        return {e: np.asarray(x, float)[0].copy() for e, x in episodes.items()}
    if method == "ballistic":
        return {e: ballistic_start(x, dt, half_size, table_height) for e, x in episodes.items()}
    raise ValueError(f"unknown initial-state method '{method}' (known: {', '.join(METHODS)})")
