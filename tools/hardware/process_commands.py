"""`adaptive-c3 impedance` and `adaptive-c3 planner`: the two controller processes of a
hardware run (impedance_process.py, planner_process.py), each a Drake Simulator held to
real time, and `hardware --split`, which starts both."""
from __future__ import annotations

import json
import subprocess
import sys
import time


def cmd_impedance(args) -> int:
    from adaptive_c3.tools.hardware.impedance_process import ImpedanceProcess
    from adaptive_c3.tools.hardware.lcm_channels import open_lcm
    from adaptive_c3.tools.hardware.realtime import load_hardware_scenario
    from adaptive_c3.tools.hardware.realtime_priority import request_fifo
    s, _, duration = load_hardware_scenario(args)
    lcm = open_lcm(args.lcm_url)
    scheduling = request_fifo(args.rt_priority)
    proc = ImpedanceProcess(s, lcm, stale_s=args.stale_ms * 1e-3)
    print(f"impedance: PANDA_STATUS + EE_PLAN -> PANDA_COMMAND on {args.lcm_url}"
          + (f" for {duration:g} s" if duration else "; Ctrl-C to stop")
          + "; one tick per PANDA_STATUS; waiting for PANDA_STATUS ...", flush=True)
    out = proc.run(duration, tick_s=args.period, wait_s=args.wait_s)
    out.update(cpu_s=time.process_time(), scheduling=scheduling)
    print(json.dumps(out, default=float), flush=True)
    return out["safety"]["exit_code"]      # 3 after a safe stop (SAFE_STOP_EXIT)


def cmd_planner(args) -> int:
    """The planner process (planner_run.py): stops planning on a stale status and waits
    for the robot again; a run of undecodable messages is a safe stop (exit code 3)."""
    import signal

    from adaptive_c3.tools.hardware.lcm_channels import open_lcm
    from adaptive_c3.tools.hardware.planner_process import build_planner_process
    from adaptive_c3.tools.hardware.planner_run import PlannerRun
    from adaptive_c3.tools.hardware.realtime import load_hardware_scenario
    from adaptive_c3.tools.hardware.realtime_priority import request_nice
    from adaptive_c3.tools.process_tuning import freeze_heap
    from adaptive_c3.tools.user_input import UserError
    s, _, duration = load_hardware_scenario(args)
    if not (0 <= args.delay_ms < 1000):
        raise UserError(f"--delay-ms must be in [0, 1000), got {args.delay_ms}")
    lcm = open_lcm(args.lcm_url)
    scheduling = request_nice(args.nice)
    proc = build_planner_process(s, lcm, delay_s=args.delay_ms * 1e-3)
    run = PlannerRun(proc, lcm, stale_s=getattr(args, "stale_ms", 100.0) * 1e-3,
                     malformed_run=s.safety.malformed_run)
    start_epoch_s = []      # wall clock at each planning start (to line up with the driver's)
    run.on_start = lambda: (start_epoch_s.append(time.time()), freeze_heap())

    def on_term(_signum, _frame):
        raise KeyboardInterrupt
    signal.signal(signal.SIGTERM, on_term)
    print("waiting for PANDA_STATUS, BALL_ESTIMATE ...", flush=True)
    print(f"planner: PANDA_STATUS + BALL_ESTIMATE -> EE_PLAN on {args.lcm_url}"
          + (f" for {duration:g} s" if duration else "; Ctrl-C to stop"), flush=True)
    wall = time.perf_counter()
    run.run(duration, wait_s=args.wait_s)
    out = {"wall_s": time.perf_counter() - wall, "cpu_s": time.process_time(),
           "start_epoch_s": start_epoch_s[0] if start_epoch_s else None,
           "scheduling": scheduling, **run.summary()}
    out["sim_time_s"] = out["planned_s"]
    print(json.dumps(out, default=float), flush=True)
    return run.exit_code()


def run_split(args) -> int:
    """`hardware --split`: the impedance and planner processes side by side; stops both
    when either ends."""
    common = [args.scenario, "--lcm-url", args.lcm_url]
    for kv in args.set or []:
        common += ["--set", kv]
    if args.duration is not None:
        common += ["--duration", str(args.duration)]
    exe = [sys.executable, "-m", "adaptive_c3.tools.cli"]
    procs = [subprocess.Popen(exe + ["impedance", *common, "--stale-ms", str(args.stale_ms),
                                     "--period", str(args.period),
                                     "--rt-priority", str(args.rt_priority)]),
             subprocess.Popen(exe + ["planner", *common])]
    try:
        while all(p.poll() is None for p in procs):
            time.sleep(0.1)
    except KeyboardInterrupt:
        pass
    finally:
        for p in procs:
            if p.poll() is None:
                p.terminate()
        codes = [p.wait() for p in procs]
    return max(codes) if any(codes) else 0
