"""The `drake` model backend (issue 30): force elements, the fitted initial state, the
--model flag, and a concealed effect in Drake-made tosses found by the drake diagnosis."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from adaptive_c3.scenarios.rigid_object_schema import RigidObjectScenario
from adaptive_c3.scenarios.schema import SCENARIO_DIR, load_scenario
from adaptive_c3.tools import cli
from adaptive_c3.tools.diagnosis.harness.concealed_rigid_data import concealed_tosses
from adaptive_c3.tools.diagnosis.backends.drake_backend import DrakeRigidSimulator
from adaptive_c3.tools.diagnosis.tasks.rigid_object.drake_baseline import with_drake
from adaptive_c3.tools.diagnosis.tasks.rigid_object.initial_state import ballistic_start
from adaptive_c3.tools.diagnosis.tasks.rigid_object.rigid_diagnose import diagnose_rigid
from adaptive_c3.tools.recording import save_recording

CUBE = SCENARIO_DIR / "cube_toss.yaml"
DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "cube_tosses.npz"
DT = 1.0 / 148
MASS = 0.37


def _flight(**drake):
    sim = DrakeRigidSimulator(with_drake(RigidObjectScenario(), **drake), DT)
    x0 = np.zeros(13)
    x0[2], x0[3] = 1.0, 1.0
    x0[7:10] = [0.8, 0.0, 0.5]
    return sim, sim.rollout(x0, 30)


def test_force_elements_act_on_the_plant():
    """BodyForces (a LeafSystem into applied_spatial_force): viscous drag slows the
    horizontal velocity as -c v / m per SAP step, an upward force m g cancels gravity."""
    sim, X = _flight(viscous_drag=0.3)
    n = 30 * round(DT / sim.time_step)
    assert X[-1, 7] == pytest.approx(0.8 * (1 - 0.3 * sim.time_step / MASS) ** n, rel=1e-6)
    _, free = _flight()
    assert free[-1, 7] == pytest.approx(0.8, abs=1e-12)          # no drag by default
    sim, X = _flight(external_force=[0.0, 0.0, MASS * 9.81])
    assert np.allclose(X[:, 9], 0.5, atol=1e-9)
    # the start's velocity shift to SAP's convention assumes free fall (module docstring)
    shift = 9.81 * (DT - sim.time_step) / 2
    assert X[-1, 2] == pytest.approx(1.0 + (0.5 - shift) * 30 * DT, abs=1e-9)


def test_ballistic_start_beats_the_noisy_first_row():
    """Noisy camera positions of a free flight: the fitted start's velocity (backward-
    difference convention, v(t0 - dt/2)) and position are closer to the truth than the
    first row's (whose velocity is a backward difference of two noisy positions)."""
    rng = np.random.default_rng(0)
    errs_fit, errs_row, pos_fit, pos_row = [], [], [], []
    for _ in range(20):
        t = np.arange(40) * DT
        p0, v0 = np.array([0.0, 0.0, 0.3]), np.array([0.7, -0.3, -0.2])    # v0 = v(t0)
        p = p0 + np.outer(t, v0) - 0.5 * 9.81 * np.outer(t ** 2, [0, 0, 1])
        x = np.zeros((40, 13))
        x[:, 0:3] = p + rng.normal(0, 2e-4, p.shape)
        x[:, 3] = 1.0
        x[1:, 7:10] = np.diff(x[:, 0:3], axis=0) / DT
        x[0, 7:10] = x[1, 7:10]
        truth_v = v0 + [0, 0, 9.81 * DT / 2]
        est = ballistic_start(x, DT, [0.0524] * 3, 0.0)
        errs_fit.append(np.linalg.norm(est[7:10] - truth_v))
        errs_row.append(np.linalg.norm(x[0, 7:10] - truth_v))
        pos_fit.append(np.linalg.norm(est[0:3] - p0))
        pos_row.append(np.linalg.norm(x[0, 0:3] - p0))
    assert np.median(errs_fit) < 0.3 * np.median(errs_row)
    assert np.median(pos_fit) < 0.8 * np.median(pos_row)


