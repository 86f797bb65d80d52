"""Compiled (numba) runs of the closed loop's innermost arithmetic, for long studies.

Each kernel here is a function of the loop stages compiled as it stands: one statement, run
by CPython in a single run and by numba in the family runner's workers.

* :func:`single_track_rk4` is :func:`pipeline.loop.model.single_track_rk4`, the nonlinear
  single-track plant's RK4 step (about 120 us per step as Python floats on a 2-core machine
  here, about 9 us compiled), and :func:`single_track_rk4_rows` the same for every member the
  lockstep engine steps at once (:mod:`pipeline.loop.engine`);
* :func:`apf_rollout_kernel` is :func:`pipeline.loop.planner.apf_rollout_arrays`, the APF
  rollout (about 65 us and 20 us with the call);
* :func:`reference_kernel` is :func:`pipeline.loop.controller.references.reference_arrays`,
  the lateral MPC's references at its stations (about 35 us and 10 us with the call);
* :func:`rollout_path_kernel`, :func:`chase_path_kernel`, :func:`frame_step_kernel`,
  :func:`plan_poses_kernel` and :func:`check_record_kernel` are the path frame's statements
  (:mod:`pipeline.loop.controller.path`): the reference path (the rollout, or its pursuit),
  one step's stations and obstacle coordinates, a plan's poses, one step's prediction check;
  :func:`halfplane_kernel` its collision half-planes
  (:func:`pipeline.loop.controller.references.lateral_side_halfplane_arrays`), and
  :func:`path_frame_rows_kernel`, :func:`plan_poses_rows_kernel` the same for every lateral MPC
  the lockstep engine steps at once (:mod:`pipeline.loop.controller.path_rows`);
* :func:`daqp_rows_kernel` is :func:`pipeline.loop.controller.daqp_rows.daqp_condensed_rows`,
  their QPs condensed and solved on each member's kept DAQP workspace (DAQP's C functions
  called by address: this one has no CPython twin, a member stepped alone fills the same
  workspace from numpy, :class:`pipeline.loop.controller.lateral_backends.DaqpCondensedQp`);
* :func:`direct_theta_rows_kernel` and :func:`direct_readout_rows_kernel` are
  :func:`pipeline.loop.controller.direct_rows.direct_theta_rows` and ``direct_readout_rows``:
  the data of their QPs on the ``clarabel_direct`` backend, and what is read from each
  member's solution (no CPython twin either: a member stepped alone runs the numpy statement
  of :meth:`pipeline.loop.controller.lateral.LateralMpc.solve`).

Compiled without fast-math, they do the same operations in the same order on the same C
library's ``atan2``, ``tanh``, ``exp``, ``cos`` and ``sin``, so they give the same bits (the
tests hold them equal with ``==``, and whole closed loops equal). The one difference in
semantics, an overflowing ``exp``, is bridged by an overload of ``planner._exp_or_inf``.

Importing this module imports numba and loads the kernels from numba's on-disk cache (about
1.5 s each the first time, when it compiles). That pays back only over several runs per process
(measured: :data:`pipeline.studies.experiment.COMPILED_KERNELS_MIN_MEMBERS`), so the family
runner turns it on
(:attr:`pipeline.loop.controller.QpCache.compiled_kernels`) and a single run does not. They are
handed to a run as one value, :data:`COMPILED_KERNELS` (:class:`pipeline.loop.kernels.Kernels`);
nothing in the loop imports this module but :func:`pipeline.loop.simulate.run_kernels`.
"""

from __future__ import annotations

from collections.abc import Callable
from math import exp
from typing import Any

from numba import njit
from numba.extending import overload

from pipeline.loop import group_rows, model, planner, scenario
from pipeline.loop.controller import (
    daqp_rows,
    direct_rows,
    lateral_qp,
    path,
    path_rows,
    prediction_check,
    references,
)
from pipeline.loop.kernels import Kernels


def _jit(function: Callable[..., Any]) -> Callable[..., Any]:
    """``numba.njit`` with numba's on-disk cache, or without it where no cache folder is
    writable (numba refuses ``cache=True`` there; the kernel is then compiled once per
    process)."""
    try:
        return njit(cache=True, nogil=True)(function)
    except RuntimeError:
        return njit(nogil=True)(function)


