"""ResidualLearner in a Drake diagram: learns the cart-pole's wall offsets online."""
from types import SimpleNamespace

import numpy as np
import pytest
import scipy.linalg
from pydrake.common.value import AbstractValue
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder, LeafSystem
from pydrake.systems.primitives import ConstantValueSource, ConstantVectorSource, VectorLogSink

from adaptive_c3.models.cartpole import CartpoleParams, cartpole_lcs
from adaptive_c3.systems.contact.lcs import Lcs
from adaptive_c3.systems.contact.lcs_plant import LcsPlant
from adaptive_c3.systems.learning.residual_learner import ResidualLearner
from adaptive_c3.systems.learning.violation_loss import LearnerOptions, batch_loss_and_grad

DPHI = np.array([-0.15, 0.15])
TRUE = cartpole_lcs()
MODEL = cartpole_lcs(wall_offset_error=DPHI)
OPTS = LearnerOptions(epsilon=100.0, gamma=1e-2, learning_rate=3e-3, batch_size=10)


class _Shaker(LeafSystem):
    """Test-only input u = -K x + 20 sin(pi t): LQR on the contact-free model keeps the
    cart near the middle (open loop the inverted pendulum runs away) while the 0.5 Hz
    push drives the pole tip past both walls (|x - l theta| up to ~0.55 m)."""

    def __init__(self, lcs):
        super().__init__()
        P = scipy.linalg.solve_discrete_are(lcs.A, lcs.B, np.diag([10, 3, 1, 1]), np.eye(1))
        self._K = np.linalg.solve(np.eye(1) + lcs.B.T @ P @ lcs.B, lcs.B.T @ P @ lcs.A)
        self.DeclareVectorInputPort("state", 4)
        self.DeclareVectorOutputPort("u", 1, self._calc)

    def _calc(self, context, out):
        x = self.get_input_port(0).Eval(context)
        out.SetFromVector(-self._K @ x + 20.0 * np.sin(np.pi * context.get_time()))


def build(enable=None, enabled_param=True, opts=OPTS, model=MODEL, rate_hz=100.0, **kw):
    b = DiagramBuilder()
    plant = b.AddSystem(LcsPlant(TRUE, np.zeros(4)))
    shaker = b.AddSystem(_Shaker(TRUE))
    learner = b.AddSystem(ResidualLearner(opts, 4, 1, 2, rate_hz=rate_hz,
                                          enabled=enabled_param, **kw))
    src = b.AddSystem(ConstantValueSource(AbstractValue.Make(model)))
    b.Connect(plant.get_output_port(0), shaker.get_input_port(0))
    b.Connect(shaker.get_output_port(0), plant.get_input_port(0))
    b.Connect(plant.get_output_port(0), learner.GetInputPort("state"))
    b.Connect(shaker.get_output_port(0), learner.GetInputPort("input"))
    b.Connect(src.get_output_port(0), learner.GetInputPort("lcs"))
    if enable is not None:
        en = b.AddSystem(ConstantVectorSource([float(enable)]))
        b.Connect(en.get_output_port(0), learner.GetInputPort("enable"))
    log_r = b.AddSystem(VectorLogSink(2, publish_period=0.01))
    b.Connect(learner.GetOutputPort("r_comp"), log_r.get_input_port(0))
    log_x = b.AddSystem(VectorLogSink(4, publish_period=0.01))
    b.Connect(plant.get_output_port(0), log_x.get_input_port(0))
    log_loss = b.AddSystem(VectorLogSink(1, publish_period=0.01))
    b.Connect(learner.GetOutputPort("loss"), log_loss.get_input_port(0))
    return SimpleNamespace(sim=Simulator(b.Build()), learner=learner, log_r=log_r,
                           log_x=log_x, log_loss=log_loss)


