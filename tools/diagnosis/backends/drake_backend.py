"""The `drake` model backend for rigid_object scenarios: Drake's MultibodyPlant of the
scenario's true-world description, replayed from recorded states (the body has no input).

The plant is models/rigid_object.py's, discrete with SAP:
- geometry (drake.contact_geometry): `corner_spheres`, the box's eight corner spheres
  (radius contact.corner_radius, their surfaces reaching the box's corners: up to four
  point contacts on a face), or `box`, one Box (point contact gives it ONE contact point
  against the table, so a cube on a face has no friction torque against spin), against
  the table's half space at the (patched) table height; mass, inertia and size from
  `body` and the geometry/inertia keys of `patch` (table_offset, size_offset, mass_scale,
  inertia_scale; the LCS-only keys restitution, r_comp, torsional_friction have no
  counterpart here);
- contact: drake.contact_model, `point` (stiffness drake.point_stiffness N/m given to every
  geometry - Drake combines a pair's in series, so a corner-table pair gets half of it -,
  0 = Drake's default) or `hydroelastic` (a compliant box of modulus
  drake.hydroelastic_modulus Pa against a rigid table);
- friction: drake.friction, < 0 = contact.friction (SAP uses one coefficient: the dynamic
  one; a static coefficient would be ignored, so there is one knob);
- the discrete contact approximation drake.discrete_contact_approximation: `sap` (default)
  or Drake's convex approximations of Hunt & Crossley, `similar` and `lagged`;
- dissipation: under SAP, its linear Kelvin-Voigt term of relaxation time
  drake.relaxation_time (s), 0 = Drake's default (0.1 s; SAP ignores Hunt & Crossley
  dissipation); under similar/lagged, Hunt & Crossley dissipation
  drake.hunt_crossley_dissipation (s/m), < 0 = Drake's default (the relaxation time is
  ignored). A small relaxation time or dissipation lets impacts bounce, if the contact's
  period (from the stiffness) is well above the step: implicit steps damp faster ones;
- forces the plant lacks (systems of the diagram into its applied_spatial_force input):
  drake.viscous_drag (N s/m), drake.angular_drag (N m s), drake.external_force (N, world)
  (drake_forces.py); drake.torsional_friction and drake.rolling_resistance (m: torque per
  newton of the table's normal force, against spin about the normal and rotation about
  axes in the table plane; contact_torques.py);
- time step: drake.time_step, 0 = the recording's dt / SUBSTEPS. Samples at multiples of
  dt (zero-order hold: the state after the last discrete update at or before k dt).

States in and out are in the recording layout and convention: the linear velocity is a
backward difference over one recording step (v(t - dt/2) in flight). SAP's semi-implicit
step at h < dt needs v(t - h/2), so a rollout starts from v - g (dt - h)/2 (z) and reports
velocities shifted back by the same amount: exact in free flight, off by that amount
(0.025 m/s at 148 Hz and SUBSTEPS 4) in sustained contact. Positions and orientations, which
the scores use, are not shifted.
"""
from __future__ import annotations

import numpy as np
from pydrake.multibody.plant import ExternallyAppliedSpatialForceMultiplexer
from pydrake.systems.analysis import Simulator

from adaptive_c3.models.drake_warnings import silence_half_space_deformable_warning
from adaptive_c3.models.rigid_object import (RigidObjectParams, build_rigid_object_plant,
                                             plant_state, recording_state)
from adaptive_c3.tools.diagnosis.backends.contact_torques import add_contact_torques
from adaptive_c3.tools.diagnosis.backends.drake_forces import add_body_forces, has_forces

SUBSTEPS = 4             # SAP updates per recording step when drake.time_step is 0
GRAVITY = 9.81           # m/s^2, Drake's default


def force_systems(d, inertia_diag, time_step: float):
    """The add_systems hook of build_rigid_object_plant for the scenario's drake section d:
    the force elements it asks for (none: None), their outputs summed into the plant's
    applied_spatial_force input."""
    forces = (d.viscous_drag, d.angular_drag, list(d.external_force))
    hooks = ([add_body_forces(*forces)] if has_forces(*forces) else []) + (
        [add_contact_torques(d.torsional_friction, d.rolling_resistance, inertia_diag,
                             time_step)] if d.torsional_friction or d.rolling_resistance else [])
    if not hooks:
        return None

    def add(builder, plant, body):
        ports = [hook(builder, plant, body) for hook in hooks]
        if len(ports) > 1:
            mux = builder.AddSystem(ExternallyAppliedSpatialForceMultiplexer(len(ports)))
            for i, port in enumerate(ports):
                builder.Connect(port, mux.get_input_port(i))
            ports = [mux.get_output_port(0)]
        builder.Connect(ports[0], plant.get_applied_spatial_force_input_port())
    return add


