"""Twin episodes (copies up to yaw + horizontal shift) and the group-respecting split."""
from pathlib import Path

import numpy as np
import pytest

from adaptive_c3.tools.diagnosis.tasks.rigid_object.episodes import (
    find_twins, fit_yaw_shift, pair_distance, split_episodes, twin_groups)
from adaptive_c3.tools.recording import Recording, load_recording

NAMES = ["x", "y", "z", "qw", "qx", "qy", "qz", "vx", "vy", "vz", "wx", "wy", "wz"]
DT = 1 / 148
REAL = Path(__file__).resolve().parents[2] / "shared" / "data" / "cube_tosses.npz"


def _qmul(a, b):
    aw, ax, ay, az = np.moveaxis(a, -1, 0)
    bw, bx, by, bz = np.moveaxis(b, -1, 0)
    return np.stack([aw * bw - ax * bx - ay * by - az * bz,
                     aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw], -1)


def _toss(rng, T):
    """A tumbling ballistic toss: [T, 13] in NAMES order, v the backward difference."""
    t = np.arange(T) * DT
    p = rng.uniform(-0.3, 0.3, 3) + np.array([0, 0, 0.5])
    v0 = rng.uniform(-1, 1, 3)
    pos = p + v0 * t[:, None] + 0.5 * np.array([0, 0, -9.81]) * t[:, None] ** 2
    vel = np.vstack([v0, np.diff(pos, axis=0) / DT])
    w = rng.uniform(-8, 8, 3) + 0.5 * np.sin(5 * t)[:, None]     # body frame, time-varying
    q = [rng.normal(size=4)]
    q[0] /= np.linalg.norm(q[0])
    for k in range(1, T):                                         # qdot = 0.5 q * [0, w]
        ang = np.linalg.norm(w[k]) * DT
        dq = np.r_[np.cos(ang / 2), np.sin(ang / 2) * w[k] / np.linalg.norm(w[k])]
        q.append(_qmul(q[-1], dq))
    return np.column_stack([pos, np.array(q), vel, w])


def _yaw_copy(x, yaw, shift):
    """x rotated by yaw about world z and shifted horizontally; body omega unchanged."""
    c, s = np.cos(yaw), np.sin(yaw)
    R = np.array([[c, -s], [s, c]])
    y = x.copy()
    y[:, :2] = x[:, :2] @ R.T + shift
    y[:, 7:9] = x[:, 7:9] @ R.T
    y[:, 3:7] = _qmul(np.array([np.cos(yaw / 2), 0, 0, np.sin(yaw / 2)]), x[:, 3:7])
    y[:, 3:7] *= -1                 # the sign of a quaternion carries no information
    return y


def _recording(episodes: dict):
    ids = list(episodes)
    xs = [episodes[e] for e in ids]
    return Recording(t=np.concatenate([np.arange(len(x)) * DT for x in xs]), x=np.vstack(xs),
                     u=np.zeros((sum(map(len, xs)), 0)), state_names=NAMES, input_names=[],
                     episode=np.concatenate([np.full(len(x), e) for x, e in zip(xs, ids)]))


@pytest.fixture(scope="module")
def synthetic():
    rng = np.random.default_rng(3)
    a = _toss(rng, 90)
    twin = _yaw_copy(a, 2.1, np.array([0.4, -0.25]))
    bent = _yaw_copy(a, -0.7, np.array([0.1, 0.2]))
    bent[50:, :2] += 0.002          # path jumps 2.8 mm; every invariant still identical
    spun = _yaw_copy(a, 1.0, np.array([0.0, 0.3]))
    spun[:, 10:13] *= 1.003         # omega off by < 0.03 rad/s
    lifted = _yaw_copy(a, 0.3, np.zeros(2))
    lifted[60:, 2] += 0.001         # 1 mm higher late in the toss
    eps = {10: a, 3: _toss(rng, 80), 7: twin, 5: bent, 12: spun, 8: lifted, 1: _toss(rng, 120)}
    return _recording(eps)


