"""The ball model's error floor on the other engine's clean data (ball_floor.py)."""
import json

from adaptive_c3.tools.diagnosis.harness.ball_floor import WORST, floor_of_draw, main


def test_the_floor_sits_in_contact_changes_of_the_push():
    """On a clean draw the rigid 100 Hz model's 10-step mismatch is carried by a few
    windows of the pushes that start or end an EE-ball contact (touch-downs, lift-offs,
    the ball rolling back into the EE), not spread evenly: the reason an effect fit
    leaves an excess over noise of about 1 (README, issue 19)."""
    r = floor_of_draw(200, episodes=4)
    assert r["windows"] > 400 and r["mean"] > 0.0
    assert r["by_phase"]["push"]["share_of_mismatch"] > 0.6
    assert r["worst_share"] > 6 * WORST            # the worst 5 % carry > 30 %
    assert r["worst_with_contact_change"] > 2 * r["windows_with_contact_change"]


def test_cli_writes_json_and_figure(tmp_path):
    assert main(["1", "201", "--out", str(tmp_path)]) == 0
    data = json.loads((tmp_path / "ball_floor.json").read_text())
    assert data["summary"]["draws"] == 1 and len(data["rows"]) == 1
    assert (tmp_path / "ball_floor.png").stat().st_size > 0
