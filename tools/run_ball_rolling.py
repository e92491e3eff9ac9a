"""Run a ball-rolling scenario: simulate, then write summary.json, log.npz and figures.

Figures (the paper's Figs. 5-6): `path.png` - the ball's path against the target circle
(and the EE's); `residual.png` - the learned EE-ball gap offset and the loss over time,
with the gait's contact events.
"""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np
from pydrake.systems.analysis import Simulator

from adaptive_c3.diagrams.ball_rolling import build_ball_rolling_diagram, controller_prior
from adaptive_c3.models.ball_rolling_controller_model import BALL_POS, INPUT_NAMES, STATE_NAMES
from adaptive_c3.models.ball_rolling_scene import TABLE_CENTER_XY, TABLE_SIZE, TABLE_TOP_Z
from adaptive_c3.systems.rolling.gait import PHASES
from adaptive_c3.tools.process_tuning import frozen_heap
from adaptive_c3.tools.progress import Progress
from adaptive_c3.tools.recording import Recording, save_recording
from adaptive_c3.tools.sim_loop import advance, ending_fields, read_logs

CONTACT_TOL_M = 0.001   # true EE-ball distance counted as contact
BAND = 0.5              # laps count only within +-BAND * radius of the circle


def simulate_ball_rolling(scenario, meshcat=None, progress: bool = True,
                          keep_partial: bool = False):
    """Simulate; returns (handles, logs dict name -> (t, data), wall seconds).
    `handles.sim_end` (tools/sim_loop.SimEnd) says how far it got and how it ended; with
    keep_partial Ctrl-C ends the simulation (logs so far kept), not the process."""
    handles = build_ball_rolling_diagram(scenario, meshcat=meshcat)
    simulator = Simulator(handles.diagram)
    context = simulator.get_mutable_context()
    simulator.Initialize()
    T = scenario.sim_duration_s
    bar = Progress(T, f"ball rolling [{scenario.name}]", enabled=None if progress else False)
    with frozen_heap():
        start = time.perf_counter()
        handles.sim_end = advance(simulator, T, max(T / 100, 0.05), bar=bar,
                                  keep_partial=keep_partial)
        wall = time.perf_counter() - start
    bar.close(handles.sim_end.t)
    return handles, read_logs(handles.logs, context, handles.sim_end), wall


def off_table(position) -> bool:
    """True if the object (positions (N, 3), m, world) ever left the table: below its top
    by more than 1 cm, or outside its x-y extent (fruit scenes collide with a half space,
    so there an object leaving the table stays on the plane's extension)."""
    p = np.asarray(position, float)
    half = np.asarray(TABLE_SIZE[:2]) / 2
    outside = np.any(np.abs(p[:, :2] - np.asarray(TABLE_CENTER_XY)) > half, axis=1)
    return bool(np.any(p[:, 2] < TABLE_TOP_Z - 0.01) or np.any(outside))


def circle_progress(xy, center, radius: float) -> float:
    """Turns (counter-clockwise positive) of a ball path [T, 2] about the circle's centre,
    counted only while the ball is on the circle's band (within BAND x radius of it):
    cutting across the centre earns nothing."""
    xy = np.asarray(xy, float)
    if len(xy) < 2:
        return 0.0
    c = np.asarray(center, float)
    angle = np.unwrap(np.arctan2(xy[:, 1] - c[1], xy[:, 0] - c[0]))
    on_band = np.abs(np.linalg.norm(xy - c, axis=1) - radius) <= BAND * radius
    return float(np.sum(np.diff(angle) * (on_band[1:] & on_band[:-1])) / (2 * np.pi))


def estimate_errors(logs) -> dict:
    """The controller's ball estimate against the truth, over the logged samples:
    horizontal (xy) error mean / p95 / max in mm and, with the camera, the fraction of
    samples whose latest frame gave no accepted detection (the estimate held)."""
    _, est = logs["lcs_state"]
    _, ball = logs["ball_true"]
    n = min(len(est), len(ball))
    err = 1e3 * np.linalg.norm(est[:n, BALL_POS][:, :2] - ball[:n, 4:6], axis=1)
    out = {"error_mean_mm": float(np.mean(err)), "error_p95_mm": float(np.percentile(err, 95)),
           "error_max_mm": float(np.max(err))}
    if "detection_ok" in logs:
        out["dropout_fraction"] = float(np.mean(logs["detection_ok"][1][:, 0] < 0.5))
    return out


