"""The violation-based loss: exact QP, gradient against finite differences, Adam, guards."""
import itertools

import numpy as np
import pytest

from adaptive_c3.models.cartpole import cartpole_lcs
from adaptive_c3.systems.contact.lcs import Lcs
from adaptive_c3.systems.learning.violation_loss import (
    KKT_TOL, LearnerOptions, ViolationLossLearner, adam_update, batch_loss_and_grad,
    check_gamma, prepare_sample, qd_matrix, solve_batch, solve_sample, violation_loss)

DPHI = np.array([-0.15, 0.15])
TRUE = cartpole_lcs()
MODEL = cartpole_lcs(wall_offset_error=DPHI)
L_POLE = 0.6


def random_lcs(rng, n, k, m):
    """A random LCS whose F = S + K (S symmetric PD, K skew) is not symmetric."""
    G = rng.standard_normal((m, m))
    K = 0.05 * (G - G.T)
    S = 0.1 * G @ G.T / m + 0.05 * np.eye(m)
    return Lcs(A=np.eye(n) + 0.05 * rng.standard_normal((n, n)),
               B=0.05 * rng.standard_normal((n, k)), D=0.1 * rng.standard_normal((n, m)),
               d=0.01 * rng.standard_normal(n), E=rng.standard_normal((m, n)), F=S + K,
               H=rng.standard_normal((m, k)), c=0.1 * rng.standard_normal(m), dt=0.01)


def valid_gamma(lcs):
    return 0.5 * np.linalg.eigvalsh(lcs.F + lcs.F.T)[0]


def random_transition(rng, lcs):
    """Data from the same LCS with c shifted, so data and model disagree on contact."""
    n, k, m = lcs.num_states, lcs.num_inputs, lcs.num_lambda
    x, u = rng.standard_normal(n), rng.standard_normal(k)
    x_next, _ = lcs.with_residual(0.3 * rng.standard_normal(m)).step(x, u)
    return x_next, x, u


def scaled_g(s, r):
    qr = s.q + r
    return np.concatenate([s.b + s.F.T @ qr / s.gamma, -qr / s.gamma])


def enumerate_bqp(H, g):
    """Ground truth for min 1/2 y'Hy + g'y, y >= 0: try every free set."""
    nv = len(g)
    for free in itertools.product([False, True], repeat=nv):
        idx = np.flatnonzero(free)
        y = np.zeros(nv)
        if idx.size:
            y[idx] = np.linalg.solve(H[np.ix_(idx, idx)], -g[idx])
        if y.min() >= -1e-11 and (H @ y + g).min() >= -1e-9:
            return y
    raise AssertionError("no KKT point found")


def central_difference(s, r, h):
    fd = np.zeros_like(r)
    for i in range(r.size):
        e = np.zeros_like(r)
        e[i] = h
        fd[i] = (solve_sample(s, r + e).loss - solve_sample(s, r - e).loss) / (2 * h)
    return fd


# ------------------------------------------------------------------ exact QP
@pytest.mark.parametrize("eps", [1e-3, 1e-5, 1e-7])
def test_qp_is_exact_against_enumeration(eps):
    rng = np.random.default_rng(1)
    active_lams = 0
    for trial in range(40):
        m = int(rng.integers(1, 6))
        lcs = random_lcs(rng, int(rng.integers(2, 7)), 2, m)
        s = prepare_sample(*random_transition(rng, lcs), lcs, eps, valid_gamma(lcs),
                           Qd=float(rng.uniform(0.1, 1e5)))
        r = 0.1 * rng.standard_normal(m)
        sol = solve_sample(s, r)
        assert sol.kkt <= KKT_TOL
        y = enumerate_bqp(s.H, scaled_g(s, r))
        np.testing.assert_allclose(np.concatenate([sol.lam, sol.eta]), y, atol=1e-9)
        active_lams += int(np.any(sol.lam > 0))
    assert active_lams >= 10  # the data really exercised contact


def test_warm_start_does_not_change_the_answer():
    rng = np.random.default_rng(2)
    lcs = random_lcs(rng, 5, 2, 4)
    data = random_transition(rng, lcs)
    warm = prepare_sample(*data, lcs, 1e-5, valid_gamma(lcs))
    for _ in range(5):
        r = 0.2 * rng.standard_normal(4)
        cold = prepare_sample(*data, lcs, 1e-5, valid_gamma(lcs))
        a, b = solve_sample(warm, r), solve_sample(cold, r)
        np.testing.assert_allclose(a.lam, b.lam, atol=1e-12)
        np.testing.assert_allclose(a.grad, b.grad, rtol=1e-9, atol=1e-9)


