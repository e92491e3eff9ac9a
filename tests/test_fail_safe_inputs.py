"""Issue 31, item 2 outside the 1 kHz loop: the planner and the simulated driver survive
malformed input (counted, in the summary, never used; a run of it is the planner's safe
stop), and the planner stops planning on a stale status and waits for the robot again.
All in one process over memq://, in lock-step (the planner's clock is the loop's time)."""
from __future__ import annotations

import numpy as np
import pytest

from adaptive_c3.scenarios.schema import load_scenario
from adaptive_c3.tools import cli

FAST = ["camera.enabled=false", "model.radius_error=0"]
GARBAGE = b"\x00garbage, not an LCM message"


def _scenario():
    s, _ = load_scenario(cli.resolve_scenario_path("ball_rolling"), FAST)
    return s


class Rig:
    """Simulated driver + planner (PlannerRun) over memq://, 1 ms lock-step steps."""

    def __init__(self, stale_s=0.1):
        from pydrake.lcm import DrakeLcm
        from pydrake.systems.analysis import Simulator

        from adaptive_c3.tools.hardware.planner_process import build_planner_process
        from adaptive_c3.tools.hardware.planner_run import PlannerRun
        from adaptive_c3.tools.hardware.sim_driver import build_sim_driver
        self.s = s = _scenario()
        self.lcm = lcm = DrakeLcm("memq://")
        self.t = 0.0
        self.plans = []                       # loop time of every EE_PLAN
        lcm.Subscribe("EE_PLAN", lambda _d: self.plans.append(self.t))
        self.lines = []
        self.driver = build_sim_driver(s, lcm)
        self.drv_sim = Simulator(self.driver.diagram)
        self.drv_sim.Initialize()             # publishes the first status and ball estimate
        self.run = PlannerRun(build_planner_process(s, lcm, transport_s=1e-3), lcm,
                              stale_s=stale_s, malformed_run=s.safety.malformed_run,
                              realtime=False, clock=lambda: self.t,
                              pump=lambda: lcm.HandleSubscriptions(0), say=self.lines.append)
        self.driver_alive = True

    def advance(self, until: float, each=None):
        while self.t < until - 1e-9:
            self.t = round(self.t + 1e-3, 6)
            if self.driver_alive:
                self.drv_sim.AdvanceTo(self.drv_sim.get_context().get_time() + 1e-3)
            if each:
                each(self.t)
            self.run.tick(1e-3)

    def plans_between(self, a, b):
        return sum(a < t <= b for t in self.plans)


@pytest.mark.parametrize("channel", ["PANDA_STATUS", "BALL_ESTIMATE"])
def test_planner_counts_garbage_and_keeps_planning(channel):
    """Before: the first undecodable message raised `ValueError: Decode error` out of the
    planner's simulator (no summary)."""
    rig = Rig()

    def garbage(t):
        if 0.1 < t <= 0.105:                  # five in a row (the safe stop needs ten)
            rig.lcm.Publish(channel, GARBAGE)
    rig.advance(0.3, garbage)
    out = rig.run.summary()
    assert rig.run.state == "planning" and out["safety"]["state"] == "ok"
    assert out["undecodable_messages"][channel] == 5
    assert out["undecodable_messages"][({"PANDA_STATUS", "BALL_ESTIMATE"} - {channel}).pop()] == 0
    assert rig.plans_between(0.2, 0.3) >= 15          # a plan every 5 ms goes on
    assert rig.run.exit_code() == 0


def test_planner_run_of_garbage_is_a_safe_stop():
    from adaptive_c3.tools.hardware.planner_run import SAFE_STOP_EXIT
    rig = Rig()

    def garbage(t):
        if 0.1 < t <= 0.1 + 1e-3 * rig.s.safety.malformed_run:
            rig.lcm.Publish("BALL_ESTIMATE", GARBAGE)
    rig.advance(0.3, garbage)
    out = rig.run.summary()
    assert rig.run.state == "safe_stop" and rig.run.exit_code() == SAFE_STOP_EXIT == 3
    assert out["safety"]["state"] == "safe_stop" and "BALL_ESTIMATE" in out["safety"]["breach"]
    assert [ln for ln in rig.lines if "SAFE STOP" in ln and "BALL_ESTIMATE" in ln]
    stop = 0.1 + 1e-3 * rig.s.safety.malformed_run
    assert rig.plans_between(0.05, 0.1) > 5 and rig.plans_between(stop + 0.003, 0.3) == 0


