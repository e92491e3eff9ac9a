"""Issue 31, the 1 kHz side as a process: ImpedanceProcess.run over memq:// on a fake
clock (garbage on its channels, silence, SIGINT / SIGTERM), and `adaptive-c3 impedance`
as an OS process over udpm (exit codes, the summary on stdout)."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from adaptive_c3.tools.hardware.lcm_channels import encode_plan
from tests.test_safety_core import KD, NOW, V, arm_status, scenario


class FakeDriver:
    """handle() for ImpedanceProcess.run: each call is 1 ms of the fake clock, with a
    status (utime = NOW + 1 ms per call) and every 5th call a plan 3 cm beside the tip;
    extra(calls, lcm) publishes more; junk = (channel, calls): garbage instead of that
    channel's messages on those calls (on every call for EE_PLAN)."""

    def __init__(self, s, lcm, *, statuses=10**9, extra=None, junk=("", ())):
        from drake import lcmt_panda_command

        from adaptive_c3.tools.hardware.impedance_tick import ImpedanceTick
        tick = ImpedanceTick(s)
        x = np.r_[tick.law.q_null, np.zeros(7)]
        self.target = np.r_[tick.law.tip_state(x)[:3] + [0.03, 0, 0], 0, 0, 0]
        self.s, self.lcm, self.statuses, self.extra, self.junk = s, lcm, statuses, extra, junk
        self.t, self.calls = 0.0, 0
        self.commands = []                         # (call, command)
        lcm.Subscribe("PANDA_COMMAND",
                      lambda d: self.commands.append((self.calls, lcmt_panda_command.decode(d))))

    def clock(self):
        return self.t

    def handle(self):
        self.calls += 1
        self.t += 1e-3
        utime = NOW + 1000 * self.calls
        channel, calls = self.junk
        if self.calls in calls:
            self.lcm.Publish(channel, b"\x01junk")
        if self.calls <= self.statuses:
            if not (channel == "PANDA_STATUS" and self.calls in calls):
                self.lcm.Publish("PANDA_STATUS", arm_status(self.s, utime).encode())
            if self.calls % 5 == 0 and not (channel == "EE_PLAN" and self.calls in calls):
                self.lcm.Publish("EE_PLAN", encode_plan(utime, self.target, np.zeros(3)).encode())
        if self.extra:
            self.extra(self.calls, self.lcm)
        self.lcm.HandleSubscriptions(0)


def run(duration, **driver):
    from pydrake.lcm import DrakeLcm

    from adaptive_c3.tools.hardware.impedance_process import ImpedanceProcess
    s = scenario()
    lcm = DrakeLcm("memq://")
    proc = ImpedanceProcess(s, lcm)
    drv = FakeDriver(s, lcm, **driver)
    return proc.run(duration, clock=drv.clock, handle=drv.handle), drv


def torque(cmd):
    return np.asarray(cmd.joint_torque)


def test_ticks_per_status_then_silence_is_a_safe_stop_without_zero_torque(capsys):
    """Old: after the stale limit the loop sent zero torque every ms (an undamped arm on
    a real Panda) and its summary said nothing of it."""
    r, drv = run(2.0, statuses=200,
                 extra=lambda k, lcm: k == 201 and lcm.Publish("PANDA_STATUS", b"not a status"))
    assert drv.commands and all(c.utime <= NOW + 200_000 for _, c in drv.commands)
    assert all(np.abs(torque(c)).max() > 0.1 for _, c in drv.commands[5:])   # never zero
    # (idle ticks repeat the last status's command until the stale limit, then nothing)
    assert [k for k, _ in drv.commands][-1] <= 251
    # (the first status ends the wait for it and shares the first tick with the second)
    assert r["status_ticks"] == 199 and r["undecodable_messages"] == 1
    assert r["tick_period_ms"]["p50"] == pytest.approx(1.0)
    saf = r["safety"]
    assert saf["state"] == "safe_stop" and saf["breach"] == "status_stale", saf
    assert saf["malformed"] == {"PANDA_STATUS": 1} and saf["exit_code"] == 3
    assert "SAFE STOP" in capsys.readouterr().err


