"""Issue 30: `none` leaves an ambiguous set when one of its effects is shown on the windows
the fit left out to lie beyond its size that matters (engine/beyond_size.py),
where the linearised interval, wide on a staircase cost, cannot say."""
import functools

import numpy as np
import pytest

from adaptive_c3.tools.diagnosis.backends.effects import Candidate
from adaptive_c3.tools.diagnosis.engine.beyond_size import answers_beyond_size, beyond_size
from adaptive_c3.tools.diagnosis.engine.evidence import (fit_row, not_excluded, verdict,
                                                        worse_z)
from adaptive_c3.tools.diagnosis.engine.fit import Fit, evaluate
from adaptive_c3.tools.diagnosis.engine.report import ambiguity_summary
from tests.test_diagnose_size_test import FRICTION, SlipProblem, _fric_fit, _spec, scored_fit

MASS = Candidate("mass_scale", "ball")


def _answer(truth_mu: float, fit_mu: float, ci):
    """The verdict (a gain too small to name: `none`, or `none` first beside mu), mu
    beside `none` (not_excluded: an interval that reaches mu 0.5), then beyond_size on
    the same windows (standing in for the left-out ones); returns (judged, the fit
    beyond_size named or None, the fit)."""
    spec = _spec()
    prob = SlipProblem(spec, truth_mu=truth_mu)
    fric, none_eval = _fric_fit(prob, fit_mu, ci)
    judged = verdict([fric], None, none_eval, 0.99)
    assert judged["verdict"] in ("none", "ambiguous")
    not_excluded(judged, spec, [fric], none_eval, prob=prob)
    assert [a["name"] for a in judged["ambiguous"]] == ["none", FRICTION.name]
    shown = beyond_size(judged, spec, [fric], prob,
                        functools.cache(lambda: evaluate(prob, None)), worse_z)
    return judged, shown, fric


def test_an_effect_beyond_its_size_on_left_out_windows_is_named():
    """Data slipping like mu 0.3, the fit at 0.32 with an interval (0.1..0.9) reaching
    above mu 0.5: the fit beats both `none` and mu fixed at 0.5, so it is named."""
    judged, shown, fric = _answer(0.3, 0.32, [0.1, 0.9])
    assert shown is fric
    assert judged["verdict"] == "named" and judged["ambiguous"] == []
    t = judged["beyond_size"][0]
    assert t["beyond"] is True and t["size"] == 0.5
    assert t["z_vs_none"] > 2.0 and t["z_vs_size"] > 2.0
    assert "beats both the unmodified model" in ambiguity_summary(judged)


def test_a_fit_past_the_size_on_data_within_it_keeps_none():
    """Data slipping like mu 0.6 (below the size: `none` is a right answer), the fit at
    0.45 just past mu 0.5: mu 0.5 is nearer the data than the fit, so `none` stays."""
    judged, shown, _ = _answer(0.6, 0.45, [0.2, 0.9])
    assert shown is None
    assert [a["name"] for a in judged["ambiguous"]] == ["none", FRICTION.name]
    t = judged["beyond_size"][0]
    assert t["beyond"] is False and t["z_vs_size"] < 0.0


def test_a_fit_within_its_size_is_not_tested():
    """Data slipping like mu 0.62, the fit at 0.66 (within its size, mu 0.5 off the
    model's 1): not beyond its size, so not tested; `none` stays."""
    judged, shown, _ = _answer(0.62, 0.66, [0.3, 1.1])
    assert shown is None and "beyond_size" not in judged
    assert [a["name"] for a in judged["ambiguous"]] == ["none", FRICTION.name]


