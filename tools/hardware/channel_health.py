"""ChannelHealth: what arrived on one LCM channel, and whether it could be used (pure Python).

`decode(data)` turns a raw LCM message into the channel's lcm-gen type, or counts it as
undecodable (wrong fingerprint, truncated, garbage) and returns None: such a message is
never used. It also keeps
  received          messages seen (decodable or not)
  undecodable       messages that did not decode
  bad_run           undecodable messages in a row now (a decoded one resets it)
  worst_run         the longest such run
  fresh_at          `clock()` (s) when a message with a utime newer than the last one
                    arrived (None before the first): how stale the channel is
The planner (planner_run.py) stops planning on a stale status and safe-stops on a run of
undecodable messages; the simulated driver counts undecodable commands. `tolerant_type`
gives Drake's LcmSubscriberSystem a message type that decodes through a ChannelHealth.
"""
from __future__ import annotations

import time


class ChannelHealth:
    def __init__(self, channel: str, lcm_type, clock=time.monotonic):
        self.channel, self._type, self.clock = channel, lcm_type, clock
        self.received = self.undecodable = self.bad_run = self.worst_run = 0
        self.fresh_at = None
        self._utime = None

    def decode(self, data):
        """The decoded message, or None (counted) if `data` does not decode."""
        self.received += 1
        try:
            msg = self._type.decode(data)
        except Exception:            # lcm-gen raises ValueError / struct.error on garbage
            self.undecodable += 1
            self.bad_run += 1
            self.worst_run = max(self.worst_run, self.bad_run)
            return None
        self.bad_run = 0
        utime = getattr(msg, "utime", None)
        if utime is None or self._utime is None or utime > self._utime:
            self._utime = utime
            self.fresh_at = self.clock()
        return msg

    def stale_s(self, now: float | None = None) -> float:
        """Seconds since the newest fresh message (inf before the first)."""
        if self.fresh_at is None:
            return float("inf")
        return (self.clock() if now is None else now) - self.fresh_at

    def restart(self) -> None:
        """Forget the newest utime (a restarted driver's clock may start anywhere)."""
        self._utime = None

    def counts(self) -> dict:
        return {"received": self.received, "undecodable": self.undecodable,
                "worst_undecodable_run": self.worst_run}


def tolerant_type(health: ChannelHealth):
    """A subclass of health's lcm-gen type whose `decode` never raises: a message that
    does not decode is counted in `health` and the last good message (a default one
    before any) is returned again - for LcmSubscriberSystem.Make, which otherwise raises
    `ValueError: Decode error` out of the simulator."""
    base = health._type
    last = [base()]

    def decode(data):
        msg = health.decode(data)
        if msg is not None:
            last[0] = msg
        return last[0]
    return type(f"Tolerant_{base.__name__}", (base,), {"decode": staticmethod(decode)})
