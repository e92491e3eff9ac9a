"""The cart-pole with soft walls, as a Drake Diagram built from a scenario.

Recipe: true LCS plant -> (optional) measurement noise -> model LCS source ->
(optional) residual learner -> C3 controller (or LQR) -> back to the plant;
loggers on the state, the input, the wall forces and the learned residual.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from pydrake.common.value import Value
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import (Adder, ConstantValueSource, ConstantVectorSource,
                                        Gain, MatrixGain, RandomSource, TrajectorySource,
                                        LogVectorOutput)
from pydrake.common import RandomDistribution
from pydrake.trajectories import PiecewisePolynomial
from pydrake.systems.controllers import DiscreteTimeLinearQuadraticRegulator

from adaptive_c3.models.cartpole import (CartpoleParams, INPUT_NAMES, LAMBDA_NAMES,
                                         STATE_NAMES, cartpole_lcs)
from adaptive_c3.scenarios.cartpole_schema import CartpoleScenario
from adaptive_c3.systems.contact.lcs import Lcs
from adaptive_c3.systems.contact.lcs_plant import LcsPlant

# Reference C3 settings for the cart-pole (DAIRLab/c3's cart-pole).
CARTPOLE_Q = [10.0, 3.0, 1.0, 1.0]
CARTPOLE_R = [1.0]


@dataclass
class CartpoleDiagram:
    diagram: object
    plant: LcsPlant
    true_lcs: Lcs
    model_lcs: Lcs
    loggers: dict = field(default_factory=dict)   # name -> VectorLogSink
    controller: object = None
    learner: object = None
    state_names: tuple = STATE_NAMES
    input_names: tuple = INPUT_NAMES
    lambda_names: tuple = LAMBDA_NAMES


def cartpole_models(s: CartpoleScenario) -> tuple[Lcs, Lcs]:
    """(true LCS, the controller's model LCS) for the scenario."""
    params = CartpoleParams(wall_stiffness=s.model.wall_stiffness,
                            wall_distance=s.model.wall_distance)
    return cartpole_lcs(params), cartpole_lcs(params, s.model.wall_offset_error)


def cartpole_c3_options(s: CartpoleScenario):
    from adaptive_c3.systems.c3.options import C3Options
    c = s.c3
    return C3Options.from_dict(dict(
        horizon=c.horizon, admm_iter=c.admm_iter, projection=c.projection,
        qp_backend=c.qp_backend, rho_scale=c.rho_scale, warm_start=c.warm_start,
        c3plus_reference=c.c3plus_reference,
        q_diag=c.q_diag or CARTPOLE_Q, r_diag=c.r_diag or CARTPOLE_R,
        g_diag=c.g_diag or [0.1] * 6 + [0.0],
        u_diag=c.u_diag or [1000.0] * 4 + [1.0] * 2 + [0.0]))  # reference cart-pole U


def learner_options(cfg, num_lambda: int):
    from adaptive_c3.systems.learning.violation_loss import LearnerOptions
    return LearnerOptions(epsilon=cfg.epsilon, gamma=cfg.gamma,
                          learning_rate=cfg.learning_rate, batch_size=cfg.batch_size,
                          Qd=list(cfg.qd_diag) or None, max_step=cfg.max_step,
                          lr_decay_steps=cfg.lr_decay_steps)


def _kick_source(s: CartpoleScenario, dt: float):
    """Zero-order-hold trajectory that is delta_state during one plant step at each kick."""
    times, values = [0.0], [np.zeros(4)]
    for kick in sorted(s.disturbances, key=lambda k: k.at_s):
        times += [kick.at_s, kick.at_s + 0.5 * dt]
        values += [np.asarray(kick.delta_state, float), np.zeros(4)]
    times.append(max(times[-1], s.sim_duration_s) + 1.0)
    values.append(np.zeros(4))
    order = np.argsort(times, kind="stable")
    t = np.asarray(times)[order]
    keep = np.concatenate([[True], np.diff(t) > 1e-12])
    v = np.asarray(values)[order][keep].T
    return TrajectorySource(PiecewisePolynomial.ZeroOrderHold(t[keep], v))


def build_cartpole_diagram(s: CartpoleScenario, model_lcs: Lcs | None = None) -> CartpoleDiagram:
    """The diagram of scenario s; model_lcs (optional) replaces the controller's model."""
    true_lcs, scenario_model = cartpole_models(s)
    model_lcs = scenario_model if model_lcs is None else model_lcs
    builder = DiagramBuilder()

    plant = builder.AddNamedSystem("cartpole", LcsPlant(true_lcs, s.initial_state))
    dt = true_lcs.dt
    kicks = None
    if s.disturbances:
        kicks = builder.AddNamedSystem("kicks", _kick_source(s, dt))
        builder.Connect(kicks.get_output_port(), plant.GetInputPort("disturbance"))

    # The state the controller and the learner see (with optional sensor noise).
    measured = plant.GetOutputPort("state")
    if s.measurement_noise:
        noise = builder.AddSystem(RandomSource(RandomDistribution.kGaussian, 4, dt))
        noise.set_name("sensor_noise")
        scale = builder.AddSystem(Gain(np.asarray(s.measurement_noise, float)))
        adder = builder.AddSystem(Adder(2, 4))
        builder.Connect(noise.get_output_port(), scale.get_input_port())
        builder.Connect(measured, adder.get_input_port(0))
        builder.Connect(scale.get_output_port(), adder.get_input_port(1))
        measured = adder.get_output_port()

    model_source = builder.AddNamedSystem("model_lcs", ConstantValueSource(Value[object](model_lcs)))
    model_port = model_source.get_output_port()

    controller = learner = None
    if s.controller == "lqr":
        Q = np.diag(s.c3.q_diag or CARTPOLE_Q)
        R = np.diag(s.c3.r_diag or CARTPOLE_R)
        K, _ = DiscreteTimeLinearQuadraticRegulator(model_lcs.A, model_lcs.B, Q, R)
        controller = builder.AddNamedSystem("lqr", MatrixGain(-K))
        builder.Connect(measured, controller.get_input_port())
        input_port = controller.get_output_port()
    else:
        from adaptive_c3.systems.c3.controller import C3Controller
        if s.learner.enabled:
            from adaptive_c3.systems.learning.residual_learner import ResidualLearner
            learner = builder.AddNamedSystem("residual_learner", ResidualLearner(
                learner_options(s.learner, 2), 4, 1, 2, rate_hz=s.learner.rate_hz,
                input_lag=1))  # C3's input is state set at the plant's step instant
            builder.Connect(measured, learner.GetInputPort("state"))
            builder.Connect(model_port, learner.GetInputPort("lcs"))
            if kicks is not None:  # the injected kicks are known: the plant steps from x + kick
                builder.Connect(kicks.get_output_port(), learner.GetInputPort("disturbance"))
            model_port = learner.GetOutputPort("lcs_with_residual")
        controller = builder.AddNamedSystem("c3_controller", C3Controller(
            cartpole_c3_options(s), 4, 1, 2, rate_hz=s.c3.rate_hz))
        target = builder.AddNamedSystem("target", ConstantVectorSource(np.zeros(4)))
        builder.Connect(measured, controller.GetInputPort("state"))
        builder.Connect(model_port, controller.GetInputPort("lcs"))
        builder.Connect(target.get_output_port(), controller.GetInputPort("target"))
        input_port = controller.GetOutputPort("input")
        if learner is not None:
            builder.Connect(input_port, learner.GetInputPort("input"))
    builder.Connect(input_port, plant.GetInputPort("input"))

    loggers = {
        "x": LogVectorOutput(plant.GetOutputPort("state"), builder, dt),
        "u": LogVectorOutput(input_port, builder, dt),
        "lambda": LogVectorOutput(plant.GetOutputPort("contact_force"), builder, dt),
    }
    if learner is not None:
        loggers["r_comp"] = LogVectorOutput(learner.GetOutputPort("r_comp"), builder, dt)
        loggers["loss"] = LogVectorOutput(learner.GetOutputPort("loss"), builder, dt)
    diagram = builder.Build()
    diagram.set_name("cartpole_softwalls")
    return CartpoleDiagram(diagram=diagram, plant=plant, true_lcs=true_lcs, model_lcs=model_lcs,
                           loggers=loggers, controller=controller, learner=learner)
