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

# Null-space posture of the ball-rolling reference (DESIGN.md section 4).
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
