"""SampledLcmSubscriber: the newest message on a channel, taken every `period` seconds.

output "message"  abstract: the newest decoded message at the last sample (a default
                  message before the first)

Drake's LcmSubscriberSystem updates its state at every message, so a 1 kHz channel
makes a subscriber's simulator step 1000 times a second even when the diagram needs
the value only at its own rate (the planner plans at c3.rate_hz, 80 Hz). This one keeps
the newest message in a mailbox outside the context (as LcmSubscriberSystem keeps its
receive buffer), and takes it in a periodic unrestricted update; a forced update event
does the same, so `initialise_from_messages` (first_messages.py) loads it too.

Every message is decoded on arrival by a ChannelHealth (channel_health.py, ~4 us for a
status): one that does not decode is counted there and never used - the mailbox keeps
the last good message (LcmSubscriberSystem raised `ValueError: Decode error` out of the
simulator instead). `health` is the channel's record (undecodable runs, staleness).
"""
from __future__ import annotations

from pydrake.common.value import AbstractValue
from pydrake.systems.framework import EventStatus, LeafSystem

from adaptive_c3.tools.hardware.channel_health import ChannelHealth


class SampledLcmSubscriber(LeafSystem):
    def __init__(self, channel: str, lcm_type, lcm, period: float):
        super().__init__()
        self._type = lcm_type
        self.health = ChannelHealth(channel, lcm_type)
        self._mailbox = {"msg": None, "count": 0}
        lcm.Subscribe(channel, self._receive)
        # (decoded message, mailbox count it came from)
        self._state = self.DeclareAbstractState(AbstractValue.Make((lcm_type(), 0)))
        self.DeclarePeriodicUnrestrictedUpdateEvent(period, 0.0, self._sample)
        self.DeclareForcedUnrestrictedUpdateEvent(self._sample)
        self.DeclareAbstractOutputPort(
            "message", lambda: AbstractValue.Make(lcm_type()),
            lambda ctx, out: out.set_value(ctx.get_abstract_state(int(self._state)).get_value()[0]))
        self.set_name(f"SampledLcmSubscriber({channel})")

    def _receive(self, data):
        msg = self.health.decode(data)
        if msg is not None:
            self._mailbox["msg"] = msg
            self._mailbox["count"] += 1

    def _sample(self, context, state):
        count = self._mailbox["count"]
        if count != context.get_abstract_state(int(self._state)).get_value()[1]:
            state.get_mutable_abstract_state(int(self._state)).set_value(
                (self._mailbox["msg"], count))
        return EventStatus.Succeeded()

    def messages_received(self) -> int:
        """Messages that decoded (the undecodable ones are in health.undecodable)."""
        return self._mailbox["count"]
