"""C3Controller LeafSystem (systems/c3/controller.py) in Drake diagrams."""
import numpy as np
import pytest
from pydrake.common.value import AbstractValue
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import (ConstantValueSource, ConstantVectorSource,
                                        LogVectorOutput)

from adaptive_c3.models.cartpole import cartpole_lcs
from adaptive_c3.systems.c3.options import cartpole_c3_options
from adaptive_c3.systems.c3.solver import C3Solution
from adaptive_c3.systems.c3.controller import C3Controller
from adaptive_c3.systems.contact.lcs import LcsSequence
from adaptive_c3.systems.contact.lcs_plant import LcsPlant


def _diagram(x0, lcs_value, rate_hz=80.0, target=None):
    lcs = cartpole_lcs()
    b = DiagramBuilder()
    plant = b.AddSystem(LcsPlant(lcs, x0))
    plant.force_log = LogVectorOutput(plant.GetOutputPort("contact_force"), b, lcs.dt)
    ctrl = b.AddSystem(C3Controller(cartpole_c3_options(), 4, 1, 2, rate_hz=rate_hz))
    src = b.AddSystem(ConstantValueSource(AbstractValue.Make(lcs_value)))
    b.Connect(plant.get_output_port(0), ctrl.GetInputPort("state"))
    b.Connect(src.get_output_port(0), ctrl.GetInputPort("lcs"))
    b.Connect(ctrl.GetOutputPort("input"), plant.get_input_port(0))
    if target is not None:
        tgt = b.AddSystem(ConstantVectorSource(np.asarray(target, float)))
        b.Connect(tgt.get_output_port(0), ctrl.GetInputPort("target"))
    return b.Build(), plant, ctrl


@pytest.mark.parametrize("x0", [[0.1, -0.3, 0.0, 0.0], [0.3, 0.0, 0.3, 0.0]])
def test_controller_stabilises_cartpole_in_a_diagram(x0):
    diagram, plant, ctrl = _diagram(x0, cartpole_lcs())
    sim = Simulator(diagram)
    sim.AdvanceTo(8.0)
    ctx = sim.get_context()
    x = plant.get_output_port(0).Eval(plant.GetMyContextFromRoot(ctx))
    assert np.abs(x).max() < 0.05
    forces = plant.force_log.FindLog(ctx).data()
    assert forces.max() > 0.0                    # it used the contacts
    stats = ctrl.solve_time_stats()
    assert stats["count"] == 8 * 80              # t = 0, 1/80, ..., 8 - 1/80 s
    assert 0 < stats["median_s"] <= stats["max_s"]
    plan = ctrl.GetOutputPort("plan").Eval(ctrl.GetMyContextFromRoot(ctx))
    assert isinstance(plan, C3Solution) and plan.x_plan.shape == (11, 4)
    assert ctrl.rejected == 0


def test_controller_holds_input_between_solves_and_accepts_sequences():
    lcs = cartpole_lcs()
    diagram, plant, ctrl = _diagram([0.1, -0.3, 0, 0], LcsSequence.constant(lcs, 10),
                                    rate_hz=20.0)
    sim = Simulator(diagram)
    ctx = sim.get_context()
    cctx = ctrl.GetMyContextFromRoot(ctx)
    sim.AdvanceTo(0.001)
    u_first = ctrl.GetOutputPort("input").Eval(cctx).copy()
    assert np.abs(u_first).max() > 0             # solved at t = 0
    sim.AdvanceTo(0.049)                         # the plant moved, no new solve yet
    np.testing.assert_array_equal(ctrl.GetOutputPort("input").Eval(cctx), u_first)
    sim.AdvanceTo(0.051)
    assert not np.array_equal(ctrl.GetOutputPort("input").Eval(cctx), u_first)
    stats = ctrl.solve_time_stats()
    assert stats["count"] == 2


def _standalone(rate_hz=100.0):
    ctrl = C3Controller(cartpole_c3_options(), 4, 1, 2, rate_hz=rate_hz)
    ctx = ctrl.CreateDefaultContext()
    ctrl.GetInputPort("lcs").FixValue(ctx, AbstractValue.Make(cartpole_lcs()))
    ctrl.GetInputPort("target").FixValue(ctx, np.zeros(4))
    return ctrl, ctx


@pytest.mark.parametrize("bad", ["state_nan", "target_inf", "lcs_none", "lcs_wrong_size"])
def test_garbage_inputs_give_zero_input_and_keep_the_plan(bad):
    ctrl, ctx = _standalone()
    ctrl.GetInputPort("state").FixValue(ctx, np.array([0.1, -0.3, 0.0, 0.0]))
    sim = Simulator(ctrl, ctx)
    sim.AdvanceTo(0.005)
    good_plan = ctrl.GetOutputPort("plan").Eval(ctx)
    assert isinstance(good_plan, C3Solution) and np.abs(good_plan.u0).max() > 0
    np.testing.assert_allclose(ctrl.GetOutputPort("input").Eval(ctx), good_plan.u0)
    if bad == "state_nan":
        ctrl.GetInputPort("state").FixValue(ctx, np.array([np.nan, 0, 0, 0]))
    elif bad == "target_inf":
        ctrl.GetInputPort("target").FixValue(ctx, np.array([np.inf, 0, 0, 0]))
    elif bad == "lcs_none":
        ctrl.GetInputPort("lcs").FixValue(ctx, AbstractValue.Make(None))
    else:
        from adaptive_c3.tools.bench.c3 import random_ballroll_lcs
        ctrl.GetInputPort("lcs").FixValue(ctx, AbstractValue.Make(random_ballroll_lcs(0)))
    sim.AdvanceTo(0.015)                                      # one more replan
    np.testing.assert_array_equal(ctrl.GetOutputPort("input").Eval(ctx), [0.0])
    assert ctrl.GetOutputPort("plan").Eval(ctx) is not None
    np.testing.assert_array_equal(ctrl.GetOutputPort("plan").Eval(ctx).u0, good_plan.u0)
    assert ctrl.rejected == 1


def test_no_plan_before_first_solve_and_bad_construction():
    ctrl, ctx = _standalone()
    assert ctrl.GetOutputPort("plan").Eval(ctx) is None
    np.testing.assert_array_equal(ctrl.GetOutputPort("input").Eval(ctx), [0.0])
    assert ctrl.solve_time_stats()["count"] == 0
    with pytest.raises(ValueError):
        C3Controller(cartpole_c3_options(), 5, 1, 2)
    with pytest.raises(ValueError):
        C3Controller(cartpole_c3_options(), 4, 1, 2, rate_hz=0.0)
    with pytest.raises(ValueError):
        C3Controller(cartpole_c3_options(), 4, 1, 0)
