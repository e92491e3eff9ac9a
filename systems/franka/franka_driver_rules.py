"""What a real Franka torque driver does with the commands it receives (numpy core).

Facts from drake-franka-driver (`franka-driver/franka_driver.cc`, torque mode) and
libfranka, kept by the simulated driver so that a controller that works against it
works against the robot:
- the latest PANDA_COMMAND is used on every 1 kHz tick until a newer one arrives or it
  expires: |now - command.utime| > expire_sec, with `now` the driver PC's wall clock in
  microseconds since the epoch. An expired command is dropped (it stays dropped) and the
  arm is held by the robot's own gravity compensation plus joint damping
  tau = -kd v, kd = DAMPING (N m s/rad); the same holds before any command arrives;
- a command that is not CONTROL_MODE_TORQUE with num_joint_position = 0,
  num_joint_velocity = 0 and num_joint_torque = 7 stops the driver (it throws);
  libfranka also stops on non-finite torques;
- torques are WITHOUT gravity; libfranka low-passes them (first order, cutoff
  low_pass_hz, 30 Hz by default, against the last commanded torque) and then limits
  their rate to MAX_TORQUE_RATE per joint.
`DriverRules.tick` applies all of that to one tick; its whole memory is a state vector
(so a Drake LeafSystem can keep it in its discrete state).
"""
from __future__ import annotations

import math

import numpy as np

NQ = 7
DAMPING = np.array([37.5, 50.0, 37.5, 25.0, 5.0, 3.75, 2.5])   # N m s/rad, the driver's kd
MAX_TORQUE_RATE = 1000.0          # N m/s per joint (libfranka's torque rate limit)
CONTROL_MODE_TORQUE = 4           # lcmt_panda_status.CONTROL_MODE_TORQUE (checked in tests)
TICK_S = 1e-3

# state vector layout
LAST_SEEN, RECEIVED, DROPPED_UTIME, EXPIRED, TICKS_HELD = 0, 1, 2, 3, 4
TAU = slice(5, 5 + NQ)
STATE_SIZE = 5 + NQ


class DriverContractError(RuntimeError):
    """A command the real driver would throw on; the message is one line."""


def initial_state() -> np.ndarray:
    s = np.zeros(STATE_SIZE)
    s[LAST_SEEN] = s[DROPPED_UTIME] = -1.0
    return s


def lowpass_gain(cutoff_hz: float, dt: float = TICK_S) -> float:
    """libfranka's first-order filter: y = g x + (1 - g) y_last, g = dt / (dt + 1/(2 pi f))."""
    return dt / (dt + 1.0 / (2.0 * math.pi * cutoff_hz))


class DriverRules:
    """One tick of the torque driver. expire_sec: the driver's --expire_sec (0.1 s
    default); low_pass_hz: its --low_pass_freq (>= 1000 Hz: no filter)."""

    def __init__(self, expire_sec: float = 0.1, low_pass_hz: float = 30.0, dt: float = TICK_S):
        if not (math.isfinite(expire_sec) and expire_sec >= 0):
            raise ValueError(f"expire_sec must be finite and >= 0, got {expire_sec}")
        if not low_pass_hz > 0:
            raise ValueError(f"low_pass_hz must be > 0, got {low_pass_hz}")
        self.expire_us = int(expire_sec * 1e6)
        self.gain = lowpass_gain(low_pass_hz, dt) if low_pass_hz < 1000.0 else 1.0
        self.max_step = MAX_TORQUE_RATE * dt

    @staticmethod
    def check_contract(msg) -> np.ndarray:
        """The command's torques, or DriverContractError naming what the driver rejects."""
        if msg.control_mode_expected != CONTROL_MODE_TORQUE:
            raise DriverContractError(
                f"command in control mode {msg.control_mode_expected}, the driver runs in "
                f"torque mode ({CONTROL_MODE_TORQUE})")
        if msg.num_joint_position != 0 or msg.num_joint_velocity != 0 or msg.num_joint_torque != NQ:
            raise DriverContractError(
                f"torque command with num_joint_position={msg.num_joint_position}, "
                f"num_joint_velocity={msg.num_joint_velocity}, num_joint_torque="
                f"{msg.num_joint_torque}; the driver needs 0, 0, {NQ}")
        tau = np.asarray(msg.joint_torque, float)
        if tau.shape != (NQ,) or not np.isfinite(tau).all():
            raise DriverContractError("torque command with non-finite or missing torques")
        return tau

    def tick(self, state: np.ndarray, msg, now_us: int, v: np.ndarray) -> np.ndarray:
        """The next state; the torque the robot applies (without gravity) is state[TAU].
        msg: the latest lcmt_panda_command (None or utime < 0: none received yet)."""
        s = np.array(state, float)
        command = None
        if msg is not None and msg.utime >= 0 and (msg.num_joint_torque or msg.utime):
            if msg.utime != s[LAST_SEEN]:
                s[LAST_SEEN] = msg.utime
                s[RECEIVED] += 1
            if msg.utime != s[DROPPED_UTIME]:
                command = msg
        if command is not None and abs(now_us - int(command.utime)) > self.expire_us:
            s[DROPPED_UTIME] = command.utime
            s[EXPIRED] += 1
            command = None
        if command is None:
            raw = -DAMPING * np.asarray(v, float)
            s[TICKS_HELD] += 1
        else:
            raw = self.check_contract(command)
        last = s[TAU]
        filtered = self.gain * raw + (1.0 - self.gain) * last
        s[TAU] = last + np.clip(filtered - last, -self.max_step, self.max_step)
        return s