def test_none_leaves_a_larger_set_and_the_rest_are_separated_from_the_effect():
    """[none, mu, mass] with mu shown beyond its size: `none` leaves, mu goes first (and
    is returned: the answer is the set's lead, not the `none` the set no longer holds)
    and the follow-up proposed separates mu from the mass (not either from `none`)."""
    spec = _spec()
    prob = SlipProblem(spec, truth_mu=0.3)
    fric, none_eval = _fric_fit(prob, 0.32, [0.1, 0.9])
    mass = Fit((MASS,), np.array([1.1]), np.array([[0.4, 2.2]]), np.array([0.4]), 0.0)
    mass.test_ssr, mass.test_n, _, _ = evaluate(prob, mass)
    mass.reduction, mass.z_vs_none = 0.0, 0.0
    judged = dict(verdict="ambiguous", separating_excitation=[], ambiguous=[
        fit_row(None, none_eval), fit_row(mass, none_eval), fit_row(fric, none_eval)])
    shown = beyond_size(judged, spec, [fric, mass], prob,
                        functools.cache(lambda: evaluate(prob, None)), worse_z)
    assert shown is fric and judged["verdict"] == "ambiguous"
    assert [a["name"] for a in judged["ambiguous"]] == [FRICTION.name, MASS.name]
    assert [p["between"] for p in judged["separating_excitation"]] == \
        [[FRICTION.name, MASS.name]]
    assert [t["name"] for t in judged["beyond_size"]] == [FRICTION.label()]


@pytest.mark.parametrize("profiled", [False, True])
def test_a_mass_that_trades_with_the_contact_is_tested_with_the_contact_fitted(profiled):
    """Data of the model's ball on a contact 4x as stiff as the model's (the contact
    frequency of a 0.25x ball on the model's contact), the mass fitted at 0.25x: at the
    model's stiffness it beats `none` and 0.5x and takes `none` out of the set (102425's
    wrong turn). With the stiffness fitted beside each side (the Sizer), the model's mass
    on a fitted contact matches the data and the ball's own share of the motion rules
    0.25x out, so `none` stays."""
    from adaptive_c3.tools.diagnosis.engine.profiled_size import Sizer
    from tests.test_diagnose_always_size_tested import FrequencyProblem, _profiled_spec
    spec = _profiled_spec()
    prob = FrequencyProblem(spec, truth=1.0, truth_k=4.0, inertia=1.0)
    mass, none_eval = scored_fit(prob, MASS, 0.25, [0.2, 0.3], 0.025)
    judged = dict(verdict="ambiguous", separating_excitation=[], ambiguous=[
        fit_row(None, none_eval), fit_row(mass, none_eval)])
    shown = beyond_size(judged, spec, [mass], prob,
                        functools.cache(lambda: evaluate(prob, None)), worse_z,
                        sized=Sizer(prob, spec) if profiled else None)
    t = judged["beyond_size"][0]
    assert t["beyond"] is (not profiled)
    if profiled:
        assert shown is None and t["z_vs_none"] < -2.0
        assert [a["name"] for a in judged["ambiguous"]] == ["none", MASS.name]
        assert t["fitted_beside"] == ["stiffness_calibration[contacts]"]
    else:
        assert shown is mass and judged["verdict"] == "named"
        assert "fitted_beside" not in t


def test_the_report_says_what_was_fitted_beside_a_profiled_effect():
    """A mass shown beyond its size with the contact fitted beside it: the report says so
    (the unmodified model it beat is the model's mass on a fitted contact)."""
    test = dict(name=MASS.label(), value=0.3, size=0.5, z_vs_none=3.1, z_vs_size=2.9,
                beyond=True, fitted_beside=["stiffness_calibration[contacts]"])
    text = ambiguity_summary(dict(beyond_size=[test]))
    assert "each with stiffness_calibration[contacts] fitted beside it" in text
    assert "fitted beside" not in ambiguity_summary(dict(beyond_size=[
        {k: v for k, v in test.items() if k != "fitted_beside"}]))


def test_the_beyond_size_fit_answers_when_named_or_when_nothing_was_chosen():
    shown, chosen = object(), object()
    assert answers_beyond_size(shown, chosen, "named")           # alone beyond its size
    assert answers_beyond_size(shown, None, "ambiguous")         # leads a set `none` left
    assert not answers_beyond_size(shown, chosen, "ambiguous")   # a chosen effect stays
    assert not answers_beyond_size(None, chosen, "named")
    assert not answers_beyond_size(None, None, "ambiguous")
    assert not answers_beyond_size(chosen, chosen, "named")      # already the answer
