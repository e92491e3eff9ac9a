"""Issue 19: the ball diagnosis says `named`, `ambiguous` (with the set, held-out scores and
the separating excitation) or `none`; a sensor delay is fitted first as a nuisance; the
evidence windows are labelled by phase. The >= 40-draw per-effect hit rate is slow."""
import json
import os
from pathlib import Path

import numpy as np
import pytest

from adaptive_c3.scenarios.schema import SCENARIO_DIR, load_scenario
from adaptive_c3.tools.diagnosis.harness.concealed_ball_data import Variation, concealed_draw
from adaptive_c3.tools.diagnosis.backends.effects import Candidate
from adaptive_c3.tools.diagnosis.tasks.ball_rolling.effects_ball import ModelParams
from adaptive_c3.tools.diagnosis.engine.evidence import (Z_AMBIG, not_excluded, verdict,
                                                        worse_z)
from adaptive_c3.tools.diagnosis.engine.fit import Fit, paired_z

BALL = str(SCENARIO_DIR / "ball_rolling.yaml")


def _fit(name, target, clusters, none_clusters):
    f = Fit((Candidate(name, target),), np.array([1.0]), np.zeros((1, 2)), np.zeros(1), 0.0)
    f.test_cluster_ssr = np.asarray(clusters, float)
    f.test_ssr, f.test_n = float(f.test_cluster_ssr.sum()), 1000
    f.score = f.test_ssr
    f.reduction = 1 - f.test_ssr / float(np.sum(none_clusters))
    d = np.asarray(none_clusters) - f.test_cluster_ssr
    f.z_vs_none = float(d.mean() / (d.std(ddof=1) / np.sqrt(len(d))))
    return f


def _score_as(f, like):
    """Give fit f the held-out scores of `like` (a multi-parameter fit built by hand)."""
    for k in ("test_cluster_ssr", "test_ssr", "test_n", "score", "reduction", "z_vs_none"):
        setattr(f, k, getattr(like, k))


RNG = np.random.default_rng(0)
NONE = 100 + RNG.normal(0, 1, 30)
NONE_EVAL = (float(NONE.sum()), 1000, NONE, None)


def test_clear_winner_is_named():
    best = _fit("rolling_resistance", "ball_table", NONE - 20 + RNG.normal(0, 1, 30), NONE)
    other = _fit("viscous_damping", "ball", NONE - 8 + RNG.normal(0, 1, 30), NONE)
    v = verdict([best, other], best, NONE_EVAL, 0.1)
    assert v["verdict"] == "named" and v["ambiguous"] == []


def test_equally_good_candidates_are_ambiguous_with_the_separating_push():
    best = _fit("rolling_resistance", "ball_table", NONE - 20 + RNG.normal(0, 3, 30), NONE)
    other = _fit("viscous_damping", "ball", best.test_cluster_ssr + RNG.normal(0.2, 3, 30), NONE)
    v = verdict([best, other], best, NONE_EVAL, 0.1)
    assert v["verdict"] == "ambiguous"
    assert [a["name"] for a in v["ambiguous"]] == ["rolling_resistance", "viscous_damping"]
    assert all(a["held_out_score"] > 0 for a in v["ambiguous"])
    assert "coast" in v["separating_excitation"][0]["change"]


def test_a_rival_that_explains_almost_nothing_does_not_join_a_choice():
    """Development draw 90028 (EE-ball friction 0.17, after a follow-up): friction cut the
    held-out SSR by 20 %, all of it in a few slip events, and torsional friction by 0.2 %
    in every cluster. The paired z of the two could not call the rival worse, so it made
    the answer ambiguous; a rival must cut at least half the reduction a choice needs."""
    gains = np.zeros(30)
    gains[[3, 11, 17, 24]] = 150.0                          # 20 % of the SSR, in 4 clusters
    fric = _fit("friction_coefficient", "ee_ball", NONE - gains, NONE)
    tors = _fit("torsional_friction", "ball_table", NONE - 0.2 + RNG.normal(0, 0.05, 30), NONE)
    assert fric.reduction == pytest.approx(0.2, abs=0.01) and tors.reduction < 0.005
    assert tors.z_vs_none > Z_AMBIG and fric.z_vs_none > Z_AMBIG
    family = 9                                  # 90028 compared ten single effects
    assert paired_z(tors.test_cluster_ssr, fric.test_cluster_ssr) < worse_z(family)  # old test
    v = verdict([fric, tors], fric, NONE_EVAL, 0.1, family)
    assert v["verdict"] == "named" and v["ambiguous"] == []
    # a rival with a cut of its own (here 8 %, at least half the 10 % bar) still joins
    rival = _fit("mass_scale", "ball", NONE - gains * 0.4 + RNG.normal(0, 0.05, 30), NONE)
    assert rival.reduction >= 0.05 and rival.z_vs_none > Z_AMBIG
    v = verdict([fric, rival], fric, NONE_EVAL, 0.1, family)
    assert v["verdict"] == "ambiguous"
    assert [a["name"] for a in v["ambiguous"]] == ["friction_coefficient", "mass_scale"]


