"""A small text progress bar on stderr (silent when stderr is not a terminal
unless forced), used by long simulations and sweeps."""
from __future__ import annotations

import os
import sys
import time


class Progress:
    def __init__(self, total: float, label: str = "", unit: str = "s", enabled: bool | None = None):
        self.total = float(total) if total else 1.0
        self.label = label
        self.unit = unit
        self.start = time.perf_counter()
        if enabled is None:
            enabled = sys.stderr.isatty() or os.environ.get("ADAPTIVE_C3_PROGRESS") == "1"
        self.enabled = enabled
        self._last = -1.0

    def update(self, done: float) -> None:
        if not self.enabled:
            return
        now = time.perf_counter()
        if now - self._last < 0.2 and done < self.total:
            return
        self._last = now
        frac = min(max(done / self.total, 0.0), 1.0)
        width = 30
        bar = "#" * int(frac * width) + "-" * (width - int(frac * width))
        elapsed = now - self.start
        eta = elapsed * (1 - frac) / frac if frac > 0 else float("nan")
        sys.stderr.write(f"\r{self.label} [{bar}] {done:.1f}/{self.total:.1f} {self.unit} "
                         f"elapsed {elapsed:.0f}s eta {eta:.0f}s ")
        sys.stderr.flush()

    def close(self, done: float | None = None) -> None:
        """End the bar at `done` (default: the total)."""
        if self.enabled:
            self._last = -1.0
            self.update(self.total if done is None else done)
            sys.stderr.write("\n")
            sys.stderr.flush()