def test_finds_exactly_the_yaw_shift_copy(synthetic):
    assert find_twins(synthetic) == [(7, 10)]
    idx = dict(synthetic.episodes())
    d = pair_distance(synthetic.x[idx[10]], synthetic.x[idx[7]])
    assert d["yaw"] == pytest.approx(2.1) and d["shift"] == pytest.approx([0.4, -0.25])
    assert d["xy"] < 1e-12 and d["rot"] < 1e-12


def test_exact_and_truncated_duplicates():
    rng = np.random.default_rng(5)
    a, b = _toss(rng, 60), _toss(rng, 70)
    rec = _recording({0: a, 1: b, 2: a.copy(), 3: b[:45].copy(), 4: a[:10].copy()})
    # episode 4 is a copy too but shorter than min_overlap, so not compared
    assert find_twins(rec) == [(0, 2), (1, 3)]
    assert find_twins(rec, min_overlap=10) == [(0, 2), (0, 4), (1, 3), (2, 4)]


def test_fit_yaw_shift_closed_form():
    rng = np.random.default_rng(0)
    p = rng.normal(size=(30, 2))
    R = np.array([[np.cos(-2.5), -np.sin(-2.5)], [np.sin(-2.5), np.cos(-2.5)]])
    yaw, shift, res = fit_yaw_shift(p, p @ R.T + [1.0, -2.0])
    assert yaw == pytest.approx(-2.5) and shift == pytest.approx([1.0, -2.0]) and res < 1e-12


def test_twin_groups_are_connected_components():
    assert twin_groups([5, 1, 2, 3, 4, 9], [(1, 2), (2, 3), (5, 9), (7, 8)]) == \
        [[1, 2, 3], [4], [5, 9]]


def test_split_keeps_groups_whole_and_is_deterministic():
    ids = list(range(100))
    groups = twin_groups(ids, [(2 * k, 2 * k + 1) for k in range(0, 40, 3)] + [(90, 91), (91, 92)])
    train, held = split_episodes(ids, 0.3, seed=4, groups=groups)
    assert (train, held) == split_episodes(ids[::-1], 0.3, seed=4, groups=groups)
    assert sorted(train + held) == ids and not set(train) & set(held)
    assert train == sorted(train) and held == sorted(held)
    assert all(type(e) is int for e in train + held)
    assert abs(len(held) - 30) <= 1
    for g in groups:
        assert set(g) <= set(train) or set(g) <= set(held)
    assert split_episodes(ids, 0.3, seed=5, groups=groups) != (train, held)
    train0, held0 = split_episodes(np.arange(10), 0.3)
    assert len(held0) == 3 and len(train0) == 7
    assert split_episodes(ids, 0.0) == (ids, []) and split_episodes(ids, 1.0) == ([], ids)


@pytest.mark.skipif(not REAL.is_file(), reason=f"{REAL} not present")
def test_real_tosses():
    rec = load_recording(REAL)
    pairs = find_twins(rec)
    # The file holds 19 such pairs (the README's 33 are of the original 570 tosses).
    assert 15 <= len(pairs) <= 40
    idx = dict(rec.episodes())
    for a, b in pairs:
        xa, xb = rec.x[idx[a]], rec.x[idx[b]]
        n = min(len(xa), len(xb))
        yaw, shift, res = fit_yaw_shift(xa[:n, :2], xb[:n, :2])
        assert res < 1e-4
        assert np.abs(xa[:n, 2] - xb[:n, 2]).max() < 1e-4
        assert np.abs(xa[:n, 10:] - xb[:n, 10:]).max() < 1e-3
    ids = sorted(idx)
    groups = twin_groups(ids, pairs)
    train, held = split_episodes(ids, 0.3, seed=0, groups=groups)
    assert abs(len(held) - 0.3 * len(ids)) <= 2
    for a, b in pairs:
        assert (a in held) == (b in held)