def test_planner_stops_when_the_driver_dies_and_waits_for_its_return():
    """Before: with the driver gone the planner kept sending plans built on the last
    status (~200/s over udpm) and said nothing; now it stops within its stale limit, says
    so in one line, and plans again only after both channels spoke again - from a fresh
    start, whose first target is the restarted robot's EE, not the old plan's."""
    from pydrake.systems.analysis import Simulator

    from adaptive_c3.tools.hardware.sim_driver import build_sim_driver
    rig = Rig(stale_s=0.1)
    rig.advance(0.3)
    assert rig.plans_between(0.2, 0.3) >= 15
    rig.driver_alive = False                      # kill -9: no status, no ball estimate
    rig.advance(0.6)
    assert rig.run.state == "waiting" and rig.run.stale_stops == 1
    said = [ln for ln in rig.lines if "stopped planning" in ln]
    assert len(said) == 1 and "PANDA_STATUS" in said[0]
    assert rig.plans_between(0.3 + 0.1 + 0.005, 0.6) == 0
    # a status alone is not enough: the wait is for both channels
    rig.lcm.Publish("PANDA_STATUS", _status_like(rig))
    rig.advance(0.65)
    assert rig.run.state == "waiting" and rig.plans_between(0.6, 0.65) == 0
    # the driver restarts (its clock from its epoch again, the arm at its start)
    rig.driver = build_sim_driver(rig.s, rig.lcm)
    rig.drv_sim = Simulator(rig.driver.diagram)
    rig.drv_sim.Initialize()
    rig.driver_alive = True
    rig.advance(0.9)
    out = rig.run.summary()
    assert rig.run.state == "planning" and out["planning_segments"] == 2
    assert rig.plans_between(0.8, 0.9) >= 15
    assert [ln for ln in rig.lines if "planning again" in ln]


def _status_like(rig):
    from adaptive_c3.tools.hardware.status_sender import status_message
    return status_message(1, rig.s.impedance.q_null, np.zeros(7), np.zeros(7), 2).encode()


def _drive(steps: int, command, **driver_settings):
    """The simulated driver alone over memq://, 1 ms steps; command(k, status utime) gives
    the bytes to publish on PANDA_COMMAND before step k (None: nothing). Returns the
    driver's summary and its applied torque after every step."""
    from drake import lcmt_panda_status
    from pydrake.lcm import DrakeLcm
    from pydrake.systems.analysis import Simulator

    from adaptive_c3.tools.hardware.sim_driver import build_sim_driver, driver_summary
    lcm = DrakeLcm("memq://")
    drv = build_sim_driver(_scenario(), lcm, **driver_settings)
    status = []
    lcm.Subscribe("PANDA_STATUS", lambda d: status.append(d))
    sim = Simulator(drv.diagram)
    sim.Initialize()
    ctx = drv.command.GetMyContextFromRoot(sim.get_context())
    taus = {}
    for k in range(1, steps + 1):
        lcm.HandleSubscriptions(0)
        data = command(k, lcmt_panda_status.decode(status[-1]).utime)
        if data is not None:
            lcm.Publish("PANDA_COMMAND", data)
        sim.AdvanceTo(k * 1e-3)
        taus[k] = np.asarray(drv.command.GetOutputPort("panda.torque_command").Eval(ctx))
    return driver_summary(drv, sim.get_context()), taus


def _torques(tau):
    from adaptive_c3.tools.hardware.torque_command_sender import torque_command_message
    return lambda utime: torque_command_message(tau, utime).encode()


def test_sim_driver_counts_garbage_commands_and_keeps_obeying():
    """Before: one undecodable PANDA_COMMAND raised `ValueError: Decode error` out of the
    driver's simulator."""
    good = _torques(np.full(7, 0.5))
    out, taus = _drive(300, lambda k, utime: GARBAGE if 100 <= k < 107 else good(utime))
    assert out["commands_undecodable"] == 7
    assert out["commands_received"] >= 280 and out["commands_expired"] == 0
    assert np.allclose(taus[300], 0.5, atol=0.05)           # the good commands are obeyed


def test_sim_driver_holds_a_killed_controller_and_obeys_a_restarted_one():
    """As the real driver: commands stop -> the last one expires, the arm is damped
    (-kd v); a new controller's commands (stamped with the current status) are obeyed."""
    good = _torques(np.full(7, 0.5))
    # the controller is dead between 0.2 and 0.4 s
    out, taus = _drive(600, lambda k, utime: good(utime) if k <= 200 or k > 400 else None)
    assert np.allclose(taus[200], 0.5, atol=0.05) and np.allclose(taus[600], 0.5, atol=0.05)
    assert np.abs(taus[390] - 0.5).max() > 0.4        # held by the driver's damping
    assert out["commands_expired"] == 1 and out["ticks_without_command"] > 80


