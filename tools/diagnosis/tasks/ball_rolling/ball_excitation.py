"""The push gait of ball-rolling diagnosis recordings, and the changes to it that
`diagnose` proposes when the data cannot separate two effects.

One push per episode: the EE lifts over the ball, lowers onto its top, presses and
rolls it along a smooth path, lifts and hovers while the ball rolls on. `Excitation`
holds what a user would change: the press depth, the push length and peak
acceleration, the ball's speed when the EE lets go (0: the push ends at rest, so the
ball stops under the EE; > 0: the EE lifts off while still moving and the ball coasts
freely; release_fraction: of the pushes, the others end at rest), push directions
(random, or cycling +x, +y, -x, -y), the touch-down time, the number and length of
episodes. Positions in the world frame, m; speeds m/s; times s.

`Excitation.changed(**fields)` is what a proposal in the report holds
(`separating_excitation[i].excitation`), e.g. {"release_speed": [0.1, 0.2],
"duration_s": 2.4}.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, fields, replace

import numpy as np


@dataclass(frozen=True)
class Excitation:
    """The push gait. Ranges are (low, high): each push draws uniformly inside."""
    episodes: int = 15
    duration_s: float = 1.6
    press: tuple = (0.004, 0.007)          # m, how far the EE target goes below contact
    push_length: tuple = (0.03, 0.08)      # m, EE travel while rolling the ball
    peak_accel: tuple = (2.0, 10.0)        # m/s^2, of a push that ends at rest
    release_speed: tuple = (0.0, 0.0)      # m/s, the ball's speed when the EE lets go
    release_fraction: float = 1.0          # of the pushes, when release_speed > 0 (the
                                           # others end at rest)
    directions: str = "random"             # random | axes (+x, +y, -x, -y in turn)
    touchdown_s: float = 0.15              # s, the last 6 mm of the descent onto the top
    strike_fraction: float = 0.0           # of the episodes, strikes instead of pushes
    strike_speed: tuple = (0.2, 0.35)      # m/s, the EE's planned speed through a strike
    strike_angle: tuple = (50.0, 70.0)     # deg, contact normal from the EE's path

    def __post_init__(self):
        """A one-line ValueError for a gait no push can follow."""
        if int(self.episodes) != self.episodes or self.episodes < 1:
            raise ValueError(f"excitation episodes must be a whole number >= 1, got {self.episodes}")
        for name in ("duration_s", "touchdown_s"):
            if not np.isfinite(getattr(self, name)) or getattr(self, name) <= 0:
                raise ValueError(f"excitation {name} must be > 0, got {getattr(self, name)}")
        for name in ("press", "push_length", "peak_accel", "release_speed", "strike_speed",
                     "strike_angle"):
            r = getattr(self, name)
            if (len(r) != 2 or not np.all(np.isfinite(r)) or r[0] < 0 or r[1] < r[0]
                    or (name != "release_speed" and r[0] <= 0)):
                raise ValueError(f"excitation {name} must be a range [low, high] with "
                                 f"0 {'<=' if name == 'release_speed' else '<'} low <= high, "
                                 f"got {list(r)}")
        for name in ("release_fraction", "strike_fraction"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ValueError(f"excitation {name} must be in [0, 1], "
                                 f"got {getattr(self, name)}")
        if self.strike_angle[1] >= 85.0:
            raise ValueError(f"excitation strike_angle must stay below 85 deg (a strike that "
                             f"grazes the ball), got {list(self.strike_angle)}")
        if self.directions not in ("random", "axes"):
            raise ValueError(f"excitation directions must be random or axes, "
                             f"got {self.directions!r}")

    def changed(self, **kw) -> "Excitation":
        known = {f.name for f in fields(self)}
        bad = sorted(set(kw) - known)
        if bad:
            raise ValueError(f"unknown excitation fields {bad} (known: {sorted(known)})")
        return replace(self, **{k: tuple(v) if isinstance(v, list) else v
                                for k, v in kw.items()})

    def as_dict(self) -> dict:
        return {k: list(v) if isinstance(v, tuple) else v for k, v in asdict(self).items()}


def merge_changes(changes) -> dict:
    """One excitation change from several proposals, each asking for more of something:
    the most and the longest episodes, the faster release, the slower touch-down, axis
    directions if any asks for them; press and acceleration from the first that sets
    them; strike angles spanning every proposal's. When one asks for release pushes and
    another for pushes without a release (it sets the press or the acceleration, not the
    release), half the pushes release and half end at rest: release pushes are where the
    LCS reads a spurious mass or EE-ball friction, so a push-phase effect needs pushes
    that end at rest."""
    changes = list(changes)
    out: dict = {}
    releases = any(ch.get("release_speed", (0.0, 0.0))[1] > 0 for ch in changes)
    at_rest = any(("press" in ch or "peak_accel" in ch) and "release_speed" not in ch
                  for ch in changes)
    if releases and at_rest:
        out["release_fraction"] = 0.5
    for ch in changes:
        for k, v in ch.items():
            if k not in out:
                out[k] = v
            elif k in ("episodes", "duration_s", "touchdown_s"):
                out[k] = max(out[k], v)
            elif k == "release_speed":
                out[k] = max(out[k], v, key=lambda r: r[1])
            elif k == "directions" and v == "axes":
                out[k] = v
    # strikes asked at different angles (a friction's glancing ones, the default, and a
    # mass's head-on ones) span both
    angles = [tuple(ch.get("strike_angle", Excitation.strike_angle)) for ch in changes
              if ch.get("strike_fraction", 0.0) > 0]
    if len(set(angles)) > 1:
        out["strike_angle"] = [min(a[0] for a in angles), max(a[1] for a in angles)]
    return out


def quintic(p0, p1, T, t, v0=None, v1=None):
    """(position, velocity) at t of the quintic from p0 (velocity v0) to p1 (v1) in T
    with zero acceleration at both ends; v0 = v1 = 0 is the minimum-jerk path."""
    s = np.clip(t / T, 0.0, 1.0)
    if v0 is None and v1 is None:
        h = 10 * s**3 - 15 * s**4 + 6 * s**5
        dh = (30 * s**2 - 60 * s**3 + 30 * s**4) / T if t < T else 0.0
        return p0 + (p1 - p0) * h, (p1 - p0) * dh
    a = np.zeros_like(p0) if v0 is None else v0 * T
    b = np.zeros_like(p0) if v1 is None else v1 * T
    d = p1 - p0
    c3, c4, c5 = 10 * d - 6 * a - 4 * b, -15 * d + 8 * a + 7 * b, 6 * d - 3 * a - 3 * b
    p = p0 + a * s + c3 * s**3 + c4 * s**4 + c5 * s**5
    v = (a + 3 * c3 * s**2 + 4 * c4 * s**3 + 5 * c5 * s**4) / T
    if t >= T:
        return p1.copy(), (np.zeros_like(p0) if v1 is None else v1.copy())
    return p, v


class Pusher:
    """Plans EE target segments relative to the measured ball (one push, then hover).

    Segments are (p0, p1, T, v0, v1); v None means at rest."""

    LIFT_S = 0.12          # s, lift-off while moving (release pushes)
    STOP_S = 0.3           # s, the EE's horizontal stop after a release or a strike
    RUN_UP_M = 0.04        # m, a strike's run-up to its speed

    def __init__(self, rng, p, center, pushes: int = 1, excitation: Excitation = Excitation(),
                 episode: int = 0):
        self.rng, self.p, self.center = rng, p, np.asarray(center, float)
        self.ex, self.episode = excitation, episode
        self.segs: list = []
        self.pushes_left = pushes
        self.hold = None

    def _direction(self, ball) -> np.ndarray:
        if self.ex.directions == "axes":
            ang = 0.5 * np.pi * (self.episode % 4)
        else:
            to_c = self.center - ball[:2]
            spread = 0.9 if np.linalg.norm(to_c) > 0.06 else 2.5
            ang = np.arctan2(to_c[1], to_c[0]) + self.rng.normal(0, spread)
        return np.array([np.cos(ang), np.sin(ang), 0.0])

    def _plan(self, ee, ball, vball):
        rng, ex, R, r = self.rng, self.ex, self.p.ball_radius, self.p.ee_radius
        ball = ball + 0.3 * vball * np.array([1, 1, 0])       # where it will roughly be
        if ex.strike_fraction > 0 and (ex.strike_fraction >= 1.0
                                       or rng.random() < ex.strike_fraction):
            self.segs = self._strike(ee, ball)
            return
        d = self._direction(ball)
        high = 2 * R + r + 0.025
        # lower onto its top, press and roll it along d (the EE and the ball's top move
        # together: no sliding at either contact under mu = 1)
        press = rng.uniform(*ex.press)
        start = ball + np.array([0, 0, R + r - press]) - 0.004 * d
        near = start + np.array([0, 0, 0.006])
        L, a = rng.uniform(*ex.push_length), rng.uniform(*ex.peak_accel)
        release = 0.0
        if ex.release_speed[1] > 0 and (ex.release_fraction >= 1.0
                                        or rng.random() < ex.release_fraction):
            release = rng.uniform(*ex.release_speed)
        end = start + L * d
        over = near.copy()
        over[2] = high
        up = ee.copy()
        up[2] = max(ee[2], high)
        segs = [(ee.copy(), up, 0.12), (up, over, 0.25), (over, near, 0.2),
                (near, start, ex.touchdown_s)]
        if release <= 0.0:
            lift = end.copy()
            lift[2] = high
            segs += [(start, end, np.sqrt(5.77 * L / a)),    # min-jerk peak accel = a
                     (end, lift, 0.15)]
        else:            # the EE's top contact moves at twice the rolling ball's speed
            v = 2.0 * release * d
            lift = end + v * self.LIFT_S
            lift[2] = high
            stop = lift + 0.5 * v * self.STOP_S
            segs += [(start, end, 1.5 * L / (2.0 * release), None, v),
                     (end, lift, self.LIFT_S, v, v), (lift, stop, self.STOP_S, v, None)]
        self.segs = [list(s) + [None] * (5 - len(s)) for s in segs]

    def _strike(self, ee, ball) -> list:
        """A glancing strike: the EE, its centre at the ball's centre height, runs up to
        strike_speed along d on a line offset sideways so that the contact normal is
        strike_angle from d, passes the ball, stops and lifts. The ball leaves along the
        normal plus what friction adds along d, and the EE's speed drops by what it gave:
        the ball's mass sets the split of the normal impulse, the EE-ball friction (up to
        its mu) the tangential one. Returns the segments (p0, p1, T, v0, v1)."""
        rng, ex, R, r = self.rng, self.ex, self.p.ball_radius, self.p.ee_radius
        d = self._direction(ball)
        side = np.array([-d[1], d[0], 0.0]) * (1.0 if rng.random() < 0.5 else -1.0)
        theta = np.radians(rng.uniform(*ex.strike_angle))
        speed = rng.uniform(*ex.strike_speed)
        reach = R + r
        centre = np.array([ball[0], ball[1], ball[2]])
        line = centre + reach * np.sin(theta) * side           # the EE centre's path
        run_up = self.RUN_UP_M
        start = line - (reach * np.cos(theta) + 0.01 + run_up) * d
        fast = start + run_up * d                                # strike_speed from here
        past = line + (reach * np.cos(theta) + 0.03) * d
        stop = past + 0.5 * speed * self.STOP_S * d
        high = 2 * R + r + 0.025
        up, above, lift = ee.copy(), start.copy(), stop.copy()
        up[2] = max(ee[2], high)
        above[2] = lift[2] = high
        v = speed * d
        segs = [(ee.copy(), up, 0.12), (up, above, 0.25), (above, start, 0.3),
                (start, fast, 2.0 * run_up / speed, None, v),
                (fast, past, float(np.linalg.norm(past - fast)) / speed, v, v),
                (past, stop, self.STOP_S, v, None), (stop, lift, 0.15)]
        return [list(s) + [None] * (5 - len(s)) for s in segs]

    def target(self, t_in_seg, ee, ball, vball):
        """(p_ref, v_ref) - plans a new push when the last one ends."""
        if self.hold is not None:
            return self.hold, np.zeros(3)
        if not self.segs:
            self.pushes_left -= 1
            self._plan(ee, ball, vball)
            self.t0 = t_in_seg
        while self.segs:
            p0, p1, T, v0, v1 = self.segs[0]
            tau = t_in_seg - self.t0
            if tau <= T:
                return quintic(p0, p1, T, tau, v0, v1)
            self.t0 += T
            last = self.segs.pop(0)[1]
            if not self.segs and self.pushes_left <= 0:
                self.hold = last
        if self.hold is not None:            # pushes done: hover, the ball rolls on
            return self.hold, np.zeros(3)
        self.pushes_left -= 1
        self._plan(ee, ball, vball)
        self.t0 = t_in_seg
        return self.target(t_in_seg, ee, ball, vball)