def test_learner_converges_to_dphi_in_a_diagram():
    h = build(enable=1.0)
    sim, learner, log_r, log_x = h.sim, h.learner, h.log_r, h.log_x
    sim.AdvanceTo(6.0)
    root = sim.get_context()
    ctx = learner.GetMyContextFromRoot(root)
    x = log_x.FindLog(root).data().T
    tip = x[:, 0] - 0.6 * x[:, 1]
    assert tip.max() > 0.5 and tip.min() < -0.5  # both walls, past the model's walls too
    r_log = log_r.FindLog(root)
    t, r = r_log.sample_times(), r_log.data().T
    assert np.abs(r[t >= 5.0] - DPHI).max() < 0.01  # the last second
    assert np.all(r[t <= 0.5] == 0.0)  # it started from the wrong model
    assert learner.num_steps(ctx) > 300 and learner.num_rejected(ctx) == 0
    # The buffered transitions: the wrong model (r = 0) leaves a clear violation loss,
    # the learned residual explains them (measured at 6 s: 4.9e-4 at r = 0, 0 at r).
    buffer = learner.transitions(ctx)
    loss_wrong = batch_loss_and_grad(buffer, np.zeros(2))[0]
    loss_learned = batch_loss_and_grad(buffer, learner.residual(ctx))[0]
    assert loss_wrong > 1e-4
    assert loss_learned <= 1e-3 * loss_wrong
    assert learner.GetOutputPort("loss").Eval(ctx)[0] <= 1e-3 * loss_wrong
    lcs_out = learner.GetOutputPort("lcs_with_residual").Eval(ctx)
    assert isinstance(lcs_out, Lcs)
    np.testing.assert_allclose(lcs_out.c, MODEL.c + learner.residual(ctx), atol=1e-15)
    np.testing.assert_array_equal(lcs_out.A, MODEL.A)


@pytest.mark.parametrize("how", ["port", "parameter"])
def test_disabled_learner_keeps_r_at_zero(how):
    if how == "port":
        h = build(enable=0.0, enabled_param=True)
    else:
        h = build(enable=None, enabled_param=False)
    sim, learner, log_r = h.sim, h.learner, h.log_r
    sim.AdvanceTo(2.0)
    ctx = learner.GetMyContextFromRoot(sim.get_context())
    assert np.all(log_r.FindLog(sim.get_context()).data() == 0.0)
    assert learner.num_steps(ctx) == 0
    assert learner.buffer_size(ctx) == 10
    loss = h.log_loss.FindLog(sim.get_context()).data()[0]
    assert np.all(np.isfinite(loss[20:])) and loss[20:].max() > 0  # still reported
    np.testing.assert_array_equal(
        learner.GetOutputPort("lcs_with_residual").Eval(ctx).c, MODEL.c)


def test_mask_learns_only_the_selected_entry():
    opts = LearnerOptions(epsilon=100.0, gamma=1e-2, learning_rate=1e-2, mask=[False, True])
    h = build(enable=1.0, opts=opts)
    h.sim.AdvanceTo(4.0)
    r = h.learner.residual(h.learner.GetMyContextFromRoot(h.sim.get_context()))
    assert r[0] == 0.0 and abs(r[1] - DPHI[1]) < 0.02


class _Script(LeafSystem):
    """Outputs x(t) = [t, 0, 0, 0] (NaN at t in nan_times) and u(t) = [10 t]."""

    def __init__(self, nan_times=()):
        super().__init__()
        self._nan = [float(t) for t in nan_times]
        self.DeclareVectorOutputPort("x", 4, self._x)
        self.DeclareVectorOutputPort("u", 1, self._u)

    def _x(self, context, out):
        t = context.get_time()
        bad = any(abs(t - tn) < 1e-9 for tn in self._nan)
        out.SetFromVector([np.nan if bad else t, 0.0, 0.0, 0.0])

    def _u(self, context, out):
        out.SetFromVector([10.0 * context.get_time()])