def test_batched_solve_matches_single_solves():
    rng = np.random.default_rng(3)
    lcs = random_lcs(rng, 6, 2, 5)
    samples = [prepare_sample(*random_transition(rng, lcs), lcs, 1e-4, valid_gamma(lcs))
               for _ in range(12)]
    r = 0.1 * rng.standard_normal(5)
    lam, eta, loss, grad, kkt = solve_batch(samples, r)
    assert kkt.max() <= KKT_TOL
    singles = [solve_sample(s, r) for s in samples]
    np.testing.assert_allclose(lam, [x.lam for x in singles], atol=1e-10)
    np.testing.assert_allclose(loss, [x.loss for x in singles], rtol=1e-9)
    np.testing.assert_allclose(grad, [x.grad for x in singles], rtol=1e-8, atol=1e-8)
    mean_loss, mean_grad, used = batch_loss_and_grad(samples, r)
    assert used == 12
    assert mean_loss == pytest.approx(np.mean([x.loss for x in singles]), rel=1e-9)
    np.testing.assert_allclose(mean_grad, np.mean([x.grad for x in singles], axis=0),
                               rtol=1e-8, atol=1e-8)


# ------------------------------------------------------------------ gradient proof
@pytest.mark.parametrize("eps", [1e-1, 1e-3, 1e-5, 1e-7])
def test_gradient_matches_central_differences_on_random_lcs(eps):
    rng = np.random.default_rng(4)
    nonzero = 0
    for trial in range(25):
        m = int(rng.integers(1, 5))
        lcs = random_lcs(rng, int(rng.integers(2, 6)), 2, m)
        s = prepare_sample(*random_transition(rng, lcs), lcs, eps, valid_gamma(lcs))
        r = 0.1 * rng.standard_normal(m)
        sol = solve_sample(s, r)
        fd = central_difference(s, r, 1e-6)
        scale = max(np.abs(sol.grad).max(), 1e-300)
        np.testing.assert_allclose(sol.grad, fd, rtol=1e-5, atol=1e-5 * scale)
        # the envelope formula itself
        w = s.q + s.F @ sol.lam + r - sol.eta
        np.testing.assert_allclose(sol.grad, w / (eps * s.gamma), rtol=1e-6,
                                   atol=1e-6 * scale)
        nonzero += int(np.abs(sol.grad).max() > 0)
    assert nonzero >= 10


def cartpole_transition(case, rng):
    """A transition of the true cart-pole in one of the four cases of Fig. 3.

    The pole tip is at p = x - l theta; the true walls are at +-0.35, the model's at
    +0.5 (wall 0, too far: false negatives) and -0.2 (wall 1, too near: false positives).
    """
    tip = {"both_wall0": 0.6, "both_wall1": -0.45, "contact_only": 0.45,
           "predicted_only": -0.28, "neither": 0.05}[case]
    x = np.array([rng.uniform(-0.1, 0.1), 0.0, rng.normal(0, 0.3), rng.normal(0, 0.5)])
    x[1] = (x[0] - tip) / L_POLE
    u = rng.normal(size=1)
    x_next, lam_true = TRUE.step(x, u)
    lam_model = MODEL.solve_lambda(x, u)
    return (x_next, x, u), lam_true, lam_model


CASES = ["both_wall0", "both_wall1", "contact_only", "predicted_only", "neither"]


@pytest.mark.parametrize("case", CASES)
@pytest.mark.parametrize("eps", [100.0, 1e-3, 1e-7])
def test_cartpole_gradient_matches_central_differences(case, eps):
    rng = np.random.default_rng(5)
    for _ in range(3):
        data, lam_true, lam_model = cartpole_transition(case, rng)
        s = prepare_sample(*data, MODEL, eps, 1e-2)
        for r in (np.zeros(2), np.array([-0.02, 0.03])):  # off the kinks at the walls
            sol = solve_sample(s, r)
            assert sol.kkt <= KKT_TOL
            fd = central_difference(s, r, 1e-7)
            scale = np.abs(sol.grad).max()
            np.testing.assert_allclose(sol.grad, fd, rtol=1e-5, atol=1e-5 * scale + 1e-12)


