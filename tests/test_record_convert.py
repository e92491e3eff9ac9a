"""`adaptive-c3 record convert`: an LCM log of a (simulated) rig run -> a recording."""
import numpy as np
import pytest

from adaptive_c3.models.ball_rolling_controller_model import INPUT_NAMES, STATE_NAMES
from adaptive_c3.scenarios.schema import load_scenario
from adaptive_c3.tools import cli
from adaptive_c3.tools.hardware.record_convert import LcmLogWriter, read_lcm_log
from adaptive_c3.tools.recording import load_recording


@pytest.fixture(scope="module")
def rig_log(tmp_path_factory):
    from adaptive_c3.tools.hardware.bridge import run_loopback
    s, _ = load_scenario(cli.resolve_scenario_path("ball_rolling"),
                         ["camera.enabled=false", "model.radius_error=0"])
    path = tmp_path_factory.mktemp("rig") / "run.lcmlog"
    out = run_loopback(s, 1.0, log_path=path)
    return path, out


def test_convert_log_of_a_loopback_run(rig_log, tmp_path, capsys):
    log, out = rig_log
    npz = tmp_path / "rec.npz"
    assert cli.main(["record", "convert", str(log), str(npz), "--scenario", "ball_rolling",
                     "--dt", "0"]) == 0
    rec = load_recording(npz)
    assert rec.state_names == list(STATE_NAMES) and rec.input_names == list(INPUT_NAMES)
    assert rec.x.shape[1] == 19 and rec.u.shape[1] == 3
    assert len(rec.t) > 900 and rec.t[0] == 0 and np.all(np.diff(rec.t) > 0)
    assert "ball_rolling" in rec.scenario
    # the ball estimate and the EE from forward kinematics match the driver's truth
    drv = out["_"]["driver"]
    ctx = out["_"]["sim_driver"].get_context()
    ball_true = drv.logs["ball_true"].FindLog(ctx).data().T
    assert np.allclose(rec.x[-1, 7:9], ball_true[-1, 4:6], atol=2e-3)
    assert abs(rec.x[-1, 9] - ball_true[-1, 6]) < 2e-3
    # the EE starts at the gait's settle pose above/behind the ball: within 0.15 m of it
    assert np.linalg.norm(rec.x[0, 0:3] - rec.x[0, 7:10]) < 0.15
    # u: the EE force the commanded torques exert, finite, not all zero
    assert np.all(np.isfinite(rec.u)) and np.max(np.abs(rec.u)) > 0.1
    assert rec.extras["tau_cmd"].shape == (len(rec.t), 7)
    # default: resampled on a uniform 10 ms grid (the diagnose model's step)
    npz2 = tmp_path / "rec10.npz"
    assert cli.main(["record", "convert", str(log), str(npz2)]) == 0
    rec2 = load_recording(npz2)
    assert np.allclose(np.diff(rec2.t), 0.01) and 95 <= len(rec2.t) <= 101


def test_malformed_logs_are_refused(rig_log, tmp_path, capsys):
    log, _ = rig_log
    blob = log.read_bytes()
    cases = {
        "garbage.log": b"this is not an lcm log at all" * 10,
        "truncated.log": blob[: len(blob) // 2 + 7],
        "empty_status.log": None,
    }
    cases_written = {}
    for name, data in cases.items():
        p = tmp_path / name
        if data is None:           # a valid log with only the commands: no status
            with LcmLogWriter(p) as w:
                for ts, ch, d in read_lcm_log(log):
                    if ch == "PANDA_COMMAND":
                        w.write(ts, ch, d)
        else:
            p.write_bytes(data)
        cases_written[name] = p
    expect = {"garbage.log": "not an LCM log", "truncated.log": "truncated",
              "empty_status.log": "no PANDA_STATUS"}
    for name, p in cases_written.items():
        assert cli.main(["record", "convert", str(p), str(tmp_path / "o.npz")]) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and expect[name] in err, err
    # a message on the status channel that is not a panda status
    p = tmp_path / "wrongtype.log"
    with LcmLogWriter(p) as w:
        w.write(0, "PANDA_STATUS", b"\x00\x01\x02")
    assert cli.main(["record", "convert", str(p), str(tmp_path / "o.npz")]) == 2
    assert "cannot decode" in capsys.readouterr().err
    assert cli.main(["record", "convert", "/no/such.log", str(tmp_path / "o.npz")]) == 2
    assert cli.main(["record", "convert", str(log), str(tmp_path / "o.txt")]) == 2
