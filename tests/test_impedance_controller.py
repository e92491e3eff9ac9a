"""Impedance controller: the pure law, and the closed loop on the simulated Panda.

Closed loop = arm plant (time_step 1 ms, SAP) + GravityCompensatedDriver +
ImpedanceController with the reference gains (the reference system's).
"""
import numpy as np
import pytest
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder, LeafSystem
from pydrake.systems.primitives import ConstantVectorSource, LogVectorOutput
from pydrake.multibody.plant import MultibodyPlant

from adaptive_c3.models.ball_rolling_scene import add_panda
from adaptive_c3.models.panda_kinematics import Q_NULL, TAU_MAX, solve_ik
from adaptive_c3.systems.franka.impedance_controller import ArmModel, ImpedanceController
from adaptive_c3.systems.franka.impedance_law import (ImpedanceGains, axis_angle_matrix,
                                               impedance_torque,
                                               nullspace_projector_transpose,
                                               orientation_error, tilted_ee_rotation)
from adaptive_c3.systems.franka.panda_sim_driver import GravityCompensatedDriver

GAINS = ImpedanceGains()


# ----------------------------------------------------------------- pure law
@pytest.fixture(scope="module")
def arm():
    return ArmModel()


def _terms(arm, q, v=np.zeros(7)):
    arm.set_state(q, v)
    p, R = arm.tip_pose()
    J = arm.tip_jacobian()
    M = arm.plant.CalcMassMatrix(arm.context)
    return p, R, J, M


def test_orientation_error_recovers_rotation_vector():
    rng = np.random.default_rng(0)
    R = axis_angle_matrix(rng.normal(size=3), 0.7)
    for angle in (1e-8, 0.3, 2.0, np.pi - 1e-6):
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        e = orientation_error(axis_angle_matrix(axis, angle) @ R, R)
        assert np.allclose(e, angle * axis, atol=1e-6)


def test_tilted_rotation_leans_tool_axis():
    R = tilted_ee_rotation(15.0, (0.0, 1.0))
    t = np.radians(15.0)
    assert np.allclose(R[:, 2], [0.0, np.sin(t), -np.cos(t)])
    assert np.isclose(np.linalg.det(R), 1.0)


def test_law_is_zero_at_the_desired_pose(arm):
    p, R, J, M = _terms(arm, Q_NULL)
    tau = impedance_torque(J=J, M=M, p=p, R=R, q=Q_NULL, v=np.zeros(7), p_des=p,
                           v_des=np.zeros(3), R_des=R, q_null=Q_NULL, gains=GAINS)
    assert np.allclose(tau, 0.0, atol=1e-9)


def test_law_feedforward_and_stiffness_map_through_jacobian(arm):
    q = Q_NULL + 0.05
    p, R, J, M = _terms(arm, q)
    base = dict(J=J, M=M, p=p, R=R, q=q, v=np.zeros(7), v_des=np.zeros(3), R_des=R,
                q_null=q, gains=GAINS)
    f = np.array([1.0, -2.0, 3.0])
    tau_ff = impedance_torque(p_des=p, f_ff=f, **base)
    assert np.allclose(tau_ff, J[3:].T @ f, atol=1e-9)
    dp = np.array([0.004, 0.0, -0.002])
    tau_k = impedance_torque(p_des=p + dp, **base)
    assert np.allclose(tau_k, J[3:].T @ (GAINS.translational_stiffness * dp), atol=1e-9)


def test_posture_term_is_dynamically_consistent(arm):
    rng = np.random.default_rng(1)
    q = Q_NULL + 0.1 * rng.normal(size=7)
    _, _, J, M = _terms(arm, q)
    tau0 = rng.normal(size=7)
    Nt = nullspace_projector_transpose(J, M)
    # The projected torque produces no EE acceleration: J M^-1 N' tau0 = 0.
    assert np.linalg.norm(J @ np.linalg.solve(M, Nt @ tau0)) < 1e-6 * np.linalg.norm(tau0)
    assert np.linalg.norm(Nt @ tau0) > 1e-3     # ... but is not zero itself


