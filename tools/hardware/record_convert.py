"""`adaptive-c3 record convert LOG OUT.npz`: an LCM log of a rig run -> a recording.

Input: an LCM event log (the standard format `lcm-logger` writes; `adaptive-c3 hardware
--log FILE` writes one too) holding
  PANDA_STATUS   drake.lcmt_panda_status   (required)
  BALL_ESTIMATE  drake.lcmt_robot_state    (required; layout in tools/hardware/bridge.py)
  PANDA_COMMAND  drake.lcmt_panda_command  (optional: without it u = 0)
Output: the recording format of tools/recording.py, sampled from the PANDA_STATUS messages:
  t            s, from the first status: a uniform grid of step --dt (default 0.01 s,
               the diagnose model's step) taking the newest status at each grid time,
               or (--dt 0) every status at its log timestamp (receive time)
  x [T, 19]    the ball-rolling controller model's state, state_names =
               models/ball_rolling_controller_model.STATE_NAMES: EE tip position and
               velocity from the status q, v through the Panda's forward kinematics
               (models/panda.urdf, frame panda_ee_tip); ball position and velocity =
               the newest BALL_ESTIMATE (its z as measured, vertical velocity 0); ball
               quaternion identity; ball angular velocity by rolling, w = z_hat x v / z
  u [T, 3]     input_names = INPUT_NAMES (ee_force_x, ee_force_y, ee_force_z): the EE
               tip force the newest PANDA_COMMAND's torques exert, F = least-squares
               solution of J_tip(q)' [0; F] = tau (the wrench's force part; null-space
               torques drop out), N in W; 0 before the first command
  extras       q [T, 7], v [T, 7], tau_cmd [T, 7] (the zero-order held command),
               ball_estimate [T, 6], status_utime [T] (the driver's clock, us)
Malformed logs (bad sync word, truncated event, undecodable message, a channel missing,
fewer than 2 status samples) are refused with one line (exit code 2 on the CLI).
"""
from __future__ import annotations

import struct
from pathlib import Path

import numpy as np

from adaptive_c3.tools.recording import Recording, RecordingError, save_recording

SYNC = 0xEDA1DA01
_HEADER = struct.Struct(">IqqII")   # sync, event number, timestamp (us), channel len, data len


class LcmLogWriter:
    """Minimal writer of the LCM event-log format (no `lcm` package needed)."""

    def __init__(self, path):
        self._f = open(path, "wb")
        self._n = 0

    def write(self, utime: int, channel: str, data: bytes) -> None:
        ch = channel.encode()
        self._f.write(_HEADER.pack(SYNC, self._n, int(utime), len(ch), len(data)) + ch + data)
        self._n += 1

    def close(self) -> None:
        self._f.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def read_lcm_log(path):
    """Yield (timestamp_us, channel, data) of each event; RecordingError if malformed."""
    path = Path(path)
    if not path.is_file():
        raise RecordingError(f"LCM log not found: {path}")
    blob = path.read_bytes()
    i, k = 0, 0
    while i < len(blob):
        if len(blob) - i < _HEADER.size:
            raise RecordingError(f"{path}: truncated LCM log (event {k} header at byte {i})")
        sync, _, ts, clen, dlen = _HEADER.unpack_from(blob, i)
        if sync != SYNC:
            raise RecordingError(f"{path}: not an LCM log (bad sync word at byte {i})")
        j = i + _HEADER.size
        if j + clen + dlen > len(blob):
            raise RecordingError(f"{path}: truncated LCM log (event {k} at byte {i})")
        try:
            channel = blob[j:j + clen].decode()
        except UnicodeDecodeError:
            raise RecordingError(f"{path}: bad channel name in event {k}")
        yield ts, channel, blob[j + clen:j + clen + dlen]
        i, k = j + clen + dlen, k + 1


