"""What a new user trips on first: scenario files without a task, how a run ends
(Meshcat's Stop, Ctrl-C), the messages and labels the tools print."""
import json

import numpy as np
import pytest

from adaptive_c3.scenarios.schema import SCENARIO_DIR
from adaptive_c3.tools.cli import main

CARTPOLE = str(SCENARIO_DIR / "cartpole_softwalls.yaml")


@pytest.mark.parametrize("text,needle", [
    ("", "empty"),
    ("# only a comment\n", "empty"),
    ("name: mine\nsim_duration_s: 1.0\n", "no 'task:'"),
])
def test_scenario_without_a_task_is_exit_2_with_one_line(text, needle, tmp_path, capsys):
    path = tmp_path / "s.yaml"
    path.write_text(text)
    assert main(["run", str(path), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and needle in err, err
    assert not (tmp_path / "out" / "summary.json").exists()


def test_task_may_come_from_an_included_file(tmp_path):
    from adaptive_c3.scenarios.schema import load_scenario
    child = tmp_path / "child.yaml"
    child.write_text(f"include: {CARTPOLE}\nname: child\n")
    assert load_scenario(child)[0].task == "cartpole"


# ------------------------------------------------------------------ how a run ends
def _start(args, tmp_path):
    """The CLI in its own process group, as a terminal runs it (Ctrl-C reaches every
    process of the group), with progress bars on stderr."""
    import os
    import signal
    import subprocess
    import sys
    env = dict(os.environ, ADAPTIVE_C3_PROGRESS="1")
    return subprocess.Popen([sys.executable, "-m", "adaptive_c3.tools.cli", *args], cwd=tmp_path,
                            env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            start_new_session=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))


def _ctrl_c(proc):
    import os
    import signal
    os.killpg(proc.pid, signal.SIGINT)
    out, err = proc.communicate(timeout=120)
    return proc.returncode, out.decode(), err.decode()


def test_ctrl_c_on_run_writes_the_partial_log_and_summary(tmp_path):
    import os
    out = tmp_path / "run"
    proc = _start(["run", CARTPOLE, "--out", str(out), "--set", "sim_duration_s=500"], tmp_path)
    seen = b""
    while b"cartpole [" not in seen:   # the simulation is under way
        chunk = os.read(proc.stderr.fileno(), 4096)
        assert chunk, "the run ended before it was interrupted"
        seen += chunk
    rc, _, err = _ctrl_c(proc)
    assert rc == 130, err
    assert "interrupted at t =" in err and "Traceback" not in err, err
    summary = json.loads((out / "summary.json").read_text())
    assert summary["interrupted"] and summary["ended"] == "interrupted"
    assert summary["sim_duration_requested_s"] == 500
    assert 0 < summary["sim_duration_s"] < 500
    assert summary["real_time_factor"] == pytest.approx(summary["sim_duration_s"]
                                                        / summary["wall_s"])
    from adaptive_c3.tools.recording import load_recording
    rec = load_recording(out / "log.npz")
    assert rec.t[-1] == pytest.approx(summary["sim_duration_s"], abs=0.011)
    np.testing.assert_allclose(rec.x[-1], summary["final_state"])


def test_ctrl_c_on_a_sweep_cancels_queued_trials_and_writes_results(tmp_path):
    import csv
    import time
    sweep = tmp_path / "sweep.yaml"
    sweep.write_text(f"scenario: {CARTPOLE}\ntrials: 40\nset: {{sim_duration_s: 3.0}}\n"
                     "success: [stabilised]\n")
    out = tmp_path / "out"
    proc = _start(["sweep", str(sweep), "--workers", "2", "--out", str(out)], tmp_path)
    while not list(out.glob("trials/*/*/summary.json")):
        assert proc.poll() is None, proc.communicate()[1].decode()
        time.sleep(0.05)
    rc, _, err = _ctrl_c(proc)
    assert rc == 130 and "Traceback" not in err, err
    assert "interrupted" in err.splitlines()[-1]
    rows = list(csv.DictReader((out / "results.csv").open()))
    status = [r["status"] for r in rows]
    assert len(rows) == 40 and status.count("ok") >= 1
    # queued trials never started: past the finished ones, at most two per worker
    started = len(list(out.glob("trials/*/*")))
    assert started <= status.count("ok") + 4, (started, status.count("ok"))
    summary = json.loads((out / "summary.json").read_text())
    assert summary["interrupted"] and summary["completed"] == status.count("ok")
    rates = next(iter(summary["cells"].values()))["rates"]["stabilised"]
    assert rates["n"] == status.count("ok")   # interrupted trials are not rated


def test_meshcat_stop_reports_the_time_simulated(tmp_path, monkeypatch):
    """Stop after three 50 ms chunks of a 2 s run: the summary says 0.15 s, and the
    settings changed live (the circle's radius) are the ones the summary reports."""
    from adaptive_c3.tools import meshcat_controls as M
    apply, polls = M.MeshcatControls.apply, []

    def apply_then_stop(self):
        self.meshcat.SetSliderValue(M.RADIUS_SLIDER, 0.12)
        req = apply(self)
        polls.append(1)
        return {**req, "stop": len(polls) >= 3}
    monkeypatch.setattr(M.MeshcatControls, "apply", apply_then_stop)
    out = tmp_path / "run"
    rc = main(["run", "ball_rolling", "--meshcat", "--out", str(out), "--set",
               "camera.enabled=false", "--set", "sim_duration_s=2.0"])
    assert rc == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["ended"] == "stopped" and not summary["interrupted"]
    assert summary["sim_duration_s"] == pytest.approx(0.15, abs=1e-9)
    assert summary["sim_duration_requested_s"] == 2.0
    assert summary["real_time_factor"] == pytest.approx(0.15 / summary["wall_s"])
    assert summary["target"]["radius_m"] == pytest.approx(0.12) and summary["restarts"] == 0


def test_meshcat_slider_names_fit_with_their_units():
    """Meshcat's name column is 40 % of its 245 px panel at 11 px type: a longer name is
    cut with an ellipsis (and the unit lost). Widths measured in DejaVu Sans 11 px."""
    from matplotlib.font_manager import FontProperties
    from matplotlib.textpath import TextPath

    from adaptive_c3.tools import meshcat_controls as M
    font = FontProperties(family="DejaVu Sans", size=11)
    for name in (M.ERROR_SLIDER, M.RADIUS_SLIDER, M.LEAD_SLIDER, M.OFFSET_DISPLAY):
        assert name.endswith("]") and "[" in name, name   # a unit
    for name in (M.ERROR_SLIDER, M.LR_SLIDER, M.RADIUS_SLIDER, M.LEAD_SLIDER, M.OFFSET_DISPLAY):
        width = TextPath((0, 0), name, prop=font).get_extents().width
        assert width <= 80, (name, width)


def test_meshcat_port_is_used_and_bad_ports_are_exit_2(tmp_path, capsys):
    import socket
    from adaptive_c3.tools.meshcat_controls import start_meshcat
    with socket.socket() as s:
        s.bind(("localhost", 0))
        port = s.getsockname()[1]
    meshcat = start_meshcat(port)
    assert meshcat.web_url() == f"http://localhost:{port}"
    # the port is taken now: one line, exit 2
    assert main(["run", "ball_rolling", "--meshcat-port", str(port), "--out", str(tmp_path),
                 "--set", "camera.enabled=false", "--set", "sim_duration_s=0.1"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and f"port {port}" in err, err
    assert main(["run", CARTPOLE, "--meshcat", "--out", str(tmp_path)]) == 2
    assert "--meshcat is available for the ball_rolling task" in capsys.readouterr().err


# ------------------------------------------------------------------ words and labels
def test_residual_figure_names_its_vertical_line():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from adaptive_c3.scenarios.schema import load_scenario
    from adaptive_c3.tools.run_ball_rolling import residual_figure
    s, _ = load_scenario(SCENARIO_DIR / "ball_rolling.yaml")
    t = np.linspace(0, 2, 21)
    logs = {"r_comp": (t, np.zeros((21, 8))), "loss": (t, np.ones((21, 1)))}
    fig = residual_figure(logs, s, {"first_contact_s": 1.25})
    try:
        top, bottom = fig.axes
        legend = [x.get_text() for x in top.get_legend().get_texts()]
        vertical = [ln for ax in (top, bottom) for ln in ax.get_lines()
                    if len(set(np.atleast_1d(ln.get_xdata()))) == 1]
        assert len(vertical) == 2
        assert "first EE-ball contact (1.25 s)" in legend
        assert all(ln.get_color() == vertical[0].get_color() for ln in vertical)
    finally:
        plt.close(fig)


def test_laps_singular_and_plural():
    from adaptive_c3.tools.run_ball_rolling import laps_text
    assert (laps_text(0), laps_text(1), laps_text(4)) == ("0 laps", "1 lap", "4 laps")


def test_evaluate_help_shows_a_plain_percent(capsys):
    with pytest.raises(SystemExit):
        main(["evaluate", "--help"])
    text = capsys.readouterr().out
    assert "% of the object's size" in text and "%%" not in text


def test_nonfinite_recording_error_names_plain_indices(tmp_path):
    from adaptive_c3.tools.recording import RecordingError, load_recording
    x = np.zeros((10, 4))
    x[5, 2] = np.nan
    path = tmp_path / "r.npz"
    np.savez(path, t=np.arange(10) * 0.01, x=x, u=np.zeros((10, 1)),
             state_names=np.array(["a", "b", "c", "d"]), input_names=np.array(["f"]))
    with pytest.raises(RecordingError) as e:
        load_recording(path)
    assert "x[5, 2]" in str(e.value) and "np.int64" not in str(e.value)
    assert "sample 5, c" in str(e.value)


def test_sim_loop_keeps_partial_only_when_asked():
    """Ctrl-C ends a `run`'s loop with what was simulated; elsewhere (studies, benchmarks)
    it propagates, so nothing goes on with a cut-short simulation."""
    from adaptive_c3.tools.sim_loop import SimEnd, advance

    class Sim:   # AdvanceTo like Drake's; Ctrl-C arrives during the step past 0.5 s
        def __init__(self):
            self.t = 0.0

        def get_context(self):
            return self

        def get_time(self):
            return self.t

        def AdvanceTo(self, t):
            if t > 0.5:
                raise KeyboardInterrupt
            self.t = t

    assert advance(Sim(), 1.0, 0.1, keep_partial=True) == SimEnd(pytest.approx(0.5), "interrupted")
    with pytest.raises(KeyboardInterrupt):
        advance(Sim(), 1.0, 0.1)
    assert advance(Sim(), 0.3, 0.1) == SimEnd(pytest.approx(0.3), "completed")
    stop_at_02 = advance(Sim(), 1.0, 0.1, after_chunk=lambda t: "stopped" if t >= 0.2 else None)
    assert stop_at_02 == SimEnd(pytest.approx(0.2), "stopped")