@pytest.mark.parametrize("case", CASES)
def test_cartpole_gradient_pattern_of_fig3(case):
    """eps Q_d = 100: zero gradient in 'neither' only; the sign moves r toward dphi."""
    rng = np.random.default_rng(6)
    for _ in range(5):
        data, lam_true, lam_model = cartpole_transition(case, rng)
        contact, predicted = bool(lam_true.any()), bool(lam_model.any())
        expected = {"both_wall0": (True, True), "both_wall1": (True, True),
                    "contact_only": (True, False), "predicted_only": (False, True),
                    "neither": (False, False)}[case]
        assert (contact, predicted) == expected
        loss, grad = violation_loss(*data, MODEL, np.zeros(2), epsilon=100.0, gamma=1e-2)
        if case == "neither":
            assert np.all(grad == 0.0) and loss == 0.0
            continue
        wall = 0 if case in ("both_wall0", "contact_only") else 1
        assert abs(grad[wall]) > 1e-4
        assert grad[1 - wall] == 0.0
        # gradient descent moves r[wall] toward dphi[wall]
        assert np.sign(-grad[wall]) == np.sign(DPHI[wall])


def test_contact_only_gradient_vanishes_when_eps_qd_is_small():
    """The documented limit of the loss: with eps Q_d = 1e-3 the contact-only case is flat,
    exactly as the KKT condition q + r + eps D'Q_d z >= 0 predicts."""
    rng = np.random.default_rng(7)
    data, lam_true, lam_model = cartpole_transition("contact_only", rng)
    s = prepare_sample(*data, MODEL, 1e-3, 1e-2)
    assert np.all(s.q >= 0) and np.all(s.q + s.b >= 0)
    assert np.all(solve_sample(s, np.zeros(2)).grad == 0.0)
    s100 = prepare_sample(*data, MODEL, 100.0, 1e-2)
    assert np.any(s100.q + s100.b < 0)
    assert np.any(solve_sample(s100, np.zeros(2)).grad != 0.0)


def test_true_model_has_zero_loss():
    rng = np.random.default_rng(8)
    for case in CASES:
        data, _, _ = cartpole_transition(case, rng)
        loss, grad = violation_loss(*data, MODEL, DPHI, epsilon=1e-5, gamma=1e-2)
        assert loss == pytest.approx(0.0, abs=1e-12 / 1e-5)
        assert np.abs(grad).max() < 1e-6


# ------------------------------------------------------------------ learning
def cartpole_dataset(rng, count):
    data = []
    for _ in range(count):
        tip = rng.uniform(-0.7, 0.7)
        x = np.array([rng.uniform(-0.2, 0.2), 0.0, rng.normal(0, 0.3), rng.normal(0, 0.5)])
        x[1] = (x[0] - tip) / L_POLE
        u = rng.normal(size=1)
        x_next, lam = TRUE.step(x, u)
        data.append(((x_next, x, u, MODEL), lam))
    return data


@pytest.mark.parametrize("eps", [100.0, 1e-3])
def test_adam_converges_to_dphi_on_fixed_cartpole_data(eps):
    rng = np.random.default_rng(9)
    data = cartpole_dataset(rng, 60)
    lams = np.array([lam for _, lam in data])
    assert (lams[:, 0] > 0).sum() >= 5 and (lams[:, 1] > 0).sum() >= 5  # both walls
    learner = ViolationLossLearner(
        LearnerOptions(epsilon=eps, gamma=1e-2, learning_rate=1e-2, batch_size=10), 2)
    samples = [learner.prepare(*t) for t, _ in data]
    first = learner.loss_and_grad(samples)[0]
    for _ in range(400):
        batch = [samples[j] for j in rng.choice(len(samples), 10, replace=False)]
        learner.step(batch)
    assert np.abs(learner.r - DPHI).max() < 0.01
    assert learner.loss_and_grad(samples)[0] < 1e-3 * first


def test_mask_freezes_entries_and_max_step_bounds_each_update():
    rng = np.random.default_rng(10)
    data = cartpole_dataset(rng, 30)
    opts = LearnerOptions(epsilon=100.0, gamma=1e-2, learning_rate=10.0, batch_size=10,
                          mask=[True, False], max_step=0.004)
    learner = ViolationLossLearner(opts, 2)
    samples = [learner.prepare(*t) for t, _ in data]
    for k in range(20):
        before = learner.r.copy()
        res = learner.step(samples[k % 3 * 10:(k % 3 + 1) * 10])
        assert np.abs(learner.r - before).max() <= 0.004 + 1e-15
        assert learner.r[1] == 0.0
        assert res.used == 10
    assert learner.r[0] < -0.07  # it did move, 0.004 at a time


