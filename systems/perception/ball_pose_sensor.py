"""`BallPoseSensor`: the ball estimate without a camera - the true pose plus noise.

Stands in for camera + detector when the camera is off (fast runs, sweeps): every
`period` seconds it samples the ball's true position from the plant, adds zero-mean
Gaussian noise (std `noise_m` per axis, seeded), low-pass filters it with weight
`alpha` on the newest sample and differentiates the filtered position for velocity,
as the detector does.

Ports (world frame W; m, m/s):
  input  ball.true_state  (13) the ball instance's plant state [quat wxyz, xyz, w, v]
  output ball.position    (3)  filtered centre
  output ball.velocity    (3)  filtered velocity (z = 0)
"""
from __future__ import annotations

import numpy as np
from pydrake.systems.framework import LeafSystem


class BallPoseSensor(LeafSystem):
    def __init__(self, *, period: float = 1.0 / 80.0, noise_m: float = 0.0,
                 alpha: float = 0.5, seed: int = 0, initial_position=(0.55, 0.0, 0.03)):
        super().__init__()
        if not (0 < alpha <= 1):
            raise ValueError(f"alpha must be in (0, 1], got {alpha}")
        if not (np.isfinite(noise_m) and noise_m >= 0):
            raise ValueError(f"noise_m must be >= 0, got {noise_m}")
        self._period, self._noise, self._alpha = float(period), float(noise_m), float(alpha)
        self._rng = np.random.default_rng(seed)
        self._in = self.DeclareVectorInputPort("ball.true_state", 13)
        # [p (3), v (3), initialised flag]
        self._xd = self.DeclareDiscreteState(np.r_[np.asarray(initial_position, float),
                                                   np.zeros(3), 0.0])
        self.DeclarePeriodicDiscreteUpdateEvent(self._period, 0.0, self._update)
        self.DeclareInitializationDiscreteUpdateEvent(self._update)
        ticket = {self.xd_ticket()}
        self.DeclareVectorOutputPort("ball.position", 3,
                                     lambda c, o: o.SetFromVector(self._s(c)[0:3]),
                                     prerequisites_of_calc=ticket)
        self.DeclareVectorOutputPort("ball.velocity", 3,
                                     lambda c, o: o.SetFromVector(self._s(c)[3:6]),
                                     prerequisites_of_calc=ticket)

    def _s(self, context):
        return context.get_discrete_state(self._xd).get_value()

    def _update(self, context, discrete_state):
        s = self._s(context).copy()
        true = np.asarray(self._in.Eval(context), float)
        if not np.isfinite(true).all():
            return   # hold the last estimate
        meas = true[4:7] + self._rng.normal(0.0, self._noise, 3) * (self._noise > 0)
        if s[6] < 0.5:
            s[0:3], s[3:6], s[6] = meas, 0.0, 1.0
        else:
            p_new = (1 - self._alpha) * s[0:3] + self._alpha * meas
            v = (p_new - s[0:3]) / self._period
            v[2] = 0.0
            s[0:3], s[3:6] = p_new, v
        discrete_state.get_mutable_vector(self._xd).set_value(s)


__all__ = ["BallPoseSensor"]
