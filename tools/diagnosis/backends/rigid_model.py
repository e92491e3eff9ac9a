"""The rigid-object model that `evaluate` and `diagnose` roll out: the scenario's
Anitescu LCS (models/rigid_object.py), re-linearised at every step, with the scenario's
`patch` effects applied.

One step from x_k (plant layout): θ = linearize(x_k) at the step dt, then
    0 <= λ ⊥ E x_k + F λ + c + c_patch >= 0,   x_{k+1} = A x_k + D λ + d,
and the quaternion is renormalised. Patch effects that act on the LCS (the rest are
geometry or inertia and shape the plant itself):
- restitution e: a corner in contact that approaches the table at speed s must leave
  it at >= e s: c_patch -= e max(-J_n v_k, 0) on that corner's rows (Newton's law);
- r_comp: added to c (one value for every row, or one per row).
After the step, torsional_friction (m) takes spin about the table normal out with a
torque impulse of at most that length x the normal impulse (Coulomb; see
_torsional_friction): the LCS has no torsional rows.
The LCP (up to 8 corners x n_e edges) is solved on the corners that can touch in this
step (free-motion gap below zero plus a margin), then checked on all of them.
"""
from __future__ import annotations

import numpy as np

from adaptive_c3.models.drake_warnings import silence_half_space_deformable_warning
from adaptive_c3.models.rigid_object import (RigidObjectParams, plant_state, quat_to_matrix,
                                             quaternion_rate, recording_state,
                                             rigid_object_linearizer)
from adaptive_c3.systems.contact.lcp import solve_lcp


def key_value(key: str, v):
    """An effect's value in the type its scenario key holds (r_comp: a one-entry list,
    friction_edges: an integer, the rest: floats)."""
    field = key.split(".")[1]
    if field == "r_comp":
        return [float(v)]
    if field == "friction_edges":
        return int(round(v))
    return float(v)


class RigidModelError(ValueError):
    """The model could not be stepped (an LCP without a solution)."""


def _acceptable(res, q) -> bool:
    """Lemke's answer, also when its residual misses the 1e-10 default by little: with
    many friction edges the LCP is degenerate (nearly parallel rows) and a residual of
    1e-5 of the offset's scale (m/s) is far below anything a rollout can see."""
    return res.solved or res.residual <= 1e-5 * max(1.0, float(np.abs(q).max()))


class RigidObjectModel:
    """Rollouts of a rigid_object scenario's model at time step dt (s)."""

    def __init__(self, scenario, dt: float):
        silence_half_space_deformable_warning()
        self.scenario = scenario
        self.params = RigidObjectParams.from_scenario(scenario)
        c = scenario.contact
        self.dt = float(c.dt) if c.dt > 0 else float(dt)
        self.linearizer = rigid_object_linearizer(self.params, self.dt, c.friction_edges,
                                                  c.eps_c)
        self.num_edges = int(c.friction_edges)
        m = self.linearizer.num_lambda
        r = np.asarray(scenario.patch.r_comp, float)
        if r.size not in (0, 1, m):
            raise RigidModelError(f"patch.r_comp must have 0, 1 or {m} entries, got {r.size}")
        self.r_comp = np.zeros(m) + (r if r.size else 0.0)
        self.restitution = float(scenario.patch.restitution)
        self.torsional_friction = float(scenario.patch.torsional_friction)
        self._inertia_body_inv = np.diag(1.0 / np.asarray(self.params.inertia_diag))
        self._u = np.zeros(0)

    @property
    def size(self) -> float:
        return self.params.size

    def step(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(x_{k+1}, λ_k) from x_k, both in the plant layout."""
        terms = self.linearizer.linearize_terms(x, self._u, self.dt)
        lcs = terms.lcs
        ne = self.num_edges
        q = lcs.E @ x + lcs.c + self.r_comp
        if self.restitution > 0:
            v = x[self.linearizer.nq:]
            approach = np.maximum(-(terms.J_n @ v), 0.0)
            approach[terms.phi > approach * self.dt + 1e-3] = 0.0   # only corners at the table
            q -= np.repeat(self.restitution * approach, ne)
        lam = self._solve(lcs.F, q, terms.phi, x, terms.J_n)
        x_next = lcs.A @ x + lcs.D @ lam + lcs.d
        if self.torsional_friction > 0 and np.any(lam > 0):
            self._torsional_friction(x, x_next, lam.sum())
        x_next[:4] /= np.linalg.norm(x_next[:4])
        return x_next, lam

    def _torsional_friction(self, x, x_next, normal_impulse: float) -> None:
        """Coulomb torsional friction about the table normal (world z), after the LCS
        step: a torque impulse of at most torsional_friction (m) x the normal impulse
        (every edge impulse has a unit normal part) takes spin about z out, never
        reversing it; the orientation step is redone with the changed spin."""
        nq = self.linearizer.nq
        R = quat_to_matrix(x[:4])
        I_inv = R @ self._inertia_body_inv @ R.T       # world frame
        wz = x_next[nq + 2]
        if wz == 0.0:
            return
        tau = min(self.torsional_friction * normal_impulse, abs(wz) / I_inv[2, 2])
        dw = -np.sign(wz) * tau * I_inv[:, 2]
        x_next[nq:nq + 3] += dw
        x_next[:4] += self.dt * quaternion_rate(x[:4], dw)    # the part of q_dot from dw

    def _solve(self, F, q, phi, x, J_n) -> np.ndarray:
        m = q.size
        ne = self.num_edges
        lam = np.zeros(m)
        v = x[self.linearizer.nq:]
        # corners that may reach the table this step (gap after a free step below a margin)
        near = phi + self.dt * np.minimum(J_n @ v, 0.0) < 0.01
        rows = np.flatnonzero(np.repeat(near, ne))
        for _ in range(3):
            if rows.size:
                res = solve_lcp(F[np.ix_(rows, rows)], q[rows])
                if not _acceptable(res, q[rows]):
                    raise RigidModelError(f"the model's LCP has no solution ({res.message})")
                lam[:] = 0.0
                lam[rows] = res.z
            w = F @ lam + q
            bad = np.flatnonzero(w < -1e-9)
            if bad.size == 0:
                return lam
            rows = np.union1d(rows, np.flatnonzero(np.isin(np.arange(m) // ne, bad // ne)))
        res = solve_lcp(F, q)
        if not _acceptable(res, q):
            raise RigidModelError(f"the model's LCP has no solution ({res.message})")
        return res.z

    def rollout(self, x0_rec: np.ndarray, num_steps: int) -> np.ndarray:
        """States [num_steps + 1, 13] in the recording layout from the recording-layout x0."""
        x = plant_state(np.asarray(x0_rec, float))
        out = np.empty((num_steps + 1, x.size))
        out[0] = x
        for k in range(num_steps):
            x, _ = self.step(x)
            out[k + 1] = x
        return recording_state(out)
