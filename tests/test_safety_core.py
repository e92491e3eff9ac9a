"""Issue 31, the 1 kHz side: the impedance loop's safety layer, one fault at a time, on
synthetic status sequences fed to ImpedanceTick (no real time, no LCM).

A breach must end in a SAFE STOP: damping commands -kd v (the driver's kd) for
safety.stop_ramp_s, then no command ever again, one line on stderr naming the breach,
and the report's safety.state = "safe_stop" with the breach's name."""
from __future__ import annotations

import math
import re

import numpy as np
import pytest

from adaptive_c3.models.panda_kinematics import Q_MAX, TAU_MAX
from adaptive_c3.scenarios.schema import load_scenario
from adaptive_c3.tools import cli
from adaptive_c3.tools.hardware.lcm_channels import encode_plan

FAST = ["camera.enabled=false", "model.radius_error=0", "impedance.ee_tilt_deg=0"]   # (q_null: flange down)
NOW = 1_764_000_000_000_000                     # the driver's clock, us
KD = np.array([37.5, 50.0, 37.5, 25.0, 5.0, 3.75, 2.5])
V = np.full(7, 0.1)                             # rad/s: damping is then visibly not zero


def scenario(*sets):
    return load_scenario(cli.resolve_scenario_path("ball_rolling"), FAST + list(sets))[0]


def arm_status(s, utime, q=None, v=V, mode=None):
    from drake import lcmt_panda_status

    from adaptive_c3.tools.hardware.status_sender import status_message
    q = np.asarray(s.impedance.q_null, float) if q is None else q
    return status_message(utime, q, v, np.zeros(7),
                          lcmt_panda_status.kMove if mode is None else mode)


class Rig:
    """An ImpedanceTick fed one tick per ms of loop time: a status (driver clock = loop
    clock), a plan 3 cm beside the q_null tip every 5 ms; everything overridable."""

    def __init__(self, *sets, **tick_settings):
        from adaptive_c3.tools.hardware.impedance_tick import ImpedanceTick
        self.s = scenario(*sets)
        self.tick = ImpedanceTick(self.s, rate_limit=math.inf, **tick_settings)
        x = np.r_[self.tick.law.q_null, np.zeros(7)]
        self.target = np.r_[self.tick.law.tip_state(x)[:3] + [0.03, 0, 0], 0, 0, 0]
        self.k = 0                               # ticks so far (1 ms each)
        self.out = []                            # (k, command or None)

    @property
    def t(self):
        return 1e-3 * self.k

    def run(self, ms, *, status_every=1, plans=True, q=None, v=V, status=None, stall_ms=0):
        """`ms` ticks; status(k) -> a message overrides the synthetic status. stall_ms:
        the loop first sleeps that long (the driver's statuses go on meanwhile)."""
        self.k += stall_ms
        last = None
        for _ in range(ms):
            self.k += 1
            utime = NOW + 1000 * self.k
            if plans and self.k % 5 == 0:
                self.tick.plan.take(encode_plan(utime, self.target, np.zeros(3)))
            msg = None
            if status is not None:
                msg = status(self.k)
            elif status_every and self.k % status_every == 0:
                msg = arm_status(self.s, utime, q=q, v=v)
            last = self.tick.step(self.t, msg)
            self.out.append((self.k, last))
        return last

    def commands(self, since=0):
        return [(k, np.asarray(c.joint_torque)) for k, c in self.out if c is not None and k > since]

    def safety(self):
        return self.tick.report()["safety"]


def assert_safe_stop(rig, name, capsys, breach_by_ms, v=V):
    """From breach_by_ms (ticks) on, only damping -kd v for at most the ramp, then no
    command; the report names the breach; one stderr line names it."""
    ramp_ms = 1e3 * rig.s.safety.stop_ramp_s
    rig.run(int(ramp_ms) + 50, v=v)               # whatever comes now
    damping = np.clip(-KD * v, -TAU_MAX, TAU_MAX)
    for k, tau in rig.commands(since=breach_by_ms):
        assert np.allclose(tau, damping, atol=1e-4), (k, tau)
        assert k < breach_by_ms + ramp_ms
    assert all(c is None for _, c in rig.out[-50:]) and rig.tick.finished
    saf = rig.safety()
    assert saf["state"] == "safe_stop" and saf["breach"] == name, saf
    assert saf["exit_code"] == 3 and 1e3 * saf["breach_t_s"] <= breach_by_ms + 1e-6
    err = capsys.readouterr().err.strip().splitlines()
    assert len([line for line in err if "SAFE STOP" in line]) == 1
    assert name in err[-1]


