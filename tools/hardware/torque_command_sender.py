"""TorqueCommandSender: PANDA_COMMAND for drake-franka-driver's torque mode, stamped in
the driver's clock.

input  "panda.torque_command" (7) N m, WITHOUT gravity
input  "lcmt_panda_status"    abstract: the latest PANDA_STATUS (Python message)
output "lcmt_panda_command"   abstract: control_mode_expected = CONTROL_MODE_TORQUE,
                              num_joint_position = num_joint_velocity = 0,
                              num_joint_torque = 7, utime = the latest status's utime
Drake's PandaCommandSender stamps the diagram time, which a real driver reads as decades
off its clock and drops. The latest status utime IS the driver's clock (no clock
synchronisation between the PCs needed), and a command built on a status that has gone
stale carries that age, so the driver drops it after its --expire_sec; the reference
controllers stamp the same way. Before any status arrives the stamp is 0: expired.
"""
from __future__ import annotations

from pydrake.common.value import AbstractValue
from pydrake.systems.framework import LeafSystem

NQ = 7


def torque_command_message(tau, utime: int):
    """lcmt_panda_command in torque mode: tau (7, N m, without gravity), stamped utime."""
    from drake import lcmt_panda_command, lcmt_panda_status
    msg = lcmt_panda_command()
    msg.utime = int(utime)
    msg.control_mode_expected = lcmt_panda_status.CONTROL_MODE_TORQUE
    msg.num_joint_position = 0
    msg.num_joint_velocity = 0
    msg.num_joint_torque = NQ
    msg.joint_torque = [float(v) for v in tau]
    return msg


class TorqueCommandSender(LeafSystem):
    def __init__(self):
        super().__init__()
        from drake import lcmt_panda_command, lcmt_panda_status
        self._tau = self.DeclareVectorInputPort("panda.torque_command", NQ)
        self._status = self.DeclareAbstractInputPort("lcmt_panda_status",
                                                     AbstractValue.Make(lcmt_panda_status()))
        self.DeclareAbstractOutputPort("lcmt_panda_command",
                                       lambda: AbstractValue.Make(lcmt_panda_command()),
                                       self._calc)

    def _calc(self, context, output):
        output.set_value(torque_command_message(self._tau.Eval(context),
                                                self._status.Eval(context).utime))
