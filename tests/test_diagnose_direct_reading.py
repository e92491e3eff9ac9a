"""Issue 30: a member beside `none` that the task reads from the recording with no model
(the ball's mass from the momentum balance) is ruled out when the reading lies within its
size that matters, and `none` leaves the set when it lies beyond it
(engine/direct_reading.py)."""
import numpy as np

from adaptive_c3.scenarios.schema import SCENARIO_DIR, load_scenario
from adaptive_c3.tools.diagnosis.backends.effects import Candidate
from adaptive_c3.tools.diagnosis.engine.boundary import ruled_out_members
from adaptive_c3.tools.diagnosis.engine.direct_reading import read_directly, shown_directly
from adaptive_c3.tools.diagnosis.engine.evidence import size_z
from adaptive_c3.tools.diagnosis.engine.fit import Fit
from adaptive_c3.tools.diagnosis.engine.report import ambiguity_summary
from adaptive_c3.tools.diagnosis.tasks.ball_rolling.effects_ball import ball_spec
from adaptive_c3.tools.diagnosis.tasks.ball_rolling.momentum_audit import MassReading

SPEC = ball_spec(load_scenario(SCENARIO_DIR / "ball_rolling.yaml")[0])


class _Reads:
    """The ball spec with its direct reading replaced by a fixed one."""

    def __init__(self, reading):
        self.reading, self.calls = reading, []

    def __getattr__(self, name):
        return getattr(SPEC, name)

    def direct_reading(self, cand, rec):
        self.calls.append(cand.label())
        return self.reading if cand.label() == "mass_scale[ball]" else None


def _judged(*names):
    rows = [dict(name=n, target=t, held_out_score=0.1) for n, t in names]
    return dict(verdict="ambiguous", ambiguous=rows, separating_excitation=[])


def _mass_fit():
    return Fit((Candidate("mass_scale", "ball"),), np.array([0.4]), np.array([[0.3, 0.5]]),
               np.array([0.05]), 0.0)


def _reading(scale, sd=0.03):
    return MassReading(scale=scale, sd=sd, delay_s=0.002, windows=200, episodes=40)


MASS, NONE, DRAG = ("mass_scale", "ball"), ("none", ""), ("viscous_damping", "ball")


def test_a_reading_within_the_size_rules_the_member_out_and_none_answers():
    j = _judged(NONE, MASS)
    out = read_directly(j, _Reads(_reading(1.02)), rec=None, z=size_z())
    assert len(out) == 1 and out[0]["within"] and not out[0]["beyond"]
    assert out[0]["sizes"] == [0.5, 2.0]
    assert ruled_out_members(j) == ["mass_scale[ball]"] and j["verdict"] == "none"
    assert shown_directly(j, [_mass_fit()]) is None


def test_a_reading_beyond_the_size_takes_none_out_and_names_the_effect():
    j = _judged(NONE, MASS)
    fit = _mass_fit()
    read_directly(j, _Reads(_reading(0.31)), rec=None, z=size_z())
    assert ruled_out_members(j) == []
    assert shown_directly(j, [fit]) is fit and j["verdict"] == "named"
    assert "`none` is not kept beside it" in ambiguity_summary(j)


def test_beyond_with_another_member_left_leads_the_set():
    j = _judged(NONE, DRAG, MASS)
    fit = _mass_fit()
    read_directly(j, _Reads(_reading(2.6, sd=0.1)), rec=None, z=size_z())
    assert shown_directly(j, [fit]) is fit
    assert j["verdict"] == "ambiguous"
    assert [a["name"] for a in j["ambiguous"]] == ["mass_scale", "viscous_damping"]
    assert j["separating_excitation"][0]["between"] == ["mass_scale", "viscous_damping"]


def test_a_reading_that_reaches_the_size_changes_nothing():
    """0.56 +- 0.05 at one-sided 5 % (and the reading's 4 % model form) reaches 0.5."""
    j = _judged(NONE, MASS)
    out = read_directly(j, _Reads(_reading(0.56, sd=0.05)), rec=None, z=size_z())
    assert not out[0]["within"] and not out[0]["beyond"]
    assert ruled_out_members(j) == [] and shown_directly(j, [_mass_fit()]) is None
    assert j["verdict"] == "ambiguous" and len(j["ambiguous"]) == 2
    assert "reaching its size that matters" in ambiguity_summary(j)


def test_nothing_is_read_without_none_in_the_set_or_without_a_reading():
    spec = _Reads(_reading(1.0))
    assert read_directly(_judged(DRAG, MASS), spec, rec=None, z=size_z()) == []
    named = dict(verdict="named", ambiguous=[], separating_excitation=[])
    assert read_directly(named, spec, rec=None, z=size_z()) == []
    assert spec.calls == []
    assert read_directly(_judged(NONE, MASS), _Reads(None), rec=None, z=size_z()) == []
    assert read_directly(_judged(NONE, DRAG), spec, rec=None, z=size_z()) == []
    assert spec.calls == ["viscous_damping[ball]"]
