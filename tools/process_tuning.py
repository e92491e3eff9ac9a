"""Process settings for a fast closed loop on a small CPU-only machine (issue 18).

`tune_allocator()`: glibc's malloc keeps freed memory instead of handing it back to the
kernel (M_MMAP_THRESHOLD 256 MiB, M_TRIM_THRESHOLD 512 MiB; they also stop glibc's
dynamic threshold). By default every large buffer - the renderer's per-frame images,
numpy temporaries over 128 kB - is a fresh mmap, and every first touch of its pages a
page fault that zeroes a page: 8 % of a camera frame's time in the kernel (perf). Measured
with `bench loop` on 2 cores: real-time factor camera on 0.88 -> 1.01, camera off 2.08 ->
2.23. The cost is a process that keeps its peak heap (tens of MB here).

The renderer's setting lives with the camera (systems/perception/camera.py,
LP_NUM_THREADS). Both change speed only, never what is simulated.
"""
from __future__ import annotations

import ctypes
import ctypes.util

M_TRIM_THRESHOLD, M_MMAP_THRESHOLD = -1, -3


def tune_allocator(mmap_threshold: int = 256 << 20, trim_threshold: int = 512 << 20) -> bool:
    """Apply the malloc settings above; False where glibc's mallopt is not available."""
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        mallopt = libc.mallopt
    except (OSError, AttributeError):
        return False
    mallopt.argtypes, mallopt.restype = [ctypes.c_int, ctypes.c_int], ctypes.c_int
    return bool(mallopt(M_MMAP_THRESHOLD, mmap_threshold)) and bool(
        mallopt(M_TRIM_THRESHOLD, trim_threshold))