def test_near_miss_without_a_choice_is_ambiguous_with_none():
    near = _fit("mass_scale", "ball", NONE - 7 + RNG.normal(0, 1, 30), NONE)  # 7 % < 10 %
    assert near.z_vs_none > Z_AMBIG
    v = verdict([near], None, NONE_EVAL, 0.1)
    assert v["verdict"] == "ambiguous"
    assert [a["name"] for a in v["ambiguous"]] == ["none", "mass_scale"]
    assert "push" in v["separating_excitation"][0]["change"]
    assert verdict([near], None, NONE_EVAL, 0.2)["verdict"] == "none"   # 7 % < 20 % / 2


def _pushes_end_at_rest(change):
    """The gait that tells mass from `none`: acceleration-rich pushes that end at rest (on
    release pushes the LCS reads a clean draw's ball 1.5-3x heavier: dev draws 12017,
    12021, 12025, 12039), more of them."""
    assert change.get("release_speed", [0.0, 0.0])[1] == 0.0
    assert change["peak_accel"][0] >= 8.0 and change["episodes"] >= 25


def test_near_miss_is_judged_against_the_effects_own_bar():
    """Mass needs a 2 % held-out cut where the ball model asks 10 % of others (BallSpec
    .min_reduction_by_effect); its near miss is half of its own bar: a 1.5 % cut carried
    across clusters is no longer dismissed as `none` (draw 8032 after its follow-up:
    mass 1.86 for 1.96, 1.9 % at z 2.6, was reported `none`)."""
    mass = _fit("mass_scale", "ball", NONE - 1.5 + RNG.normal(0, 0.5, 30), NONE)
    fric = _fit("friction_coefficient", "ee_ball", mass.test_cluster_ssr, NONE)
    assert mass.z_vs_none > Z_AMBIG and 0.01 < mass.reduction < 0.02
    own = {"mass_scale": 0.02}
    v = verdict([mass], None, NONE_EVAL, 0.1, own_reduction=own)
    assert [a["name"] for a in v["ambiguous"]] == ["none", "mass_scale"]
    _pushes_end_at_rest(v["separating_excitation"][0]["excitation"])
    assert verdict([mass], None, NONE_EVAL, 0.1)["verdict"] == "none"
    assert verdict([fric], None, NONE_EVAL, 0.1, own_reduction=own)["verdict"] == "none"


def test_an_effect_joins_the_set_once():
    """Draw 9019 listed rolling resistance twice: a near miss on all windows and again
    on the free windows."""
    from adaptive_c3.tools.diagnosis.engine.evidence import _join, fit_row
    near = _fit("rolling_resistance", "ball_table", NONE - 7 + RNG.normal(0, 1, 30), NONE)
    judged = verdict([near], None, NONE_EVAL, 0.1)
    assert [a["name"] for a in judged["ambiguous"]] == ["none", "rolling_resistance"]
    _join(judged, fit_row(None, NONE_EVAL), dict(fit_row(near, NONE_EVAL), note="free windows"))
    assert [a["name"] for a in judged["ambiguous"]] == ["none", "rolling_resistance"]
    assert len(judged["separating_excitation"]) == 1


