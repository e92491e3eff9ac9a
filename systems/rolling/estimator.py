"""`BallRollingEstimator`: EE and ball measurements -> the controller's 19-state.

Stateless and direct-feedthrough. The ball's orientation is not observed (a uniform
sphere's orientation does not enter the LCS's contact geometry), so the quaternion is
identity; its height is the model's radius (the ball rests on the table as far as the
model knows - the true radius is what the learner has to find out); its angular
velocity follows the rolling assumption omega = (z_hat x v) / R_model.

Input ports (world frame W = robot base frame, table top z = 0; m, m/s):
  ee.state       (6)  EE tip position then velocity.
  ball.position  (3)  estimated ball centre (only x, y are used).
  ball.velocity  (3)  estimated ball velocity (only x, y are used).
Output port:
  lcs_state      (19) models/ball_rolling_controller_model.STATE_NAMES order; all NaN
                      if any input is non-finite (downstream systems hold).
"""
from __future__ import annotations

import numpy as np
from pydrake.systems.framework import LeafSystem

from adaptive_c3.models.ball_rolling_controller_model import (BALL_ANGVEL, BALL_POS,
                                                              BALL_QUAT, BALL_VEL,
                                                              EE_POS, EE_VEL, STATE_NAMES)


def lcs_state(ee_state, ball_position, ball_velocity, model_radius: float) -> np.ndarray:
    """The 19-state from measurements (see the module docstring)."""
    ee = np.asarray(ee_state, float)
    p = np.asarray(ball_position, float)
    v = np.asarray(ball_velocity, float)
    x = np.zeros(len(STATE_NAMES))
    if not (np.isfinite(ee).all() and np.isfinite(p[:2]).all()
            and np.isfinite(v[:2]).all()):
        return np.full(len(STATE_NAMES), np.nan)
    x[EE_POS], x[EE_VEL] = ee[:3], ee[3:6]
    x[BALL_QUAT] = [1.0, 0.0, 0.0, 0.0]
    x[BALL_POS] = [p[0], p[1], model_radius]
    x[BALL_VEL] = [v[0], v[1], 0.0]
    x[BALL_ANGVEL] = [-v[1] / model_radius, v[0] / model_radius, 0.0]   # z_hat x v / R
    return x


class BallRollingEstimator(LeafSystem):
    """Assembles the LCS state from EE and ball estimates (see module docstring)."""

    def __init__(self, model_radius: float):
        super().__init__()
        if not (np.isfinite(model_radius) and model_radius > 0):
            raise ValueError(f"model_radius must be > 0, got {model_radius}")
        self._R = float(model_radius)
        self._ee = self.DeclareVectorInputPort("ee.state", 6)
        self._p = self.DeclareVectorInputPort("ball.position", 3)
        self._v = self.DeclareVectorInputPort("ball.velocity", 3)
        self.DeclareVectorOutputPort("lcs_state", len(STATE_NAMES), self._calc)

    def _calc(self, context, out):
        out.SetFromVector(lcs_state(self._ee.Eval(context), self._p.Eval(context),
                                    self._v.Eval(context), self._R))


__all__ = ["BallRollingEstimator", "lcs_state"]
