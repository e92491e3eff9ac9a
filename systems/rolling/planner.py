"""`BallRollingPlanner`: C3 on the ball-rolling LCS plus the roll/return gait, as the EE
command for an impedance controller (Drake LeafSystem).

Every 1/rate_hz seconds (80 Hz by default; offset 1 ms so it reads LCSs linearised at
the same tick) it
  1. picks the gait phase and the C3 target (systems/rolling/gait.py);
  2. solves C3 on the "lcs" input (θ* with the learned residual, planning dt) with the
     roll-phase weights, or the return-phase weights (EE pinned to the gait);
  3. executes the plan's first input through the "lcs_loop" input (θ* linearised with
     the loop period as its dt, plus the residual rescaled to that dt): one LCS step
     from the current state gives the next desired EE position and velocity, clamped
     to the gait's maximum EE speed;
  4. holds the EE command and the plan's EE force until the next tick.
With `predict_state`, steps 2-3 start from the state predicted at the time the plan
takes effect (`predict_state_ahead`: constant EE and ball velocities over the lead),
the lead being `predict_latency_s` or, if None, the median of the last solve times plus
`transport_s` (the time the plan takes to reach the impedance loop).
The warm start is the last plan of the same solver moved on by one LCS step
(`warm_start_shift="knot"`) or by the time between the two plans' start states, in
LCS steps (`"elapsed"`: at 80 Hz and a 0.1 s step, an eighth of a knot per solve; the
wall-clock process's diagram time follows the wall clock, so this is real time there).

Input ports (world frame W, SI units):
  state     (19)       estimated state, models/ball_rolling_controller_model order.
  lcs       abstract   Lcs θ* without residual (planning dt); the planner adds r_comp.
  lcs_loop  abstract   Lcs without residual, dt = loop period.
  r_comp    (m)        the learned residual (m/s at the planning dt); optional (0).
                       C3's LCSs get it unless residual_in_lcs is False; the gait's
                       heights and floor use its EE-ball gap as RollingGait decides.
Output ports:
  ee.desired_state     (6)  desired EE tip position (m) and velocity (m/s) in W.
  ee.feedforward_force (3)  the plan's first EE force u0 minus the model EE's weight
                            (N, in W; the robot compensates its own gravity; 0 if
                            disabled).
  lcs_input            (3)  u0, the input the LCS and learner see (N).
  phase                (1)  index into gait.PHASES.
  ball_target          (2)  the ball's current circle target (m).
  plan                 abstract  the latest C3Solution (None before the first).
A non-finite state or a failed solve holds the EE where it is with zero force.
"""
from __future__ import annotations

import time

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import BasicVector, EventStatus, LeafSystem

from adaptive_c3.models.ball_rolling_controller_model import (BALL_ANGVEL, BALL_POS,
                                                              BALL_QUAT, BALL_VEL, EE_POS,
                                                              EE_VEL)
from adaptive_c3.models.rigid_object import quaternion_rate
from adaptive_c3.systems.c3.options import C3Options
from adaptive_c3.systems.c3.solver import C3Solver
from adaptive_c3.systems.contact.lcs import Lcs
from adaptive_c3.systems.rolling.gait import (PHASES, RollingGait, clamp_ee_command,
                                              step_toward)

N_X, N_U = 19, 3