def test_a_named_effect_whose_interval_holds_the_models_value_is_not_confident():
    """Set 3 (seeds 51000-51047) named effects whose own 95 % interval held the model's
    value: clean draw 51028, EE-ball offset 0.11 mm [-2.25, 2.48]; 51029 (rolling
    resistance), drag 9.15 [-10.5, 28.8]. Such an effect is as consistent with the data
    as the model without it: the verdict is ambiguous with `none`, and a pair with an
    unsupported member is ambiguous with the single fit of the other member."""
    from adaptive_c3.tools.diagnosis.engine.evidence import require_support
    from adaptive_c3.tools.diagnosis.tasks.ball_rolling.effects_ball import ball_spec
    spec = ball_spec(load_scenario(BALL)[0])
    drag = _fit("viscous_damping", "ball", NONE - 20 + RNG.normal(0, 1, 30), NONE)
    drag.values[:], drag.ci[:], drag.sd[:] = 0.09, [-0.1, 0.28], 0.097
    judged = verdict([drag], drag, NONE_EVAL, 0.1)
    assert judged["verdict"] == "named"
    require_support(judged, spec, drag, [drag], NONE_EVAL)
    assert judged["verdict"] == "ambiguous"
    assert [a["name"] for a in judged["ambiguous"]] == ["viscous_damping", "none"]
    assert "holds the model's value" in judged["ambiguous"][1]["reason"]
    from adaptive_c3.tools.diagnosis.engine.report import ambiguity_summary
    assert "none (held-out" in ambiguity_summary(judged)
    assert "viscous_damping[ball]: its 95 % interval holds" in ambiguity_summary(judged)
    assert judged["separating_excitation"][0]["between"] == ["viscous_damping", "none"]
    assert judged["separating_excitation"][0]["excitation"]["release_speed"] == [0.05, 0.3]
    # the same effect with an interval clear of zero stays named
    drag.ci[:] = [0.05, 0.13]
    judged = verdict([drag], drag, NONE_EVAL, 0.1)
    require_support(judged, spec, drag, [drag], NONE_EVAL)
    assert judged["verdict"] == "named"
    # an offset is read as the total offset: a calibration shift can carry it off zero
    off = _fit("contact_offset", "ball_table", NONE - 20 + RNG.normal(0, 1, 30), NONE)
    off.values[:], off.ci[:], off.sd[:] = 2e-4, [-3e-4, 7e-4], 2.5e-4
    judged = verdict([off], off, NONE_EVAL, 0.1)
    require_support(judged, spec, off, [off], NONE_EVAL, shift={"ball_table": 9e-4})
    assert judged["verdict"] == "named"
    require_support(judged, spec, off, [off], NONE_EVAL)
    assert [a["name"] for a in judged["ambiguous"]] == ["contact_offset", "none"]
    # a pair (51005: the true EE-ball offset with a mass) whose mass holds 1
    ee = _fit("contact_offset", "ee_ball", NONE - 10 + RNG.normal(0, 0.5, 30), NONE)
    best = _fit("contact_offset", "ee_ball", NONE - 20 + RNG.normal(0, 0.5, 30), NONE)
    pair = Fit((Candidate("contact_offset", "ee_ball"), Candidate("mass_scale", "ball")),
               np.array([3e-3, 1.1]), np.array([[2e-3, 4e-3], [0.7, 1.5]]),
               np.array([5e-4, 0.2]), 0.0)
    _score_as(pair, best)
    judged = verdict([ee, pair], pair, NONE_EVAL, 0.1)
    assert judged["verdict"] == "named"
    require_support(judged, spec, pair, [ee, pair], NONE_EVAL)
    assert [a["name"] for a in judged["ambiguous"]][1] == "contact_offset"
    assert judged["ambiguous"][1]["target"] == "ee_ball"
    assert "mass_scale[ball]" in judged["ambiguous"][1]["reason"]
    assert judged["separating_excitation"][-1]["excitation"]["peak_accel"] == [8.0, 12.0]
    # an offset of every pair (51023: a table 1.25 mm off, named r_comp over both pairs)
    # whose EE-ball part holds zero is ambiguous with the table offset alone
    table = _fit("contact_offset", "ball_table", NONE - 10 + RNG.normal(0, 0.5, 30), NONE)
    rc = Fit((Candidate("r_comp", "all_pairs"),), np.array([1e-4, 1.05e-3]),
             np.array([[-4e-4, 6e-4], [8e-4, 1.3e-3]]), np.array([2.5e-4, 1.2e-4]), 0.0)
    _score_as(rc, best)
    judged = verdict([table, rc], rc, NONE_EVAL, 0.1)
    require_support(judged, spec, rc, [table, rc], NONE_EVAL)
    assert [(a["name"], a["target"]) for a in judged["ambiguous"]] == [
        ("r_comp", "all_pairs"), ("contact_offset", "ball_table")]


