"""Torques Drake's point contact does not give a body resting or sliding on a table, as a
system of the plant's diagram: torsional friction (against spin about the table normal)
and rolling resistance (against rotation about axes in the table plane), each the
contact's normal force times a length (m).

`contact_torque` is the pure-numpy core; `ContactTorques` the LeafSystem that feeds it
into the plant's `applied_spatial_force` input (ExternallyAppliedSpatialForce, a pure
torque on the body, world frame). The normal force is the table's push on the body at
the plant's last discrete step (summed contact forces along world z, from the plant's
contact results), held in the system's discrete state: the torque depends on the plant's
state and that held force only, so the diagram has no algebraic loop.
"""
from __future__ import annotations

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.multibody.math import SpatialForce
from pydrake.multibody.plant import ContactResults, ExternallyAppliedSpatialForce
from pydrake.systems.framework import LeafSystem

from adaptive_c3.models.rigid_object import quat_to_matrix

NORMAL = np.array([0.0, 0.0, 1.0])       # the table's normal, world


def normal_force(results, body_index) -> float:
    """The table's push on the body along world z (N, >= 0) in a plant's ContactResults:
    its point-pair forces (on body B, so negated where the body is A) and its
    hydroelastic forces (the body has no other contact than the table)."""
    fz = 0.0
    for i in range(results.num_point_pair_contacts()):
        info = results.point_pair_contact_info(i)
        if info.bodyB_index() == body_index:
            fz += info.contact_force()[2]
        elif info.bodyA_index() == body_index:
            fz -= info.contact_force()[2]
    for i in range(results.num_hydroelastic_contacts()):
        fz += abs(results.hydroelastic_contact_info(i).F_Ac_W().translational()[2])
    return max(fz, 0.0)


def contact_torque(x_plant, normal: float, torsional_friction: float,
                   rolling_resistance: float, inertia_diag, time_step: float) -> np.ndarray:
    """Torque [3] (N m, world) on a free body of plant state x_plant (q = [qw, qx, qy, qz,
    x, y, z], v = [w_world (3), v_world (3)]) pressed on the table with `normal` N:
    - about the normal: -sign(w_n) torsional_friction N,
    - in the table plane: -w_t/|w_t| rolling_resistance N,
    each capped at the torque that stops that rotation within one time_step (s) about the
    body's centre (inertia_diag, kg m^2, body frame): Coulomb-like, never reversing it."""
    x = np.asarray(x_plant, float)
    w = x[7:10]
    N = max(float(normal), 0.0)
    if N == 0.0 or time_step <= 0:
        return np.zeros(3)
    R = quat_to_matrix(x[0:4])
    inertia = R @ np.diag(np.asarray(inertia_diag, float)) @ R.T       # world frame
    tau = np.zeros(3)
    w_n = float(w @ NORMAL)
    w_t = w - w_n * NORMAL
    for axis_w, coef in ((w_n * NORMAL, torsional_friction), (w_t, rolling_resistance)):
        speed = float(np.linalg.norm(axis_w))
        if coef <= 0 or speed == 0.0:
            continue
        u = axis_w / speed
        stop = float(u @ inertia @ u) * speed / time_step     # N m that stops it in one step
        tau -= min(coef * N, stop) * u
    return tau


class ContactTorques(LeafSystem):
    """Inputs: `state` (13, plant layout), `contact_results` (the plant's ContactResults).
    Output `spatial_forces`: one ExternallyAppliedSpatialForce on `body_index` (a pure
    torque, world frame). Discrete state: the normal force on the body (N), sampled from
    the contact results every `time_step` s (the plant's step)."""

    def __init__(self, body_index, torsional_friction: float, rolling_resistance: float,
                 inertia_diag, time_step: float):
        super().__init__()
        self._body = body_index
        self._coef = (float(torsional_friction), float(rolling_resistance))
        self._inertia = np.asarray(inertia_diag, float).copy()
        self._h = float(time_step)
        self._state = self.DeclareVectorInputPort("state", 13)
        self._results = self.DeclareAbstractInputPort("contact_results",
                                                      AbstractValue.Make(ContactResults()))
        self._normal = self.DeclareDiscreteState(1)
        self.DeclarePeriodicDiscreteUpdateEvent(self._h, 0.0, self._sample)
        self.DeclareAbstractOutputPort(
            "spatial_forces", lambda: AbstractValue.Make([ExternallyAppliedSpatialForce()]),
            self._calc, prerequisites_of_calc={self.input_port_ticket(self._state.get_index()),
                                               self.xd_ticket()})

    def _sample(self, context, discrete_state):
        discrete_state.set_value(0, [normal_force(self._results.Eval(context), self._body)])

    def _calc(self, context, output):
        tau = contact_torque(self._state.Eval(context), context.get_discrete_state(0)[0],
                             *self._coef, self._inertia, self._h)
        force = ExternallyAppliedSpatialForce()
        force.body_index = self._body
        force.p_BoBq_B = np.zeros(3)
        force.F_Bq_W = SpatialForce(tau, np.zeros(3))
        output.set_value([force])


def add_contact_torques(torsional_friction: float, rolling_resistance: float, inertia_diag,
                        time_step: float):
    """A hook (builder, plant, body) -> the ContactTorques output port, wired from the
    plant's state and contact results (the caller connects the output)."""
    def add(builder, plant, body):
        system = builder.AddSystem(ContactTorques(body.index(), torsional_friction,
                                                  rolling_resistance, inertia_diag, time_step))
        system.set_name("contact_torques")
        builder.Connect(plant.get_state_output_port(), system.get_input_port(0))
        builder.Connect(plant.get_contact_results_output_port(), system.get_input_port(1))
        return system.get_output_port(0)
    return add
