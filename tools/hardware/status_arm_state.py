"""StatusArmState: a PANDA_STATUS message as the arm state vector.

input  "lcmt_panda_status"  abstract: a Python drake.lcmt_panda_status
output "panda.state"        (14) q (rad), v (rad/s) of the message, or `fallback` (14)
                            when the message is empty or its 7 + 7 values are not all
                            finite: the controller's pipeline stays finite and the
                            watchdog, which reads the message itself, latches the stop.
(Stateless; replaces Drake's PandaStatusReceiver + a finiteness guard so that each
status is decoded once, by the Python subscriber the watchdog and the gate read too.)
"""
from __future__ import annotations

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import LeafSystem

NQ = 7


def arm_state_from_status(msg, fallback) -> np.ndarray:
    """(14) q, v of a PANDA_STATUS message, or `fallback` when it is empty or its 7 + 7
    values are not all finite."""
    if msg.num_joints == NQ:
        try:
            cand = np.array([*msg.joint_position, *msg.joint_velocity], float)
        except (TypeError, ValueError):
            cand = None
        if cand is not None and cand.shape == (2 * NQ,) and np.all(np.isfinite(cand)):
            return cand
    return fallback


class StatusArmState(LeafSystem):
    def __init__(self, fallback):
        super().__init__()
        from drake import lcmt_panda_status
        self._fb = np.asarray(fallback, float).reshape(2 * NQ)
        self._in = self.DeclareAbstractInputPort("lcmt_panda_status",
                                                 AbstractValue.Make(lcmt_panda_status()))
        self.DeclareVectorOutputPort("panda.state", 2 * NQ, self._calc)

    def _calc(self, context, output):
        output.SetFromVector(arm_state_from_status(self._in.Eval(context), self._fb))