class BallRollingPlanner(LeafSystem):
    """C3 + gait -> EE impedance command (see module docstring)."""

    def __init__(self, gait: RollingGait, roll_options: C3Options,
                 return_options: C3Options, *, num_lambda: int, rate_hz: float = 80.0,
                 ee_ball_rows=(0, 1, 2, 3), planning_dt: float = 0.1,
                 feedforward: bool = True, model_ee_weight: float = 0.0,
                 predict_state: bool = False, predict_latency_s: float | None = None,
                 transport_s: float = 0.0, warm_start_shift: str = "knot",
                 residual_in_lcs: bool = True):
        super().__init__()
        self._gait = gait
        self._roll = C3Solver(roll_options)
        self._ret = C3Solver(return_options)
        self._m = int(num_lambda)
        self._rows = list(ee_ball_rows)
        self._dt_plan = float(planning_dt)
        self.period_s = 1.0 / float(rate_hz)
        self._ff = bool(feedforward)
        # the model EE's weight (N) is in u0; the robot compensates its own gravity
        self._ee_weight = np.array([0.0, 0.0, float(model_ee_weight)])
        self.solve_times: list[float] = []
        self.failures = 0
        self._predict = bool(predict_state)
        self._lead_s = predict_latency_s
        self._transport_s = float(transport_s)
        if warm_start_shift not in ("knot", "elapsed"):
            raise ValueError(f"warm_start_shift must be knot or elapsed, got {warm_start_shift!r}")
        self._shift_elapsed = warm_start_shift == "elapsed"
        self._r_in_lcs = bool(residual_in_lcs)

        self._x_port = self.DeclareVectorInputPort("state", N_X)
        self._lcs_port = self.DeclareAbstractInputPort("lcs", AbstractValue.Make(None))
        self._loop_port = self.DeclareAbstractInputPort("lcs_loop", AbstractValue.Make(None))
        self._r_port = self.DeclareVectorInputPort("r_comp", self._m)
        # command vector: [p_des(3), v_des(3), f_ff(3), u0(3), phase, target(2)]
        self._cmd = self.DeclareDiscreteState(np.full(15, np.nan))
        self._plan = self.DeclareAbstractState(AbstractValue.Make(None))
        ticket = {self.xd_ticket()}
        for name, sl in (("ee.desired_state", slice(0, 6)),
                         ("ee.feedforward_force", slice(6, 9)),
                         ("lcs_input", slice(9, 12)), ("phase", slice(12, 13)),
                         ("ball_target", slice(13, 15))):
            self.DeclareVectorOutputPort(
                name, sl.stop - sl.start, self._make_output(sl), prerequisites_of_calc=ticket)
        self.DeclareAbstractOutputPort(
            "plan", lambda: AbstractValue.Make(None),
            lambda ctx, out: out.set_value(self.solution(ctx)))
        self.DeclarePeriodicUnrestrictedUpdateEvent(self.period_s, 0.001, self._tick)
        self.DeclareInitializationUnrestrictedUpdateEvent(self._init)

    def _make_output(self, sl):
        def calc(context, out):
            v = context.get_discrete_state(int(self._cmd)).get_value()[sl]
            if sl.start < 6 and not np.isfinite(v).all():   # before the first tick
                x = self._x_port.Eval(context)
                v = np.r_[x[EE_POS], np.zeros(3)][sl]
            out.SetFromVector(np.nan_to_num(v))
        return calc

    # ------------------------------------------------------------------ events
    def _init(self, context, state):
        x = np.asarray(self._x_port.Eval(context), float)
        cmd = np.zeros(15)
        cmd[0:3] = x[EE_POS] if np.isfinite(x).all() else np.nan
        state.get_mutable_discrete_state(int(self._cmd)).set_value(cmd)
        return EventStatus.Succeeded()

    def _residual(self, context) -> np.ndarray:
        if self._r_port.HasValue(context):
            r = np.asarray(self._r_port.Eval(context), float)
            if np.isfinite(r).all():
                return r
        return np.zeros(self._m)

    def gap_offset(self, r) -> float:
        """The learned EE-ball gap offset (m): mean residual of its rows times dt."""
        return float(np.mean(np.asarray(r)[self._rows]) * self._dt_plan)

    def _hold(self, state, x, reason_phase: float):
        cmd = state.get_mutable_discrete_state(int(self._cmd)).get_value().copy()
        p = x[EE_POS] if np.isfinite(x[EE_POS]).all() else cmd[0:3]
        cmd[0:3], cmd[3:12] = p, 0.0
        cmd[12] = reason_phase
        state.get_mutable_discrete_state(int(self._cmd)).set_value(cmd)
        self.failures += 1

    def _tick(self, context, state):
        t = context.get_time()
        x = np.asarray(self._x_port.Eval(context), float)
        lcs, lcs_loop = self._lcs_port.Eval(context), self._loop_port.Eval(context)
        phase, _ = self._gait.phase(t)
        iphase = float(PHASES.index(phase))
        if not (np.isfinite(x).all() and isinstance(lcs, Lcs) and isinstance(lcs_loop, Lcs)):
            self._hold(state, x, iphase)
            return EventStatus.Succeeded()
        r = self._residual(context)
        t_start = t                      # the time the plan's start state stands for
        if self._predict:
            t_start += self.lead_s()
            x = predict_state_ahead(x, t_start - t)
        gap = self._gait.gait_gap(self.gap_offset(r))
        target = self._gait.target_state(phase, x, gap)
        if not self._r_in_lcs:
            r = np.zeros_like(r)
        if phase != "roll" and self._gait.s.return_mode == "waypoint":
            self._waypoint(state, x, iphase, target)
            return EventStatus.Succeeded()
        which = "roll" if phase == "roll" else "return"
        solver = self._roll if which == "roll" else self._ret
        prev = context.get_abstract_state(int(self._plan)).get_value()
        # (the held plan is deep-copied with the context: compare by name, not identity)
        warm = prev if (prev is not None and prev[0] == which) else None
        shift = 1.0
        if warm and self._shift_elapsed:     # the plans' start states are this many knots apart
            shift = max(t_start - warm[2], 0.0) / self._dt_plan
        t0 = time.perf_counter()
        try:
            sol = solver.solve(lcs.with_residual(r), x, target,
                               warm=warm[1] if warm else None, warm_shift=shift)
            loop = lcs_loop.with_residual(r * (self._dt_plan / lcs_loop.dt))
            x_next, _ = loop.step(x, sol.u0)
        except (ValueError, RuntimeError, np.linalg.LinAlgError):
            sol, x_next = None, None
        self.solve_times.append(time.perf_counter() - t0)
        if sol is None or not (np.isfinite(sol.u0).all() and np.isfinite(x_next).all()):
            self._hold(state, x, iphase)
            return EventStatus.Succeeded()
        p_des, v_des = clamp_ee_command(x[EE_POS], x_next[EE_POS], x_next[EE_VEL],
                                        self.period_s, self._gait.s.max_ee_speed)
        floor = self._gait.floor_height(gap)
        if p_des[2] < floor:
            p_des[2], v_des[2] = floor, max(v_des[2], 0.0)
        cmd = np.concatenate([p_des, v_des, (sol.u0 - self._ee_weight) if self._ff else np.zeros(3), sol.u0,
                              [iphase], target[7:9]])
        state.get_mutable_discrete_state(int(self._cmd)).set_value(cmd)
        state.get_mutable_abstract_state(int(self._plan)).set_value((which, sol, t_start))
        return EventStatus.Succeeded()

    def _waypoint(self, state, x, iphase, target):
        """Return phases in "waypoint" mode: a straight line from the last command toward
        the phase's EE target (target[EE_POS]); no contact force is planned (u0 = the model
        EE's weight)."""
        cmd = state.get_mutable_discrete_state(int(self._cmd)).get_value().copy()
        start = cmd[0:3] if np.isfinite(cmd[0:3]).all() else x[EE_POS]
        p_des, v_des = step_toward(start, target[EE_POS], self._gait.s.return_speed,
                                   self.period_s)
        cmd = np.concatenate([p_des, v_des, np.zeros(3), self._ee_weight, [iphase],
                              target[7:9]])
        state.get_mutable_discrete_state(int(self._cmd)).set_value(cmd)

    def lead_s(self) -> float:
        """How far ahead the plan's start state is predicted, s."""
        if self._lead_s is not None:
            return float(self._lead_s)
        recent = self.solve_times[-20:]
        return (float(np.median(recent)) if recent else 0.0) + self._transport_s

    # ------------------------------------------------------------------ accessors
    def solution(self, context):
        """The latest C3Solution in this context (None before the first)."""
        held = context.get_abstract_state(int(self._plan)).get_value()
        return None if held is None else held[1]

    def fallback_counts(self) -> dict:
        """Fall-back totals of both C3 solvers (systems/c3/solver.py FALLBACKS) and the
        ticks that held the EE (`holds`)."""
        out = {k: self._roll.fallbacks[k] + self._ret.fallbacks[k] for k in self._roll.fallbacks}
        return {**out, "holds": self.failures}

    def solve_time_stats(self) -> dict:
        t = np.asarray(self.solve_times, float)
        if t.size == 0:
            return {"count": 0, "median_s": float("nan"), "max_s": float("nan")}
        return {"count": int(t.size), "median_s": float(np.median(t)),
                "max_s": float(t.max())}


def predict_state_ahead(x: np.ndarray, lead_s: float) -> np.ndarray:
    """The 19-state lead_s seconds on at constant velocities: EE and ball positions move
    with their velocities, the ball's quaternion turns with its angular velocity (world
    frame, q_dot = 0.5 [0, w] (x) q)."""
    x = np.array(x, float)
    if lead_s <= 0:
        return x
    x[EE_POS] += lead_s * x[EE_VEL]
    x[BALL_POS] += lead_s * x[BALL_VEL]
    q = x[BALL_QUAT] + lead_s * quaternion_rate(x[BALL_QUAT], x[BALL_ANGVEL])
    x[BALL_QUAT] = q / np.linalg.norm(q)
    return x


__all__ = ["BallRollingPlanner", "predict_state_ahead"]
