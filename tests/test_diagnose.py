"""`adaptive-c3 diagnose`: effect library, locating, fitting, report files, refusals."""
import json

import numpy as np
import pytest

from adaptive_c3.models.cartpole import cartpole_lcs
from adaptive_c3.scenarios.schema import SCENARIO_DIR, load_scenario
from adaptive_c3.tools.cli import main
from adaptive_c3.tools.diagnosis.harness.concealed_data import NOISE_STD, concealed_draw, make_recording, Truth
from adaptive_c3.tools.diagnosis.backends.effects import (EFFECT_NAMES, Candidate, applicable_candidates,
                                                cartpole_spec, patch, rollout)
from adaptive_c3.tools.diagnosis.engine.locate import LAG, estimate_noise, make_windows
from adaptive_c3.tools.recording import Recording, save_recording

CARTPOLE = str(SCENARIO_DIR / "cartpole_softwalls.yaml")


@pytest.fixture(scope="module")
def spec():
    return cartpole_spec(load_scenario(CARTPOLE)[0])


def _save(tmp_path, name, rec):
    path = tmp_path / name
    save_recording(path, rec)
    return str(path)


def test_library_has_the_issue_names_and_says_what_does_not_apply(spec):
    for name in ("contact_offset", "contact_stiffness", "contact_damping", "friction_coefficient",
                 "rolling_resistance", "viscous_damping", "coulomb_friction", "mass_scale",
                 "actuator_gain", "actuator_delay", "external_force", "r_comp"):
        assert name in EFFECT_NAMES
    cands, skipped = applicable_candidates(spec)
    labels = {c.label() for c in cands}
    assert {"contact_offset[right_wall]", "viscous_damping[pole_theta]", "mass_scale[cart]",
            "actuator_delay", "r_comp[all_pairs]"} <= labels
    assert set(skipped) == {"friction_coefficient", "rolling_resistance", "contact_dissipation",
                            "torsional_friction"}


def test_unpatched_batch_rollout_is_the_lcs(spec):
    rng = np.random.default_rng(0)
    X0 = rng.normal(0, 0.3, (6, 4))
    U = rng.normal(0, 5, (6, LAG + 8, 1))
    X, _ = rollout(patch(spec, []), X0, U, 8, LAG)
    lcs = cartpole_lcs()
    for w in range(6):
        np.testing.assert_allclose(lcs.rollout(X0[w], U[w, LAG:])[0][1:], X[w], atol=1e-12)


def test_effects_change_the_step_as_physics_says(spec):
    x = np.array([[0.0, 0.0, 1.0, 0.0]])
    U = np.zeros((1, LAG + 1, 1))
    base = rollout(patch(spec, []), x, U, 1, LAG)[0][0, 0]
    damped = rollout(patch(spec, [(Candidate("viscous_damping", "cart_x"), [2.0])]), x, U, 1, LAG)[0][0, 0]
    # -b v dt / m on the cart velocity (and the coupled pole row through Minv)
    np.testing.assert_allclose(damped[2] - base[2], -2.0 * 1.0 * 0.01 / 0.978, rtol=1e-9)
    assert damped[3] < base[3]
    # contact offset shifts where the wall force starts
    tip_in = np.array([[0.36, 0.0, 0.0, 0.0]])
    lam0 = rollout(patch(spec, []), tip_in, U, 1, LAG)[1][0, 0]
    lam1 = rollout(patch(spec, [(Candidate("contact_offset", "right_wall"), [0.02])]), tip_in, U, 1, LAG)[1][0, 0]
    assert lam0[0] > 0 and lam1[0] == 0


def test_noise_floor_is_estimated_from_the_data(spec):
    rec, _ = make_recording(Truth("none", "", 0.0, ""), seed=3, episodes=3, noise_scale=1.0)
    sigma = estimate_noise(patch(spec, []), make_windows(rec, 1))
    np.testing.assert_allclose(sigma, NOISE_STD, rtol=0.25)


@pytest.mark.parametrize("seed,name,target", [(11, "coulomb_friction", "cart_x"),
                                              (12, "contact_offset", "left_wall")])
def test_cli_names_fits_and_patches_a_concealed_effect(tmp_path, seed, name, target, capsys):
    rec, truth, _ = concealed_draw(seed, name=name, target=target)
    path = _save(tmp_path, "rec.npz", rec)
    out = tmp_path / "diag"
    assert main(["diagnose", path, "--scenario", CARTPOLE, "--out", str(out)]) == 0
    report = json.loads((out / "report.json").read_text())
    for key in ("mismatch_windows", "candidates", "selected", "error_before", "error_after"):
        assert key in report
    sel = report["selected"]
    assert [(s["name"], s["target"]) for s in sel] == [(name, target)]
    lo, hi = sel[0]["params"][0]["ci95"]
    assert lo <= truth.value <= hi
    assert report["error_after"]["rollout"]["normalised_rms"] < \
        report["error_before"]["rollout"]["normalised_rms"]
    assert report["error_after"]["inside_mismatch_windows"]["rollout"] is not None
    cand = report["candidates"][0]
    assert {"name", "target", "held_out_error", "penalty_score"} <= set(cand)
    assert all("ci95" in p and "unit" in p for e in cand["effects"] for p in e["params"])
    html = (out / "report.html").read_text()
    assert html.count("data:image/png;base64,") >= 3 and "leaves out" in html
    assert (out / "rollouts.png").stat().st_size > 10_000
    patched = (out / "patched_scenario.yaml").read_text()
    if name == "contact_offset":
        assert report["mismatch_windows"] and any(
            target in w["contact_pairs"] for w in report["mismatch_windows"])
        assert "wall_offset_error" in patched and "effects:" not in patched
    else:
        assert "effects:" in patched and name in patched
    # the patched scenario explains the recording: diagnosing again finds nothing
    out2 = tmp_path / "again"
    assert main(["diagnose", path, "--scenario", str(out / "patched_scenario.yaml"),
                 "--out", str(out2)]) == 0
    assert json.loads((out2 / "report.json").read_text())["selected"] == [{"name": "none"}]
    assert "selected:" in capsys.readouterr().out