def test_a_none_that_cannot_rule_out_a_size_that_matters_is_ambiguous():
    """`none` claims the data exclude every effect of a size that matters. Clean
    calibration draw 201: mass 95 % interval 0.61-1.69 (nothing cut the held-out SSR);
    draws 8008 and 9010, balls 1.65x and 1.48x heavier, were reported a confident
    `none` with intervals 0.99-1.96 and 0.58-2.59. The mass size that matters is a
    factor of 2: 9010's interval reaches it, 201's does not."""
    from adaptive_c3.tools.diagnosis.tasks.ball_rolling.effects_ball import ball_spec
    spec = ball_spec(load_scenario(BALL)[0])
    mass = _fit("mass_scale", "ball", NONE + RNG.normal(0, 1, 30), NONE)
    fric = _fit("friction_coefficient", "ee_ball", mass.test_cluster_ssr, NONE)
    table = _fit("friction_coefficient", "ball_table", mass.test_cluster_ssr, NONE)
    drag = _fit("viscous_damping", "ball", mass.test_cluster_ssr, NONE)
    mass.ci[:] = [0.58, 2.59]
    fric.ci[:] = [0.8, 1.4]            # a higher mu acts as the model's 1: not a size
    table.ci[:] = [-12.0, 14.0]        # that matters; table mu is not listed
    drag.ci[:] = [-0.3, 0.05]          # drag is never negative
    judged = verdict([mass, fric, table, drag], None, NONE_EVAL, 0.1)
    assert judged["verdict"] == "none"
    not_excluded(judged, spec, [mass, fric, table, drag], NONE_EVAL)
    assert judged["verdict"] == "ambiguous"
    assert [a["name"] for a in judged["ambiguous"]] == ["none", "mass_scale"]
    assert judged["ambiguous"][1]["ci95"] == [0.58, 2.59]
    assert judged["separating_excitation"][0]["between"] == ["none", "mass_scale"]
    _pushes_end_at_rest(judged["separating_excitation"][0]["excitation"])
    from adaptive_c3.tools.diagnosis.engine.report import ambiguity_summary
    assert "not excluded: 95% interval 0.58 to 2.59" in ambiguity_summary(judged)
    # a free-ball effect's interval is read from its free-window fit; its score is global
    drag_free = _fit("viscous_damping", "ball", mass.test_cluster_ssr, NONE)
    drag_free.ci[:] = [-0.02, 0.3]
    judged = verdict([drag], None, NONE_EVAL, 0.1)
    not_excluded(judged, spec, [drag], NONE_EVAL, [drag_free])
    assert [a["name"] for a in judged["ambiguous"]] == ["none", "viscous_damping"]
    assert "free windows" in judged["ambiguous"][1]["note"]
    assert judged["ambiguous"][1]["ci95"] == [-0.02, 0.3]
    assert judged["ambiguous"][1]["held_out_score"] == pytest.approx(np.sqrt(drag.test_ssr / 1000))
    # intervals inside the sizes that matter leave `none` confident (201's 0.61-1.69)
    mass.ci[:] = [0.61, 1.69]
    judged = verdict([mass, fric], None, NONE_EVAL, 0.1)
    not_excluded(judged, spec, [mass, fric], NONE_EVAL)
    assert judged["verdict"] == "none" and judged["ambiguous"] == []
    # a named effect is left as it is
    best = _fit("rolling_resistance", "ball_table", NONE - 20 + RNG.normal(0, 1, 30), NONE)
    mass.ci[:] = [0.2, 2.0]
    judged = verdict([best, mass], best, NONE_EVAL, 0.1)
    not_excluded(judged, spec, [best, mass], NONE_EVAL)
    assert judged["verdict"] == "named"


