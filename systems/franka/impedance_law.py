"""Cartesian impedance law with null-space posture control (pure numpy core).

The law (all vectors in the world frame W, SI units):

    wrench F = [ K_r e_R - D_r w ;  K_t (p_d - p) + D_t (v_d - v) + f_ff ]
    tau      = J' F + N' (K_n (q_null - q) - D_n qdot) + C(q, qdot) qdot
    tau      = clip(tau, -tau_max, tau_max)

J (6 x 7) is the EE tip's spatial-velocity Jacobian with rows [angular; translational]
(Drake's order), w and v the tip's angular and translational velocity, e_R the rotation
vector of R_d R' (the rotation that takes the current EE orientation R to the desired
R_d). Like Franka's cartesian impedance example the task term is a plain J' F (no
operational-space inertia); the null-space projector is the dynamically consistent one,
N' = I - J' Lambda J M^-1 with Lambda = (J M^-1 J')^-1, so the posture term does not
disturb the EE. C(q, qdot) qdot (Coriolis/centripetal) is compensated; gravity is NOT:
the torque command means "without gravity", as a real Franka in torque mode expects.

Option `operational_space=True` replaces the feedback part of F by Lambda F_fb
(Lambda = task-space inertia; f_ff is still added unweighted): the gains then mean
per-unit-mass stiffness (1/s^2) and damping (1/s), and 500/45 gives a critically damped
EE in every direction. With the plain law (the reference's, the default) the Panda's
large reflected motor inertia makes the EE's apparent mass about 16 kg along x near
q_null, so K = 500 N/m, D = 45 N s/m is under-damped there (damping ratio ~0.25).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.linalg.lapack import dposv as posv

from adaptive_c3.models.panda_kinematics import Q_NULL, TAU_MAX  # rad, N m


@dataclass(frozen=True)
class ImpedanceGains:
    """The reference system's gains (its public Franka impedance controller)."""
    translational_stiffness: float = 500.0   # N/m
    translational_damping: float = 45.0      # N s/m
    rotational_stiffness: float = 900.0      # N m/rad
    rotational_damping: float = 20.0         # N m s/rad
    nullspace_stiffness: float = 4.0         # N m/rad
    nullspace_damping: float = 4.0           # N m s/rad
    torque_limits: np.ndarray = field(default_factory=lambda: TAU_MAX.copy())  # N m
    operational_space: bool = False          # True: feedback wrench weighted by Lambda


def axis_angle_matrix(axis, angle: float) -> np.ndarray:
    """Rotation matrix of `angle` (rad) about the unit vector along `axis`."""
    k = np.asarray(axis, float)
    k = k / np.linalg.norm(k)
    K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + np.sin(angle) * K + (1.0 - np.cos(angle)) * K @ K


EE_DOWN = np.diag([1.0, -1.0, -1.0])   # flange z down, x along W x (as at q_null)


def tilted_ee_rotation(tilt_deg: float = 15.0, lean_direction_xy=(-1.0, 0.0)) -> np.ndarray:
    """EE orientation R_WE with the tool axis leaning tilt_deg from vertical.

    The tool axis (flange +z, from the flange to the tip) becomes
    (sin t * d, -cos t) for the horizontal unit direction d = lean_direction_xy: the
    tip leans towards d, the flange away from it. tilt_deg = 0 gives EE_DOWN, the
    orientation the flange has at q_null. The reference experiment tilts the EE by 15
    degrees, away from the ball's desired direction of motion (so it changes with the
    plan; see the optional "ee.desired_orientation" input of ImpedanceController). The
    fixed default leans the tip towards the robot base (-x): at the circle about
    (0.55, 0) this keeps the wrist away from its limits and tracks about twice as well
    as leaning outwards.
    """
    d = np.array([lean_direction_xy[0], lean_direction_xy[1], 0.0], float)
    d = d / np.linalg.norm(d)
    axis = np.cross(d, [0.0, 0.0, 1.0])
    return axis_angle_matrix(axis, np.radians(tilt_deg)) @ EE_DOWN


def quaternion_to_rotation(q_wxyz) -> np.ndarray:
    """Rotation matrix of a (not necessarily normalised) quaternion [w, x, y, z]."""
    w, x, y, z = np.asarray(q_wxyz, float) / np.linalg.norm(q_wxyz)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