def test_normal_run_commands_every_tick_without_a_word(capsys):
    rig = Rig()
    rig.run(600)
    cmds = rig.commands()
    assert len(cmds) == 596 and max(abs(c).max() for _, c in cmds[1:]) > 0.1   # (plan at 5 ms)
    saf = rig.safety()
    assert saf["state"] == "active" and saf["breach"] is None
    assert saf["warnings"] == {"status_rate": 0, "plan_rate": 0}
    assert capsys.readouterr().err == ""


def test_driver_killed_statuses_stop(capsys):
    """Old: commands went on, zero torque stamped with the last status utime."""
    rig = Rig()
    rig.run(100)
    rig.run(300, status_every=0, plans=False)
    assert rig.commands(since=152) == []
    assert_safe_stop(rig, "status_stale", capsys, 152)


def test_driver_restarted_old_plan_is_not_resumed(capsys):
    """Old: after 200 ms without statuses the loop resumed at once with the held plan.
    Now the gap is a safe stop, and a restarted impedance loop waits for a plan made
    from the restarted driver's statuses."""
    rig = Rig()
    rig.run(100)
    rig.run(200, status_every=0, plans=False)
    rig.run(100, plans=False)                      # the driver is back, the plan is old
    assert_safe_stop(rig, "status_stale", capsys, 152)   # (damping at most, then nothing)
    # a fresh impedance process: the old plan (age 200 ms) is not enough to start
    fresh = Rig()
    fresh.k = 300
    fresh.tick.plan.take(encode_plan(NOW + 100_000, fresh.target, np.zeros(3)))
    fresh.run(3, plans=False)
    assert fresh.commands() == []
    fresh.run(10)                                   # a plan from a new status: commands
    assert len(fresh.commands()) >= 5


def test_status_at_200_hz_is_a_safe_stop(capsys):
    rig = Rig()
    rig.run(50)
    rig.run(500, status_every=5)
    assert_safe_stop(rig, "status_rate", capsys, 460)        # (two 200 ms windows)
    assert rig.safety()["min_status_rate_hz"] < 500


def test_status_at_800_hz_warns_once_and_goes_on(capsys):
    rig = Rig()
    rig.run(1000, status=lambda k: arm_status(rig.s, NOW + 1000 * k) if k % 5 else None)
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "warning" in err[0] and "800 Hz" in err[0]
    saf = rig.safety()
    assert saf["state"] == "active" and saf["warnings"]["status_rate"] >= 4


def test_plan_rate_below_the_planners_warns(capsys):
    rig = Rig()
    rig.run(10)
    for _ in range(60):                             # a plan every 10 ms: 100 Hz
        rig.run(5, plans=False)
        rig.run(5)
    assert re.search(r"EE_PLAN at 1\d\d Hz", capsys.readouterr().err)
    saf = rig.safety()
    assert saf["state"] == "active" and saf["warnings"]["plan_rate"] >= 2


def test_driver_stall_of_100_ms(capsys):
    rig = Rig()
    rig.run(100)
    rig.run(100, status_every=0, plans=False)
    rig.run(100)
    assert_safe_stop(rig, "status_stale", capsys, 152)


def test_loop_stall_of_100_ms(capsys):
    """The impedance process itself starved for 100 ms: the statuses queued meanwhile
    arrive at once; the loop must not carry on as if nothing happened."""
    rig = Rig()
    rig.run(100)
    rig.run(100, stall_ms=100)
    assert_safe_stop(rig, "loop_stall", capsys, 201)


def test_status_utime_jump_is_a_gap(capsys):
    rig = Rig()
    rig.run(100)
    rig.run(20, status=lambda k: arm_status(rig.s, NOW + 1000 * k + 80_000))
    assert_safe_stop(rig, "status_gap", capsys, 101)


