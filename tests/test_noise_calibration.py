"""The sensor noise the reported errors are measured in (engine/locate.py calibrate_noise).

The one-step estimate reads low where the model smooths its start positions (the ball):
a perfect model's rollouts then show an "excess over noise" that is only noise. On Drake's
plant of the ball (the backend that opts in) the calibrated estimate must recover the noise
the recording was made with; a model whose one-step map passes noise on (the cart-pole)
keeps what the one-step estimate said.
"""
import numpy as np
import pytest

from adaptive_c3.scenarios.schema import SCENARIO_DIR, load_scenario
from adaptive_c3.tools.diagnosis.backends.effects import cartpole_spec, patch
from adaptive_c3.tools.diagnosis.engine.locate import calibrate_noise, estimate_noise, make_windows
from adaptive_c3.tools.diagnosis.harness import concealed_ball_data as ball_data
from adaptive_c3.tools.diagnosis.harness import concealed_data as cartpole_data
from adaptive_c3.tools.diagnosis.tasks.ball_rolling.drake_ball import drake_ball_spec
from adaptive_c3.tools.diagnosis.tasks.ball_rolling.effects_ball import (POS, ModelParams,
                                                                         smooth_positions)


@pytest.fixture(scope="module")
def ball():
    scenario, _ = load_scenario(SCENARIO_DIR / "ball_rolling.yaml")
    rec, _, _ = ball_data.concealed_draw(8003, name="none", target="", vary=False, episodes=6,
                                         noise_scale=1.0,
                                         params=ModelParams.from_scenario(scenario))
    spec = drake_ball_spec(scenario)
    spec.prepare(rec)
    yield spec, rec
    spec.close()


def test_drake_ball_positions_read_low_one_step_and_right_calibrated(ball):
    spec, rec = ball
    assert spec.calibrated_noise          # the backend opts in
    P = patch(spec, [])
    sigma = estimate_noise(P, make_windows(rec, 1))
    true = ball_data.NOISE_STD
    # the smoothed start positions hide part of the position noise from the one-step residual
    assert np.all(sigma[POS] < 0.8 * true[POS])
    cal = calibrate_noise(spec, rec, P, sigma)
    scored = spec.fit_weight > 0
    np.testing.assert_allclose(cal[POS], true[POS], rtol=0.2)
    assert abs(np.median(cal[scored] / true[scored]) - 1.0) < 0.15
    # the spec's cache is back on the recording itself (the calibration re-prepares it)
    np.testing.assert_array_equal(spec.cache["psmooth"], smooth_positions(rec, spec.dt))


def test_cartpole_noise_is_left_where_the_one_step_estimate_put_it():
    spec = cartpole_spec(load_scenario(SCENARIO_DIR / "cartpole_softwalls.yaml")[0])
    rec, _ = cartpole_data.make_recording(cartpole_data.Truth("none", "", 0.0, ""), seed=3,
                                          episodes=3, noise_scale=1.0)
    P = patch(spec, [])
    sigma = estimate_noise(P, make_windows(rec, 1))
    cal = calibrate_noise(spec, rec, P, sigma)
    np.testing.assert_allclose(cal, sigma, rtol=0.15)
    np.testing.assert_allclose(cal, cartpole_data.NOISE_STD, rtol=0.25)
