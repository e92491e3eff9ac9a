"""Issue 4 item 6: r_comp (violation loss) against an additive dynamics residual r_dyn,
same cart-pole data, same budget (tools/studies/residual_comparison.py)."""
import json

import numpy as np
import pytest

from adaptive_c3.tools.studies.residual_comparison import (
    compare, extend_kicks, first_stays_below, main, _load, DEFAULT_SCENARIO)


def test_first_stays_below():
    ns = [10, 20, 30, 40]
    assert first_stays_below(ns, [5, 1, 3, 1], 2) == 40
    assert first_stays_below(ns, [1, 1, 1, 1], 2) == 10
    assert first_stays_below(ns, [1, 1, 1, 3], 2) is None


def test_extend_kicks_repeats_the_schedule():
    s = _load(DEFAULT_SCENARIO)
    e = extend_kicks(s, 40.0)
    times = [k.at_s for k in e.disturbances]
    assert times == [2.0 * i for i in range(1, 20)]
    signs = [np.sign(k.delta_state[2]) for k in e.disturbances]
    assert all(a == -b for a, b in zip(signs, signs[1:]))  # still alternating
    assert e.sim_duration_s == 40.0 and s.sim_duration_s == 20.0


def test_r_comp_learns_from_data_where_r_dyn_cannot():
    """20 s of data, no closed loops: the measurement machinery and the claim that can fail.
    r_dyn_ls is the best constant r_dyn on the training data, so if it cannot get the
    error down 90 %, no optimiser of r_dyn can."""
    res = compare(eval_every=50, closed_loop_runs=False)
    assert res["error_true_model"] < 1e-12          # noise-free data from the true system
    assert res["error_wrong_model"] > 0.05
    assert res["num_train"] + res["num_holdout"] == 1999 and res["num_holdout"] == 499
    to90 = res["transitions_to_90pct_reduction"]
    assert to90["r_comp"] is not None and to90["r_comp"] <= 600
    assert to90["r_dyn"] is None and to90["r_dyn_ls"] is None
    assert res["final"]["error_comp"] < 0.1 * res["final"]["error_dyn_ls"]
    assert min(res["error_dyn_ls"]) > 0.5 * res["error_wrong_model"]


@pytest.mark.slow
def test_full_comparison_writes_figure_and_json(tmp_path):
    assert main(["--out", str(tmp_path), "--data-duration", "40"]) == 0
    res = json.loads((tmp_path / "comparison.json").read_text())
    assert (tmp_path / "comparison.png").exists()
    to = res["transitions_to_threshold"]
    assert to["r_comp"] is not None and to["r_dyn"] is None and to["r_dyn_ls"] is None
    assert np.all(np.abs(np.array(res["final"]["r_comp"]) - [-0.15, 0.15]) < 0.005)
    cl = res["closed_loop"]
    assert cl["r_comp"]["stabilised"] is True
    assert cl["wrong_model"]["stabilised"] is False
    assert cl["r_dyn"]["stabilised"] is False and cl["r_dyn_ls"]["stabilised"] is False
