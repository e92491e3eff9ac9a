"""Run a cart-pole scenario: simulate, then write summary.json, log.npz and plots."""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np
from pydrake.systems.analysis import Simulator

from adaptive_c3.diagrams.cartpole import CARTPOLE_Q, CARTPOLE_R, build_cartpole_diagram
from adaptive_c3.tools.progress import Progress
from adaptive_c3.tools.recording import Recording, save_recording
from adaptive_c3.tools.sim_loop import advance, ending_fields, read_logs


def time_to_stabilise(t, x, tol):
    """First time after which |x|_inf stays below tol (None if it never does)."""
    ok = np.max(np.abs(x), axis=1) < tol
    if not ok[-1]:
        return None
    bad = np.flatnonzero(~ok)
    return float(t[0] if len(bad) == 0 else t[min(bad[-1] + 1, len(t) - 1)])


def closed_loop_cost(x, u, q_diag, r_diag, dt) -> float:
    """Sum over the logged steps of (x'Qx + u'Ru) dt with C3's diagonal weights."""
    x, u = np.asarray(x, float), np.asarray(u, float)
    return float(dt * (np.sum(x * x * np.asarray(q_diag)) + np.sum(u * u * np.asarray(r_diag))))


def simulate_cartpole(scenario, progress_label="cartpole", model_lcs=None,
                      keep_partial: bool = False):
    """Simulate the scenario; returns (handles, logs dict name -> (t, data), wall seconds).
    `handles.sim_end` (tools/sim_loop.SimEnd) says how far it got and how it ended; with
    keep_partial Ctrl-C ends the simulation (logs so far kept), not the process.

    model_lcs (optional) replaces the controller's model LCS (see build_cartpole_diagram)."""
    handles = build_cartpole_diagram(scenario, model_lcs)
    simulator = Simulator(handles.diagram)
    context = simulator.get_mutable_context()
    if scenario.measurement_noise:
        handles.diagram.SetRandomContext(context, _generator(scenario.seed))
    simulator.Initialize()
    bar = Progress(scenario.sim_duration_s, progress_label)
    start = time.perf_counter()
    handles.sim_end = advance(simulator, scenario.sim_duration_s,
                              max(scenario.sim_duration_s / 50, 0.01), bar=bar,
                              keep_partial=keep_partial)
    wall = time.perf_counter() - start
    bar.close(handles.sim_end.t)
    return handles, read_logs(handles.loggers, context, handles.sim_end), wall


def _generator(seed):
    from pydrake.common import RandomGenerator
    return RandomGenerator(int(seed))


def run_cartpole(scenario, scenario_text: str, out: Path) -> dict:
    handles, logs, wall = simulate_cartpole(scenario, keep_partial=True)
    t, x = logs["x"]
    _, u = logs["u"]
    _, lam = logs["lambda"]
    tol = scenario.stabilise_tolerance
    t_stab = time_to_stabilise(t, x, tol)
    summary = {
        "scenario": scenario.name,
        "task": "cartpole",
        "controller": ("lqr on the no-contact model" if scenario.controller == "lqr" else "c3"),
        **ending_fields(handles.sim_end, scenario.sim_duration_s, wall),
        "initial_state": list(scenario.initial_state),
        "final_state": x[-1].tolist(),
        "state_names": list(handles.state_names),
        "stabilised": t_stab is not None,
        "time_to_stabilise_s": t_stab,
        "stabilise_tolerance": tol,
        "wall_contact_steps": {name: int(np.sum(lam[:, i] > 1e-9))
                               for i, name in enumerate(handles.lambda_names)},
        "max_wall_force_N": {name: float(lam[:, i].max())
                             for i, name in enumerate(handles.lambda_names)},
        "model_wall_offset_error": list(scenario.model.wall_offset_error),
        "closed_loop_cost": closed_loop_cost(x, u, scenario.c3.q_diag or CARTPOLE_Q,
                                             scenario.c3.r_diag or CARTPOLE_R,
                                             handles.true_lcs.dt),
    }
    if hasattr(handles.controller, "solve_time_stats"):
        summary["c3_solve_time"] = handles.controller.solve_time_stats()
    if hasattr(handles.controller, "fallback_counts"):
        summary["c3_fallbacks"] = handles.controller.fallback_counts()
    extras = {"lambda": lam}
    if handles.learner is not None:
        _, r = logs["r_comp"]
        _, loss = logs["loss"]
        summary["residual_final"] = r[-1].tolist()
        summary["residual_names"] = list(handles.lambda_names)
        summary["residual_target"] = list(scenario.model.wall_offset_error)
        summary["loss_final"] = float(loss[-1, 0])
        extras.update(r_comp=r, loss=loss[:, 0])
    save_recording(out / "log.npz", Recording(
        t=t, x=x, u=u, state_names=list(handles.state_names),
        input_names=list(handles.input_names), scenario=scenario_text, extras=extras))
    summary["plots"] = [str(p.name) for p in plot_cartpole(out, t, x, u, lam, logs, handles,
                                                           scenario)]
    return summary


def plot_cartpole(out: Path, t, x, u, lam, logs, handles, scenario) -> list[Path]:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    rows = 4 if handles.learner is not None else 3
    fig, axes = plt.subplots(rows, 1, figsize=(8, 2.4 * rows), sharex=True)
    for i, name in enumerate(handles.state_names):
        axes[0].plot(t, x[:, i], label=name)
    axes[0].axhline(scenario.stabilise_tolerance, color="k", lw=0.5, ls=":")
    axes[0].axhline(-scenario.stabilise_tolerance, color="k", lw=0.5, ls=":")
    axes[0].set_ylabel("state")
    axes[0].legend(loc="upper right", fontsize=7, ncol=2)
    axes[1].plot(t, u[:, 0], color="tab:purple")
    axes[1].set_ylabel("cart force [N]")
    for i, name in enumerate(handles.lambda_names):
        axes[2].plot(t, lam[:, i], label=name)
    axes[2].set_ylabel("wall force [N]")
    axes[2].legend(loc="upper right", fontsize=7)
    if handles.learner is not None:
        tr, r = logs["r_comp"]
        for i, name in enumerate(handles.lambda_names):
            line, = axes[3].plot(tr, r[:, i], label=f"r_comp {name}")
            axes[3].axhline(scenario.model.wall_offset_error[i], color=line.get_color(),
                            ls="--", lw=0.8)
        axes[3].set_ylabel("residual [m]")
        axes[3].legend(loc="lower right", fontsize=7)
    axes[-1].set_xlabel("time [s]")
    fig.suptitle(f"{scenario.name}: x0 = {list(scenario.initial_state)}", fontsize=9)
    fig.tight_layout()
    path = out / "states.png"
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return [path]