def test_law_clips_and_rejects_nonfinite(arm):
    p, R, J, M = _terms(arm, Q_NULL)
    kw = dict(J=J, M=M, p=p, R=R, q=Q_NULL, v=np.zeros(7), v_des=np.zeros(3),
              R_des=R, gains=GAINS)
    tau = impedance_torque(p_des=p + np.array([1.0, 1.0, -1.0]), **kw)
    assert np.all(np.abs(tau) <= TAU_MAX + 1e-12)
    assert np.any(np.isclose(np.abs(tau), TAU_MAX))
    bad = impedance_torque(p_des=np.array([np.nan, 0.0, 0.0]), **kw)
    assert np.array_equal(bad, np.zeros(7))


def test_leaf_system_nonfinite_input_gives_zero_torque():
    ctrl = ImpedanceController()
    ctx = ctrl.CreateDefaultContext()
    ctrl.GetInputPort("panda.state").FixValue(ctx, np.concatenate([Q_NULL, np.zeros(7)]))
    ctrl.GetInputPort("ee.desired_state").FixValue(ctx, [0.5, 0.0, np.inf, 0, 0, 0])
    out = ctrl.GetOutputPort("panda.torque_command").Eval(ctx)
    assert np.array_equal(out, np.zeros(7))
    # A finite target far away: nonzero but within the limits.
    ctrl.GetInputPort("ee.desired_state").FixValue(ctx, [0.3, 0.3, 0.3, 0, 0, 0])
    out = ctrl.GetOutputPort("panda.torque_command").Eval(ctx)
    assert np.any(out != 0) and np.all(np.abs(out) <= TAU_MAX + 1e-12)
    ee = ctrl.GetOutputPort("ee.state").Eval(ctx)
    assert np.allclose(ee[:3], [0.55, 0.0, 0.0903], atol=2e-4) and np.allclose(ee[3:], 0)


def test_leaf_system_orientation_input():
    ctrl = ImpedanceController()
    ctx = ctrl.CreateDefaultContext()
    ctrl.GetInputPort("panda.state").FixValue(ctx, np.concatenate([Q_NULL, np.zeros(7)]))
    tip = ctrl.GetOutputPort("ee.state").Eval(ctx)[:3]
    ctrl.GetInputPort("ee.desired_state").FixValue(ctx, np.concatenate([tip, np.zeros(3)]))
    tau_default = ctrl.GetOutputPort("panda.torque_command").Eval(ctx).copy()
    assert np.linalg.norm(tau_default) > 1.0          # 15 degrees from the default tilt
    # q_null's own orientation (flange straight down, quaternion of diag(1,-1,-1)).
    ctrl.GetInputPort("ee.desired_orientation").FixValue(ctx, [0.0, 1.0, 0.0, 0.0])
    tau = ctrl.GetOutputPort("panda.torque_command").Eval(ctx)
    assert np.allclose(tau, 0.0, atol=1e-8)
    ctrl.GetInputPort("ee.desired_orientation").FixValue(ctx, [0.0, 0.0, 0.0, 0.0])
    assert np.array_equal(ctrl.GetOutputPort("panda.torque_command").Eval(ctx), np.zeros(7))


# ------------------------------------------------------------- closed loop
class Circle(LeafSystem):
    """Desired tip state: hold (c + r x_hat, z) until t0, then a circle of period T
    whose angular speed ramps up linearly over the first second."""

    def __init__(self, center, radius, period, z, t0):
        super().__init__()
        self.c, self.r, self.w, self.z, self.t0 = center, radius, 2 * np.pi / period, z, t0
        self.DeclareVectorOutputPort("ee.desired_state", 6, self._calc)

    def _calc(self, context, out):
        s = max(context.get_time() - self.t0, 0.0)
        phase = self.w * (s * s / 2 if s < 1 else s - 0.5)
        rate = self.w * min(s, 1.0)
        c, r = self.c, self.r
        out.SetFromVector([c[0] + r * np.cos(phase), c[1] + r * np.sin(phase), self.z,
                           -r * rate * np.sin(phase), r * rate * np.cos(phase), 0.0])


