"""StatusSender: PANDA_STATUS as drake-franka-driver publishes it in torque mode.

input  "panda.state"          (14) q (rad), v (rad/s), measured
input  "panda.torque_command" (7) N m, the torque applied (without gravity)
output "lcmt_panda_status"    abstract: num_joints = 7, positions / velocities (the
                              desired ones = the measured: torque mode has no desired
                              motion), joint_torque = joint_torque_desired = the applied
                              torque, robot_mode = kMove (the control loop runs),
                              control_mode = torque, utime = clock(t) (microseconds since
                              the epoch: the driver PC's wall clock), robot_utime = t (us)
"""
from __future__ import annotations

from pydrake.common.value import AbstractValue
from pydrake.systems.framework import LeafSystem

NQ = 7


class StatusSender(LeafSystem):
    def __init__(self, clock, robot_mode: int | None = None):
        super().__init__()
        from drake import lcmt_panda_status
        self._clock = clock
        self._mode = lcmt_panda_status.kMove if robot_mode is None else int(robot_mode)
        self._state = self.DeclareVectorInputPort("panda.state", 2 * NQ)
        self._tau = self.DeclareVectorInputPort("panda.torque_command", NQ)
        self.DeclareAbstractOutputPort("lcmt_panda_status",
                                       lambda: AbstractValue.Make(lcmt_panda_status()),
                                       self._calc)

    def _calc(self, context, output):
        x = [float(v) for v in self._state.Eval(context)]
        tau = [float(v) for v in self._tau.Eval(context)]
        output.set_value(status_message(int(self._clock(context.get_time())), x[:NQ], x[NQ:],
                                        tau, self._mode,
                                        int(round(context.get_time() * 1e6))))


def status_message(utime: int, q, v, tau, robot_mode: int, robot_utime: int = 0):
    """A complete torque-mode lcmt_panda_status (q rad, v rad/s, tau N m)."""
    from drake import lcmt_panda_status
    msg = lcmt_panda_status()
    msg.utime = int(utime)
    msg.num_joints = NQ
    msg.joint_position = msg.joint_position_desired = [float(a) for a in q]
    msg.joint_velocity = msg.joint_velocity_desired = [float(a) for a in v]
    msg.joint_acceleration_desired = [0.0] * NQ
    msg.joint_torque = msg.joint_torque_desired = [float(a) for a in tau]
    msg.joint_torque_external = [0.0] * NQ
    msg.control_command_success_rate = 1.0
    msg.robot_mode = int(robot_mode)
    msg.robot_utime = int(robot_utime)
    msg.control_mode = lcmt_panda_status.CONTROL_MODE_TORQUE
    return msg
