"""WireListener: LCM messages on a udpm:// URL with the time the kernel received each one.

A listener that timestamps messages in its Python callback measures its own scheduling
as well: on this 2-core VM, a SCHED_FIFO 90 Python listener over DrakeLcm saw the
simulated driver's statuses 0.3 ms (p50) and 2-3 ms (p99) after the driver stamped them,
while the impedance loop's own tick period had p99 1.35 ms. This listener reads the
multicast group on a plain UDP socket with SO_TIMESTAMPNS, so each message carries the
moment the packet reached the loopback receive path - the moment any subscriber's
socket, the driver's included, has it - whenever this process gets round to reading it.

LCM's small-message packet (lcm-udpm, messages under 64 kB; ours are < 1 kB): uint32
magic "LC02", uint32 sequence number, the channel name NUL-terminated, then the
message's own encoding (fingerprint first). Fragmented packets ("LC03") are skipped.
"""
from __future__ import annotations

import select
import socket
import struct

_MAGIC_SHORT = 0x4C433032
_SO_TIMESTAMPNS = getattr(socket, "SO_TIMESTAMPNS", 35)   # Linux; SCM_TIMESTAMPNS is the same


class WireListener:
    def __init__(self, url: str):
        from adaptive_c3.tools.hardware.lcm_channels import parse_udpm_url
        parsed = parse_udpm_url(url)
        if parsed is None:
            raise ValueError(f"WireListener needs a udpm:// URL, got '{url}'")
        group, port = parsed
        self._sock = s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM, socket.IPPROTO_UDP)
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        if hasattr(socket, "SO_REUSEPORT"):
            s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEPORT, 1)
        s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4 << 20)
        s.bind(("", port))
        s.setsockopt(socket.IPPROTO_IP, socket.IP_ADD_MEMBERSHIP,
                     socket.inet_aton(group) + socket.inet_aton("0.0.0.0"))
        s.setsockopt(socket.SOL_SOCKET, _SO_TIMESTAMPNS, 1)
        s.setblocking(False)
        self._callbacks: dict = {}
        self.packets = self.skipped = 0

    def subscribe(self, channel: str, callback) -> None:
        """callback(arrival_s, message_bytes): arrival on the wall clock (time.time())."""
        self._callbacks[channel.encode()] = callback

    def handle(self, timeout_s: float) -> int:
        """Wait up to timeout_s for packets, deliver all that are queued; returns how many."""
        if not select.select([self._sock], [], [], timeout_s)[0]:
            return 0
        n = 0
        while True:
            try:
                data, anc, _, _ = self._sock.recvmsg(65536, 64)
            except BlockingIOError:
                return n
            n += 1
            self.packets += 1
            arrival = None
            for level, kind, payload in anc:
                if level == socket.SOL_SOCKET and kind == _SO_TIMESTAMPNS:
                    sec, nsec = struct.unpack_from("qq", payload)
                    arrival = sec + 1e-9 * nsec
            if len(data) < 9 or struct.unpack_from(">I", data)[0] != _MAGIC_SHORT or arrival is None:
                self.skipped += 1
                continue
            end = data.find(b"\0", 8)
            cb = self._callbacks.get(data[8:end]) if end > 0 else None
            if cb is not None:
                cb(arrival, data[end + 1:])

    def close(self) -> None:
        self._sock.close()
