"""Episode bookkeeping for recordings of free-flying bodies: find "twin" episodes (copies
of one another up to a yaw rotation about world z and a horizontal shift) and split
episodes into train / held-out sets so that twins never straddle the split; read a
recording's episodes and score a rollout of one against it (the metrics of `evaluate`).

Pure numpy/scipy. State columns are looked up by name: x, y, z, qw, qx, qy, qz (world from
body), vx, vy, vz (world), wx, wy, wz (body frame).
"""
from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from adaptive_c3.models.rigid_object import (RECORDING_STATE_NAMES, orientation_error_deg,
                                             quat_to_matrix)
from adaptive_c3.tools.diagnosis.backends.model_backend import FAILED_SCORE
from adaptive_c3.tools.user_input import UserError

_NAMES = ("x", "y", "z", "qw", "qx", "qy", "qz", "vx", "vy", "vz", "wx", "wy", "wz")


def _columns(state_names) -> list[int]:
    names = list(state_names)
    missing = [n for n in _NAMES if n not in names]
    if missing:
        raise ValueError(f"find_twins needs state columns {missing} (has {names})")
    return [names.index(n) for n in _NAMES]


def _yaw_matrix(theta: float) -> np.ndarray:
    c, s = np.cos(theta), np.sin(theta)
    return np.array([[c, -s], [s, c]])


def fit_yaw_shift(p_a, p_b, d_a=None, d_b=None) -> tuple[float, np.ndarray, float]:
    """Closed-form 2-D Procrustes (rotation + shift, no scale): p_b ~ R(yaw) p_a + shift.

    p_a, p_b: [T, 2] horizontal paths. Optional d_a, d_b: [K, 2] extra direction vectors
    (rotated but not shifted) that help pin the yaw when the path barely moves.
    Returns (yaw in rad, shift [2], max path residual in m)."""
    p_a, p_b = np.asarray(p_a, float), np.asarray(p_b, float)
    ma, mb = p_a.mean(0), p_b.mean(0)
    A, B = p_a - ma, p_b - mb
    if d_a is not None:
        A, B = np.vstack([A, d_a]), np.vstack([B, d_b])
    cross = np.sum(A[:, 0] * B[:, 1] - A[:, 1] * B[:, 0])
    dot = np.sum(A * B)
    yaw = float(np.arctan2(cross, dot))
    R = _yaw_matrix(yaw)
    shift = mb - R @ ma
    residual = float(np.max(np.linalg.norm(p_a @ R.T + shift - p_b, axis=1)))
    return yaw, shift, residual


def _invariants(x: np.ndarray, Rq: np.ndarray) -> np.ndarray:
    """Per-sample quantities unchanged by a yaw about z + horizontal shift:
    z, |v_xy|, vz, body omega (3), world z axis seen in the body frame (3)."""
    return np.column_stack([x[:, 2], np.hypot(x[:, 7], x[:, 8]), x[:, 9], x[:, 10:13],
                            Rq[:, 2, :]])


def pair_distance(x_a, x_b, attitude_length: float = 0.05) -> dict:
    """Max-abs mismatches of two episodes ([T, 13] in _NAMES order) over the shorter length,
    after fitting yaw + shift: keys z, speed (|v_xy| and vz), omega, tilt, xy (path residual),
    vxy (rotated v_xy), rot (rotation matrices), and yaw, shift, n (samples compared)."""
    n = min(len(x_a), len(x_b))
    x_a, x_b = np.asarray(x_a, float)[:n], np.asarray(x_b, float)[:n]
    Ra, Rb = quat_to_matrix(x_a[:, 3:7]), quat_to_matrix(x_b[:, 3:7])
    ia, ib = _invariants(x_a, Ra), _invariants(x_b, Rb)
    # body x and y axes, horizontal parts, as yaw-only direction hints
    da = attitude_length * np.concatenate([Ra[:, :2, 0], Ra[:, :2, 1]])
    db = attitude_length * np.concatenate([Rb[:, :2, 0], Rb[:, :2, 1]])
    yaw, shift, res = fit_yaw_shift(x_a[:, :2], x_b[:, :2], da, db)
    R2 = _yaw_matrix(yaw)
    Rz = np.eye(3)
    Rz[:2, :2] = R2
    d = np.abs(ia - ib)
    return dict(
        z=float(d[:, 0].max()), speed=float(d[:, 1:3].max()), omega=float(d[:, 3:6].max()),
        tilt=float(d[:, 6:9].max()), xy=res,
        vxy=float(np.abs(x_a[:, 7:9] @ R2.T - x_b[:, 7:9]).max()),
        rot=float(np.abs(Rz @ Ra - Rb).max()), yaw=yaw, shift=shift, n=n)