def run_loop(source, t_final, q0=Q_NULL, f_ff=None, gains=GAINS):
    b = DiagramBuilder()
    plant = b.AddSystem(MultibodyPlant(1e-3))
    panda = add_panda(plant)
    plant.Finalize()
    ctrl = b.AddSystem(ImpedanceController(gains))
    drv = b.AddSystem(GravityCompensatedDriver())
    src = b.AddSystem(source)
    state = plant.get_state_output_port(panda)
    b.Connect(state, ctrl.GetInputPort("panda.state"))
    b.Connect(state, drv.GetInputPort("panda.state"))
    b.Connect(src.get_output_port(), ctrl.GetInputPort("ee.desired_state"))
    if f_ff is not None:
        ff = b.AddSystem(ConstantVectorSource(np.asarray(f_ff, float)))
        b.Connect(ff.get_output_port(), ctrl.GetInputPort("ee.feedforward_force"))
    b.Connect(ctrl.GetOutputPort("panda.torque_command"),
              drv.GetInputPort("panda.torque_command"))
    b.Connect(drv.GetOutputPort("panda.actuation"), plant.get_actuation_input_port(panda))
    logs = {name: LogVectorOutput(port, b, 1e-3) for name, port in [
        ("tau", ctrl.GetOutputPort("panda.torque_command")),
        ("ee", ctrl.GetOutputPort("ee.state")),
        ("des", src.get_output_port())]}
    diagram = b.Build()
    sim = Simulator(diagram)
    ctx = sim.get_mutable_context()
    plant.SetPositions(plant.GetMyMutableContextFromRoot(ctx), q0)
    sim.AdvanceTo(t_final)
    out = {k: v.FindLog(ctx).data() for k, v in logs.items()}
    out["t"] = logs["ee"].FindLog(ctx).sample_times()
    return out


def test_gravity_compensated_arm_holds_still_with_zero_command():
    b = DiagramBuilder()
    plant = b.AddSystem(MultibodyPlant(1e-3))
    panda = add_panda(plant)
    plant.Finalize()
    drv = b.AddSystem(GravityCompensatedDriver())
    zero = b.AddSystem(ConstantVectorSource(np.zeros(7)))
    b.Connect(zero.get_output_port(), drv.GetInputPort("panda.torque_command"))
    b.Connect(plant.get_state_output_port(panda), drv.GetInputPort("panda.state"))
    b.Connect(drv.GetOutputPort("panda.actuation"), plant.get_actuation_input_port(panda))
    sim = Simulator(b.Build())
    pctx = plant.GetMyMutableContextFromRoot(sim.get_mutable_context())
    q0 = Q_NULL + np.array([0.2, -0.1, 0.1, 0.2, -0.3, 0.1, 0.4])
    plant.SetPositions(pctx, q0)
    sim.AdvanceTo(1.0)
    assert np.max(np.abs(plant.GetPositions(pctx) - q0)) < 1e-4
    # The compensation is far from zero (a zero-torque arm would fall).
    assert np.linalg.norm(drv.gravity_compensation(q0)) > 5.0


# Start of the closed-loop runs: tip at rest at (0.55, 0, 0.09) with the default
# (15 degree) orientation, from the independent numpy IK.
Q_START = solve_ik([0.55, 0.0, 0.09], tilted_ee_rotation(15.0))


def _error(res, target):
    """Tip position error (m) per sample; target (6,) or logged (6, T)."""
    target = np.asarray(target)
    ref = target[:3, None] if target.ndim == 1 else target[:3]
    return np.linalg.norm(res["ee"][:3] - ref, axis=0)