def _probe_lcs(dt):
    """A = I, B = d = 0, so z = x_k - x_{k+S}; q = E x_k + H u_k + c reads x_k[0] and u_k."""
    return Lcs(A=np.eye(4), B=np.zeros((4, 1)), D=0.01 * np.ones((4, 2)), d=np.zeros(4),
               E=np.array([[1.0, 0, 0, 0], [0, 0, 0, 0]]), F=0.02 * np.eye(2),
               H=np.array([[0.0], [1.0]]), c=np.array([1.0, 1.0]), dt=dt)


def _script_diagram(lcs, nan_times=(), **kw):
    b = DiagramBuilder()
    src = b.AddSystem(_Script(nan_times))
    learner = b.AddSystem(ResidualLearner(LearnerOptions(epsilon=1.0, gamma=1e-2,
                                                         batch_size=4), 4, 1, 2, **kw))
    lcs_src = b.AddSystem(ConstantValueSource(AbstractValue.Make(lcs)))
    b.Connect(src.get_output_port(0), learner.GetInputPort("state"))
    b.Connect(src.get_output_port(1), learner.GetInputPort("input"))
    b.Connect(lcs_src.get_output_port(0), learner.GetInputPort("lcs"))
    return Simulator(b.Build()), learner


def test_transitions_span_transition_dt_with_the_input_averaged():
    # sample at 200 Hz, transitions over 0.02 s (S = 4 samples), one every 2nd sample
    sim, learner = _script_diagram(_probe_lcs(0.02), rate_hz=200.0, transition_dt=0.02,
                                   transition_stride=2)
    sim.AdvanceTo(0.101)  # samples at t = 0, 0.005, ..., 0.1
    ctx = learner.GetMyContextFromRoot(sim.get_context())
    buf = learner.transitions(ctx)
    assert len(buf) == 4
    # transitions end at t = 0.02, 0.03, ..., 0.1 (stride 2): the last four start at
    # t0 = 0.05, 0.06, 0.07, 0.08
    for s, t0 in zip(buf, [0.05, 0.06, 0.07, 0.08]):
        np.testing.assert_allclose(s.z[0], -0.02, atol=1e-12)  # x_k - x_{k+S}
        np.testing.assert_allclose(s.q[0], 1.0 + t0, atol=1e-12)  # E x_k + c
        u_mean = 10.0 * np.mean([t0 + 0.005 * i for i in range(4)])
        np.testing.assert_allclose(s.q[1], 1.0 + u_mean, atol=1e-12)  # H u_k + c


def test_non_finite_samples_are_counted_not_learned():
    sim, learner = _script_diagram(_probe_lcs(0.01), nan_times=[0.05], rate_hz=100.0)
    sim.AdvanceTo(0.2)
    ctx = learner.GetMyContextFromRoot(sim.get_context())
    # x(0.05) is NaN: the transitions ending and starting there are refused
    assert learner.num_rejected(ctx) == 2
    assert np.all(np.isfinite(learner.residual(ctx)))
    assert learner.num_steps(ctx) > 0


def test_lcs_step_must_match_the_transition_span():
    sim, learner = _script_diagram(_probe_lcs(0.01), rate_hz=20.0)
    with pytest.raises(Exception, match="dt"):
        sim.AdvanceTo(0.2)
    with pytest.raises(ValueError, match="multiple"):
        ResidualLearner(OPTS, 4, 1, 2, rate_hz=200.0, transition_dt=0.0123)
    params = CartpoleParams(dt=0.05)
    with pytest.raises(Exception, match="dt"):
        build(enable=1.0, model=cartpole_lcs(params, DPHI)).sim.AdvanceTo(0.1)


class _HeldShaker(_Shaker):
    """The shaker's input held in state, recomputed in an unrestricted update at every
    plant step (as C3Controller does): the plant, stepping at the same instant, gets the
    new value while a learner updated at that instant still reads the old one."""

    def __init__(self, lcs, period=0.01):
        LeafSystem.__init__(self)
        P = scipy.linalg.solve_discrete_are(lcs.A, lcs.B, np.diag([10, 3, 1, 1]), np.eye(1))
        self._K = np.linalg.solve(np.eye(1) + lcs.B.T @ P @ lcs.B, lcs.B.T @ P @ lcs.A)
        self.DeclareVectorInputPort("state", 4)
        held = self.DeclareDiscreteState(1)
        self.DeclareStateOutputPort("u", held)
        self.DeclarePeriodicUnrestrictedUpdateEvent(period, 0.0, self._hold)

    def _hold(self, context, state):
        x = self.get_input_port(0).Eval(context)
        state.get_mutable_discrete_state(0).SetFromVector(
            -self._K @ x + 20.0 * np.sin(np.pi * context.get_time()))


