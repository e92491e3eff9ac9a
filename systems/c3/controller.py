"""C3 as a Drake LeafSystem: replans periodically and holds its input in between."""
from __future__ import annotations

import time

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import EventStatus, LeafSystem

from adaptive_c3.systems.c3.options import C3Options
from adaptive_c3.systems.c3.solver import C3Solver
from adaptive_c3.systems.contact.lcs import Lcs, LcsSequence

__all__ = ["C3Controller"]


def _placeholder_lcs(n: int, k: int, m: int) -> Lcs:
    z = np.zeros
    return Lcs(A=np.eye(n), B=z((n, k)), D=z((n, m)), d=z(n), E=z((m, n)), F=np.eye(m),
               H=z((m, k)), c=np.ones(m))


class C3Controller(LeafSystem):
    """Consensus complementarity control (systems/c3/solver.py) at a fixed replanning rate.

    Input ports:
      state   (vector, n)   the estimated state x, in the LCS's units.
      lcs     (abstract)    an `Lcs` or `LcsSequence` (horizon long) - the model to plan
                            with, e.g. from a linearizer or with a learned residual.
      target  (vector, n)   the desired state; optional (0 when unconnected).
    Output ports:
      input   (vector, k)   the input u0 of the latest plan, held until the next solve
                            (0 before the first solve and after a rejected one).
      plan    (abstract)    the latest `C3Solution` (None before the first solve).
    Every 1/rate_hz seconds (first at t = 0) an unrestricted update replans from the
    current state. A non-finite state or target, an LCS of the wrong type or size, or a
    failed / non-finite solve sets the input to 0 and keeps the last plan (counted in
    `rejected`). The warm start is the plan held in the context, so the controller
    carries no hidden state between simulations except timing statistics.
    """

    def __init__(self, options: C3Options, num_states: int, num_inputs: int,
                 num_lambda: int, rate_hz: float = 80.0):
        super().__init__()
        if not isinstance(options, C3Options):
            raise ValueError("C3Controller needs C3Options")
        n, k, m = int(num_states), int(num_inputs), int(num_lambda)
        if (n, k) != (options.num_states, options.num_inputs):
            raise ValueError(f"C3Controller sizes n={n}, k={k} do not match the options "
                             f"(n={options.num_states}, k={options.num_inputs})")
        if m < 1:
            raise ValueError("C3Controller needs num_lambda >= 1")
        rate_hz = float(rate_hz)
        if not np.isfinite(rate_hz) or rate_hz <= 0:
            raise ValueError(f"C3Controller rate_hz must be positive, got {rate_hz}")
        self._n, self._k, self._m = n, k, m
        self._options = options
        self._solver = C3Solver(options)
        self.period_s = 1.0 / rate_hz
        self.rejected = 0
        self._solve_times: list[float] = []

        self._state_port = self.DeclareVectorInputPort("state", n)
        self._lcs_port = self.DeclareAbstractInputPort(
            "lcs", AbstractValue.Make(_placeholder_lcs(n, k, m)))
        self._target_port = self.DeclareVectorInputPort("target", n)
        self._u_index = self.DeclareDiscreteState(k)
        self._plan_index = self.DeclareAbstractState(AbstractValue.Make(None))
        self.DeclareStateOutputPort("input", self._u_index)
        self.DeclareAbstractOutputPort("plan", lambda: AbstractValue.Make(None),
                                       self._calc_plan)
        self.DeclarePeriodicUnrestrictedUpdateEvent(self.period_s, 0.0, self._replan)

    @property
    def solver(self) -> C3Solver:
        return self._solver

    def _calc_plan(self, context, output):
        output.set_value(context.get_abstract_state(int(self._plan_index)).get_value())

    def _valid_lcs(self, lcs) -> bool:
        if isinstance(lcs, Lcs):
            s = lcs
        elif isinstance(lcs, LcsSequence) and len(lcs) == self._options.horizon:
            s = lcs[0]
        else:
            return False
        return (s.num_states, s.num_inputs, s.num_lambda) == (self._n, self._k, self._m)

    def _replan(self, context, state):
        u_vec = state.get_mutable_discrete_state(int(self._u_index))
        x = np.asarray(self._state_port.Eval(context), float)
        lcs = self._lcs_port.Eval(context)
        target = (np.asarray(self._target_port.Eval(context), float)
                  if self._target_port.HasValue(context) else np.zeros(self._n))
        if not (np.isfinite(x).all() and np.isfinite(target).all()
                and self._valid_lcs(lcs)):
            self.rejected += 1
            u_vec.SetFromVector(np.zeros(self._k))
            return EventStatus.Succeeded()
        prev = context.get_abstract_state(int(self._plan_index)).get_value()
        if prev is None:
            self._solver.reset()
        t0 = time.perf_counter()
        try:
            sol = self._solver.solve(lcs, x, target,
                                     warm=prev if self._options.warm_start else None)
        except (ValueError, RuntimeError, np.linalg.LinAlgError):
            sol = None
        self._solve_times.append(time.perf_counter() - t0)
        if sol is None or not np.isfinite(sol.u0).all():
            self.rejected += 1
            u_vec.SetFromVector(np.zeros(self._k))
            return EventStatus.Succeeded()
        u_vec.SetFromVector(sol.u0)
        state.get_mutable_abstract_state(int(self._plan_index)).set_value(sol)
        return EventStatus.Succeeded()

    def solve_time_stats(self) -> dict:
        """{"count", "median_s", "max_s", "mean_s"} of the solves so far (seconds)."""
        t = np.asarray(self._solve_times, float)
        if t.size == 0:
            return {"count": 0, "median_s": float("nan"), "max_s": float("nan"),
                    "mean_s": float("nan")}
        return {"count": int(t.size), "median_s": float(np.median(t)),
                "max_s": float(t.max()), "mean_s": float(t.mean())}

    def fallback_counts(self) -> dict:
        """The solver's fall-back totals (systems/c3/solver.py FALLBACKS) and `rejected`."""
        return {**self._solver.fallbacks, "rejected": self.rejected}

    def reset_stats(self):
        self._solve_times.clear()
        self.rejected = 0