def rolling_metrics(logs, scenario, true_radius: float) -> dict:
    """laps, first contact, pushes before it and tracking error from the logs."""
    t, ball = logs["ball_true"]
    _, ee = logs["ee"]
    _, phase = logs["phase"]
    progress = 2 * np.pi * circle_progress(ball[:, 4:6], scenario.target.center,
                                           scenario.target.radius)
    radial = (np.linalg.norm(ball[:, 4:6] - np.asarray(scenario.target.center, float), axis=1)
              - scenario.target.radius)
    gap = (np.linalg.norm(ee[:, :3] - ball[:, 4:7], axis=1) - true_radius
           - scenario.model.ee_radius)
    touching = gap <= CONTACT_TOL_M
    first = int(np.argmax(touching)) if touching.any() else None
    roll = phase[:, 0] == PHASES.index("roll")
    roll_starts = np.flatnonzero(roll[1:] & ~roll[:-1]) + 1
    if roll.size and roll[0]:
        roll_starts = np.r_[0, roll_starts]
    t_first = None if first is None else float(t[first])
    pushes = (int(np.sum(t[roll_starts] <= t_first)) if t_first is not None
              else int(len(roll_starts)))
    since = slice(first or 0, None)
    laps = int(max(progress, 0.0) // (2 * np.pi))
    return {
        "laps": laps,
        # the paper's success criteria (Section VII-C)
        "initiated": bool(progress >= 0.5 * np.pi),
        "one_circle": laps >= 1,
        "four_circles": laps >= 4,
        "circle_progress": progress / (2 * np.pi),
        "first_contact_s": t_first,
        "pushes_before_contact": pushes,
        "contact_fraction": float(np.mean(touching)),
        "tracking_rmse_m": float(np.sqrt(np.mean(radial[since] ** 2))),
        "ball_fell_off": off_table(ball[:, 4:7]),
    }


def run_ball_rolling(scenario, scenario_text: str, out: Path, meshcat: bool = False,
                     meshcat_port: int | None = None) -> dict:
    if meshcat:   # interactive: localhost, sliders + buttons (tools/meshcat_controls.py)
        from adaptive_c3.tools.meshcat_controls import simulate_interactive, start_meshcat
        mc = start_meshcat(meshcat_port)
        print(f"Meshcat: {mc.web_url()}", flush=True)
        handles, logs, wall = simulate_interactive(scenario, mc)
    else:
        handles, logs, wall = simulate_ball_rolling(scenario, keep_partial=True)
    requested_s = scenario.sim_duration_s
    scenario = getattr(handles, "scenario_as_run", scenario)   # Meshcat: the final settings
    t, x = logs["lcs_state"]
    _, u = logs["lcs_input"]
    _, r = logs["r_comp"]
    _, loss = logs["loss"]
    dt = scenario.model.planning_dt
    half = len(handles.lambda_names) // 2
    summary = {
        "scenario": scenario.name,
        "task": "ball_rolling",
        "robot": scenario.robot,
        **ending_fields(getattr(handles, "sim_end", None), requested_s, wall),
        "final_state": x[-1].tolist(),
        "state_names": list(STATE_NAMES),
        "object": scenario.model.object,
        "model_radius_m": controller_prior(scenario).model.ball_radius,
        "true_radius_m": handles.true_radius,
        "adaptation": bool(scenario.learner.enabled),
        "target": {"center_m": list(scenario.target.center), "radius_m": scenario.target.radius,
                   "lead_deg": scenario.target.lead_deg},
        **rolling_metrics(logs, scenario, handles.true_radius),
        "ball_estimate": estimate_errors(logs),
        "residual_final": r[-1].tolist(),
        "residual_names": list(handles.lambda_names),
        "ee_ball_gap_offset_m": float(np.mean(r[-1, :half]) * dt),
        "loss_final": float(loss[-1, 0]),
        "c3_solve_time": handles.planner.solve_time_stats(),
        "planner_holds": handles.planner.failures,
        "c3_fallbacks": handles.planner.fallback_counts(),
    }
    if hasattr(handles, "restarts"):   # interactive: the last episode, its final settings
        summary.update(restarts=handles.restarts,
                       model_radius_error_m=scenario.model.radius_error,
                       learning_rate=scenario.learner.learning_rate)
    _, ball = logs["ball_true"]
    _, ee = logs["ee"]
    _, phase = logs["phase"]
    save_recording(out / "log.npz", Recording(
        t=t, x=x, u=u, state_names=list(STATE_NAMES), input_names=list(INPUT_NAMES),
        scenario=scenario_text,
        extras={"ee_force": logs["ee_force"][1], "ee_desired": logs["ee.desired_state"][1],
                "r_comp": r, "loss": loss[:, 0], "ball_true": ball, "ee_true": ee,
                "phase": phase[:, 0]}))
    summary["plots"] = [p.name for p in plot_ball_rolling(out, logs, handles, scenario,
                                                          summary)]
    return summary


def laps_text(laps: int) -> str:
    return f"{laps} lap" if laps == 1 else f"{laps} laps"


def plot_ball_rolling(out: Path, logs, handles, scenario, summary) -> list[Path]:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    _, ball = logs["ball_true"]
    _, ee = logs["ee"]
    c, R = np.asarray(scenario.target.center), scenario.target.radius
    fig, ax = plt.subplots(figsize=(5.5, 5.5))
    a = np.linspace(0, 2 * np.pi, 200)
    ax.plot(c[0] + R * np.cos(a), c[1] + R * np.sin(a), "k--", lw=1, label="target circle")
    ax.plot(ee[:, 0], ee[:, 1], color="0.75", lw=0.6, label="EE tip")
    ax.plot(ball[:, 4], ball[:, 5], color="tab:orange", lw=1.5, label="ball")
    ax.plot(ball[0, 4], ball[0, 5], "o", color="tab:orange")
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    on = "on" if scenario.learner.enabled else "off"
    ax.set_title(f"{scenario.name}: adaptation {on}, {laps_text(summary['laps'])}")
    ax.legend(loc="upper right", fontsize=7)
    path_png = out / "path.png"
    fig.savefig(path_png, dpi=120, bbox_inches="tight")
    plt.close(fig)

    fig = residual_figure(logs, scenario, summary)
    res_png = out / "residual.png"
    fig.savefig(res_png, dpi=120, bbox_inches="tight")
    plt.close(fig)
    return [path_png, res_png]


def residual_figure(logs, scenario, summary):
    """The learned gap offsets (top) and the violation loss (bottom) over time, with the
    first EE-ball contact as a vertical line (named in the top legend)."""
    import matplotlib.pyplot as plt
    tr, r = logs["r_comp"]
    tl, loss = logs["loss"]
    half = r.shape[1] // 2
    dt = scenario.model.planning_dt
    fig, axes = plt.subplots(2, 1, figsize=(8, 5), sharex=True)
    axes[0].plot(tr, 1e3 * dt * r[:, :half].mean(axis=1), label="EE-ball (learned)")
    axes[0].plot(tr, 1e3 * dt * r[:, half:].mean(axis=1), label="ball-table (learned)")
    axes[0].axhline(2e3 * scenario.model.radius_error, color="k", ls="--", lw=0.8,
                    label="EE-ball on top: 2 x radius error")
    axes[1].semilogy(tl, np.maximum(loss[:, 0], 1e-12))
    t_contact = summary["first_contact_s"]
    if t_contact is not None:
        axes[0].axvline(t_contact, color="tab:green", lw=0.8,
                        label=f"first EE-ball contact ({t_contact:.2f} s)")
        axes[1].axvline(t_contact, color="tab:green", lw=0.8)
    axes[0].set_ylabel("gap offset r dt [mm]")
    axes[0].legend(fontsize=7)
    axes[1].set_ylabel("violation loss")
    axes[1].set_xlabel("t [s]")
    return fig
