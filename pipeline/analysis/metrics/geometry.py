"""Obstacle geometry of a logged run: obstacle tracks, clearances (sampled and continuous),
straight-line time to contact, time to collision, and whether a collision was avoidable (a
sampled reachability check). Definitions: :mod:`pipeline.analysis.metrics`."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from pipeline.analysis.metrics.signals import TrajectoryContext, float_columns, time_derivative
from pipeline.analysis.settings import MetricsConfig
from pipeline.loop.trajectory import TrajectoryLike, obstacle_indices


def obstacle_count(trajectory: TrajectoryLike) -> int:
    """How many obstacles the table carries (their indices may have gaps)."""
    return len(obstacle_indices(trajectory.columns))


def ego_disc_view(trajectory: TrajectoryLike, offsets_m: tuple[float, ...]) -> TrajectoryLike:
    """The logged table as the ego's logged position sees an ego of several discs along its
    heading (``vehicle.footprint_discs``, centres ``offsets_m`` ahead of the logged position):
    each obstacle's radius at each step grown by how much nearer its nearest ego disc is than
    the logged position, ``r + |p - o| - min_c |p + c h - o|``, so that every gap the metrics
    take from the logged position is the gap from that disc. The positions stay as logged (the
    obstacles' velocities, differenced from them, stay true); a radius is floored at 0, which
    can only happen deep inside a contact. One disc at the logged position (``(0.0,)``): the
    table itself."""
    offsets = np.asarray(offsets_m, float)
    if offsets.shape == (1,) and offsets[0] == 0.0:
        return trajectory
    xy = float_columns(trajectory, "X_m", "Y_m")
    psi = trajectory["psi_rad"].to_numpy(float)
    heading = np.stack([np.cos(psi), np.sin(psi)], axis=1)
    centres = xy[:, None, :] + offsets[None, :, None] * heading[:, None, :]   # (K, n, 2)
    view = trajectory.copy()
    for j in obstacle_indices(trajectory.columns):
        obstacle = float_columns(trajectory, f"obs{j}_x_m", f"obs{j}_y_m")
        nearest = np.min(np.linalg.norm(centres - obstacle[:, None, :], axis=2), axis=1)
        logged = np.linalg.norm(xy - obstacle, axis=1)
        radius = trajectory[f"obs{j}_radius_m"].to_numpy(float)
        view[f"obs{j}_radius_m"] = np.maximum(radius + logged - nearest, 0.0)
    return view


def clearance_series(trajectory: TrajectoryLike, vehicle_radius_m: float,
                     tracks: list[ObstacleTrack] | None = None) -> np.ndarray:
    """Per-step clearance to the nearest visible obstacle (NaN while none is visible);
    ``tracks``: the table's :func:`obstacle_tracks` when the caller has them (the same
    numbers, without reading the obstacles' columns again)."""
    xy = float_columns(trajectory, "X_m", "Y_m")
    result = np.full(len(trajectory), np.inf)
    # no time column needed: the positions, radii and visibility alone
    columns = [(track.position, track.radius, track.visible) for track in tracks] \
        if tracks is not None else _obstacle_columns(trajectory)
    for position, radius, visible in columns:
        gap = np.linalg.norm(xy - position, axis=1) - radius - vehicle_radius_m
        result = np.where(visible, np.minimum(result, gap), result)
    return np.where(np.isfinite(result), result, np.nan)


def min_time_to_collision(trajectory: TrajectoryLike, vehicle_radius_m: float,
                          tracks: list[ObstacleTrack] | None = None) -> float:
    """Smallest ``clearance / closing speed`` over steps and visible obstacles while closing;
    ``tracks`` as for :func:`clearance_series`."""
    t = trajectory["time_s"].to_numpy(float)
    xy = float_columns(trajectory, "X_m", "Y_m")
    best = np.inf
    for track in tracks if tracks is not None else obstacle_tracks(trajectory):
        dist = np.linalg.norm(xy - track.position, axis=1)
        closing = -time_derivative(dist, t)
        gap = np.maximum(dist - track.radius - vehicle_radius_m, 0.0)
        ok = track.visible & (closing > 1e-6)
        if np.any(ok):
            best = min(best, float(np.min(gap[ok] / closing[ok])))
    return float(best) if np.isfinite(best) else float("nan")


def straight_line_time_to_contact(p: np.ndarray, v: np.ndarray, o: np.ndarray, ov: np.ndarray,
                                  reach_m: np.ndarray, horizon_s: float | np.ndarray
                                  ) -> np.ndarray:
    """First time in ``[0, horizon_s]`` at which ``|(o + ov t) - (p + v t)| <= reach`` (inf if
    none): the vehicle continuing straight at its current velocity, the obstacle at constant
    velocity. Closed form (a quadratic in t); arrays broadcast over rows (``horizon_s`` too: a
    per-row horizon such as the time left in the run).
    """
    r0 = np.asarray(o, float) - np.asarray(p, float)
    dv = np.asarray(ov, float) - np.asarray(v, float)
    a = np.sum(dv * dv, axis=-1)
    b = 2.0 * np.sum(r0 * dv, axis=-1)
    c = np.sum(r0 * r0, axis=-1) - np.asarray(reach_m, float) ** 2
    with np.errstate(invalid="ignore", divide="ignore"):
        disc = b * b - 4.0 * a * c
        first = (-b - np.sqrt(np.maximum(disc, 0.0))) / (2.0 * a)
    hit = (disc >= 0.0) & (a > 1e-12) & (first >= 0.0) & (first <= horizon_s)
    return np.where(c <= 0.0, 0.0, np.where(hit, first, np.inf))


@dataclass(frozen=True)
class ObstacleTrack:
    """One obstacle as logged: positions (n, 2), forward-difference velocities (n, 2), radii
    (n,), visibility (n,) and the first visible row (-1 if never visible)."""

    position: np.ndarray
    velocity: np.ndarray
    radius: np.ndarray
    visible: np.ndarray
    appear: int


def _obstacle_columns(trajectory: TrajectoryLike
                      ) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Every obstacle's logged positions (n, 2), radii (n,) and visibility (n,), read in two
    selections (among walkers 50 obstacles: 200 columns, one at a time most of a run's
    metrics); the same values, column for column."""
    indices = obstacle_indices(trajectory.columns)
    if not indices:
        return []
    numbers = trajectory[[f"obs{j}_{name}" for j in indices
                          for name in ("x_m", "y_m", "radius_m")]].to_numpy(float)
    flags = trajectory[[f"obs{j}_visible" for j in indices]].to_numpy(bool)
    return [(numbers[:, 3 * k:3 * k + 2].copy(), numbers[:, 3 * k + 2].copy(),
             flags[:, k].copy()) for k in range(len(indices))]


def obstacle_tracks(trajectory: TrajectoryLike) -> list[ObstacleTrack]:
    """Every obstacle of the table as an :class:`ObstacleTrack`."""
    t = trajectory["time_s"].to_numpy(float)
    tracks = []
    for pos, radius, visible in _obstacle_columns(trajectory):
        vel = np.zeros_like(pos)
        if len(t) > 1:
            vel[:-1] = np.diff(pos, axis=0) / np.diff(t)[:, None]
            vel[-1] = vel[-2]
        tracks.append(ObstacleTrack(pos, vel, radius, visible,
                                    int(np.argmax(visible)) if visible.any() else -1))
    return tracks


def continuous_clearance(time_s: np.ndarray, xy: np.ndarray, tracks: list[ObstacleTrack],
                         vehicle_radius_m: float) -> tuple[float, int, float]:
    """Smallest clearance with vehicle and obstacles moving linearly between log rows.

    Over each interval where the obstacle is visible at both ends the closest approach of the
    relative position is found in closed form; single visible rows count as well.

    Returns
    -------
    min_clearance_m : float
        NaN when no obstacle is ever visible.
    contact_obstacle : int
        Index of the obstacle of the first contact (clearance < 0), -1 if none.
    contact_time_s : float
        Time of that first contact (the interval's closest approach), NaN if none.
    """
    best, contact_j, contact_t = np.inf, -1, np.inf
    for j, track in enumerate(tracks):
        rel = xy - track.position
        vis = track.visible
        reach = track.radius + vehicle_radius_m
        gaps = np.where(vis, np.linalg.norm(rel, axis=1) - reach, np.inf)
        times = np.asarray(time_s, float).copy()
        if len(rel) > 1:
            p0, d = rel[:-1], np.diff(rel, axis=0)
            dd = np.sum(d * d, axis=1)
            with np.errstate(invalid="ignore", divide="ignore"):
                s = np.clip(np.where(dd > 0, -np.sum(p0 * d, axis=1) / dd, 0.0), 0.0, 1.0)
            closest = np.linalg.norm(p0 + s[:, None] * d, axis=1) - reach[1:]
            both = vis[:-1] & vis[1:]
            interval_gaps = np.where(both, closest, np.inf)
            interval_times = time_s[:-1] + s * np.diff(time_s)
            gaps = np.concatenate([gaps, interval_gaps])
            times = np.concatenate([times, interval_times])
        if np.isfinite(gaps).any():
            best = min(best, float(np.min(gaps)))
            touching = np.nonzero(gaps < 0.0)[0]
            if touching.size:
                first = float(np.min(times[touching]))
                if first < contact_t:
                    contact_j, contact_t = j, first
    return (float(best) if np.isfinite(best) else float("nan"), contact_j,
            float(contact_t) if np.isfinite(contact_t) else float("nan"))


def attribution_manoeuvres(context: TrajectoryContext, thresholds: MetricsConfig,
                           switch_times_s: np.ndarray) -> dict[str, np.ndarray]:
    """The manoeuvres the collision attribution tries, as arrays of one entry per manoeuvre.

    A *primitive* is a steering target from ``linspace(-steering_max, steering_max,
    attribution_steering_samples)`` with a longitudinal acceleration: full braking
    (``-context.braking_mps2``, down to standstill), none, and speeding up
    (``context.accel_mps2``) where the track's controller commands the acceleration. A
    manoeuvre holds one primitive throughout, or one until a switch time (each of
    ``switch_times_s``) and another one after it: swerve and straighten out, brake and turn,
    turn one way and back.

    Returns
    -------
    dict
        ``target_rad``, ``accel_mps2`` (first phase), ``then_target_rad``,
        ``then_accel_mps2`` (second phase) and ``switch_s`` (the switch time, inf for none).
    """
    targets = np.linspace(-context.steering_max_rad, context.steering_max_rad,
                          thresholds.attribution_steering_samples)
    accels = np.unique(np.array([-context.braking_mps2, 0.0, context.accel_mps2]))
    target, accel = (g.ravel() for g in np.meshgrid(targets, accels))
    n = target.size
    first, then = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    differ = first != then
    first, then = first[differ], then[differ]
    switch = np.repeat(np.asarray(switch_times_s, float), first.size)
    first, then = np.tile(first, len(switch_times_s)), np.tile(then, len(switch_times_s))
    return {"target_rad": np.concatenate([target, target[first]]),
            "accel_mps2": np.concatenate([accel, accel[first]]),
            "then_target_rad": np.concatenate([target, target[then]]),
            "then_accel_mps2": np.concatenate([accel, accel[then]]),
            "switch_s": np.concatenate([np.full(n, np.inf), switch])}


def collision_is_avoidable(time_s: np.ndarray, pose: np.ndarray, tracks: list[ObstacleTrack],
                           contact_obstacle: int, contact_time_s: float,
                           context: TrajectoryContext, thresholds: MetricsConfig) -> bool:
    """Whether any manoeuvre the oracle tries from the state at the colliding obstacle's
    appearance keeps a non-negative clearance to every obstacle (a sampled reachability check).

    The manoeuvres (:func:`attribution_manoeuvres`): constant steering targets and two-phase
    steering and speed profiles, switching at ``attribution_switch_samples`` times spread
    evenly between the appearance and the end of the check (each on the log's sample grid, so
    a controller acting once per sample can switch there). Steering moves to its target at
    ``context.steering_rate_max_rad_s`` (at once where the steering angle is the input: the
    Appendix-A track); the speed changes at the phase's acceleration, never below standstill.
    Integrated on the kinematic bicycle (``context.wheelbase_m``) in steps of 0.02 s from the
    appearance until the contact time plus ``attribution_extra_s``. Obstacles follow their
    logged tracks (extrapolated at their last velocity), each from its own appearance on.

    ``False`` ("unavoidable") therefore means: no manoeuvre *tried* avoids it within that
    window; it is not a proof that none exists. The report's label also asks every other
    method that ran the same scenario (:mod:`pipeline.analysis.unavoidable`).

    Parameters
    ----------
    time_s : ndarray, shape (n,)
    pose : ndarray, shape (n, 5)
        ``X, Y, psi, speed, delta`` per log row (delta NaN when unknown: taken as 0).
    """
    t = np.asarray(time_s, float)
    track = tracks[contact_obstacle]
    a = track.appear
    if a < 0:
        return True
    x0, y0, psi0, v0, delta0 = (float(v) for v in pose[a])
    delta0 = delta0 if np.isfinite(delta0) else 0.0
    if not all(np.isfinite([x0, y0, psi0, v0])):
        return False
    dt = 0.02
    end = contact_time_s + thresholds.attribution_extra_s
    steps = max(int(np.ceil((end - t[a]) / dt)), 1)
    m = thresholds.attribution_switch_samples
    wanted = t[a] + (end - t[a]) * np.arange(1, m + 1) / (m + 1)
    # each switch on the first log row at or after it (a controller acts on its samples)
    rows = np.searchsorted(t, wanted - 1e-9, side="left")
    switches = np.unique(t[rows[rows < len(t)]])
    man = attribution_manoeuvres(context, thresholds, switches[switches < end])
    compiled = _compiled_reach()
    if compiled is not None:  # the same statement manoeuvre by manoeuvre, compiled
        # a writeable copy: pandas' columns come read-only, another type to numba (a second
        # compilation beside the one make install's warm step caches)
        return bool(compiled(np.array(t), float(t[a]), x0, y0, psi0, v0, delta0, steps, dt,
                             context.steering_rate_max_rad_s * dt, context.wheelbase_m,
                             context.vehicle_radius_m, *_search_arrays(man, tracks, len(t))))
    size = man["switch_s"].size
    X, Y = np.full(size, x0), np.full(size, y0)
    psi, v, delta = np.full(size, psi0), np.full(size, v0), np.full(size, delta0)
    rate = context.steering_rate_max_rad_s * dt
    for k in range(1, steps + 1):
        began = t[a] + (k - 1) * dt  # the input over this step is the phase it began in
        second = began >= man["switch_s"] - 1e-9
        target = np.where(second, man["then_target_rad"], man["target_rad"])
        accel = np.where(second, man["then_accel_mps2"], man["accel_mps2"])
        delta = delta + np.clip(target - delta, -rate, rate)
        X = X + dt * v * np.cos(psi)
        Y = Y + dt * v * np.sin(psi)
        psi = psi + dt * v * np.tan(delta) / context.wheelbase_m
        v = np.maximum(v + accel * dt, 0.0)
        now = t[a] + k * dt
        ok = np.ones(X.size, dtype=bool)
        for other in tracks:
            if other.appear < 0 or now < t[other.appear] - 1e-9:
                continue
            i = min(int(np.searchsorted(t, now, side="right")) - 1, len(t) - 1)
            centre = other.position[i] + other.velocity[i] * (now - t[i])
            reach = other.radius[i] + context.vehicle_radius_m
            ok &= np.hypot(X - centre[0], Y - centre[1]) >= reach
        if not ok.all():  # only the manoeuvres still clear go on
            if not ok.any():
                return False
            X, Y, psi, v, delta = X[ok], Y[ok], psi[ok], v[ok], delta[ok]
            man = {key: value[ok] for key, value in man.items()}
    return True


def _search_arrays(man: dict[str, np.ndarray], tracks: list[ObstacleTrack],
                   rows: int) -> tuple[np.ndarray, ...]:
    """The manoeuvres' and the obstacles' arrays as :func:`manoeuvre_survives` takes them."""
    return (man["target_rad"], man["accel_mps2"], man["then_target_rad"],
            man["then_accel_mps2"], man["switch_s"],
            np.array([other.appear for other in tracks], dtype=np.int64),
            _stacked([other.position for other in tracks], (rows, 2)),
            _stacked([other.velocity for other in tracks], (rows, 2)),
            _stacked([other.radius for other in tracks], (rows,)))


def _stacked(arrays: list[np.ndarray], shape: tuple[int, ...]) -> np.ndarray:
    """``arrays`` (each of ``shape``) as one contiguous float array, one row per array."""
    if not arrays:
        return np.zeros((0, *shape))
    return np.ascontiguousarray(np.stack([np.asarray(a, float) for a in arrays]))


def manoeuvre_survives(t: np.ndarray, t_appear_s: float, x0: float, y0: float, psi0: float,
                       v0: float, delta0: float, steps: int, dt: float, rate: float,
                       wheelbase_m: float, vehicle_radius_m: float, target: np.ndarray,
                       accel: np.ndarray, then_target: np.ndarray, then_accel: np.ndarray,
                       switch: np.ndarray, appear_rows: np.ndarray, positions: np.ndarray,
                       velocities: np.ndarray, radii: np.ndarray) -> bool:
    """:func:`collision_is_avoidable`'s search one manoeuvre at a time: whether any of the
    manoeuvres (``target`` ... ``switch``, one entry each) keeps clear of every obstacle
    (``appear_rows``, ``positions`` (J, n, 2), ``velocities`` (J, n, 2), ``radii`` (J, n)) on
    every step. The same operations in the same order on each manoeuvre as the vectorised
    search (which drops a manoeuvre at its first contact and answers False when none is left),
    so the same answer; it stops at the first manoeuvre that survives. Written for numba
    (:mod:`pipeline.analysis.metrics.compiled`): in CPython the vectorised search is faster."""
    n_rows = t.shape[0]
    n_tracks = appear_rows.shape[0]
    # where each obstacle is on each step (the same for every manoeuvre)
    active = np.zeros((steps + 1, n_tracks), dtype=np.bool_)
    centre_x, centre_y = np.zeros((steps + 1, n_tracks)), np.zeros((steps + 1, n_tracks))
    reach = np.zeros((steps + 1, n_tracks))
    for k in range(1, steps + 1):
        now = t_appear_s + k * dt
        i = min(int(np.searchsorted(t, now, side="right")) - 1, n_rows - 1)
        for j in range(n_tracks):
            if appear_rows[j] < 0 or now < t[appear_rows[j]] - 1e-9:
                continue
            active[k, j] = True
            centre_x[k, j] = positions[j, i, 0] + velocities[j, i, 0] * (now - t[i])
            centre_y[k, j] = positions[j, i, 1] + velocities[j, i, 1] * (now - t[i])
            reach[k, j] = radii[j, i] + vehicle_radius_m
    for m in range(target.shape[0]):
        x, y, psi, v, delta = x0, y0, psi0, v0, delta0
        clear = True
        for k in range(1, steps + 1):
            began = t_appear_s + (k - 1) * dt
            second = began >= switch[m] - 1e-9
            goal = then_target[m] if second else target[m]
            acceleration = then_accel[m] if second else accel[m]
            delta = delta + min(max(goal - delta, -rate), rate)
            x_next = x + dt * v * np.cos(psi)
            y = y + dt * v * np.sin(psi)
            x = x_next
            psi = psi + dt * v * np.tan(delta) / wheelbase_m
            v = max(v + acceleration * dt, 0.0)
            for j in range(n_tracks):
                if active[k, j] and not np.hypot(x - centre_x[k, j], y - centre_y[k, j]) \
                        >= reach[k, j]:
                    clear = False
                    break
            if not clear:
                break
        if clear:
            return True
    return False


def _compiled_reach() -> Callable[..., bool] | None:
    """The compiled :func:`manoeuvre_survives` where numba is already loaded in this process
    (a family's workers, which run the loop's compiled kernels), else None: loading numba for
    one run's check would cost it more than the vectorised search (about 25 ms)."""
    import sys

    if "numba" not in sys.modules:
        return None
    from pipeline.analysis.metrics.compiled import manoeuvre_survives_kernel

    return manoeuvre_survives_kernel
