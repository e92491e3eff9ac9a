"""FiniteOr: a vector passed through, or a fallback if any entry is not finite."""
from __future__ import annotations

import numpy as np
from pydrake.systems.framework import LeafSystem


class FiniteOr(LeafSystem):
    """Passes a vector through, or `fallback` if it has a non-finite entry (stateless):
    keeps the controller's pipeline finite; the watchdog latches the stop itself."""

    def __init__(self, fallback):
        super().__init__()
        self._fb = np.asarray(fallback, float)
        self._in = self.DeclareVectorInputPort("u", self._fb.size)
        self.DeclareVectorOutputPort("y", self._fb.size, self._calc)

    def _calc(self, context, output):
        x = self._in.Eval(context)
        output.SetFromVector(x if np.all(np.isfinite(x)) else self._fb)
