"""A discrete-time plant that steps an LCS (the 'true system' of synthetic tasks)."""
from __future__ import annotations

import numpy as np
from pydrake.systems.framework import BasicVector, LeafSystem

from adaptive_c3.systems.contact.lcs import Lcs


class LcsPlant(LeafSystem):
    """Steps x+ = A x + B u + D lam + d with lam from the LCP, every lcs.dt seconds.

    Input ports:
      input        (k)  the input u applied over the next step (units of the LCS).
      disturbance  (n)  optional; added to the state once per step (e.g. a kick).
    Output ports:
      state          (n)  the current state x.
      contact_force  (m)  lam of the most recent step (0 before the first step).
    A non-finite input is treated as zero and counted in `bad_inputs`.
    """

    def __init__(self, lcs: Lcs, x0, dt: float | None = None):
        super().__init__()
        self._lcs = lcs
        self._dt = float(dt if dt is not None else lcs.dt)
        if self._dt <= 0:
            raise ValueError("LcsPlant needs a positive step (lcs.dt or dt)")
        n, k, m = lcs.num_states, lcs.num_inputs, lcs.num_lambda
        x0 = np.asarray(x0, float)
        if x0.shape != (n,):
            raise ValueError(f"initial state has {x0.size} entries, the LCS has {n}")
        self.bad_inputs = 0
        self._x = self.DeclareDiscreteState(BasicVector(x0))
        self._lam = self.DeclareDiscreteState(m)
        self.DeclareVectorInputPort("input", k)
        self.DeclareVectorInputPort("disturbance", n)
        self.DeclareStateOutputPort("state", self._x)
        self.DeclareStateOutputPort("contact_force", self._lam)
        self.DeclarePeriodicDiscreteUpdateEvent(self._dt, 0.0, self._step)

    def _step(self, context, discrete_state):
        x = context.get_discrete_state(self._x).get_value()
        u = self.get_input_port(0).Eval(context)
        if not np.isfinite(u).all():
            self.bad_inputs += 1
            u = np.zeros_like(u)
        if self.get_input_port(1).HasValue(context):
            x = x + self.get_input_port(1).Eval(context)
        x_next, lam = self._lcs.step(x, u)
        discrete_state.get_mutable_vector(self._x).SetFromVector(x_next)
        discrete_state.get_mutable_vector(self._lam).SetFromVector(lam)