def find_twins(rec, pos_tol: float = 1e-4, vel_tol: float = 1e-3, omega_tol: float = 1e-3,
               rot_tol: float = 1e-4, min_overlap: int = 20) -> list[tuple[int, int]]:
    """Pairs (a, b), a < b, of episode ids of `rec` that are copies of one another up to a
    yaw rotation about world z and an x-y shift (yaw 0 / shift 0, i.e. exact duplicates,
    included), compared over the shorter length (at least `min_overlap` samples, aligned
    at the start). Tolerances are max-abs: pos_tol m (z and the horizontal path after the
    fitted yaw + shift), vel_tol m/s, omega_tol rad/s (body frame), rot_tol (rotation
    matrix entries).

    Candidates come from a k-d tree on the first `min_overlap` samples of invariant
    signatures (z, |v_xy|, vz, body omega, tilt), each scaled by its tolerance; each
    candidate is confirmed over the whole overlap, the yaw fitted in closed form
    (Procrustes on the horizontal path, the body axes' horizontal parts pinning it when
    the path barely moves).

    On /work/shared/data/cube_tosses.npz (390 tosses) this finds 19 disjoint pairs (an
    exhaustive search, time lags included, finds no other copy; the README's 33 pairs are
    of the original 570 tosses). Twins match to float rounding: <= 1.7e-16 m on the path
    after the fitted yaw + shift, <= 9e-16 in every other channel (yaws -152..169 deg, shift
    0, none a pure duplicate). Nearest non-twins, over the shorter length: path residual
    after the best path-only yaw + shift 1.4 mm (14x pos_tol), z 2.7 mm, body omega
    3.3 rad/s, |v_xy| or vz 0.18 m/s; in the combined test the closest non-twin is 4200x
    outside the tolerances. Scaling all four default tolerances by any factor from 1e-11
    to 1e3 gives the same 19 pairs.
    Runtime about 0.035 s."""
    cols = _columns(rec.state_names)
    ids, xs = [], []
    for eid, idx in rec.episodes():
        if len(idx) >= min_overlap:
            ids.append(int(eid))
            xs.append(np.asarray(rec.x[idx][:, cols], float))
    if len(xs) < 2:
        return []
    k = int(min_overlap)
    scale = np.array([pos_tol, vel_tol, vel_tol, omega_tol, omega_tol, omega_tol,
                      rot_tol, rot_tol, rot_tol])
    sig = np.stack([(_invariants(x[:k], quat_to_matrix(x[:k, 3:7])) / scale).ravel()
                    for x in xs])
    candidates = cKDTree(sig).query_pairs(r=1.0 + 1e-9, p=np.inf, output_type="ndarray")
    pairs = []
    for i, j in candidates:
        d = pair_distance(xs[i], xs[j])
        if (d["z"] <= pos_tol and d["xy"] <= pos_tol and d["speed"] <= vel_tol
                and d["vxy"] <= vel_tol and d["omega"] <= omega_tol
                and d["tilt"] <= rot_tol and d["rot"] <= rot_tol):
            a, b = ids[i], ids[j]
            pairs.append((min(a, b), max(a, b)))
    return sorted(set(pairs))


def twin_groups(episode_ids, pairs) -> list[list[int]]:
    """Connected components of `pairs` over `episode_ids` (ids not in any pair are
    singletons; pair members not in episode_ids are ignored). Sorted lists, sorted by
    their smallest id."""
    ids = sorted({int(e) for e in episode_ids})
    parent = {e: e for e in ids}

    def root(e):
        while parent[e] != e:
            parent[e] = parent[parent[e]]
            e = parent[e]
        return e

    for a, b in pairs:
        a, b = int(a), int(b)
        if a in parent and b in parent:
            ra, rb = root(a), root(b)
            if ra != rb:
                parent[max(ra, rb)] = min(ra, rb)
    groups: dict[int, list[int]] = {}
    for e in ids:
        groups.setdefault(root(e), []).append(e)
    return sorted(groups.values(), key=lambda g: g[0])


