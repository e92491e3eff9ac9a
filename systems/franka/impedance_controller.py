"""Cartesian impedance controller for the Panda's EE tip (Drake LeafSystem).

A thin wrapper of systems/franka/impedance_law.py: it evaluates the tip pose, Jacobian, mass
matrix and Coriolis term on an internal plant (the arm alone, from models/panda.urdf)
and applies the law. Stateless and direct-feedthrough: with a discrete plant at 1 ms it
acts as a 1 kHz controller (the plant's step is the zero-order hold).

Ports (world frame W = robot base frame, SI units):
  input  "panda.state"          (14) joint positions q (rad) then velocities v (rad/s)
  input  "ee.desired_state"     (6)  desired tip position (m) then velocity (m/s), in W
  input  "ee.feedforward_force" (3)  force (N, in W) the controller adds at the tip,
                                     e.g. the plan's EE force; optional, zero if
                                     unconnected
  input  "ee.desired_orientation" (4) desired tip orientation R_WE as a quaternion
                                     [w, x, y, z]; optional, the fixed `ee_rotation`
                                     if unconnected
  output "panda.torque_command" (7)  joint torques (N m) WITHOUT gravity compensation,
                                     clipped to the torque limits; zero if an input is
                                     non-finite
  output "ee.state"             (6)  measured tip position (m) and velocity (m/s) in W
                                     (depends on "panda.state" only)
  output "ee.commanded_force"   (3)  the translational tip force the law commands (N, W):
                                     K (p_des - p) + D (v_des - v) + feed-forward, before
                                     torque limits; zero on non-finite input
Gains: ImpedanceGains (reference values by default; the law is the reference's plain
J' F, see impedance_law.py for the operational_space option and why: with the Panda's
reflected motor inertia the default gains are under-damped along x, ~0.25).
The tip is the frame `panda_ee_tip` (centre of the 0.0195 m tool sphere). Without the
orientation input the EE orientation is held at `ee_rotation` (default: tilted 15
degrees, tip leaning towards the base; see impedance_law.tilted_ee_rotation).
"""
from __future__ import annotations

import math

import numpy as np
from pydrake.multibody.tree import JacobianWrtVariable
from pydrake.systems.framework import LeafSystem

from adaptive_c3.models.ball_rolling_scene import EE_TIP_FRAME, make_arm_plant
from adaptive_c3.systems.franka.impedance_law import (Q_NULL, ImpedanceGains,
                                               impedance_torque,
                                               quaternion_to_rotation,
                                               tilted_ee_rotation)

NQ = 7


class ArmModel:
    """The arm-only plant and one context of it, for kinematics and dynamics queries."""

    def __init__(self, plant=None):
        self.plant = plant if plant is not None else make_arm_plant()
        self.context = self.plant.CreateDefaultContext()
        self.tip = self.plant.GetFrameByName(EE_TIP_FRAME)
        self.world = self.plant.world_frame()

    def set_state(self, q, v) -> None:
        self.plant.SetPositions(self.context, q)
        self.plant.SetVelocities(self.context, v)

    def tip_pose(self):
        """(p_WE (3,), R_WE (3, 3)) of the tip."""
        X = self.plant.CalcRelativeTransform(self.context, self.world, self.tip)
        return X.translation(), X.rotation().matrix()

    def tip_jacobian(self) -> np.ndarray:
        """6 x 7 spatial-velocity Jacobian of the tip in W, rows [angular; translational]."""
        return self.plant.CalcJacobianSpatialVelocity(
            self.context, JacobianWrtVariable.kV, self.tip, np.zeros(3),
            self.world, self.world)