@pytest.mark.parametrize("command", ["evaluate", "diagnose"])
def test_unknown_model_is_one_line_exit_2(tmp_path, capsys, command):
    scenario, _ = load_scenario(CUBE)
    rec = concealed_tosses(scenario, episodes=6, steps=10, seed=1)
    path = save_recording(tmp_path / "rec.npz", rec)
    assert cli.main([command, str(path), "--scenario", str(CUBE), "--model", "mujoco",
                     "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "unknown --model 'mujoco'" in err


def test_drake_diagnosis_finds_concealed_friction_and_its_patch_runs(tmp_path, capsys):
    """Tosses made by the drake backend with mu 0.3 where the scenario says 0.18: the drake
    diagnosis names friction first with 0.3 in its 95 % interval, the report says the
    model and the LCS patch, and the patched scenario runs as-is with evaluate."""
    scenario, _ = load_scenario(CUBE)
    rec = concealed_tosses(scenario, episodes=24, steps=40, seed=5, friction=0.3)
    path = save_recording(tmp_path / "tosses.npz", rec)
    out = tmp_path / "diag"
    assert cli.main(["diagnose", str(path), "--scenario", str(CUBE), "--model", "drake",
                     "--out", str(out), "--fit-episodes", "10", "--workers", "2",
                     "--effects", "friction,table_offset"]) == 0
    printed = capsys.readouterr().out
    assert "Model diagnosed: drake" in printed and "LCS patch contact.friction" in printed
    report = json.loads((out / "report.json").read_text())
    assert report["model"] == "drake" and report["initial_state"] == "ballistic"
    first = report["selected"][0]
    assert first["name"] == "friction" and first["kind"] == "physics"
    lo, hi = first["ci95"]
    assert lo <= 0.3 <= hi
    held = report["held_out"]
    assert held["diagnosed"]["position_pct_mean_median"] < held["nominal"]["position_pct_mean_median"]
    assert cli.main(["evaluate", str(path), "--scenario", str(out / "patched_scenario.yaml"),
                     "--model", "drake", "--baseline", "lcs", "--out", str(tmp_path / "ev")]) == 0
    printed = capsys.readouterr().out
    assert "model drake, start ballistic" in printed
    ev = json.loads((tmp_path / "ev" / "evaluate.json").read_text())
    assert set(ev["summary"]) == {"model", "lcs"}
    assert ev["summary"]["model"]["position_pct_mean_median"] < 2.0   # the truth, up to noise


def test_patched_external_force_key_runs(tmp_path):
    """Indexed keys (drake.external_force[2], patch.com_offset[2]) land in the patched YAML
    as full lists, starting from the schema's default where the file has none."""
    from adaptive_c3.tools.diagnosis.tasks.rigid_object.rigid_report import patched_scenario_text
    assert "com_offset" not in CUBE.read_text()
    text = patched_scenario_text(CUBE.read_text(), {"drake.external_force[2]": 0.1,
                                                    "drake.viscous_drag": 0.05,
                                                    "patch.com_offset[2]": 0.0077})
    (tmp_path / "p.yaml").write_text(text)
    patched, _ = load_scenario(tmp_path / "p.yaml")
    assert patched.drake.external_force == [0.0, 0.0, 0.1]
    assert patched.drake.viscous_drag == 0.05
    assert patched.patch.com_offset == [0.0, 0.0, 0.0077]


@pytest.fixture(scope="module")
def real_comparison():
    """rigid_compare on the real tosses (both diagnoses; ~34 min on 2 loaded cores)."""
    if not DATA.is_file():
        pytest.skip("../shared/data/cube_tosses.npz not present")
    from adaptive_c3.tools.diagnosis.tasks.rigid_object.rigid_compare import compare
    from adaptive_c3.tools.recording import load_recording
    scenario, _ = load_scenario(CUBE)
    return compare(load_recording(DATA), scenario, progress=False)


@pytest.mark.slow
def test_real_tosses_diagnosed_lcs_beats_nominal(real_comparison):
    """Fitted on training tosses (twins kept on one side), on the held-out 30 % from the
    same fitted starts: diagnosed LCS beats nominal LCS by more than the bootstrap interval
    of the paired per-toss difference (and of the difference of the medians)."""
    c = real_comparison["comparisons"]["ballistic"]["lcs_nominal_to_diagnosed"]
    assert c["paired_difference"]["below"]
    assert c["median_difference"]["ci95"][0] > 0


@pytest.mark.slow
def test_real_tosses_diagnosed_drake_beats_drake_default(real_comparison):
    """The drake diagnosis (paired fit objective) keeps a centre of mass 7.7 mm off along
    body z with friction re-fitted to 0.175; on the 117 held-out tosses from the fitted
    starts it beats Drake's default by more than the interval of the paired per-toss
    difference (measured once, 255db66: 10.01 % -> 8.10 %, median difference -0.64
    [-2.20, -0.12] % of size; the target of 8 % is missed by 0.1)."""
    c = real_comparison["comparisons"]["ballistic"]["drake_default_to_diagnosed"]
    assert c["paired_difference"]["below"]


def test_hydroelastic_box_rests_on_its_face():
    """contact_model hydroelastic: a compliant box (no corner spheres) on the rigid table."""
    sim = DrakeRigidSimulator(with_drake(RigidObjectScenario(), contact_model="hydroelastic"), DT)
    assert sim.plant.num_collision_geometries() == 2          # the table and the box
    x0 = np.zeros(13)
    x0[2], x0[3] = 0.0524 + 0.02, 1.0
    X = sim.rollout(x0, 120)
    assert X[-1, 2] == pytest.approx(0.0524, abs=1e-3)
    assert np.linalg.norm(X[-1, 7:10]) < 0.05


def test_compare_of_one_backend_rolls_out_only_its_models():
    """rigid_compare with models=("drake",): the drake diagnosis and its default/diagnosed
    held-out comparison only (the LCS half costs ~30x as much)."""
    from adaptive_c3.tools.diagnosis.tasks.rigid_object.rigid_compare import compare
    scenario, _ = load_scenario(CUBE)
    rec = concealed_tosses(scenario, episodes=12, steps=20, seed=1)
    out = compare(rec, scenario, workers=1, drake_effects=("friction",), progress=False,
                  models=("drake",))
    assert list(out["diagnoses"]) == ["drake"]
    for method in ("first-row", "ballistic"):
        assert sorted(out["held_out"][method]) == ["drake_default", "drake_diagnosed"]
        assert list(out["comparisons"][method]) == ["drake_default_to_diagnosed"]


def test_run_of_a_rigid_object_scenario_is_one_line(tmp_path, capsys):
    """`run` has no controller for a rigid_object scenario (a patched one included): one
    line naming evaluate, exit 2, no results folder (it was a KeyError traceback)."""
    assert cli.main(["run", str(CUBE), "--out", str(tmp_path / "r")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "adaptive-c3 evaluate" in err
    assert not (tmp_path / "r").exists()


@pytest.mark.parametrize("flags, fitted", [([], 30), (["--model", "drake"], 60),
                                           (["--model", "drake", "--fit-episodes", "7"], 7)])
def test_diagnose_fits_on_60_tosses_by_default_with_drake(tmp_path, monkeypatch, flags, fitted):
    """--fit-episodes defaults to 60 with --model drake (its rollouts are ~30x cheaper than
    the LCS's; the real-toss comparison fits on 60), 30 with the LCS."""
    import adaptive_c3.tools.diagnosis.tasks.rigid_object.rigid_diagnose as rd
    import adaptive_c3.tools.diagnosis.tasks.rigid_object.rigid_report as rr
    seen = {}
    monkeypatch.setattr(rd, "diagnose_rigid", lambda *a, **k: seen.update(k) or {"rollouts": {}})
    monkeypatch.setattr(rr, "write_report", lambda *a, **k: {"summary": "ok"})
    scenario, _ = load_scenario(CUBE)
    path = save_recording(tmp_path / "t.npz", concealed_tosses(scenario, episodes=6, steps=5,
                                                               seed=1))
    assert cli.main(["diagnose", str(path), "--scenario", str(CUBE), "--out",
                     str(tmp_path / "d"), *flags]) == 0
    assert seen["max_fit_episodes"] == fitted
