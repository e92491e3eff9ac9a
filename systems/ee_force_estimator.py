"""`EeForceEstimator`: the EE input the controller model would need to move as measured.

The residual learner must see the input that was actually applied over a transition,
not the one C3 planned: on a real arm the impedance controller, not the plan, decides
the force at the tip. In the controller model the EE is a point mass m on prismatic
joints, so the input consistent with the measured motion is

    u = m (v_now - v_prev) / h + m g z_hat        (N, world frame)

sampled every h seconds. Averaged over a transition of S samples (as the learner does)
this is m times the mean acceleration plus the weight. The EE-ball contact reaction is
included in the measured acceleration; with Q_d on the ball's velocity only, the
learner's loss does not weigh the EE's own prediction.

Ports (world frame W; m/s, N):
  input  ee.state          (6) EE position then velocity
  output ee.applied_force  (3) u above (held between samples; 0 before two samples
                               and after a non-finite one)
"""
from __future__ import annotations

import numpy as np
from pydrake.systems.framework import LeafSystem


class EeForceEstimator(LeafSystem):
    def __init__(self, *, mass: float, period: float = 1.0 / 200.0, gravity: float = 9.81):
        super().__init__()
        if not (np.isfinite(mass) and mass > 0 and period > 0):
            raise ValueError("EeForceEstimator needs mass > 0 and period > 0")
        self._m, self._h, self._g = float(mass), float(period), float(gravity)
        self._in = self.DeclareVectorInputPort("ee.state", 6)
        # [v_prev (3), u (3), have_prev]
        self._xd = self.DeclareDiscreteState(np.zeros(7))
        self.DeclarePeriodicDiscreteUpdateEvent(self._h, 0.0, self._update)
        self.DeclareVectorOutputPort(
            "ee.applied_force", 3,
            lambda c, o: o.SetFromVector(c.get_discrete_state(self._xd).get_value()[3:6]),
            prerequisites_of_calc={self.xd_ticket()})

    def _update(self, context, discrete_state):
        s = context.get_discrete_state(self._xd).get_value().copy()
        v = np.asarray(self._in.Eval(context), float)[3:6]
        if not np.all(np.isfinite(v)):
            s[:] = 0.0
        else:
            if s[6] > 0.5:
                s[3:6] = self._m * (v - s[0:3]) / self._h
                s[5] += self._m * self._g
            s[0:3], s[6] = v, 1.0
        discrete_state.get_mutable_vector(self._xd).set_value(s)


__all__ = ["EeForceEstimator"]
