"""Benchmark of the residual learner's update: `run_bench(quick)` -> rows for `bench learner`.

One *update* = prepare one fresh transition, solve the violation-loss QP of each of the
n_b = 10 transitions in the ring buffer at the current r (exact block pivoting,
warm-started), average loss and gradient, one Adam step. The baseline row does the same
update but solves every per-sample QP with a generic call through Drake's
MathematicalProgram (AddQuadraticCost + AddBoundingBoxConstraint, `Solve`, which picks
Drake's default QP solver here) on the identical eps-scaled data.

Problems:
  m8: a random LCS of the ball-rolling size (n = 19, k = 3, m = 8): 9 velocities
      (EE 3 + ball 6), 10 positions (EE xyz, ball quaternion, ball xyz), dt = 0.1, ball
      mass 0.132 kg, EE 0.01 kg; F = dt J M^-1 J' + 1e-2 I (so sigma_min(F + F') >= 2e-2);
      eps = 2e-5, gamma = 1e-2 (valid: checked), Q_d = 1e5 on the 3 ball velocities, 0
      elsewhere. Data from the same LCS with c shifted by a random +-5 mm.
  m2: the cart-pole (true model vs the model with wall offsets wrong by [-0.15, 0.15]),
      eps = 100, gamma = 1e-2, Q_d = I.
"""
from __future__ import annotations

import argparse
import json
import time

import numpy as np

from adaptive_c3.models.cartpole import cartpole_lcs
from adaptive_c3.systems.contact.lcs import Lcs
from adaptive_c3.systems.learning.violation_loss import (
    LearnerOptions, PreparedSample, ViolationLossLearner, adam_update, solve_sample)

__all__ = ["run_bench", "ballroll_size_problem", "cartpole_problem"]

NB = 10


def ballroll_size_problem(seed: int = 0):
    """(model Lcs, true Lcs, state sampler, options) of the ball-rolling size."""
    rng = np.random.default_rng(seed)
    n, k, m, dt = 19, 3, 8, 0.1
    nv = 9
    masses = np.array([0.01] * 3 + [2.0 / 5 * 0.132 * 0.0315 ** 2] * 3 + [0.132] * 3)
    Minv = np.diag(1.0 / masses)
    J = rng.standard_normal((m, nv)) * np.concatenate([np.ones(3), 0.03 * np.ones(3),
                                                       np.ones(3)])
    # velocity index ranges: ee_vel 10:13, ball_angvel 13:16, ball_vel 16:19
    A = np.eye(n)
    A[0:3, 10:13] = dt * np.eye(3)
    A[7:10, 16:19] = dt * np.eye(3)
    A += 1e-3 * rng.standard_normal((n, n))
    B = np.zeros((n, k))
    B[10:13, :] = dt / 0.01 * np.eye(3) * 1e-2  # EE is position-controlled-ish: small gain
    B[0:3, :] = dt * B[10:13, :]
    D = np.zeros((n, m))
    D[10:19, :] = Minv @ J.T * dt * 1e-2  # impulses scaled to N s of a light contact
    D[0:3, :] = dt * D[10:13, :]
    D[7:10, :] = dt * D[16:19, :]
    F = dt * (J @ Minv @ J.T) * 1e-2
    F = F / max(1.0, np.linalg.eigvalsh(F)[-1]) + 1e-2 * np.eye(m)
    E = np.zeros((m, n))
    E[:, 10:19] = dt * J
    E[:, 0:3] = rng.standard_normal((m, 3))
    E[:, 7:10] = rng.standard_normal((m, 3))
    H = 0.01 * rng.standard_normal((m, k))
    c = rng.uniform(-0.01, 0.02, m)
    model = Lcs(A=A, B=B, D=D, d=np.zeros(n), E=E, F=F, H=H, c=c, dt=dt)
    true = model.replace(c=c + rng.uniform(-0.005, 0.005, m))
    Qd = np.zeros(n)
    Qd[16:19] = 1e5
    opts = LearnerOptions(epsilon=2e-5, gamma=1e-2, learning_rate=5e-3, batch_size=NB,
                          Qd=list(Qd))

    def sample_state(r):
        x = np.zeros(n)
        x[0:3] = 0.01 * r.standard_normal(3)
        x[3] = 1.0
        x[7:10] = 0.01 * r.standard_normal(3)
        x[10:19] = 0.1 * r.standard_normal(9)
        return x, r.standard_normal(k)

    return model, true, sample_state, opts


def cartpole_problem(seed: int = 0):
    """(model Lcs, true Lcs, state sampler, options) for the cart-pole with walls."""
    model = cartpole_lcs(wall_offset_error=[-0.15, 0.15])
    true = cartpole_lcs()
    opts = LearnerOptions(epsilon=100.0, gamma=1e-2, learning_rate=1e-2, batch_size=NB)

    def sample_state(r):
        s = r.uniform(-0.7, 0.7)
        x = np.array([r.uniform(-0.2, 0.2), 0.0, r.normal(0, 0.3), r.normal(0, 0.5)])
        x[1] = (x[0] - s) / 0.6
        return x, r.normal(size=1)

    return model, true, sample_state, opts


