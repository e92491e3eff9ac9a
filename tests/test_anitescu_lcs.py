"""Anitescu LCS from a MultibodyPlant (issue 5).

The one-step predictions are checked against Drake's own simulation of the same plant:
a discrete MultibodyPlant with SAP and point contact, stiff (k = 1e6 N/m, so the static
penetration m g / k is about 1.3 µm) and finely stepped (h = 1e-4 s, integrated up to
the LCS step dt). Tolerances, and why:
- positions: the LCS is symplectic Euler (q_{k+1} = q_k + dt N v_{k+1}) while the fine
  simulation integrates v(t) over the step; they differ by about ½ dt |Δv| per body
  (exactly ½ g dt² in free flight). Tolerance: ½ dt |Δv_sap| + 30 µm (compliance).
- quaternion: the LCS updates it linearly, q + dt N(q*) ω; that leaves out the
  second-order term (|ω| dt)²/8 and, as for positions, ½ dt |Δω| of rotation angle.
  Tolerance on ‖Δq‖: (|ω| dt)²/4 + ½ dt |Δω| + 1e-5.
- velocities: SAP is compliant and regularises friction (stiction tolerance 1e-4 m/s);
  the Anitescu LCS is rigid with ε_c λ regularisation. Tolerance 3 mm/s on linear
  velocities and 0.03 rad/s on the ball's angular velocity (1 mm/s at its surface).
- impact step (ball falling onto the table): the LCS velocity is the mean velocity that
  lands the ball exactly on the table at the end of the step (−φ/dt), the simulation's
  is the post-impact velocity, so only positions are compared after step 1; after a
  second step (re-linearised) velocities must agree too.
"""
from __future__ import annotations

import numpy as np
import pytest
from pydrake.all import (AddMultibodyPlantSceneGraph, Box, ConstantVectorSource,
                         CoulombFriction, DiagramBuilder, RevoluteJoint, RigidTransform,
                         Simulator, SpatialInertia, Sphere, UnitInertia)

from adaptive_c3.models.ball_rolling_controller_model import (
    BALL_ANGVEL, BALL_POS, BALL_QUAT, BALL_VEL, EE_POS, EE_VEL, INPUT_NAMES, STATE_NAMES,
    ball_rolling_linearizer, build_controller_plant, default_state)
from adaptive_c3.systems.contact.anitescu_lcs import AnitescuLinearizer, ContactPair
from adaptive_c3.systems.contact.anitescu_lcs_system import AnitescuLcsSystem

R_BALL, M_EE, G = 0.0315, 0.01, 9.81
U_HOLD = np.array([0.0, 0.0, M_EE * G])  # EE gravity compensation, N
SAP_H, SAP_K = 1e-4, 1e6


@pytest.fixture(scope="module")
def sap_model():
    return build_controller_plant(time_step=SAP_H, point_stiffness=SAP_K)


@pytest.fixture(scope="module")
def lin01():
    return ball_rolling_linearizer(dt=0.01)


def sap_states(model, x, u, times):
    """Drake's SAP simulation of the same plant from x under constant u, at `times`."""
    sim = Simulator(model.diagram)
    plant = model.plant
    ctx = plant.GetMyMutableContextFromRoot(sim.get_mutable_context())
    plant.SetPositionsAndVelocities(ctx, x)
    plant.get_actuation_input_port().FixValue(ctx, u)
    out = []
    for t in times:
        sim.AdvanceTo(t)
        out.append(np.array(plant.GetPositionsAndVelocities(ctx)))
    return out


def check_prediction(x0, x_lcs, x_sap, dt, check_velocity=True):
    """Compare one LCS step with the SAP state; returns the errors (see module doc)."""
    err = {}
    for name, pos, vel in (("ee", EE_POS, EE_VEL), ("ball", BALL_POS, BALL_VEL)):
        tol = 0.5 * dt * np.linalg.norm(x_sap[vel] - x0[vel]) + 30e-6
        err[name + "_pos"] = np.abs(x_lcs[pos] - x_sap[pos]).max()
        assert err[name + "_pos"] <= tol, (name, err[name + "_pos"], tol)
        if check_velocity:
            err[name + "_vel"] = np.abs(x_lcs[vel] - x_sap[vel]).max()
            assert err[name + "_vel"] <= 3e-3, (name, err[name + "_vel"])
    w0, w1 = x0[BALL_ANGVEL], x_sap[BALL_ANGVEL]
    q_tol = (np.linalg.norm(w0) * dt) ** 2 / 4 + 0.5 * dt * np.linalg.norm(w1 - w0) + 1e-5
    err["quat"] = np.linalg.norm(x_lcs[BALL_QUAT] - x_sap[BALL_QUAT])
    assert err["quat"] <= q_tol, (err["quat"], q_tol)
    if check_velocity:
        err["ball_angvel"] = np.abs(x_lcs[BALL_ANGVEL] - w1).max()
        assert err["ball_angvel"] <= 0.03, err["ball_angvel"]
    return err


