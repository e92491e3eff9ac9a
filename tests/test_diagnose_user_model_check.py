"""Issue 30: an answer whose own held-out rollouts are clearly worse than the user's model
is not confident; `none` joins its set (engine/user_model_check.py)."""
import numpy as np

from adaptive_c3.tools.diagnosis.engine.report import ambiguity_summary
from adaptive_c3.tools.diagnosis.engine.user_model_check import per_episode_ssr, worse_than_user

DRAG = dict(name="viscous_damping", target="ball", held_out_score=1.0, ssr_reduction=0.2,
            z_vs_none=5.0)
NONE = dict(name="none", target="", held_out_score=1.2, ssr_reduction=0.0, z_vs_none=0.0)


def _named():
    return dict(verdict="named", ambiguous=[], separating_excitation=[])


def test_per_episode_ssr_sums_the_scored_states_in_noise_units():
    err = np.ones((3, 2, 2))                     # 3 windows, 2 steps, 2 states
    err[:, :, 1] = 100.0                         # an unscored state
    floor = np.full((2, 2), 0.5)
    out = per_episode_ssr(err, np.array([4, 4, 7]), floor, np.array([True, False]))
    assert out == {4: 16.0, 7: 8.0}              # (1 / 0.5)^2 x 2 steps per window


def test_an_answer_clearly_worse_than_the_users_model_keeps_none_beside_it():
    """Fifteen episodes, each about three times worse with the answer: `none` joins."""
    rng = np.random.default_rng(0)
    before = {e: float(v) for e, v in enumerate(rng.uniform(10, 20, 15))}
    after = {e: 3.0 * v + rng.normal(0, 1) for e, v in before.items()}
    judged = _named()
    rec = worse_than_user(judged, object(), before, after, NONE, DRAG)
    assert rec["joined"] and rec["z"] >= 2.0 and rec["episodes"] == 15
    assert judged["verdict"] == "ambiguous"
    assert [a["name"] for a in judged["ambiguous"]] == ["viscous_damping", "none"]
    assert judged["separating_excitation"][0]["between"] == ["viscous_damping", "none"]
    report = dict(judged, against_user_model=rec)
    assert "so `none` is kept beside it" in ambiguity_summary(report)


def test_an_answer_that_helps_or_is_no_clearer_worse_stays_named():
    """Better on every episode, or worse on some and better on as many: unchanged."""
    rng = np.random.default_rng(1)
    before = {e: float(v) for e, v in enumerate(rng.uniform(10, 20, 15))}
    for after in ({e: 0.7 * v for e, v in before.items()},
                  {e: v + (2.0 if e % 2 else -2.0) for e, v in before.items()}):
        judged = _named()
        rec = worse_than_user(judged, object(), before, after, NONE, DRAG)
        assert not rec["joined"] and rec["z"] < 2.0
        assert judged["verdict"] == "named" and judged["ambiguous"] == []


def test_nothing_chosen_or_too_few_episodes_is_not_judged():
    judged = _named()
    assert worse_than_user(judged, None, {0: 1.0, 1: 1.0, 2: 1.0}, {0: 9.0, 1: 9.0, 2: 9.0},
                           NONE, DRAG) is None
    assert worse_than_user(judged, object(), {0: 1.0, 1: 1.0}, {0: 9.0, 1: 9.0},
                           NONE, DRAG) is None
    assert "against_user_model" not in judged and judged["verdict"] == "named"
