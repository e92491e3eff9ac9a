"""Recordings (.npz): the file format runs write and `diagnose` reads.

Keys (the recording format; docs/diagnosis.md): t [T] s; x [T, n]; u [T, m]; state_names [n];
input_names [m]; optional scenario (YAML text), episode [T] integer ids, and
any extra arrays a run wants to keep (lambda, r_comp, ...).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np


class RecordingError(ValueError):
    """A recording is malformed; the message is one line for the user."""


@dataclass
class Recording:
    t: np.ndarray
    x: np.ndarray
    u: np.ndarray
    state_names: list
    input_names: list
    scenario: str = ""
    episode: np.ndarray | None = None
    extras: dict = field(default_factory=dict)

    def episode_ids(self) -> np.ndarray:
        """[T] each row's episode id (0 throughout for a recording without ids)."""
        return np.zeros(len(self.t), np.int64) if self.episode is None \
            else np.asarray(self.episode)

    def episodes(self):
        """Yield (episode id, index array) per episode, in order of first appearance."""
        if self.episode is None:
            yield 0, np.arange(len(self.t))
            return
        for eid in dict.fromkeys(self.episode.tolist()):
            yield eid, np.flatnonzero(self.episode == eid)


def save_recording(path, rec: Recording) -> Path:
    path = Path(path)
    arrays = dict(t=np.asarray(rec.t, float), x=np.asarray(rec.x, float),
                  u=np.asarray(rec.u, float),
                  state_names=np.asarray(rec.state_names, dtype=str),
                  input_names=np.asarray(rec.input_names, dtype=str))
    if rec.scenario:
        arrays["scenario"] = np.asarray(rec.scenario)
    if rec.episode is not None:
        arrays["episode"] = np.asarray(rec.episode, dtype=np.int64)
    for key, value in rec.extras.items():
        arrays[key] = np.asarray(value)
    _validate(arrays, str(path))
    np.savez_compressed(path, **arrays)
    return path


def concat_recordings(recs) -> Recording:
    """One recording holding every episode of recs in turn (episode ids renumbered so
    that they stay apart; a recording without ids is one episode). The state and input
    names must agree; extras are dropped (they need not exist in every recording) but
    one: `part` [T], the index in recs of the recording each row came from (the
    diagnosis tests a size on each recording alone as well as on all of them)."""
    recs = list(recs)
    first = recs[0]
    for r in recs[1:]:
        if list(r.state_names) != list(first.state_names) or \
                list(r.input_names) != list(first.input_names):
            raise RecordingError("recordings to combine must have the same state and input "
                                 "names")
    eps, offset = [], 0
    for r in recs:
        _, ids = np.unique(r.episode_ids(), return_inverse=True)
        eps.append(ids + offset)
        offset += int(ids.max()) + 1 if len(ids) else 0
    return Recording(t=np.concatenate([r.t for r in recs]),
                     x=np.concatenate([r.x for r in recs]),
                     u=np.concatenate([r.u for r in recs]),
                     state_names=list(first.state_names), input_names=list(first.input_names),
                     scenario=first.scenario, episode=np.concatenate(eps),
                     extras=dict(part=np.concatenate([np.full(len(r.t), i, np.int64)
                                                      for i, r in enumerate(recs)])))


def load_recording(path, allow_nonfinite: bool = False) -> Recording:
    path = Path(path)
    if not path.is_file():
        raise RecordingError(f"recording not found: {path}")
    try:
        with np.load(path, allow_pickle=False) as f:
            arrays = {k: f[k] for k in f.files}
    except Exception as e:  # zip/npy parse errors of many kinds
        raise RecordingError(f"{path}: not a readable .npz recording ({type(e).__name__})")
    _validate(arrays, str(path), allow_nonfinite)
    extras = {k: v for k, v in arrays.items()
              if k not in ("t", "x", "u", "state_names", "input_names", "scenario", "episode")}
    return Recording(t=arrays["t"].astype(float), x=arrays["x"].astype(float),
                     u=arrays["u"].astype(float),
                     state_names=[str(s) for s in arrays["state_names"]],
                     input_names=[str(s) for s in arrays["input_names"]],
                     scenario=str(arrays["scenario"]) if "scenario" in arrays else "",
                     episode=arrays.get("episode"), extras=extras)


def _validate(a: dict, where: str, allow_nonfinite: bool = False) -> None:
    for key in ("t", "x", "u", "state_names", "input_names"):
        if key not in a:
            raise RecordingError(f"{where}: missing array '{key}'")
    t, x, u = a["t"], a["x"], a["u"]
    if t.ndim != 1 or len(t) < 2:
        raise RecordingError(f"{where}: t must be 1-D with at least 2 samples, got shape {t.shape}")
    T = len(t)
    if x.ndim != 2 or x.shape[0] != T:
        raise RecordingError(f"{where}: x must have shape [T={T}, n], got {x.shape}")
    if u.ndim != 2 or u.shape[0] != T:
        raise RecordingError(f"{where}: u must have shape [T={T}, m], got {u.shape}")
    if a["state_names"].shape != (x.shape[1],):
        raise RecordingError(f"{where}: state_names has {a['state_names'].size} names, x has {x.shape[1]} columns")
    if a["input_names"].shape != (u.shape[1],):
        raise RecordingError(f"{where}: input_names has {a['input_names'].size} names, u has {u.shape[1]} columns")
    for key in ("t", "x", "u"):
        if not np.issubdtype(a[key].dtype, np.number):
            raise RecordingError(f"{where}: '{key}' is not numeric")
        if not allow_nonfinite and not np.all(np.isfinite(a[key])):
            bad = [int(i) for i in np.argwhere(~np.isfinite(a[key]))[0]]
            names = {"x": a["state_names"], "u": a["input_names"]}.get(key)
            column = f", {str(names[bad[1]])}" if names is not None else ""
            raise RecordingError(f"{where}: '{key}' has non-finite values (first at {key}"
                                 f"[{', '.join(map(str, bad))}]: sample {bad[0]}{column})")
    ep = a.get("episode")
    if ep is not None and (ep.shape != (T,) or not np.issubdtype(ep.dtype, np.integer)):
        raise RecordingError(f"{where}: episode must be [T={T}] integers, got {ep.shape} {ep.dtype}")
    # time increases within each episode
    ids = ep if ep is not None else np.zeros(T, int)
    same = ids[1:] == ids[:-1]
    if np.any(np.diff(t)[same] <= 0):
        raise RecordingError(f"{where}: t must increase strictly within each episode")
