"""What a new user trips on first: scenario files without a task, how a run ends
(Meshcat's Stop, Ctrl-C), the messages and labels the tools print."""
import json

import numpy as np
import pytest

from adaptive_c3.scenarios.schema import SCENARIO_DIR
from adaptive_c3.tools.cli import main

CARTPOLE = str(SCENARIO_DIR / "cartpole_softwalls.yaml")


@pytest.mark.parametrize("text,needle", [
    ("", "empty"),
    ("# only a comment\n", "empty"),
    ("name: mine\nsim_duration_s: 1.0\n", "no 'task:'"),
])
def test_scenario_without_a_task_is_exit_2_with_one_line(text, needle, tmp_path, capsys):
    path = tmp_path / "s.yaml"
    path.write_text(text)
    assert main(["run", str(path), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and needle in err, err
    assert not (tmp_path / "out" / "summary.json").exists()


def test_task_may_come_from_an_included_file(tmp_path):
    from adaptive_c3.scenarios.schema import load_scenario
    child = tmp_path / "child.yaml"
    child.write_text(f"include: {CARTPOLE}\nname: child\n")
    assert load_scenario(child)[0].task == "cartpole"