class ImpedanceLaw:
    """The law of impedance_law.py evaluated on an arm state: the arm model, the gains,
    the held orientation and the posture. Framework-free, so that the 1 kHz process can
    call it without a Drake diagram (tools/hardware/impedance_tick.py)."""

    def __init__(self, gains: ImpedanceGains = ImpedanceGains(), *, ee_rotation=None,
                 tilt_deg: float = 15.0, q_null=Q_NULL, compensate_coriolis: bool = True,
                 plant=None):
        self.gains = gains
        self.R_des = (tilted_ee_rotation(tilt_deg) if ee_rotation is None
                      else np.asarray(ee_rotation, float).reshape(3, 3))
        self.q_null = np.asarray(q_null, float).reshape(NQ)
        self._coriolis = compensate_coriolis
        self.arm = ArmModel(plant)

    def torque(self, x, des, f_ff, R_des=None) -> np.ndarray:
        """(7) N m without gravity for arm state x (14), desired tip state des (6, m and
        m/s in W) and feed-forward f_ff (3, N); zeros if any input is non-finite."""
        # the plant refuses non-finite joint values; impedance_torque checks the rest
        if not math.isfinite(x @ x):
            return np.zeros(NQ)
        q, v = x[:NQ], x[NQ:]
        arm = self.arm
        arm.set_state(q, v)
        p, R = arm.tip_pose()
        J = arm.tip_jacobian()
        M = arm.plant.CalcMassMatrix(arm.context)
        cor = arm.plant.CalcBiasTerm(arm.context) if self._coriolis else None
        return impedance_torque(J=J, M=M, p=p, R=R, q=q, v=v, p_des=des[:3], v_des=des[3:],
                                R_des=self.R_des if R_des is None else R_des, f_ff=f_ff,
                                q_null=self.q_null, gains=self.gains, coriolis=cor)

    def tip_state(self, x) -> np.ndarray:
        """(6) tip position (m) and velocity (m/s) in W; NaN for a non-finite state."""
        if not np.isfinite(x).all():
            return np.full(6, np.nan)
        self.arm.set_state(x[:NQ], x[NQ:])
        p, _ = self.arm.tip_pose()
        return np.concatenate([p, (self.arm.tip_jacobian() @ x[NQ:])[3:]])

    def commanded_force(self, x, des, f_ff) -> np.ndarray:
        """(3) N in W: K (p_des - p) + D (v_des - v) + f_ff; zero on non-finite input."""
        if not (np.isfinite(x).all() and np.isfinite(des).all() and np.isfinite(f_ff).all()):
            return np.zeros(3)
        tip, g = self.tip_state(x), self.gains
        return (g.translational_stiffness * (des[:3] - tip[:3])
                + g.translational_damping * (des[3:] - tip[3:]) + f_ff)


class ImpedanceController(LeafSystem):
    """Cartesian impedance on the EE tip + null-space posture + torque limits."""

    def __init__(self, gains: ImpedanceGains = ImpedanceGains(), *, ee_rotation=None,
                 tilt_deg: float = 15.0, q_null=Q_NULL, compensate_coriolis: bool = True,
                 plant=None):
        super().__init__()
        # Internal model (not part of the context: this system has no state, and the
        # law's plant context is only scratch space for each evaluation).
        self._law = ImpedanceLaw(gains, ee_rotation=ee_rotation, tilt_deg=tilt_deg,
                                 q_null=q_null, compensate_coriolis=compensate_coriolis,
                                 plant=plant)
        self._state = self.DeclareVectorInputPort("panda.state", 2 * NQ)
        self._desired = self.DeclareVectorInputPort("ee.desired_state", 6)
        self._ff = self.DeclareVectorInputPort("ee.feedforward_force", 3)
        self._orient = self.DeclareVectorInputPort("ee.desired_orientation", 4)
        self.DeclareVectorOutputPort("panda.torque_command", NQ, self._calc_torque)
        self.DeclareVectorOutputPort(
            "ee.state", 6, self._calc_ee_state,
            prerequisites_of_calc={self._state.ticket()})
        self.DeclareVectorOutputPort("ee.commanded_force", 3, self._calc_force)

    @property
    def law(self) -> ImpedanceLaw:
        return self._law

    @property
    def desired_rotation(self) -> np.ndarray:
        return self._law.R_des.copy()

    def _ff_value(self, context):
        return self._ff.Eval(context) if self._ff.HasValue(context) else np.zeros(3)

    def _calc_torque(self, context, output):
        R_des = None
        if self._orient.HasValue(context):
            quat = self._orient.Eval(context)
            if not (np.isfinite(quat).all() and np.linalg.norm(quat) > 1e-6):
                output.SetFromVector(np.zeros(NQ))
                return
            R_des = quaternion_to_rotation(quat)
        output.SetFromVector(self._law.torque(self._state.Eval(context),
                                              self._desired.Eval(context),
                                              self._ff_value(context), R_des))

    def _calc_force(self, context, output):
        output.SetFromVector(self._law.commanded_force(
            self._state.Eval(context), self._desired.Eval(context), self._ff_value(context)))

    def _calc_ee_state(self, context, output):
        output.SetFromVector(self._law.tip_state(self._state.Eval(context)))
