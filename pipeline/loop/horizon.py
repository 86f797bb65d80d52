"""What each step planned, kept for the report's scenario explorer: the APF's rolled-out path,
the obstacles' velocities as the vehicle saw them, and (asked of the controller once, after the
run) the MPC's predicted horizon and its collision constraints in the global frame.

Nothing here changes a number of the run: the loop copies arrays it already has into arrays
allocated once per run (:class:`HorizonLog`), and a controller turns the records it already
keeps into global coordinates after the last step (its ``horizon_view(rows)``, as its
``model_check``). The arrays (:data:`HORIZON_ARRAYS`) are written beside the run's trajectory by
the store.

A collision constraint is a half-plane ``cos(a) x + sin(a) y >= c`` in the global frame: ``a``
(``constraint_normal_rad``) the direction of its normal, pointing to the allowed side, and ``c``
(``constraint_offset_m``); NaN where a slot holds no constraint (no obstacle, or one too far to
constrain). The lateral MPC's half-plane in path coordinates (``e_y >= b`` at a station, or
``<=``) is the line through the boundary point, across the path's normal there.
"""

from __future__ import annotations

from math import cos, sin
from typing import Any

import numpy as np

from pipeline.loop.planner import ApfRollout
from pipeline.loop.scenario import ObstacleSnapshot

#: The arrays of a run's horizon record: name -> (shape after the row axis, meaning).
HORIZON_ARRAYS = {
    "apf_path_m": ("(P, 2)", "the APF's rolled-out path (global frame)"),
    "obstacle_velocity_mps": ("(n_obstacles, 2)", "each obstacle's velocity as predicted with"),
    "plan_xy_m": ("(N + 1, 2)", "the MPC's predicted positions, step 0 first"),
    "prediction_step_s": ("()", "the prediction's step (s)"),
    "constraint_normal_rad": ("(N, slots)", "each half-plane's normal direction"),
    "constraint_offset_m": ("(N, slots)", "each half-plane's offset c"),
}


class HorizonLog:
    """Preallocated arrays of what each step planned (one row per step, NaN where nothing).

    Parameters
    ----------
    n_rows : int
        The run's largest number of log rows.
    n_obstacles : int
    """

    def __init__(self, n_rows: int, n_obstacles: int) -> None:
        self.n_rows = n_rows
        self.apf_path_m: np.ndarray | None = None  # allocated at the first step (its length)
        self.obstacle_velocity_mps = np.full((n_rows, n_obstacles, 2), np.nan)

    def put(self, k: int, rollout: ApfRollout, snapshot: ObstacleSnapshot) -> None:
        """Step ``k``'s APF path and obstacle velocities (copies into the arrays)."""
        path = rollout.path_m
        store = self.apf_path_m
        if store is None:
            store = self.apf_path_m = np.full((self.n_rows, path.shape[0], 2), np.nan)
        n = path.shape[0] if path.shape[0] <= store.shape[1] else store.shape[1]
        store[k, :n] = path[:n]
        self.obstacle_velocity_mps[k] = snapshot.velocities_mps

    def arrays(self, controller: Any, rows: int) -> dict[str, np.ndarray]:
        """The record of a finished run of ``rows`` log rows: the loop's arrays and what the
        controller's ``horizon_view(rows)`` gives (nothing for one without it)."""
        out: dict[str, np.ndarray] = {
            "obstacle_velocity_mps": self.obstacle_velocity_mps[:rows]}
        if self.apf_path_m is not None:
            out["apf_path_m"] = self.apf_path_m[:rows]
        view = getattr(controller, "horizon_view", None)
        if view is not None and rows:
            out.update(view(rows))
        return out


def halfplane_from_path(point_x: float, point_y: float, path_heading_rad: float,
                        gain: float) -> tuple[float, float]:
    """The global half-plane ``(a, c)`` of ``gain * e_y >= gain * b`` about a path: the
    boundary point ``(point_x, point_y)`` (the path's point at the station, ``b`` to its left)
    and the path's heading there; the normal is the path's left normal, turned over when
    ``gain < 0``."""
    a = path_heading_rad + (0.5 * np.pi if gain > 0.0 else -0.5 * np.pi)
    return a, cos(a) * point_x + sin(a) * point_y


