"""The drake backend's discrete contact approximation and Hunt-Crossley dissipation
(issue 30): drake.discrete_contact_approximation and drake.hunt_crossley_dissipation reach
the plant, so a dropped cube bounces in Drake's own terms."""
from __future__ import annotations

import numpy as np
import pytest

from adaptive_c3.scenarios.common import ScenarioError
from adaptive_c3.scenarios.rigid_object_schema import (RigidObjectScenario,
                                                       validate_rigid_object)
from adaptive_c3.tools.diagnosis.backends.drake_backend import DrakeRigidSimulator
from adaptive_c3.tools.diagnosis.tasks.rigid_object.drake_baseline import with_drake

DT = 1.0 / 148
SIDE = 0.1048


def _rebound(**drake) -> float:
    """Highest rise (m) of the centre above its lowest point after a cube, flat, falls
    2 cm onto the table (0.3 s)."""
    sim = DrakeRigidSimulator(with_drake(RigidObjectScenario(), **drake), DT)
    x0 = np.zeros(13)
    x0[2], x0[3] = SIDE / 2 + 0.02, 1.0
    z = sim.rollout(x0, 45)[:, 2]
    k = int(np.argmin(z[:15]))                  # the first impact (~0.064 s)
    return float(z[k:].max() - z[k])


def test_hunt_crossley_contact_bounces_and_its_dissipation_damps_it():
    """On a soft contact (2000 N/m a geometry: a contact period well above the SAP step),
    SAP with Drake's default relaxation time does not bounce; the `similar` approximation
    with no Hunt-Crossley dissipation bounces like a spring (measured 16 mm), and 10 s/m
    of dissipation takes most of it out (1.8 mm)."""
    soft = dict(point_stiffness=2.0e3)
    sap = _rebound(**soft)
    similar = dict(soft, discrete_contact_approximation="similar")
    elastic = _rebound(**similar, hunt_crossley_dissipation=0.0)
    damped = _rebound(**similar, hunt_crossley_dissipation=10.0)
    assert sap < 1e-3
    assert elastic > 0.01
    assert damped < 0.25 * elastic


@pytest.mark.parametrize("drake, message", [
    (dict(discrete_contact_approximation="tamsi"), "discrete_contact_approximation"),
    (dict(hunt_crossley_dissipation=float("nan")), "hunt_crossley_dissipation"),
])
def test_bad_contact_approximation_keys_are_rejected(drake, message):
    with pytest.raises(ScenarioError, match=message):
        validate_rigid_object(with_drake(RigidObjectScenario(), **drake))


@pytest.mark.parametrize("radius", [1e-3, 8e-3])
def test_corner_rounding_lowers_a_cube_balanced_on_an_edge(radius):
    """The corner_rounding effect (contact.corner_radius) is geometry the drake plant
    uses: a cube balanced on an edge (45 deg) rests with its centre at (h - r) sqrt 2 + r,
    2.9 mm lower at r = 8 mm than at 1 mm (a sharp cube: h sqrt 2)."""
    from adaptive_c3.tools.diagnosis.tasks.rigid_object.rigid_effects import (DRAKE_EFFECTS,
                                                                           with_values)
    effect = next(e for e in DRAKE_EFFECTS if e.name == "corner_rounding")
    assert effect.refit == "drake.friction" and radius in effect.grid
    sim = DrakeRigidSimulator(with_values(RigidObjectScenario(), {effect.key: radius}), DT)
    h = SIDE / 2
    x0 = np.zeros(13)
    x0[3], x0[4] = np.cos(np.pi / 8), np.sin(np.pi / 8)       # 45 deg about body x
    x0[2] = (h - radius) * np.sqrt(2) + radius
    z = sim.rollout(x0, 10)[:, 2]
    assert z[-1] == pytest.approx(x0[2], abs=2e-4)
