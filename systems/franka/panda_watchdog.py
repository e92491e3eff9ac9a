"""`PandaWatchdog`: the safety gate between the torque controller and the Panda's command.

Sits between the impedance controller's torque command and Drake's `PandaCommandSender`
in the LCM bridge (tools/hardware/bridge.py). Every `period` seconds (1 kHz by default) it
looks at the newest Panda status message and the requested torques and decides what
torque to command:

  - WAITING    no status received yet                              -> 0 (not a fault)
  - STALE      no NEW status (utime unchanged) for more than `stale_s` (50 ms) of
               the diagram clock (receive time), or, with use_message_time, the
               message's utime older than `stale_s` against the diagram clock  -> 0
  - MALFORMED  status with num_joints / array sizes != 7, or a torque request of the
               wrong size                                          -> 0 while it lasts
  - LAGGING    (real-time bridges: wall_clock=True and max_lag_s) the diagram clock is
               more than max_lag_s behind the wall clock: the controller cannot keep
               up, its commands would be late                         -> 0 while it lasts
  - NONFINITE  any NaN/inf in the status (q, v) or in the requested torque
               -> 0 and LATCHED: the watchdog stays stopped until reset (a new
               Context / restart of the bridge)
  - OK         the request clipped to +-torque_limits (reference [87 x 4, 12 x 3] N m)
               and rate limited to `rate_limit` N m/s per joint (from the last
               commanded value; after a fault the command ramps up from zero).
A fault drops the command to zero at once (not rate limited). Everything is counted
(`counts`: ok, waiting, stale, malformed, nonfinite, clipped, rate_limited, in update
periods), the first fault's reason and time are kept, and each transition into a fault
is logged (Python `logging`, logger "adaptive_c3.watchdog").

Pure-numpy core: `WatchdogCore.step(state, t, status, tau_request)`; `StatusSample`
carries what it needs from the message (utime, num_joints, q, v).

Ports:
  input  "panda.status"         abstract: a Python `drake.lcmt_panda_status` (from an
                                 LcmSubscriberSystem without the C++ serializer)
  input  "panda.torque_request" (7) N m, without gravity (the impedance controller's)
  output "panda.torque_command" (7) N m, what may be sent (held between updates)
  output "watchdog.fault"       (1) the current mode code, FAULT_CODES below
"""
from __future__ import annotations

import copy
import logging
import math
from dataclasses import dataclass, field

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import LeafSystem

LOG = logging.getLogger("adaptive_c3.watchdog")

TORQUE_LIMITS = (87.0, 87.0, 87.0, 87.0, 12.0, 12.0, 12.0)   # N m (Franka Panda)
FAULT_CODES = {"ok": 0, "waiting": 1, "stale": 2, "malformed": 3, "nonfinite": 4, "lagging": 5}


@dataclass
class WatchdogConfig:
    stale_s: float = 0.05            # status older than this -> zero torque
    torque_limits: tuple = TORQUE_LIMITS
    rate_limit: float = 1000.0       # N m/s per joint (the Franka's own limit is 1000)
    num_joints: int = 7
    use_message_time: bool = False   # judge age by the message's utime (same clock)
    max_lag_s: float = math.inf      # real-time bridges: the diagram clock may fall this
                                     # far behind the wall clock (else "lagging" -> 0)

    def __post_init__(self):
        lim = np.asarray(self.torque_limits, float)
        if lim.shape != (self.num_joints,) or not np.isfinite(lim).all() or np.any(lim <= 0):
            raise ValueError(f"torque_limits must be {self.num_joints} positive numbers")
        if not (math.isfinite(self.stale_s) and self.stale_s > 0):
            raise ValueError(f"stale_s must be > 0, got {self.stale_s}")
        if not (self.rate_limit > 0):   # inf allowed: no rate limit
            raise ValueError(f"rate_limit must be > 0, got {self.rate_limit}")


