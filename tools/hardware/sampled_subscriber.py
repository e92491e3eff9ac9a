"""SampledLcmSubscriber: the newest message on a channel, taken every `period` seconds.

output "message"  abstract: the newest decoded message at the last sample (a default
                  message before the first)

Drake's LcmSubscriberSystem updates its state at every message, so a 1 kHz channel
makes a subscriber's simulator step 1000 times a second even when the diagram needs
the value only at its own rate (the planner plans at c3.rate_hz, 80 Hz). This one keeps
the newest raw message in a mailbox outside the context (as LcmSubscriberSystem keeps
its receive buffer), and decodes it in a periodic unrestricted update; a forced update
event does the same, so `initialise_from_messages` (first_messages.py) loads it too.
"""
from __future__ import annotations

from pydrake.common.value import AbstractValue
from pydrake.systems.framework import EventStatus, LeafSystem


class SampledLcmSubscriber(LeafSystem):
    def __init__(self, channel: str, lcm_type, lcm, period: float):
        super().__init__()
        self._type = lcm_type
        self._mailbox = {"data": None, "count": 0}
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
        self._mailbox["data"] = data
        self._mailbox["count"] += 1

    def _sample(self, context, state):
        count = self._mailbox["count"]
        if count != context.get_abstract_state(int(self._state)).get_value()[1]:
            msg = self._type.decode(self._mailbox["data"])
            state.get_mutable_abstract_state(int(self._state)).set_value((msg, count))
        return EventStatus.Succeeded()

    def messages_received(self) -> int:
        return self._mailbox["count"]
