"""The ball-rolling gait: roll / return phases, C3 targets and the EE command (pure numpy).

The EE does not roll the ball in one continuous contact. Each period of
roll_s + return_s seconds it

  roll    C3 plans with contact: EE target just above the ball's top, ball target on the
          circle leading the ball by lead_deg (counter-clockwise);
  lift    EE straight up to lift_height above the model's "touching the top" height;
  side    EE moves behind the ball (back_distance from the ball centre, opposite to the
          ball's direction of travel) at the same height;
  place   EE lowers onto the ball's upper back (place_height, negative = pressing).

Heights are relative to the model's touching height h_touch = 2 R_model + r_ee - gap,
where `gap` (m) is the learned EE-ball gap offset (the residual r_comp of the EE-ball
contact times the LCS step): the learned offset shifts the return heights too, unless
`use_learned_gap` is off (then gap = 0 in every height). The floor of the commanded EE
height (`floor_height`) is either h_touch + min_height ("gap", moves with the learned
gap) or r_ee + table_clearance above the table ("table": independent of the learner and
of the model ball).
The return sub-phases last return_s / 3 each. Before the first period the EE settles
for settle_s above the ball's start (the lift pose).

Frames and units: world frame W = robot base frame (table top z = 0), m, s, rad.
The state layout is models/ball_rolling_controller_model.STATE_NAMES (19).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from adaptive_c3.models.ball_rolling_controller_model import (BALL_POS, BALL_QUAT,
                                                              EE_POS, EE_VEL)

PHASES = ("settle", "roll", "lift", "side", "place")


@dataclass(frozen=True)
class GaitSettings:
    roll_s: float = 1.0
    return_s: float = 0.5
    settle_s: float = 0.5
    back_distance: float = 0.02     # m, EE behind the ball centre in side/place
    roll_height: float = 0.02       # m above h_touch: the roll-phase EE target
    lift_height: float = 0.03       # m above h_touch in lift and side
    place_height: float = -0.005    # m above h_touch in place (negative: pressing)
    max_ee_speed: float = 1.0       # m/s clamp on the commanded EE motion
    min_height: float = -0.01       # m above h_touch: floor of the commanded EE height
    roll_lead: float = 0.0          # roll-phase EE target xy: 0 over the ball, 1 over its target
    return_mode: str = "c3"         # "c3": C3 with the return weights; "waypoint": straight
                                    # lines to the phase's EE target at return_speed
    return_speed: float = 0.5       # m/s, EE speed toward the waypoint ("waypoint" mode)
    place_xy_tolerance: float = 0.0 # m; > 0: the place phase lowers the EE only once the
                                    # measured EE is within this distance (x-y) of its
                                    # place point (a lagging arm lands on the object's
                                    # front and drags it back); 0: lower at once
    use_learned_gap: bool = True    # false: gap = 0 in every height (and the "gap" floor)
    floor: str = "gap"              # "gap" | "table" (module docstring)
    table_clearance: float = 0.005  # m, the "table" floor's clearance of the EE sphere


@dataclass(frozen=True)
class CirclePath:
    center: tuple = (0.55, 0.0)     # m
    radius: float = 0.1             # m
    lead_deg: float = 20.0          # deg ahead of the ball (counter-clockwise)

    def angle_of(self, xy) -> float:
        return math.atan2(xy[1] - self.center[1], xy[0] - self.center[0])

    def point(self, angle: float) -> np.ndarray:
        return np.array([self.center[0] + self.radius * math.cos(angle),
                         self.center[1] + self.radius * math.sin(angle)])

    def target_for(self, ball_xy) -> np.ndarray:
        """The ball target: the circle point lead_deg ahead of the ball's angle."""
        return self.point(self.angle_of(ball_xy) + math.radians(self.lead_deg))


