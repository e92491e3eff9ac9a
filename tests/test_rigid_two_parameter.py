"""Two-parameter effects of the rigid diagnosis (issue 30): contact stiffness or SAP
relaxation time fitted together with friction (a profile over friction), and a concealed
torsional friction in Drake-made tosses found by the drake diagnosis."""
from __future__ import annotations

import numpy as np
import pytest

from adaptive_c3.scenarios.schema import SCENARIO_DIR, load_scenario
from adaptive_c3.tools.diagnosis.harness.concealed_rigid_data import concealed_tosses
from adaptive_c3.tools.diagnosis.tasks.rigid_object.rigid_diagnose import (
    REFIT_FACTORS, diagnose_rigid, profile_scores)
from adaptive_c3.tools.diagnosis.tasks.rigid_object.rigid_effects import (DRAKE_EFFECTS,
                                                                      RigidEffect)
from adaptive_c3.tools.diagnosis.tasks.rigid_object.rigid_report import (lcs_meaning,
                                                                     plain_summary)

CUBE = SCENARIO_DIR / "cube_toss.yaml"
MU_TRUE, K_TRUE = 0.18 * 0.97, 5e3


def _score(scenarios):
    """A stand-in for the rollout scores [scenarios, 3 episodes]: zero only at the true
    (stiffness, friction) pair, each away from it costs (a valley along neither axis)."""
    out = []
    for s in scenarios:
        k, mu = s.drake.point_stiffness, s.drake.friction
        e = abs(np.log(k / K_TRUE)) + 40 * abs(mu - MU_TRUE) + 0.3 * abs(mu - MU_TRUE) * k / 1e3
        out.append([e, e + 0.1, e + 0.2])
    return np.array(out)


def test_profile_over_friction_finds_the_pair_a_single_key_misses():
    scenario, _ = load_scenario(CUBE)
    stiffness = next(e for e in DRAKE_EFFECTS if e.name == "point_stiffness")
    assert stiffness.refit == "drake.friction" and 0.97 in REFIT_FACTORS
    grid = [2e3, 5e3, 1e4]
    S, refitted = profile_scores(_score, scenario, stiffness, grid)
    assert S.shape == (3, 3)
    assert int(np.argmin(S[:, 0])) == 1 and S[1, 0] == pytest.approx(0.0, abs=1e-9)
    assert refitted[1] == {"drake.friction": pytest.approx(MU_TRUE)}
    single = RigidEffect("k", "drake.point_stiffness", tuple(grid), "N/m", "stiffness alone")
    S1, none = profile_scores(_score, scenario, single, grid)
    assert none == [{}, {}, {}] and S1[:, 0].min() > 0.1         # friction stays wrong


def test_report_names_the_refitted_friction_and_its_lcs_patch():
    s = dict(name="point_stiffness", value=5e3, unit="N/m", ci95=[4e3, 8e3], physics="soft",
             kind="nuisance", lcs="no LCS counterpart: rigid",
             refitted={"drake.friction": 0.1746},
             validation_gain=dict(relative=0.1, relative_ci95=[0.06, 0.2], ci95=[0.5, 2.0],
                                  drop=1.0))
    lines = lcs_meaning([s])
    assert any("LCS patch contact.friction = 0.1746" in line for line in lines)
    held = {k: {"summary": {"position_pct_mean_median": v, "episodes": 10}}
            for k, v in (("nominal", 10.0), ("diagnosed", 9.0))}
    text = plain_summary(dict(held_out=held, model="drake", selected=[s], rounds=[],
                              initial_state="ballistic"))
    assert "with drake.friction re-fitted to 0.1746" in text


@pytest.mark.slow
def test_drake_diagnosis_finds_a_concealed_torsional_friction():
    """Tosses made by the drake backend with torsional friction 0.01 m (the scenario has
    none): the drake diagnosis names torsional_friction before friction, with the truth in
    its 95 % interval, and the patched model predicts held-out tosses better (~45 s)."""
    scenario, _ = load_scenario(CUBE)
    rec = concealed_tosses(scenario, episodes=20, steps=50, seed=5, torsional_friction=0.01)
    r = diagnose_rigid(rec, scenario, max_fit_episodes=8, workers=1, model="drake",
                       effects=("torsional_friction", "friction"), progress=False)
    first = r["selected"][0]
    assert first["name"] == "torsional_friction"
    assert first["ci95"][0] <= 0.01 <= first["ci95"][1]
    held = r["held_out"]
    assert (held["diagnosed"]["summary"]["position_pct_mean_median"]
            < held["nominal"]["summary"]["position_pct_mean_median"])


