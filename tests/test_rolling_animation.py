"""The ball-rolling animation: drawn from a run's log.npz, one clear error otherwise."""
import numpy as np
from PIL import Image

from adaptive_c3.tools.recording import Recording, save_recording
from adaptive_c3.tools.rolling_animation import main, write_rolling_gif


def _fake_run(tmp_path, seconds=4.0):
    t = np.arange(0.0, seconds, 0.01)
    ball = np.zeros((len(t), 13))
    ball[:, 0] = 1.0
    ball[:, 4] = 0.55 + 0.1 * np.cos(t)
    ball[:, 5] = 0.1 * np.sin(t)
    ball[:, 6] = 0.0315
    ee = np.zeros((len(t), 6))
    ee[:, :3] = ball[:, 4:7] + [-0.05, 0.0, 0.01]
    save_recording(tmp_path / "log.npz", Recording(
        t=t, x=np.zeros((len(t), 1)), u=np.zeros((len(t), 1)), state_names=["a"],
        input_names=["b"], scenario="task: ball_rolling\n",
        extras={"ball_true": ball, "ee_true": ee}))
    return tmp_path


def test_gif_has_one_frame_per_played_interval(tmp_path):
    run = _fake_run(tmp_path)
    path = write_rolling_gif(run, speedup=2.0, fps=5, duration_s=3.0)
    with Image.open(path) as im:
        assert im.n_frames == 8          # 3 s at 2x and 5 fps: a frame every 0.4 s
        assert im.size[0] > im.size[1]   # two views side by side


def test_a_folder_without_a_ball_rolling_log_is_one_line_and_exit_2(tmp_path, capsys):
    assert main([str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "recording not found" in err[0]
