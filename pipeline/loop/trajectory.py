"""The trajectory table's columns, declared once: the simulator writes them in this order and
every reader (metrics, score, figures) finds them here.

Units are in the names (``_m``, ``_rad``, ``_mps``, ``_s``). A scored external trajectory needs
only :data:`REQUIRED`; the others, when present, make the metrics exact instead of derived from
the path (see :mod:`pipeline.studies.score`).
"""

from __future__ import annotations

import re
from collections.abc import Iterable

#: Columns every trajectory has.
REQUIRED = ("time_s", "X_m", "Y_m")
#: Plant state and applied input; derived from the path when a scored trajectory lacks them.
STATE = ("psi_rad", "vx_mps", "vy_mps", "r_rad_s", "delta_rad", "steering_rate_rad_s")
#: Line-frame errors, the kinematic track's acceleration and the references fed to the MPC.
REFERENCES = ("e_y_m", "e_psi_rad", "accel_mps2", "speed_ref_mps", "y_ref_m", "psi_ref_rad")
#: The APF's next point, rollout end, forces at the vehicle and whether its step limits bound.
APF = ("apf_next_x_m", "apf_next_y_m", "apf_end_x_m", "apf_end_y_m", "apf_att_x", "apf_att_y",
       "apf_rep_x", "apf_rep_y", "apf_rep_norm", "apf_step_capped", "apf_step_min_used",
       "apf_step_cap_share")
#: Per-obstacle columns, ``j`` = 0, 1, ...: centre, radius and whether it is visible yet.
OBSTACLE_FIELDS = ("x_m", "y_m", "radius_m", "visible")
#: Solver bookkeeping (``ltv_*`` on the kinematic track only).
SOLVER = ("solver_status", "solver_iterations", "fallback", "max_slack_m", "ltv_passes",
          "ltv_change")

#: Column order of a simulated trajectory; obstacle columns follow :data:`HEAD`.
HEAD = REQUIRED + ("psi_rad", "vx_mps", "vy_mps", "r_rad_s", "delta_rad", "e_y_m", "e_psi_rad",
                   "steering_rate_rad_s", "accel_mps2", "speed_ref_mps", "y_ref_m",
                   "psi_ref_rad") + APF
#: The lateral MPC's path frame (path coordinates), the plant's tyres, and how each step's
#: prediction held against the plant (:mod:`pipeline.loop.controller.path`).
MODEL = ("path_beyond_limit", "path_curvature_1_per_m", "r_d_rad_s", "tyre_slip_norm",
         "model_heading_error_rad", "model_error_05s_m", "model_error_1s_m",
         "plan_error_05s_m", "plan_error_1s_m")
TAIL = SOLVER + MODEL

OBSTACLE_COLUMN = re.compile(r"obs(\d+)_(x_m|y_m|radius_m|visible)")


def obstacle_column(j: int, field: str) -> str:
    """Name of obstacle ``j``'s column ``field`` (one of :data:`OBSTACLE_FIELDS`)."""
    return f"obs{j}_{field}"


def obstacle_indices(columns: Iterable[object]) -> list[int]:
    """The obstacle indices that have an ``x`` column, in order (gaps allowed)."""
    found = {int(m.group(1)) for c in columns if (m := OBSTACLE_COLUMN.fullmatch(str(c)))
             and m.group(2) == "x_m"}
    return sorted(found)