@dataclass
class StatusSample:
    utime: int
    num_joints: int
    q: np.ndarray
    v: np.ndarray

    @staticmethod
    def from_lcm(msg) -> "StatusSample | None":
        """None for the default (never received) message."""
        if msg is None or (msg.num_joints == 0 and msg.utime == 0):
            return None
        return StatusSample(int(msg.utime), int(msg.num_joints),
                            np.asarray(msg.joint_position, float),
                            np.asarray(msg.joint_velocity, float))


@dataclass
class WatchdogState:
    tau: np.ndarray = field(default_factory=lambda: np.zeros(7))
    last_utime: int | None = None
    last_rx_s: float = -math.inf
    last_t: float | None = None
    latched: bool = False
    mode: str = "waiting"
    counts: dict = field(default_factory=lambda: {k: 0 for k in (
        "ok", "waiting", "stale", "malformed", "nonfinite", "lagging", "clipped",
        "rate_limited")})
    wall0: float | None = None       # wall-clock origin (PandaWatchdog with wall_clock)
    first_fault: str = ""
    first_fault_t: float | None = None
    messages: int = 0

    def __deepcopy__(self, memo):
        # Drake clones abstract state several times per update (4 per 1 kHz tick
        # measured): keep it cheap - the fields are immutable but for tau and counts
        new = object.__new__(WatchdogState)
        new.__dict__.update(self.__dict__)
        new.tau = self.tau.copy()
        new.counts = dict(self.counts)
        return new

    def report(self) -> dict:
        return {"mode": self.mode, "latched": self.latched, "counts": dict(self.counts),
                "first_fault": self.first_fault or None, "first_fault_t": self.first_fault_t,
                "status_messages": self.messages}


class WatchdogCore:
    """The numpy decision logic; `step` mutates and returns the state's command."""

    def __init__(self, config: WatchdogConfig = WatchdogConfig()):
        self.config = config
        self._lim = np.asarray(config.torque_limits, float)

    def new_state(self) -> WatchdogState:
        return WatchdogState(tau=np.zeros(self.config.num_joints))

    def _fault(self, s: WatchdogState, t: float, mode: str, reason: str) -> np.ndarray:
        s.counts[mode] += 1
        if mode != s.mode:
            if mode != "waiting":
                LOG.warning("watchdog: %s at t=%.4f s: %s -> zero torque", mode, t, reason)
            if not s.first_fault and mode != "waiting":
                s.first_fault, s.first_fault_t = f"{mode}: {reason}", float(t)
        s.mode = mode
        s.tau = np.zeros(self.config.num_joints)
        return s.tau

    def step(self, s: WatchdogState, t: float, status: StatusSample | None,
             tau_request, lag_s: float = 0.0) -> np.ndarray:
        """One update at diagram time t; lag_s = how far t is behind the wall clock."""
        cfg, n = self.config, self.config.num_joints
        dt = None if s.last_t is None else max(t - s.last_t, 0.0)
        s.last_t = float(t)
        if s.latched:
            return self._fault(s, t, "nonfinite", "latched stop")
        # --- status ---
        if status is None:
            return self._fault(s, t, "waiting", "no status received yet")
        if status.utime != s.last_utime:
            s.last_utime, s.last_rx_s = status.utime, float(t)
            s.messages += 1
        if (status.num_joints != n or np.shape(status.q) != (n,)
                or np.shape(status.v) != (n,)):
            return self._fault(s, t, "malformed",
                               f"status with {status.num_joints} joints, q {np.shape(status.q)},"
                               f" v {np.shape(status.v)}")
        if not (np.isfinite(status.q).all() and np.isfinite(status.v).all()):
            s.latched = True
            return self._fault(s, t, "nonfinite", "non-finite joint state in the status")
        age = (t - 1e-6 * status.utime) if cfg.use_message_time else (t - s.last_rx_s)
        if age > cfg.stale_s:
            return self._fault(s, t, "stale", f"status {1e3 * age:.1f} ms old "
                               f"(limit {1e3 * cfg.stale_s:.0f} ms)")
        if lag_s > cfg.max_lag_s:
            return self._fault(s, t, "lagging", f"the controller runs {1e3 * lag_s:.0f} ms "
                               f"behind real time (limit {1e3 * cfg.max_lag_s:.0f} ms)")
        # --- request ---
        tau = np.asarray(tau_request, float).reshape(-1)
        if tau.shape != (n,):
            return self._fault(s, t, "malformed", f"torque request of size {tau.size}")
        if not np.isfinite(tau).all():
            s.latched = True
            return self._fault(s, t, "nonfinite", "non-finite torque request")
        clipped = np.clip(tau, -self._lim, self._lim)
        if np.any(clipped != tau):
            s.counts["clipped"] += 1
        prev = s.tau if s.mode == "ok" else np.zeros(n)
        if dt is not None and math.isfinite(cfg.rate_limit):
            step = cfg.rate_limit * max(dt, 1e-6) if dt > 0 else 0.0
            limited = prev + np.clip(clipped - prev, -step, step)
            if np.any(np.abs(limited - clipped) > 1e-12):
                s.counts["rate_limited"] += 1
            clipped = limited
        elif dt is None and math.isfinite(cfg.rate_limit):
            clipped = prev                     # first update: start from zero
        if s.mode != "ok" and s.mode != "waiting":
            LOG.warning("watchdog: status OK again at t=%.4f s", t)
        s.mode = "ok"
        s.counts["ok"] += 1
        s.tau = clipped
        return s.tau


