"""The paper's Fig. 4 on the cart-pole: adaptive C3 learns delta_phi and stabilises.

Fast: the shipped scenario end to end (one 20 s closed loop takes ~3 s) and its
adaptation-off twin. Slow: the same scenario at neighbouring learning rates and kick
sizes (the robustness the README states).
"""
import copy
import json
from pathlib import Path

import numpy as np
import pytest

from adaptive_c3.scenarios.schema import load_scenario
from adaptive_c3.tools.run import run_scenario
from adaptive_c3.tools.run_cartpole import simulate_cartpole, time_to_stabilise

SCENARIO = Path(__file__).resolve().parents[1] / "scenarios" / "cartpole_adaptive.yaml"
DPHI = np.array([-0.15, 0.15])


def test_adaptive_scenario_converges_and_stabilises(tmp_path):
    summary, out = run_scenario(SCENARIO, tmp_path / "run")
    on_disk = json.loads((out / "summary.json").read_text())
    assert on_disk["stabilised"] is True
    r = np.asarray(on_disk["residual_final"])
    assert np.all(np.abs(r - DPHI) <= 0.01), r
    assert min(on_disk["wall_contact_steps"].values()) > 0  # both walls were touched
    assert (out / "states.png").exists()


def test_adaptation_off_fails_on_the_same_scenario(tmp_path):
    on, _ = run_scenario(SCENARIO, tmp_path / "on")
    off, _ = run_scenario(SCENARIO, tmp_path / "off", ["learner.enabled=false"])
    assert off["stabilised"] is False and "residual_final" not in off
    # the model's left wall is 0.15 m too close: C3 keeps pushing into it
    assert off["wall_contact_steps"]["left_wall"] > 3 * on["wall_contact_steps"]["left_wall"]
    assert off["closed_loop_cost"] > 5 * on["closed_loop_cost"]


def test_learner_pairs_the_applied_input_with_each_transition():
    """With the learner's input timing right, every non-kick transition of the closed
    loop has zero loss gradient at r = delta_phi (no bias toward contact)."""
    from adaptive_c3.diagrams.cartpole import cartpole_models
    from adaptive_c3.systems.learning.violation_loss import violation_loss
    s, _ = load_scenario(SCENARIO, ["sim_duration_s=6.0"])
    handles, logs, _ = simulate_cartpole(s, progress_label=None)
    _, x = logs["x"]
    _, u = logs["u"]
    _, model = cartpole_models(s)
    kicks = {int(round(k.at_s / model.dt)) for k in s.disturbances}
    grads = [violation_loss(x[k + 1], x[k], u[k + 1], model, DPHI, 100.0, 1e-2)[1]
             for k in range(len(x) - 1) if k not in kicks]
    assert np.abs(grads).max() < 1e-12
    # the input one step early (the old pairing) would bias the residual
    bad = [violation_loss(x[k + 1], x[k], u[k], model, DPHI, 100.0, 1e-2)[1]
           for k in range(len(x) - 1) if k not in kicks]
    assert np.abs(bad).max() > 1e-3


def _run(lr, kick):
    s, _ = load_scenario(SCENARIO, [f"learner.learning_rate={lr}"])
    s = copy.deepcopy(s)
    for k in s.disturbances:
        k.delta_state = [0.0, 0.0, float(np.sign(k.delta_state[2]) * kick), 0.0]
    handles, logs, _ = simulate_cartpole(s, progress_label=None)
    t, x = logs["x"]
    _, r = logs["r_comp"]
    return r[-1], time_to_stabilise(t, x, s.stabilise_tolerance)


@pytest.mark.slow
@pytest.mark.parametrize("lr", [0.002, 0.003, 0.005])
@pytest.mark.parametrize("kick", [0.8, 1.0])
def test_robust_to_learning_rate_and_kick_size(lr, kick):
    r, t_stab = _run(lr, kick)
    assert t_stab is not None
    assert np.all(np.abs(r - DPHI) <= 0.01), r
