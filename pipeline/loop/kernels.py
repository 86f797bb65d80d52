"""The closed loop's innermost arithmetic as one value: a set of callables, each a statement of
the loop stages run by CPython (:data:`pipeline.loop.python_kernels.PYTHON_KERNELS`) or
compiled by numba (:data:`pipeline.loop.compiled.COMPILED_KERNELS`), the same bits either way.

A run is handed one :class:`Kernels` (the family runner chooses the compiled set once a process
has runs enough to pay numba's start-up); the plant, the planner and the controllers call
through it and never ask which set they hold, except to prepare their arguments
(:meth:`Kernels.prepare`: lists for CPython, whose arithmetic on numpy scalars is slower;
contiguous arrays for numba). This module imports nothing of the pipeline, so every stage may
name the type without an import circle.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, NamedTuple

import numpy as np

from pipeline.loop.arrays import KernelValues


class Kernels(NamedTuple):
    """One set of the loop's kernels (see the module docstring).

    Attributes
    ----------
    compiled : bool
        Whether the callables are numba's (arrays in) or CPython's (lists in).
    plant_rk4 : callable
        :func:`pipeline.loop.model.single_track_rk4`.
    apf_rollout : callable
        :func:`pipeline.loop.planner.apf_rollout_arrays`.
    references : callable
        :func:`pipeline.loop.controller.references.reference_arrays`.
    chase_path, rollout_path, frame_step, plan_poses : callable
        :func:`pipeline.loop.controller.path.chase_path_arrays`, ``rollout_path_arrays``,
        ``frame_step_arrays``, ``plan_poses_arrays``.
    check_record : callable
        :func:`pipeline.loop.controller.prediction_check.check_record_arrays`.
    plant_rk4_rows : callable
        :func:`pipeline.loop.model.single_track_rk4_rows`: the plants of the members the
        lockstep engine steps at once (:mod:`pipeline.loop.engine`).
    halfplanes : callable
        :func:`pipeline.loop.controller.references.lateral_side_halfplane_arrays`.
    path_frame_rows, plan_poses_rows : callable
        :func:`pipeline.loop.controller.path_rows.path_frame_rows` and ``plan_poses_rows``:
        the path frame of the lateral MPCs the lockstep engine steps at once.
    daqp_rows : callable or None
        :func:`pipeline.loop.controller.daqp_rows.daqp_condensed_rows`: their QPs condensed
        and solved by DAQP's C interface (compiled only: it calls C by address; None in
        CPython's set, whose members step alone).
    direct_theta_rows, direct_readout_rows : callable or None
        :func:`pipeline.loop.controller.direct_rows.direct_theta_rows` and
        ``direct_readout_rows``: the data and read-out of their QPs on the ``clarabel_direct``
        backend around each member's own Clarabel solver (compiled only, as ``daqp_rows``).
    observe_plan_rows, frame_rows, solve_rows, apply_rows, theta_rows, readout_rows, check_rows : callable or None
        :mod:`pipeline.loop.group_rows`: the whole step of the members the engine steps as
        one group of arrays (:mod:`pipeline.loop.lateral_group`; compiled only: None in
        CPython's set, whose members step through their own loops).
    """

    compiled: bool
    plant_rk4: Callable[..., Any]
    apf_rollout: Callable[..., Any]
    references: Callable[..., Any]
    chase_path: Callable[..., Any]
    rollout_path: Callable[..., Any]
    frame_step: Callable[..., Any]
    plan_poses: Callable[..., Any]
    check_record: Callable[..., Any]
    plant_rk4_rows: Callable[..., Any]
    halfplanes: Callable[..., Any]
    path_frame_rows: Callable[..., Any]
    plan_poses_rows: Callable[..., Any]
    daqp_rows: Callable[..., Any] | None
    direct_theta_rows: Callable[..., Any] | None = None
    direct_readout_rows: Callable[..., Any] | None = None
    observe_plan_rows: Callable[..., Any] | None = None
    frame_rows: Callable[..., Any] | None = None
    solve_rows: Callable[..., Any] | None = None
    apply_rows: Callable[..., Any] | None = None
    theta_rows: Callable[..., Any] | None = None
    readout_rows: Callable[..., Any] | None = None
    check_rows: Callable[..., Any] | None = None

    def prepare(self, values: object) -> KernelValues:
        """``values`` as this set's callables take them: a contiguous float array for numba, a
        (nested) list for CPython."""
        if self.compiled:
            return np.ascontiguousarray(values, dtype=float)
        return np.asarray(values, dtype=float).tolist()
