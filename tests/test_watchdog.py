"""The Panda watchdog: stale / malformed status, limits, latched stop, logging."""
import math

import numpy as np
import pytest

from adaptive_c3.systems.franka.panda_watchdog import (FAULT_CODES, PandaWatchdog, StatusSample,
                                                WatchdogConfig, WatchdogCore)

Q = np.array([0.0, 0.36, 0.0, -2.2, 0.0, 2.58, 0.0])


def status(utime, q=Q, v=np.zeros(7), n=7):
    return StatusSample(utime, n, np.asarray(q, float), np.asarray(v, float))


def run(core, s, times, statuses, taus):
    return [core.step(s, t, st, tau).copy() for t, st, tau in zip(times, statuses, taus)]


def test_ok_then_stale_within_limit():
    core = WatchdogCore(WatchdogConfig(stale_s=0.05, rate_limit=math.inf))
    s = core.new_state()
    tau = np.full(7, 1.0)
    core.step(s, 0.0, None, tau)
    assert s.mode == "waiting" and not s.first_fault
    for k in range(1, 11):            # fresh status every ms
        out = core.step(s, k * 1e-3, status(k * 1000), tau)
    assert s.mode == "ok" and np.allclose(out, tau)
    last_rx = 10e-3
    # the status stops: still OK up to 50 ms, zero just after
    t = last_rx
    while True:
        t += 1e-3
        out = core.step(s, t, status(10 * 1000), tau)
        if s.mode != "ok":
            break
    assert s.mode == "stale" and np.all(out == 0)
    assert 0.05 < t - last_rx <= 0.05 + 1.001e-3
    assert s.first_fault.startswith("stale") and s.counts["stale"] == 1
    # status resumes: the command ramps back (rate limit off here: at once)
    out = core.step(s, t + 1e-3, status(99_000), tau)
    assert s.mode == "ok" and np.allclose(out, tau)


def test_message_time_mode():
    core = WatchdogCore(WatchdogConfig(stale_s=0.05, use_message_time=True))
    s = core.new_state()
    core.step(s, 1.0, status(int(0.90e6)), np.zeros(7))   # 100 ms old on arrival
    assert s.mode == "stale"
    core.step(s, 1.001, status(int(0.99e6)), np.zeros(7))
    assert s.mode == "ok"


def test_torque_and_rate_limits():
    core = WatchdogCore(WatchdogConfig(rate_limit=1000.0))
    s = core.new_state()
    big = np.array([200.0, -200.0, 50.0, 0.0, 30.0, -30.0, 1.0])
    outs = run(core, s, [k * 1e-3 for k in range(400)], [status(k + 1) for k in range(400)],
               [big] * 400)
    outs = np.array(outs)
    steps = np.abs(np.diff(outs, axis=0))
    assert np.all(steps <= 1.0 + 1e-9)          # 1000 N m/s at 1 ms
    lim = np.array([87, 87, 87, 87, 12, 12, 12.0])
    assert np.allclose(outs[-1], np.clip(big, -lim, lim))
    assert s.counts["clipped"] > 0 and s.counts["rate_limited"] > 0


def test_malformed_status_and_request_hold_zero_without_latching():
    core = WatchdogCore(WatchdogConfig(rate_limit=math.inf))
    s = core.new_state()
    out = core.step(s, 0.0, status(1, q=np.zeros(6), n=6), np.ones(7))
    assert s.mode == "malformed" and np.all(out == 0) and not s.latched
    out = core.step(s, 0.001, status(2), np.ones(5))
    assert s.mode == "malformed" and np.all(out == 0)
    out = core.step(s, 0.002, status(3), np.ones(7))
    assert s.mode == "ok" and np.allclose(out, 1.0)
    assert s.first_fault.startswith("malformed: status with 6 joints")


@pytest.mark.parametrize("where", ["q", "v", "tau"])
def test_nonfinite_latches(where, caplog):
    core = WatchdogCore(WatchdogConfig(rate_limit=math.inf))
    s = core.new_state()
    core.step(s, 0.0, status(1), np.ones(7))
    bad_q = np.r_[Q[:6], np.nan] if where == "q" else Q
    bad_v = np.r_[np.zeros(6), np.inf] if where == "v" else np.zeros(7)
    bad_tau = np.r_[np.ones(6), np.nan] if where == "tau" else np.ones(7)
    with caplog.at_level("WARNING", logger="adaptive_c3.watchdog"):
        out = core.step(s, 0.001, status(2, bad_q, bad_v), bad_tau)
    assert s.latched and s.mode == "nonfinite" and np.all(out == 0)
    assert any("nonfinite" in r.message for r in caplog.records)
    for k in range(3, 10):             # good data afterwards: still stopped
        out = core.step(s, k * 1e-3, status(k), np.ones(7))
        assert np.all(out == 0) and s.mode == "nonfinite"


def test_bad_config():
    with pytest.raises(ValueError):
        WatchdogConfig(stale_s=0)
    with pytest.raises(ValueError):
        WatchdogConfig(torque_limits=(1.0,) * 6)


def test_leaf_system_in_a_diagram():
    from drake import lcmt_panda_status
    from pydrake.common.value import AbstractValue
    wd = PandaWatchdog(WatchdogConfig(stale_s=0.05, rate_limit=math.inf), period=1e-3)
    ctx = wd.CreateDefaultContext()
    msg = lcmt_panda_status()
    msg.utime, msg.num_joints = 1000, 7
    msg.joint_position, msg.joint_velocity = list(Q), [0.0] * 7
    wd.get_input_port(0).FixValue(ctx, AbstractValue.Make(msg))
    wd.get_input_port(1).FixValue(ctx, np.full(7, 2.0))
    from pydrake.systems.analysis import Simulator
    sim = Simulator(wd, ctx)
    sim.AdvanceTo(0.02)
    assert np.allclose(wd.GetOutputPort("panda.torque_command").Eval(ctx), 2.0)
    assert wd.GetOutputPort("watchdog.fault").Eval(ctx)[0] == FAULT_CODES["ok"]
    sim.AdvanceTo(0.1)                 # the same message, 100 ms later: stale
    assert np.all(wd.GetOutputPort("panda.torque_command").Eval(ctx) == 0)
    rep = wd.report(ctx)
    assert rep["mode"] == "stale" and rep["first_fault_t"] == pytest.approx(0.051, abs=1.5e-3)


def test_lagging_controller_holds_zero():
    core = WatchdogCore(WatchdogConfig(rate_limit=math.inf, max_lag_s=0.1))
    s = core.new_state()
    core.step(s, 0.0, status(1), np.ones(7), lag_s=0.0)
    assert s.mode == "ok"
    out = core.step(s, 0.001, status(2), np.ones(7), lag_s=0.2)
    assert s.mode == "lagging" and np.all(out == 0) and not s.latched
    out = core.step(s, 0.002, status(3), np.ones(7), lag_s=0.05)
    assert s.mode == "ok" and np.allclose(out, 1.0)
