"""ball_hit_rate's summary reports the answers separately: an ambiguous verdict is never
counted as right (issue 30)."""
from adaptive_c3.tools.diagnosis.harness.ball_hit_rate import ANSWERS, answer, answer_line, summarise


def _row(truth, verdict, named, in_set=None, in_ci=False):
    return dict(truth=dict(name=truth, target="ball" if truth != "none" else "", value=1.0),
                verdict=verdict, named=named, in_ambiguous_set=in_set, in_interval=in_ci,
                favoured=named and verdict != "ambiguous", excess_cut=2.0, clean_cut=2.0)


def test_summary_separates_confident_and_ambiguous_answers():
    rows = [_row("mass_scale", "named", True, in_ci=True),       # confident right
            _row("mass_scale", "named", False),                  # confident wrong
            _row("viscous_damping", "ambiguous", True, True),    # named first, ambiguous
            _row("viscous_damping", "ambiguous", False, False),  # ambiguous without truth
            _row("none", "named", True)]
    s = summarise(rows)
    assert (s["confident_right"], s["confident_wrong"], s["ambiguous_with_truth"],
            s["ambiguous_without_truth"], s["named_first"], s["truth_in_interval"]) == \
        (2, 1, 1, 1, 3, 1)
    line = answer_line(s)
    assert "confident right 2/5" in line and "ambiguous with the truth 1/5" in line
    rows[3]["follow_up"] = _row("viscous_damping", "named", True, in_ci=True)
    f = summarise(rows)["after_follow_up"]
    assert (f["confident_right"], f["ambiguous_without_truth"], f["follow_ups"]) == (3, 0, 1)


def _draw(truth, value, target, selected, verdict, ambiguous=()):
    """A scored row as concealed_ball_data._score leaves it before the size rule."""
    from adaptive_c3.tools.diagnosis.harness.concealed_data import Truth, _named
    t = Truth(truth, target, value, "")
    amb = list(ambiguous)
    row = dict(truth=t.as_dict(), selected=[dict(name=n, target=g) for n, g in selected],
               verdict=verdict, ambiguous=amb, in_interval=False, excess_cut=1.0,
               clean_cut=1.0, in_ambiguous_set=(f"{truth}[{target}]" in amb) if amb else None)
    row["named"] = _named(row["selected"], t)
    return t, row


def test_an_effect_too_small_to_matter_is_right_as_none():
    """A concealed effect below its size that matters (BallSpec.relevant_size) is scored
    right when the answer is `none`, and an ambiguous set holding `none` holds the truth;
    above that size `none` stays wrong. The four answers sum to the draws."""
    from adaptive_c3.scenarios.schema import SCENARIO_DIR, load_scenario
    from adaptive_c3.tools.diagnosis.harness.concealed_ball_data import apply_size_rule
    from adaptive_c3.tools.diagnosis.tasks.ball_rolling.effects_ball import ball_spec
    spec = ball_spec(load_scenario(SCENARIO_DIR / "ball_rolling.yaml")[0])
    none = [("none", "")]
    cases = [  # (truth, value, target, selected, verdict, ambiguous) -> answer
        (("mass_scale", 1.9, "ball", none, "none"), "confident_right"),
        (("mass_scale", 2.2, "ball", none, "none"), "confident_wrong"),
        (("mass_scale", 0.45, "ball", none, "none"), "confident_wrong"),
        (("mass_scale", 0.75, "ball", [("mass_scale", "ball")], "named"), "confident_right"),
        (("external_force", -0.007, "ball_x", none, "ambiguous",
          ["none", "mass_scale[ball]"]), "ambiguous_with_truth"),
        (("external_force", -0.02, "ball_x", none, "ambiguous",
          ["none", "mass_scale[ball]"]), "ambiguous_without_truth"),
        (("friction_coefficient", 0.6, "ee_ball", none, "none"), "confident_right"),
        (("friction_coefficient", 0.45, "ee_ball", none, "none"), "confident_wrong"),
        (("contact_offset", 8e-4, "ee_ball", [("contact_offset", "ball_table")], "named"),
         "confident_wrong"),
        (("viscous_damping", 0.05, "ball", [("viscous_damping", "ball")], "named"),
         "confident_right"),
        (("none", 0.0, "", [("rolling_resistance", "ball_table")], "named"), "confident_wrong"),
    ]
    rows = []
    for args, want in cases:
        t, row = _draw(*args)
        apply_size_rule(row, t, spec)
        row["favoured"] = row["named"] and row["verdict"] != "ambiguous"
        assert answer(row) == want, (args, row)
        rows.append(row)
    s = summarise(rows)
    assert sum(s[a] for a in ANSWERS) == s["draws"] == len(cases)
    assert (s["confident_right"], s["confident_wrong"], s["ambiguous_with_truth"],
            s["ambiguous_without_truth"]) == (4, 5, 1, 1)
    assert s["below_size_draws"] == 6 and s["below_size"]["confident_right"] == 4
    # named effect draws (interval, excess cut): the answers that name the true effect
    assert s["named_effect_count"] == 2
    assert s["per_effect"]["mass_scale[ball]"]["confident_right"] == 2


