"""Schema of the cart-pole scenarios (the paper's soft-wall cart-pole).

Registered with the scenario loader under `task: cartpole`.
"""
import dataclasses as dc
import math
from typing import List

from adaptive_c3.scenarios.common import (C3Config, LearnerConfig, ScenarioError,
                                          _validate_common, register_task)


@dc.dataclass
class Disturbance:
    """A velocity kick added to the state at time `at_s` (units of the state)."""
    at_s: float = 0.0
    delta_state: List[float] = dc.field(default_factory=list)


@dc.dataclass
class CartpoleModel:
    wall_stiffness: float = 50.0        # ks, N/m
    wall_distance: float = 0.35         # true wall offsets, m
    wall_offset_error: List[float] = dc.field(default_factory=lambda: [0.0, 0.0])  # delta_phi, m


@dc.dataclass
class CartpoleScenario:
    task: str = "cartpole"
    name: str = "cartpole"
    controller: str = "c3"              # c3 | lqr
    model: CartpoleModel = dc.field(default_factory=CartpoleModel)
    c3: C3Config = dc.field(default_factory=C3Config)
    learner: LearnerConfig = dc.field(default_factory=LearnerConfig)
    initial_state: List[float] = dc.field(default_factory=lambda: [0.1, -0.3, 0.0, 0.0])
    disturbances: List[Disturbance] = dc.field(default_factory=list)
    measurement_noise: List[float] = dc.field(default_factory=list)  # std per state
    sim_duration_s: float = 8.0
    stabilise_tolerance: float = 0.05   # |x|_inf below this counts as stabilised
    seed: int = 0


def validate_cartpole(s: CartpoleScenario) -> None:
    _validate_common(s)
    if s.controller not in ("c3", "lqr"):
        raise ScenarioError(f"controller must be c3 or lqr, got '{s.controller}'")
    if len(s.initial_state) != 4:
        raise ScenarioError(f"initial_state must have 4 entries for the cart-pole, got {len(s.initial_state)}")
    m = s.model
    if not (m.wall_stiffness > 0 and math.isfinite(m.wall_stiffness)):
        raise ScenarioError(f"model.wall_stiffness must be > 0, got {m.wall_stiffness}")
    if not (m.wall_distance > 0 and math.isfinite(m.wall_distance)):
        raise ScenarioError(f"model.wall_distance must be > 0, got {m.wall_distance}")
    if len(m.wall_offset_error) != 2:
        raise ScenarioError("model.wall_offset_error must have 2 entries (left, right wall)")
    for d in s.disturbances:
        if len(d.delta_state) != 4:
            raise ScenarioError("disturbances[].delta_state must have 4 entries")
    if s.measurement_noise and len(s.measurement_noise) != 4:
        raise ScenarioError("measurement_noise must be empty or have 4 entries")


register_task("cartpole", CartpoleScenario, validate_cartpole)