def test_adam_update_is_standard_adam():
    opts = LearnerOptions(epsilon=1.0, gamma=0.1, learning_rate=0.1, max_step=1.0)
    g = np.array([2.0, -0.5])
    delta, m1, m2, t = adam_update(g, np.zeros(2), np.zeros(2), 0, opts)
    # first step: mhat = g, vhat = g^2 -> delta = -lr * sign(g) (up to adam_eps)
    np.testing.assert_allclose(delta, -0.1 * np.sign(g), rtol=1e-7)
    assert t == 1
    delta2, *_ = adam_update(np.array([np.nan, 1.0]), m1, m2, t, opts)
    assert np.all(delta2 == 0.0)


# ------------------------------------------------------------------ guards
def test_non_finite_samples_are_skipped_and_counted():
    rng = np.random.default_rng(11)
    data = cartpole_dataset(rng, 10)
    learner = ViolationLossLearner(LearnerOptions(epsilon=100.0, gamma=1e-2), 2)
    batch = [learner.prepare(*t) for t, _ in data]
    x_next, x, u, lcs = data[0][0]
    bad = [learner.prepare(x_next * np.nan, x, u, lcs),
           learner.prepare(x_next, x, np.array([np.inf]), lcs)]
    assert bad == [None, None] and learner.num_rejected == 2
    res = learner.step(batch + bad)
    assert res.used == 10 and res.rejected == 2
    assert np.all(np.isfinite(learner.r)) and np.isfinite(res.loss)
    empty = learner.step(bad)
    assert empty.used == 0 and np.all(empty.delta == 0)


@pytest.mark.parametrize("eps", [0.0, -1e-3, np.nan, np.inf])
def test_bad_epsilon_is_refused(eps):
    with pytest.raises(ValueError, match="epsilon"):
        LearnerOptions(epsilon=eps, gamma=1e-2)
    x = np.zeros(4)
    with pytest.raises(ValueError, match="epsilon"):
        violation_loss(x, x, [0.0], MODEL, np.zeros(2), epsilon=eps, gamma=1e-2)


def test_gamma_outside_the_convex_range_is_refused():
    assert check_gamma(MODEL.F, 0.039) == pytest.approx(0.04)  # sigma_min(F + F') = 2/ks
    x = np.zeros(4)
    for gamma in (0.04, 0.1):
        with pytest.raises(ValueError, match="gamma"):
            violation_loss(x, x, [0.0], MODEL, np.zeros(2), epsilon=1.0, gamma=gamma)
    with pytest.raises(ValueError, match="gamma"):
        LearnerOptions(epsilon=1.0, gamma=0.0)
    indefinite = MODEL.replace(F=np.array([[0.02, 0.0], [0.0, -0.01]]))
    with pytest.raises(ValueError, match="positive definite"):
        violation_loss(x, x, [0.0], indefinite, np.zeros(2), epsilon=1.0, gamma=1e-3)


def test_options_validation_and_qd_forms():
    with pytest.raises(ValueError, match="batch_size"):
        LearnerOptions(epsilon=1.0, gamma=0.01, batch_size=0)
    with pytest.raises(ValueError, match="max_step"):
        LearnerOptions(epsilon=1.0, gamma=0.01, max_step=0.0)
    with pytest.raises(ValueError, match="mask"):
        LearnerOptions(epsilon=1.0, gamma=0.01, mask=[True]).mask_array(2)
    np.testing.assert_array_equal(qd_matrix(None, 3), np.eye(3))
    np.testing.assert_array_equal(qd_matrix(2.0, 2), 2 * np.eye(2))
    np.testing.assert_array_equal(qd_matrix([0, 1e5], 2), np.diag([0, 1e5]))
    with pytest.raises(ValueError, match="entries"):
        qd_matrix([1, 2, 3], 2)
    with pytest.raises(ValueError, match="semidefinite"):
        qd_matrix(np.diag([1.0, -1.0]), 2)
    with pytest.raises(ValueError, match="symmetric"):
        qd_matrix(np.array([[1.0, 0.5], [0.0, 1.0]]), 2)