def test_a_row_keeps_why_each_member_joined_and_the_size_tests():
    """The harness row keeps each ambiguous member's note and every size test, so how
    often a rule let an effect join `none` can be counted on an evaluation set."""
    from adaptive_c3.tools.diagnosis.harness.concealed_ball_data import Truth, judged_fields
    note = "not excluded: its fit is worse than `none` on the held-out windows, ..."
    tests = [dict(name="friction_coefficient[ee_ball]", excluded=False,
                  tested=[dict(value=0.5, z_vs_none=-0.45)]),
             dict(name="mass_scale[ball]", excluded=True,
                  tested=[dict(value=0.5, z_vs_none=-4.0), dict(value=2.0, z_vs_none=-3.9)])]
    errors = {tag: dict(rollout=dict(excess_over_noise=e)) for tag, e in (("before", 1.2),
                                                                         ("after", 0.3))}
    reason = "viscous_damping[ball]: its 95 % interval holds the model's value"
    result = dict(judged=dict(verdict="ambiguous", size_tests=tests, ambiguous=[
        dict(name="viscous_damping", target="ball"),
        dict(name="none", target="", reason=reason),
        dict(name="friction_coefficient", target="ee_ball", note=note)]), errors=errors)
    row = judged_fields(result, Truth("friction_coefficient", "ee_ball", 0.35, "1"))
    assert row["in_ambiguous_set"] is True
    # a not_excluded member's `note`, and require_support's `reason` for `none`
    assert row["ambiguous_notes"] == ["", reason, note]
    assert row["size_excluded"] == ["mass_scale[ball]"]
    assert row["size_tests"] == tests
    assert row["excess_cut"] == 1.2 / 0.3


def test_the_summary_counts_the_confirmations_on_the_left_out_windows():
    """Tested, confirmed, and confirmed on the true effect (a pair holding it counts);
    stopped by a nuisance rival (a failed test that holds rivals: it beat `none`), and
    stopped while it held the truth."""
    rows = [_row("mass_scale", "named", True), _row("mass_scale", "ambiguous", False, True),
            _row("viscous_damping", "named", True), _row("none", "named", False),
            _row("none", "named", True), _row("friction_coefficient", "ambiguous", False, True),
            _row("friction_coefficient", "ambiguous", False, True)]
    rows[-1]["truth"]["target"] = "ee_ball"
    rival = [dict(name="actuator_delay", z_effect_vs_it=0.5, z_it_vs_none=2.2)]
    conf = [("mass_scale[ball]", True, []), ("mass_scale[ball]", False, []),
            ("contact_offset[ee_ball] + viscous_damping[ball]", True, []),
            ("contact_offset[ee_ball]", True, []), None,
            ("mass_scale[ball]", False, rival), ("friction_coefficient[ee_ball]", False, rival)]
    for r, c in zip(rows, conf):
        r["confirmation"] = c and dict(name=c[0], confirmed=c[1], z_vs_none=2.5,
                                       nuisance_rivals=c[2])
    assert summarise(rows)["confirmations"] == dict(
        tested=6, confirmed=3, confirmed_the_truth=2, stopped_by_nuisance=2,
        stopped_the_truth=1)


def test_the_summary_counts_the_beyond_size_tests():
    """Answers with a member tested beyond its size, and those whose `none` left."""
    rows = [_row("friction_coefficient", "named", True), _row("none", "ambiguous", True, True),
            _row("none", "named", True)]
    rows[0]["beyond_size"] = [dict(name="friction_coefficient[ee_ball]", beyond=True)]
    rows[1]["beyond_size"] = [dict(name="friction_coefficient[ee_ball]", beyond=False),
                              dict(name="mass_scale[ball]", beyond=False)]
    assert summarise(rows)["beyond_size"] == dict(tested=2, none_out=1)


def test_the_summary_counts_sizes_ruled_out_by_one_recording_alone():
    """An exclusion the pooled test did not reach (z above the bar shared by the pooled
    test and each recording's) counts; one the pooled test reached, or a test not
    excluded, does not."""
    rows = [_row("none", "named", True) for _ in range(3)]
    rows[0]["size_tests"] = [dict(name="mass_scale[ball]", excluded=True, tested=[
        dict(value=2.0, z_vs_none=-0.99, by_recording=[-2.25, 0.4], bar=2.13)])]
    rows[1]["size_tests"] = [dict(name="mass_scale[ball]", excluded=True, tested=[
        dict(value=2.0, z_vs_none=-2.5, by_recording=[-2.25, -1.0], bar=2.13)])]
    rows[2]["size_tests"] = [dict(name="mass_scale[ball]", excluded=False, tested=[
        dict(value=2.0, z_vs_none=-0.99, by_recording=[-1.5, 0.4], bar=2.13)])]
    assert summarise(rows)["excluded_by_one_recording"] == 1


def test_the_summary_counts_the_rivals_dropped_on_the_left_out_windows():
    """Draws with a left-out rival test, the rivals dropped, and those that were the
    truth (a drag dropped where the truth was a drag)."""
    rows = [_row("viscous_damping", "named", True), _row("viscous_damping", "named", True),
            _row("rolling_resistance", "ambiguous", False, True), _row("none", "named", True)]
    rows[2]["truth"]["target"] = "ball_table"

    def rival(name, dropped):
        return dict(name=name, beaten_by="x", z=2.5, bar=2.24, dropped=dropped, windows=300)
    rows[0]["left_out_rivals"] = [rival("rolling_resistance[ball_table]", True)]
    rows[1]["left_out_rivals"] = [rival("viscous_damping[ball]", True),
                                  rival("mass_scale[ball]", True)]
    rows[2]["left_out_rivals"] = [rival("rolling_resistance[ball_table]", False)]
    assert summarise(rows)["left_out_rivals"] == dict(tested=3, dropped=3,
                                                      dropped_the_truth=1)