def split_episodes(episode_ids, held_out_fraction: float = 0.3, seed: int = 0,
                   groups=None) -> tuple[list[int], list[int]]:
    """Deterministic random split by episode: (train_ids, held_out_ids), sorted ints.

    `groups` (e.g. twin_groups(ids, find_twins(rec))) are kept whole on one side; ids in no
    group are singletons. Groups are shuffled with `seed` and taken into the held-out set
    while that brings its size closer to round(held_out_fraction * n)."""
    if not 0.0 <= held_out_fraction <= 1.0:
        raise ValueError(f"held_out_fraction must be in [0, 1], got {held_out_fraction}")
    ids = sorted({int(e) for e in episode_ids})
    units = twin_groups(ids, []) if groups is None else None
    if groups is not None:
        seen, units = set(), []
        for g in groups:
            g = sorted({int(e) for e in g} & (set(ids) - seen))
            if g:
                units.append(g)
                seen.update(g)
        units += [[e] for e in ids if e not in seen]
        units.sort(key=lambda g: g[0])
    target = round(held_out_fraction * len(ids))
    order = np.random.default_rng(seed).permutation(len(units))
    held, n_held = [], 0
    for u in order:
        size = len(units[u])
        if abs(n_held + size - target) < abs(n_held - target):
            held += units[u]
            n_held += size
    held_set = set(held)
    return [e for e in ids if e not in held_set], sorted(held)


METRICS = ("position_pct_mean", "position_pct_final", "orientation_deg_mean",
           "orientation_deg_final")
DT_TOLERANCE = 0.05      # relative spread of sample steps allowed within a recording


def recording_episodes(rec, episode_ids=None) -> tuple[dict, float]:
    """({episode id: (t [T], x [T, 13])}, dt) after checking the recording fits a
    rigid-object model: state names, at least two rows per episode, a uniform step."""
    if list(rec.state_names) != list(RECORDING_STATE_NAMES):
        raise UserError(f"recording state names {list(rec.state_names)} do not match the "
                        f"rigid object's {list(RECORDING_STATE_NAMES)}")
    episodes = {int(e): idx for e, idx in rec.episodes()}
    if episode_ids is not None:
        missing = sorted(set(episode_ids) - set(episodes))
        if missing:
            raise UserError(f"episodes not in the recording: {missing[:10]}")
        episodes = {e: episodes[e] for e in episode_ids}
    steps = []
    for e, idx in episodes.items():
        if len(idx) < 2:
            raise UserError(f"episode {e} has {len(idx)} row; an episode needs at least 2")
        steps.append(np.diff(rec.t[idx]))
    steps = np.concatenate(steps)
    dt = float(np.median(steps))
    if np.max(np.abs(steps - dt)) > DT_TOLERANCE * dt:
        raise UserError(f"the recording's time step is not uniform (median {dt:g} s, "
                        f"range {steps.min():g}-{steps.max():g} s); resample it first")
    return {e: (rec.t[idx], rec.x[idx]) for e, idx in episodes.items()}, dt


def episode_errors(x_model: np.ndarray | None, x_data: np.ndarray, size: float) -> dict:
    """The per-episode metrics of METRICS for two [T, 13] recording-layout arrays. A model
    rollout that failed (x_model None: its LCP had no solution, or it went non-finite)
    scores FAILED_SCORE % and 180 deg, as the fit scores it, and is marked `failed`."""
    if x_model is None:
        return {"position_pct_mean": FAILED_SCORE, "position_pct_final": FAILED_SCORE,
                "orientation_deg_mean": 180.0, "orientation_deg_final": 180.0, "failed": True}
    pos = np.linalg.norm(x_model[:, 0:3] - x_data[:, 0:3], axis=1) / size * 100.0
    ori = orientation_error_deg(x_model[:, 3:7], x_data[:, 3:7])
    return {"position_pct_mean": float(pos.mean()), "position_pct_final": float(pos[-1]),
            "orientation_deg_mean": float(ori.mean()), "orientation_deg_final": float(ori[-1])}


def summarise(per_episode: list[dict]) -> dict:
    out = {"episodes": len(per_episode),
           "failed": sum(bool(e.get("failed")) for e in per_episode)}
    for key in METRICS:
        v = np.array([e[key] for e in per_episode])
        out[f"{key}_median"] = float(np.median(v))
        out[f"{key}_mean"] = float(np.mean(v))
        out[f"{key}_p90"] = float(np.percentile(v, 90))
    return out
