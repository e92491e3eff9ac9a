"""Drake's own simulation of a rigid_object scenario (tools/diagnosis/tasks/rigid_object/drake_baseline.py)."""
from __future__ import annotations

import numpy as np
import pytest

from adaptive_c3.models.rigid_object import orientation_error_deg
from adaptive_c3.scenarios.rigid_object_schema import RigidObjectScenario
from adaptive_c3.tools.diagnosis.tasks.rigid_object.drake_baseline import (DrakeRigidSimulator, score_episodes,
                                                        tune_drake, with_drake)

DT = 1.0 / 148
HALF = 0.0524


def _toss(z=1.0):
    x0 = np.zeros(13)
    x0[:3] = [0.0, 0.0, z]
    x0[3] = 1.0
    x0[7:10] = [0.5, -0.2, 1.0]
    x0[10:13] = [1.0, 2.0, 3.0]       # body frame
    return x0


@pytest.mark.parametrize("time_step", [0.0, DT / 3])
def test_free_flight_is_the_discrete_parabola_and_spin_is_constant(time_step):
    sim = DrakeRigidSimulator(with_drake(RigidObjectScenario(), time_step=time_step), DT)
    X = sim.rollout(_toss(), 20)
    assert X.shape == (21, 13)
    # the start's velocity is a backward difference over one recording step, v(t0 - DT/2):
    # whatever SAP's step h (0 = DT / 4), the samples lie on the exact parabola of
    # v(t0) = vz - g DT / 2 (the rollout starts SAP from v(t0 - h / 2))
    h = sim.time_step
    assert h == pytest.approx(DT / 4 if time_step == 0 else time_step)
    t = np.arange(21) * DT
    assert np.abs(X[:, 2] - (1.0 + (1.0 - 9.81 * DT / 2) * t - 9.81 * t ** 2 / 2)).max() < 1e-6
    assert np.abs(X[:, 0:2] - np.outer(t, [0.5, -0.2])).max() < 1e-6
    assert np.abs(X[:, 7:10] - np.c_[0.5 + 0 * t, -0.2 + 0 * t, 1.0 - 9.81 * t]).max() < 1e-9
    # a cube is torque-free and symmetric: the body-frame angular velocity stays put
    assert np.abs(X[:, 10:13] - [1.0, 2.0, 3.0]).max() < 1e-6
    assert orientation_error_deg(X[-1, 3:7], X[0, 3:7]) > 10.0     # it did turn


def test_a_flat_cube_dropped_on_the_table_rests_on_its_face():
    sim = DrakeRigidSimulator(RigidObjectScenario(), DT)
    x0 = np.zeros(13)
    x0[2], x0[3] = HALF + 0.02, 1.0
    X = sim.rollout(x0, 200)
    assert X[-1, 2] == pytest.approx(HALF, abs=2e-3)      # SAP's penetration: below 2 mm
    assert np.linalg.norm(X[-1, 7:13]) < 0.05
    assert orientation_error_deg(X[-1, 3:7], [1, 0, 0, 0]) < 1.0
    # the context is reused: a second rollout from the same state is the same
    assert np.array_equal(sim.rollout(x0, 200), X)


def _sliding_episodes(scenario, n=60):
    """Three low tosses that land and slide, simulated by Drake with the scenario's knobs."""
    sim = DrakeRigidSimulator(scenario, DT)
    episodes = []
    for vx, vy, wz in [(1.2, 0.0, 2.0), (0.8, 0.6, -3.0), (-1.0, 0.4, 0.0)]:
        x0 = np.zeros(13)
        x0[2], x0[3] = HALF + 0.01, 1.0
        x0[7:10] = [vx, vy, -0.3]
        x0[12] = wz
        episodes.append(sim.rollout(x0, n))
    return episodes


def test_tune_drake_moves_friction_towards_the_data_and_leaves_the_scenario_alone():
    scenario = RigidObjectScenario()          # contact.friction 0.18, drake defaults
    episodes = _sliding_episodes(with_drake(scenario, friction=0.3))
    default = score_episodes(DrakeRigidSimulator(scenario, DT), episodes)
    info = {}
    values, score = tune_drake(scenario, episodes, DT, knobs=("friction",), max_evals=12,
                               info=info)
    assert set(values) == {"friction"} and info["evaluations"] <= 12
    assert default > 1.0 and score < 0.5 * default
    assert abs(values["friction"] - 0.3) < abs(0.18 - 0.3)
    assert scenario == RigidObjectScenario()  # not mutated
    assert score == pytest.approx(score_episodes(
        DrakeRigidSimulator(with_drake(scenario, **values), DT), episodes))


def test_tune_drake_flags_a_knob_without_effect():
    """A toss high above the table never touches it: the contact stiffness cannot matter."""
    scenario = RigidObjectScenario()
    x0 = np.zeros(13)
    x0[2], x0[3], x0[7] = 1.0, 1.0, 0.3
    episodes = [DrakeRigidSimulator(scenario, DT).rollout(x0, 20)]
    info = {}
    values, score = tune_drake(scenario, episodes, DT, knobs=("point_stiffness",),
                               max_evals=6, grid_points=3, info=info)
    assert info["no_effect"] == ["point_stiffness"]
    assert values == {"point_stiffness": 0.0} and score == pytest.approx(0.0, abs=1e-9)
    with pytest.raises(ValueError, match="unknown knobs"):
        tune_drake(scenario, episodes, DT, knobs=("restitution",))
