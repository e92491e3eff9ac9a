"""Franka Emika Panda kinematics from its published modified (Craig) DH parameters.

Pure numpy, independent of Drake and of the URDF: the test compares the URDF loaded in a
MultibodyPlant against this. Parameters as in Franka's FCI documentation ("Robot and
interface specifications", Denavit-Hartenberg table), per row i (joint i):

    T_{i-1,i} = RotX(alpha_i) . TransX(a_i) . RotZ(theta_i) . TransZ(d_i)

Joint i rotates about the z axis of frame i. The flange (frame 8, `panda_link8` in the
URDF) is a fixed d = 0.107 m along z of frame 7. Lengths in m, angles in rad.
"""
from __future__ import annotations

import numpy as np

# (a, d, alpha) per joint 1..7, then the flange (theta fixed at 0).
DH_A = np.array([0.0, 0.0, 0.0, 0.0825, -0.0825, 0.0, 0.088, 0.0])
DH_D = np.array([0.333, 0.0, 0.316, 0.0, 0.384, 0.0, 0.0, 0.107])
DH_ALPHA = np.array([0.0, -np.pi / 2, np.pi / 2, np.pi / 2, -np.pi / 2,
                     np.pi / 2, np.pi / 2, 0.0])

# Published joint limits (FCI documentation), rad, rad/s, N m.
Q_MIN = np.array([-2.8973, -1.7628, -2.8973, -3.0718, -2.8973, -0.0175, -2.8973])
Q_MAX = np.array([2.8973, 1.7628, 2.8973, -0.0698, 2.8973, 3.7525, 2.8973])
V_MAX = np.array([2.1750, 2.1750, 2.1750, 2.1750, 2.6100, 2.6100, 2.6100])
TAU_MAX = np.array([87.0, 87.0, 87.0, 87.0, 12.0, 12.0, 12.0])

# Null-space posture of the ball-rolling reference system.
Q_NULL = np.array([0.0, 0.361, 0.0, -2.223, 0.0, 2.584, 0.0])

# The project's end-effector tool: a rod along the flange z axis ending in a sphere of
# radius EE_TIP_RADIUS whose centre (the frame `panda_ee_tip`) is EE_TIP_OFFSET below
# the flange (along flange +z). Must match models/panda.urdf.
EE_TIP_OFFSET = 0.12
EE_TIP_RADIUS = 0.0195


def mdh_transform(a: float, d: float, alpha: float, theta: float) -> np.ndarray:
    """4x4 homogeneous transform RotX(alpha) TransX(a) RotZ(theta) TransZ(d)."""
    ca, sa = np.cos(alpha), np.sin(alpha)
    ct, st = np.cos(theta), np.sin(theta)
    return np.array([
        [ct, -st, 0.0, a],
        [st * ca, ct * ca, -sa, -d * sa],
        [st * sa, ct * sa, ca, d * ca],
        [0.0, 0.0, 0.0, 1.0],
    ])


def link_transforms(q) -> list[np.ndarray]:
    """Poses X_0i (base to frame i) for i = 1..8 (8 = flange), as 4x4 arrays."""
    q = np.asarray(q, dtype=float).reshape(7)
    thetas = np.concatenate([q, [0.0]])
    X = np.eye(4)
    out = []
    for a, d, alpha, th in zip(DH_A, DH_D, DH_ALPHA, thetas):
        X = X @ mdh_transform(a, d, alpha, th)
        out.append(X.copy())
    return out


def flange_pose(q) -> np.ndarray:
    """4x4 pose of the flange frame in the base frame (link0)."""
    return link_transforms(q)[-1]


def tip_pose(q, tip_offset: float = EE_TIP_OFFSET) -> np.ndarray:
    """4x4 pose of the EE tip (sphere centre) in the base frame."""
    X = flange_pose(q).copy()
    X[:3, 3] = X[:3, 3] + X[:3, 2] * tip_offset
    return X


def tip_jacobian(q, tip_offset: float = EE_TIP_OFFSET) -> np.ndarray:
    """6 x 7 geometric Jacobian of the tip in the base frame, rows [angular; linear]."""
    Xs = link_transforms(q)
    p_tip = tip_pose(q, tip_offset)[:3, 3]
    J = np.zeros((6, 7))
    for i in range(7):
        z, o = Xs[i][:3, 2], Xs[i][:3, 3]      # joint i+1 axis and origin
        J[:3, i] = z
        J[3:, i] = np.cross(z, p_tip - o)
    return J


def solve_ik(p_des, R_des, q_guess=Q_NULL, tip_offset: float = EE_TIP_OFFSET,
             iters: int = 200, tol: float = 1e-10, damping: float = 1e-3):
    """Joint angles putting the tip at p_des (m) with orientation R_des (3x3), or None.

    Damped least squares from q_guess (the redundancy is resolved towards q_guess by
    a null-space pull), clamped to the joint limits. Returns None if the pose error
    does not fall below sqrt(tol) (position in m, orientation in rad).
    """
    q = np.asarray(q_guess, float).copy()
    q0 = q.copy()
    p_des = np.asarray(p_des, float)
    R_des = np.asarray(R_des, float)
    for _ in range(iters):
        X = tip_pose(q, tip_offset)
        dR = R_des @ X[:3, :3].T
        w = 0.5 * np.array([dR[2, 1] - dR[1, 2], dR[0, 2] - dR[2, 0], dR[1, 0] - dR[0, 1]])
        err = np.concatenate([w, p_des - X[:3, 3]])
        if err @ err < tol:
            return q
        J = tip_jacobian(q, tip_offset)
        JJt = J @ J.T + damping ** 2 * np.eye(6)
        dq = J.T @ np.linalg.solve(JJt, err)
        N = np.eye(7) - J.T @ np.linalg.solve(JJt, J)
        q = np.clip(q + dq + 0.1 * N @ (q0 - q), Q_MIN, Q_MAX)
    X = tip_pose(q, tip_offset)
    ok = (np.linalg.norm(X[:3, 3] - p_des) < np.sqrt(tol)
          and np.linalg.norm(R_des @ X[:3, :3].T - np.eye(3)) < np.sqrt(tol))
    return q if ok else None
