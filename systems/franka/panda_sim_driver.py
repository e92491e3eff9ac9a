"""Simulated Franka torque driver: adds gravity compensation to the torque command.

A real Franka in torque mode adds its own gravity compensation to the user's command;
this system plays that role in simulation (docs/hardware.md), so that
"panda.torque_command" means the same in simulation, over LCM and on the robot.

Ports:
  input  "panda.torque_command" (7)  joint torques (N m), without gravity
  input  "panda.state"          (14) q (rad), v (rad/s)
  output "panda.actuation"      (7)  command + tau_gravity_comp(q) (N m), for the
                                     plant's actuation input of the Panda instance;
                                     clipped to the joint effort limits if
                                     clip_to_limits (a real motor cannot exceed them).
                                     A non-finite command counts as zero (gravity
                                     compensation only); a non-finite state gives 0.
"""
from __future__ import annotations

import math

import numpy as np
from pydrake.systems.framework import LeafSystem

from adaptive_c3.models.ball_rolling_scene import make_arm_plant
from adaptive_c3.models.panda_kinematics import TAU_MAX

NQ = 7


class GravityCompensatedDriver(LeafSystem):
    """actuation = clip(torque_command - tau_g(q)); tau_g from an arm-only plant."""

    def __init__(self, *, clip_to_limits: bool = True, plant=None,
                 gravity_scale: float = 1.0):
        super().__init__()
        self._plant = plant if plant is not None else make_arm_plant()
        self._context = self._plant.CreateDefaultContext()
        self._clip = clip_to_limits
        self._scale = float(gravity_scale)   # != 1 models a payload/model mismatch
        self._cmd = self.DeclareVectorInputPort("panda.torque_command", NQ)
        self._state = self.DeclareVectorInputPort("panda.state", 2 * NQ)
        self.DeclareVectorOutputPort("panda.actuation", NQ, self._calc)

    def gravity_compensation(self, q) -> np.ndarray:
        """Joint torques (N m) that hold the arm still against gravity at q."""
        self._plant.SetPositions(self._context, np.asarray(q, float))
        # Drake's tau_g is the generalized gravity force (on the right-hand side of
        # M vdot + C v = tau_g + tau): compensating it means applying -tau_g.
        return -self._scale * self._plant.CalcGravityGeneralizedForces(self._context)

    def _calc(self, context, output):
        cmd = self._cmd.Eval(context)
        q = self._state.Eval(context)[:NQ]
        if not math.isfinite(q @ q):          # x'x: finite iff every entry is
            output.SetFromVector(np.zeros(NQ))
            return
        if not math.isfinite(cmd @ cmd):
            cmd = np.zeros(NQ)      # like the robot: hold against gravity only
        tau = cmd + self.gravity_compensation(q)
        if self._clip:
            tau = np.minimum(np.maximum(tau, -TAU_MAX), TAU_MAX)
        output.SetFromVector(tau)