def test_a_none_reads_an_offset_with_the_calibration_it_sits_on():
    """The +-1 mm calibration nuisance is fitted first and a contact_offset of the same
    pair on top of it; `none` must exclude a 1 mm TOTAL offset. Evaluation draw 41011 (a
    1.03 mm table offset, 0.71 mm of it taken by the calibration, the rest's interval
    inside +-1 mm) was answered without the offset in its set."""
    from adaptive_c3.tools.diagnosis.tasks.ball_rolling.effects_ball import ball_spec
    spec = ball_spec(load_scenario(BALL)[0])
    table = _fit("contact_offset", "ball_table", NONE + RNG.normal(0, 1, 30), NONE)
    table.values[:] = 0.25e-3
    table.ci[:] = [0.1e-3, 0.4e-3]
    judged = verdict([table], None, NONE_EVAL, 0.1)
    not_excluded(judged, spec, [table], NONE_EVAL, shift={"ball_table": 0.71e-3})
    assert [a["name"] for a in judged["ambiguous"]] == ["none", "contact_offset"]
    assert judged["ambiguous"][1]["ci95"] == pytest.approx([0.81e-3, 1.11e-3])
    assert judged["ambiguous"][1]["values"] == pytest.approx([0.96e-3])
    # the calibration of the other pair does not move it; without a shift it is excluded
    for shift in ({"ee_ball": 0.71e-3}, None):
        judged = verdict([table], None, NONE_EVAL, 0.1)
        not_excluded(judged, spec, [table], NONE_EVAL, shift=shift)
        assert judged["verdict"] == "none"


def test_the_ee_ball_offset_is_reported_through_the_lcs_model_form():
    """Against Drake's compliant contact the LCS's best EE-ball offset reads ~+0.16 mm
    on draws without one and ~1.25x a true 2.5-2.9 mm one, whatever the stiffness or
    noise (BallSpec.model_form_bias). Development draw 12034 (effective truth 2.89 mm)
    was reported 3.55 mm, 95 % interval 3.22-3.88 mm: the reported physical value maps
    the model's back, the model form's spread widens the interval; the model's own
    value stays for the patch."""
    from adaptive_c3.tools.diagnosis.tasks.ball_rolling.effects_ball import ball_spec
    from adaptive_c3.tools.diagnosis.engine.report import effect_params
    spec = ball_spec(load_scenario(BALL)[0])
    f = Fit((Candidate("contact_offset", "ee_ball"),), np.array([3.55e-3]),
            np.array([[3.22e-3, 3.88e-3]]), np.array([1.68e-4]), 0.0)
    p = effect_params(f, spec)[0]["params"][0]
    lo, hi = p["ci95"]
    assert lo < 2.89e-3 < hi and p["value"] == pytest.approx((3.55e-3 - 1.6e-4) / 1.25)
    assert p["model_value"] == pytest.approx(3.55e-3) and hi - lo > 3.88e-3 - 3.22e-3
    # a draw without an offset (12021: +0.09 mm read for +0.07 mm) stays well inside
    # the 1 mm that matters; a negative one is only shifted
    f.values[:], f.ci[:] = 0.09e-3, [[-0.1e-3, 0.28e-3]]
    p = effect_params(f, spec)[0]["params"][0]
    assert -0.6e-3 < p["ci95"][0] < 0.0 < p["ci95"][1] < 0.6e-3
    f.values[:], f.ci[:] = -0.19e-3, [[-0.5e-3, 0.12e-3]]
    assert effect_params(f, spec)[0]["params"][0]["value"] == pytest.approx(-0.35e-3)
    # the table offset (no listed model form) is reported as fitted
    f.values[:], f.ci[:] = 3.55e-3, [[3.22e-3, 3.88e-3]]
    f.cands = (Candidate("contact_offset", "ball_table"),)
    p = effect_params(f, spec)[0]["params"][0]
    assert p["value"] == pytest.approx(3.55e-3) and p["ci95"] == pytest.approx([3.22e-3, 3.88e-3])


