"""The loop's kernels run by CPython (:class:`pipeline.loop.kernels.Kernels`): what a single run
uses, and the statements :mod:`pipeline.loop.compiled` compiles."""

from __future__ import annotations

from pipeline.loop.controller.path import (
    chase_path_arrays,
    frame_step_arrays,
    plan_poses_arrays,
    rollout_path_arrays,
)
from pipeline.loop.controller.path_rows import path_frame_rows, plan_poses_rows
from pipeline.loop.controller.prediction_check import check_record_arrays
from pipeline.loop.controller.references import lateral_side_halfplane_arrays, reference_arrays
from pipeline.loop.kernels import Kernels
from pipeline.loop.model import single_track_rk4, single_track_rk4_rows
from pipeline.loop.planner import apf_rollout_arrays

#: The CPython set (immutable: a named tuple of functions).
PYTHON_KERNELS = Kernels(False, single_track_rk4, apf_rollout_arrays, reference_arrays,
                         chase_path_arrays, rollout_path_arrays, frame_step_arrays,
                         plan_poses_arrays,
                         check_record_arrays, single_track_rk4_rows,
                         lateral_side_halfplane_arrays, path_frame_rows, plan_poses_rows, None)
