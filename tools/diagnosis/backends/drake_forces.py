"""Forces Drake's MultibodyPlant does not model, as a system of the plant's diagram: viscous
drag on the body's linear and angular velocity and a constant external force.

`body_wrench` is the pure-numpy core; `BodyForces` the LeafSystem that feeds it into the
plant's `applied_spatial_force` input (ExternallyAppliedSpatialForce on the body, applied
at its origin = centre of mass, world frame).
"""
from __future__ import annotations

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.multibody.math import SpatialForce
from pydrake.multibody.plant import ExternallyAppliedSpatialForce
from pydrake.systems.framework import LeafSystem


def body_wrench(x_plant: np.ndarray, viscous_drag: float, angular_drag: float,
                external_force) -> tuple[np.ndarray, np.ndarray]:
    """(torque [3] N m, force [3] N), world frame, on a free body of plant state x_plant
    (q = [qw, qx, qy, qz, x, y, z], v = [w_world (3), v_world (3)]): -angular_drag w,
    -viscous_drag v + external_force."""
    x = np.asarray(x_plant, float)
    w, v = x[7:10], x[10:13]
    return -float(angular_drag) * w, -float(viscous_drag) * v + np.asarray(external_force, float)


def has_forces(viscous_drag: float, angular_drag: float, external_force) -> bool:
    """Whether body_wrench is ever nonzero for these coefficients."""
    return bool(viscous_drag or angular_drag or np.any(np.asarray(external_force, float)))


class BodyForces(LeafSystem):
    """Input `state`: the plant's state (13, plant layout). Output `spatial_forces`: a list
    with one ExternallyAppliedSpatialForce on `body_index` at its origin (world frame)."""

    def __init__(self, body_index, viscous_drag: float, angular_drag: float, external_force):
        super().__init__()
        self._body = body_index
        self._coef = (float(viscous_drag), float(angular_drag),
                      np.asarray(external_force, float).copy())
        self._state = self.DeclareVectorInputPort("state", 13)
        self.DeclareAbstractOutputPort(
            "spatial_forces", lambda: AbstractValue.Make([ExternallyAppliedSpatialForce()]),
            self._calc)

    def _calc(self, context, output):
        tau, f = body_wrench(self._state.Eval(context), *self._coef)
        force = ExternallyAppliedSpatialForce()
        force.body_index = self._body
        force.p_BoBq_B = np.zeros(3)
        force.F_Bq_W = SpatialForce(tau, f)
        output.set_value([force])


def add_body_forces(viscous_drag: float, angular_drag: float, external_force):
    """A hook (builder, plant, body) -> the BodyForces output port, wired from the plant's
    state (the caller connects the output: drake_backend.py)."""
    def add(builder, plant, body):
        forces = builder.AddSystem(BodyForces(body.index(), viscous_drag, angular_drag,
                                              external_force))
        forces.set_name("body_forces")
        builder.Connect(plant.get_state_output_port(), forces.get_input_port(0))
        return forces.get_output_port(0)
    return add