class RollingGait:
    """Phase clock and C3 state targets for the ball-rolling gait."""

    def __init__(self, settings: GaitSettings, path: CirclePath, *, ball_radius: float,
                 ee_radius: float, start_time: float = 0.0):
        self.s, self.path = settings, path
        self.R, self.r_ee = float(ball_radius), float(ee_radius)
        self.t0 = float(start_time)

    @property
    def period(self) -> float:
        return self.s.roll_s + self.s.return_s

    def phase(self, t: float) -> tuple[str, int]:
        """(phase name, index of the gait period; -1 while settling)."""
        tau = t - self.t0 - self.s.settle_s
        if tau < 0:
            return "settle", -1
        k = int(tau // self.period)
        tp = tau - k * self.period
        if tp < self.s.roll_s:
            return "roll", k
        sub = (tp - self.s.roll_s) / (self.s.return_s / 3.0)
        return ("lift", "side", "place")[min(int(sub), 2)], k

    def touch_height(self, gap: float = 0.0) -> float:
        """Model EE-centre height when touching the ball's top, corrected by gap (m)."""
        return 2.0 * self.R + self.r_ee - gap

    def gait_gap(self, learned_gap: float) -> float:
        """The gap (m) the gait's heights use: the learned one, or 0 (use_learned_gap off)."""
        return float(learned_gap) if self.s.use_learned_gap else 0.0

    def floor_height(self, gap: float) -> float:
        """Lowest commanded EE-centre height (m, W) given the gait's gap (see module doc)."""
        if self.s.floor == "table":
            return self.r_ee + self.s.table_clearance
        return self.touch_height(gap) + self.s.min_height

    def ee_target(self, phase: str, x: np.ndarray, gap: float = 0.0) -> np.ndarray:
        """The EE position target (3) of a phase from the estimated state x (19)."""
        ball = x[BALL_POS]
        h = self.touch_height(gap)
        if phase == "roll":
            xy = ball[:2] + self.s.roll_lead * (self.path.target_for(ball[:2]) - ball[:2])
            return np.array([xy[0], xy[1], h + self.s.roll_height])
        if phase == "lift":
            return np.array([x[EE_POS][0], x[EE_POS][1], h + self.s.lift_height])
        direction = self.travel_direction(ball[:2])
        behind = ball[:2] - self.s.back_distance * direction
        if phase == "place":
            tol = self.s.place_xy_tolerance
            if tol > 0 and np.linalg.norm(x[EE_POS][:2] - behind) > tol:
                return np.array([behind[0], behind[1], h + self.s.lift_height])
            return np.array([behind[0], behind[1], h + self.s.place_height])
        # settle and side: behind the ball, lifted
        return np.array([behind[0], behind[1], h + self.s.lift_height])

    def travel_direction(self, ball_xy) -> np.ndarray:
        """Unit vector from the ball to its target (the direction it should roll)."""
        e = self.path.target_for(ball_xy) - np.asarray(ball_xy, float)
        n = np.linalg.norm(e)
        return e / n if n > 1e-9 else np.array([1.0, 0.0])

    def target_state(self, phase: str, x: np.ndarray, gap: float = 0.0) -> np.ndarray:
        """The C3 target (19): EE target of the phase, ball at its circle target, at rest."""
        xt = np.zeros_like(x)
        xt[EE_POS] = self.ee_target(phase, x, gap)
        xt[BALL_QUAT] = [1.0, 0.0, 0.0, 0.0]
        xt[BALL_POS] = np.r_[self.path.target_for(x[BALL_POS][:2]), self.R]
        return xt


def step_toward(p_from, goal, speed: float, dt: float):
    """One period of a straight-line move from p_from toward goal at `speed` (m/s);
    returns (p_des, v_des), v_des zero once the goal is reached."""
    p_from, goal = np.asarray(p_from, float), np.asarray(goal, float)
    e = goal - p_from
    n = float(np.linalg.norm(e))
    if n <= speed * dt:
        return goal.copy(), np.zeros(3)
    direction = e / n
    return p_from + speed * dt * direction, speed * direction


def clamp_ee_command(p_now, p_next, v_next, dt: float, max_speed: float):
    """Limit the commanded EE step to max_speed (m/s) over dt; returns (p_des, v_des)."""
    p_now, p_next, v_next = (np.asarray(a, float) for a in (p_now, p_next, v_next))
    step = p_next - p_now
    n = np.linalg.norm(step)
    if n > max_speed * dt:
        step *= max_speed * dt / n
    sv = np.linalg.norm(v_next)
    if sv > max_speed:
        v_next = v_next * (max_speed / sv)
    return p_now + step, v_next


__all__ = ["PHASES", "GaitSettings", "CirclePath", "RollingGait", "clamp_ee_command",
           "step_toward"]
