"""`ResidualLearner`: online learning of r_comp as a Drake LeafSystem (paper Alg. 1).

A thin wrapper around `adaptive_c3.systems.learning.violation_loss`. Every 1/rate_hz seconds it
samples (x, u, theta*) from its inputs; once it holds a sample from transition_dt ago it
forms the transition (x_{k+1}, x_k, u_k, theta*_k), appends it to a ring buffer of
n_b = options.batch_size transitions, and, when the buffer is full (and learning is
enabled), takes one Adam step on the whole buffer (a sliding window: every new transition
triggers one step on the latest n_b).

Transition spacing. A transition must span the LCS step. By default transition_dt =
1/rate_hz (e.g. the cart-pole LCS has dt = 0.01 s: run the learner at 100 Hz). With
transition_dt = S / rate_hz (S a whole number) the learner keeps the last S + 1 samples
and pairs x_k with x_{k+S}; u_k is the mean of the S inputs sampled over the span and
theta*_k the LCS sampled with x_k (e.g. ball rolling: rate 200 Hz, transition_dt 0.1 s).
`transition_stride` appends only every stride-th transition (and so steps at
rate_hz / stride). If the incoming LCS declares a dt (> 0) that differs from
transition_dt, the update raises ValueError: the learner never silently pairs states
at the wrong spacing.

Input timing (`input_lag`). Drake applies a time step's unrestricted updates before its
discrete updates, so a controller whose output is state set by an unrestricted (or
discrete) update at the same instant as the plant's step (C3Controller) hands the plant
the input computed *at* t, while the learner, updated at t too, still reads the previous
one. Then the input applied from the sample at t is the one the learner reads at t + 1/rate:
set input_lag=1 and u_k is averaged over the S samples after x_k instead of from x_k on.
With a feedthrough controller (output computed from the state input) keep input_lag=0.
Mispairing shifts the input by one step, a prediction error of B (u_k - u_{k-1}) that the
loss can only read as contact, and the residual drifts wherever C3's input changes fast.

Known disturbances. The optional `disturbance` input (n) is a state increment the
plant adds at the start of its step (LcsPlant's port of the same name: the plant steps
from x_k + w_k), e.g. an injected excitation kick. With S = 1 the learner uses x_k + w_k
as the transition's start state; with S > 1 a transition whose span holds a nonzero w is
skipped. Unconnected, w = 0. Without it an injected kick is an unexplained velocity jump
that the loss can only explain as a contact force, which biases r_comp toward contact.

Guards: non-finite samples are skipped and counted (`num_rejected` in the state); epsilon
and gamma are checked against each sample's F (ValueError); each Adam update is clipped to
+-options.max_step per entry.

State: a discrete vector [r (m), Adam m1 (m), Adam m2 (m), t, loss, num_rejected,
num_steps] and an abstract memory of the sample history and the transition buffer. (The
buffered samples also carry a warm-start guess of their QP's active set, which is shared
between context copies; it only affects speed, never a result.)
"""
from __future__ import annotations

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import BasicVector, LeafSystem

from adaptive_c3.systems.contact.lcs import Lcs
from adaptive_c3.systems.learning.violation_loss import (
    LearnerOptions, adam_update, batch_loss_and_grad, check_epsilon, qd_matrix,
    prepare_sample)

__all__ = ["ResidualLearner"]


class _Memory:
    """The learner's history of samples and its transition buffer (treated as immutable:
    updates build a new _Memory; copies share the tuples)."""

    __slots__ = ("history", "buffer", "count")

    def __init__(self, history=(), buffer=(), count=0):
        self.history = history  # tuple of (x, u, lcs, w), newest last, at most S + 1
        self.buffer = buffer    # tuple of PreparedSample, newest last, at most n_b
        self.count = count      # transitions formed so far (for the stride)

    def __deepcopy__(self, memo):
        return _Memory(self.history, self.buffer, self.count)


def _placeholder_lcs(n: int, k: int, m: int) -> Lcs:
    return Lcs(A=np.zeros((n, n)), B=np.zeros((n, k)), D=np.zeros((n, m)), d=np.zeros(n),
               E=np.zeros((m, n)), F=np.eye(m), H=np.zeros((m, k)), c=np.zeros(m))


