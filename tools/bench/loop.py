"""`bench loop`: the whole ball-rolling closed loop, camera on and off.

Rows `loop/ballroll/camera_on` and `loop/ballroll/camera_off` carry `real_time_factor`
(simulated seconds per wall second) and `share` - the fraction of wall time spent in
each component's callbacks (timed by wrapping the LeafSystem methods while the diagram
is built and run; `plant_and_framework` is the rest: SAP, rendering set-up, scheduling).
`median_ms` is the wall time per simulated 12.5 ms control period. camera_on is compared
against camera_off (speedup < 1 means the camera costs time).
"""
from __future__ import annotations

import time
from contextlib import contextmanager

CAMERA_BEFORE = ("camera.width=320", "camera.height=240")   # the image size until issue 18

COMPONENTS = {   # label -> (module, class, method)
    "planner_c3": ("adaptive_c3.systems.rolling.planner", "BallRollingPlanner", "_tick"),
    "anitescu_lcs": ("adaptive_c3.systems.contact.anitescu_lcs_system", "AnitescuLcsSystem", "_update"),
    "residual_learner": ("adaptive_c3.systems.learning.residual_learner", "ResidualLearner", "_update"),
    "impedance": ("adaptive_c3.systems.franka.impedance_controller", "ImpedanceController",
                  "_calc_torque"),
    "detector_and_render": ("adaptive_c3.systems.perception.ball_detector", "BallDetector", "_update"),
}


@contextmanager
def timed_components(totals: dict):
    """Wrap each component's callback with a timer accumulating into totals[label]."""
    import importlib
    saved = []
    for label, (mod, cls, meth) in COMPONENTS.items():
        klass = getattr(importlib.import_module(mod), cls)
        original = getattr(klass, meth)
        totals[label] = 0.0

        def wrapper(self, *args, _f=original, _label=label):
            t0 = time.perf_counter()
            try:
                return _f(self, *args)
            finally:
                totals[_label] += time.perf_counter() - t0
        setattr(klass, meth, wrapper)
        saved.append((klass, meth, original))
    try:
        yield totals
    finally:
        for klass, meth, original in saved:
            setattr(klass, meth, original)


def measure(camera: bool, sim_s: float, extra=()) -> dict:
    from adaptive_c3.scenarios.schema import SCENARIO_DIR, load_scenario
    from adaptive_c3.tools.run_ball_rolling import simulate_ball_rolling
    scenario, _ = load_scenario(SCENARIO_DIR / "ball_rolling.yaml",
                                [f"camera.enabled={str(camera).lower()}",
                                 f"sim_duration_s={sim_s}", *extra])
    totals: dict = {}
    with timed_components(totals):
        _, _, wall = simulate_ball_rolling(scenario, progress=False)
    share = {k: v / wall for k, v in totals.items() if v > 0}
    share["plant_and_framework"] = max(0.0, 1.0 - sum(share.values()))
    period = 1.0 / scenario.c3.rate_hz
    return {"median_ms": 1e3 * wall * period / sim_s, "real_time_factor": sim_s / wall,
            "wall_s": wall, "sim_s": sim_s, "share": share}


def run_bench(quick: bool = False) -> list:
    sim_s = 2.0 if quick else 6.0
    off = {"name": "loop/ballroll/camera_off", **measure(False, sim_s),
           "note": "Panda + SAP 1 ms + impedance + LCS + learner + C3; ball pose + noise"}
    on = {"name": "loop/ballroll/camera_on", **measure(True, sim_s),
          "baseline": "loop/ballroll/camera_off",
          "note": "as camera_off, with RgbdSensor (VTK) + Hough detector at 80 Hz"}
    on["speedup"] = off["median_ms"] / on["median_ms"]
    before = {"name": "loop/ballroll/camera_on_320x240", **measure(True, sim_s, CAMERA_BEFORE),
              "note": "camera_on with the image size before issue 18 (320 x 240)"}
    on["speedup_vs_320x240"] = before["median_ms"] / on["median_ms"]
    return [off, on, before]