def _transitions(true: Lcs, model: Lcs, sampler, count: int, seed: int):
    r = np.random.default_rng(seed)
    out = []
    for _ in range(count):
        x, u = sampler(r)
        x_next, _ = true.step(x, u)
        out.append((x_next, x, u, model))
    return out


def _mathprog_solve(s: PreparedSample, r):
    """The same per-sample QP through MathematicalProgram; returns (loss, grad)."""
    from pydrake.solvers import MathematicalProgram, Solve
    m = s.q.shape[0]
    qr = s.q + r
    g = np.concatenate([s.b + s.F.T @ qr / s.gamma, -qr / s.gamma])
    prog = MathematicalProgram()
    y = prog.NewContinuousVariables(2 * m, "y")
    prog.AddQuadraticCost(s.H, g, y, is_convex=True)
    prog.AddBoundingBoxConstraint(0.0, np.inf, y)
    result = Solve(prog)
    yv = np.maximum(result.GetSolution(y), 0.0)
    lam, eta = yv[:m], yv[m:]
    w = qr + s.F @ lam - eta
    e = s.D @ lam + s.z
    loss = 0.5 * e @ (s.Qd @ e) + (lam @ eta + w @ w / (2 * s.gamma)) / s.epsilon
    kkt = float(np.abs(np.minimum(yv, s.H @ yv + g)).max())
    return loss, w / (s.epsilon * s.gamma), kkt, result.get_solver_id().name()


def _run_updates(problem, n_updates: int, use_mathprog: bool, seed: int = 1):
    model, true, sampler, opts = problem
    data = _transitions(true, model, sampler, n_updates + NB, seed)
    learner = ViolationLossLearner(opts, model.num_lambda)
    buffer = [learner.prepare(*t) for t in data[:NB]]
    times, kkts = [], []
    solver = "block-pivoting"
    for i in range(n_updates):
        t0 = time.perf_counter()
        buffer = buffer[1:] + [learner.prepare(*data[NB + i])]
        if use_mathprog:
            losses, grads = [], []
            for s in buffer:
                loss, grad, kkt, solver = _mathprog_solve(s, learner.r)
                losses.append(loss)
                grads.append(grad)
                kkts.append(kkt)
            grad = np.mean(grads, axis=0)
            delta, learner.m1, learner.m2, learner.t = adam_update(
                grad, learner.m1, learner.m2, learner.t, opts, learner.mask)
            learner.r = learner.r + delta
        else:
            learner.step(buffer)
        times.append(time.perf_counter() - t0)
    if not use_mathprog:
        kkts = [solve_sample(s, learner.r).kkt for s in buffer]
    return np.array(times), float(np.max(kkts)), solver


def run_bench(quick: bool = False) -> list[dict]:
    """Rows learner/m{8,2}/nb10 (+ their mathprog baselines) with median_ms per update."""
    rows = []
    n_fast = 150 if quick else 1000
    n_base = 30 if quick else 200
    for tag, problem in (("m8", ballroll_size_problem()), ("m2", cartpole_problem())):
        _run_updates(problem, 10, False)  # warm up imports and caches
        _run_updates(problem, 2, True)
        t_fast, kkt_fast, _ = _run_updates(problem, n_fast, False)
        t_base, kkt_base, solver = _run_updates(problem, n_base, True)
        med_fast = float(np.median(t_fast) * 1e3)
        med_base = float(np.median(t_base) * 1e3)
        name = f"learner/{tag}/nb{NB}"
        base = f"{name}/mathprog"
        rows.append(dict(name=name, median_ms=med_fast, updates_per_s=1e3 / med_fast,
                         baseline=base, speedup=med_base / med_fast, samples=len(t_fast),
                         qp_solver="block principal pivoting (exact)",
                         max_kkt_residual=kkt_fast))
        rows.append(dict(name=base, median_ms=med_base, updates_per_s=1e3 / med_base,
                         samples=len(t_base), qp_solver=f"MathematicalProgram/{solver}",
                         max_kkt_residual=kkt_base))
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description="Benchmark the residual learner update.")
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--json", help="write the rows to this file")
    args = ap.parse_args(argv)
    rows = run_bench(args.quick)
    for row in rows:
        extra = f"  speedup {row['speedup']:.1f}x" if "speedup" in row else ""
        print(f"{row['name']:28s} {row['median_ms']:8.3f} ms  "
              f"{row['updates_per_s']:8.0f} updates/s{extra}")
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"results": rows}, f, indent=2)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