class ResidualLearner(LeafSystem):
    """Learns the complementarity residual r_comp online.

    Input ports:
      state   (n)         measured state x.
      input   (k)         applied input u.
      lcs     (abstract)  Lcs: the prior model theta* at the current state.
      enable  (1)         optional; > 0.5 learns. Unconnected: the `enabled` argument.
      disturbance (n)     optional; known state increment applied at the start of the
                          plant's step (see the module doc). Unconnected: zero.
    Output ports:
      r_comp             (m)         the current residual.
      loss               (1)         mean l_eps over the buffer at the last update (NaN
                                     before the buffer first fills).
      lcs_with_residual  (abstract)  Lcs: theta* (the lcs input) with r_comp added to c.

    Arguments: options (LearnerOptions; batch_size is n_b), sizes n, k, m; rate_hz, the
    sampling rate; enabled, used when the enable port is unconnected; transition_dt (s,
    default 1/rate_hz) and transition_stride (see the module doc; ball rolling:
    rate_hz=200, transition_dt=0.1, transition_stride=10 -> one step at 20 Hz);
    initial_residual (default zeros); input_lag (0 or 1, see the module doc);
    tied_groups, lists of residual indices learned as one value (their gradients are
    averaged before the Adam step; e.g. the friction-cone edges of one contact pair,
    whose rows share one gap, so a gap offset moves them together); input_from_motion,
    optional f(x_k, x_{k+1}, span_s) -> u_k: the input that explains the measured motion
    of the actuated bodies (e.g. a position-controlled end effector whose true force
    law differs from the model's), used instead of the averaged input port. For a discrete
    plant stepping at the LCS dt, use
    rate_hz = 1/dt: sampling such a plant faster than it steps would pair held states
    with inputs it never used.
    """

    def __init__(self, options: LearnerOptions, num_states: int, num_inputs: int,
                 num_lambda: int, rate_hz: float = 20.0, enabled: bool = True,
                 transition_dt: float | None = None, transition_stride: int = 1,
                 initial_residual=None, input_lag: int = 0, tied_groups=(),
                 input_from_motion=None):
        super().__init__()
        self._input_fn = input_from_motion
        self._groups = [list(map(int, g)) for g in tied_groups]
        if input_lag not in (0, 1):
            raise ValueError(f"ResidualLearner input_lag must be 0 or 1, got {input_lag}")
        self._lag = int(input_lag)
        n, k, m = int(num_states), int(num_inputs), int(num_lambda)
        if min(n, k, m) < 1:
            raise ValueError("ResidualLearner needs num_states, num_inputs, num_lambda >= 1")
        if not (np.isfinite(rate_hz) and rate_hz > 0):
            raise ValueError(f"ResidualLearner rate_hz must be > 0, got {rate_hz}")
        self._opts = options
        self._n, self._k, self._m = n, k, m
        self._period = 1.0 / float(rate_hz)
        span = self._period if transition_dt is None else float(transition_dt)
        S = int(round(span / self._period))
        if S < 1 or abs(S * self._period - span) > 1e-9 * max(1.0, span):
            raise ValueError(f"transition_dt = {span} s must be a whole multiple (>= 1) of "
                             f"the sample period 1/rate_hz = {self._period} s")
        if int(transition_stride) < 1:
            raise ValueError("transition_stride must be >= 1")
        self._span, self._S = span, S
        self._stride = int(transition_stride)
        self._enabled_default = bool(enabled)
        self._mask = options.mask_array(m)
        self._Qd = qd_matrix(options.Qd, n)
        check_epsilon(options.epsilon)
        r0 = np.zeros(m) if initial_residual is None else np.asarray(initial_residual, float)
        if r0.shape != (m,) or not np.isfinite(r0).all():
            raise ValueError(f"initial_residual must be {m} finite numbers")

        # state vector layout
        self._i_r = slice(0, m)
        self._i_m1 = slice(m, 2 * m)
        self._i_m2 = slice(2 * m, 3 * m)
        self._i_t, self._i_loss, self._i_rej, self._i_steps = 3 * m, 3 * m + 1, 3 * m + 2, 3 * m + 3
        s0 = np.zeros(3 * m + 4)
        s0[self._i_r] = r0
        s0[self._i_loss] = np.nan
        self._xs = self.DeclareDiscreteState(BasicVector(s0))
        self._mem = self.DeclareAbstractState(AbstractValue.Make(_Memory()))

        self._placeholder = _placeholder_lcs(n, k, m)
        self.DeclareVectorInputPort("state", n)
        self.DeclareVectorInputPort("input", k)
        self.DeclareAbstractInputPort("lcs", AbstractValue.Make(self._placeholder))
        self.DeclareVectorInputPort("enable", 1)
        self.DeclareVectorInputPort("disturbance", n)

        self.DeclareVectorOutputPort("r_comp", m, self._calc_r,
                                     {self.discrete_state_ticket(self._xs)})
        self.DeclareVectorOutputPort("loss", 1, self._calc_loss,
                                     {self.discrete_state_ticket(self._xs)})
        self.DeclareAbstractOutputPort(
            "lcs_with_residual", lambda: AbstractValue.Make(self._placeholder),
            self._calc_lcs,
            {self.discrete_state_ticket(self._xs),
             self.input_port_ticket(self.get_input_port(2).get_index())})
        self.DeclarePeriodicUnrestrictedUpdateEvent(self._period, 0.0, self._update)

    # ------------------------------------------------------------------ accessors
    @property
    def options(self) -> LearnerOptions:
        return self._opts

    @property
    def tied_groups(self) -> list:
        """Groups of residual rows that share one value (their gradients averaged)."""
        return [list(g) for g in self._groups]

    def residual(self, context) -> np.ndarray:
        """r_comp in this context."""
        return context.get_discrete_state(self._xs).get_value()[self._i_r].copy()

    def num_rejected(self, context) -> int:
        """Non-finite transitions refused so far in this context."""
        return int(context.get_discrete_state(self._xs).get_value()[self._i_rej])

    def num_steps(self, context) -> int:
        """Adam steps taken so far in this context."""
        return int(context.get_discrete_state(self._xs).get_value()[self._i_steps])

    def buffer_size(self, context) -> int:
        """Transitions in the ring buffer (<= batch_size)."""
        return len(context.get_abstract_state(self._mem).get_value().buffer)

    def transitions(self, context) -> tuple:
        """The buffered transitions as PreparedSample (z, q, ...), oldest first."""
        return context.get_abstract_state(self._mem).get_value().buffer

    # ------------------------------------------------------------------ outputs
    def _calc_r(self, context, out):
        out.SetFromVector(context.get_discrete_state(self._xs).get_value()[self._i_r])

    def _calc_loss(self, context, out):
        out.SetFromVector([context.get_discrete_state(self._xs).get_value()[self._i_loss]])

    def _calc_lcs(self, context, out):
        lcs = self._read_lcs(context)
        r = context.get_discrete_state(self._xs).get_value()[self._i_r]
        out.set_value(lcs.with_residual(r))

    # ------------------------------------------------------------------ update
    def _read_lcs(self, context) -> Lcs:
        port = self.get_input_port(2)
        if not port.HasValue(context):
            raise RuntimeError("ResidualLearner: the 'lcs' input port is not connected")
        lcs = port.Eval(context)
        if not isinstance(lcs, Lcs):
            raise TypeError(f"ResidualLearner: 'lcs' input carries a {type(lcs).__name__}, "
                            "not an Lcs")
        if (lcs.num_states, lcs.num_inputs, lcs.num_lambda) != (self._n, self._k, self._m):
            raise ValueError(
                f"ResidualLearner: 'lcs' input has (n, k, m) = ({lcs.num_states}, "
                f"{lcs.num_inputs}, {lcs.num_lambda}), expected ({self._n}, {self._k}, "
                f"{self._m})")
        if lcs.dt > 0 and abs(lcs.dt - self._span) > 1e-9 * max(1.0, self._span):
            raise ValueError(
                f"ResidualLearner: the LCS step is dt = {lcs.dt} s but transitions span "
                f"{self._span} s; set rate_hz = 1/dt or transition_dt = dt")
        return lcs

    def _is_enabled(self, context) -> bool:
        port = self.get_input_port(3)
        if port.HasValue(context):
            return bool(port.Eval(context)[0] > 0.5)
        return self._enabled_default

    def _disturbance(self, context):
        port = self.get_input_port(4)
        if port.HasValue(context):
            return np.array(port.Eval(context), float)
        return None

    def _update(self, context, state):
        x = np.array(self.get_input_port(0).Eval(context), float)
        u = np.array(self.get_input_port(1).Eval(context), float)
        lcs = self._read_lcs(context)
        w = self._disturbance(context)
        mem = context.get_abstract_state(self._mem).get_value()
        vec = context.get_discrete_state(self._xs).get_value().copy()

        history = (mem.history + ((x, u, lcs, w),))[-(self._S + 1):]
        buffer, count = mem.buffer, mem.count
        appended = False
        if len(history) == self._S + 1:
            x_k, _, lcs_k, _ = history[0]
            if self._input_fn is not None:
                u_k = np.asarray(self._input_fn(x_k, x, self._span), float)
            else:
                u_k = np.mean([h[1] for h in history[self._lag:self._S + self._lag]], axis=0)
            ws = [h[3] for h in history[:-1] if h[3] is not None and np.any(h[3] != 0)]
            skip = bool(ws) and self._S > 1
            if ws and not skip:
                x_k = x_k + ws[0]  # S = 1: the plant stepped from x_k + w_k
            if count % self._stride == 0 and not skip:
                s = prepare_sample(x, x_k, u_k, lcs_k, self._opts.epsilon,
                                   self._opts.gamma, self._Qd)
                if s is None:
                    vec[self._i_rej] += 1
                else:
                    buffer = (buffer + (s,))[-self._opts.batch_size:]
                    appended = True
            count += 1

        if appended and len(buffer) == self._opts.batch_size:
            r = vec[self._i_r]
            try:
                loss, grad, used = batch_loss_and_grad(buffer, r)
            except RuntimeError:   # a QP not solved to tolerance: skip this step
                loss, grad, used = np.nan, None, 0
                vec[self._i_rej] += 1
            vec[self._i_loss] = loss
            if used and self._is_enabled(context):
                grad = np.array(grad, float)
                for g in self._groups:
                    grad[g] = np.mean(grad[g])
                delta, m1, m2, t = adam_update(grad, vec[self._i_m1], vec[self._i_m2],
                                               int(vec[self._i_t]), self._opts, self._mask)
                vec[self._i_r] = r + delta
                vec[self._i_m1], vec[self._i_m2], vec[self._i_t] = m1, m2, t
                vec[self._i_steps] += 1

        state.get_mutable_discrete_state(self._xs).set_value(vec)
        state.get_mutable_abstract_state(self._mem).set_value(_Memory(history, buffer, count))
