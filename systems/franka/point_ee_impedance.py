"""`PointEeImpedance`: Cartesian impedance for a point end-effector (robot: point_ee).

The point EE is a sphere on three world prismatic joints (x, y, z) with force
actuators - the controller model's own EE, with a realistic mass. The law mirrors the
Panda's: f = K (p_des - p) + D (v_des - v) + f_ff + m g_comp, clipped to max_force.

Ports (world frame W; m, m/s, N):
  input  point_ee.state        (6) [x, y, z, vx, vy, vz] (the EE instance's plant state)
  input  ee.desired_state      (6) desired position then velocity
  input  ee.feedforward_force  (3) optional, zero if unconnected
  output point_ee.actuation    (3) joint forces; zero if any input is non-finite
  output ee.state              (6) the measured EE state (same as the input)
  output ee.commanded_force    (3) the actuation without the weight compensation
"""
from __future__ import annotations

import numpy as np
from pydrake.systems.framework import LeafSystem


class PointEeImpedance(LeafSystem):
    def __init__(self, *, stiffness: float = 500.0, damping: float = 45.0,
                 mass: float = 1.0, gravity: float = 9.81, max_force: float = 50.0):
        super().__init__()
        self._K, self._D, self._mg, self._fmax = stiffness, damping, mass * gravity, max_force
        self._x = self.DeclareVectorInputPort("point_ee.state", 6)
        self._des = self.DeclareVectorInputPort("ee.desired_state", 6)
        self._ff = self.DeclareVectorInputPort("ee.feedforward_force", 3)
        self.DeclareVectorOutputPort("point_ee.actuation", 3, self._calc)
        self.DeclareVectorOutputPort("ee.state", 6,
                                     lambda c, o: o.SetFromVector(self._x.Eval(c)),
                                     prerequisites_of_calc={self._x.ticket()})
        self.DeclareVectorOutputPort("ee.commanded_force", 3, self._calc_force)

    def _calc_force(self, context, out):
        f = self.get_output_port(0).Eval(context).copy()
        if np.any(f):
            f[2] -= self._mg
        out.SetFromVector(f)

    def _calc(self, context, out):
        x, des = self._x.Eval(context), self._des.Eval(context)
        ff = self._ff.Eval(context) if self._ff.HasValue(context) else np.zeros(3)
        if not (np.isfinite(x).all() and np.isfinite(des).all() and np.isfinite(ff).all()):
            out.SetFromVector(np.zeros(3))
            return
        f = self._K * (des[:3] - x[:3]) + self._D * (des[3:] - x[3:]) + ff
        f[2] += self._mg
        n = np.linalg.norm(f)
        if n > self._fmax:
            f *= self._fmax / n
        out.SetFromVector(f)


__all__ = ["PointEeImpedance"]