def test_a_pair_with_a_calibration_sized_offset_is_no_choice():
    """Dev draw 12038 (a -0.78 mm table offset; EE and ball radii 0.26 / 0.23 mm off)
    was answered `contact_offset[ball_table] + contact_offset[ee_ball]` with 0.70 mm on
    the EE-ball pair: inside the +-1 mm calibration tolerance that part is calibration,
    as it is for r_comp; the table offset competes on its own."""
    from adaptive_c3.tools.diagnosis.tasks.ball_rolling.effects_ball import ball_spec
    from adaptive_c3.tools.diagnosis.engine.selection import _calibration_sized
    spec = ball_spec(load_scenario(BALL)[0])

    def fit(cands, values):
        values = np.array(values, float)
        return Fit(tuple(Candidate(*c) for c in cands), values, np.zeros((len(values), 2)),
                   np.zeros(len(values)), 0.0)
    table, ee = ("contact_offset", "ball_table"), ("contact_offset", "ee_ball")
    assert _calibration_sized(fit([table, ee], [-6.2e-4, 7.0e-4]), spec)
    assert _calibration_sized(fit([("mass_scale", "ball"), ee], [1.5, 4e-4]), spec)
    assert not _calibration_sized(fit([table, ee], [-2.2e-3, 1.4e-3]), spec)
    assert not _calibration_sized(fit([table], [-1.2e-3]), spec)      # a single competes
    assert not _calibration_sized(fit([("mass_scale", "ball"), ("viscous_damping", "ball")],
                                      [1.5, 4e-4]), spec)


def test_a_single_offset_whose_total_is_within_the_calibration_tolerance_is_no_choice():
    """A contact_offset on top of its pair's kept calibration is read as their total from
    the user's model (report.calibration_shift); within the +-1 mm tolerance it is that
    calibration re-estimated, not an effect. The twenty-fourth set's 100315 (an EE-ball
    offset of 1.06 mm) named a table offset of -0.30 mm on a 0.50 mm table calibration:
    0.20 mm in total."""
    from adaptive_c3.tools.diagnosis.tasks.ball_rolling.effects_ball import ball_spec
    from adaptive_c3.tools.diagnosis.engine.selection import _calibration_sized, base_shift
    spec = ball_spec(load_scenario(BALL)[0])

    def fit(cands, values):
        values = np.array(values, float)
        return Fit(tuple(Candidate(*c) for c in cands), values, np.zeros((len(values), 2)),
                   np.zeros(len(values)), 0.0)
    table = ("contact_offset", "ball_table")
    assert _calibration_sized(fit([table], [-6.2e-4]), spec)           # no calibration kept
    assert _calibration_sized(fit([table], [-3.0e-4]), spec, {"ball_table": 5.0e-4})
    assert not _calibration_sized(fit([table], [6.0e-4]), spec, {"ball_table": 5.0e-4})
    # another pair's calibration does not count toward this pair's total
    assert _calibration_sized(fit([table], [6.0e-4]), spec, {"ee_ball": 5.0e-4})
    assert not _calibration_sized(fit([("mass_scale", "ball")], [1.5]), spec, {"ee_ball": 5e-4})

    class Base:
        base = [(Candidate("calibration_offset", "ball_table"), np.array([5e-4])),
                (Candidate("actuator_delay", ""), np.array([0.006])),
                (Candidate("calibration_offset", "ee_ball"), np.array([-2e-4]))]
    assert base_shift(Base) == {"ball_table": 5e-4, "ee_ball": -2e-4}


@pytest.fixture(scope="module")
def delayed_force_report(tmp_path_factory):
    """The CLI on a drawn external force with an 8 ms sensor delay and a softer contact."""
    from adaptive_c3.tools.cli import main
    from adaptive_c3.tools.recording import save_recording
    scenario = load_scenario(BALL)[0]
    var = Variation(stiffness=3e4, relaxation_time=4e-3, sensor_delay=0.008, table_dz=0.0)
    rec, truth, _ = concealed_draw(41, name="external_force", target="ball_y", variation=var,
                                   params=ModelParams.from_scenario(scenario))
    tmp = tmp_path_factory.mktemp("delay")
    save_recording(tmp / "rec.npz", rec)
    assert main(["diagnose", str(tmp / "rec.npz"), "--scenario", BALL,
                 "--out", str(tmp / "d")]) == 0
    return json.loads((tmp / "d" / "report.json").read_text()), truth


def test_sensor_delay_is_fitted_as_a_nuisance(delayed_force_report):
    report, _ = delayed_force_report
    assert [n["name"] for n in report["nuisance"]] == ["actuator_delay"]
    assert abs(report["nuisance"][0]["params"][0]["value"] - 0.008) < 0.002
    assert report["scenario_effects"] == []


