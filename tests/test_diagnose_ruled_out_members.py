"""Issue 30: an effect beside `none` whose every size that matters the size tests ruled out
(the model fixed there clearly worse than `none` on held-out windows) leaves the set; the
verdict is `none` when nothing else is left (engine/boundary.py ruled_out_members)."""
from adaptive_c3.tools.diagnosis.engine.boundary import ruled_out_members
from adaptive_c3.tools.diagnosis.engine.proposals import proposal
from adaptive_c3.tools.diagnosis.engine.report import ambiguity_summary


def _row(name, target=""):
    return dict(name=name, target=target)


def _test(label, excluded, zs=(-3.7, -4.1)):
    return dict(name=label, excluded=excluded,
                tested=[dict(value=v, z_vs_none=z) for v, z in zip((0.5, 2.0), zs)])


def _judged(rows, tests):
    names = [r["name"] for r in rows]
    return dict(verdict="ambiguous", ambiguous=rows, size_tests=tests,
                evidence=dict(windows=[]),
                separating_excitation=[proposal([a, b], ("x", {}))
                                       for i, a in enumerate(names) for b in names[i + 1:]])


def test_a_member_whose_sizes_were_all_ruled_out_leaves_and_none_is_the_answer():
    """101411 after its follow-up: mass 1.4x led {mass, none}; the ball at 0.5x and 2x was
    clearly worse than `none` on held-out windows, so the answer is `none`."""
    j = _judged([_row("mass_scale", "ball"), _row("none")],
                [_test("mass_scale[ball]", True)])
    assert ruled_out_members(j) == ["mass_scale[ball]"]
    assert j["verdict"] == "none" and j["ambiguous"] == [] and j["separating_excitation"] == []
    assert "evidence" not in j and j["ruled_out_members"] == ["mass_scale[ball]"]
    assert "so not kept beside `none`: mass_scale[ball]." in ambiguity_summary(j)


def test_the_others_stay_beside_none():
    j = _judged([_row("none"), _row("mass_scale", "ball"), _row("viscous_damping", "ball")],
                [_test("mass_scale[ball]", True), _test("viscous_damping[ball]", False,
                                                        (-1.0, 0.5))])
    assert ruled_out_members(j) == ["mass_scale[ball]"]
    assert j["verdict"] == "ambiguous"
    assert [a["name"] for a in j["ambiguous"]] == ["none", "viscous_damping"]
    assert [p["between"] for p in j["separating_excitation"]] == [["none", "viscous_damping"]]


def test_a_member_not_ruled_out_or_a_set_without_none_is_left_as_it_is():
    kept = _judged([_row("mass_scale", "ball"), _row("none")],
                   [_test("mass_scale[ball]", False, (-3.7, 1.2))])
    assert ruled_out_members(kept) == [] and kept["verdict"] == "ambiguous"
    assert len(kept["ambiguous"]) == 2
    no_none = _judged([_row("mass_scale", "ball"), _row("viscous_damping", "ball")],
                      [_test("mass_scale[ball]", True)])
    assert ruled_out_members(no_none) == [] and len(no_none["ambiguous"]) == 2
    named = dict(verdict="named", ambiguous=[], size_tests=[_test("mass_scale[ball]", True)])
    assert ruled_out_members(named) == [] and named["verdict"] == "named"
