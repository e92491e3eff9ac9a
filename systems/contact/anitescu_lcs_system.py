"""`AnitescuLcsSystem`: the Anitescu LCS of a plant, recomputed periodically.

Input ports
  "state"  vector [n_q + n_v]: the estimated plant state, in the plant's order
           (positions then velocities; SI units, floating bodies as [quat wxyz, xyz]
           and [ω_W, v_W]).
  "input"  vector [n_u]: the last applied actuation (plant actuator order, N or N·m).
           Optional: when unconnected the LCS is linearised about u = 0.
Output ports
  "lcs"            abstract `Lcs`: θ* at the last update (λ = contact impulses, N·s).
  "contact_names"  abstract list[str]: one name per λ entry, '<pair>/<edge>'.

The LCS is held in abstract state and refreshed by a periodic unrestricted update at
`update_rate_hz` (default 80 Hz) and once at initialisation, so "lcs" is valid from
t = 0 and constant between updates. `dt` (s, default the linearizer's) is the LCS
step: systems that share one linearizer at different dt and update at the same state
and input share its evaluation at that point (AnitescuLinearizer keeps the last one).
"""
from __future__ import annotations

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import LeafSystem

from adaptive_c3.systems.contact.anitescu_lcs import AnitescuLinearizer


class AnitescuLcsSystem(LeafSystem):
    """Wraps an AnitescuLinearizer as a Drake system (see module docstring)."""

    def __init__(self, linearizer: AnitescuLinearizer, update_rate_hz: float = 80.0,
                 initial_state=None, initial_input=None, dt: float | None = None):
        super().__init__()
        if not (np.isfinite(update_rate_hz) and update_rate_hz > 0):
            raise ValueError(f"update_rate_hz must be > 0, got {update_rate_hz}")
        self._lin = linearizer
        self._dt = linearizer.dt if dt is None else float(dt)
        self._names = list(linearizer.lambda_names())
        self._nx, self._nu = linearizer.nx, linearizer.nu
        self.update_period = 1.0 / float(update_rate_hz)

        x0 = (self._default_state() if initial_state is None
              else np.asarray(initial_state, float).reshape(-1))
        u0 = (np.zeros(self._nu) if initial_input is None
              else np.asarray(initial_input, float).reshape(-1))
        self._u_zero = np.zeros(self._nu)
        initial_lcs = linearizer.linearize(x0, u0, self._dt)

        self._state_port = self.DeclareVectorInputPort("state", self._nx)
        self._input_port = self.DeclareVectorInputPort("input", self._nu)
        self._lcs_index = self.DeclareAbstractState(AbstractValue.Make(initial_lcs))
        self.DeclarePeriodicUnrestrictedUpdateEvent(self.update_period, 0.0, self._update)
        self.DeclareInitializationUnrestrictedUpdateEvent(self._update)
        self.DeclareStateOutputPort("lcs", self._lcs_index)
        self.DeclareAbstractOutputPort(
            "contact_names", lambda: AbstractValue.Make(list(self._names)),
            self._calc_names, prerequisites_of_calc={self.nothing_ticket()})

    def _default_state(self) -> np.ndarray:
        plant = self._lin.plant
        ctx = plant.CreateDefaultContext()
        return np.asarray(plant.GetPositionsAndVelocities(ctx), float)

    @property
    def linearizer(self) -> AnitescuLinearizer:
        return self._lin

    def lambda_names(self) -> list[str]:
        """One name per λ entry, '<pair>/<edge>', in λ order."""
        return list(self._names)

    def _update(self, context, state):
        x = self._state_port.Eval(context)
        u = self._input_port.Eval(context) if self._input_port.HasValue(context) \
            else self._u_zero
        lcs = self._lin.linearize(x, u, self._dt)
        state.get_mutable_abstract_state(self._lcs_index).set_value(lcs)

    def _calc_names(self, context, output):
        output.set_value(list(self._names))
