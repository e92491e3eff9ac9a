"""The `adaptive-c3` command line.

Every user mistake (bad scenario, bad recording, bad flag) ends with one line
on stderr and exit code 2; anything else is a bug and shows its traceback.
"""
from __future__ import annotations

import argparse
import importlib
import json
import sys

from adaptive_c3.tools.user_input import UserError, resolve_scenario_path

USER_ERROR = 2

BENCH_SUITES = {   # suite -> module exposing run_bench(quick) -> list of rows
    "lcp": "adaptive_c3.tools.bench.lcp",
    "c3": "adaptive_c3.tools.bench.c3",
    "learner": "adaptive_c3.tools.bench.learner",
    "lcs": "adaptive_c3.tools.bench.lcs",
    "loop": "adaptive_c3.tools.bench.loop",
    "sweep": "adaptive_c3.tools.bench.sweep",
    "bridge": "adaptive_c3.tools.bench.bridge",
    "diagnose": "adaptive_c3.tools.bench.diagnose",
}


def _user_error_types():
    from adaptive_c3.scenarios.schema import ScenarioError
    from adaptive_c3.tools.recording import RecordingError
    from adaptive_c3.systems.contact.lcs import LcsError
    from adaptive_c3.tools.sweep import SweepError
    return (UserError, ScenarioError, RecordingError, LcsError, SweepError)


def _scenario_help() -> str:
    from adaptive_c3.scenarios.schema import SCENARIO_DIR, shipped_scenarios
    names = shipped_scenarios()
    return ("shipped scenarios (in " + str(SCENARIO_DIR) + "): " + ", ".join(names)) if names else ""


def cmd_run(args) -> int:
    from adaptive_c3.tools.run import run_scenario
    overrides = list(args.set or [])
    if args.seed is not None:
        overrides.append(f"seed={args.seed}")
    summary, out = run_scenario(resolve_scenario_path(args.scenario), args.out, overrides,
                                meshcat=args.meshcat, meshcat_port=args.meshcat_port)
    print(json.dumps({k: summary[k] for k in summary if k in
                      ("scenario", "stabilised", "laps", "residual_final", "real_time_factor")},
                     default=float))
    print(f"results in {out}: summary.json, log.npz, " + ", ".join(summary.get("plots", [])))
    if "wall_s" in summary and "sim_duration_s" in summary:
        wall = float(summary["wall_s"])
        print(f"wall time {int(wall // 60)}m{wall % 60:04.1f}s for {summary['sim_duration_s']:g} s "
              f"simulated: real-time factor {summary['sim_duration_s'] / wall:.2f}")
    if summary.get("interrupted"):
        print(f"adaptive-c3 run: interrupted at t = {summary['sim_duration_s']:.2f} s; "
              f"partial results in {out}", file=sys.stderr)
        return 130
    return 0


def cmd_bench(args) -> int:
    from adaptive_c3.tools.bench.runner import run_suites
    suites = list(BENCH_SUITES) if args.suite == "all" else [args.suite]
    if args.overload is not None and args.suite != "bridge":
        raise UserError("--overload is for `bench bridge` only")
    run_suites({s: BENCH_SUITES[s] for s in suites}, json_path=args.json, quick=args.quick,
               options={"overload": args.overload})
    return 0


