"""Forces Drake's point contact does not model, on each ball of the ball-rolling plant, as
a system of its diagram: rolling resistance, torsional friction, viscous drag and a
constant force.

`ball_wrenches` is the pure-numpy core; `BallForces` the LeafSystem that feeds it into
the plant's `applied_spatial_force` input (an ExternallyAppliedSpatialForce per ball at
its centre, world frame). The coefficients and the ball mass are a numeric parameter of
its context (`set_coefficients`), so one built diagram serves every parameter set.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.multibody.math import SpatialForce
from pydrake.multibody.plant import ExternallyAppliedSpatialForce
from pydrake.systems.framework import BasicVector, LeafSystem

G = 9.81
OMEGA0 = 0.3              # rad/s: the resistance torques saturate below this spin
ON_TABLE = 1e-3           # m: the ball's gap to the table within which they act


@dataclass(frozen=True)
class BallForceCoefficients:
    """rolling (m): torque rolling * m g opposing the spin about horizontal axes;
    torsional (m): torque torsional * m g opposing the spin about the vertical; both on
    the table only, saturated below OMEGA0. drag (N s/m): force -drag v. force (N): a
    constant world-frame force [fx, fy]."""
    rolling: float = 0.0
    torsional: float = 0.0
    drag: float = 0.0
    force: tuple = (0.0, 0.0)

    def any(self) -> bool:
        return bool(self.rolling or self.torsional or self.drag or any(self.force))


def ball_wrenches(w: np.ndarray, v: np.ndarray, gap: np.ndarray, mass: float,
                  c: BallForceCoefficients) -> tuple[np.ndarray, np.ndarray]:
    """(torques [N, 3] N m, forces [N, 3] N), world frame, on N balls of angular velocity
    w [N, 3] (rad/s), velocity v [N, 3] (m/s) and table gap [N] (m)."""
    w, v = np.atleast_2d(w), np.atleast_2d(v)
    tau, f = np.zeros_like(w), np.zeros_like(v)
    on = (np.asarray(gap) < ON_TABLE)[:, None]
    if c.rolling:
        wh = w[:, :2]
        tau[:, :2] -= on * c.rolling * mass * G * wh / np.maximum(
            np.linalg.norm(wh, axis=1, keepdims=True), OMEGA0)
    if c.torsional:
        tau[:, 2:] -= on * c.torsional * mass * G * w[:, 2:] / np.maximum(np.abs(w[:, 2:]), OMEGA0)
    f[:, :2] += np.asarray(c.force, float)
    f -= c.drag * v
    return tau, f


def _parameter(coefficients: BallForceCoefficients, mass: float) -> np.ndarray:
    c = coefficients
    return np.array([c.rolling, c.torsional, c.drag, c.force[0], c.force[1], mass], float)


class BallForces(LeafSystem):
    """Input `state`: the plant's state. Output `spatial_forces`: one
    ExternallyAppliedSpatialForce per ball (body index, at its origin, world frame).
    Numeric parameter 0: [rolling (m), torsional (m), drag (N s/m), fx, fy (N), ball mass
    (kg)] (BallForceCoefficients' fields and the mass)."""

    def __init__(self, num_positions: int, num_states: int, balls: list, q_start, v_start,
                 mass: float, radius: float, table_z: float, coefficients: BallForceCoefficients):
        """q_start, v_start [N]: each ball's first index in the plant's q and v; mass (kg),
        radius (m), table_z (m, the table top's world z): the world's; mass and
        coefficients are the parameter's default."""
        super().__init__()
        self._balls = list(balls)
        self._q, self._v = np.asarray(q_start), np.asarray(v_start)
        self._radius, self._table_z = float(radius), float(table_z)
        self._nq = int(num_positions)
        self._state = self.DeclareVectorInputPort("state", num_states)
        self._param = self.DeclareNumericParameter(BasicVector(_parameter(coefficients, mass)))
        vi = self._nq + self._v
        self._w_idx, self._v_idx = vi[:, None] + np.arange(3), vi[:, None] + np.arange(3, 6)
        self._forces = []                  # one per ball, F_Bq_W rewritten on each output
        for b in self._balls:
            force = ExternallyAppliedSpatialForce()
            force.body_index = b
            force.p_BoBq_B = np.zeros(3)
            self._forces.append(force)
        self.DeclareAbstractOutputPort(
            "spatial_forces",
            lambda: AbstractValue.Make([ExternallyAppliedSpatialForce()] * len(self._balls)),
            self._calc)

    def set_coefficients(self, context, coefficients: BallForceCoefficients, mass: float):
        """Write the coefficients and the ball mass (kg) into this system's context."""
        context.get_mutable_numeric_parameter(self._param).SetFromVector(
            _parameter(coefficients, mass))

    def _calc(self, context, output):
        x = self._state.Eval(context)
        p = context.get_numeric_parameter(self._param).get_value()
        c = BallForceCoefficients(p[0], p[1], p[2], (p[3], p[4]))
        z = x[self._q + 6]                                   # ball z (after the quaternion, x, y)
        tau, f = ball_wrenches(x[self._w_idx], x[self._v_idx],
                               z - self._radius - self._table_z, p[5], c)
        for force, t, fi in zip(self._forces, tau, f):
            force.F_Bq_W = SpatialForce(t, fi)
        output.set_value(self._forces)                       # copied into the output


def add_ball_forces(world, coefficients: BallForceCoefficients):
    """An add_systems hook for ball_plant.build_ball_plant: BallForces on every ball,
    wired state -> forces (world: the plant's BallWorld)."""
    def add(builder, plant, balls):
        q0 = np.array([plant.get_body(b).floating_positions_start() for b in balls])
        v0 = np.array([plant.get_body(b).floating_velocities_start_in_v() for b in balls])
        sys = BallForces(plant.num_positions(), plant.num_multibody_states(), balls, q0, v0,
                         world.ball_mass, world.ball_radius, world.table_z, coefficients)
        sys.set_name("ball_forces")
        builder.AddSystem(sys)
        builder.Connect(plant.get_state_output_port(), sys.get_input_port(0))
        builder.Connect(sys.get_output_port(0), plant.get_applied_spatial_force_input_port())
    return add
