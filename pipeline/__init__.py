"""Reference reproduction of Yoo & Choi (2025), "Improved Model Predictive Control for Dynamical
Obstacle Avoidance".

The package reads in data-flow order:

* :mod:`pipeline.config` - the composed configuration (schemas live beside their stages);
* :mod:`pipeline.loop` - scenario, vehicle model, planner (APF), controller (MPC), simulate;
* :mod:`pipeline.analysis` - metrics and claims: pure functions of a record;
* :mod:`pipeline.store` - the run-folder layout, its only reader and writer;
* :mod:`pipeline.studies` - experiment, family, sweeps, ablation, multiverse, verify, bench;
* :mod:`pipeline.reporting` - figures, sections and the HTML page.

The entry modules (``python -m pipeline.run``, ``.report``, ``.aggregate``, ``.multiverse``,
``.verify``, ``.bench``, ``.score``) are thin wrappers over those stages.
"""

from __future__ import annotations

from importlib.metadata import PackageNotFoundError, version

from pipeline.numerics import pin_numerical_kernels

# before anything of the package imports numpy: the same kernels, so the same bits, on every
# x86-64 machine (see pipeline.numerics)
pin_numerical_kernels()

try:
    __version__ = version("apf-mpc-repro")
except PackageNotFoundError:  # run from a source tree that was never installed
    __version__ = "0+unknown"