class DrakeRigidSimulator:
    """Rollouts of Drake's SAP simulation of a rigid_object scenario, sampled every dt (s).

    The plant (see the module docstring) is built once; its Simulator and context are
    reused by every rollout (reset to the initial context, time 0)."""

    name = "drake"

    def __init__(self, scenario, dt: float):
        silence_half_space_deformable_warning()
        if not dt > 0:
            raise ValueError(f"dt must be > 0, got {dt}")
        self.scenario = scenario
        self.params = RigidObjectParams.from_scenario(scenario)
        self.dt = float(dt)
        d = scenario.drake
        self.time_step = float(d.time_step) if d.time_step > 0 else self.dt / SUBSTEPS
        self.friction = float(d.friction) if d.friction >= 0 else self.params.friction
        self.point_stiffness = float(d.point_stiffness) if d.point_stiffness > 0 else None
        self.relaxation_time = float(d.relaxation_time) if d.relaxation_time > 0 else None
        self.hunt_crossley_dissipation = (float(d.hunt_crossley_dissipation)
                                          if d.hunt_crossley_dissipation >= 0 else None)
        self.model = build_rigid_object_plant(
            self.params, self.time_step, point_stiffness=self.point_stiffness,
            relaxation_time=self.relaxation_time, friction=self.friction,
            hydroelastic_modulus=(float(d.hydroelastic_modulus)
                                  if d.contact_model == "hydroelastic" else None),
            geometry=d.contact_geometry, approximation=d.discrete_contact_approximation,
            hunt_crossley_dissipation=self.hunt_crossley_dissipation,
            add_systems=force_systems(d, self.params.inertia_diag, self.time_step))
        self.plant = self.model.plant
        self.context = self.model.diagram.CreateDefaultContext()
        self.plant_context = self.plant.GetMyMutableContextFromRoot(self.context)
        self._initial = self.context.Clone()
        self.simulator = Simulator(self.model.diagram, self.context)
        # recording convention -> SAP's: v(t - dt/2) -> v(t - h/2) in free flight
        self._v_shift = np.array([0.0, 0.0, -0.5 * GRAVITY * max(self.dt - self.time_step, 0.0)])

    @property
    def size(self) -> float:
        return self.params.size

    def updates_before(self, num_steps: int) -> np.ndarray:
        """For k = 1..num_steps, the number of discrete updates (at 0, h, 2h, ...) that
        precede the sample at k dt: those strictly before it, an update within 1e-9 h of
        k dt counting as at k dt (so time_step = dt gives k)."""
        k = np.arange(1, num_steps + 1)
        return np.ceil(k * self.dt / self.time_step - 1e-9).astype(int)

    def _start(self, x0_rec: np.ndarray) -> None:
        x0 = np.asarray(x0_rec, float).copy()
        if x0.shape != (13,):
            raise ValueError(f"x0 must have 13 entries (recording layout), got {x0.shape}")
        x0[7:10] += self._v_shift
        self.context.SetTimeStateAndParametersFrom(self._initial)
        self.plant.SetPositionsAndVelocities(self.plant_context, plant_state(x0))
        self.simulator.Initialize()

    def _sample(self) -> np.ndarray:
        """The plant state, its linear velocity back in the recording convention."""
        x = np.array(self.plant.GetPositionsAndVelocities(self.plant_context))
        x[10:13] -= self._v_shift
        return x

    def rollout(self, x0_rec: np.ndarray, num_steps: int) -> np.ndarray:
        """States [num_steps + 1, 13] in the recording layout from the recording-layout x0
        (its quaternion normalised), sampled at k dt; row 0 is x0 itself."""
        self._start(x0_rec)
        out = np.empty((num_steps + 1, 13))
        out[0] = self._sample()
        for k, n in enumerate(self.updates_before(num_steps), start=1):
            if n > 0:   # half way between updates n - 1 and n: no float tie with an event
                self.simulator.AdvanceTo((n - 0.5) * self.time_step)
            out[k] = self._sample()
        return recording_state(out)

    def step(self, x_plant: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """One recording step from a plant-layout state: (next plant-layout state, [number
        of corner contacts at its end]) - what tools/diagnosis/tasks/rigid_object/rigid_locate.py asks of a
        model (a nonzero second entry = in contact)."""
        X = self.rollout(recording_state(np.asarray(x_plant, float)), 1)
        results = self.plant.get_contact_results_output_port().Eval(self.plant_context)
        contacts = results.num_point_pair_contacts() + results.num_hydroelastic_contacts()
        return plant_state(X[1]), np.array([float(contacts)])