def test_statuses_that_end_with_the_run_are_its_end_not_a_fault(capsys):
    """A simulated driver given the same --duration stops publishing about when the
    impedance run ends: within END_GRACE_S (1 s) of the end that is no safe stop."""
    r, drv = run(2.0, statuses=1500)
    saf = r["safety"]
    assert saf["state"] == "stopped" and saf["stop_reason"] == "driver_ended", saf
    assert saf["exit_code"] == 0 and "SAFE STOP" not in capsys.readouterr().err


def test_garbage_on_every_channel_is_counted_and_the_run_goes_on():
    def garbage(k, lcm):
        if k in (100, 300):
            for ch in ("PANDA_STATUS", "EE_PLAN", "BALL_ESTIMATE"):
                lcm.Publish(ch, b"\x00garbage")
        if k == 200:                              # decodes, but not in the plan's layout
            bad = encode_plan(NOW + 1000 * k + 1, np.zeros(6), np.zeros(3))
            bad.joint_name = ["x"] * 9
            lcm.Publish("EE_PLAN", bad.encode())
    r, drv = run(0.5, extra=garbage)
    saf = r["safety"]
    assert saf["state"] == "stopped" and saf["stop_reason"] == "end of the run", saf
    assert saf["malformed"] == {"PANDA_STATUS": 2, "EE_PLAN": 3, "BALL_ESTIMATE": 2}
    assert r["undecodable_messages"] == 6 and r["plans_ignored"] == 1
    assert len(drv.commands) > 450


@pytest.mark.parametrize("channel", ["PANDA_STATUS", "EE_PLAN"])
def test_a_run_of_garbage_is_a_safe_stop(channel, capsys):
    """Garbage instead of the channel's messages for 20 ms: 10 in a row stop the run."""
    r, drv = run(1.0, junk=(channel, range(100, 120)))
    assert r["wall_s"] < 0.5 and max(k for k, _ in drv.commands) < 0.5e3   # stopped early (fake clock: 1 ms a call)
    saf = r["safety"]
    assert saf["breach"] == "malformed_input" and f"10 malformed {channel}" in saf["breach_detail"]
    assert saf["breach_t_s"] < 0.115
    assert f"malformed {channel}" in capsys.readouterr().err


def test_half_garbage_over_a_window_is_a_safe_stop():
    """Garbage as often as good plans (not 10 in a row): the rate rule."""
    r, drv = run(1.0, extra=lambda k, lcm: k >= 100 and k % 5 == 1 and lcm.Publish("EE_PLAN", b"x"))
    assert r["wall_s"] < 0.8                        # stopped early
    saf = r["safety"]
    assert saf["breach"] == "malformed_input" and "EE_PLAN messages malformed" in saf["breach_detail"]


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_signal_damps_then_writes_the_summary(sig):
    """Old: SIGTERM ended the process without its summary; SIGINT stopped commanding at
    once (the last impedance torque stood until the driver expired it)."""
    def send(k, _lcm):
        if k == 200:
            os.kill(os.getpid(), sig)
    r, drv = run(None, extra=send)
    after = [torque(c) for k, c in drv.commands if k > 200]
    assert after and all(np.allclose(tau, -KD * V, atol=1e-4) for tau in after)
    saf = r["safety"]
    assert r["signal"] == sig.name and saf["state"] == "stopped" and saf["stop_reason"] == sig.name
    assert saf["exit_code"] == 0 and saf["damping_commands"] > 250
    assert signal.getsignal(sig) is not None       # the handlers were put back


def _publish_until(lcm, s, proc, stop, t_max=25.0):
    """Statuses at ~1 kHz and plans every 5th over `lcm` until stop() or the process
    ends; returns the commands seen."""
    from drake import lcmt_panda_command

    from adaptive_c3.tools.hardware.impedance_tick import ImpedanceTick
    law = ImpedanceTick(s).law
    tip = law.tip_state(np.r_[law.q_null, np.zeros(7)])
    target = np.r_[tip[:3] + [0.03, 0, 0], 0, 0, 0]
    seen = []
    lcm.Subscribe("PANDA_COMMAND", lambda d: seen.append(lcmt_panda_command.decode(d)))
    k, end = 0, time.monotonic() + t_max
    while proc.poll() is None and time.monotonic() < end and not stop(seen):
        k += 1
        utime = int(time.time() * 1e6)
        lcm.Publish("PANDA_STATUS", arm_status(s, utime).encode())
        if k % 5 == 0:
            lcm.Publish("EE_PLAN", encode_plan(utime, target, np.zeros(3)).encode())
        lcm.HandleSubscriptions(1)
    return seen


