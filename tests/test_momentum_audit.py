"""Issue 30: the ball's mass read from the recording's momentum balance, no contact model
(tasks/ball_rolling/momentum_audit.py): the EE's impulses against the ball's angular
momentum about its table contact, with the sensor delay fitted beside the mass."""
import numpy as np
import pytest

from adaptive_c3.tools.diagnosis.harness.concealed_ball_data import Variation, make_recording
from adaptive_c3.tools.diagnosis.harness.concealed_data import Truth
from adaptive_c3.tools.diagnosis.tasks.ball_rolling.effects_ball import ModelParams
from adaptive_c3.tools.diagnosis.tasks.ball_rolling.momentum_audit import (MODEL_FORM,
                                                                          mass_reading)

P = ModelParams()


def _read(rec):
    return mass_reading(rec.x, rec.u, rec.episode, 0.01, ball_mass=P.ball_mass,
                        ee_mass=P.ee_mass, ee_radius=P.ee_radius, ball_radius=P.ball_radius)


@pytest.mark.parametrize("scale, stiffness", [(1.0, 2e5), (0.4, 3e4), (2.5, 1e5)])
def test_noise_free_pushes_read_the_mass_whatever_the_contact(scale, stiffness):
    """The reading needs no stiffness or damping: a light ball on a soft contact and a heavy
    one on a stiff contact read within the reading's model form."""
    truth = Truth("mass_scale", "ball", scale, "1") if scale != 1.0 else Truth("none", "", 0.0, "")
    rec, _ = make_recording(truth, seed=3, episodes=6, noise_scale=0.0,
                            variation=Variation(stiffness=stiffness, relaxation_time=0.002))
    r = _read(rec)
    assert r is not None and r.episodes == 6
    assert abs(r.scale - scale) < MODEL_FORM * scale
    assert abs(r.delay_s) < 1e-3


def test_noisy_delayed_pushes_read_the_mass_and_the_delay():
    """With sensor noise and a 6 ms delay (the recorded state lags the applied force) the
    mass is read within its interval, which tells it from the model's ball, and the delay
    within 1 ms."""
    truth = Truth("mass_scale", "ball", 0.6, "1")
    rec, _ = make_recording(truth, seed=4, episodes=15,
                            variation=Variation(stiffness=5e4, sensor_delay=0.006))
    r = _read(rec)
    lo, hi = r.interval(2.0)
    assert lo < 0.6 < hi < 1.0
    assert abs(r.delay_s - 0.006) < 1e-3


def test_a_recording_without_contact_reads_nothing():
    rec, _ = make_recording(Truth("none", "", 0.0, ""), seed=5, episodes=6, noise_scale=0.0)
    far = rec.x.copy()
    far[:, 2] += 0.5                       # the EE half a metre above the ball throughout
    assert mass_reading(far, rec.u, rec.episode, 0.01, P.ball_mass, P.ee_mass, P.ee_radius,
                        P.ball_radius) is None