class _FakeScorer:
    """Scores without rollouts: table_offset 2 mm lowers the fit episodes' error by 2 but
    raises the validation episodes' by 1 (an over-fit), friction 0.25 lowers both by 1."""
    made = []

    def __init__(self, episodes, dt, size, workers=1, model="drake", starts=None):
        self.n, self.role = len(episodes), ("fit", "validation", "held")[min(len(self.made), 2)]
        self.made.append(self)

    def _one(self, s):
        bump = lambda v, at, w: float(np.exp(-((v - at) / w) ** 2))   # noqa: E731
        offset = bump(s.patch.table_offset, 2e-3, 1e-3)
        friction = bump(s.drake.friction if s.drake.friction >= 0 else 0.18, 0.25, 0.03)
        e = 10.0 - friction - (2.0 * offset if self.role == "fit" else -1.0 * offset)
        return e + 0.01 * np.arange(self.n)

    def __call__(self, scenarios, progress=None):
        return np.array([self._one(s) for s in scenarios])

    def run(self, scenarios, progress=None, keep=False):
        return self(scenarios), None

    def close(self):
        pass


def test_a_candidate_that_fails_validation_lets_the_next_best_be_checked(monkeypatch):
    """The best fit candidate (table_offset) makes the validation episodes worse and is
    rejected; the next (friction) pays on them and is kept."""
    import adaptive_c3.tools.diagnosis.tasks.rigid_object.rigid_diagnose as rd
    scenario, _ = load_scenario(CUBE)
    rec = concealed_tosses(scenario, episodes=12, steps=12, seed=1)
    _FakeScorer.made.clear()
    monkeypatch.setattr(rd, "Scorer", _FakeScorer)
    monkeypatch.setattr(rd, "held_out_runs", lambda runs, ids, *a, **k: (
        {tag: {"summary": {}, "per_episode": [{"position_pct_mean": 1.0}] * len(ids)}
         for tag, _, _ in runs}, {}))
    r = rd.diagnose_rigid(rec, scenario, max_fit_episodes=6, workers=1, model="drake",
                          effects=("table_offset", "friction"), progress=False)
    first = r["rounds"][0]
    assert [t["name"] for t in first["tries"]] == ["table_offset", "friction"]
    assert [t["accepted"] for t in first["tries"]] == [False, True]
    assert [s["name"] for s in r["selected"]] == ["friction"]
    assert r["chosen"]["drake.friction"] == pytest.approx(0.25, abs=0.01)


def test_paired_objective_judges_the_change_per_episode():
    """The drake backend's fit objective is paired with the current model's errors: its
    value at the current model is the unpaired one, a change of d on every episode moves
    it by exactly d whatever the spread between episodes (trimming acts on the per-episode
    changes, not on the errors), and the minimiser's bootstrap resamples the reference with
    the episodes."""
    from scipy.stats import trim_mean

    from adaptive_c3.tools.diagnosis.tasks.rigid_object.rigid_diagnose import (
        PAIRED_FIT, TRIM, bootstrap_interval, objective)
    assert "drake" in PAIRED_FIT and "lcs" not in PAIRED_FIT
    rng = np.random.default_rng(0)
    ref = rng.lognormal(2.0, 0.8, size=50)                 # % of size, a wide spread
    assert objective(ref, ref) == pytest.approx(trim_mean(ref, TRIM))
    S = np.vstack([ref - 0.7, ref + 0.2])
    assert objective(S, ref) == pytest.approx(trim_mean(ref, TRIM) + np.array([-0.7, 0.2]))
    grid = np.linspace(-1, 1, 9)
    S = ref[None, :] + (grid[:, None] - 0.3) ** 2
    lo, hi = bootstrap_interval(grid, S, rng, ref=ref)     # every episode changes alike:
    assert (lo, hi) == pytest.approx((0.3, 0.3), abs=1e-9)  # no uncertainty from the spread
