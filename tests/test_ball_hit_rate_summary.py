"""ball_hit_rate's summary reports the answers separately: an ambiguous verdict is never
counted as right (issue 30)."""
from adaptive_c3.tools.diagnosis.harness.ball_hit_rate import answer_line, summarise


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
