"""Issue 30: nuisances fitted one after another, an early one takes up what a later one
explains better; a second sweep fits each kept nuisance again with the others held
(engine/selection.py fit_nuisance)."""
import numpy as np

from adaptive_c3.tools.diagnosis.engine.selection import fit_nuisance
from tests.test_diagnose_joint_refit import EE_CAL, TABLE_CAL, PressProblem, _spec


class LevelProblem(PressProblem):
    """PressProblem with the ball's height seen at `ball_weight` noise sd per mm: the EE's
    height over the table moves with both calibrations, the ball's with the table's."""

    def __init__(self, spec, truth, ball_weight: float):
        super().__init__(spec, truth)
        self.ball_weight = ball_weight

    def residuals(self, effects, W):
        r = super().residuals(effects, W)
        b = sum(float(v[0]) for c, v in list(self.base) + list(effects) if c == TABLE_CAL)
        r[..., 1] = self.noise[W.row // 10, :, 1] + self.ball_weight * (b - self.truth[1])
        return r


def _kept(sweeps: int, truth=(0.9e-3, 0.0), ball_weight: float = 3e3):
    spec = _spec()
    spec.nuisance_sweeps = sweeps
    prob = LevelProblem(spec, truth, ball_weight)
    kept = {f.cands[0]: float(f.values[0]) for f in fit_nuisance(prob)}
    return prob, kept


def test_a_second_sweep_gives_back_what_the_table_took_from_the_ee():
    # one sweep: the table, fitted first, takes 16/25 of the EE's 0.9 mm
    _, once = _kept(1)
    assert abs(once[TABLE_CAL] - 0.576e-3) < 3e-5
    assert abs(once[EE_CAL] - 0.324e-3) < 3e-5
    # the second: the table with the EE held, then the EE with the table held
    prob, twice = _kept(2)
    assert abs(twice[TABLE_CAL] - 0.369e-3) < 3e-5
    assert abs(twice[EE_CAL] - 0.531e-3) < 3e-5
    assert sorted(c.target for c, _ in prob.base) == ["ball_table", "ee_ball"]
    # the model in prob.base holds the refitted values, each once
    assert {c: float(v[0]) for c, v in prob.base} == twice


def test_a_nuisance_the_second_sweep_puts_at_its_bound_is_left_to_the_candidates():
    # an EE-ball offset of 1.5 mm, the ball's height seen as sharply as the EE's: the
    # table takes half, the EE the rest (0.75 mm each, both within the 1 mm tolerance)
    _, once = _kept(1, truth=(1.5e-3, 0.0), ball_weight=4e3)
    assert abs(once[TABLE_CAL] - 0.75e-3) < 3e-5 and abs(once[EE_CAL] - 0.75e-3) < 3e-5
    # the second sweep: the table gives half back (0.375), the EE wants 1.125 mm, beyond
    # its tolerance: an effect, left to the candidates
    prob, kept = _kept(2, truth=(1.5e-3, 0.0), ball_weight=4e3)
    assert set(kept) == {TABLE_CAL} and abs(kept[TABLE_CAL] - 0.375e-3) < 3e-5
    assert [c for c, _ in prob.base] == [TABLE_CAL]


def test_a_single_nuisance_is_not_fitted_again():
    spec = _spec()
    spec.nuisance_sweeps = 2
    kept = fit_nuisance(LevelProblem(spec, (0.0, 0.4e-3), ball_weight=3e3))
    assert [f.cands[0] for f in kept] == [TABLE_CAL]
    assert abs(kept[0].values[0] - 0.4e-3) < 3e-5
    assert not hasattr(kept[0], "earlier_values")        # the first sweep's fit


def test_the_second_sweep_records_the_first_sweeps_values():
    spec = _spec()
    spec.nuisance_sweeps = 2
    kept = fit_nuisance(LevelProblem(spec, (0.9e-3, 0.0), ball_weight=3e3))
    first = {f.cands[0]: float(f.earlier_values[0]) for f in kept}
    assert abs(first[TABLE_CAL] - 0.576e-3) < 3e-5 and abs(first[EE_CAL] - 0.324e-3) < 3e-5


def test_the_second_sweep_leaves_the_users_own_effects_in_the_model():
    # a scenario that already sets an EE-ball calibration of its own (the user's base):
    # the sweep takes out only what the first sweep added
    spec = _spec()
    spec.nuisance_sweeps = 2
    prob = LevelProblem(spec, (0.9e-3, 0.0), ball_weight=3e3)
    own = (EE_CAL, np.array([0.1e-3]))
    prob.base = [own]
    kept = {f.cands[0]: float(f.values[0]) for f in fit_nuisance(prob)}
    assert any(e is own for e in prob.base)
    assert sorted(float(v[0]) for c, v in prob.base if c == EE_CAL) == \
        sorted([0.1e-3, kept[EE_CAL]])