def test_clean_data_gives_none(tmp_path):
    rec, truth, _ = concealed_draw(5, name="none")
    out = tmp_path / "d"
    assert main(["diagnose", _save(tmp_path, "r.npz", rec), "--scenario", CARTPOLE,
                 "--out", str(out)]) == 0
    report = json.loads((out / "report.json").read_text())
    assert report["selected"] == [{"name": "none"}]
    assert "No effect" in report["summary"]


def test_a_run_log_diagnoses_its_wall_offset(tmp_path):
    """A `run` recording (one episode) of a plant whose walls differ from the model."""
    run = tmp_path / "run"
    assert main(["run", CARTPOLE, "--out", str(run), "--set", "controller=lqr",
                 "--set", "sim_duration_s=6", "--set", "initial_state=[0.3,-0.5,1.5,0]",
                 "--set", "measurement_noise=[0.0005,0.001,0.01,0.02]",
                 "--set", "disturbances=[{at_s: 2.0, delta_state: [0,0,-2.0,0]},"
                 "{at_s: 4.0, delta_state: [0,0,1.5,0]}]"]) == 0
    model = tmp_path / "model.yaml"
    model.write_text(f"include: {CARTPOLE}\nmodel:\n  wall_offset_error: [0.05, 0.0]\n")
    out = tmp_path / "d"
    assert main(["diagnose", str(run / "log.npz"), "--scenario", str(model),
                 "--out", str(out)]) == 0
    report = json.loads((out / "report.json").read_text())
    assert "time blocks" in report["split"]
    sel = report["selected"][0]
    assert sel["name"] == "contact_offset" and sel["target"] == "right_wall"
    lo, hi = sel["params"][0]["ci95"]
    assert lo <= 0.05 <= hi


def test_sindy_baseline_names_an_obvious_effect(spec):
    from adaptive_c3.tools.diagnosis.harness.sindy_baseline import sindy_diagnose
    rec, truth, _ = concealed_draw(1, name="external_force", target="cart_x")
    sel = sindy_diagnose(rec, spec)["selected"][0]
    assert (sel["name"], sel["target"]) == ("external_force", "cart_x")


def test_scored_draw_reports_named_interval_and_cut():
    from adaptive_c3.tools.diagnosis.harness.concealed_data import score_draw
    row = score_draw(21, name="viscous_damping", target="cart_x")
    assert row["named"] and row["in_interval"] and row["clean_cut"] >= 5


# ------------------------------------------------------------------ refusals
def _good(n=60):
    t = np.arange(n) * 0.01
    return dict(t=t, x=np.zeros((n, 4)), u=np.zeros((n, 1)),
                state_names=["cart_x", "pole_theta", "cart_xdot", "pole_thetadot"],
                input_names=["cart_force"])


@pytest.mark.parametrize("change,needle", [
    (dict(x="nan"), "non-finite"),
    (dict(x=np.zeros((60, 3))), "state_names has 4 names, x has 3 columns"),
    (dict(u=np.zeros((59, 1))), "u must have shape"),
    (dict(state_names=["a", "b", "c", "d"]), "do not match the scenario"),
    (dict(input_names=["force"]), "input names"),
    (dict(t=np.arange(60) * 0.02), "sampled every 0.02"),
    (dict(t=np.arange(10) * 0.01, x=np.zeros((10, 4)), u=np.zeros((10, 1))), "too short"),
])
def test_malformed_recordings_exit_2_with_one_line(tmp_path, capsys, change, needle):
    arrays = _good()
    for k, v in change.items():
        if isinstance(v, str) and v == "nan":
            v = arrays[k].copy()
            v[5, 1] = np.nan
        arrays[k] = v
    path = tmp_path / "bad.npz"
    np.savez(path, **{k: np.asarray(v) for k, v in arrays.items()})
    rc = main(["diagnose", str(path), "--scenario", CARTPOLE, "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err.strip()
    assert rc == 2
    assert len(err.splitlines()) == 1 and needle in err, err


def test_missing_files_exit_2(tmp_path, capsys):
    assert main(["diagnose", str(tmp_path / "none.npz"), "--scenario", CARTPOLE]) == 2
    assert "not found" in capsys.readouterr().err
    rec = Recording(**{k: v for k, v in _good().items()})
    path = _save(tmp_path, "ok.npz", rec)
    assert main(["diagnose", path, "--scenario", str(tmp_path / "nope.yaml")]) == 2
    bad = tmp_path / "bad_effects.yaml"
    bad.write_text(f"include: {CARTPOLE}\neffects:\n  - name: warp_drive\n    value: 1\n")
    assert main(["diagnose", path, "--scenario", str(bad)]) == 2
    assert "effects[0] needs a name" in capsys.readouterr().err