def test_delayed_force_named_with_its_evidence(delayed_force_report):
    report, truth = delayed_force_report
    sel = report["selected"][0]
    assert (sel["name"], sel["target"]) == ("external_force", "ball_y"), report["summary"]
    lo, hi = sel["params"][0]["ci95"]
    assert lo <= truth.value <= hi
    assert report["verdict"] in ("named", "ambiguous")
    ev = report["evidence"]
    assert ev["phases"] == ["coast", "rest"] and ev["windows"]
    assert {w["phase"] for w in ev["windows"]} <= {"coast", "rest"}


# ------------------------------------------------------------------ the hit rate
@pytest.mark.parametrize("seed,name,target", [(34, "rolling_resistance", "ball_table"),
                                              (35, "none", "")])
def test_hit_rate_fast(seed, name, target):
    """Two varied draws scored as the slow run scores them: the truth named first, or
    (ambiguous verdict) inside the ambiguous set; the summary counts them."""
    from adaptive_c3.tools.diagnosis.harness.ball_hit_rate import summarise
    from adaptive_c3.tools.diagnosis.harness.concealed_ball_data import score_draw
    row = score_draw(seed, baseline=False, pairs=False, name=name, target=target)
    assert row["named"] or row["in_ambiguous_set"], row
    label = f"{name}[{target}]" if target else name
    assert summarise([row])["per_effect"][label]["draws"] == 1


# ------------------------------------------------------------------ the hit rate (slow)
@pytest.mark.slow
def test_ball_per_effect_hit_rate_slow(tmp_path):
    """>= 40 concealed draws with the second-engine variation, each ambiguous verdict
    followed by one recording with the excitation the report proposed (as its user
    would); writes JSON + a figure. Bars for the first answer and after the follow-up."""
    from adaptive_c3.tools.diagnosis.harness.ball_hit_rate import run
    out = os.environ.get("ADAPTIVE_C3_BALL_HIT_RATE_DIR") or str(tmp_path)
    s = run(40, 8000, Path(out), follow_up=True)
    print(json.dumps(s, indent=1))
    assert s["draws"] >= 40
    # measured bars (not all of the targets are reached: see README)
    assert s["named"] >= SLOW_NAMED, s
    assert s["truth_in_ambiguous"] is None or s["truth_in_ambiguous"] >= SLOW_IN_AMBIGUOUS, s
    assert s["none_on_clean"] >= SLOW_NONE_ON_CLEAN, s
    assert s["coverage"] >= SLOW_COVERAGE, s
    f = s["after_follow_up"]
    assert f["named"] >= SLOW_NAMED_AFTER_FOLLOW_UP, f
    assert f["none_on_clean"] == 1.0, f
    assert f["coverage"] >= SLOW_COVERAGE, f
    assert f["truth_in_ambiguous"] is None or f["truth_in_ambiguous"] == 1.0, f
    assert f["confident_wrong"] == 0, f       # a miss is reported ambiguous, truth in the set


SLOW_NAMED = 0.75         # measured 0.80 (32/40), seeds 8000-8039 (0.725 before mass got
                          # its own significance bar, 0.55 before the calibration nuisance)
SLOW_IN_AMBIGUOUS = 0.85  # measured 1.0 (19/19 ambiguous draws; 0.73 at first, 0.93
                          # before a `none` had to rule out the sizes that matter)
SLOW_NONE_ON_CLEAN = 0.8  # measured 4/5 (2/5 at first)
SLOW_COVERAGE = 0.85      # measured 0.93 (26/28 named draws; 0.80 before the nuisance
                          # and push-force allowances on the interval); 0.90 after follow-up
SLOW_NAMED_AFTER_FOLLOW_UP = 0.9   # measured 0.975 (39/40: mass draw 8021 is {none, mass,
                                   # friction}; 0.90 before the sizes that matter)