# timing limits a loaded machine cannot break (this test is about the exit paths)
LOOSE = [f"--set=safety.{kv}" for kv in ("status_gap_s=3", "status_min_rate_hz=0",
                                          "status_warn_rate_hz=0", "plan_warn_rate_hz=0",
                                          "plan_max_age_s=3")]


@pytest.mark.parametrize("end", ["SIGTERM", "driver_killed"])
def test_impedance_command_exit_codes(end):
    """`adaptive-c3 impedance` over udpm: SIGTERM -> damping, the summary, exit 0; the
    driver's statuses stop -> a safe stop, one stderr line, the summary, exit 3."""
    from adaptive_c3.tools.hardware.lcm_channels import open_lcm
    from adaptive_c3.tools.process_tuning import frozen_heap
    url = f"udpm://239.255.76.67:{7700 + os.getpid() % 200}?ttl=0"
    lcm = open_lcm(url)
    s = scenario()
    proc = subprocess.Popen(
        [sys.executable, "-m", "adaptive_c3.tools.cli", "impedance", "ball_rolling",
         "--lcm-url", url, "--rt-priority", "0", "--wait-s", "30", "--duration", "60",
         "--set", "impedance.ee_tilt_deg=0", "--stale-ms", "3000", *LOOSE],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    # (a full garbage collection of this test process stops the fake driver for 50-100
    # ms: a status gap the impedance process rightly stops on)
    with frozen_heap():
        return _run_impedance_command(end, lcm, s, proc)


def _run_impedance_command(end, lcm, s, proc):
    try:
        seen = _publish_until(lcm, s, proc, lambda seen: len(seen) > 50)
        assert len(seen) > 50, proc.stderr.read() if proc.poll() is not None else ""
        if end == "SIGTERM":
            proc.send_signal(signal.SIGTERM)
            _publish_until(lcm, s, proc, lambda _: False, t_max=10.0)
        out, err = proc.communicate(timeout=10)
    finally:
        if proc.poll() is None:
            proc.kill()
    summary = json.loads(out.strip().splitlines()[-1])
    saf = summary["safety"]
    if end == "SIGTERM":
        assert proc.returncode == 0 and saf["stop_reason"] == "SIGTERM", saf
        assert saf["damping_commands"] > 0
    else:
        assert proc.returncode == 3 and saf["breach"] == "status_stale"
        assert [line for line in err.splitlines() if "SAFE STOP" in line]


def test_unstable_gain_in_closed_loop_with_the_simulated_driver(capsys):
    """Lock-step with the simulated driver (memq://): a stiffness of 1e5 N/m pins the
    torques at their limits within ~0.1 s. Old: the loop kept commanding them (the
    driver applied a torque at its limit for the rest of the run). Now: a safe stop;
    the driver then applies no torque at its limit for more than 50 ms."""
    from adaptive_c3.models.panda_kinematics import TAU_MAX
    from adaptive_c3.tools.hardware.split_loopback import run_split_loopback
    s = scenario("impedance.translational_stiffness=100000", "impedance.ee_tilt_deg=15")
    out = run_split_loopback(s, 0.6)
    h = out["_"]
    tau = h["driver"].logs["tau"].FindLog(h["sims"][0].get_context()).data().T   # every 10 ms
    at_limit = (np.abs(tau) >= 0.99 * TAU_MAX).any(axis=1)
    longest = run = 0
    for hit in at_limit:
        run = run + 1 if hit else 0
        longest = max(longest, run)
    assert longest <= 5, longest                   # at most 50 ms in a row
    saf = out["safety"]
    assert saf["state"] == "safe_stop" and saf["breach"] == "torque_saturation", saf
    assert out["driver"]["commands_received"] <= 1e3 * saf["breach_t_s"] + 300 + 1
    assert "torque_saturation" in capsys.readouterr().err
