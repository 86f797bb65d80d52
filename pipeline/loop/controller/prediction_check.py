"""How each step's prediction of the lateral MPC held against what the plant then did (the
model's validity, recorded per step; :func:`prediction_check`).

A :class:`PredictionRecord` keeps what one step predicted with (the frame, the state, the model,
the previewed ``r_d``, the plan); after the run each record is replayed against the plant's log
by :func:`check_record_arrays`, one statement for CPython and numba
(:mod:`pipeline.loop.compiled`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from math import floor, pi, sqrt
from typing import Any

import numpy as np

from pipeline.loop.arrays import KernelValues
from pipeline.loop.controller.path import ReferencePath, _heading_at, _point_at, _project_point
from pipeline.loop.model import LateralModel


@dataclass(frozen=True)
class PredictionRecord:
    """What one step of the lateral MPC predicted with, kept to check it against the plant
    afterwards (:func:`prediction_check`).

    Attributes
    ----------
    frame : tuple
        ``("path", ReferencePath, stations, step_s)`` or ``("fixed", origin_m, heading_rad,
        stations, step_s)``: the path the state's errors were measured against (in the fixed
        frame, the start-goal line from the vehicle's projection on it, as a straight path),
        the stations (arc lengths at the prediction's steps, 0 first) the model puts the
        vehicle at, and the prediction step (s).
    x0 : ndarray, shape (5,)
    model : LateralModel
        The step's model at the log's sample time (the replay's).
    disturbance_rad_s : ndarray, shape (N,)
        The previewed ``r_d``.
    plan_lateral_m : ndarray or None, shape (N + 1,)
        The QP's predicted lateral errors (None when the step fell back).
    constraint_gain, constraint_bound : ndarray or None, shape (N, slots)
        The step's half-planes ``G e_y + s >= h`` (the QP's own arrays; for the report's
        explorer, :func:`pipeline.loop.horizon.lateral_horizon_view`).
    plan_xy_m : ndarray or None, shape (N + 1, 2)
        The plan's global positions where the frame computed them anyway (the path frame's
        plan poses); None: computed from the plan's lateral errors when asked.
    """

    frame: tuple[Any, ...]
    x0: np.ndarray
    model: LateralModel
    disturbance_rad_s: np.ndarray
    plan_lateral_m: np.ndarray | None
    constraint_gain: np.ndarray | None = None
    constraint_bound: np.ndarray | None = None
    plan_xy_m: np.ndarray | None = None

    @property
    def stations_m(self) -> np.ndarray:
        return np.asarray(self.frame[-2], float)

    @property
    def step_s(self) -> float:
        return float(self.frame[-1])

    def path(self, n_intervals: int) -> ReferencePath:
        """The record's path (the fixed frame's line as a straight path)."""
        if self.frame[0] == "path":
            return self.frame[1]
        ds = self.model.speed_mps * self.model.sample_time_s
        return ReferencePath.straight(self.frame[1], self.frame[2], ds, n_intervals)


#: Columns of :func:`prediction_check` (the trajectory keeps them, one value per step).
MODEL_CHECK_COLUMNS = ("model_heading_error_rad", "model_error_05s_m", "model_error_1s_m",
                       "plan_error_05s_m", "plan_error_1s_m")


def check_record_arrays(points: KernelValues, headings: KernelValues, curvature: KernelValues,
                        ds: float, n: int, stations: KernelValues, step: int,
                        x0: KernelValues, Ad: KernelValues, Bd: KernelValues,
                        Ed: KernelValues, plan_lateral: KernelValues, xy: KernelValues,
                        psi: KernelValues, delta: KernelValues, first: int, last: int,
                        half: int, one: int, ts: float
                        ) -> tuple[float, float, float, float, float]:
    """:func:`prediction_check` of one record on plain numbers: ``heading error, model error
    at half and one, plan error at half and one`` (NaN where not computable).

    ``xy``, ``psi``, ``delta`` are the plant's log rows; ``first`` the record's row, ``last``
    the last row of its window; ``stations`` the model's, one per prediction step of ``step``
    seconds (read at the log's sample time ``ts`` by linear interpolation, continued at their
    last spacing); ``Ad, Bd, Ed`` the model at the sample time ``ts`` (the replay runs at the
    log's rate, with the path's heading change over each sample as ``r_d``); ``plan_lateral``
    the plan's ``e_y`` at its steps (empty when it fell back)."""
    nan = float("nan")
    worst = 0.0
    for row in range(first, last + 1):
        s_pose, _ = _project_point(xy[row][0], xy[row][1], points, headings, ds, n)
        e = psi[row] - _heading_at(s_pose, headings, curvature, ds, n)
        while e > pi:
            e -= 2.0 * pi
        while e < -pi:
            e += 2.0 * pi
        e = -e if e < 0.0 else e
        worst = e if e > worst else worst
    steps = last - first
    errors = [nan, nan, nan, nan]
    if steps < half:
        return worst, errors[0], errors[1], errors[2], errors[3]
    n_model = len(stations) - 1
    n_plan = len(plan_lateral) - 1
    ratio = ts / step
    station_now = stations[0]
    x = [x0[0], x0[1], x0[2], x0[3], x0[4]]
    for j in range(steps):
        # the station one sample on: interpolated on the model's steps, continued beyond them
        f = (j + 1) * ratio
        i = int(floor(f))
        if i >= n_model:
            spacing = stations[n_model] - stations[n_model - 1] if n_model > 0 else 0.0
            station_next = stations[n_model] + (f - n_model) * spacing
        else:
            station_next = stations[i] + (f - i) * (stations[i + 1] - stations[i])
        disturbance = (_heading_at(station_next, headings, curvature, ds, n)
                       - _heading_at(station_now, headings, curvature, ds, n)) / ts
        rate = (delta[first + j + 1] - delta[first + j]) / ts
        x = [Ad[r][0] * x[0] + Ad[r][1] * x[1] + Ad[r][2] * x[2] + Ad[r][3] * x[3]
             + Ad[r][4] * x[4] + Bd[r] * rate + Ed[r] * disturbance for r in range(5)]
        station_now = station_next
        ahead = j + 1
        if ahead == half or ahead == one:  # noqa: SIM109 (a numba kernel: plain comparisons)
            slot = 0 if ahead == half else 1
            px, py = _point_at(station_now, x[0], points, headings, ds, n)
            gx, gy = px - xy[first + ahead][0], py - xy[first + ahead][1]
            errors[slot] = sqrt(gx * gx + gy * gy)
            if n_plan >= 0 and f <= n_plan + 1e-9:
                k = i if i < n_plan else n_plan - 1
                k = 0 if k < 0 else k
                lateral = plan_lateral[k] + (f - k) * (plan_lateral[k + 1] - plan_lateral[k]) \
                    if n_plan > 0 else plan_lateral[0]
                px, py = _point_at(station_now, lateral, points, headings, ds, n)
                gx, gy = px - xy[first + ahead][0], py - xy[first + ahead][1]
                errors[2 + slot] = sqrt(gx * gx + gy * gy)
    return worst, errors[0], errors[1], errors[2], errors[3]