def test_calibration_offset_is_a_nuisance_only_and_folds_into_a_selected_offset():
    """A table height / tool radius within +-1 mm is calibration (issue 19: the second
    engine's table is off by up to 0.3 mm): fitted as a nuisance, never a candidate; a
    selected contact_offset / r_comp of the same pair reports the offset from the
    user's model, the calibration included."""
    from types import SimpleNamespace

    from adaptive_c3.scenarios.schema import SCENARIO_DIR, load_scenario
    from adaptive_c3.tools.diagnosis.backends.effects import EFFECTS, Candidate, applicable_candidates
    from adaptive_c3.tools.diagnosis.tasks.ball_rolling.effects_ball import ball_spec
    from adaptive_c3.tools.diagnosis.engine.report import effect_params
    spec = ball_spec(load_scenario(SCENARIO_DIR / "ball_rolling.yaml")[0])
    assert EFFECTS["calibration_offset"].nuisance_only
    assert ("calibration_offset", "ball_table") in spec.nuisance
    assert all(c.name != "calibration_offset" for c in applicable_candidates(spec)[0])
    shift = {"ball_table": 4e-4}
    off = SimpleNamespace(cands=[Candidate("contact_offset", "ball_table")],
                          values=np.array([2e-3]), ci=np.array([[1.8e-3, 2.2e-3]]),
                          sd=np.array([1e-4]))
    p = effect_params(off, spec, shift)[0]["params"][0]
    assert p["value"] == pytest.approx(2.4e-3) and p["ci95"] == pytest.approx([2.2e-3, 2.6e-3])
    rc = SimpleNamespace(cands=[Candidate("r_comp", "all_pairs")], values=np.array([1e-3, 1e-3]),
                         ci=np.zeros((2, 2)), sd=np.zeros(2))
    vals = [q["value"] for q in effect_params(rc, spec, shift)[0]["params"]]
    assert vals == pytest.approx([1e-3, 1.4e-3])           # pairs: ee_ball, ball_table
    mu = SimpleNamespace(cands=[Candidate("friction_coefficient", "ball_table")],
                         values=np.array([0.5]), ci=np.array([[0.4, 0.6]]), sd=np.array([0.05]))
    assert effect_params(mu, spec, shift)[0]["params"][0]["value"] == 0.5


@pytest.mark.parametrize("seed, effect, calibration_kept, named", [
    # table off by -0.29 mm: kept. EE-ball mu 0.197 was named first (cut 31.5 %) by the
    # relaxed cone's open-pair reach; with the open-pair gate (issue 30) its cut is
    # 0.5-1.7 % and the verdict was ambiguous (none, EE-ball friction, mass); on the
    # windows the fit left out mu beats `none` and the mass (z 2.02 against the mass:
    # engine/left_out_rivals.py), so it is named, 0.229 [0.144, 0.314]
    (8019, "friction_coefficient", True, True),
    (8026, "contact_offset", False, True),    # a 2.3 mm EE-ball offset is not calibration
])
def test_calibration_nuisance_on_concealed_draws(seed, effect, calibration_kept, named):
    from adaptive_c3.tools.diagnosis.harness.concealed_ball_data import score_draw
    r = score_draw(seed, baseline=False)
    assert r["truth"]["name"] == effect
    if named:
        assert r["named"], r["selected"]
    else:
        assert r["verdict"] == "ambiguous" and r["in_ambiguous_set"], r["selected"]
    kept = [n for n in r["nuisance"] if n["name"].startswith("calibration_offset")]
    assert bool(kept) is calibration_kept, r["nuisance"]
    assert all(abs(n["values"][0]) < 1e-3 for n in kept)


@pytest.mark.parametrize("seed, effect", [
    (8002, "friction_coefficient"),    # mu 0.131 read as 0.198 +- 0.034 before
    (8005, "contact_offset"),          # -2.92 mm read as -2.63 +- 0.06 mm before
    # EE-ball 2.34 mm read as 2.75 +- 0.18 mm before; with the open-pair gate (issue 30)
    # 2.77 mm (light pushes 2.62, firm 2.84), the interval missing the truth (a strict
    # xfail). Read through the LCS's measured model form (BallSpec.model_form_bias,
    # calibrated on seeds 12000-12039 and 777, not this one) the interval holds it again
    (8026, "contact_offset"),
])
def test_interval_allows_for_the_nuisances_and_the_push_force(seed, effect):
    """The chosen effect refitted with the spec's nuisances free (sensor delay, the
    calibrations of pairs it does not offset itself), and on light and firm pushes
    apart: the shift and the spread widen the interval, which then holds the truth on
    these draws it missed before."""
    from adaptive_c3.tools.diagnosis.harness.concealed_ball_data import score_draw
    r = score_draw(seed, baseline=False)
    assert r["truth"]["name"] == effect and r["named"], r["selected"]
    assert r["in_interval"], r["selected"]