def test_garbage_statuses_are_counted_never_used_and_a_run_stops():
    """Old: a malformed status made a zero-torque command (the watchdog's fault)."""
    from drake import lcmt_panda_status
    rig = Rig()
    rig.run(100)
    bad = lcmt_panda_status()
    bad.utime, bad.num_joints = NOW + 101_000, 3
    bad.joint_position = bad.joint_velocity = [0.0] * 3
    rig.run(1, status=lambda k: bad)
    tau = rig.out[-1][1].joint_torque
    assert max(abs(a) for a in tau) > 0.1           # the last good status, not zero
    nan = arm_status(rig.s, NOW + 102_000, v=np.r_[np.nan, V[1:]])
    rig.run(1, status=lambda k: nan)
    assert max(abs(a) for a in rig.out[-1][1].joint_torque) > 0.1
    rig.run(20)
    assert rig.safety()["malformed"] == {"PANDA_STATUS": 2}
    assert rig.safety()["state"] == "active"
    rig.run(12, status=lambda k: bad)
    saf = rig.safety()
    assert saf["state"] == "safe_stop" and saf["breach"] == "malformed_input"
    assert "10 malformed PANDA_STATUS" in saf["breach_detail"]


def test_unstable_gain_saturates_the_torque(capsys):
    rig = Rig("impedance.translational_stiffness=100000")
    rig.run(200)
    assert_safe_stop(rig, "torque_saturation", capsys, 60)
    assert rig.safety()["max_saturation_ms"] > 50


def test_joint_driven_to_its_limit(capsys):
    rig = Rig("safety.workspace_min=[-2, -2, -2]", "safety.workspace_max=[2, 2, 2]",
              "safety.saturation_s=10")                  # this check alone
    q = np.asarray(rig.s.impedance.q_null, float)
    rig.run(50)
    # joint 4 walks to 1 deg below its upper limit at 0.02 rad per ms

    def walking(k):
        qk = q.copy()
        qk[3] = min(q[3] + 0.02 * (k - 50), Q_MAX[3] - math.radians(1.0))
        return arm_status(rig.s, NOW + 1000 * k, q=qk)
    rig.run(200, status=walking)
    assert_safe_stop(rig, "joint_limit", capsys, 160)
    assert "joint 4" in rig.safety()["breach_detail"]


def test_ee_speed(capsys):
    rig = Rig()
    fast = np.r_[0, 3.0, 0, 0, 0, 0, 0]
    rig.run(20, v=fast)
    assert_safe_stop(rig, "ee_speed", capsys, 6, v=fast)


def test_workspace(capsys):
    rig = Rig("safety.workspace_max=[0.85, 0.4, 0.05]")   # the tip is ~10 cm up
    rig.run(20)
    assert_safe_stop(rig, "workspace", capsys, 6)


def test_plan_that_stops_coming(capsys):
    """Old: held at rest, then zero torque after the plan timeout."""
    rig = Rig()
    rig.run(100)
    rig.run(700, plans=False)
    assert_safe_stop(rig, "plan_stale", capsys, 602)


def test_ball_estimate_that_stops_coming(capsys):
    from adaptive_c3.tools.hardware.lcm_channels import BALL_ESTIMATE_NAMES
    from drake import lcmt_robot_state
    ball = lcmt_robot_state()
    ball.num_joints, ball.joint_name = 6, list(BALL_ESTIMATE_NAMES)
    ball.joint_position = [0.55, 0.1, 0.03, 0, 0, 0]
    rig = Rig()
    rig.run(10)
    for _ in range(20):                             # 80 Hz
        rig.tick.receive_ball(ball)
        rig.run(12)
    assert rig.safety()["state"] == "active"
    rig.run(400)
    assert_safe_stop(rig, "ball_stale", capsys, 10 + 12 * 20 + 250 + 2)


def test_waits_for_status_and_plan_and_sends_nothing_before():
    rig = Rig()
    assert rig.tick.step(0.0, None) is None
    rig.run(4, plans=False)                         # statuses, no plan
    assert rig.commands() == [] and rig.safety()["state"] == "waiting"


def test_requested_stop_damps_then_goes_quiet(capsys):
    rig = Rig()
    rig.run(100)
    rig.tick.request_stop(rig.t, "SIGTERM")
    rig.run(400)
    saf = rig.safety()
    assert saf["state"] == "stopped" and saf["breach"] is None and saf["exit_code"] == 0
    damp = rig.commands(since=100)
    assert 290 <= len(damp) <= 301 and all(np.allclose(tau, -KD * V, atol=1e-4) for _, tau in damp)
    assert rig.tick.finished and "SIGTERM" in capsys.readouterr().err
