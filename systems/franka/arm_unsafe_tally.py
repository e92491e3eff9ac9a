"""UnsafeTally: how long the simulated robot was out of control (numpy core of
ArmUnsafeMonitor, arm_unsafe_monitor.py).

The robot is UNSAFE at an instant when any of
  torque  a joint's applied torque (without gravity) at its limit (>= 98 % of the
          Panda's [87 x 4, 12 x 3] N m) for longer than saturation_s (0.05 s)
  joint   a joint within margin_deg (2 deg) of the Panda's position limit
  ball    the ball off the table: its centre below half its radius above the table
          top, or outside the table's x-y extent
holds. The tally adds time (s of the driver's simulation) to: unsafe_s (unsafe while the
driver applied a controller's commands - not while it held the arm with its own damping
after commands stopped or expired, which is what a safe stop ends in), unsafe_total_s
(either way) and the time each condition held. State vector layout below.
"""
from __future__ import annotations

import math

import numpy as np

from adaptive_c3.models.ball_rolling_scene import TABLE_CENTER_XY, TABLE_SIZE, TABLE_TOP_Z
from adaptive_c3.models.panda_kinematics import Q_MAX, Q_MIN, TAU_MAX

NQ = 7
SAT_RUN = slice(0, NQ)          # s each joint's torque has been at its limit
HELD_TICKS = NQ                 # the driver's ticks-held counter at the last update
UNSAFE, UNSAFE_TOTAL, TORQUE_S, JOINT_S, BALL_S, NOW = range(NQ + 1, NQ + 7)
STATE_SIZE = NQ + 7             # NOW: bit flags of the conditions at the last update
TORQUE, JOINT, BALL = 1, 2, 4
REASONS = {TORQUE: "torque_at_limit", JOINT: "joint_near_limit", BALL: "ball_off_table"}
AT_LIMIT = 0.98


def reasons(bits: int) -> list:
    return [name for bit, name in REASONS.items() if int(bits) & bit]


class UnsafeTally:
    def __init__(self, ball_radius: float, *, saturation_s: float = 0.05,
                 margin_deg: float = 2.0):
        self.saturation_s = float(saturation_s)
        margin = math.radians(margin_deg)
        self.q_lo, self.q_hi = Q_MIN + margin, Q_MAX - margin
        self.ball_z_min = TABLE_TOP_Z + 0.5 * ball_radius
        half = np.asarray(TABLE_SIZE[:2]) / 2
        self.xy_lo = np.asarray(TABLE_CENTER_XY) - half
        self.xy_hi = np.asarray(TABLE_CENTER_XY) + half

    @staticmethod
    def initial_state() -> np.ndarray:
        return np.zeros(STATE_SIZE)

    def step(self, s, dt: float, q, tau, ball_p, held_ticks: float) -> np.ndarray:
        """The state after dt seconds with joint positions q (rad), applied torques tau
        (N m, without gravity), ball centre ball_p (m, W) and the driver's ticks-held
        counter (it grew: the driver held the arm itself in this interval)."""
        s = np.array(s, float)
        at_limit = np.abs(np.asarray(tau, float)) >= AT_LIMIT * TAU_MAX
        s[SAT_RUN] = np.where(at_limit, s[SAT_RUN] + dt, 0.0)
        q = np.asarray(q, float)
        p = np.asarray(ball_p, float)
        bits = 0
        if np.any(s[SAT_RUN] > self.saturation_s + 1e-9):
            bits |= TORQUE
        if np.any(q < self.q_lo) or np.any(q > self.q_hi) or not np.all(np.isfinite(q)):
            bits |= JOINT
        if (not np.all(np.isfinite(p)) or p[2] < self.ball_z_min
                or np.any(p[:2] < self.xy_lo) or np.any(p[:2] > self.xy_hi)):
            bits |= BALL
        holding = held_ticks > s[HELD_TICKS]
        s[HELD_TICKS] = held_ticks
        if bits:
            s[UNSAFE_TOTAL] += dt
            s[UNSAFE] += 0.0 if holding else dt
        s[TORQUE_S] += dt if bits & TORQUE else 0.0
        s[JOINT_S] += dt if bits & JOINT else 0.0
        s[BALL_S] += dt if bits & BALL else 0.0
        s[NOW] = bits
        return s

    @staticmethod
    def report(s) -> dict:
        return {"unsafe_s": float(s[UNSAFE]), "unsafe_total_s": float(s[UNSAFE_TOTAL]),
                "unsafe_by_reason_s": {"torque_at_limit": float(s[TORQUE_S]),
                                       "joint_near_limit": float(s[JOINT_S]),
                                       "ball_off_table": float(s[BALL_S])}}
