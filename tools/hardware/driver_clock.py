"""The driver's clock: microseconds since the epoch, as drake-franka-driver stamps
PANDA_STATUS and compares PANDA_COMMAND's utime against.

`wall_clock_us` is the real thing (a real-time process); `SimEpochClock` is a fixed
epoch plus simulation time, for lock-step runs in which simulation time stands in for
the wall clock (tests, `hardware --loopback`)."""
from __future__ import annotations

import time


def wall_clock_us(_t: float | None = None) -> int:
    return int(time.time() * 1e6)


class SimEpochClock:
    def __init__(self, epoch_us: int | None = None):
        self.epoch_us = int(epoch_us if epoch_us is not None else wall_clock_us())

    def __call__(self, t: float) -> int:
        return self.epoch_us + int(round(t * 1e6))
