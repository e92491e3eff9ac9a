"""The CLI contract: results files for a run, one-line errors with exit code 2."""
import json
import subprocess
import sys

import numpy as np
import pytest

from adaptive_c3.scenarios.schema import SCENARIO_DIR, ScenarioError, load_scenario
from adaptive_c3.tools.cli import main
from adaptive_c3.tools.recording import load_recording

CARTPOLE = str(SCENARIO_DIR / "cartpole_softwalls.yaml")


def test_run_lqr_writes_summary_log_and_plot(tmp_path):
    out = tmp_path / "run"
    rc = main(["run", CARTPOLE, "--out", str(out), "--set", "controller=lqr",
               "--set", "sim_duration_s=2.0"])
    assert rc == 0
    summary = json.loads((out / "summary.json").read_text())
    for key in ("scenario", "sim_duration_s", "wall_s", "real_time_factor", "final_state",
                "state_names", "stabilised"):
        assert key in summary
    assert summary["state_names"] == ["cart_x", "pole_theta", "cart_xdot", "pole_thetadot"]
    rec = load_recording(out / "log.npz")
    assert rec.x.shape == (len(rec.t), 4) and rec.u.shape == (len(rec.t), 1)
    assert rec.input_names == ["cart_force"]
    assert "task: cartpole" in rec.scenario
    np.testing.assert_allclose(rec.x[-1], summary["final_state"])
    assert (out / "states.png").stat().st_size > 10_000


@pytest.mark.parametrize("args,needle", [
    (["--set", "bogus=1"], "unknown key 'bogus'"),
    (["--set", "c3.admm_iter=ten"], "c3.admm_iter: expected an integer"),
    (["--set", "learner.learning_rate=.nan"], "learner.learning_rate: NaN"),
    (["--set", "learner.epsilon=0"], "learner.epsilon must be > 0"),
    (["--set", "model.wall_stiffness=-5"], "model.wall_stiffness must be > 0"),
    (["--set", "c3.projection=gurobi"], "c3.projection must be"),
    (["--set", "novalue"], "--set expects key.path=value"),
])
def test_bad_scenario_exits_2_with_one_line(args, needle, capsys, tmp_path):
    rc = main(["run", CARTPOLE, "--out", str(tmp_path), *args])
    err = capsys.readouterr().err.strip()
    assert rc == 2
    assert len(err.splitlines()) == 1 and needle in err, err


def test_missing_and_malformed_files(tmp_path, capsys):
    assert main(["run", str(tmp_path / "nope.yaml")]) == 2
    assert "not found" in capsys.readouterr().err
    bad = tmp_path / "bad.yaml"
    bad.write_text("task: cartpole\nc3: [unclosed\n")
    assert main(["run", str(bad)]) == 2
    assert "not valid YAML" in capsys.readouterr().err
    wrong_type = tmp_path / "wt.yaml"
    wrong_type.write_text("task: cartpole\nsim_duration_s: soon\n")
    assert main(["run", str(wrong_type)]) == 2
    assert "sim_duration_s: expected a number" in capsys.readouterr().err


def test_include_and_override(tmp_path):
    base = tmp_path / "base.yaml"
    base.write_text("task: cartpole\nname: base\nc3: {admm_iter: 7, horizon: 8}\n")
    child = tmp_path / "child.yaml"
    child.write_text("include: base.yaml\nname: child\nc3: {horizon: 6}\n")
    s, text = load_scenario(child, ["c3.rho_scale=3"])
    assert (s.name, s.c3.admm_iter, s.c3.horizon, s.c3.rho_scale) == ("child", 7, 6, 3.0)
    loop = tmp_path / "loop.yaml"
    loop.write_text("include: loop.yaml\n")
    with pytest.raises(ScenarioError, match="include cycle"):
        load_scenario(loop)


def test_console_script_help_lists_scenarios():
    out = subprocess.run([sys.executable, "-m", "adaptive_c3.tools.cli", "run", "--help"],
                         capture_output=True, text=True, check=True).stdout
    assert "cartpole_softwalls.yaml" in out


def test_bad_flag_is_exit_2():
    with pytest.raises(SystemExit) as e:
        main(["run"])
    assert e.value.code == 2
