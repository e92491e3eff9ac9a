"""The simulated driver keeps drake-franka-driver's torque-mode rules (issue 17, item 2),
and the bridge stamps its commands in the driver's clock (the regression behind it)."""
from __future__ import annotations

import numpy as np
import pytest

from adaptive_c3.systems.franka.franka_driver_rules import (CONTROL_MODE_TORQUE, DAMPING,
                                                            EXPIRED, MAX_TORQUE_RATE, NQ,
                                                            RECEIVED, TAU, DriverContractError,
                                                            DriverRules, initial_state,
                                                            lowpass_gain)

NOW = 1_764_000_000_000_000          # microseconds since the epoch (late 2025)


def command(utime, tau=None, mode=CONTROL_MODE_TORQUE, nq=0, nv=0, nt=NQ):
    from drake import lcmt_panda_command
    m = lcmt_panda_command()
    m.utime = int(utime)
    m.control_mode_expected = mode
    m.num_joint_position, m.num_joint_velocity, m.num_joint_torque = nq, nv, nt
    m.joint_position = [0.0] * nq
    m.joint_velocity = [0.0] * nv
    m.joint_torque = list(np.full(nt, 2.0) if tau is None else tau)
    return m


def run(rules, msgs, v=None, start=NOW):
    """Tick once per message (1 ms apart); returns the states."""
    v = np.zeros(NQ) if v is None else v
    s, out = initial_state(), []
    for k, msg in enumerate(msgs):
        s = rules.tick(s, msg, start + 1000 * k, v)
        out.append(s)
    return out


def test_torque_mode_constant_is_drakes():
    from drake import lcmt_panda_status
    assert CONTROL_MODE_TORQUE == lcmt_panda_status.CONTROL_MODE_TORQUE


def test_a_command_stamped_with_diagram_time_is_expired():
    """PandaCommandSender's stamp (diagram time: 5 s -> 5e6 us) is decades from the
    driver's clock: the driver drops it and holds the arm with damping only."""
    v = np.linspace(-1, 1, NQ)
    rules = DriverRules(expire_sec=0.1, low_pass_hz=1000.0)
    s = run(rules, [command(5_000_000)], v)[-1]
    assert s[EXPIRED] == 1 and s[RECEIVED] == 1
    assert np.allclose(s[TAU], np.clip(-DAMPING * v, -1.0, 1.0))     # rate-limited damping


def test_fresh_command_is_low_passed_rate_limited_and_reused_until_it_expires():
    rules = DriverRules(expire_sec=0.1, low_pass_hz=30.0)
    msg = command(NOW, tau=np.full(NQ, 0.5))
    states = run(rules, [msg] * 150)
    g = lowpass_gain(30.0)
    assert states[0][TAU] == pytest.approx(np.full(NQ, g * 0.5))     # first-order filter
    assert states[98][EXPIRED] == 0 and states[98][TAU][0] > 0.45    # used for 100 ms
    assert states[-1][EXPIRED] == 1                                  # then dropped ...
    assert states[-1][TAU][0] < states[98][TAU][0]                   # ... and damped to 0
    big = run(DriverRules(low_pass_hz=1000.0), [command(NOW, tau=np.full(NQ, 50.0))] * 3)
    assert [s[TAU][0] for s in big] == pytest.approx([1.0, 2.0, 3.0])   # 1000 N m/s
    assert MAX_TORQUE_RATE == 1000.0


def test_an_expired_command_stays_dropped_and_a_new_one_is_used():
    rules = DriverRules(expire_sec=0.1, low_pass_hz=1000.0)
    old = command(NOW - 200_000, tau=np.full(NQ, 0.5))
    new = command(NOW + 3000, tau=np.full(NQ, 0.5))
    states = run(rules, [old, old, old, new])
    assert states[2][EXPIRED] == 1 and np.allclose(states[2][TAU], 0.0)
    assert states[3][TAU][0] == pytest.approx(0.5) and states[3][RECEIVED] == 2


@pytest.mark.parametrize("msg, words", [
    (lambda: command(NOW, mode=1), "control mode 1"),
    (lambda: command(NOW, nq=NQ), "num_joint_position=7"),
    (lambda: command(NOW, nt=6), "num_joint_torque=6"),
    (lambda: command(NOW, tau=[np.nan] * NQ), "non-finite"),
])
def test_a_command_the_driver_throws_on_stops_it(msg, words):
    with pytest.raises(DriverContractError, match=words):
        run(DriverRules(), [msg()])


def test_torque_command_sender_stamps_the_latest_status_utime():
    from drake import lcmt_panda_status
    from pydrake.common.value import AbstractValue

    from adaptive_c3.tools.hardware.torque_command_sender import TorqueCommandSender
    sender = TorqueCommandSender()
    ctx = sender.CreateDefaultContext()
    status = lcmt_panda_status()
    status.utime = NOW
    sender.GetInputPort("panda.torque_command").FixValue(ctx, np.arange(NQ, dtype=float))
    sender.GetInputPort("lcmt_panda_status").FixValue(ctx, AbstractValue.Make(status))
    msg = sender.get_output_port().Eval(ctx)
    assert msg.utime == NOW and list(msg.joint_torque) == list(range(NQ))
    DriverRules.check_contract(msg)                   # the driver accepts it


def test_sim_driver_stops_on_a_wrong_mode_command():
    """The whole simulated driver (plant, LCM) raises the driver's error and stops."""
    from pydrake.lcm import DrakeLcm
    from pydrake.systems.analysis import Simulator

    from adaptive_c3.scenarios.schema import SCENARIO_DIR, load_scenario
    from adaptive_c3.tools.hardware.driver_clock import SimEpochClock
    from adaptive_c3.tools.hardware.sim_driver import build_sim_driver
    s, _ = load_scenario(SCENARIO_DIR / "ball_rolling.yaml", ["camera.enabled=false"])
    lcm = DrakeLcm("memq://")
    clock = SimEpochClock(NOW)
    drv = build_sim_driver(s, lcm, clock=clock)
    sim = Simulator(drv.diagram)
    sim.Initialize()
    sim.AdvanceTo(0.01)
    lcm.Publish("PANDA_COMMAND", command(clock(0.01), mode=2).encode())
    lcm.HandleSubscriptions(0)
    with pytest.raises(DriverContractError, match="control mode 2"):
        sim.AdvanceTo(0.02)