def _delegate(module: str, func: str):
    def run(args):
        try:
            mod = importlib.import_module(module)
        except ModuleNotFoundError as e:
            if e.name and e.name.startswith("adaptive_c3"):
                raise UserError(f"this command is not available in this build ({e.name} missing)")
            raise
        return getattr(mod, func)(args)
    return run


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="adaptive-c3",
        description="Adaptive contact-implicit MPC (C3) with online residual learning, on Drake.")
    sub = p.add_subparsers(dest="command", required=True)

    run = sub.add_parser("run", help="simulate a scenario headless (or in Meshcat)",
                         description="Simulate a scenario and write summary.json, log.npz and plots. "
                         + _scenario_help())
    run.add_argument("scenario", help="scenario YAML (a path, or the name of a shipped one)")
    run.add_argument("--out", default=None, help="output folder (default runs/<scenario>-<time>)")
    run.add_argument("--set", action="append", metavar="KEY.PATH=VALUE",
                     help="override a scenario key; the value is parsed as YAML (repeatable)")
    run.add_argument("--meshcat", action="store_true",
                     help="interactive, in real time, in Meshcat on localhost: sliders for the "
                     "model error, learning rate and target, buttons Adaptation on/off, Restart, "
                     "Stop (ball_rolling)")
    run.add_argument("--meshcat-port", type=int, default=None, metavar="PORT",
                     help="Meshcat's port on localhost (implies --meshcat; default: the first "
                     "free port from 7000)")
    run.add_argument("--seed", type=int, default=None, help="random seed (overrides the scenario's)")
    run.set_defaults(func=cmd_run)

    sweep = sub.add_parser("sweep", help="run a sweep of trials")
    sweep.add_argument("sweep_file")
    sweep.add_argument("--workers", type=int, default=1)
    sweep.add_argument("--out", default=None)
    sweep.add_argument("--set", action="append", metavar="KEY.PATH=VALUE")
    sweep.add_argument("--cluster", default=None, help="address of a running distributed scheduler")
    sweep.set_defaults(func=_delegate("adaptive_c3.tools.sweep", "cmd_sweep"))

    bench = sub.add_parser("bench", help="benchmarks, as ratios against baselines measured in the same run")
    bench.add_argument("suite", nargs="?", default="all", choices=["all", *BENCH_SUITES])
    bench.add_argument("--json", default=None, help="write the results to this JSON file")
    bench.add_argument("--quick", action="store_true", help="fewer repeats (a smoke test)")
    bench.add_argument("--overload", type=int, default=None, metavar="N",
                       help="bridge: run the three processes without real-time priority and "
                       "with N busy processes beside them; rows bridge/overload/unsafe_s and "
                       "bridge/overload/outcome")
    bench.set_defaults(func=cmd_bench)

    diag = sub.add_parser("diagnose", help="find where a recording and the model disagree")
    diag.add_argument("recording")
    diag.add_argument("--scenario", required=True)
    diag.add_argument("--also", action="append", default=[], metavar="RECORDING",
                      help="more recordings of the same rig (e.g. made with the excitation a "
                      "report proposed), diagnosed together with RECORDING as more episodes")
    diag.add_argument("--out", default=None)
    diag.add_argument("--baseline", choices=["drake"], default=None,
                      help="rigid_object: also Drake's SAP simulation on the held-out episodes, "
                      "as it is and tuned on the fit episodes")
    diag.add_argument("--held-out", type=float, default=0.3,
                      help="rigid_object: fraction of episodes held out (default 0.3)")
    diag.add_argument("--fit-episodes", type=int, default=None,
                      help="rigid_object: at most this many episodes to fit on (default 30; "
                      "60 with --model drake)")
    diag.add_argument("--workers", type=int, default=2,
                      help="rigid_object, and ball_rolling with --model drake: processes (default 2)")
    diag.add_argument("--effects", default=None,
                      help="rigid_object: comma-separated effects to try (default: the whole library)")
    diag.add_argument("--model", default="lcs", metavar="lcs|drake",
                      help="rigid_object and ball_rolling: the model diagnosed - lcs, the "
                      "controller's Anitescu LCS (default), or drake, Drake's SAP plant of the "
                      "scenario's true world (ball_rolling: its drake: section)")
    diag.add_argument("--initial-state", default="ballistic", metavar="ballistic|first-row",
                      help="rigid_object: rollout starts - a fit of each episode's free-flight "
                      "prefix (default) or its recorded first row")
    diag.set_defaults(func=_delegate("adaptive_c3.tools.diagnosis.diagnose", "cmd_diagnose"))

    ev = sub.add_parser("evaluate", help="open-loop rollouts of a scenario's model against a recording",
                        description="Rolls the scenario's model out from every episode's first state "
                        "and reports position (% of the object's size) and orientation (deg) errors; "
                        "writes evaluate.json and evaluate.png.")
    ev.add_argument("recording")
    ev.add_argument("--scenario", required=True)
    ev.add_argument("--out", default=None, help="output folder (default runs/evaluate)")
    ev.add_argument("--model", default="lcs", metavar="lcs|drake",
                    help="the model rolled out: lcs, the controller's Anitescu LCS (default), or "
                    "drake, Drake's SAP plant of the scenario's true world")
    ev.add_argument("--baseline", default=None, metavar="drake|lcs",
                    help="also roll out this backend from the same starts")
    ev.add_argument("--initial-state", default="ballistic", metavar="ballistic|first-row",
                    help="rollout starts: a fit of each episode's free-flight prefix (default) "
                    "or its recorded first row")
    ev.add_argument("--workers", type=int, default=2, help="processes for the rollouts (default 2)")
    ev.add_argument("--episodes", default=None, help="episode ids, e.g. 0-99,120 (default: all)")
    ev.add_argument("--set", action="append", metavar="KEY.PATH=VALUE", help="override a scenario key")
    ev.set_defaults(func=_delegate("adaptive_c3.tools.diagnosis.evaluate", "cmd_evaluate"))

    hw = sub.add_parser(
        "hardware", help="LCM bridge to a real Franka driver",
        description="The controller side over LCM: subscribes PANDA_STATUS (lcmt_panda_status) "
        "and BALL_ESTIMATE (lcmt_robot_state: ball_x, ball_y, ball_z, ball_vx, ball_vy, ball_vz), "
        "publishes PANDA_COMMAND (lcmt_panda_command, torque without gravity) through a watchdog.")
    hw.add_argument("scenario", help="ball_rolling scenario YAML (a path or a shipped name)")
    hw.add_argument("--lcm-url", default=None,
                    help="LCM URL, e.g. udpm://239.255.76.67:7667?ttl=0 (required unless --loopback)")
    hw.add_argument("--duration", type=float, default=None, help="stop after S seconds (default: until Ctrl-C)")
    hw.add_argument("--stale-ms", type=float, default=50.0, help="watchdog: status older than this -> zero torque")
    hw.add_argument("--log", default=None, help="write all LCM traffic to this LCM log file")
    hw.add_argument("--max-lag-ms", type=float, default=100.0,
                    help="watchdog: zero torque while the controller runs more than this behind real time")
    hw.add_argument("--period", type=float, default=1e-3, help="command (and watchdog) period, s")
    hw.add_argument("--rt-priority", type=int, default=70,
                    help="--split: SCHED_FIFO priority of the impedance loop (0: ordinary)")
    hw.add_argument("--set", action="append", metavar="KEY.PATH=VALUE", help="override a scenario key")
    hw.add_argument("--loopback", action="store_true",
                    help="run the bridge and the simulated driver in one process over memq://, "
                    "in lock-step (a self-test; --duration defaults to the scenario's)")
    hw.add_argument("--split", action="store_true",
                    help="run the 1 kHz impedance loop and the planner as two processes "
                    "(`impedance` + `planner`); with --loopback: the three parts in lock-step")
    hw.set_defaults(func=_delegate("adaptive_c3.tools.hardware.bridge", "cmd_hardware"))

    def controller_process(name, help_text, func):
        cp = sub.add_parser(name, help=help_text, description=help_text)
        cp.add_argument("scenario", help="ball_rolling scenario YAML (a path or a shipped name)")
        cp.add_argument("--lcm-url", required=True, help="LCM URL, e.g. udpm://239.255.76.67:7667?ttl=0")
        cp.add_argument("--duration", type=float, default=None, help="stop after S seconds")
        cp.add_argument("--wait-s", type=float, default=10.0,
                        help="give up (exit 2) if the robot's first messages take longer")
        cp.add_argument("--set", action="append", metavar="KEY.PATH=VALUE", help="override a scenario key")
        cp.set_defaults(func=_delegate("adaptive_c3.tools.hardware.process_commands", func))
        return cp
    imp = controller_process(
        "impedance", "the 1 kHz loop alone: PANDA_STATUS + EE_PLAN -> PANDA_COMMAND (torque mode, "
        "stamped with the status utime), watchdog, plan hold/timeout, robot_mode gate", "cmd_impedance")
    imp.add_argument("--stale-ms", type=float, default=50.0,
                     help="no new status for this long -> safe stop (the scenario's "
                          "safety.status_gap_s where that is smaller)")
    imp.add_argument("--period", type=float, default=1e-3,
                     help="tick, s: one per PANDA_STATUS, or per period of silence")
    imp.add_argument("--rt-priority", type=int, default=70,
                     help="SCHED_FIFO priority of the loop (0: ordinary scheduling)")
    pl = controller_process("planner", "estimator, Anitescu LCS, residual learner and C3: "
                            "PANDA_STATUS + BALL_ESTIMATE -> EE_PLAN (drake.lcmt_robot_state: EE "
                            "target, velocity, feed-forward force)", "cmd_planner")
    pl.add_argument("--nice", type=int, default=0,
                    help="nice value (e.g. -10: ahead of ordinary work on the machine, still "
                         "behind the SCHED_FIFO driver and impedance loop)")
    pl.add_argument("--stale-ms", type=float, default=100.0,
                    help="no new PANDA_STATUS for this long: stop planning and wait for the "
                    "robot's first messages again")
    pl.add_argument("--delay-ms", type=float, default=0.0,
                    help="hold every plan back this long before sending it (an injected latency)")

    sd = sub.add_parser("sim-driver", help="the simulated robot + ball speaking only LCM (for `hardware`)",
                        description="Runs the true plant (Panda, table, ball; SAP) in real time and "
                        "speaks only LCM: publishes PANDA_STATUS and BALL_ESTIMATE, obeys PANDA_COMMAND.")
    sd.add_argument("scenario")
    sd.add_argument("--lcm-url", required=True)
    sd.add_argument("--duration", type=float, default=None, help="seconds (default: the scenario's)")
    sd.add_argument("--status-period", type=float, default=1e-3, help="PANDA_STATUS period, s")
    sd.add_argument("--expire-sec", type=float, default=0.1,
                    help="drop a command whose utime is further than this from the driver's clock "
                    "(the real driver's --expire_sec)")
    sd.add_argument("--low-pass-hz", type=float, default=30.0,
                    help="first-order low-pass of the torque command (the real driver's "
                    "--low_pass_freq; >= 1000: off)")
    sd.add_argument("--rt-priority", type=int, default=80,
                    help="SCHED_FIFO priority, as libfranka's control thread (0: ordinary)")
    sd.add_argument("--set", action="append", metavar="KEY.PATH=VALUE", help="override a scenario key")
    sd.set_defaults(func=_delegate("adaptive_c3.tools.hardware.sim_driver", "cmd_sim_driver"))

    rec = sub.add_parser("record", help="recordings from a rig")
    rsub = rec.add_subparsers(dest="record_command", required=True)
    conv = rsub.add_parser("convert", help="an LCM log (PANDA_STATUS, PANDA_COMMAND, BALL_ESTIMATE) -> a recording .npz")
    conv.add_argument("log", help="LCM event log file")
    conv.add_argument("out", help="output recording (.npz)")
    conv.add_argument("--scenario", default=None, help="scenario YAML to store in the recording")
    conv.add_argument("--dt", type=float, default=0.01,
                      help="resample to this uniform step, s (0: every status message)")
    conv.set_defaults(func=_delegate("adaptive_c3.tools.hardware.record_convert", "cmd_record_convert"))

    gm = sub.add_parser("gradient-map", help="the paper's Fig. 3 for the cart-pole")
    gm.add_argument("--out", default="runs/gradient_map")
    gm.set_defaults(func=_delegate("adaptive_c3.tools.studies.gradient_map", "cmd_gradient_map"))
    return p


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)   # argparse itself exits with code 2 on bad flags
    from adaptive_c3.tools.process_tuning import limit_library_threads, tune_allocator
    limit_library_threads()
    tune_allocator()
    try:
        return int(args.func(args) or 0)
    except _user_error_types() as e:
        msg = " ".join(str(e).split())
        print(f"adaptive-c3 {args.command}: error: {msg}", file=sys.stderr)
        return USER_ERROR
    except KeyboardInterrupt:
        print(f"adaptive-c3 {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