def lateral_horizon_view(records: list[Any], rows: int, horizon: int, slots: int
                         ) -> dict[str, np.ndarray]:
    """The lateral MPC's horizon record from its :class:`~pipeline.loop.controller.
    prediction_check.PredictionRecord` list (one per solved step): the plan's lateral errors
    and the half-planes ``G e_y >= h`` put back in the global frame about the step's path (the
    fixed frame's line as a straight path)."""
    plan = np.full((rows, horizon + 1, 2), np.nan)
    step_s = np.full(rows, np.nan)
    normal = np.full((rows, horizon, slots), np.nan)
    offset = np.full((rows, horizon, slots), np.nan)
    for k, record in enumerate(records[:rows]):
        frame = record.frame
        step_s[k] = frame[-1]
        gain = record.constraint_gain
        active = gain is not None and record.constraint_bound is not None \
            and np.count_nonzero(gain)
        if record.plan_xy_m is not None:
            n = min(record.plan_xy_m.shape[0], horizon + 1)
            plan[k, :n] = record.plan_xy_m[:n]
            if not active:
                continue
        stations = frame[-2].tolist()
        point, heading = _frame_geometry(frame)
        if record.plan_xy_m is None and record.plan_lateral_m is not None:
            for i, (s, d) in enumerate(zip(stations, record.plan_lateral_m.tolist(),
                                               strict=False)):
                if i <= horizon:
                    plan[k, i] = point(s, d)
        bound = record.constraint_bound
        if not active or gain is None or bound is None:
            continue
        for i, j in zip(*np.nonzero(gain), strict=True):
            if i + 1 >= len(stations) or j >= slots:
                continue
            s = stations[i + 1]
            g = float(gain[i, j])
            x, y = point(s, float(bound[i, j]) / g)
            normal[k, i, j], offset[k, i, j] = halfplane_from_path(x, y, heading(s), g)
    return {"plan_xy_m": plan, "prediction_step_s": step_s, "constraint_normal_rad": normal,
            "constraint_offset_m": offset}


def _frame_geometry(frame: tuple[Any, ...]) -> tuple[Any, Any]:
    """A prediction record's frame as two functions: the global point at path coordinates
    ``(s, d)`` and the path's heading at ``s`` (the fixed frame's line as a straight path)."""
    from pipeline.loop.controller.path import _heading_at, _point_at

    if frame[0] == "path":
        path = frame[1]
        points, headings = path.points_m.tolist(), path.headings_rad.tolist()
        curvature, ds, n = path.curvature_1_per_m.tolist(), path.ds_m, path.n_intervals
        return (lambda s, d: _point_at(s, d, points, headings, ds, n),
                lambda s: _heading_at(s, headings, curvature, ds, n))
    ox, oy = np.asarray(frame[1], float).tolist()
    line = float(frame[2])
    ux, uy = cos(line), sin(line)
    return (lambda s, d: (ox + s * ux - d * uy, oy + s * uy + d * ux), lambda s: line)


def kinematic_horizon_view(records: list[Any], halfplanes: dict[int, tuple[Any, ...]],
                           rows: int, horizon: int, slots: int, step_s: float
                           ) -> dict[str, np.ndarray]:
    """The kinematic track's horizon record: each step's plan (its states' positions, global
    already) and the half-planes ``nx x + ny y >= h`` its last linearization pass used."""
    plan = np.full((rows, horizon + 1, 2), np.nan)
    normal = np.full((rows, horizon, slots), np.nan)
    offset = np.full((rows, horizon, slots), np.nan)
    for k, (_, states) in enumerate(records[:rows]):
        if states is not None:
            n = min(states.shape[1], horizon + 1)
            plan[k, :n] = states[:2, :n].T
        planes = halfplanes.get(k)
        if planes is None:
            continue
        gx, gy, h = (np.asarray(part)[:horizon, :slots] for part in planes)
        # each row in use as (the normal's angle, the boundary's distance along it)
        used = (np.abs(gx) + np.abs(gy)) != 0.0
        if used.any():
            n, m = gx.shape
            nx, ny = gx[used], gy[used]
            normal[k, :n, :m][used] = np.arctan2(ny, nx)
            offset[k, :n, :m][used] = h[used] / np.sqrt(nx * nx + ny * ny)
    return {"plan_xy_m": plan, "prediction_step_s": np.full(rows, step_s),
            "constraint_normal_rad": normal, "constraint_offset_m": offset}
