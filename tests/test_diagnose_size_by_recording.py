"""Issue 30: with a follow-up recording diagnosed beside the first, a size that matters is
tested on each recording alone as well as on both (engine/boundary.py `excluded`): a
recording that rules the size out is not overruled by one where the effect hardly
shows, the 5 % is shared among the three tests, and a recording that clearly favours
the size keeps it."""
import numpy as np
import pytest

from adaptive_c3.tools.diagnosis.engine.boundary import excluded, recording_parts
from adaptive_c3.tools.diagnosis.engine.evidence import not_excluded, size_z
from adaptive_c3.tools.recording import Recording, concat_recordings
from tests.test_diagnose_size_test import SlipProblem, _fric_fit, _spec

WINDOWS = 240          # the first half from the first recording, the rest the follow-up


class TwoRecordings(SlipProblem):
    """The first recording's windows show the data's slip response (truth_mu; clean data:
    mu 1) scaled by `first`; the follow-up's barely see it: a per-window offset (mean `lean_at`)
    that an EE-ball mu below the slip point reduces by `lean` (a model-form lean)."""

    def __init__(self, spec, first: float, lean: float, lean_at: float = 0.0,
                 truth_mu: float = 1.0):
        super().__init__(spec, truth_mu=truth_mu, windows=WINDOWS)
        self.first, self.lean = first, lean
        self.offset = np.random.default_rng(5).normal(lean_at, 1.0, (WINDOWS, 1, 1))

    def residuals(self, effects, W):
        mu = self.mu_of(effects)
        i = W.row // 10
        follow_up = (i >= WINDOWS // 2)[:, None, None]
        return self.noise[i] + np.where(follow_up, self.offset[i] - self.lean * self._slip(mu),
                                        self.first * (self._slip(mu)
                                                      - self._slip(self.truth_mu)))


PART_OF_ROW = (np.arange(WINDOWS * 10) // 10 >= WINDOWS // 2).astype(int)


def _test(first, lean, lean_at=0.0):
    prob = TwoRecordings(_spec(), first, lean, lean_at)
    fric, none_eval = _fric_fit(prob, 0.9, [0.2, 1.6])
    pooled = excluded(prob, fric, [(0.5, -1)], none_eval, size_z)
    each = excluded(prob, fric, [(0.5, -1)], none_eval, size_z,
                    recording_parts(prob, PART_OF_ROW))
    return pooled, each


def test_a_recording_that_rules_the_size_out_is_not_overruled():
    """The first recording alone puts mu 0.5 at z < -3; pooled with a follow-up that
    hardly sees it the size is not clearly worse (z > -1.645): excluded once each
    recording is scored alone."""
    (out_pooled, t_pooled), (out, tested) = _test(0.3, 0.1)
    _, z, each = tested[0]
    assert out_pooled is False and t_pooled[0][1] > -size_z(1)
    assert each[0] < -3.0 and each[0] < -size_z(3) and abs(each[1]) < size_z(3)
    assert out is True and z == pytest.approx(t_pooled[0][1])


def test_three_tests_share_the_five_percent():
    """Each recording alone above the shared bar (z > -2.13): the pooled test is held to
    it too, so a pooled z between -2.13 and -1.645 no longer excludes."""
    (out_pooled, t_pooled), (out, tested) = _test(0.15, -0.7)
    _, z, each = tested[0]
    assert -size_z(3) < z <= -size_z(1) and min(each) > -size_z(3)
    assert out_pooled is True and out is False


def test_a_recording_that_favours_the_size_keeps_it():
    """The first recording rules mu 0.5 out, the follow-up clearly favours it (a model
    form the data's physics does not have, or the effect is there): the recordings
    disagree, so the size is not excluded."""
    (_, _), (out, tested) = _test(0.3, 0.3, lean_at=0.3)
    _, z, each = tested[0]
    assert each[0] < -size_z(3) and max(z, each[1]) >= size_z(3)
    assert out is False


def test_concatenated_recordings_say_where_each_row_came_from():
    def rec(n):
        return Recording(t=np.arange(n) * 0.01, x=np.zeros((n, 2)), u=np.zeros((n, 1)),
                         state_names=["a", "b"], input_names=["u"])
    both = concat_recordings([rec(3), rec(2), rec(4)])
    assert both.extras["part"].tolist() == [0, 0, 0, 1, 1, 2, 2, 2, 2]


def test_not_excluded_reports_each_recordings_z():
    prob = TwoRecordings(_spec(), 0.3, 0.1)
    fric, none_eval = _fric_fit(prob, 0.9, [0.2, 1.6])
    judged = dict(verdict="none", ambiguous=[], separating_excitation=[])
    not_excluded(judged, prob.spec, [fric], none_eval, prob=prob, part_of_row=PART_OF_ROW)
    t = judged["size_tests"][0]
    assert t["excluded"] is True and len(t["tested"][0]["by_recording"]) == 2
    assert judged["verdict"] == "none" and not judged["ambiguous"]
    judged = dict(verdict="none", ambiguous=[], separating_excitation=[])
    not_excluded(judged, prob.spec, [fric], none_eval, prob=prob)       # pooled only
    assert judged["size_tests"][0]["excluded"] is False
    assert [a["name"] for a in judged["ambiguous"]] == ["none", "friction_coefficient"]


def test_the_report_says_which_recording_ruled_a_size_out():
    from adaptive_c3.tools.diagnosis.engine.report import ambiguity_summary
    prob = TwoRecordings(_spec(), 0.3, 0.1)
    fric, none_eval = _fric_fit(prob, 0.9, [0.2, 1.6])
    judged = dict(verdict="none", ambiguous=[], separating_excitation=[])
    not_excluded(judged, prob.spec, [fric], none_eval, prob=prob, part_of_row=PART_OF_ROW)
    text = ambiguity_summary(judged)
    assert "friction_coefficient[ee_ball] at 0.5 (by recording 1 alone)" in text, text


def test_a_size_outside_the_pooled_interval_that_one_recording_favours_stays():
    """The first recording's data slip as at mu 0.4, the follow-up hardly sees mu; the
    pooled fit (0.9, interval 0.7..1.6) does not reach mu 0.5. One recording alone finds
    mu 0.5 clearly better than `none`, so the friction stays beside `none`
    (boundary.favoured_alone); without the recordings apart it is left out."""
    prob = TwoRecordings(_spec(), 0.3, 0.0, truth_mu=0.4)
    fric, none_eval = _fric_fit(prob, 0.9, [0.7, 1.6])
    judged = dict(verdict="none", ambiguous=[], separating_excitation=[])
    not_excluded(judged, prob.spec, [fric], none_eval, prob=prob, part_of_row=PART_OF_ROW)
    t = judged["size_tests"][0]
    assert t["excluded"] is False and "tested" not in t
    f = t["favoured"][0]
    assert f["value"] == 0.5 and max(f["by_recording"]) >= f["bar"] > 2.0
    assert [a["name"] for a in judged["ambiguous"]] == ["none", "friction_coefficient"]
    assert "clearly better than `none`" in judged["ambiguous"][1]["note"]
    judged = dict(verdict="none", ambiguous=[], separating_excitation=[])
    not_excluded(judged, prob.spec, [fric], none_eval, prob=prob)       # pooled only
    assert judged["verdict"] == "none" and not judged.get("size_tests")


def test_a_size_beyond_an_interval_that_lies_short_of_it_is_not_favoured():
    """Both recordings show the data's slip at mu 0.6, just short of the size that matters
    (0.5): mu 0.5 beats the model's 1 on each recording alone, yet the pooled fit (0.6,
    interval 0.52..0.68) beats mu 0.5 there too, so no recording disagrees with the
    interval and `none` stays confident with the small effect ruled out."""
    from adaptive_c3.tools.diagnosis.engine.boundary import at_size
    prob = SlipProblem(_spec(), truth_mu=0.6, windows=WINDOWS)
    fric, none_eval = _fric_fit(prob, 0.6, [0.52, 0.68])
    parts = recording_parts(prob, PART_OF_ROW)
    assert at_size(prob, fric.cands[0], 0.5, none_eval) > size_z(3)    # beats `none`
    judged = dict(verdict="none", ambiguous=[], separating_excitation=[])
    not_excluded(judged, prob.spec, [fric], none_eval, prob=prob, part_of_row=PART_OF_ROW)
    assert parts is not None and judged["verdict"] == "none" and not judged["ambiguous"]
    assert not any(t.get("favoured") for t in judged.get("size_tests", []))


def test_a_fit_beyond_its_size_clearly_worse_on_the_test_windows_is_tested():
    """Clean data (mu 1) and a fit read at mu 0.3 [0.28, 0.32], beyond the size that matters
    (0.5), that had beaten `none` on its own held-out clusters (z_vs_none > 0). Where the
    size tests are scored it is clearly worse than `none`, so it no longer keeps its
    effect untested: mu 0.5 is tested, clearly worse too, and the effect is excluded."""
    prob = TwoRecordings(_spec(), 3.0, 0.0)
    fric, none_eval = _fric_fit(prob, 0.3, [0.28, 0.32])
    assert fric.z_vs_none < -size_z(3)
    fric.z_vs_none = 1.0                        # as read on the fit's own sparse clusters
    out, tested = excluded(prob, fric, [(0.5, -1)], none_eval, size_z,
                           recording_parts(prob, PART_OF_ROW))
    assert out is True and tested[0][0] == 0.5 and tested[0][1] < -size_z(3)