# ---------------------------------------------------------------- the model
def test_state_and_input_order_match_design():
    model = build_controller_plant()
    plant = model.plant
    assert tuple(plant.GetStateNames(False)) == STATE_NAMES
    assert len(STATE_NAMES) == 19
    actuators = [plant.get_joint_actuator(i).name() for i in plant.GetJointActuatorIndices()]
    assert tuple(actuators) == INPUT_NAMES
    B = plant.MakeActuationMatrix()
    np.testing.assert_array_equal(B[:3], np.eye(3))
    np.testing.assert_array_equal(B[3:], 0.0)
    assert [p.name for p in model.contact_pairs] == ["ee_ball", "ball_table"]


def test_sizes_names_and_contact_geometry(lin01):
    x = default_state()
    terms = lin01.linearize_terms(x, U_HOLD)
    lcs = terms.lcs
    assert (lcs.num_states, lcs.num_inputs, lcs.num_lambda) == (19, 3, 8)
    assert lcs.dt == 0.01
    assert lin01.lambda_names() == [f"{p}/{e}" for p in ("ee_ball", "ball_table")
                                    for e in ("+t1", "+t2", "-t1", "-t2")]
    np.testing.assert_allclose(terms.phi, [0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(terms.normals, [[-1, 0, 0], [0, 0, 1]], atol=1e-12)
    # ball sliding along +x without rotation: table-contact slip +0.2 m/s along t1 = x
    v = np.zeros(9)
    v[6] = 0.2
    np.testing.assert_allclose(terms.J_t[4:] @ v, [0.2, 0, -0.2, 0], atol=1e-12)
    # rolling without slip (ω_y = v/r): zero slip at the table
    v[4] = 0.2 / R_BALL
    np.testing.assert_allclose(terms.J_t[4:] @ v, 0.0, atol=1e-12)
    np.testing.assert_allclose(terms.J_n[1] @ v, 0.0, atol=1e-12)


@pytest.mark.parametrize("where", ["contact", "apart", "tilted"])
def test_F_is_symmetric_positive_definite(where):
    eps_c = 1e-2
    lin = ball_rolling_linearizer(dt=0.1, eps_c=eps_c)
    x = default_state()
    if where == "apart":
        x = default_state(ee_offset=(-0.2, 0.1, 0.1))
        x[BALL_POS.start + 2] += 0.05
    elif where == "tilted":
        x = default_state(ee_offset=(-0.04, 0.02, 0.02))
        x[BALL_QUAT] = np.array([0.9, 0.1, -0.3, 0.2]) / np.linalg.norm([0.9, 0.1, -0.3, 0.2])
    F = lin.linearize(x, U_HOLD).F
    np.testing.assert_allclose(F, F.T, atol=1e-12)
    eig = np.linalg.eigvalsh(F)
    assert eig.min() >= eps_c * (1 - 1e-9)
    # Anitescu's J_c M⁻¹ J_cᵀ has rank <= 3 per contact: ε_c is exactly the floor
    assert eig.min() == pytest.approx(eps_c, rel=1e-6)


def test_lcs_is_the_anitescu_step(lin01):
    """A, B, D, d, E, F, H, c reproduce the paper's equations from the terms."""
    rng = np.random.default_rng(0)
    x_star = default_state()
    x_star[10:] = rng.normal(0, 0.1, 9)
    u_star = np.array([0.3, -0.1, 0.2])
    t = lin01.linearize_terms(x_star, u_star)
    lcs, dt, nq = t.lcs, 0.01, 10
    E_t = np.kron(np.eye(2), np.ones((1, 4)))
    for _ in range(3):
        x = x_star + rng.normal(0, 1e-3, 19)
        u = u_star + rng.normal(0, 0.1, 3)
        lam = np.abs(rng.normal(0, 0.01, 8))
        xu = np.concatenate([x, u])
        xu_star = np.concatenate([x_star, u_star])
        v_next = x[nq:] + dt * (t.f + t.J_f @ (xu - xu_star)) + np.linalg.solve(t.M, t.J_c.T @ lam)
        q_next = x[:nq] + dt * t.N @ v_next
        np.testing.assert_allclose(lcs.A @ x + lcs.B @ u + lcs.D @ lam + lcs.d,
                                   np.concatenate([q_next, v_next]), atol=1e-10)
        w = (E_t.T @ (t.phi + t.J_n @ t.N_plus @ (x[:nq] - x_star[:nq])) / dt
             + t.J_c @ v_next + 1e-2 * lam)
        np.testing.assert_allclose(lcs.E @ x + lcs.F @ lam + lcs.H @ u + lcs.c, w,
                                   atol=1e-9)


# ---------------------------------------------------------------- against Drake
def _free_ee():
    return default_state(ee_offset=(-0.1, 0.0, 0.05))


def test_a_ball_at_rest_on_table(lin01, sap_model):
    x = _free_ee()
    x_lcs, lam = lin01.linearize(x, U_HOLD).step(x, U_HOLD)
    (x_sap,) = sap_states(sap_model, x, U_HOLD, [0.01])
    np.testing.assert_array_equal(lam[:4], 0.0)  # EE is 5 cm away from the ball
    # the table carries the ball's weight: total normal impulse m g dt over 4 edges
    assert lam[4:].sum() == pytest.approx(0.132 * G * 0.01, rel=1e-3)
    err = check_prediction(x, x_lcs, x_sap, 0.01)
    assert err["ball_vel"] < 1e-4  # both stay at rest


def test_b_ball_pushed_sideways_by_ee(lin01, sap_model):
    x = default_state()          # EE touching the ball from -x at the ball's centre height
    x[EE_VEL.start] = x[BALL_VEL.start] = 0.05
    x[BALL_ANGVEL.start + 1] = 0.05 / R_BALL
    u = U_HOLD + np.array([0.5, 0.0, 0.0])  # 0.5 N toward the ball
    x_lcs, lam = lin01.linearize(x, u).step(x, u)
    (x_sap,) = sap_states(sap_model, x, u, [0.01])
    assert lam[:4].sum() > 0 and lam[4:].sum() > 0
    # the ball rolls forward; at most as fast as if the push drove the rolling ball
    # alone (friction at the EE also drags the light EE upward along the ball)
    dv = x_lcs[BALL_VEL.start] - 0.05
    assert 0 < dv < 0.5 * 0.01 / (M_EE + 1.4 * 0.132)
    assert x_lcs[BALL_ANGVEL.start + 1] == pytest.approx(x_lcs[BALL_VEL.start] / R_BALL,
                                                         rel=1e-3)
    check_prediction(x, x_lcs, x_sap, 0.01)


@pytest.mark.parametrize("dt", [0.01, 0.1])
def test_c_ball_rolling_freely(dt, sap_model):
    lin = ball_rolling_linearizer(dt=dt)
    x = _free_ee()
    quat = np.array([0.8, 0.2, -0.4, 0.4])
    x[BALL_QUAT] = quat / np.linalg.norm(quat)  # exercise N(q) away from identity
    v = np.array([0.2, -0.1, 0.0])
    x[BALL_VEL] = v
    x[BALL_ANGVEL] = np.cross([0, 0, 1], v) / R_BALL  # ω = n × v / r: no slip
    x_lcs, lam = lin.linearize(x, U_HOLD).step(x, U_HOLD)
    (x_sap,) = sap_states(sap_model, x, U_HOLD, [dt])
    np.testing.assert_array_equal(lam[:4], 0.0)
    check_prediction(x, x_lcs, x_sap, dt)
    # velocity kept; the ball sinks at ε_c λ (3e-4 m/s at dt = 0.1), the regulariser
    np.testing.assert_allclose(x_lcs[BALL_VEL], v, atol=1e-3 * dt / 0.1)


def test_d_ball_falling_onto_table(lin01, sap_model):
    x = _free_ee()
    x[BALL_POS.start + 2] += 1e-3          # 1 mm above the table ...
    x[BALL_VEL.start + 2] = -0.3           # ... falling at 0.3 m/s: lands mid-step
    x1, lam0 = lin01.linearize(x, U_HOLD).step(x, U_HOLD)
    x_sap1, x_sap2 = sap_states(sap_model, x, U_HOLD, [0.01, 0.02])
    assert lam0[4:].sum() > 0
    check_prediction(x, x1, x_sap1, 0.01, check_velocity=False)
    assert x1[BALL_VEL.start + 2] == pytest.approx(-1e-3 / 0.01, abs=1e-3)  # -φ/dt
    x2, _ = lin01.linearize(x1, U_HOLD).step(x1, U_HOLD)
    check_prediction(x1, x2, x_sap2, 0.01)
    assert abs(x2[BALL_VEL.start + 2]) < 1e-3 and abs(x_sap2[BALL_VEL.start + 2]) < 1e-3


def test_no_contact_gives_zero_lambda(lin01, sap_model):
    x = default_state(ee_offset=(-0.2, 0.0, 0.1))
    x[BALL_POS.start + 2] += 0.05
    x[BALL_VEL] = [0.1, 0.0, 0.2]
    x[BALL_ANGVEL] = [0.0, 3.0, 0.0]
    x_lcs, lam = lin01.linearize(x, U_HOLD).step(x, U_HOLD)
    np.testing.assert_array_equal(lam, 0.0)
    (x_sap,) = sap_states(sap_model, x, U_HOLD, [0.01])
    check_prediction(x, x_lcs, x_sap, 0.01)
    # free flight: the LCS step (symplectic Euler) lies ½ g dt² below the parabola, the
    # simulation (symplectic Euler at h) ½ g h dt below it
    assert x_sap[BALL_POS.start + 2] - x_lcs[BALL_POS.start + 2] == pytest.approx(
        0.5 * G * 0.01 * (0.01 - SAP_H), rel=1e-6)


# ---------------------------------------------------------------- J_f by AutoDiff
def _test_plant():
    """A pendulum with a tip sphere, a free body with anisotropic inertia, a ground box."""
    builder = DiagramBuilder()
    plant, _ = AddMultibodyPlantSceneGraph(builder, 0.0)
    link = plant.AddRigidBody("link", SpatialInertia.MakeFromCentralInertia(
        0.7, [0.0, 0.0, -0.25], 0.7 * UnitInertia.SolidBox(0.05, 0.05, 0.5)))
    joint = plant.AddJoint(RevoluteJoint("pin", plant.world_frame(), link.body_frame(),
                                         [0.0, 1.0, 0.0]))
    plant.AddJointActuator("pin_torque", joint)
    box = plant.AddRigidBody("box", SpatialInertia.MakeFromCentralInertia(
        0.4, [0.01, -0.02, 0.0], 0.4 * UnitInertia.SolidBox(0.1, 0.2, 0.3)))
    friction = CoulombFriction(0.5, 0.5)
    tip = plant.RegisterCollisionGeometry(link, RigidTransform([0, 0, -0.5]), Sphere(0.05),
                                          "tip", friction)
    ball = plant.RegisterCollisionGeometry(box, RigidTransform(), Sphere(0.08), "box_ball",
                                           friction)
    ground = plant.RegisterCollisionGeometry(plant.world_body(), RigidTransform([0, 0, -1.05]),
                                             Box(3, 3, 0.1), "ground", friction)
    plant.Finalize()
    diagram = builder.Build()
    pairs = [ContactPair("tip_ground", tip, ground, 0.5),
             ContactPair("box_ground", "box_ball", "ground", 0.8),
             ContactPair("tip_box", "link", "box", 0.3)]
    return diagram, plant, pairs


def _continuous_f(plant, ctx, x, u):
    plant.SetPositionsAndVelocities(ctx, x)
    tau = plant.MakeActuationMatrix() @ u + plant.CalcGravityGeneralizedForces(ctx) \
        - plant.CalcBiasTerm(ctx)
    return np.linalg.solve(plant.CalcMassMatrix(ctx), tau)


def test_J_f_matches_central_differences():
    diagram, plant, pairs = _test_plant()
    lin = AnitescuLinearizer(diagram, plant, pairs, num_edges=6, dt=0.05, eps_c=1e-3)
    assert lin.num_lambda == 18 and lin.lambda_names()[6] == "box_ground/edge0"
    rng = np.random.default_rng(1)
    quat = rng.normal(size=4)
    q = np.concatenate([[0.4], quat / np.linalg.norm(quat), [0.3, -0.2, -0.5]])
    x = np.concatenate([q, rng.normal(0, 1.0, 7)])
    u = np.array([0.7])
    f, J_f, M, _ = lin.smooth_dynamics(x, u)
    ctx = plant.CreateDefaultContext()
    np.testing.assert_allclose(f, _continuous_f(plant, ctx, x, u), atol=1e-10)
    h = 1e-6
    J_fd = np.empty_like(J_f)
    xu = np.concatenate([x, u])
    for i in range(xu.size):
        p, m = xu.copy(), xu.copy()
        p[i] += h
        m[i] -= h
        J_fd[:, i] = (_continuous_f(plant, ctx, p[:-1], p[-1:])
                      - _continuous_f(plant, ctx, m[:-1], m[-1:])) / (2 * h)
    assert np.abs(J_f).max() > 1.0  # nontrivial: gyroscopic and pendulum terms
    np.testing.assert_allclose(J_f, J_fd, atol=1e-6 * max(1.0, np.abs(J_fd).max()))


def test_normal_jacobian_matches_distance_differences():
    diagram, plant, pairs = _test_plant()
    lin = AnitescuLinearizer(diagram, plant, pairs, num_edges=4, dt=0.05)
    x = np.concatenate([[0.3, 1, 0, 0, 0, 0.35, 0.1, -0.6], np.zeros(7)])
    phi, J_n, _, _ = lin.contact_geometry(x)
    assert np.all(phi > 0)
    ctx = plant.CreateDefaultContext()
    plant.SetPositions(ctx, x[:8])
    N = plant.MakeVelocityToQDotMap(ctx).toarray()
    h = 1e-6
    for k in range(7):
        dv = np.zeros(7)
        dv[k] = 1.0
        xp, xm = x.copy(), x.copy()
        xp[:8] += h * N @ dv
        xm[:8] -= h * N @ dv
        dphi = (lin.contact_geometry(xp)[0] - lin.contact_geometry(xm)[0]) / (2 * h)
        np.testing.assert_allclose(J_n[:, k], dphi, atol=1e-6)


# ---------------------------------------------------------------- errors, system
def test_bad_arguments_are_refused():
    model = build_controller_plant()
    with pytest.raises(ValueError, match="eps_c"):
        AnitescuLinearizer(model.diagram, model.plant, model.contact_pairs, eps_c=0.0)
    with pytest.raises(ValueError, match="dt"):
        AnitescuLinearizer(model.diagram, model.plant, model.contact_pairs, dt=-1.0)
    with pytest.raises(ValueError, match="no collision geometry"):
        AnitescuLinearizer(model.diagram, model.plant, [("x", "nope", "ball", 1.0)])
    lin = AnitescuLinearizer(model.diagram, model.plant, model.contact_pairs)
    with pytest.raises(ValueError, match="19 states"):
        lin.linearize(np.zeros(18), np.zeros(3))
    with pytest.raises(ValueError):
        build_controller_plant(ball_radius=-0.01)


def test_lcs_system_ports_and_rate():
    lin = ball_rolling_linearizer(dt=0.1)
    builder = DiagramBuilder()
    system = builder.AddSystem(AnitescuLcsSystem(lin, update_rate_hz=50.0))
    x = default_state()
    x[BALL_VEL.start] = 0.1
    source = builder.AddSystem(ConstantVectorSource(x))
    builder.Connect(source.get_output_port(), system.GetInputPort("state"))
    diagram = builder.Build()
    sim = Simulator(diagram)
    sim.Initialize()
    ctx = system.GetMyContextFromRoot(sim.get_context())
    assert system.update_period == pytest.approx(0.02)
    names = system.GetOutputPort("contact_names").Eval(ctx)
    assert names == system.lambda_names() == lin.lambda_names() and len(names) == 8
    lcs0 = system.GetOutputPort("lcs").Eval(ctx)  # valid at t = 0 (initialisation)
    expected = lin.linearize(x, np.zeros(3))   # "input" unconnected: u = 0
    np.testing.assert_allclose(lcs0.c, expected.c)
    np.testing.assert_allclose(lcs0.A, expected.A)
    sim.AdvanceTo(0.05)
    lcs1 = system.GetOutputPort("lcs").Eval(ctx)
    np.testing.assert_allclose(lcs1.E, expected.E)
    assert lcs1.dt == 0.1
