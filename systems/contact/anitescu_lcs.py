"""Anitescu LCS linearisation of a MultibodyPlant (the paper's Section V).

Given a nominal (x*, u*), x = [q, v], `AnitescuLinearizer.linearize` returns the LCS
θ* = (A, B, D, d, E, F, H, c) of the multi-step Anitescu time-stepping model

    v_{k+1} = v_k + dt (J_f [q_k; v_k; u_k] + d_v) + M⁻¹ J_cᵀ λ_k
    q_{k+1} = q_k + dt N(q*) v_{k+1}
    0 <= λ_k ⊥ (1/dt) E_tᵀ (φ + J_n N⁺(q*) (q_k − q*)) + J_c v_{k+1} + ε_c λ_k >= 0

with f(q, v, u) = M⁻¹ (B u − C(q, v) v + τ_app(q, v)), J_f = ∂f/∂(q, v, u) at the
nominal point (automatic differentiation), d_v = f* − J_f [q*; v*; u*],
J_c = E_tᵀ J_n + μ J_t, and q̇ = N(q) v the plant's velocity-to-q̇ map.

Units and conventions:
- λ is an *impulse* along one edge n + μ d_j of the polyhedral friction cone (N·s),
  as in the paper (D = M⁻¹ J_cᵀ); the complementarity rows are velocities (m/s), so
  ε_c is in (m/s)/(N·s) = 1/kg. F = J_c M⁻¹ J_cᵀ + ε_c I is symmetric positive definite
  for ε_c > 0 and, because rank(J_c) <= 3 per contact, σ_min(F + Fᵀ) = 2 ε_c whenever
  n_e > 3: a residual learner's γ must stay below 2 ε_c.
- Quaternions: J_n is a Jacobian with respect to v. The position offset q_k − q* is
  mapped into velocity coordinates by N⁺(q*) (Drake's q̇-to-v map), i.e. the
  first-order change of φ is J_n N⁺(q*) (q_k − q*). For a unit quaternion N⁺N = I, so
  this is exact to first order for displacements along the quaternion's tangent space.
  N(q*) is frozen at the nominal point (the term ∂N/∂q · v is dropped).
- Edges: for contact normal n (pointing from geometry B to geometry A) the tangent
  t1 is world x projected onto the contact plane (world y when n is near ±x) and
  t2 = n × t1; edge j has direction d_j = cos(2πj/n_e) t1 + sin(2πj/n_e) t2, so for
  n_e = 4 the edges are +t1, +t2, −t1, −t2. λ is ordered pair by pair, edge by edge.
- Open pairs (`open_pair_tol`): Anitescu's relaxed cone lets an OPEN pair act. Edge
  row j, φ/dt + J_n v + μ d_jᵀ J_t v >= 0, binds while φ < dt (μ |v_t| − v_n), so a
  body sliding past another a few mm away is pushed or braked (at dt = 0.01 s and
  0.4 m/s of slip, ~4 mm of reach). With `open_pair_tol` set (m), a pair's μ in its J_c
  rows is scaled by `open_pair_scale(φ − dt max(0, −J_n v*))`: 1 while the pair is
  closed or closes within the step at its approach speed (to the tolerance), 0 once it
  is more than tol + 1 mm out of that reach (non-penetration rows only, no friction),
  linear between so the model stays continuous. None (default) = the paper's model.
- Geometry (φ, witness points, J_n, J_t) comes from the double plant's SceneGraph
  (ComputeSignedDistancePairClosestPoints) and CalcJacobianTranslationalVelocity;
  only M and the bias term go through AutoDiff (one pass, reused contexts).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydrake.autodiffutils import AutoDiffXd, ExtractGradient, ExtractValue, \
    InitializeAutoDiff
from pydrake.geometry import GeometryId, Role
from pydrake.multibody.tree import JacobianWrtVariable, MultibodyForces_

from adaptive_c3.systems.contact.lcs import Lcs


OPEN_PAIR_TOL = 5e-4   # m, the default gap tolerance of the open-pair gate (module doc)
OPEN_PAIR_RAMP = 1e-3  # m, the gate takes friction from mu to 0 over this much more gap


def open_pair_scale(gap, tol: float = OPEN_PAIR_TOL, ramp: float = OPEN_PAIR_RAMP):
    """Friction factor in [0, 1] of a pair with the given reach-corrected gap (m): 1 up
    to tol, 0 beyond tol + ramp, linear between (continuous in the state and in a
    fitted gap offset)."""
    return np.clip((tol + ramp - np.asarray(gap, float)) / ramp, 0.0, 1.0)


@dataclass(frozen=True)
class ContactPair:
    """A contact between two geometries (GeometryId, or geometry / body name) with μ."""

    name: str
    geometry_a: object
    geometry_b: object
    mu: float


@dataclass(frozen=True)
class AnitescuTerms:
    """Everything the linearisation computed at one nominal point (for tests/tools)."""

    lcs: Lcs
    phi: np.ndarray      # [n_c] signed distances, m
    J_n: np.ndarray      # [n_c, n_v] normal Jacobians (separation speed), wrt v
    J_t: np.ndarray      # [n_c*n_e, n_v] edge-direction Jacobians, wrt v
    J_c: np.ndarray      # [n_c*n_e, n_v] E_tᵀJ_n + μJ_t
    J_f: np.ndarray      # [n_v, n_q+n_v+n_u] ∂f/∂(q, v, u)
    f: np.ndarray        # [n_v] f(q*, v*, u*), generalized accelerations
    M: np.ndarray        # [n_v, n_v] mass matrix
    N: np.ndarray        # [n_q, n_v] q̇ = N v
    N_plus: np.ndarray   # [n_v, n_q] v = N⁺ q̇
    normals: np.ndarray  # [n_c, 3] contact normals in world (B to A)


class AnitescuLinearizer:
    """Builds Anitescu LCSs of a plant; all contexts and seeds are made once here.

    The linearizer owns its (double and AutoDiff) contexts: give each system or thread
    its own instance. `linearize(x, u, dt=...)` may override the step per call.
    """

    def __init__(self, diagram, plant, contact_pairs, num_edges: int = 4,
                 dt: float = 0.1, eps_c: float = 1e-2, open_pair_tol: float | None = None):
        if int(num_edges) < 2:
            raise ValueError(f"num_edges must be >= 2, got {num_edges}")
        if not (np.isfinite(dt) and dt > 0):
            raise ValueError(f"dt must be > 0, got {dt}")
        if not (np.isfinite(eps_c) and eps_c > 0):
            raise ValueError(f"eps_c must be > 0 (F positive definite), got {eps_c}")
        if not contact_pairs:
            raise ValueError("at least one contact pair is needed")
        if open_pair_tol is not None and not (np.isfinite(open_pair_tol)
                                              and open_pair_tol >= 0):
            raise ValueError(f"open_pair_tol must be >= 0 m or None, got {open_pair_tol}")
        self.open_pair_tol = None if open_pair_tol is None else float(open_pair_tol)
        self.plant = plant
        self.num_edges = int(num_edges)
        self.dt = float(dt)
        self.eps_c = float(eps_c)
        self.nq = plant.num_positions()
        self.nv = plant.num_velocities()
        self.nu = plant.num_actuators()
        self.nx = self.nq + self.nv

        # double copy: kinematics, geometry, N(q)
        self._context = diagram.CreateDefaultContext()
        self._plant_context = plant.GetMyMutableContextFromRoot(self._context)
        # AutoDiff copy: mass matrix and bias term
        self._diagram_ad = diagram.ToAutoDiffXd()
        self._plant_ad = self._diagram_ad.GetSubsystemByName(plant.get_name())
        self._context_ad = self._diagram_ad.CreateDefaultContext()
        self._plant_context_ad = self._plant_ad.GetMyMutableContextFromRoot(
            self._context_ad)
        self._forces_ad = MultibodyForces_[AutoDiffXd](self._plant_ad)
        self._zero_vdot_ad = np.array([AutoDiffXd(0.0) for _ in range(self.nv)])
        self._B_act = np.asarray(plant.MakeActuationMatrix(), float).reshape(
            self.nv, self.nu)

        self._pairs = [self._resolve_pair(p) for p in contact_pairs]
        self.num_contacts = len(self._pairs)
        self.num_lambda = self.num_contacts * self.num_edges
        ang = 2.0 * np.pi * np.arange(self.num_edges) / self.num_edges
        self._edge_cs = np.stack([np.cos(ang), np.sin(ang)], axis=1)  # [n_e, 2]
        self._edge_cs[np.abs(self._edge_cs) < 1e-12] = 0.0
        self._E_t = np.kron(np.eye(self.num_contacts), np.ones((1, self.num_edges)))
        self._mu_edges = np.repeat([p["mu"] for p in self._pairs], self.num_edges)
        self._point = (None, None)    # (key of (x, u), its dt-independent terms)

    # ------------------------------------------------------------------ set-up
    def _resolve_geometry(self, g, inspector) -> GeometryId:
        if isinstance(g, GeometryId):
            if inspector.GetProximityProperties(g) is None:
                raise ValueError(f"geometry {g} has no proximity role")
            return g
        name = str(g)
        for gid in inspector.GetAllGeometryIds(Role.kProximity):
            full = inspector.GetName(gid)
            if full == name or full.split("::")[-1] == name:
                return gid
        if self.plant.HasBodyNamed(name):
            ids = self.plant.GetCollisionGeometriesForBody(self.plant.GetBodyByName(name))
            if len(ids) == 1:
                return ids[0]
            raise ValueError(f"body {name!r} has {len(ids)} collision geometries; "
                             "name the geometry")
        raise ValueError(f"no collision geometry or body named {name!r}")

    def _resolve_pair(self, pair) -> dict:
        if not isinstance(pair, ContactPair):
            pair = ContactPair(*pair)
        if not (np.isfinite(pair.mu) and pair.mu >= 0):
            raise ValueError(f"contact {pair.name}: mu must be >= 0, got {pair.mu}")
        query = self.plant.get_geometry_query_input_port().Eval(self._plant_context)
        inspector = query.inspector()
        out = dict(name=pair.name, mu=float(pair.mu))
        for side, g in (("a", pair.geometry_a), ("b", pair.geometry_b)):
            gid = self._resolve_geometry(g, inspector)
            body = self.plant.GetBodyFromFrameId(inspector.GetFrameId(gid))
            X_BG = inspector.GetPoseInFrame(gid)
            out["id_" + side] = gid
            out["frame_" + side] = None if body.index() == self.plant.world_body().index() \
                else body.body_frame()
            out["R_BG_" + side] = X_BG.rotation().matrix()
            out["p_BG_" + side] = X_BG.translation()
        return out

    def lambda_names(self) -> list[str]:
        """One name per λ entry: '<pair>/<edge>' (edges +t1, +t2, -t1, -t2 for n_e=4)."""
        if self.num_edges == 4:
            edges = ["+t1", "+t2", "-t1", "-t2"]
        elif self.num_edges == 2:
            edges = ["+t1", "-t1"]
        else:
            edges = [f"edge{j}" for j in range(self.num_edges)]
        return [f"{p['name']}/{e}" for p in self._pairs for e in edges]

    @property
    def contact_names(self) -> list[str]:
        return [p["name"] for p in self._pairs]

    # ------------------------------------------------------------------ pieces
    def _check(self, x, u):
        x = np.asarray(x, float).reshape(-1)
        u = np.asarray(u, float).reshape(-1)
        if x.shape != (self.nx,):
            raise ValueError(f"x has {x.size} entries, the plant has {self.nx} states")
        if u.shape != (self.nu,):
            raise ValueError(f"u has {u.size} entries, the plant has {self.nu} inputs")
        if not (np.isfinite(x).all() and np.isfinite(u).all()):
            raise ValueError("x and u must be finite")
        return x, u

    def smooth_dynamics(self, x, u):
        """(f, J_f, M, M⁻¹): f = M⁻¹(Bu − Cv + τ_app) and J_f = ∂f/∂(q, v, u)."""
        x, u = self._check(x, u)
        plant_ad, ctx_ad = self._plant_ad, self._plant_context_ad
        plant_ad.SetPositionsAndVelocities(ctx_ad, InitializeAutoDiff(x).reshape(-1))
        M_ad = plant_ad.CalcMassMatrix(ctx_ad)
        plant_ad.CalcForceElementsContribution(ctx_ad, self._forces_ad)
        # inverse dynamics at zero vdot: b = C(q, v) v − τ_app(q, v) (gravity, elements)
        b_ad = plant_ad.CalcInverseDynamics(ctx_ad, self._zero_vdot_ad, self._forces_ad)
        nv, nx = self.nv, self.nx
        M = ExtractValue(M_ad).reshape(nv, nv)
        dM = ExtractGradient(M_ad.reshape(-1)).reshape(nv, nv, nx)
        b = ExtractValue(b_ad).reshape(nv)
        db = ExtractGradient(b_ad).reshape(nv, nx)
        M_inv = np.linalg.inv(M)  # small and SPD; one inverse serves every solve
        M_inv = 0.5 * (M_inv + M_inv.T)
        f = M_inv @ (self._B_act @ u - b)
        # d(M f) = dr  =>  M df = dr − dM f
        rhs = np.empty((nv, nx + self.nu))
        rhs[:, :nx] = -db - np.einsum("ijk,j->ik", dM, f)
        rhs[:, nx:] = self._B_act
        J_f = M_inv @ rhs
        return f, J_f, M, M_inv

    def contact_geometry(self, x):
        """(φ [n_c], J_n [n_c, n_v], J_t [n_c n_e, n_v], normals [n_c, 3]) at x."""
        plant, ctx = self.plant, self._plant_context
        x = np.asarray(x, float).reshape(-1)
        plant.SetPositionsAndVelocities(ctx, x)
        query = plant.get_geometry_query_input_port().Eval(ctx)
        world = plant.world_frame()
        nc, ne, nv = self.num_contacts, self.num_edges, self.nv
        phi = np.empty(nc)
        J_n = np.empty((nc, nv))
        J_t = np.empty((nc * ne, nv))
        normals = np.empty((nc, 3))
        for i, p in enumerate(self._pairs):
            res = query.ComputeSignedDistancePairClosestPoints(p["id_a"], p["id_b"])
            n = np.asarray(res.nhat_BA_W, float).reshape(3)
            p_GCa = np.asarray(res.p_ACa, float).reshape(3)
            p_GCb = np.asarray(res.p_BCb, float).reshape(3)
            if res.id_A != p["id_a"]:  # the query reported the pair swapped
                n, p_GCa, p_GCb = -n, p_GCb, p_GCa
            J = np.zeros((3, nv))
            if p["frame_a"] is not None:
                J += plant.CalcJacobianTranslationalVelocity(
                    ctx, JacobianWrtVariable.kV, p["frame_a"],
                    p["R_BG_a"] @ p_GCa + p["p_BG_a"], world, world)
            if p["frame_b"] is not None:
                J -= plant.CalcJacobianTranslationalVelocity(
                    ctx, JacobianWrtVariable.kV, p["frame_b"],
                    p["R_BG_b"] @ p_GCb + p["p_BG_b"], world, world)
            t1, t2 = _tangents(n)
            dirs = self._edge_cs @ np.stack([t1, t2])  # [n_e, 3]
            phi[i] = res.distance
            J_n[i] = n @ J
            J_t[i * ne:(i + 1) * ne] = dirs @ J
            normals[i] = n
        return phi, J_n, J_t, normals

    def geometry_terms(self, x):
        """(φ, J_n, J_t, normals, N, N⁺) at x: contact geometry and the q̇ ↔ v maps
        (no dynamics; for callers that take the smooth part once)."""
        phi, J_n, J_t, normals = self.contact_geometry(x)  # also sets the double context
        N = self.plant.MakeVelocityToQDotMap(self._plant_context).toarray()
        N_plus = self.plant.MakeQDotToVelocityMap(self._plant_context).toarray()
        return phi, J_n, J_t, normals, N, N_plus

    # ------------------------------------------------------------------ LCS
    def linearize(self, x_star, u_star, dt: float | None = None) -> Lcs:
        """θ* at (x*, u*) as an Lcs (dt defaults to the linearizer's dt)."""
        return self.linearize_terms(x_star, u_star, dt).lcs

    def _point_terms(self, x, u):
        """The dt-independent terms at (x, u): smooth dynamics, contact geometry and the
        kinematic maps. The last point is kept, so LCSs of several dt at the same state
        and input (planning, loop period, learner) cost one evaluation."""
        key = x.tobytes() + u.tobytes()
        if self._point[0] != key:
            terms = (*self.smooth_dynamics(x, u), *self.geometry_terms(x))
            for a in terms:           # shared by every LCS built at this point
                a.setflags(write=False)
            self._point = (key, terms)
        return self._point[1]

    def linearize_terms(self, x_star, u_star, dt: float | None = None) -> AnitescuTerms:
        """θ* and the intermediate terms (φ, Jacobians, J_f, M, N)."""
        x, u = self._check(x_star, u_star)
        dt = self.dt if dt is None else float(dt)
        if not (np.isfinite(dt) and dt > 0):
            raise ValueError(f"dt must be > 0, got {dt}")
        nq, nv, nx, nu = self.nq, self.nv, self.nx, self.nu
        f, J_f, M, M_inv, phi, J_n, J_t, normals, N, N_plus = self._point_terms(x, u)
        q_star = x[:nq]
        mu_e = self._mu_edges
        if self.open_pair_tol is not None:    # pairs out of one step's reach: no friction
            reach = phi - dt * np.maximum(0.0, -(J_n @ x[nq:]))
            mu_e = mu_e * np.repeat(open_pair_scale(reach, self.open_pair_tol),
                                    self.num_edges)
        J_c = self._E_t.T @ J_n + mu_e[:, None] * J_t
        MinvJcT = M_inv @ J_c.T
        Jf_q, Jf_v, Jf_u = J_f[:, :nq], J_f[:, nq:nx], J_f[:, nx:]
        d_v = f - J_f @ np.concatenate([x, u])

        # v_{k+1} = Av_q q + Av_v v + Bv u + Dv λ + dv
        Av = np.hstack([dt * Jf_q, np.eye(nv) + dt * Jf_v])
        Bv = dt * Jf_u
        Dv = MinvJcT
        dv = dt * d_v
        dtN = dt * N
        A = np.empty((nx, nx))
        A[:nq] = dtN @ Av
        A[:nq, :nq] += np.eye(nq)
        A[nq:] = Av
        B = np.vstack([dtN @ Bv, Bv])
        D = np.vstack([dtN @ Dv, Dv])
        d = np.concatenate([dtN @ dv, dv])

        # w = (1/dt) E_tᵀ (φ + J_n N⁺ (q − q*)) + J_c v_{k+1} + ε_c λ
        EtJnNp = self._E_t.T @ (J_n @ N_plus) / dt
        E = J_c @ Av
        E[:, :nq] += EtJnNp
        F = J_c @ Dv
        F = 0.5 * (F + F.T) + self.eps_c * np.eye(self.num_lambda)
        H = J_c @ Bv
        c = self._E_t.T @ phi / dt - EtJnNp @ q_star + J_c @ dv
        lcs = Lcs(A, B, D, d, E, F, H, c, dt)
        return AnitescuTerms(lcs, phi, J_n, J_t, J_c, J_f, f, M, N, N_plus, normals)


def _tangents(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Orthonormal t1, t2 with t2 = n × t1; t1 follows world x (world y near n = ±x)."""
    a = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    t1 = a - (a @ n) * n
    t1 /= np.linalg.norm(t1)
    t2 = np.array([n[1] * t1[2] - n[2] * t1[1], n[2] * t1[0] - n[0] * t1[2],
                   n[0] * t1[1] - n[1] * t1[0]])
    return t1, t2
