"""Interactive Meshcat controls for the ball-rolling run (`adaptive-c3 run ... --meshcat`).

`MeshcatControls` puts on Drake's Meshcat page (served on localhost by `start_meshcat`):
  sliders  "ball err [mm]"       the injected ball-radius error (model - true);
                                 a structural change: applied by "Restart"
           "learning rate"       the residual learner's Adam step (live)
           "circle r [m]"        the target circle's radius (live)
           "lead [deg]"          how far the target leads the ball along the
                                 circle - the rolling speed (live)
           "learned [mm]"        display only: the learned EE-ball gap offset
                                 (mean r_comp of the EE-ball rows x planning dt)
  buttons  "Adaptation on/off"   toggles learning (the learner's enable port)
           "Restart"             rebuilds the run with the slider's model error
           "Stop"                ends the run (results are written for the time simulated)
The slider names fit Meshcat's name column (about 94 px at 11 px type) with their units.
and draws the current C3 plan (EE and ball positions over the horizon) as two lines.

It works between simulator steps on a built BallRollingDiagram (it does not add
systems): `apply()` copies the sliders into the learner / gait, `show()` draws.
`simulate_interactive` is the run loop that uses it (real time by default); it returns
what tools/run_ball_rolling.simulate_ball_rolling returns.
"""
from __future__ import annotations

import dataclasses
import time

import numpy as np

from adaptive_c3.tools.sim_loop import advance, read_logs

ERROR_SLIDER = "ball err [mm]"
LR_SLIDER = "learning rate"
RADIUS_SLIDER = "circle r [m]"
LEAD_SLIDER = "lead [deg]"
OFFSET_DISPLAY = "learned [mm]"
ADAPT_BUTTON = "Adaptation on/off"
RESTART_BUTTON = "Restart"
STOP_BUTTON = "Stop"


def start_meshcat(port: int | None = None):
    """A Meshcat server bound to localhost (not all interfaces: nothing outside the machine
    can drive it), on `port` or, with None, the first free port from Drake's 7000."""
    from pydrake.geometry import Meshcat, MeshcatParams

    from adaptive_c3.tools.user_input import UserError
    if port is not None and not 1 <= int(port) <= 65535:
        raise UserError(f"--meshcat-port must be 1-65535, got {port}")
    try:
        return Meshcat(MeshcatParams(host="localhost", port=port))
    except RuntimeError as e:
        if port is None:
            raise
        raise UserError(f"Meshcat could not open port {port} on localhost ({e}); "
                        "choose another --meshcat-port or leave it out for the first free one")