def test_tip_converges_to_setpoint():
    target = np.array([0.565, 0.012, 0.08, 0.0, 0.0, 0.0])      # a 2.2 cm step
    res = run_loop(ConstantVectorSource(target), 2.5, q0=Q_START)
    err = _error(res, target)
    print(f"set-point (2.2 cm step): {1000 * err[999]:.2f} mm at 1 s, "
          f"{1000 * err[1999]:.2f} mm at 2 s, {1000 * err[-1]:.2f} mm at 2.5 s, "
          f"peak after 0.3 s {1000 * err[300:].max():.1f} mm")
    assert err[0] > 0.02
    assert err[-1] < 2e-3
    assert np.all(np.abs(res["tau"]) <= TAU_MAX[:, None] + 1e-9)


def test_tip_converges_from_q_null_despite_orientation_transient():
    # q_null holds the flange vertical: a 15 degree orientation error at the start
    # saturates the wrist torques; the EE still settles.
    target = np.array([0.57, 0.02, 0.08, 0.0, 0.0, 0.0])
    res = run_loop(ConstantVectorSource(target), 5.0, q0=Q_NULL)
    err = _error(res, target)
    print(f"from q_null: {1000 * err[1999]:.2f} mm at 2 s, {1000 * err[-1]:.2f} mm at 5 s")
    assert np.any(np.isclose(np.abs(res["tau"][4:]), 12.0))       # wrist saturated
    assert np.all(np.abs(res["tau"]) <= TAU_MAX[:, None] + 1e-9)
    assert err[-1] < 2e-3


def test_tip_tracks_slow_circle():
    # Circle of radius 0.1 m about (0.55, 0) at z = 0.08 m, period 8 s (0.079 m/s).
    q0 = solve_ik([0.65, 0.0, 0.08], tilted_ee_rotation(15.0))
    res = run_loop(Circle((0.55, 0.0), 0.1, 8.0, 0.08, t0=0.5), 0.5 + 1.0 + 8.0, q0=q0)
    err = _error(res, res["des"])
    lap = res["t"] > 1.5                        # one full lap after the speed ramp
    rms, worst = np.sqrt(np.mean(err[lap] ** 2)), err[lap].max()
    print(f"circle T=8 s: rms {1000 * rms:.2f} mm, max {1000 * worst:.2f} mm")
    assert rms < 4e-3 and worst < 8e-3
    assert np.all(np.abs(res["tau"]) <= TAU_MAX[:, None] + 1e-9)


def test_operational_space_option_tracks_faster_circle_tightly():
    gains = ImpedanceGains(operational_space=True)
    q0 = solve_ik([0.65, 0.0, 0.08], tilted_ee_rotation(15.0))
    res = run_loop(Circle((0.55, 0.0), 0.1, 4.0, 0.08, t0=0.5), 0.5 + 1.0 + 4.0, q0=q0,
                   gains=gains)
    err = _error(res, res["des"])
    lap = res["t"] > 1.5
    worst = err[lap].max()
    print(f"circle T=4 s, operational-space gains: max {1000 * worst:.2f} mm")
    assert worst < 2e-3
    assert np.all(np.abs(res["tau"]) <= TAU_MAX[:, None] + 1e-9)


def test_feedforward_force_shifts_equilibrium_by_f_over_k():
    # Free space, static target: K (p_des - p) + f_ff = 0  =>  p = p_des + f_ff / K.
    target = np.array([0.55, 0.0, 0.09, 0.0, 0.0, 0.0])
    f = np.array([0.0, 0.0, -5.0])
    res = run_loop(ConstantVectorSource(target), 3.0, q0=Q_START, f_ff=f)
    shift = res["ee"][:3, -1] - target[:3]
    expected = f / GAINS.translational_stiffness       # 1 cm down
    print(f"feed-forward shift {1000 * shift} mm, expected {1000 * expected} mm")
    assert np.linalg.norm(shift - expected) < 1e-3