def rotation_vector(R: np.ndarray) -> np.ndarray:
    """Rotation vector (axis * angle, angle in [0, pi]) of a rotation matrix."""
    # scalar math on the 9 entries: this runs at 1 kHz, and numpy's per-call cost on
    # 3-vectors is most of the work
    (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = R.tolist()
    angle = math.acos(min(1.0, max(-1.0, (r00 + r11 + r22 - 1.0) / 2.0)))
    w = np.array([r21 - r12, r02 - r20, r10 - r01])
    if angle < 1e-6:
        return 0.5 * w                      # first order: R ~ I + [w]x
    if math.pi - angle < 1e-4:
        # Near pi: axis from the diagonal of (R + I) / 2 = a a'.
        B = (R + np.eye(3)) / 2.0
        i = int(np.argmax(np.diag(B)))
        axis = B[:, i] / np.sqrt(max(B[i, i], 1e-12))
        axis = axis / np.linalg.norm(axis)
        if axis @ w < 0:
            axis = -axis
        return angle * axis
    return (angle / (2.0 * math.sin(angle))) * w


def orientation_error(R_des: np.ndarray, R: np.ndarray) -> np.ndarray:
    """Rotation vector e_R (world frame) of R_des R': rotating R by e_R gives R_des."""
    return rotation_vector(R_des @ R.T)


def task_inertia(J: np.ndarray, M: np.ndarray, reg: float = 1e-8):
    """(Lambda, M^-1 J'): task-space inertia (J M^-1 J')^-1 (slightly regularised)."""
    # M and J M^-1 J' are symmetric positive definite: Cholesky solves (LAPACK posv
    # directly, a third of numpy.linalg.solve's call cost at this size)
    _, Minv_Jt, info = posv(M, J.T)
    if info != 0:
        return np.zeros(len(q))
    JMJ = J @ Minv_Jt
    JMJ[np.diag_indices_from(JMJ)] += reg
    return np.linalg.inv(JMJ), Minv_Jt


def nullspace_projector_transpose(J: np.ndarray, M: np.ndarray,
                                  reg: float = 1e-8) -> np.ndarray:
    """Dynamically consistent N' = I - J' Lambda J M^-1 (7 x 7)."""
    Lam, Minv_Jt = task_inertia(J, M, reg)
    # J M^-1 = (M^-1 J')' since M is symmetric.
    return np.eye(M.shape[0]) - J.T @ Lam @ Minv_Jt.T


def impedance_torque(*, J, M, p, R, q, v, p_des, v_des, R_des, f_ff=None,
                     q_null=Q_NULL, gains: ImpedanceGains = ImpedanceGains(),
                     coriolis=None) -> np.ndarray:
    """Joint torque command (7, N m, without gravity) of the impedance law above.

    J: 6x7 tip Jacobian [angular; translational] in W; M: 7x7 mass matrix; p (m), R:
    tip position and orientation in W; q (rad), v (rad/s): joint state; p_des (m),
    v_des (m/s): desired tip position/velocity in W; R_des: desired orientation;
    f_ff (N, W): feed-forward force added at the tip; coriolis: C(q, v) v (N m) or None.
    Returns zeros if any input is non-finite.
    """
    J, M, q, v = (np.asarray(a, float) for a in (J, M, q, v))
    p, R, p_des, v_des, R_des, q_null = (np.asarray(a, float)
                                         for a in (p, R, p_des, v_des, R_des, q_null))
    f_ff = _ZERO3 if f_ff is None else np.asarray(f_ff, float)
    parts = (J, M, p, R, q, v, p_des, v_des, R_des, f_ff, q_null)
    if coriolis is not None:
        coriolis = np.asarray(coriolis, float)
        parts += (coriolis,)
    # one finiteness check for all inputs (1 kHz budget; numpy's reductions cost about a
    # microsecond each): x'x is finite iff every entry is (NaN and inf propagate; only
    # entries beyond 1e154 would be refused too)
    flat = np.concatenate([a.ravel() for a in parts])
    if not math.isfinite(flat @ flat):
        return np.zeros(len(q))
    g = gains
    V = J @ v                                  # [w; v_tip]
    wrench = np.concatenate([g.rotational_stiffness * orientation_error(R_des, R)
                             - g.rotational_damping * V[:3],
                             g.translational_stiffness * (p_des - p)
                             + g.translational_damping * (v_des - V[3:])])
    # Lambda = (J M^-1 J')^-1 is only ever applied to vectors: solves, no inverse
    # M and J M^-1 J' are symmetric positive definite: Cholesky solves (LAPACK posv
    # directly, a third of numpy.linalg.solve's call cost at this size)
    _, Minv_Jt, info = posv(M, J.T)
    if info != 0:
        return np.zeros(len(q))
    JMJ = J @ Minv_Jt
    JMJ.flat[::JMJ.shape[0] + 1] += 1e-8       # the regularisation of task_inertia
    tau_posture = g.nullspace_stiffness * (q_null - q) - g.nullspace_damping * v
    y = tau_posture @ Minv_Jt                  # = J M^-1 tau_posture (M symmetric)
    _, both, info = posv(JMJ, np.column_stack([wrench, y]) if g.operational_space else y)
    if info != 0:
        return np.zeros(len(q))
    if g.operational_space:
        wrench, lam_y = both[:, 0].copy(), both[:, 1]
    else:
        lam_y = both
    wrench[3:] += f_ff
    # N' tau_posture = tau_posture - J' Lambda (J M^-1) tau_posture, without forming N'
    tau = (wrench - lam_y) @ J + tau_posture
    if coriolis is not None:
        tau += coriolis
    if not math.isfinite(tau.sum()):
        return np.zeros(len(q))
    lim = g.torque_limits
    return np.minimum(np.maximum(tau, -lim), lim)


_ZERO3 = np.zeros(3)
_ZERO3.setflags(write=False)