def prediction_check(records: list[Any], time_s: np.ndarray, plant: np.ndarray,
                     sample_time_s: float, kernel: Callable[..., Any] | None = None
                     ) -> dict[str, np.ndarray]:
    """Each step's prediction against what the plant then did.

    For the record of step ``k`` (``records[k]`` belongs to log row ``k``):

    * ``model_heading_error_rad``: the largest ``|psi - psi_path(s)|`` of the plant's poses
      over the next second (rows ``k .. k + 1 s``), each projected on that step's path: the
      heading error the model's small-angle assumption is about (in the fixed frame, the
      heading against the line). A path that starts along the vehicle's velocity has only the
      sideslip as heading error at ``k`` itself, so the window is what tells.
    * ``model_error_05s_m``, ``model_error_1s_m``: the model replayed from the step's state
      with the steering rates the plant then applied (the logged steering angle's change per
      step, which includes the actuator's bound), and the step's previewed ``r_d``, mapped to
      the global frame at its stations on the path, against the plant's position 0.5 s and
      1 s later (m).
    * ``plan_error_05s_m``, ``plan_error_1s_m``: the same for the QP's own plan (the inputs it
      planned, not those applied; NaN where it fell back or the horizon is shorter).

    The replay runs at the log's sample time with the path's heading change over each
    sample as ``r_d`` (the preview itself where the prediction step is the sample time). NaN
    where the run ends before the time ahead. Each record by :func:`check_record_arrays` (run
    by ``kernel``, its compiled statement, when given).

    Parameters
    ----------
    records : list of PredictionRecord
    time_s : ndarray, shape (rows,)
    plant : ndarray, shape (rows, 4)
        ``X, Y, psi, delta`` of every log row.
    sample_time_s : float

    Returns
    -------
    dict of ndarray, shape (rows,)
        Keyed by :data:`MODEL_CHECK_COLUMNS`.
    """
    rows = plant.shape[0]
    out = np.full((rows, len(MODEL_CHECK_COLUMNS)), np.nan)
    one = int(round(1.0 / sample_time_s))
    half = int(round(0.5 / sample_time_s))
    compiled = kernel is not None
    check = kernel if kernel is not None else check_record_arrays
    xy = np.ascontiguousarray(plant[:, :2]) if compiled else plant[:, :2].tolist()
    psi = np.ascontiguousarray(plant[:, 2]) if compiled else plant[:, 2].tolist()
    delta = np.ascontiguousarray(plant[:, 3]) if compiled else plant[:, 3].tolist()
    for k, record in enumerate(records[:rows]):
        last = min(rows - 1, k + one)
        path, arrays = _record_arrays(record, one, compiled)
        points, headings, curvature, stations, x0, Ad, Bd, Ed, plan = arrays
        out[k] = check(points, headings, curvature, path.ds_m, path.n_intervals, stations,
                       record.step_s, x0, Ad, Bd, Ed, plan, xy, psi, delta, k, last, half, one,
                       sample_time_s)
    return {name: out[:, i] for i, name in enumerate(MODEL_CHECK_COLUMNS)}


def _record_arrays(record: PredictionRecord, one: int, compiled: bool) -> tuple[Any, ...]:
    """A record's path (long enough for ``one`` sample ahead) and the arrays
    :func:`check_record_arrays` reads of it (lists for CPython, arrays for the kernel): the
    path's points, headings and curvature, the model's stations, the state, ``Ad``, ``Bd``,
    ``Ed`` and the plan's lateral error (empty when it fell back)."""
    path = record.path(max(one, record.disturbance_rad_s.shape[0]))
    model = record.model
    plan = record.plan_lateral_m if record.plan_lateral_m is not None else np.zeros(0)
    arrays: tuple[Any, ...] = (path.points_m, path.headings_rad, path.curvature_1_per_m,
              record.stations_m, record.x0, model.Ad, np.ascontiguousarray(model.Bd[:, 0]),
              np.ascontiguousarray(model.Ed[:, 0]), plan)
    if not compiled:
        arrays = tuple(a.tolist() for a in arrays)
    return path, arrays
