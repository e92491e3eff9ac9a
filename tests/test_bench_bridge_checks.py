"""`bench bridge`'s own checks (issue 31, items 4 and 5) without running the processes:
the validity of a run, the overload rows, and the machine reference in every bench JSON."""
from __future__ import annotations

import json

import pytest

from adaptive_c3.scenarios.schema import load_scenario
from adaptive_c3.tools import cli
from adaptive_c3.tools.bench.bridge_overload import overload_rows, safe_stop, validity


def _run(**over):
    r = {"status_rate_hz": 998.0, "plan_rate_hz": 200.0, "duration_s": 90.0,
         "overload": 2, "realtime": False, "circle_turns": 0.4,
         "command_period_ms": {"p50": 1.0, "p99": 3.0, "max": 9.0},
         "planner_latency_ms": {"p50": 2.7, "p99": 12.0},
         "status_to_command_ms": {"p50": 0.4, "p99": 1.5},
         "exit_codes": {"planner": 0, "impedance": 0, "sim-driver": 0},
         "read_at": {"impedance": 1000.0},
         "processes": {"sim-driver": {"scheduling": "SCHED_FIFO 80", "unsafe_s": 0.5,
                                      "unsafe_total_s": 0.5,
                                      "unsafe_episodes": [[990.0, 990.2, 0.2, ["joint_near_limit"]],
                                                          [995.0, 995.3, 0.3, ["ball_off_table"]]]},
                       "impedance": {"scheduling": "SCHED_FIFO 70", "wall_s": 20.0,
                                     "safety": {"state": "ok", "min_status_rate_hz": 995.0,
                                                 "min_plan_rate_hz": 195.0,
                                                 "warnings": {"status_rate": 0, "plan_rate": 0},
                                                 "max_plan_age_ms": 6.0}},
                       "planner": {}}}
    r.update(over)
    return r


def _safety():
    s, _ = load_scenario(cli.resolve_scenario_path("ball_rolling"), ["camera.enabled=false"])
    return s.safety


def test_validity_names_each_broken_timing_assumption():
    assert validity(_run(), _safety()) == []
    r = _run(status_rate_hz=420.0, plan_rate_hz=44.0)
    r["processes"]["impedance"]["scheduling"] = "SCHED_OTHER (not requested)"
    reasons = validity(r, _safety())
    assert len(reasons) == 3
    assert "420 Hz" in reasons[0] and "impedance" in reasons[1] and "EE_PLAN at 44" in reasons[2]


def test_validity_uses_the_impedance_loops_own_windows_and_the_planner_latency():
    # the no-overload run of 2026-11-26 08:53 (runs/bridge/three_processes.json): the whole
    # run's averages held (status 1000 Hz, EE_PLAN 200 Hz, SCHED_FIFO) and it was marked
    # valid, but the loop's own 200 ms windows fell to 604 Hz status and 0 plans, a plan
    # was 259 ms old when used, and it safe-stopped at 4.9 s
    r = _run()
    r["processes"]["impedance"]["safety"] = {
        "state": "safe_stop", "min_status_rate_hz": 603.7, "min_plan_rate_hz": 0.0,
        "warnings": {"status_rate": 12, "plan_rate": 22}, "max_plan_age_ms": 258.9}
    reasons = validity(r, _safety())
    assert len(reasons) == 3
    assert "604 Hz" in reasons[0] and "12 status_rate warnings" in reasons[0]
    assert "EE_PLAN down to 0 Hz" in reasons[1] and "22 plan_rate" in reasons[1]
    assert "259 ms old" in reasons[2]
    # warnings alone (a window just under the rate between the minima's updates) count
    r["processes"]["impedance"]["safety"] = {**_run()["processes"]["impedance"]["safety"],
                                             "warnings": {"status_rate": 1, "plan_rate": 0}}
    assert ["1 status_rate warnings" in x for x in validity(r, _safety())] == [True]
    # the planner latency p99 beyond what the controller was shown to tolerate
    from adaptive_c3.tools.bench.bridge_overload import PLANNER_LATENCY_P99_MAX_MS
    r = _run(planner_latency_ms={"p50": 3.0, "p99": PLANNER_LATENCY_P99_MAX_MS + 30})
    assert ["planner latency p99" in x for x in validity(r, _safety())] == [True]
    # status -> command p99 beyond the wrist's delay margin (that run's was 6.1 ms)
    r = _run(status_to_command_ms={"p50": 0.5, "p99": 6.1})
    assert ["status -> command p99 6.1 ms" in x for x in validity(r, _safety())] == [True]
    # a safe stop on the machine's timing (09:43 run: the driver's start-up stall) is
    # named; one on the arm's state is the run's outcome, not its validity
    r = _run()
    r["processes"]["impedance"]["safety"] = {
        "state": "safe_stop", "breach": "status_stale", "min_status_rate_hz": None,
        "breach_detail": "no PANDA_STATUS for 50.1 ms (limit 50 ms)"}
    assert validity(r, _safety()) == ["impedance loop safe-stopped on timing: status_stale: "
                                      "no PANDA_STATUS for 50.1 ms (limit 50 ms)"]
    r["processes"]["impedance"]["safety"].update(breach="torque_saturation")
    assert validity(r, _safety()) == []
    # no summary from the loop (it crashed): not a valid run
    r = _run()
    del r["processes"]["impedance"]["safety"]
    assert validity(r, _safety()) == ["the impedance loop wrote no safety summary"]


def test_overload_rows_count_unsafe_time_only_before_the_safe_stop():
    rows = overload_rows(_run(), [])
    assert [r["name"] for r in rows] == ["bridge/overload/unsafe_s", "bridge/overload/outcome"]
    assert rows[0]["value"] == pytest.approx(0.5) and rows[1]["value"] == "rolled"
    r = _run()
    # the loop breached at its t = 12 s and wrote its summary at t = 20 s, read at 1000
    # (wall clock): the stop began at 992, after the first episode, before the second
    r["processes"]["impedance"]["safety"] = {"state": "safe_stop", "breach": "status_gap",
                                             "breach_detail": "two statuses 131 ms apart",
                                             "breach_t_s": 12.0}
    assert safe_stop(r) == ("status_gap: two statuses 131 ms apart", pytest.approx(992.0))
    rows = overload_rows(r, [{"name": "bridge/circles_90s", "median_ms": 1.0, "value": 0.0}])
    assert rows[0]["value"] == pytest.approx(0.2)
    assert rows[1]["value"] == "safe_stop" and "status_gap" in rows[1]["reason"]
    assert rows[2]["name"] == "bridge/overload/circles_90s"
    r["processes"]["impedance"]["start_epoch_s"] = 983.0        # its own wall clock at t = 0
    assert safe_stop(r)[1] == pytest.approx(995.0)
    assert overload_rows(r, [])[0]["value"] == pytest.approx(0.2)   # the second episode after
    assert all("value" in row for row in rows)


def test_every_bench_json_has_the_machine_reference(tmp_path, capsys):
    from adaptive_c3.tools.bench.runner import run_suites
    run_suites({}, json_path=tmp_path / "b.json")
    rows = json.loads((tmp_path / "b.json").read_text())["results"]
    names = [r["name"] for r in rows]
    assert names == ["machine/python", "machine/drake"]
    assert all(r["median_ms"] > 0 for r in rows)


def test_overload_is_for_bench_bridge_only(capsys):
    assert cli.main(["bench", "lcp", "--overload", "2"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--overload" in err[0]