def _exp_or_inf_compiled(x: float) -> Callable[[float], float]:  # pragma: no cover (numba's)
    """Compiled, ``exp`` overflows to ``inf`` without raising (numba compares the typing
    function's signature with the implementation's, annotations included)."""
    def implementation(x: float) -> float:
        return exp(x)

    return implementation


overload(planner._exp_or_inf)(_exp_or_inf_compiled)


def _same_signature(function: Callable[..., Any]) -> Callable[..., Any]:
    """numba's typing function for ``overload(function)``: ``function`` itself is the
    implementation (a helper the kernels call, compiled with them)."""
    import inspect

    def typer(*args: Any) -> Callable[..., Any]:
        return function

    typer.__signature__ = inspect.signature(function)  # type: ignore[attr-defined]
    return typer


for _helper in (path._polyline, path._heading_at, path._curvature_at, path._project_point,
                path._point_at, model.single_track_kinematic_substep, model.single_track_rk4,
                path.rollout_path_arrays, path.frame_step_arrays, path.plan_poses_arrays,
                references.lateral_side_halfplane_arrays, scenario.route_point_ahead,
                daqp_rows.condensed_free, daqp_rows.plan_readout, daqp_rows.slots_in_use, lateral_qp.direct_theta_size,
                planner.apf_rollout_arrays, path_rows.path_frame_rows, path_rows.plan_poses_rows,
                daqp_rows.daqp_condensed_rows, group_rows._tyre_slip, group_rows._plant_columns,
                group_rows._settings_of, group_rows._status_code, group_rows._grid_key,
                group_rows._as_int, group_rows._finite_members,
                group_rows._qp_arrays, direct_rows.direct_theta_rows,
                direct_rows.direct_readout_rows, prediction_check.check_record_arrays):
    overload(_helper)(_same_signature(_helper))

single_track_rk4 = _jit(model.single_track_rk4)
single_track_rk4_rows = _jit(model.single_track_rk4_rows)
apf_rollout_kernel = _jit(planner.apf_rollout_arrays)
reference_kernel = _jit(references.reference_arrays)
chase_path_kernel = _jit(path.chase_path_arrays)
rollout_path_kernel = _jit(path.rollout_path_arrays)
frame_step_kernel = _jit(path.frame_step_arrays)
plan_poses_kernel = _jit(path.plan_poses_arrays)
check_record_kernel = _jit(prediction_check.check_record_arrays)
halfplane_kernel = _jit(references.lateral_side_halfplane_arrays)
path_frame_rows_kernel = _jit(path_rows.path_frame_rows)
plan_poses_rows_kernel = _jit(path_rows.plan_poses_rows)
daqp_rows_kernel = _jit(daqp_rows.daqp_condensed_rows)
direct_theta_rows_kernel = _jit(direct_rows.direct_theta_rows)
direct_readout_rows_kernel = _jit(direct_rows.direct_readout_rows)
observe_plan_rows_kernel = _jit(group_rows.observe_plan_rows)
frame_rows_kernel = _jit(group_rows.frame_rows)
solve_rows_kernel = _jit(group_rows.solve_rows)
apply_rows_kernel = _jit(group_rows.apply_rows)
theta_rows_kernel = _jit(group_rows.theta_rows)
readout_rows_kernel = _jit(group_rows.readout_rows)
check_rows_kernel = _jit(group_rows.check_rows)

#: The compiled set (immutable: a named tuple of numba's dispatchers).
COMPILED_KERNELS = Kernels(True, single_track_rk4, apf_rollout_kernel, reference_kernel,
                           chase_path_kernel, rollout_path_kernel, frame_step_kernel,
                           plan_poses_kernel,
                           check_record_kernel, single_track_rk4_rows, halfplane_kernel,
                           path_frame_rows_kernel, plan_poses_rows_kernel, daqp_rows_kernel,
                           direct_theta_rows_kernel, direct_readout_rows_kernel,
                           observe_plan_rows_kernel, frame_rows_kernel, solve_rows_kernel,
                           apply_rows_kernel, theta_rows_kernel, readout_rows_kernel,
                           check_rows_kernel)