class PandaWatchdog(LeafSystem):
    """Drake wrapper of WatchdogCore, updated every `period` s (see the module doc)."""

    def __init__(self, config: WatchdogConfig = WatchdogConfig(), period: float = 1e-3,
                 wall_clock: bool = False):
        super().__init__()
        self._wall = bool(wall_clock)
        from drake import lcmt_panda_status
        self._core = WatchdogCore(config)
        self._n = config.num_joints
        self._status = self.DeclareAbstractInputPort(
            "panda.status", AbstractValue.Make(lcmt_panda_status()))
        self._request = self.DeclareVectorInputPort("panda.torque_request", self._n)
        self._state = self.DeclareAbstractState(AbstractValue.Make(self._core.new_state()))
        self.DeclarePeriodicUnrestrictedUpdateEvent(period, 0.0, self._update)
        ticket = {self.abstract_state_ticket(self._state)}
        self.DeclareVectorOutputPort(
            "panda.torque_command", self._n,
            lambda c, o: o.SetFromVector(self._get(c).tau), prerequisites_of_calc=ticket)
        self.DeclareVectorOutputPort(
            "watchdog.fault", 1,
            lambda c, o: o.SetFromVector([FAULT_CODES[self._get(c).mode]]),
            prerequisites_of_calc=ticket)

    @property
    def core(self) -> WatchdogCore:
        return self._core

    def _get(self, context) -> WatchdogState:
        return context.get_abstract_state(self._state).get_value()

    def _update(self, context, state):
        s = copy.deepcopy(self._get(context))
        msg = self._status.Eval(context)
        req = self._request.Eval(context)
        t = context.get_time()
        lag = 0.0
        if self._wall:       # diagram time vs the wall clock since the first update
            import time
            now = time.monotonic()
            if s.wall0 is None:
                s.wall0 = now - t
            lag = (now - s.wall0) - t
        self._core.step(s, t, StatusSample.from_lcm(msg), req, lag_s=lag)
        state.get_mutable_abstract_state(self._state).set_value(s)

    def report(self, context) -> dict:
        """Counts, mode and first fault, from this system's context."""
        return self._get(context).report()


__all__ = ["PandaWatchdog", "WatchdogCore", "WatchdogConfig", "WatchdogState",
           "StatusSample", "FAULT_CODES", "TORQUE_LIMITS"]
