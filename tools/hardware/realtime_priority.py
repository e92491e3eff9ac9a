"""Real-time scheduling for the 1 kHz processes (sim-driver, impedance).

libfranka runs its 1 kHz control callback at the highest SCHED_FIFO priority and, by
default (RealtimeConfig::kEnforce), refuses to run without it; a Franka PC runs a
PREEMPT_RT kernel for the same reason. A 1 ms loop sharing two cores with a C3 planner
under the ordinary scheduler is preempted for whole time slices (measured here: p99
command period 4-5 ms). `request_fifo(priority)` asks for SCHED_FIFO at `priority`
(1-99; 0 = leave the process as it is) and says what it got; without the privilege
(root or CAP_SYS_NICE / an rtprio limit) the process goes on under the ordinary
scheduler, like libfranka's RealtimeConfig::kIgnore, and the summary says so.

The planner stays under the ordinary scheduler (nothing at 1 kHz waits for it), at most
with a higher weight there (`request_nice`, a negative nice: ahead of ordinary work on
the machine, behind the real-time loops). Not SCHED_FIFO: with it the real-time tasks
together wanted over 95 % of the two cores, the kernel's real-time throttling
(sched_rt_runtime_us) stopped them all for tens of ms, and the measured worst command
period went from 3 to 217 ms.
"""
from __future__ import annotations

import os


def request_fifo(priority: int) -> str:
    """Put this process under SCHED_FIFO at `priority`; returns what it runs under."""
    if priority <= 0:
        return "SCHED_OTHER (not requested)"
    if not hasattr(os, "sched_setscheduler"):
        return "SCHED_OTHER (no sched_setscheduler on this OS)"
    priority = min(int(priority), os.sched_get_priority_max(os.SCHED_FIFO))
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except PermissionError:
        return "SCHED_OTHER (SCHED_FIFO not permitted: needs root, CAP_SYS_NICE or rtprio)"
    return f"SCHED_FIFO {priority}"


def request_nice(nice: int) -> str:
    """Set this process's nice value (negative: more CPU share under SCHED_OTHER)."""
    if nice == 0:
        return "SCHED_OTHER nice 0"
    try:
        os.setpriority(os.PRIO_PROCESS, 0, int(nice))
    except (PermissionError, OSError):
        return f"SCHED_OTHER nice {os.getpriority(os.PRIO_PROCESS, 0)} (nice {nice} not permitted)"
    return f"SCHED_OTHER nice {int(nice)}"
