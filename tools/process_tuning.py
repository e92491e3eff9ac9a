"""Process settings for a fast closed loop on a small CPU-only machine (issue 18).

`tune_allocator()`: glibc's malloc keeps freed memory instead of handing it back to the
kernel (M_MMAP_THRESHOLD 256 MiB, M_TRIM_THRESHOLD 512 MiB; they also stop glibc's
dynamic threshold). By default every large buffer - the renderer's per-frame images,
numpy temporaries over 128 kB - is a fresh mmap, and every first touch of its pages a
page fault that zeroes a page: 8 % of a camera frame's time in the kernel (perf). Measured
with `bench loop` on 2 cores: real-time factor camera on 0.88 -> 1.01, camera off 2.08 ->
2.23. The cost is a process that keeps its peak heap (tens of MB here).

`limit_library_threads()`: OpenBLAS (numpy's and scipy's, two libraries) starts a
worker per core, and its idle workers spin and yield between calls. Every matrix in the
loop is tiny (at most 19 x 19 and the C3 KKT), so the workers never help; perf put 4.5 %
of the camera-off loop in their spin (`blas_thread_server`). One thread each: the loop
1.5 % faster and the second core left to the renderer, a sweep worker or the bridge's
other processes. OpenCV likewise splits the detector's 160 x 120 frame over a thread
pool whose wake-ups cost more than the split saves (detector 0.80 -> 0.73 ms a frame in
the loop). Set before the libraries load (the CLI calls it first); a value the user
exported is kept.

`frozen_heap()`: a context in which the objects alive when it starts are out of the
cyclic garbage collector's sight (gc.freeze), so that its full collections walk only
what the simulation makes: with pydrake and the built diagram loaded each one walked
~72,000 objects (freeze_heap below). 2 % of the camera-off loop in
perf. The objects are handed back when it ends (gc.unfreeze), so a sweep worker that
builds one diagram a trial does not keep them all.

The renderer's setting lives with the camera (systems/perception/camera.py,
LP_NUM_THREADS). All of these change speed only, never what is simulated.
"""
from __future__ import annotations

import ctypes
import ctypes.util
import gc
import os
from contextlib import contextmanager

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


def limit_library_threads() -> None:
    """One OpenBLAS and one OpenCV thread unless the user chose (see above); takes
    effect only for libraries not loaded yet."""
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    os.environ.setdefault("OPENCV_FOR_THREADS_NUM", "1")


def freeze_heap() -> None:
    """Move every object alive now out of the cyclic garbage collector's sight, for good.

    Python's full (generation 2) collection walks every tracked object. With pydrake,
    the scenario and the built diagram loaded that is about 72,000 objects, and one
    collection took 43 ms on a quiet core and over 100 ms under load. Python starts
    such a collection on its own now and then, and it stopped a 1 kHz loop mid-stream:
    the driver's status had gaps of 110-180 ms. Called once, after start-up and before
    the loop, it leaves the collector only the loop's own new objects (0.002 ms).
    """
    gc.collect()
    gc.freeze()


@contextmanager
def frozen_heap():
    """The objects alive now are left out of the garbage collector's walks until the
    context ends (see above)."""
    freeze_heap()
    try:
        yield
    finally:
        gc.unfreeze()
