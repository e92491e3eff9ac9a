"""The drake backend's contact geometry and contact torques (issue 30): corner spheres vs
one box, torsional friction and rolling resistance as a force element driven by the
plant's own normal force."""
from __future__ import annotations

import numpy as np
import pytest

from adaptive_c3.scenarios.common import ScenarioError
from adaptive_c3.scenarios.rigid_object_schema import (RigidObjectScenario,
                                                       validate_rigid_object)
from adaptive_c3.tools.diagnosis.backends.contact_torques import contact_torque
from adaptive_c3.tools.diagnosis.backends.drake_backend import DrakeRigidSimulator
from adaptive_c3.tools.diagnosis.tasks.rigid_object.drake_baseline import with_drake

DT = 1.0 / 148
MASS, SIDE = 0.37, 0.1048
I_CUBE = MASS * SIDE ** 2 / 6            # kg m^2, a solid cube about any centre axis


def _spinning_on_a_face(steps: int, wz: float = 5.0, **drake):
    """A cube resting on a face, spinning at wz rad/s about the vertical."""
    sim = DrakeRigidSimulator(with_drake(RigidObjectScenario(), **drake), DT)
    x0 = np.zeros(13)
    x0[2], x0[3], x0[12] = SIDE / 2, 1.0, wz
    X = sim.rollout(x0, steps)
    contacts = sim.plant.get_contact_results_output_port().Eval(sim.plant_context)
    return X, contacts.num_point_pair_contacts()


def test_corner_spheres_give_four_contacts_and_stop_a_spin_a_box_gives_one():
    """Point contact of a Box on a half space is ONE contact point, so a cube spinning on
    its face never slows; the eight corner spheres give four, whose friction stops it."""
    X, n = _spinning_on_a_face(20)
    assert n == 4
    assert abs(X[-1, 12]) < 0.05
    X, n = _spinning_on_a_face(20, contact_geometry="box")
    assert n == 1
    assert X[-1, 12] == pytest.approx(5.0, abs=0.05)


def test_contact_torque_opposes_the_spin_and_never_reverses_it():
    x = np.zeros(13)
    x[0] = 1.0
    x[7:10] = [0.0, 0.0, 4.0]                              # spin about the table normal
    inertia = [I_CUBE] * 3
    tau = contact_torque(x, 3.6, 0.01, 0.0, inertia, 1e-3)
    assert tau == pytest.approx([0.0, 0.0, -0.036])        # -mu_t N along the spin
    assert contact_torque(x, 0.0, 0.01, 0.0, inertia, 1e-3) == pytest.approx(np.zeros(3))
    assert contact_torque(x, 3.6, 0.0, 0.02, inertia, 1e-3) == pytest.approx(np.zeros(3))
    slow = x.copy()
    slow[9] = 0.01                                         # would reverse within a step
    assert contact_torque(slow, 3.6, 0.01, 0.0, inertia, 1e-3)[2] == pytest.approx(
        -I_CUBE * 0.01 / 1e-3)
    x[7:10] = [3.0, 4.0, 0.0]                              # rotation in the table plane
    tau = contact_torque(x, 2.0, 0.01, 0.02, inertia, 1e-3)
    assert tau == pytest.approx([-0.024, -0.032, 0.0])     # -mu_r N w_t / |w_t|


def test_torsional_friction_element_decelerates_a_spin_by_mu_n_over_i():
    """On its face, with the plant's normal force m g: the spin falls mu_t m g / I faster
    than with the corner friction alone, while both still spin."""
    base, _ = _spinning_on_a_face(6)
    X, n = _spinning_on_a_face(6, torsional_friction=0.01)
    assert n == 4
    t = np.arange(7) * DT
    extra = base[:, 12] - X[:, 12]
    alpha = 0.01 * MASS * 9.81 / I_CUBE
    assert base[4, 12] > 1.0 and X[4, 12] > 0.5           # both still spinning at step 4
    assert extra[4] == pytest.approx(alpha * t[4], rel=0.1)


def test_rolling_resistance_leaves_a_resting_spin_and_flight_alone():
    base, _ = _spinning_on_a_face(6)
    X, _ = _spinning_on_a_face(6, rolling_resistance=0.02)
    assert X[:, 12] == pytest.approx(base[:, 12], abs=1e-9)
    sim = DrakeRigidSimulator(with_drake(RigidObjectScenario(), rolling_resistance=0.02,
                                         torsional_friction=0.02, viscous_drag=0.1), DT)
    x0 = np.zeros(13)
    x0[2], x0[3], x0[10:13] = 1.0, 1.0, [3.0, 0.0, 2.0]
    X = sim.rollout(x0, 20)                                 # in flight: no normal force
    assert X[-1, 10:13] == pytest.approx([3.0, 0.0, 2.0], abs=1e-9)


@pytest.mark.parametrize("drake, message", [
    (dict(contact_geometry="mesh"), "contact_geometry"),
    (dict(torsional_friction=-0.01), "torsional_friction"),
    (dict(rolling_resistance=0.5), "rolling_resistance"),
])
def test_bad_drake_contact_keys_are_rejected(drake, message):
    with pytest.raises(ScenarioError, match=message):
        validate_rigid_object(with_drake(RigidObjectScenario(), **drake))
