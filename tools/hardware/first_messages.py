"""Start a controller diagram from the robot's first messages, not from defaults.

An LcmSubscriberSystem holds an empty message until its first update after a message
arrives, so a controller initialised at once would latch whatever the empty message
decodes to: PandaStatusReceiver gives q = 0, whose EE tip is 0.7 m above the ball, and
the planner's first target then walks from there (measured in lock-step: the arm was
pulled 0.6 m up and out in the first 0.5 s, and at the driver's 30 Hz torque filter it
ran into the elbow limit). A robot process instead waits for its inputs:
`start_from_first_messages` waits until every channel has delivered a message, copies
the newest messages into the context (the subscribers' forced update events), and only
then initialises the simulator, so every initialisation event sees the real state.
A process that loses the robot waits the same way again (FirstMessages.reset).
"""
from __future__ import annotations

import time

from adaptive_c3.tools.user_input import UserError


class FirstMessagesTimeout(UserError):
    """No message on some channel within the timeout (one line naming them; exit 2)."""


class FirstMessages:
    """Which of `channels` delivered a message since the last `reset()` (or since this
    was made). Subscribes once; a process that must wait again (the planner after the
    robot's status went stale) resets it and polls `ready()`."""

    def __init__(self, lcm, channels):
        self.channels = list(dict.fromkeys(channels))
        self._seen = set()
        for ch in self.channels:     # (pydrake keeps these for the LCM's lifetime)
            lcm.Subscribe(ch, lambda _data, ch=ch: self._seen.add(ch))

    def reset(self) -> None:
        self._seen.clear()

    def ready(self) -> bool:
        return len(self._seen) == len(self.channels)

    def missing(self) -> list:
        return [ch for ch in self.channels if ch not in self._seen]


def wait_for_channels(lcm, channels, *, pump=None, timeout_s: float = 10.0,
                      clock=time.monotonic, first: FirstMessages | None = None) -> None:
    """Return once each channel in `channels` has delivered a message (since `first` was
    reset, when a FirstMessages is given).

    pump(): makes messages arrive (default: lcm.HandleSubscriptions(50), a real-time
    wait); a lock-step run passes lcm.HandleSubscriptions(0) after the driver has
    published. Raises FirstMessagesTimeout naming the silent channels after timeout_s
    (measured by `clock`, seconds; 0: one pump only)."""
    first = first if first is not None else FirstMessages(lcm, channels)
    if pump is None:
        def pump():
            lcm.HandleSubscriptions(50)
    deadline = clock() + timeout_s
    while True:
        pump()
        if first.ready():
            return
        if clock() > deadline:
            missing = ", ".join(sorted(first.missing()))
            raise FirstMessagesTimeout(
                f"no message on {missing} within {timeout_s:g} s: is the robot driver "
                f"(or sim-driver) running on the same LCM URL?")


def initialise_from_messages(sim) -> None:
    """Copy the messages the diagram's LCM subscribers hold into its context (their
    forced update events), then initialise the simulator."""
    sim.get_system().ExecuteForcedEvents(sim.get_mutable_context(), publish=False)
    sim.Initialize()


def start_from_first_messages(sim, lcm, channels, **wait) -> None:
    """wait_for_channels, then initialise_from_messages (see the module doc)."""
    wait_for_channels(lcm, channels, **wait)
    initialise_from_messages(sim)
