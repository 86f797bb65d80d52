"""The collision oracle's reachability search compiled (numba):
:func:`~pipeline.analysis.metrics.geometry.manoeuvre_survives` as it stands, for the processes
that have numba loaded already (a family's workers). Without fast-math, on the same C
library's ``cos``, ``sin``, ``tan`` and ``hypot`` as numpy's: the same answer as the vectorised
search (tests/analysis/test_unavoidable.py holds the two equal on planted cases, and
manoeuvre by manoeuvre on sixty of one of them).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from pipeline.analysis.metrics.geometry import manoeuvre_survives

try:  # numba's on-disk cache; compiled once per process where no cache folder is writable
    manoeuvre_survives_kernel = njit(cache=True, nogil=True)(manoeuvre_survives)
except RuntimeError:  # pragma: no cover (a read-only install)
    manoeuvre_survives_kernel = njit(nogil=True)(manoeuvre_survives)


def warm_kernel() -> None:
    """Compile :data:`manoeuvre_survives_kernel` into numba's on-disk cache on a planted case
    (``make install`` calls it through :mod:`pipeline.warm`: a first family's workers then load
    it instead of compiling it, about 1.5 s)."""
    t = np.arange(3) * 0.1
    one = np.ones(1)
    manoeuvre_survives_kernel(t, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 2, 0.02, 0.01, 2.5, 1.0,
                              one, one, one, one, one * np.inf, np.zeros(1, dtype=np.int64),
                              np.full((1, 3, 2), 5.0), np.zeros((1, 3, 2)), np.ones((1, 3)))
