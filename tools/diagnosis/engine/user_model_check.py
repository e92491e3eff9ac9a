"""An answer is not confident when its own held-out rollouts are clearly worse than the
user's model.

The report scores the user's model (`before`) and the model with the answer (`after`:
each fold's episodes rolled out with the values fitted without them) on the same
held-out rollout windows. The choice itself was judged on other windows (a free-ball
effect on the free windows' 0.3 s rollouts, any effect on a sparse subset on Drake's
plant), so the two can disagree. On the thirtieth set's 100935 (a rolling resistance of
3.2 mm, one recording) a drag was named and the report's own rollouts went from 2.04 to
4.14 noise units; on the thirty-first set's 101008 (a rolling resistance of 0.98 mm) a
drag of 13 N s/m went from 1.14 to 3.71. On the right answers of the twenty-sixth to
thirty-first sets the largest such rise was 1.39 to 1.54 (100812, a constant force).

The test: per episode (the cluster of the report's windows), the SSR in noise units
before and after, and the paired z of the rise (evidence.Z_AMBIG, the bar of the other
consistency tests). An answer clearly worse than the user's model gets `none` beside it
in the set: the answer is ambiguous, and the follow-up asks what tells the two apart.
"""
from __future__ import annotations

import numpy as np


def per_episode_ssr(err: np.ndarray, episodes: np.ndarray, floor: np.ndarray,
                    scored: np.ndarray) -> dict:
    """{episode: SSR in noise units} of rollout errors err [W, H, n] whose windows belong
    to `episodes` [W]; floor [H, n] the noise floor, scored [n] the states that count."""
    per_w = np.sum(((err / floor)[..., scored]) ** 2, axis=(1, 2))
    ids, inv = np.unique(episodes, return_inverse=True)
    return dict(zip(ids.tolist(), np.bincount(inv, weights=per_w).tolist()))


def worse_than_user(judged: dict, chosen, before: dict, after: dict, none_row: dict,
                    chosen_row: dict) -> dict | None:
    """`none` joins the set when the answer's held-out rollouts (after: {episode: SSR})
    are clearly worse than the user's model's (before) across episodes (paired z >=
    Z_AMBIG); recorded as judged["against_user_model"] = {z, before, after, episodes,
    joined}. Returns that record (None when nothing was chosen or too few episodes)."""
    from adaptive_c3.tools.diagnosis.engine.evidence import Z_AMBIG, _join
    from adaptive_c3.tools.diagnosis.engine.fit import paired_z
    eps = sorted(set(before) & set(after))
    if chosen is None or len(eps) < 3:
        return None
    b = np.array([before[e] for e in eps])
    a = np.array([after[e] for e in eps])
    z = float(paired_z(a, b))              # positive: `before`, the user's model, is better
    joined = z >= Z_AMBIG
    record = dict(z=z, before=float(b.sum()), after=float(a.sum()), episodes=len(eps),
                  joined=bool(joined))
    judged["against_user_model"] = record
    if joined:
        judged.setdefault("ambiguous", [])
        judged.setdefault("separating_excitation", [])
        _join(judged, chosen_row, none_row)
    return record
