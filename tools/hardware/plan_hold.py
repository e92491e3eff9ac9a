"""PlanHold: the impedance process's view of the planner's EE plan (EE_PLAN), pure Python.

`take(msg)` keeps the newest plan that fits the layout (lcm_channels.PLAN_NAMES; others
are counted as ignored). `target(status_utime)` gives what the 1 kHz law tracks:
  desired (6)  tip position (m) and velocity (m/s), robot base frame
  feedforward (3) N
  ok           False = command zero torque
A plan's age is the driver's clock (the latest status utime) minus the plan's utime.
Older than hold_s: the last target is held at rest (zero velocity, zero feed-forward) -
the arm stays where the planner last wanted it; older than timeout_s, or no plan yet:
ok = False.
"""
from __future__ import annotations

import math

import numpy as np

from adaptive_c3.tools.hardware.lcm_channels import decode_plan

_AT_REST = np.zeros(3)


class PlanHold:
    def __init__(self, hold_s: float = 0.1, timeout_s: float = 0.5):
        if not (0 < hold_s <= timeout_s and math.isfinite(timeout_s)):
            raise ValueError(f"need 0 < plan hold ({hold_s}) <= plan timeout ({timeout_s})")
        self._hold_us, self._timeout_us = hold_s * 1e6, timeout_s * 1e6
        self._plan = np.zeros(9)        # [p (3), v (3), f (3)]
        self._utime = None
        self.used = self.ignored = 0

    def take(self, msg) -> bool | None:
        """A new EE_PLAN message: True = taken, False = it does not fit the layout
        (counted as ignored), None = a repeat of the held plan's utime (not counted)."""
        if self._utime is not None and int(msg.utime) == self._utime:
            return None
        v = decode_plan(msg)
        if v is None:
            self.ignored += 1
            return False
        self._plan, self._utime = v, int(msg.utime)
        self.used += 1
        return True

    def age_us(self, status_utime: int) -> float:
        return math.inf if self._utime is None else float(status_utime - self._utime)

    def target(self, status_utime: int):
        """(desired (6), feedforward (3), ok) at the driver's clock status_utime."""
        age = self.age_us(status_utime)
        p = self._plan
        if age <= self._hold_us:
            return p[:6], p[6:9], True
        return np.r_[p[:3], _AT_REST], _AT_REST, age <= self._timeout_us

    def counts(self) -> dict:
        return {"plans_used": self.used, "plans_ignored": self.ignored}
