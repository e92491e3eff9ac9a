"""Cart-pole with two soft walls as an LCS (the paper's synthetic example).

State x = [cart_x (m), pole_theta (rad), cart_xdot (m/s), pole_thetadot (rad/s)],
input u = [cart_force (N)], lambda = [right (+x) wall force, left (-x) wall force] (N).
Numbers are those of the C3 authors' public cart-pole (DAIRLab/c3).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from adaptive_c3.systems.contact.lcs import Lcs

STATE_NAMES = ("cart_x", "pole_theta", "cart_xdot", "pole_thetadot")
INPUT_NAMES = ("cart_force",)
# lambda[0] acts when the pole tip x - l*theta passes +wall_distance (the wall on the
# +x side), lambda[1] when it passes -wall_distance (the wall on the -x side).
LAMBDA_NAMES = ("right_wall", "left_wall")


@dataclass(frozen=True)
class CartpoleParams:
    g: float = 9.81            # m/s^2
    mp: float = 0.411          # pole mass, kg
    mc: float = 0.978          # cart mass, kg
    length: float = 0.6        # pole length, m
    lc: float = 0.4267         # pole COM distance from the pivot, m
    wall_distance: float = 0.35  # walls at +-this, m
    wall_stiffness: float = 50.0  # ks, N/m per unit of F = 1/ks
    dt: float = 0.01           # s


def cartpole_lcs(params: CartpoleParams = CartpoleParams(),
                 wall_offset_error=(0.0, 0.0)) -> Lcs:
    """The cart-pole LCS.

    With wall_offset_error = delta_phi the returned *model* has
    c_hat = c_true - delta_phi (so the true c = c_hat + delta_phi, as in the paper);
    the default (0, 0) gives the true system.
    """
    p = params
    g, mp, mc, l, lc = p.g, p.mp, p.mc, p.length, p.lc
    Ac = np.array([[0, 0, 1, 0],
                   [0, 0, 0, 1],
                   [0, g * mp / mc, 0, 0],
                   [0, g * (mc + mp) / (lc * mc), 0, 0]], float)
    Bc = np.array([[0], [0], [1 / mc], [1 / (lc * mc)]], float)
    d_cart = -1 / mc + l / (mc * lc)
    d_pole = -1 / (mc * lc) + l * (mc + mp) / (mc * mp * lc * lc)
    Dc = np.array([[0, 0], [0, 0], [d_cart, -d_cart], [d_pole, -d_pole]], float)
    A = np.eye(4) + p.dt * Ac
    B = p.dt * Bc
    D = p.dt * Dc
    E = np.array([[-1, l, 0, 0], [1, -l, 0, 0]], float)
    F = np.eye(2) / p.wall_stiffness
    H = np.zeros((2, 1))
    c_true = np.array([p.wall_distance, p.wall_distance])
    c = c_true - np.asarray(wall_offset_error, float).reshape(2)
    return Lcs(A=A, B=B, D=D, d=np.zeros(4), E=E, F=F, H=H, c=c, dt=p.dt)
