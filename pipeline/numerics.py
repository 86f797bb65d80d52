"""The same bits on every x86-64 machine: which compiled kernels numpy and OpenBLAS may use.

The closed loop is sensitive to the last bit: a QP whose active set changes on a rounding
difference steers differently from then on (measured on the paper scenario: OpenBLAS's Haswell
kernels against its Nehalem ones change 20 of the reference's numbers, one of them by 13 %).
numpy and OpenBLAS choose their kernels by the processor they find, so the same commit gave
other numbers on an AVX-512 machine than on an AVX2 one, and the reference in
``reports/reference/`` could hold on one kind of machine only.

Importing :mod:`pipeline` therefore sets, unless the user set them already:

* ``OPENBLAS_CORETYPE=Nehalem`` - OpenBLAS's SSE4.2 kernels, which every processor numpy's
  wheels run on has (they need x86-64-v2); the loop's products are tiny and run on one thread
  (:func:`pipeline.loop.simulate.simulate`), so the wider kernels bought nothing measurable
  (paper runs of every method: 6.4 s against 6.9 s with Haswell's, on a 2-core machine);
* ``NPY_DISABLE_CPU_FEATURES`` - numpy's dispatched kernels above its x86-64-v2 baseline
  (AVX2, AVX-512), whose ``exp``, ``log``, ``sin`` and ``cos`` are numpy's own where the
  baseline's are the C library's.

Both are read when numpy loads its libraries: set after ``import numpy`` they change nothing.
:func:`numerical_kernels` says what is in effect; the member cache keys its entries by it and
the report's provenance prints it. On other architectures nothing is set.
"""

from __future__ import annotations

import os
import platform
import sys
import warnings

#: What importing :mod:`pipeline` sets on x86-64, where the variable is not set already.
PINNED_KERNELS = {
    "OPENBLAS_CORETYPE": "Nehalem",
    "NPY_DISABLE_CPU_FEATURES": "X86_V3 X86_V4 AVX512_ICL AVX512_SPR",
}


def pin_numerical_kernels() -> None:
    """Set :data:`PINNED_KERNELS` in this process's environment (and so its workers'), each
    only where the user has not set it; nothing on a processor other than x86-64."""
    if platform.machine().lower() not in ("x86_64", "amd64"):
        return
    unset = [name for name in PINNED_KERNELS if name not in os.environ]
    for name in unset:
        os.environ[name] = PINNED_KERNELS[name]
    if unset and "numpy" in sys.modules:
        warnings.warn("numpy was imported before pipeline, so it runs the kernels this processor "
                      "chose: numbers may differ from the reference in their last bits (import "
                      "pipeline first, or set " + " and ".join(unset) + " as in "
                      "pipeline.numerics.PINNED_KERNELS)", RuntimeWarning, stacklevel=3)


def numerical_kernels() -> dict[str, str]:
    """The kernels in effect in this process: numpy's dispatched SIMD levels and OpenBLAS's
    core type, e.g. ``{"numpy_simd": "X86_V2", "openblas": "Nehalem"}``.

    ``openblas`` is OpenBLAS's own answer where threadpoolctl finds it (``unknown`` otherwise);
    ``numpy_simd`` is the baseline plus every dispatched level numpy uses.
    """
    from numpy._core import _multiarray_umath as umath  # type: ignore[attr-defined]

    levels = list(umath.__cpu_baseline__)
    levels += [name for name in umath.__cpu_dispatch__ if umath.__cpu_features__.get(name)]
    openblas = "unknown"
    try:
        from threadpoolctl import threadpool_info

        for library in threadpool_info():
            if library.get("internal_api") == "openblas" and "numpy" in library.get("filepath", ""):
                openblas = str(library.get("architecture", "unknown"))
    except Exception:  # threadpoolctl absent or a library it cannot read: say so, go on
        pass
    return {"numpy_simd": " ".join(levels), "openblas": openblas}