def test_unsafe_tally_conditions():
    from adaptive_c3.models.panda_kinematics import Q_MAX, Q_NULL, TAU_MAX
    from adaptive_c3.systems.franka.arm_unsafe_tally import UnsafeTally
    tally = UnsafeTally(0.03)
    ball = [0.55, 0.0, 0.03]
    s = tally.initial_state()
    for _ in range(20):                                  # 40 ms at the limit: not yet
        s = tally.step(s, 2e-3, Q_NULL, TAU_MAX, ball, 0)
    assert tally.report(s)["unsafe_s"] == 0.0
    for _ in range(10):                                  # 60 ms: 10 ms of it unsafe
        s = tally.step(s, 2e-3, Q_NULL, TAU_MAX, ball, 0)
    assert tally.report(s)["unsafe_s"] == pytest.approx(0.01)
    s = tally.initial_state()
    near = Q_NULL.copy()
    near[3] = Q_MAX[3] - np.radians(1.5)
    s = tally.step(s, 2e-3, near, np.zeros(7), ball, 0)
    s = tally.step(s, 2e-3, Q_NULL, np.zeros(7), [0.55, 0.0, -0.5], 0)
    s = tally.step(s, 2e-3, Q_NULL, np.zeros(7), [2.0, 0.0, 0.03], 1)   # held by the driver
    r = tally.report(s)
    assert r["unsafe_s"] == pytest.approx(0.004) and r["unsafe_total_s"] == pytest.approx(0.006)
    assert r["unsafe_by_reason_s"] == pytest.approx(
        {"torque_at_limit": 0.0, "joint_near_limit": 0.002, "ball_off_table": 0.004})


def test_sim_driver_measures_unsafe_time_of_a_saturating_controller():
    """A controller that pins joint 1 at +87 N m: the driver's summary says how long the
    arm was unsafe under its commands, and when (episodes in the driver's clock)."""
    from adaptive_c3.tools.hardware.sim_driver import unsafe_before
    tau = np.zeros(7)
    tau[0] = 87.0
    pinned = _torques(tau)
    # then the controller stops at 0.3 s: the driver holds once the last command expires
    out, _ = _drive(400, lambda k, utime: pinned(utime) if k <= 300 else None,
                    low_pass_hz=1000.0)
    # the torque reaches its limit after ~90 ms (1000 N m/s), unsafe 50 ms later, until
    # the last command expires at 0.4 s (then the driver's own damping: not counted)
    assert 0.2 < out["unsafe_s"] < 0.3 and out["unsafe_by_reason_s"]["torque_at_limit"] > 0.2
    episodes = out["unsafe_episodes"]
    assert episodes and "torque_at_limit" in episodes[0][3]
    assert unsafe_before(episodes, None) == pytest.approx(out["unsafe_s"], abs=0.011)
    assert unsafe_before(episodes, episodes[0][0]) == 0.0


@pytest.mark.slow
def test_three_os_processes_survive_garbage_on_every_channel():
    """sim-driver + impedance + planner over udpm, 8 s, one undecodable message on each
    of PANDA_STATUS, PANDA_COMMAND, BALL_ESTIMATE and EE_PLAN every 0.5 s: every process
    writes its summary with the counts, and none stops for the garbage (single messages,
    not a run of them)."""
    from adaptive_c3.tools.bench.bridge import run_three_processes
    r = run_three_processes(8.0, inject_garbage_s=0.5)
    p = r["processes"]
    assert r["garbage_sent"] >= 10
    assert sum(p["planner"]["undecodable_messages"].values()) > 0
    assert p["planner"]["safety"]["state"] == "ok" and r["exit_codes"]["planner"] == 0
    assert p["impedance"]["undecodable_messages"] > 0
    assert p["impedance"]["safety"].get("breach") != "malformed_input"
    assert p["sim-driver"]["commands_undecodable"] > 0 and r["exit_codes"]["sim-driver"] == 0


def test_single_process_bridge_counts_a_garbage_status():
    """`hardware` (one process) takes PANDA_STATUS at every message (Drake's
    LcmSubscriberSystem): a garbage status raised `ValueError: Decode error` there."""
    from pydrake.lcm import DrakeLcm
    from pydrake.systems.analysis import Simulator

    from adaptive_c3.tools.hardware.bridge import build_hardware_bridge
    from adaptive_c3.tools.hardware.status_sender import status_message
    s = _scenario()
    lcm = DrakeLcm("memq://")
    b = build_hardware_bridge(s, lcm)
    sim = Simulator(b.diagram)
    sim.Initialize()
    for k in range(1, 30):
        if k in (10, 11, 20):
            lcm.Publish("PANDA_STATUS", GARBAGE)
            lcm.Publish("BALL_ESTIMATE", GARBAGE)
        else:
            lcm.Publish("PANDA_STATUS", status_message(1000 * k, s.impedance.q_null, np.zeros(7),
                                                       np.zeros(7), 2).encode())
        sim.AdvanceTo(k * 1e-3)
    assert b.undecodable() == {"PANDA_STATUS": 3, "BALL_ESTIMATE": 3}
    rep = b.watchdog.report(b.watchdog.GetMyContextFromRoot(sim.get_context()))
    assert rep["counts"]["ok"] > 20 and not rep["latched"]
