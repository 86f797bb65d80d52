"""The array types the loop and the analysis annotate with (numpy's, named once)."""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

#: An array of float64 (states, inputs, trajectories, QP data).
FloatArray = npt.NDArray[np.float64]
#: An array of flags.
BoolArray = npt.NDArray[np.bool_]
#: An array of any dtype (what a library hands back without saying which).
AnyArray = npt.NDArray[Any]
#: What a kernel takes (:mod:`pipeline.loop.kernels`): a contiguous float array under numba, a
#: (nested) list of floats in CPython; the same statements run on either.
KernelValues = Any
