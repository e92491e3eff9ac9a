"""An animated GIF of a ball-rolling run, drawn from its `log.npz`.

Two views side by side: from above (the target circle, the ball's trail, the ball and the
EE tip drawn at their true radii) and from the side along the robot's x axis (the ball
rolling on the table, the EE lifting between pushes). Times are simulated seconds; the
GIF plays `speedup` times faster than real time.

    python -m adaptive_c3.tools.rolling_animation runs/default --duration 30
        # -> runs/default/rolling.gif: the first 30 s at 5x
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import yaml

from adaptive_c3.tools.recording import RecordingError, load_recording

BALL_XYZ = slice(4, 7)       # columns of `ball_true`: quaternion wxyz, position xyz (m, world)
EE_XYZ = slice(0, 3)         # columns of `ee_true`: EE tip position xyz (m, world)
EE_RADIUS_M = 0.0195


def _scenario_geometry(rec) -> tuple[np.ndarray, float, float]:
    """(target centre xy [m], target radius [m], true ball radius [m]) of the run's scenario."""
    spec = yaml.safe_load(rec.scenario) if rec.scenario else {}
    target = (spec or {}).get("target", {}) or {}
    model = (spec or {}).get("model", {}) or {}
    centre = np.asarray(target.get("center", [0.55, 0.0]), float)
    radius = float(target.get("radius", 0.1))
    ball = float(model.get("ball_radius", 0.0315)) - float(model.get("radius_error", 0.0))
    return centre, radius, ball


def write_rolling_gif(run_dir, out=None, speedup: float = 5.0, fps: int = 15,
                      start_s: float = 0.0, duration_s: float | None = None,
                      max_frames: int = 600) -> Path:
    """Draw `run_dir/log.npz` from `start_s` for `duration_s` simulated seconds (default: to
    the end) as `out` (default `run_dir/rolling.gif`); returns its path."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.animation import FuncAnimation, PillowWriter

    run_dir = Path(run_dir)
    rec = load_recording(run_dir / "log.npz")
    if "ball_true" not in rec.extras or "ee_true" not in rec.extras:
        raise RecordingError(f"{run_dir / 'log.npz'}: not a ball-rolling run "
                             "(no ball_true / ee_true arrays)")
    t = np.asarray(rec.t, float)
    ball = np.asarray(rec.extras["ball_true"], float)[:, BALL_XYZ]
    ee = np.asarray(rec.extras["ee_true"], float)[:, EE_XYZ]
    n = min(len(t), len(ball), len(ee))
    t, ball, ee = t[:n], ball[:n], ee[:n]
    centre, radius, r_ball = _scenario_geometry(rec)

    frame_dt = speedup / fps
    end = t[-1] if duration_s is None else min(t[-1], start_s + duration_s)
    frames = np.searchsorted(t, np.arange(max(t[0], start_s), end, frame_dt))
    if len(frames) == 0:
        raise RecordingError(f"{run_dir / 'log.npz'}: no samples between {start_s:g} s "
                             f"and {end:g} s")
    frames = frames[np.linspace(0, len(frames) - 1, min(len(frames), max_frames)).astype(int)]

    fig, (top, side) = plt.subplots(1, 2, figsize=(8.0, 4.0),
                                    gridspec_kw={"width_ratios": [1.0, 1.0]})
    a = np.linspace(0, 2 * np.pi, 200)
    top.plot(centre[0] + radius * np.cos(a), centre[1] + radius * np.sin(a), "k--", lw=0.8,
             label="target circle")
    trail, = top.plot([], [], color="tab:orange", lw=1.2, label="ball path")
    ball_top = plt.Circle((0, 0), r_ball, color="tab:orange")
    ee_top = plt.Circle((0, 0), EE_RADIUS_M, color="0.35", alpha=0.8, label="EE tip")
    top.add_patch(ball_top)
    top.add_patch(ee_top)
    span = radius + 0.08
    top.set_xlim(centre[0] - span, centre[0] + span)
    top.set_ylim(centre[1] - span, centre[1] + span)
    top.set_aspect("equal")
    top.set_xlabel("x [m]")
    top.set_ylabel("y [m]")
    top.set_title("from above")
    top.legend(handles=[trail, ee_top], loc="upper right", fontsize=7)

    side.axhspan(-0.05, 0.0, color="0.85")
    ball_side = plt.Circle((0, 0), r_ball, color="tab:orange")
    ee_side = plt.Circle((0, 0), EE_RADIUS_M, color="0.35", alpha=0.8)
    side.add_patch(ball_side)
    side.add_patch(ee_side)
    side.set_xlim(centre[0] - span, centre[0] + span)
    side.set_ylim(-0.02, 0.12)
    side.set_aspect("equal")
    side.set_xlabel("x [m]")
    side.set_ylabel("z [m]")
    side.set_title("from the side")
    clock = fig.suptitle("")
    fig.tight_layout()

    def draw(i):
        trail.set_data(ball[:i + 1, 0], ball[:i + 1, 1])
        ball_top.center = tuple(ball[i, :2])
        ee_top.center = tuple(ee[i, :2])
        ball_side.center = (ball[i, 0], ball[i, 2])
        ee_side.center = (ee[i, 0], ee[i, 2])
        clock.set_text(f"t = {t[i]:5.1f} s  (x{speedup:g})")
        return trail, ball_top, ee_top, ball_side, ee_side, clock

    out = Path(out) if out else run_dir / "rolling.gif"
    FuncAnimation(fig, draw, frames=frames, blit=False).save(out, writer=PillowWriter(fps=fps),
                                                             dpi=70)
    plt.close(fig)
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description="Animate a ball-rolling run's log.npz as a GIF.")
    p.add_argument("run_dir", help="a run's output folder (holds log.npz)")
    p.add_argument("--out", help="GIF path (default RUN_DIR/rolling.gif)")
    p.add_argument("--speedup", type=float, default=5.0, help="playback speed-up (default 5)")
    p.add_argument("--start", type=float, default=0.0, help="first simulated second drawn")
    p.add_argument("--duration", type=float, help="simulated seconds drawn (default: to the end)")
    args = p.parse_args(argv)
    try:
        path = write_rolling_gif(args.run_dir, args.out, speedup=args.speedup,
                                 start_s=args.start, duration_s=args.duration)
    except (RecordingError, OSError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    print(f"animation: {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
