"""The true world of the ball-rolling experiment, from a scenario: what the plant holds
and where things start. Shared by the simulation's plant and the camera's twin of it.
"""
from __future__ import annotations

import dataclasses as dc
import math

import numpy as np

from adaptive_c3.models.ball_rolling_controller_model import default_state
from adaptive_c3.models.ball_rolling_scene import (EE_TIP_FRAME, add_ball_rolling_scene,
                                                   add_point_ee, partner_friction,
                                                   set_body_friction)
from adaptive_c3.scenarios.ball_rolling_schema import BallRollingScenario
from adaptive_c3.systems.rolling.gait import CirclePath, GaitSettings, RollingGait


def true_radius(s: BallRollingScenario) -> float:
    return s.model.ball_radius - s.model.radius_error


def true_mass(s: BallRollingScenario) -> float:
    """The simulated ball's mass, kg (the model's times model.true_mass_scale)."""
    return s.model.ball_mass * s.model.true_mass_scale


def ball_start_xy(s: BallRollingScenario) -> np.ndarray:
    """Start on the circle at ball_start_angle_deg (from +x about the centre, CCW)."""
    a = math.radians(s.ball_start_angle_deg)
    c, r = s.target.center, s.target.radius
    return np.array([c[0] + r * math.cos(a), c[1] + r * math.sin(a)])


def make_gait(s: BallRollingScenario) -> RollingGait:
    g = s.gait
    # the schema's Gait carries every GaitSettings field (plus C3's return weight)
    settings = GaitSettings(**{f.name: getattr(g, f.name) for f in dc.fields(GaitSettings)})
    path = CirclePath(tuple(s.target.center), s.target.radius, s.target.lead_deg)
    return RollingGait(settings, path, ball_radius=s.model.ball_radius,
                       ee_radius=s.model.ee_radius)


def start_states(s: BallRollingScenario):
    """(x_start, ee_start): the controller model's start state (19) and the EE's start
    position (3, m in W), where the gait's settle phase puts it."""
    m = s.model
    x_start = default_state(tuple(ball_start_xy(s)), ball_radius=m.ball_radius,
                            ee_radius=m.ee_radius)
    return x_start, make_gait(s).ee_target("settle", x_start)


def true_world(s: BallRollingScenario):
    """A function plant -> (BallRollingScene, point-EE instance or None) that adds the
    true world's bodies and geometry to a plant: the TRUE ball radius, mass and friction, a
    lumpy fruit drawn from the seed for a fruit object, the Panda or a point EE. The
    same scenario gives the same world every time (the camera's twin relies on it)."""
    m = s.model
    fruit = None
    if m.object != "ball":   # a lumpy fruit drawn from the seed; the prior stays a sphere
        from adaptive_c3.models.fruit import sample_fruit
        fruit = sample_fruit(m.object, s.seed)
    start_xy = ball_start_xy(s)
    _, ee_start = start_states(s)

    def add(plant):
        scene = add_ball_rolling_scene(plant, ball_radius=true_radius(s), ball_mass=true_mass(s),
                                       ball_position=tuple(start_xy), mu=m.true_friction,
                                       with_arm=(s.robot == "panda"), fruit=fruit)
        ee = None
        if s.robot == "point_ee":
            ee = add_point_ee(plant, radius=m.ee_radius, mass=s.point_ee_mass,
                              position=ee_start, mu=m.true_friction)
        return scene, ee
    return add


def apply_true_ee_friction(plant, scene_graph, s: BallRollingScenario, panda=None,
                           ee_instance=None) -> None:
    """Gives the truth's EE-ball pair the friction model.true_ee_friction (when >= 0) by
    setting the EE tip's geometry friction; the ball and table keep true_friction, so the
    ball-table pair is unchanged. Call after Finalize, before a context is created."""
    m = s.model
    if m.true_ee_friction < 0:
        return
    if panda is not None:
        tip = plant.GetBodyByName(EE_TIP_FRAME, panda)
    else:
        tip = plant.GetBodyByName(plant.GetModelInstanceName(ee_instance), ee_instance)
    set_body_friction(plant, scene_graph, tip,
                      partner_friction(m.true_ee_friction, m.true_friction))
