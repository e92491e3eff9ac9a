"""Synthetic tosses with known physics, for checking the rigid-object diagnosis.

Tosses of the scenario's box are simulated by the `drake` model backend
(tools/diagnosis/backends/drake_backend.py: Drake's SAP plant, 8 corner spheres on a half space, at
the recording's dt / 4) whose friction, table height or size differ from the scenario by
known amounts; the diagnosis of the scenario's model (either backend) on them should name
those effects with intervals around them.
Starts are drawn like the real cube tosses: 10-16 cm up, 0.4-1.2 m/s sideways, falling
at up to 0.5 m/s, spinning at up to 6 rad/s about a random axis, a random orientation.
"""
from __future__ import annotations

import copy

import numpy as np

from adaptive_c3.models.rigid_object import RECORDING_STATE_NAMES
from adaptive_c3.tools.recording import Recording


def random_toss_start(rng) -> np.ndarray:
    """One recording-layout start state."""
    x = np.zeros(13)
    heading = rng.uniform(0, 2 * np.pi)
    speed = rng.uniform(0.4, 1.2)
    x[0:3] = [rng.uniform(-0.2, 0.2), rng.uniform(-0.2, 0.2), rng.uniform(0.10, 0.16)]
    q = rng.normal(size=4)
    x[3:7] = q / np.linalg.norm(q)
    x[7:10] = [speed * np.cos(heading), speed * np.sin(heading), -rng.uniform(0.0, 0.5)]
    axis = rng.normal(size=3)
    x[10:13] = axis / np.linalg.norm(axis) * rng.uniform(0.0, 6.0)
    return x


def truth_scenario(scenario, friction=None, table_offset=0.0, size_offset=0.0, **drake):
    """The scenario Drake simulates as the truth (the model's scenario is not changed);
    drake: other fields of its `drake` section (e.g. torsional_friction=0.02)."""
    s = copy.deepcopy(scenario)
    if friction is not None:
        s.drake.friction = float(friction)
    for key, value in drake.items():
        if not hasattr(s.drake, key):
            raise ValueError(f"no drake.{key} in the scenario")
        setattr(s.drake, key, value)
    s.patch.table_offset += float(table_offset)
    s.patch.size_offset += float(size_offset)
    return s


def concealed_tosses(scenario, episodes: int, steps: int, seed: int, dt: float = 1.0 / 148,
                     noise_m: float = 2e-4, **truth) -> Recording:
    """A recording of `episodes` tosses of `steps` + 1 samples from Drake SAP with the truth
    (truth_scenario's friction / table_offset / size_offset / drake fields), positions with noise_m Gaussian noise and
    velocities as the backward differences of the noisy positions (as the real data)."""
    from adaptive_c3.tools.diagnosis.backends.drake_backend import DrakeRigidSimulator
    rng = np.random.default_rng(seed)
    sim = DrakeRigidSimulator(truth_scenario(scenario, **truth), dt)
    xs, ts, eps = [], [], []
    for e in range(episodes):
        x = sim.rollout(random_toss_start(rng), steps)
        x[:, 0:3] += rng.normal(0.0, noise_m, size=(len(x), 3))
        x[1:, 7:10] = np.diff(x[:, 0:3], axis=0) / dt
        xs.append(x)
        ts.append(np.arange(steps + 1) * dt)
        eps.append(np.full(steps + 1, e))
    return Recording(t=np.concatenate(ts), x=np.vstack(xs), u=np.zeros((len(eps) * (steps + 1), 0)),
                     state_names=list(RECORDING_STATE_NAMES), input_names=[],
                     episode=np.concatenate(eps))