def test_optional_learning_rate_decay():
    opts = LearnerOptions(epsilon=1.0, gamma=0.01, learning_rate=0.1, max_step=1.0)
    g = np.array([1.0, -2.0])
    d0, *_ = adam_update(g, np.zeros(2), np.zeros(2), 0, opts)
    np.testing.assert_allclose(d0, [-0.1, 0.1], rtol=1e-6)  # default: no decay
    decayed = LearnerOptions(epsilon=1.0, gamma=0.01, learning_rate=0.1, max_step=1.0,
                             lr_decay_steps=4.0)
    d1, m1, m2, t = adam_update(g, np.zeros(2), np.zeros(2), 9, decayed)
    assert t == 10
    # step t = 10: xi / (1 + 10 / 4); Adam's first normalised step is sign(g) only at t = 1,
    # so compare against the undecayed step from the same moments
    d_ref, *_ = adam_update(g, np.zeros(2), np.zeros(2), 9, opts)
    np.testing.assert_allclose(d1, d_ref / 3.5, rtol=1e-12)
    with pytest.raises(ValueError, match="lr_decay_steps"):
        LearnerOptions(epsilon=1.0, gamma=0.01, lr_decay_steps=-1.0)


# ------------------------------------------------------------------ independent l_eps
def paper_loss(x_next, x, u, lcs, r, eps, gamma, Qd):
    """l_eps and (lam*, eta*) built by hand from the paper's formula (Algorithm 1):
    min over lam, eta >= 0 of 1/2 (D lam + z)' Qd (D lam + z)
    + (1/eps) (lam'eta + 1/(2 gamma) ||q + F lam + r - eta||^2), z = A x + B u + d - x+,
    q = E x + H u + c - solved by a generic bounded optimiser from several starts (the
    problem is convex for 0 < gamma < sigma_min(F + F')), not by the module's QP data."""
    from scipy.optimize import minimize
    m = lcs.num_lambda
    z = lcs.A @ x + lcs.B @ u + lcs.d - x_next
    q = lcs.E @ x + lcs.H @ u + lcs.c

    def scaled(y):        # eps * l_eps and its gradient, with y = [lam, eta]
        lam, eta = y[:m], y[m:]
        e = lcs.D @ lam + z
        w = q + lcs.F @ lam + r - eta
        f = 0.5 * eps * e @ Qd @ e + lam @ eta + w @ w / (2 * gamma)
        g_lam = eps * lcs.D.T @ (Qd @ e) + eta + lcs.F.T @ w / gamma
        g_eta = lam - w / gamma
        return f, np.concatenate([g_lam, g_eta])

    best = None
    rng = np.random.default_rng(0)
    for start in [np.zeros(2 * m), np.abs(np.r_[np.zeros(m), q + r])] + [
            rng.uniform(0, 1, 2 * m) for _ in range(4)]:
        res = minimize(scaled, start, jac=True, method="L-BFGS-B",
                       bounds=[(0, None)] * (2 * m),
                       options=dict(ftol=1e-16, gtol=1e-13, maxiter=20000))
        if best is None or res.fun < best.fun:
            best = res
    lam, eta = best.x[:m], best.x[m:]
    grad = (q + lcs.F @ lam + r - eta) / (eps * gamma)      # the paper's envelope gradient
    return best.fun / eps, grad


@pytest.mark.parametrize("seed", range(6))
def test_loss_and_gradient_match_the_papers_formula_built_by_hand(seed):
    rng = np.random.default_rng(100 + seed)
    for _ in range(50):        # a transition on which data and model disagree (loss > 0)
        m = int(rng.integers(1, 5))
        lcs = random_lcs(rng, int(rng.integers(2, 6)), 2, m)
        eps, gamma = 1e-2, 0.5 * valid_gamma(lcs)
        Qd = np.diag(rng.uniform(0.5, 5.0, lcs.num_states))
        x_next, x, u = random_transition(rng, lcs)
        r = 0.1 * rng.standard_normal(m)
        got_loss, got_grad = violation_loss(x_next, x, u, lcs, r, eps, gamma, Qd)
        if got_loss > 1e-3:
            break
    want_loss, want_grad = paper_loss(x_next, x, u, lcs, r, eps, gamma, Qd)
    assert want_loss > 1e-3
    assert _agrees((got_loss, got_grad), (want_loss, want_grad))
    # the check has teeth: broken inputs to the module (r off by 0.01, Qd doubled;
    # measured loss changes >= 3 %) do not pass it
    for r_bad, Qd_bad in ((r + 0.01, Qd), (r, 2 * Qd)):
        bad = violation_loss(x_next, x, u, lcs, r_bad, eps, gamma, Qd_bad)
        assert not _agrees(bad, (want_loss, want_grad))


def _agrees(got, want) -> bool:
    """Loss within 1e-6 relative, gradient within 1e-4 of its largest entry."""
    (gl, gg), (wl, wg) = got, want
    return bool(abs(gl - wl) <= 1e-6 * abs(wl)
                and np.abs(gg - wg).max() <= 1e-4 * np.abs(wg).max())