def _run_at_dphi(held=False, input_lag=0, kick_at=None, tell_learner=True, t_end=4.0):
    """Learner started at r = delta_phi; returns max_t |r - delta_phi| and the steps.
    With the transitions paired right every sample is explained exactly (gradient zero
    to rounding); Adam's scale invariance still turns rounding-level gradients into
    steps of up to ~lr, so r wanders by a few lr at most, never more."""
    from pydrake.systems.primitives import TrajectorySource
    from pydrake.trajectories import PiecewisePolynomial
    b = DiagramBuilder()
    plant = b.AddSystem(LcsPlant(TRUE, np.zeros(4)))
    shaker = b.AddSystem(_HeldShaker(TRUE) if held else _Shaker(TRUE))
    learner = b.AddSystem(ResidualLearner(OPTS, 4, 1, 2, rate_hz=100.0,
                                          initial_residual=DPHI, input_lag=input_lag))
    src = b.AddSystem(ConstantValueSource(AbstractValue.Make(MODEL)))
    b.Connect(plant.get_output_port(0), shaker.get_input_port(0))
    b.Connect(shaker.get_output_port(0), plant.get_input_port(0))
    b.Connect(plant.get_output_port(0), learner.GetInputPort("state"))
    b.Connect(shaker.get_output_port(0), learner.GetInputPort("input"))
    b.Connect(src.get_output_port(0), learner.GetInputPort("lcs"))
    if kick_at is not None:
        kick = np.array([0.0, 0.0, 3.0, 0.0])
        traj = PiecewisePolynomial.ZeroOrderHold(
            [0.0, kick_at, kick_at + 0.005, 100.0], np.stack([0 * kick, kick, 0 * kick, 0 * kick]).T)
        ks = b.AddSystem(TrajectorySource(traj))
        b.Connect(ks.get_output_port(), plant.GetInputPort("disturbance"))
        if tell_learner:
            b.Connect(ks.get_output_port(), learner.GetInputPort("disturbance"))
    log = b.AddSystem(VectorLogSink(2, publish_period=0.01))
    b.Connect(learner.GetOutputPort("r_comp"), log.get_input_port(0))
    sim = Simulator(b.Build())
    sim.AdvanceTo(t_end)
    ctx = learner.GetMyContextFromRoot(sim.get_context())
    r = log.FindLog(sim.get_context()).data().T
    return float(np.abs(r - DPHI).max()), learner.num_steps(ctx)


def test_input_lag_pairs_a_held_controller_input_with_its_step():
    dev, steps = _run_at_dphi(held=True, input_lag=1)
    assert steps > 300
    assert dev < 3 * OPTS.learning_rate
    assert dev == _run_at_dphi(held=False)[0]  # exactly the feedthrough controller's run
    dev_bad, _ = _run_at_dphi(held=True, input_lag=0)  # one step late: reads B du as contact
    assert dev_bad > 10 * OPTS.learning_rate
    with pytest.raises(ValueError, match="input_lag"):
        ResidualLearner(OPTS, 4, 1, 2, rate_hz=100.0, input_lag=2)


def test_known_disturbance_is_not_read_as_contact():
    dev, _ = _run_at_dphi(kick_at=1.0)
    assert dev < 3 * OPTS.learning_rate
    dev_blind, _ = _run_at_dphi(kick_at=1.0, tell_learner=False)  # a 3 m/s jump read as contact
    assert dev_blind > 3 * dev and dev_blind > 3 * OPTS.learning_rate
