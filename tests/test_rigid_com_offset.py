"""patch.com_offset: a rigid object whose centre of mass is off its box's centre (body
frame). The recorded position stays the box's centre; the plant's mass sits at the offset."""
import dataclasses

import numpy as np
import pytest

from adaptive_c3.models.rigid_object import RigidObjectParams, build_rigid_object_plant
from adaptive_c3.scenarios.rigid_object_schema import RigidObjectScenario, validate_rigid_object
from adaptive_c3.scenarios.schema import ScenarioError
from adaptive_c3.tools.diagnosis.backends.drake_backend import DrakeRigidSimulator
from adaptive_c3.tools.diagnosis.tasks.rigid_object.rigid_effects import DRAKE_EFFECTS

DT = 1.0 / 148


def _with_com(offset):
    s = RigidObjectScenario()
    return dataclasses.replace(s, patch=dataclasses.replace(s.patch, com_offset=list(offset)))


def test_the_plants_centre_of_mass_is_at_the_offset_in_the_body_frame():
    s = _with_com([0.0, 0.004, 0.009])
    plant = build_rigid_object_plant(RigidObjectParams.from_scenario(s), 1e-3).plant
    ctx = plant.CreateDefaultContext()
    assert np.allclose(plant.CalcCenterOfMassPositionInWorld(ctx), [0.0, 0.004, 0.009])
    nominal = build_rigid_object_plant(RigidObjectParams.from_scenario(RigidObjectScenario()),
                                       1e-3).plant
    assert np.allclose(nominal.CalcCenterOfMassPositionInWorld(
        nominal.CreateDefaultContext()), 0.0)


def test_a_cube_heavy_on_one_side_tips_towards_it_from_an_edge():
    """Balanced on its bottom edge along body y (the cube turned 45 deg about y): with the
    mass centred it stays up for a while; with the mass off towards +x it falls that way."""
    half = RigidObjectScenario().body.box_size[0] / 2
    x0 = np.zeros(13)
    c, s = np.cos(np.pi / 8), np.sin(np.pi / 8)
    x0[3:7] = [c, 0.0, s, 0.0]                       # 45 deg about body y
    x0[2] = half * np.sqrt(2) + 1e-4
    ends = {}
    for off in (0.0, 0.008, -0.008):
        sim = DrakeRigidSimulator(_with_com([off, 0.0, 0.0]), DT)
        ends[off] = sim.rollout(x0, 40)[-1]
    assert abs(ends[0.0][0]) < 2e-3                  # the centred cube barely moves
    # rotated +45 deg about y, body +x points down-right: the heavy corner pulls the box
    # centre to the other side as the cube falls onto that face
    assert np.sign(ends[0.008][0]) == -np.sign(ends[-0.008][0]) != 0
    assert abs(ends[0.008][0]) > 0.01 and abs(ends[-0.008][0]) > 0.01


@pytest.mark.parametrize("bad", [[0.0, 0.0], [0.0, 0.0, 0.06], [0.0, float("nan"), 0.0]])
def test_a_com_offset_outside_the_box_is_a_scenario_error(bad):
    with pytest.raises(ScenarioError, match="patch.com_offset"):
        validate_rigid_object(_with_com(bad))


def test_drakes_library_tries_the_offset_along_each_body_axis_with_friction_refitted():
    effects = {e.name: e for e in DRAKE_EFFECTS}
    for i, axis in enumerate("xyz"):
        e = effects[f"com_offset_{axis}"]
        assert e.key == f"patch.com_offset[{i}]" and e.refit == "drake.friction"
        assert min(e.grid) < 0 < max(e.grid) and 0.0 in e.grid