def convert_lcm_log(log_path, *, scenario_text: str = "", dt: float = 0.01,
                    status_channel="PANDA_STATUS",
                    command_channel="PANDA_COMMAND", ball_channel="BALL_ESTIMATE") -> Recording:
    from drake import lcmt_panda_command, lcmt_panda_status, lcmt_robot_state

    from adaptive_c3.models.ball_rolling_controller_model import INPUT_NAMES, STATE_NAMES
    from adaptive_c3.systems.franka.impedance_controller import ArmModel
    from adaptive_c3.tools.hardware.lcm_channels import decode_ball_estimate

    where = str(log_path)
    types = {status_channel: lcmt_panda_status, command_channel: lcmt_panda_command,
             ball_channel: lcmt_robot_state}
    ball = np.full(6, np.nan)
    tau = np.zeros(7)
    rows = []            # (ts, utime, q, v, tau, ball)
    seen = set()
    for ts, channel, data in read_lcm_log(log_path):
        if channel not in types:
            continue
        try:
            msg = types[channel].decode(data)
        except Exception as e:
            raise RecordingError(f"{where}: cannot decode a {channel} message as "
                                 f"{types[channel].__name__} ({type(e).__name__})")
        seen.add(channel)
        if channel == ball_channel:
            b = decode_ball_estimate(msg)
            if np.all(np.isfinite(b)):
                ball = b
        elif channel == command_channel:
            t_cmd = np.asarray(msg.joint_torque, float)
            if t_cmd.shape == (7,) and np.all(np.isfinite(t_cmd)):
                tau = t_cmd
        else:
            q = np.asarray(msg.joint_position, float)
            v = np.asarray(msg.joint_velocity, float)
            if msg.num_joints != 7 or q.shape != (7,) or v.shape != (7,):
                raise RecordingError(f"{where}: a {channel} message has {msg.num_joints} joints, "
                                     "expected 7")
            if np.all(np.isfinite(ball)):   # samples start with the first ball estimate
                rows.append((ts, msg.utime, q, v, tau.copy(), ball.copy()))
    for ch in (status_channel, ball_channel):
        if ch not in seen:
            raise RecordingError(f"{where}: no {ch} messages in the log")
    if len(rows) < 2:
        raise RecordingError(f"{where}: fewer than 2 {status_channel} samples after the first "
                             f"{ball_channel}")
    ts = np.array([r[0] for r in rows], float)
    keep = np.r_[True, np.diff(ts) > 0]        # strictly increasing time
    rows = [r for r, k in zip(rows, keep) if k]
    if dt and dt > 0:     # uniform grid: the newest status at or before each grid time
        ts = np.array([r[0] for r in rows], float) * 1e-6
        grid = ts[0] + dt * np.arange(int(np.floor((ts[-1] - ts[0]) / dt + 1e-9)) + 1)
        idx = np.searchsorted(ts, grid + 1e-9, side="right") - 1
        rows = [(int(round(g * 1e6)),) + rows[i][1:] for g, i in zip(grid, idx)]
        if len(rows) < 2:
            raise RecordingError(f"{where}: the log spans less than one step of {dt} s")
    arm = ArmModel()
    T = len(rows)
    x = np.zeros((T, len(STATE_NAMES)))
    u = np.zeros((T, len(INPUT_NAMES)))
    for i, (_, _, q, v, tq, b) in enumerate(rows):
        arm.set_state(q, v)
        p, _ = arm.tip_pose()
        J = arm.tip_jacobian()
        x[i, 0:3], x[i, 10:13] = p, (J @ v)[3:]
        x[i, 3:7] = [1.0, 0.0, 0.0, 0.0]
        x[i, 7:10] = b[:3]
        x[i, 16:19] = [b[3], b[4], 0.0]
        z = b[2] if b[2] > 1e-3 else 1e-3
        x[i, 13:16] = np.cross([0.0, 0.0, 1.0], x[i, 16:19]) / z
        # tau = J' w, w = [torque; force]: least squares for w, keep the force
        w, *_ = np.linalg.lstsq(J.T, tq, rcond=None)
        u[i] = w[3:]
    t = (np.array([r[0] for r in rows], float) - rows[0][0]) * 1e-6
    return Recording(t=t, x=x, u=u, state_names=list(STATE_NAMES),
                     input_names=list(INPUT_NAMES), scenario=scenario_text,
                     extras={"q": np.array([r[2] for r in rows]),
                             "v": np.array([r[3] for r in rows]),
                             "tau_cmd": np.array([r[4] for r in rows]),
                             "ball_estimate": np.array([r[5] for r in rows]),
                             "status_utime": np.array([r[1] for r in rows], np.int64)})


def cmd_record_convert(args) -> int:
    from adaptive_c3.tools.user_input import UserError, resolve_scenario_path
    text = ""
    if args.scenario:
        from adaptive_c3.scenarios.schema import load_scenario
        _, text = load_scenario(resolve_scenario_path(args.scenario))
    out = Path(args.out)
    if out.suffix != ".npz":
        raise UserError(f"output must be a .npz file, got {out}")
    if not out.parent.is_dir():
        raise UserError(f"output folder does not exist: {out.parent}")
    if not (args.dt >= 0):
        raise UserError(f"--dt must be >= 0, got {args.dt}")
    rec = convert_lcm_log(args.log, scenario_text=text, dt=args.dt)
    save_recording(out, rec)
    print(f"{out}: {len(rec.t)} samples over {rec.t[-1]:.2f} s, x {rec.x.shape[1]} states, "
          f"u {rec.u.shape[1]} inputs ({', '.join(rec.input_names)})")
    return 0


__all__ = ["LcmLogWriter", "read_lcm_log", "convert_lcm_log", "cmd_record_convert"]
