"""What the metrics read of a run: its context (geometry and limits), its signals in the
goal-line frame (:func:`trajectory_signals`), and the time-series helpers every criterion uses
(RMS, derivatives, settling and band-exit times, reversals). Definitions:
:mod:`pipeline.analysis.metrics`."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from pipeline.loop.trajectory import TrajectoryLike


@dataclass(frozen=True)
class TrajectoryContext:
    """What the metrics need besides the table: geometry and limits of the run (SI units).

    The limits feed the collision attribution (defaults: the compact car of ``conf/vehicle``
    on the lateral track). ``steering_rate_max_rad_s`` is infinite where the steering angle is
    itself the input, held over a sample (the Appendix-A track); ``accel_mps2`` is the forward
    acceleration the vehicle may use, 0 where its speed follows the planner's reference (the
    lateral track: the controller steers only) and the controller's upper acceleration bound
    where it commands the acceleration (the Appendix-A track).
    """

    start_m: tuple[float, float]
    goal_m: tuple[float, float]
    vehicle_radius_m: float
    validity_heading_rad: float = math.inf
    tyre_linear_limit: float = math.inf
    wheelbase_m: float = 2.5
    steering_max_rad: float = 0.4
    steering_rate_max_rad_s: float = 1.0
    braking_mps2: float = 3.0
    accel_mps2: float = 0.0
    #: among walkers (recorded pedestrians): the surface gap (m) below which a step intrudes
    #: into a walker's personal space; None elsewhere (no crowd metrics)
    personal_space_m: float | None = None
    #: the controller's obstacle slots (the crowd metrics count the steps with more walkers
    #: in sensor range than slots); None: unlimited
    obstacle_slots: int | None = None
    #: the ego's disc centres along its heading (m; ``vehicle.footprint_discs``): one disc at
    #: the logged position unless the ego is a covered rectangle
    vehicle_offsets_m: tuple[float, ...] = (0.0,)
    #: among recorded walkers, the crossing's difficulty from the recording alone (whether
    #: the straight line at the drawn speed meets a walker, whether a platform standing still
    #: at the start is touched: :func:`pipeline.loop.pedestrians.crossing_difficulty`); None
    #: elsewhere
    crossing: tuple[bool, bool] | None = None


def rms(values: np.ndarray) -> float:
    """Root mean square of the finite entries (NaN for none)."""
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    return float(np.sqrt(np.mean(v**2))) if v.size else float("nan")


def window_mask(time_s: np.ndarray, start_s: float, end_s: float) -> np.ndarray:
    """Rows whose time lies in ``[start_s, end_s]`` (1e-9 s of slack at both ends; none when
    either end is NaN): the samples a windowed metric (C2's RMS jerk) is taken over."""
    t = np.asarray(time_s, dtype=float)
    if not (np.isfinite(start_s) and np.isfinite(end_s)):
        return np.zeros(t.shape, dtype=bool)
    return (t >= start_s - 1e-9) & (t <= end_s + 1e-9)


def max_abs(values: np.ndarray) -> float:
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    return float(np.max(np.abs(v))) if v.size else float("nan")


def sign_changes(values: np.ndarray, band: float) -> int:
    """Number of sign changes of ``values`` counting only samples with ``|v| > band``."""
    v = np.asarray(values, dtype=float)
    signs = np.sign(v[np.abs(v) > band])
    return int(np.count_nonzero(signs[1:] != signs[:-1])) if signs.size > 1 else 0


def time_derivative(values: np.ndarray, time_s: np.ndarray) -> np.ndarray:
    """Central-difference derivative (one-sided at the ends): ``np.gradient(values, time_s)``
    with its statements for a 1-D signal written out, the same bits (its general checks and
    slicing cost more than the arithmetic on a run's hundred samples, 5-6 calls per run's
    metrics); any other shape goes to ``np.gradient`` itself."""
    v = np.asarray(values, dtype=float)
    if v.size < 2:
        return np.full(v.shape, np.nan)
    t = np.asarray(time_s, dtype=float)
    if v.ndim != 1 or t.shape != v.shape:
        return np.gradient(v, t)
    dx = np.diff(t)
    out = np.empty_like(v)
    if (dx == dx[0]).all():  # np.gradient's uniform spacing: the scalar step
        step = dx[0]
        out[1:-1] = (v[2:] - v[:-2]) / (2. * step)
        out[0] = (v[1] - v[0]) / step
        out[-1] = (v[-1] - v[-2]) / step
        return out
    dx1, dx2 = dx[:-1], dx[1:]
    a = -(dx2) / (dx1 * (dx1 + dx2))
    b = (dx2 - dx1) / (dx1 * dx2)
    c = dx1 / (dx2 * (dx1 + dx2))
    out[1:-1] = a * v[:-2] + b * v[1:-1] + c * v[2:]
    out[0] = (v[1] - v[0]) / dx[0]
    out[-1] = (v[-1] - v[-2]) / dx[-1]
    return out


def settling_time(time_s: np.ndarray, error: np.ndarray, band: float) -> float:
    """Time after ``time_s[0]`` from which ``|error|`` stays within ``band`` (NaN if it ends
    outside).

    Uses ``control.step_info`` on the mirrored signal ``e0 - e(t)``, a step from 0 to ``e0`` whose
    settling band ``SettlingTimeThreshold * |e0|`` is set to ``band``.
    """
    t = np.asarray(time_s, dtype=float) - float(time_s[0])
    e = np.asarray(error, dtype=float)
    if e.size == 0 or not np.all(np.isfinite(e)):
        return float("nan")
    if abs(e[-1]) > band:
        return float("nan")
    e0 = float(e[0])
    if abs(e0) <= band and np.all(np.abs(e) <= band):
        return 0.0
    if abs(e0) <= 1e-12:
        # step_info needs a non-zero step; the error starts at zero, so measure from the
        # last exit directly (same convention: first sample after the last exit)
        outside = np.nonzero(np.abs(e) > band)[0]
        return float(t[outside[-1] + 1])
    mirrored = e0 - e
    if np.all(np.sign(e0) * mirrored < 0.9 * abs(e0)):
        # step_info's rise-time search would find no 90 % point; settle by direct rule
        outside = np.nonzero(np.abs(e) > band)[0]
        return float(t[outside[-1] + 1])
    # imported here: python-control costs a second to import, and readers of run folders (the
    # report, verify, aggregate) never settle a signal themselves
    import control

    info = control.step_info(mirrored, t, final_output=e0, SettlingTimeThreshold=band / abs(e0))
    return float(info["SettlingTime"])


def float_columns(frame: TrajectoryLike, *names: str) -> np.ndarray:
    """Columns ``names`` of ``frame`` side by side as floats, shape (rows, len(names)); the
    same values as ``frame[list(names)].to_numpy(float)`` without pandas' multi-column
    selection (an index lookup and a copy of a block, ten times the cost)."""
    return np.column_stack([frame[name].to_numpy(float) for name in names])


def band_exit_time(time_s: np.ndarray, values: np.ndarray, start_time_s: float, band: float,
                   interpolate: bool = True) -> float:
    """Time from ``start_time_s`` until ``|values - values(start)|`` first exceeds ``band``.

    With ``interpolate`` the crossing is placed by linear interpolation between the last sample
    inside the band and the first outside (exact for a piecewise-linear signal); otherwise at the
    first sample outside. NaN if the band is never left.
    """
    t = np.asarray(time_s, dtype=float)
    v = np.asarray(values, dtype=float)
    after = np.nonzero(t >= start_time_s - 1e-9)[0]
    if after.size == 0:
        return float("nan")
    deviation = np.abs(v[after] - v[after[0]])
    exits = np.nonzero(deviation > band)[0]
    if exits.size == 0:
        return float("nan")
    i = exits[0]
    if not interpolate or i == 0:
        return float(t[after[i]] - start_time_s)
    d0, d1 = deviation[i - 1], deviation[i]
    t0, t1 = t[after[i - 1]], t[after[i]]
    return float(t0 + (band - d0) / (d1 - d0) * (t1 - t0) - start_time_s)


def reversal_count(values: np.ndarray, band: float) -> tuple[int, int]:
    """Direction reversals of a signal with a hysteresis of ``band``, and the first direction.

    The direction is set by the first move of more than ``band`` from the start; a reversal is
    counted each time the signal retreats from its running extreme by more than ``band``.

    Returns
    -------
    count : int
    first_direction : int
        +1, -1, or 0 when the signal never moved by more than ``band``.
    """
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    if v.size < 2:
        return 0, 0
    start = extreme = float(v[0])
    direction = first = count = 0
    for x in v[1:].tolist():
        if direction == 0:
            if x - start > band or start - x > band:
                direction = first = 1 if x > start else -1
                extreme = x
        elif direction == 1:
            if x > extreme:
                extreme = x
            elif extreme - x > band:
                count, direction, extreme = count + 1, -1, x
        else:
            if x < extreme:
                extreme = x
            elif x - extreme > band:
                count, direction, extreme = count + 1, 1, x
    return count, first


@dataclass(frozen=True)
class Signals:
    """The trajectory's signals in the goal-line frame; optional columns derived from the path
    when a scored trajectory lacks them (``vy`` is None then)."""

    t: np.ndarray
    dt: float
    start: np.ndarray
    goal: np.ndarray
    line: np.ndarray
    xy: np.ndarray
    along: np.ndarray
    lateral: np.ndarray
    psi: np.ndarray
    velocity: np.ndarray
    speed: np.ndarray
    vx: np.ndarray
    vy: np.ndarray | None
    yaw_rate: np.ndarray
    delta: np.ndarray
    steer_rate: np.ndarray
    heading_error: np.ndarray
    bearing_error: np.ndarray
    model_heading_error: np.ndarray | None = None


#: The trajectory columns :func:`trajectory_signals` reads (where the table has them).
SIGNAL_COLUMNS = ("time_s", "X_m", "Y_m", "psi_rad", "vx_mps", "vy_mps", "r_rad_s", "delta_rad",
                  "steering_rate_rad_s", "model_heading_error_rad")


def trajectory_signals(tr: TrajectoryLike, context: TrajectoryContext) -> Signals:
    """The signals every criterion reads, from the table's columns (or the path)."""
    t = tr["time_s"].to_numpy(float)
    dt = float(np.median(np.diff(t))) if t.size > 1 else float("nan")
    start, goal = np.asarray(context.start_m, float), np.asarray(context.goal_m, float)
    line = (goal - start) / np.linalg.norm(goal - start)
    normal = np.array([-line[1], line[0]])
    xy = float_columns(tr, "X_m", "Y_m")
    if "psi_rad" in tr:
        psi = tr["psi_rad"].to_numpy(float)
    else:
        psi = np.unwrap(np.arctan2(time_derivative(xy[:, 1], t), time_derivative(xy[:, 0], t)))
    if "vx_mps" in tr:
        vx = tr["vx_mps"].to_numpy(float)
        vy = tr["vy_mps"].to_numpy(float) if "vy_mps" in tr else np.zeros(len(tr))
        speed = np.hypot(vx, vy)
        velocity = np.column_stack([vx * np.cos(psi) - vy * np.sin(psi),
                                    vx * np.sin(psi) + vy * np.cos(psi)])
    else:
        velocity = np.column_stack([time_derivative(xy[:, 0], t), time_derivative(xy[:, 1], t)])
        speed = np.hypot(velocity[:, 0], velocity[:, 1])
        vx, vy = speed, None
    yaw_rate = tr["r_rad_s"].to_numpy(float) if "r_rad_s" in tr \
        else time_derivative(np.unwrap(psi), t)
    delta = tr["delta_rad"].to_numpy(float) if "delta_rad" in tr else np.full(len(tr), np.nan)
    steer_rate = tr["steering_rate_rad_s"].to_numpy(float) if "steering_rate_rad_s" in tr \
        else time_derivative(delta, t)
    line_heading = np.arctan2(line[1], line[0])
    heading_error = np.arctan2(np.sin(psi - line_heading), np.cos(psi - line_heading))
    to_goal = goal - xy
    bearing = np.arctan2(to_goal[:, 1], to_goal[:, 0])
    bearing_error = np.arctan2(np.sin(psi - bearing), np.cos(psi - bearing))
    model_heading = tr["model_heading_error_rad"].to_numpy(float) \
        if "model_heading_error_rad" in tr else None
    return Signals(t, dt, start, goal, line, xy, (xy - start) @ line, (xy - start) @ normal, psi,
                   velocity, speed, vx, vy, yaw_rate, delta, steer_rate, heading_error,
                   bearing_error, model_heading)
