"""Linear complementarity systems (LCS).

    x_{k+1} = A x_k + B u_k + D lam_k + d
    0 <= lam_k  _|_  E x_k + F lam_k + H u_k + c >= 0

`Lcs` is immutable (its arrays are read-only copies) and validated on
construction: every dimension mismatch names the offending matrix, and
non-finite entries are refused. `LcsSequence` is a time-varying list of LCSs
over an MPC horizon.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Iterable, Sequence

import numpy as np

from adaptive_c3.systems.contact.lcp import solve_lcp

_NAMES = ("A", "B", "D", "d", "E", "F", "H", "c")


class LcsError(ValueError):
    """An LCS was built from inconsistent or non-finite data."""


def _frozen(name: str, value, ndim: int) -> np.ndarray:
    arr = np.array(value, dtype=float, copy=True)
    if arr.ndim != ndim:
        raise LcsError(f"LCS matrix {name} must be {ndim}-D, got shape {arr.shape}")
    if not np.isfinite(arr).all():
        raise LcsError(f"LCS matrix {name} has non-finite entries")
    arr.flags.writeable = False
    return arr


def _mode(values):
    return max(values, key=values.count)   # ties: the first listed wins


@dataclass(frozen=True)
class Lcs:
    """One linear complementarity system; n states, k inputs, m contact forces."""

    A: np.ndarray
    B: np.ndarray
    D: np.ndarray
    d: np.ndarray
    E: np.ndarray
    F: np.ndarray
    H: np.ndarray
    c: np.ndarray
    dt: float = 0.0  # the time step the LCS stands for, s (0 = unspecified)

    def __post_init__(self):
        ndims = dict(A=2, B=2, D=2, d=1, E=2, F=2, H=2, c=1)
        for name in _NAMES:
            object.__setattr__(self, name, _frozen(name, getattr(self, name), ndims[name]))
        # sizes by majority vote, so that the one inconsistent matrix is the one named
        n = _mode([self.A.shape[0], self.A.shape[1], self.B.shape[0], self.D.shape[0],
                   self.d.shape[0], self.E.shape[1]])
        m = _mode([self.D.shape[1], self.E.shape[0], self.F.shape[0], self.F.shape[1],
                   self.H.shape[0], self.c.shape[0]])
        k = _mode([self.B.shape[1], self.H.shape[1]])
        expected = dict(A=(n, n), B=(n, k), D=(n, m), d=(n,), E=(m, n), F=(m, m),
                        H=(m, k), c=(m,))
        for name in _NAMES:
            got = getattr(self, name).shape
            if got != expected[name]:
                raise LcsError(
                    f"LCS matrix {name} has shape {got}, expected {expected[name]} "
                    f"(n={n} states, k={k} inputs, m={m} contact forces)")
        if not np.isfinite(self.dt) or self.dt < 0:
            raise LcsError(f"LCS dt must be finite and >= 0, got {self.dt}")

    # Immutable: copies (e.g. through Drake's abstract ports) can share the arrays.
    def __copy__(self):
        return self

    def __deepcopy__(self, memo):
        return self

    # --- sizes -------------------------------------------------------------
    @property
    def num_states(self) -> int:
        return self.A.shape[0]

    @property
    def num_inputs(self) -> int:
        return self.B.shape[1]

    @property
    def num_lambda(self) -> int:
        return self.D.shape[1]

    # --- evaluation --------------------------------------------------------
    def complementarity_offset(self, x, u) -> np.ndarray:
        """q = E x + H u + c, the LCP offset for the contact forces at (x, u)."""
        return self.E @ np.asarray(x, float) + self.H @ np.asarray(u, float) + self.c

    def solve_lambda(self, x, u) -> np.ndarray:
        """The contact forces: the solution of LCP(E x + H u + c, F)."""
        result = solve_lcp(self.F, self.complementarity_offset(x, u))
        if not result.solved:
            raise LcsError(f"LCP of the LCS step has no solution found ({result.message})")
        return result.z

    def step(self, x, u) -> tuple[np.ndarray, np.ndarray]:
        """One step: returns (x_next, lam)."""
        x = self._check_vec("x", x, self.num_states)
        u = self._check_vec("u", u, self.num_inputs)
        lam = self.solve_lambda(x, u)
        x_next = self.A @ x + self.B @ u + self.D @ lam + self.d
        return x_next, lam

    def rollout(self, x0, us) -> tuple[np.ndarray, np.ndarray]:
        """States [T+1, n] and forces [T, m] from x0 under inputs us [T, k]."""
        xs = [np.asarray(x0, float)]
        lams = []
        for u in np.atleast_2d(us):
            x_next, lam = self.step(xs[-1], u)
            xs.append(x_next)
            lams.append(lam)
        return np.array(xs), np.array(lams).reshape(len(lams), self.num_lambda)

    # --- variants ----------------------------------------------------------
    def with_residual(self, r_comp) -> "Lcs":
        """The same LCS with r_comp added to the complementarity offset c."""
        r = self._check_vec("r_comp", r_comp, self.num_lambda)
        return self.replace(c=self.c + r)

    def replace(self, **changes) -> "Lcs":
        fields = {name: getattr(self, name) for name in _NAMES}
        fields["dt"] = self.dt
        fields.update(changes)
        return Lcs(**fields)

    def _check_vec(self, name, v, size) -> np.ndarray:
        arr = np.asarray(v, dtype=float).reshape(-1)
        if arr.shape != (size,):
            raise LcsError(f"{name} has {arr.size} entries, the LCS expects {size}")
        if not np.isfinite(arr).all():
            raise LcsError(f"{name} has non-finite entries")
        return arr


@dataclass(frozen=True)
class LcsSequence:
    """A time-varying LCS over an MPC horizon: systems[k] maps knot k to k+1."""

    systems: tuple = field(default_factory=tuple)

    def __post_init__(self):
        systems = tuple(self.systems)
        if not systems:
            raise LcsError("an LCS sequence needs at least one LCS")
        first = systems[0]
        for i, s in enumerate(systems):
            if not isinstance(s, Lcs):
                raise LcsError(f"LCS sequence entry {i} is a {type(s).__name__}, not an Lcs")
            if (s.num_states, s.num_inputs, s.num_lambda) != (
                    first.num_states, first.num_inputs, first.num_lambda):
                raise LcsError(f"LCS sequence entry {i} has different sizes than entry 0")
        object.__setattr__(self, "systems", systems)

    @classmethod
    def constant(cls, lcs: Lcs, horizon: int) -> "LcsSequence":
        return cls(tuple([lcs] * int(horizon)))

    def __len__(self) -> int:
        return len(self.systems)

    def __getitem__(self, k: int) -> Lcs:
        return self.systems[k]

    def __iter__(self):
        return iter(self.systems)

    def with_residual(self, r_comp) -> "LcsSequence":
        return LcsSequence(tuple(s.with_residual(r_comp) for s in self.systems))


def as_sequence(lcs: Lcs | LcsSequence | Sequence[Lcs], horizon: int) -> LcsSequence:
    """An LcsSequence of the given horizon from one LCS or a sequence."""
    if isinstance(lcs, Lcs):
        return LcsSequence.constant(lcs, horizon)
    seq = lcs if isinstance(lcs, LcsSequence) else LcsSequence(tuple(lcs))
    if len(seq) != horizon:
        raise LcsError(f"LCS sequence has {len(seq)} entries, the horizon is {horizon}")
    return seq
