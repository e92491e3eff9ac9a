"""The LCM layout the bridge, the simulated driver and `record convert` share.

Channels: PANDA_STATUS (drake.lcmt_panda_status), PANDA_COMMAND (drake.lcmt_panda_command,
joint torques in N m without gravity) and BALL_ESTIMATE (drake.lcmt_robot_state in the
BALL_ESTIMATE_NAMES layout: ball centre in m and velocity in m/s, robot base frame, table
top z = 0). Also: opening an LCM URL with a one-line error, cheap message copies.
"""
from __future__ import annotations

import time

import numpy as np

STATUS_CHANNEL = "PANDA_STATUS"
COMMAND_CHANNEL = "PANDA_COMMAND"
BALL_CHANNEL = "BALL_ESTIMATE"
BALL_ESTIMATE_NAMES = ("ball_x", "ball_y", "ball_z", "ball_vx", "ball_vy", "ball_vz")
NQ = 7


def fast_lcm_copies(*types) -> None:
    """Let lcm-gen Python message classes be shared instead of deep-copied.

    LcmSubscriberSystem keeps the newest message in abstract state, which Drake clones
    (copy.deepcopy) on every unrestricted update and context copy: the generic deepcopy
    of a status costs ~100 us, an encode + decode ~10 us, at 1 kHz and several ports a
    tenth of the impedance loop's budget. Messages on our ports are values nobody
    changes in place (every producer builds a new message: the subscribers decode one
    per arrival, the encoders build one per output), so a copy may be the message
    itself."""
    for cls in types:
        if "__deepcopy__" not in cls.__dict__:
            cls.__deepcopy__ = _shared_copy


def _shared_copy(msg, memo):
    return msg


def fast_drake_lcm_copies():
    from drake import lcmt_panda_command, lcmt_panda_status, lcmt_robot_state
    fast_lcm_copies(lcmt_panda_command, lcmt_panda_status, lcmt_robot_state)


def decode_ball_estimate(msg) -> np.ndarray:
    """(6) [p, v] from a BALL_ESTIMATE message, all NaN if it does not fit the layout."""
    try:
        if (msg.num_joints == len(BALL_ESTIMATE_NAMES)
                and tuple(msg.joint_name) == BALL_ESTIMATE_NAMES):
            v = np.asarray(msg.joint_position, float)
            if v.shape == (6,) and np.all(np.isfinite(v)):
                return v
    except (TypeError, ValueError):
        pass
    return np.full(6, np.nan)


def parse_udpm_url(url: str):
    """(multicast group, port) of a udpm://GROUP:PORT[?options] URL, None if it is not one."""
    import ipaddress
    import re
    m = re.fullmatch(r"udpm://([0-9.]+):(\d+)(\?.*)?", url)
    try:
        if m and ipaddress.ip_address(m.group(1)).is_multicast and 0 < int(m.group(2)) < 65536:
            return m.group(1), int(m.group(2))
    except ValueError:
        pass
    return None


def open_lcm(url: str):
    """A DrakeLcm on `url`, or a UserError for a URL LCM cannot open."""
    from pydrake.lcm import DrakeLcm

    from adaptive_c3.tools.user_input import UserError
    if not url or "://" not in url:
        raise UserError(f"bad --lcm-url '{url}': expected e.g. udpm://239.255.76.67:7667?ttl=0 "
                        "or memq://")
    provider = url.split("://", 1)[0]
    if provider not in ("udpm", "memq"):
        raise UserError(f"bad --lcm-url '{url}': unknown LCM provider '{provider}'")
    if provider == "udpm" and parse_udpm_url(url) is None:
        raise UserError(f"bad --lcm-url '{url}': expected udpm://MULTICAST_IP:PORT[?ttl=N]")
    try:
        lcm = DrakeLcm(url)
    except Exception as e:
        raise UserError(f"cannot open LCM at '{url}': {' '.join(str(e).split())}")
    # LCM reports a bad URL on stderr only: check that a message gets through
    got = []
    probe = "ADAPTIVE_C3_PROBE"
    lcm.Subscribe(probe, got.append)
    lcm.Publish(probe, b"probe")
    deadline = time.monotonic() + 1.0
    while not got and time.monotonic() < deadline:
        lcm.HandleSubscriptions(50)
    if not got:
        raise UserError(f"cannot send/receive on LCM at '{url}'")
    return lcm


# ---------------------------------------------------------------- the planner's EE plan
PLAN_CHANNEL = "EE_PLAN"
# drake.lcmt_robot_state in this layout: the impedance target from the planner process,
# robot base frame; utime = the PANDA_STATUS utime the plan was computed from (the
# driver's clock), so the impedance process can judge the plan's age in that clock
PLAN_NAMES = ("ee_x", "ee_y", "ee_z",          # desired EE tip position, m
              "ee_vx", "ee_vy", "ee_vz",       # desired EE tip velocity, m/s
              "ee_fx", "ee_fy", "ee_fz")       # feed-forward force at the tip, N


def encode_plan(utime: int, desired_state, feedforward):
    """An lcmt_robot_state in the EE_PLAN layout."""
    from drake import lcmt_robot_state
    msg = lcmt_robot_state()
    msg.utime = int(utime)
    msg.num_joints = len(PLAN_NAMES)
    msg.joint_name = list(PLAN_NAMES)
    msg.joint_position = [float(v) for v in np.r_[desired_state, feedforward]]
    return msg


def decode_plan(msg) -> np.ndarray | None:
    """(9) [p, v, f] from an EE_PLAN message, None if it does not fit the layout."""
    try:
        if msg.num_joints == len(PLAN_NAMES) and tuple(msg.joint_name) == PLAN_NAMES:
            v = np.asarray(msg.joint_position, float)
            if v.shape == (len(PLAN_NAMES),) and np.all(np.isfinite(v)):
                return v
    except (TypeError, ValueError):
        pass
    return None
