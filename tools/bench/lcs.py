"""`adaptive-c3 bench lcs`: time to produce the ball-rolling Anitescu LCS θ*.

Rows
  lcs/ballroll          AnitescuLinearizer.linearize at a contact state (EE touching
                        the ball, ball on the table): one AutoDiff pass of M and the
                        bias term, two signed-distance pairs with Jacobians, assembly.
  lcs/ballroll/numdiff  the straightforward way, measured in the same run: J_f by
                        central finite differences of the double plant's dynamics
                        (2 (n_x + n_u) evaluations of M, C and τ_g), same geometry and
                        assembly. lcs/ballroll carries baseline/speedup against it.
"""
from __future__ import annotations

import time

import numpy as np

from adaptive_c3.models.ball_rolling_controller_model import (
    build_controller_plant, default_state)
from adaptive_c3.systems.contact.anitescu_lcs import AnitescuLinearizer


class NumDiffLinearizer(AnitescuLinearizer):
    """The same linearizer with J_f from central differences of the double plant."""

    def __init__(self, *args, step: float = 1e-6, **kwargs):
        super().__init__(*args, **kwargs)
        self._step = float(step)

    def _f(self, x, u):
        plant, ctx = self.plant, self._plant_context
        plant.SetPositionsAndVelocities(ctx, x)
        M = plant.CalcMassMatrix(ctx)
        tau = self._B_act @ u + plant.CalcGravityGeneralizedForces(ctx) \
            - plant.CalcBiasTerm(ctx)
        return np.linalg.solve(M, tau), M

    def smooth_dynamics(self, x, u):
        x, u = self._check(x, u)
        nx, h = self.nx, self._step
        f, M = self._f(x, u)
        J_f = np.empty((self.nv, nx + self.nu))
        for i in range(nx):
            xp, xm = x.copy(), x.copy()
            xp[i] += h
            xm[i] -= h
            J_f[:, i] = (self._f(xp, u)[0] - self._f(xm, u)[0]) / (2 * h)
        for j in range(self.nu):
            up, um = u.copy(), u.copy()
            up[j] += h
            um[j] -= h
            J_f[:, nx + j] = (self._f(x, up)[0] - self._f(x, um)[0]) / (2 * h)
        M_inv = np.linalg.inv(M)
        return f, J_f, M, 0.5 * (M_inv + M_inv.T)


def _median_ms(fn, repeats: int, warmup: int = 20) -> float:
    for _ in range(warmup):
        fn()
    times = np.empty(repeats)
    for k in range(repeats):
        t0 = time.perf_counter()
        fn()
        times[k] = time.perf_counter() - t0
    return float(np.median(times) * 1e3)


def run_bench(quick: bool = False) -> list[dict]:
    model = build_controller_plant(time_step=0.0)
    kwargs = dict(num_edges=4, dt=0.1, eps_c=1e-2)
    fast = AnitescuLinearizer(model.diagram, model.plant, model.contact_pairs, **kwargs)
    slow = NumDiffLinearizer(model.diagram, model.plant, model.contact_pairs, **kwargs)
    x = default_state()            # EE touching the ball, ball resting on the table
    x[10], x[16], x[14] = 0.05, 0.05, 0.05 / 0.0315
    u = np.array([0.5, 0.0, 0.01 * 9.81])
    agree = float(np.max(np.abs(fast.linearize(x, u).A - slow.linearize(x, u).A)))
    n = 300 if quick else 3000
    t_fast = _median_ms(lambda: fast.linearize(x, u), n)
    t_slow = _median_ms(lambda: slow.linearize(x, u), max(n // 5, 50))
    t_ad = _median_ms(lambda: fast.smooth_dynamics(x, u), n)
    t_geom = _median_ms(lambda: fast.contact_geometry(x), n)
    return [
        {"name": "lcs/ballroll", "median_ms": t_fast, "baseline": "lcs/ballroll/numdiff",
         "speedup": t_slow / t_fast, "n_x": fast.nx, "n_lambda": fast.num_lambda,
         "autodiff_dynamics_ms": t_ad, "contact_geometry_ms": t_geom,
         "max_abs_A_diff_vs_numdiff": agree},
        {"name": "lcs/ballroll/numdiff", "median_ms": t_slow},
    ]


if __name__ == "__main__":
    for row in run_bench(quick=True):
        print(row)
