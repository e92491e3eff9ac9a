"""The three processes of a hardware run - simulated driver, impedance loop, planner -
in one process over memq://, advanced in lock-step (a test and a self-check of the
split; the real run starts them as separate processes).

Every `step` of simulated time the driver advances first (status, ball estimate), then
the planner (EE_PLAN), then the impedance loop (PANDA_COMMAND), so each sees the others'
newest messages. The driver keeps the real driver's rules on a clock of simulation time
from a fixed epoch. status_delay_s: the impedance loop is handed each PANDA_STATUS that
much simulated time after it was published (a loop that answers late, as on a loaded
machine; its commands then carry that age to the driver)."""
from __future__ import annotations

import time
from collections import deque


class LateStatuses:
    """Hands an ImpedanceTick each PANDA_STATUS delay_s (s, loop time) after it arrived."""

    def __init__(self, tick, delay_s: float):
        self._take, self._delay, self._queue, self.t = tick.receive_status, delay_s, deque(), 0.0
        tick.receive_status = self.arrive

    def arrive(self, msg) -> None:
        """A status arriving now (at loop time self.t)."""
        self._queue.append((self.t, msg))

    def release(self, t: float) -> None:
        """At loop time t: hand over what arrived by t - delay_s."""
        while self._queue and self._queue[0][0] <= t - self._delay + 1e-9:
            self._take(self._queue.popleft()[1])


def run_split_loopback(s, duration: float, *, step: float = 1e-3, low_pass_hz: float = 30.0,
                       stale_s: float = 0.05, delay_s: float = 0.0,
                       status_delay_s: float = 0.0) -> dict:
    from pydrake.lcm import DrakeLcm
    from pydrake.systems.analysis import Simulator

    from adaptive_c3.tools.hardware.first_messages import (initialise_from_messages,
                                                               wait_for_channels)
    from adaptive_c3.tools.hardware.impedance_process import ImpedanceProcess
    from adaptive_c3.tools.hardware.lcm_channels import BALL_CHANNEL, STATUS_CHANNEL
    from adaptive_c3.tools.hardware.planner_process import build_planner_process
    from adaptive_c3.tools.hardware.sim_driver import build_sim_driver, driver_summary
    lcm = DrakeLcm("memq://")
    drv = build_sim_driver(s, lcm, low_pass_hz=low_pass_hz)
    planner = build_planner_process(s, lcm, delay_s=delay_s, transport_s=step)
    imp = ImpedanceProcess(s, lcm, stale_s=stale_s)
    late = LateStatuses(imp.tick, status_delay_s) if status_delay_s > 0 else None
    sims = [Simulator(d) for d in (drv.diagram, planner.diagram)]
    sims[0].Initialize()                # publishes the first status and ball estimate
    wait_for_channels(lcm, [STATUS_CHANNEL, BALL_CHANNEL],
                      pump=lambda: lcm.HandleSubscriptions(0), timeout_s=0.0)
    initialise_from_messages(sims[1])
    wall = time.perf_counter()
    for k in range(1, int(round(duration / step)) + 1):
        for sim in sims:
            sim.AdvanceTo(k * step)
        if late:
            late.t = k * step
        lcm.HandleSubscriptions(0)
        if late:
            late.release(k * step)
        imp.step(k * step)
    wall = time.perf_counter() - wall
    return {"sim_duration_s": duration, "wall_s": wall,
            "driver": driver_summary(drv, sims[0].get_context()),
            **imp.tick.report(),
            "_": {"driver": drv, "planner": planner, "impedance": imp, "sims": sims}}