class MeshcatControls:
    def __init__(self, meshcat, scenario):
        self.meshcat = meshcat
        self.scenario = scenario
        m, t, lr = scenario.model, scenario.target, scenario.learner.learning_rate
        lim = 0.45 * m.ball_radius * 1e3
        meshcat.AddSlider(ERROR_SLIDER, -round(lim, 1), round(lim, 1), 0.5, m.radius_error * 1e3)
        meshcat.AddSlider(LR_SLIDER, 0.0, max(0.02, 2 * lr), 1e-4, lr)
        meshcat.AddSlider(RADIUS_SLIDER, 0.05, 0.15, 0.005, t.radius)
        meshcat.AddSlider(LEAD_SLIDER, 5.0, 45.0, 1.0, t.lead_deg)
        meshcat.AddSlider(OFFSET_DISPLAY, -20.0, 20.0, 0.01, 0.0)
        for b in (ADAPT_BUTTON, RESTART_BUTTON, STOP_BUTTON):
            meshcat.AddButton(b)
        self._clicks = {b: 0 for b in (ADAPT_BUTTON, RESTART_BUTTON, STOP_BUTTON)}
        self.adaptation = bool(scenario.learner.enabled)
        self.handles = None
        self._ctx = None

    # ----------------------------------------------------------------- state
    def _new_clicks(self, button) -> int:
        n = self.meshcat.GetButtonClicks(button)
        new, self._clicks[button] = n - self._clicks[button], n
        return new

    def model_error_m(self) -> float:
        return 1e-3 * self.meshcat.GetSliderValue(ERROR_SLIDER)

    def scenario_for_restart(self):
        """The scenario with every slider's setting, the model error included."""
        s = self.live_settings(self.scenario)
        return dataclasses.replace(s, model=dataclasses.replace(
            s.model, radius_error=self.model_error_m()))

    def live_settings(self, s):
        """s with the settings the sliders and buttons change live (target circle and
        lead, learning rate, adaptation on/off); the model error only changes on Restart."""
        target = dataclasses.replace(s.target, radius=self.meshcat.GetSliderValue(RADIUS_SLIDER),
                                     lead_deg=self.meshcat.GetSliderValue(LEAD_SLIDER))
        learner = dataclasses.replace(s.learner, enabled=self.adaptation,
                                      learning_rate=self.meshcat.GetSliderValue(LR_SLIDER))
        return dataclasses.replace(s, target=target, learner=learner)

    def attach(self, handles, root_context) -> None:
        """Control this diagram (a BallRollingDiagram) in this root context."""
        self.handles, self._ctx = handles, root_context
        self._learner_ctx = handles.learner.GetMyMutableContextFromRoot(root_context)
        self._planner_ctx = handles.planner.GetMyContextFromRoot(root_context)
        self._set_enable()

    def _set_enable(self):
        port = self.handles.learner.GetInputPort("enable")
        port.FixValue(self._learner_ctx, [1.0 if self.adaptation else 0.0])

    # ----------------------------------------------------------------- polling
    def apply(self) -> dict:
        """Copy sliders / buttons into the running diagram; returns the requests."""
        h = self.handles
        if self._new_clicks(ADAPT_BUTTON) % 2:
            self.adaptation = not self.adaptation
            self._set_enable()
        lr = float(self.meshcat.GetSliderValue(LR_SLIDER))
        learner = h.learner
        if lr != learner.options.learning_rate:
            # the learner reads its options at every Adam step
            learner._opts = dataclasses.replace(learner.options, learning_rate=lr)
        gait = h.planner._gait
        radius = float(self.meshcat.GetSliderValue(RADIUS_SLIDER))
        lead = float(self.meshcat.GetSliderValue(LEAD_SLIDER))
        if (radius, lead) != (gait.path.radius, gait.path.lead_deg):
            gait.path = dataclasses.replace(gait.path, radius=radius, lead_deg=lead)
        return {"stop": self._new_clicks(STOP_BUTTON) > 0,
                "restart": self._new_clicks(RESTART_BUTTON) > 0,
                "adaptation": self.adaptation, "learning_rate": lr,
                "target_radius": radius, "target_lead_deg": lead}

    def show(self) -> None:
        """Draw the plan and the learned offset."""
        from pydrake.geometry import Rgba
        h = self.handles
        sol = h.planner.solution(self._planner_ctx)
        if sol is not None and np.all(np.isfinite(sol.x_plan)):
            self.meshcat.SetLine("plan/ee", np.asarray(sol.x_plan[:, 0:3].T, order="F"),
                                 3.0, Rgba(0.1, 0.4, 1.0, 1.0))
            self.meshcat.SetLine("plan/ball", np.asarray(sol.x_plan[:, 7:10].T, order="F"),
                                 3.0, Rgba(1.0, 0.5, 0.0, 1.0))
        c, R = np.asarray(h.planner._gait.path.center, float), h.planner._gait.path.radius
        a = np.linspace(0, 2 * np.pi, 73)
        circle = np.vstack([c[0] + R * np.cos(a), c[1] + R * np.sin(a), np.full(a.size, 0.001)])
        self.meshcat.SetLine("target_circle", np.asarray(circle, order="F"), 1.0,
                             Rgba(0.0, 0.0, 0.0, 1.0))
        # the gap offset the planner uses (its r_comp input is at the planning dt)
        r = np.asarray(h.planner.GetInputPort("r_comp").Eval(self._planner_ctx), float)
        offset_mm = h.planner.gap_offset(r) * 1e3
        if np.isfinite(offset_mm):
            self.meshcat.SetSliderValue(OFFSET_DISPLAY, float(np.clip(offset_mm, -20, 20)))

    def close(self) -> None:
        for name in (ERROR_SLIDER, LR_SLIDER, RADIUS_SLIDER, LEAD_SLIDER, OFFSET_DISPLAY):
            self.meshcat.DeleteSlider(name)
        for b in self._clicks:
            self.meshcat.DeleteButton(b)


def simulate_interactive(scenario, meshcat, progress: bool = True, realtime_rate: float = 1.0,
                         chunk_s: float = 0.05, controls: MeshcatControls | None = None):
    """The interactive run loop: simulate in chunks, polling the controls between them;
    "Restart" rebuilds with the sliders' settings, "Stop" (or Ctrl-C) ends. Returns
    (handles, logs, wall seconds) of the last episode, like simulate_ball_rolling, with
    `handles.sim_end` saying how far it got and how it ended, `handles.scenario_as_run`
    the last episode's scenario with the live settings at the end, and
    `handles.restarts` how many times Restart was pressed."""
    from pydrake.systems.analysis import Simulator

    from adaptive_c3.diagrams.ball_rolling import build_ball_rolling_diagram
    controls = controls or MeshcatControls(meshcat, scenario)
    s, restarts = scenario, 0
    while True:
        meshcat.Delete()
        handles = build_ball_rolling_diagram(s, meshcat=meshcat)
        sim = Simulator(handles.diagram)
        if realtime_rate:
            sim.set_target_realtime_rate(realtime_rate)
        context = sim.get_mutable_context()
        sim.Initialize()
        controls.attach(handles, context)
        start = time.perf_counter()

        def poll(_t):
            req = controls.apply()
            controls.show()
            return "stopped" if req["stop"] else "restart" if req["restart"] else None
        handles.sim_end = advance(sim, s.sim_duration_s, chunk_s, after_chunk=poll,
                                  keep_partial=True)
        restart = handles.sim_end.reason == "restart"
        wall = time.perf_counter() - start
        if not restart:
            break
        s, restarts = controls.scenario_for_restart(), restarts + 1
        if progress:
            print(f"restart: model error {1e3 * s.model.radius_error:.1f} mm", flush=True)
    handles.scenario_as_run, handles.restarts = controls.live_settings(s), restarts
    return handles, read_logs(handles.logs, context, handles.sim_end), wall


__all__ = ["MeshcatControls", "simulate_interactive", "start_meshcat"]
