"""The trajectory table's columns, declared once: the simulator writes them in this order and
every reader (metrics, score, figures) finds them here.

Units are in the names (``_m``, ``_rad``, ``_mps``, ``_s``). A scored external trajectory needs
only :data:`REQUIRED`; the others, when present, make the metrics exact instead of derived from
the path (see :mod:`pipeline.studies.score`).
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np
import pandas as pd

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


class TableColumn:
    """One column of a :class:`TrajectoryTable` (or several side by side), read as the
    metrics read a pandas Series: ``to_numpy``, ``astype``, ``isin``, ``==`` and ``sum`` give
    the values pandas gives for the same cells."""

    __slots__ = ("values",)

    def __init__(self, values: np.ndarray) -> None:
        self.values = values

    def to_numpy(self, dtype: Any = None) -> np.ndarray:
        """The cells as an array (of ``dtype`` when given; the column itself otherwise, as
        pandas hands out a column's own block)."""
        return self.values if dtype is None else np.asarray(self.values, dtype=dtype)

    def astype(self, dtype: Any) -> TableColumn:
        """The cells converted (``str``: each cell's text, a missing cell kept missing, as
        pandas converts them)."""
        if dtype is not str:
            return TableColumn(self.values.astype(dtype))
        texts = self.values.astype(str).astype(object)
        texts[pd.isna(self.values)] = np.nan
        return TableColumn(texts)

    def isin(self, values: Sequence[Any]) -> TableColumn:
        """Whether each cell is one of ``values``."""
        wanted = set(values)
        return TableColumn(np.array([cell in wanted for cell in self.values.tolist()],
                                    dtype=bool))

    def __eq__(self, other: object) -> TableColumn:  # type: ignore[override]
        return TableColumn(np.asarray(self.values == other))

    __hash__ = None  # type: ignore[assignment]

    def sum(self) -> Any:
        """The cells' sum."""
        return self.values.sum()


class TrajectoryTable:
    """A logged run's columns as arrays, one row per step: what the simulator hands the
    metrics and the trajectory file without building a pandas DataFrame (measured: about a
    third of a training member's metrics and result time was pandas' own).

    It answers the part of a DataFrame's interface the metrics use (``name in table``,
    ``len(table)``, ``table.columns``, ``table[name]`` and ``table[[names]]`` as
    :class:`TableColumn`, ``copy`` and column assignment), and :meth:`to_frame` gives the
    DataFrame itself (the same columns in the same order).

    Parameters
    ----------
    columns : dict of str to ndarray
        The columns in their order, each with ``n_rows`` cells. The table keeps read-only
        views of them (as pandas' copy-on-write hands out its columns): a reader that wrote
        into a column would change the run's log, which the trajectory file is written from
        after the metrics, so it is refused instead.
    n_rows : int
    """

    def __init__(self, columns: dict[str, np.ndarray], n_rows: int) -> None:
        self.n_rows = n_rows
        self._columns: dict[str, np.ndarray] = {}
        for name, values in columns.items():
            self[name] = values

    @property
    def columns(self) -> list[str]:
        """The column names in order."""
        return list(self._columns)

    def __len__(self) -> int:
        return self.n_rows

    def __contains__(self, name: object) -> bool:
        return name in self._columns

    def __getitem__(self, key: str | list[str]) -> TableColumn:
        if isinstance(key, list):
            return TableColumn(np.column_stack([self._columns[name] for name in key])
                               if key else np.empty((self.n_rows, 0)))
        return TableColumn(self._columns[key])

    def __setitem__(self, name: str, values: np.ndarray) -> None:
        view = np.asarray(values).view()
        if view.shape[:1] != (self.n_rows,):
            raise ValueError(f"column {name!r} has {view.shape[0]} rows, not {self.n_rows}")
        view.flags.writeable = False
        self._columns[name] = view

    def copy(self) -> TrajectoryTable:
        """A table of the same columns whose assignments leave this one as it is."""
        return TrajectoryTable(dict(self._columns), self.n_rows)

    def arrays(self) -> dict[str, np.ndarray]:
        """The columns by name, in order (the table's read-only views)."""
        return dict(self._columns)

    def to_frame(self) -> pd.DataFrame:
        """The table as a pandas DataFrame (its own copy of the cells)."""
        return pd.DataFrame(self._columns)


#: What the metrics and the trajectory file read: a logged table or a DataFrame of its columns
TrajectoryLike = pd.DataFrame | TrajectoryTable
