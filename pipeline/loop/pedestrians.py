"""Recorded pedestrians (ETH/UCY) as dynamic obstacles: the track files, their replay, and the
seeded family of crossings (``scenario=pedestrians``; its source, :class:`PedestrianSource`).

A track file holds tab-separated rows ``frame  pedestrian_id  x_m  y_m`` (world metres), one
row per pedestrian and frame; frames are numbered 10 apart at 2.5 Hz, so a frame number times
``seconds_per_frame`` (0.04 s) is the recording time. A pedestrian is a disc that exists from
its first to its last sample and moves linearly between samples (its recorded positions are
replayed exactly at their times); its velocity is that of the segment it is on. It does not
react to the platform. Which pedestrians the planner and the MPC see (those within the sensor
range) is decided in the loop (:mod:`pipeline.loop.simulate`), from these true positions.
"""

from __future__ import annotations

import functools
import gzip
import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from pipeline.errors import ConfigError, TrackFileError
from pipeline.loop.scenario import Extra, ObstacleMotion, Scenario, refuse_blocks, with_family_seed
from pipeline.loop.settings import PedestrianConfig, ScenarioConfig, ScenarioSourceConfig


def _data_dir() -> Path:
    """``pipeline/data`` in an installed package (the wheel ships the tracks there), else the
    repository's ``data/`` beside the package (a checkout or an editable install)."""
    packaged = Path(__file__).resolve().parent.parent / "data"
    if packaged.is_dir():
        return packaged
    return Path(__file__).resolve().parent.parent.parent / "data"


#: Where relative ``scenario.pedestrians.data_dir`` folders are read from.
DATA_DIR = _data_dir()
#: Tolerance (s) within which a time counts as a track's sample time (exact replay there).
SAMPLE_TOLERANCE_S = 1e-9


@dataclass(frozen=True)
class SceneTracks:
    """Every pedestrian of one recorded scene, resampled on its own uniform grid.

    Attributes
    ----------
    name : str
    path : Path
        The file read.
    step_s : float
        Time between two samples of one pedestrian (s).
    first_s : ndarray, shape (n,)
        Recording time of each pedestrian's first sample (s).
    counts : ndarray of int, shape (n,)
        Samples per pedestrian.
    positions_m : ndarray, shape (n, K, 2)
        Samples (K = the most of any pedestrian; a shorter track repeats its last sample).
    ids : ndarray, shape (n,)
        The file's pedestrian ids.
    """

    name: str
    path: Path
    step_s: float
    first_s: np.ndarray
    counts: np.ndarray
    positions_m: np.ndarray
    ids: np.ndarray
    #: :func:`recorded_motion`'s walkers near a crossing, by the crossing (a run's scenario
    #: and its metrics ask for the same member in one process, moments apart)
    near: dict[tuple[Any, ...], np.ndarray] = field(default_factory=dict, compare=False, repr=False)

    @property
    def start_s(self) -> float:
        return float(self.first_s.min())

    @property
    def end_s(self) -> float:
        return float((self.first_s + (self.counts - 1) * self.step_s).max())

    @functools.cached_property
    def extent_m(self) -> tuple[float, float, float, float]:
        """``(x_min, x_max, y_min, y_max)`` of every recorded position."""
        points = self.recorded_points_m
        return (float(points[:, 0].min()), float(points[:, 0].max()),
                float(points[:, 1].min()), float(points[:, 1].max()))

    @functools.cached_property
    def recorded_points_m(self) -> np.ndarray:
        """Every recorded position, shape (m, 2): where someone walked."""
        return np.concatenate([self.positions_m[j, :c] for j, c in enumerate(self.counts)])

    @functools.cached_property
    def walkable(self) -> Any:
        """A k-d tree of :attr:`recorded_points_m` (``scipy.spatial.cKDTree``): is a place
        near where someone walked."""
        from scipy.spatial import cKDTree

        return cKDTree(self.recorded_points_m)

    def motion(self, which: np.ndarray, window_start_s: float,
               extension_s: float = 0.0) -> RecordedTrackMotion:
        """The pedestrians ``which`` (indices) on a clock whose 0 is ``window_start_s``, each
        track extended by ``extension_s`` at both ends (:class:`RecordedTrackMotion`)."""
        which = np.asarray(which, dtype=int)
        return RecordedTrackMotion(self.first_s[which] - window_start_s, self.step_s,
                                   self.counts[which], self.positions_m[which],
                                   float(extension_s))


@dataclass(frozen=True)
class RecordedTrackMotion:
    """Obstacles that move on recorded tracks (linear between samples); the scenario's
    :class:`~pipeline.loop.scenario.ObstacleMotion` for recorded pedestrians. Times on the
    scenario's clock (s); a pedestrian exists from its first to its last sample and holds
    its first (last) position before (after), absent."""

    first_s: np.ndarray
    step_s: float
    counts: np.ndarray
    positions_m: np.ndarray
    #: each track goes on this long (s) before its first and after its last sample, straight
    #: at its first (last) segment's velocity (a one-sample track stands); 0: none
    extension_s: float = 0.0

    def states_at(self, time_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Positions (n, 2), velocities (n, 2) and presence (n,) at ``time_s``.

        At a sample time the position is the sample itself (bit for bit); between samples
        the linear interpolation; the velocity is the current segment's (the one starting at
        a sample time; the last segment's at the last sample; zero for a one-sample track).
        """
        here, ahead, frac, present = self._segments(time_s)
        return self._along(here, ahead, frac), (ahead - here) / self.step_s, present

    def positions_over(self, times_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`states_at`'s positions (T, n, 2) and presence (T, n) at every time of
        ``times_s`` at once (the same operations, element for element)."""
        here, ahead, frac, present = self._segments(np.asarray(times_s, float)[:, None])
        return self._along(here, ahead, frac), present

    def states_over(self, times_s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`states_at` at every time of ``times_s`` at once: positions (T, n, 2),
        velocities (T, n, 2) and presence (T, n), the same operations element for element."""
        here, ahead, frac, present = self._segments(np.asarray(times_s, float)[:, None])
        return self._along(here, ahead, frac), (ahead - here) / self.step_s, present

    def _along(self, here: np.ndarray, ahead: np.ndarray, frac: np.ndarray) -> np.ndarray:
        """The position a fraction ``frac`` along each segment from ``here`` to ``ahead``."""
        # (1 - f) a + f b: exactly a at f = 0 and exactly b at f = 1 (a sample is replayed)
        between = (1.0 - frac) * here + frac * ahead
        if self.extension_s <= 0.0:
            return between
        # an extended end: on from its end sample (a standing walker stays exactly there)
        step = ahead - here
        return np.where(frac < 0.0, here + frac * step,
                        np.where(frac > 1.0, ahead + (frac - 1.0) * step, between))

    def _segments(self, time_s: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Each pedestrian's segment at ``time_s`` (a number, or times broadcast against the
        pedestrians: shape (T, 1)): its start and end samples, the fraction along it (a
        trailing axis of 1) and whether the pedestrian is present."""
        last = (self.counts - 1).astype(float)
        u = (time_s - self.first_s) / self.step_s
        nearest = np.rint(u)
        u = np.where(np.abs(u - nearest) * self.step_s < SAMPLE_TOLERANCE_S, nearest, u)
        ahead = self.extension_s / self.step_s
        present = (u >= -ahead) & (u <= last + ahead)
        # before the first (after the last) sample: the first (last) segment extended, its
        # fraction below 0 (above 1)
        u = np.clip(u, -ahead, last + ahead)
        i = np.clip(np.floor(u), 0.0, np.maximum(last - 1.0, 0.0)).astype(int)
        rows = np.arange(self.counts.shape[0])
        return (self.positions_m[rows, i], self.positions_m[rows, i + 1], (u - i)[..., None],
                present)


@dataclass(frozen=True)
class SteppedTrackMotion:
    """A :class:`RecordedTrackMotion` read at every step time of a run at once (the same
    operations, element for element, as each step's :meth:`RecordedTrackMotion.states_at`):
    the loop's one call per step becomes a row's copy. A time that is not one of
    ``times_s`` exactly is answered by the tracks themselves."""

    tracks: RecordedTrackMotion
    times_s: np.ndarray
    sample_time_s: float
    positions_m: np.ndarray
    velocities_mps: np.ndarray
    present: np.ndarray

    @classmethod
    def of(cls, tracks: RecordedTrackMotion, sample_time_s: float,
           n_steps: int) -> SteppedTrackMotion:
        """The tracks at ``k * sample_time_s`` for k = 0..n_steps (the loop's step times)."""
        times = np.arange(int(n_steps) + 1) * float(sample_time_s)
        return cls(tracks, times, float(sample_time_s), *tracks.states_over(times))

    def states_at(self, time_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`RecordedTrackMotion.states_at`, from the table at a step time."""
        k = int(round(time_s / self.sample_time_s)) if math.isfinite(time_s) else -1
        if 0 <= k < self.times_s.size and self.times_s[k] == time_s:
            return self.positions_m[k].copy(), self.velocities_mps[k].copy(), \
                self.present[k].copy()
        return self.tracks.states_at(time_s)


def scene_path(cfg: PedestrianConfig, scene: str) -> Path:
    """The track file of ``scene``: ``<data_dir>/<scene>.txt.gz``, else ``.txt``."""
    folder = Path(cfg.data_dir)
    if not folder.is_absolute():
        folder = DATA_DIR / folder
    for suffix in (".txt.gz", ".txt"):
        path = folder / f"{scene}{suffix}"
        if path.is_file():
            return path
        if path.exists() or path.is_symlink():  # a folder, a pipe, a device, a broken link
            kind = "a folder" if path.is_dir() else "not a regular file"
            raise TrackFileError(f"data error: {path}: {kind} (scenario.pedestrians.scenes "
                                 f"names '{scene}'); allowed: a track file <scene>.txt.gz or "
                                 "<scene>.txt")
    raise TrackFileError(f"data error: {folder / (scene + '.txt.gz')}: no such track file "
                         f"(scenario.pedestrians.scenes names '{scene}'); allowed: a scene "
                         f"with a file <scene>.txt.gz or <scene>.txt in {folder}"
                         f"{_available(folder)}")


def _available(folder: Path) -> str:
    if not folder.is_dir():
        return " (the folder does not exist)"
    names = sorted({p.name.split(".")[0] for p in folder.glob("*.txt*")})
    return f" (found: {', '.join(names)})" if names else " (none there)"


def load_scene(cfg: PedestrianConfig, scene: str) -> SceneTracks:
    """The tracks of ``scene`` (read once per process and version of the file)."""
    path = scene_path(cfg, scene)
    stat = path.stat()
    return _load(path, scene, float(cfg.seconds_per_frame), (stat.st_mtime_ns, stat.st_size))


@functools.lru_cache(maxsize=16)
def _load(path: Path, scene: str, seconds_per_frame: float,
          version: tuple[int, int]) -> SceneTracks:
    """:func:`load_scene` of one file; ``version`` (modification time, size) only keys the
    cache, so that a file written again is read again."""
    rows, lines = _rows_and_lines(path)
    frames, ids, xy = rows[:, 0], rows[:, 1], rows[:, 2:4]
    step_frames = _check_frames(path, frames, ids, lines)
    step_s = step_frames * seconds_per_frame
    order = np.lexsort((frames, ids))
    frames, ids, xy = frames[order], ids[order], xy[order]
    unique_ids, starts = np.unique(ids, return_index=True)
    ends = np.append(starts[1:], ids.size)
    tracks, firsts, counts = [], [], []
    for a, b in zip(starts.tolist(), ends.tolist(), strict=True):
        f = frames[a:b]
        if np.any(np.diff(f) <= 0):
            raise TrackFileError(f"data error: {path}: pedestrian {ids[a]:g} has two rows for "
                                 "one frame; allowed: one row per pedestrian and frame")
        # on the uniform grid of this pedestrian (a gap is bridged linearly; np.interp
        # returns a sample itself at its own frame)
        grid = np.arange(f[0], f[-1] + 0.5 * step_frames, step_frames)
        track = np.column_stack([np.interp(grid, f, xy[a:b, k]) for k in range(2)])
        tracks.append(track)
        firsts.append(f[0] * seconds_per_frame)
        counts.append(grid.size)
    width = max(max(counts), 2)
    positions = np.empty((len(tracks), width, 2))
    for j, track in enumerate(tracks):
        positions[j, :track.shape[0]] = track
        positions[j, track.shape[0]:] = track[-1]
    return SceneTracks(scene, path, step_s, np.array(firsts), np.array(counts), positions,
                       unique_ids)


#: A pedestrian's track may miss at most this many frame steps in a row (bridged linearly):
#: the recordings miss none (ETH/UCY: at most 1 step between a pedestrian's rows); more is a
#: mistyped frame number, which once made the loader allocate 58 GiB.
MAX_GAP_STEPS = 25
#: The tracks' array (pedestrians x frames x 2 floats) may take at most this many bytes.
MAX_TRACKS_BYTES = 2 ** 30


def _check_frames(path: Path, frames: np.ndarray, ids: np.ndarray, lines: np.ndarray) -> float:
    """The file's frame step (the most common gap between its distinct frames), once every
    frame is a whole number on its lattice, no pedestrian's track has a gap longer than
    :data:`MAX_GAP_STEPS` and the tracks' array fits :data:`MAX_TRACKS_BYTES`; else a
    :class:`~pipeline.errors.TrackFileError` naming the file and the line, before any array
    of the tracks' size is made."""
    def bad(i: int, why: str) -> TrackFileError:
        return TrackFileError(f"data error: {path}: line {int(lines[i])} (frame {frames[i]:g}, "
                              f"pedestrian {ids[i]:g}): {why}")

    whole = frames == np.round(frames)
    if not whole.all() or frames.min() < 0:
        i = int(np.flatnonzero(~whole | (frames < 0))[0])
        raise bad(i, "allowed: a whole frame number >= 0")
    distinct = np.unique(frames)
    gaps, counts = np.unique(np.diff(distinct), return_counts=True)
    step = float(gaps[counts.argmax()]) if gaps.size else 10.0
    off = np.flatnonzero((frames - distinct[0]) % step != 0)
    if off.size:
        raise bad(int(off[0]), f"not on the file's frame lattice ({distinct[0]:g} + k x "
                               f"{step:g}); allowed: frames {step:g} apart (a mistyped number?)")
    order = np.lexsort((frames, ids))
    same = ids[order][1:] == ids[order][:-1]
    steps = np.diff(frames[order]) / step
    long = np.flatnonzero(same & (steps > MAX_GAP_STEPS))
    if long.size:
        i = int(order[long[0] + 1])
        raise bad(i, f"{steps[long[0]]:g} frame steps after the pedestrian's previous row; "
                     f"allowed: at most {MAX_GAP_STEPS} (a mistyped number?)")
    unique_ids, first = np.unique(ids[order], return_index=True)
    last = np.append(first[1:], ids.size) - 1
    widths = (frames[order][last] - frames[order][first]) / step + 1
    need = float(unique_ids.size) * float(widths.max()) * 2 * 8
    if need > MAX_TRACKS_BYTES:
        raise TrackFileError(f"data error: {path}: {unique_ids.size} pedestrians over "
                             f"{widths.max():g} frames would take {need / 2 ** 30:.1f} GiB; "
                             f"allowed: at most {MAX_TRACKS_BYTES / 2 ** 30:g} GiB")
    return step


def read_track_rows(path: Path) -> np.ndarray:
    """The rows of a track file as an array (m, 4); a malformed file is a
    :class:`~pipeline.errors.TrackFileError` naming the file, the line and the format."""
    return _rows_and_lines(path)[0]


def _rows_and_lines(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """:func:`read_track_rows` and each row's line number in the file."""
    fmt = "4 tab- or space-separated numbers per line (frame, pedestrian_id, x_m, y_m)"
    try:
        opener = gzip.open if path.name.endswith(".gz") else open
        with opener(path, "rt") as handle:
            lines = handle.read().splitlines()
    except (OSError, UnicodeDecodeError, EOFError) as exc:
        raise TrackFileError(f"data error: {path}: cannot be read ({exc}); allowed: a text "
                             f"file (optionally gzip-compressed) of {fmt}") from None
    values, numbers = [], []
    for number, line in enumerate(lines, start=1):
        parts = line.split()
        if not parts:
            continue
        try:
            row = [float(p) for p in parts]
        except ValueError:
            row = []
        if len(row) != 4 or not all(math.isfinite(v) for v in row):
            shown = line if len(line) <= 40 else line[:37] + "..."
            raise TrackFileError(f"data error: {path}: line {number} ({shown!r}) is "
                                 f"malformed; allowed: {fmt}, all finite")
        values.append(row)
        numbers.append(number)
    if not values:
        raise TrackFileError(f"data error: {path}: no tracks; allowed: {fmt}")
    return np.array(values), np.array(numbers)


def pedestrians_near(tracks: SceneTracks, start_m: np.ndarray, goal_m: np.ndarray,
                     window_start_s: float, duration_s: float, corridor_m: float,
                     extension_s: float = 0.0) -> np.ndarray:
    """Indices of the pedestrians present in the window whose samples in it come within
    ``corridor_m`` of the start-goal segment (nearest first by that distance); a track
    extended by ``extension_s`` at both ends is present ``extension_s`` longer each way."""
    t = tracks.first_s[:, None] + np.arange(tracks.positions_m.shape[1])[None, :] \
        * tracks.step_s
    inside = (t >= window_start_s - tracks.step_s - extension_s) \
        & (t <= window_start_s + duration_s + tracks.step_s + extension_s) \
        & (np.arange(tracks.positions_m.shape[1])[None, :] < tracks.counts[:, None])
    gap = segment_distance(tracks.positions_m, start_m, goal_m)
    gap = np.where(inside, gap, np.inf).min(axis=1)
    near = np.flatnonzero(gap <= corridor_m)
    return near[np.argsort(gap[near], kind="stable")]


def segment_distance(points_m: np.ndarray, a_m: np.ndarray, b_m: np.ndarray) -> np.ndarray:
    """Distance of ``points_m`` (..., 2) to the segment from ``a_m`` to ``b_m``."""
    d = np.asarray(b_m, float) - np.asarray(a_m, float)
    rel = points_m - a_m
    s = np.clip((rel @ d) / float(d @ d), 0.0, 1.0)
    return np.linalg.norm(rel - s[..., None] * d, axis=-1)


def check_scene_fits(cfg: PedestrianConfig, tracks: SceneTracks, duration_s: float) -> None:
    """A scene too small for the crossing, or recorded for less time than a run lasts, is a
    :class:`~pipeline.errors.ConfigError` naming the key and the allowed range."""
    x0, x1, y0, y1 = tracks.extent_m
    room = math.hypot(x1 - x0, y1 - y0) - 2.0 * cfg.scene_margin_m
    if cfg.crossing_length_m > room:
        raise ConfigError("scenario.pedestrians.crossing_length_m", cfg.crossing_length_m,
                          f"<= {max(room, 0.0):.1f} m for scene '{tracks.name}' (its recorded "
                          f"extent {x1 - x0:.1f} m x {y1 - y0:.1f} m less scene_margin_m="
                          f"{cfg.scene_margin_m} on each side): the scene is too small for "
                          "the crossing")
    recorded = tracks.end_s - tracks.start_s
    if recorded < duration_s:
        raise ConfigError("scenario.n_steps", round(duration_s, 3),
                          f"a run no longer than scene '{tracks.name}' is recorded "
                          f"({recorded:.1f} s = n_steps x sample_time_s)")


def draw_pedestrian_member(base: ScenarioConfig, index: int,
                           vehicle_radius_m: float = 1.0) -> ScenarioConfig:
    """Member ``index`` of the pedestrian family of ``base`` (``base.family`` gives the seed,
    ``base.pedestrians`` the ranges).

    From ``numpy.random.default_rng([seed, index])``: a scene (uniformly, once), then the
    platform's speed, a window of the recording, a pedestrian present when the platform would
    be halfway (its position is the crossing's midpoint: the busy part) and a heading; start
    and goal lie ``crossing_length_m / 2`` either side. A draw whose start or goal leaves the
    scene's extent (less ``scene_margin_m``), or whose start is within both radii plus
    ``start_clearance_m`` of a pedestrian present at t = 0, is redrawn in the same scene (up to
    ``max_draws`` times).

    Returns
    -------
    ScenarioConfig
        A plain scenario (``family = None``) named ``<base>_<scene>_s<seed>_i<index>``, with
        ``pedestrians.scene`` and ``pedestrians.window_start_s`` set.
    """
    fam, ped = base.family, base.pedestrians
    if fam is None or ped is None:
        raise ValueError(f"scenario {base.name} has no pedestrian family to draw from")
    rng = np.random.default_rng([fam.seed, index])
    duration = base.n_steps * base.sample_time_s
    half = 0.5 * ped.crossing_length_m
    scenes = {name: load_scene(ped, name) for name in ped.scenes}
    for tracks in scenes.values():
        check_scene_fits(ped, tracks, duration)
    # the scene first and once: every scene gets its share of members, whatever its
    # rejection rate
    tracks = scenes[ped.scenes[int(rng.integers(len(ped.scenes)))]]
    if ped.draw == "scene":
        return _draw_from_scene(base, index, tracks, rng, vehicle_radius_m)
    for _attempt in range(ped.max_draws):
        low, high = ped.platform_speed_mps
        speed = round(float(rng.uniform(low, high)), 2)
        window = float(rng.uniform(tracks.start_s, tracks.end_s - duration))
        heading = float(rng.uniform(-np.pi, np.pi))
        pick = float(rng.uniform())
        everyone = tracks.motion(np.arange(tracks.counts.size), window,
                                   ped.track_extension_s)
        mid, _, present = everyone.states_at(half / speed)
        if not present.any():
            continue
        centre = mid[np.flatnonzero(present)[min(int(pick * present.sum()),
                                                 int(present.sum()) - 1)]]
        e = np.array([math.cos(heading), math.sin(heading)])
        start, goal = centre - half * e, centre + half * e
        if not (_inside(tracks, start, ped.scene_margin_m)
                and _inside(tracks, goal, ped.scene_margin_m)):
            continue
        if not _start_is_free(everyone, start, vehicle_radius_m, ped):
            continue
        return _drawn_member(base, index, tracks, start, goal, heading, speed, window)
    raise ConfigError("scenario.pedestrians.crossing_length_m", ped.crossing_length_m,
                      f"a crossing that fits scene '{tracks.name}' with a free start "
                      f"(member {index}: no fitting draw in max_draws={ped.max_draws}); a "
                      "shorter crossing, more draws or another scene")


def _draw_from_scene(base: ScenarioConfig, index: int, tracks: SceneTracks,
                     rng: np.random.Generator, vehicle_radius_m: float) -> ScenarioConfig:
    """A ``draw: scene`` member (see :func:`draw_pedestrian_member`): the platform's speed, a
    window, a crossing whose midpoint is a recorded position of the whole recording (a place
    someone walked, at any time: busy, never aimed at where a walker will be) and a heading;
    start and goal must each lie within ``walkable_radius_m`` of a recorded position and
    inside the scene's extent, the start free at t = 0; redrawn up to ``max_draws`` times."""
    fam, ped = base.family, base.pedestrians
    assert fam is not None and ped is not None
    duration = base.n_steps * base.sample_time_s
    half = 0.5 * ped.crossing_length_m
    points = tracks.recorded_points_m
    for _attempt in range(ped.max_draws):
        low, high = ped.platform_speed_mps
        speed = round(float(rng.uniform(low, high)), 2)
        window = float(rng.uniform(tracks.start_s, tracks.end_s - duration))
        heading = float(rng.uniform(-np.pi, np.pi))
        centre = points[int(rng.integers(points.shape[0]))]
        e = np.array([math.cos(heading), math.sin(heading)])
        start, goal = centre - half * e, centre + half * e
        if not (_inside(tracks, start, ped.scene_margin_m)
                and _inside(tracks, goal, ped.scene_margin_m)):
            continue
        gaps, _ = tracks.walkable.query(np.array([start, goal]))
        if np.max(gaps) > ped.walkable_radius_m:
            continue
        everyone = tracks.motion(np.arange(tracks.counts.size), window,
                                   ped.track_extension_s)
        if not _start_is_free(everyone, start, vehicle_radius_m, ped):
            continue
        return _drawn_member(base, index, tracks, start, goal, heading, speed, window)
    raise ConfigError("scenario.pedestrians.crossing_length_m", ped.crossing_length_m,
                      f"a crossing that fits scene '{tracks.name}' between walked places with "
                      f"a free start (member {index}: no fitting draw in max_draws="
                      f"{ped.max_draws}); a shorter crossing, more draws, a larger "
                      "walkable_radius_m or another scene")


def _start_is_free(everyone: RecordedTrackMotion, start_m: np.ndarray,
                   vehicle_radius_m: float, ped: PedestrianConfig) -> bool:
    """No pedestrian present at t = 0 within both radii plus ``start_clearance_m`` of the
    start."""
    at_start, _, there = everyone.states_at(0.0)
    clear = vehicle_radius_m + ped.radius_m + ped.start_clearance_m
    return not (there.any()
                and np.min(np.linalg.norm(at_start[there] - start_m, axis=1)) < clear)


def _drawn_member(base: ScenarioConfig, index: int, tracks: SceneTracks, start_m: np.ndarray,
                  goal_m: np.ndarray, heading_rad: float, speed_mps: float,
                  window_start_s: float) -> ScenarioConfig:
    """Member ``index`` as drawn: a plain scenario named ``<base>_<scene>_s<seed>_i<index>``
    with its crossing, speed, scene and window."""
    fam, ped = base.family, base.pedestrians
    assert fam is not None and ped is not None
    return replace(base, name=f"{base.name}_{tracks.name}_s{fam.seed}_i{index:04d}",
                   start_xy_m=[float(start_m[0]), float(start_m[1])],
                   goal_xy_m=[float(goal_m[0]), float(goal_m[1])],
                   start_heading_rad=heading_rad, speed_mps=speed_mps, family=None,
                   pedestrians=replace(ped, scene=tracks.name, window_start_s=window_start_s))


def _inside(tracks: SceneTracks, point_m: np.ndarray, margin_m: float) -> bool:
    x0, x1, y0, y1 = tracks.extent_m
    return bool(x0 + margin_m <= point_m[0] <= x1 - margin_m
                and y0 + margin_m <= point_m[1] <= y1 - margin_m)


def scene_of(scenario_name: str, scenes: list[str] | tuple[str, ...]) -> str | None:
    """The scene a member's name (``<base>_<scene>_s<seed>_i<index>``) was drawn from."""
    for scene in sorted(scenes, key=len, reverse=True):
        if f"_{scene}_s" in scenario_name:
            return scene
    return None


def recorded_motion(cfg: ScenarioConfig) -> tuple[RecordedTrackMotion, int]:
    """A member's pedestrians (those near its crossing, :func:`pedestrians_near`) and their
    number."""
    ped = cfg.pedestrians
    if ped is None or ped.scene is None or ped.window_start_s is None:
        raise ConfigError("scenario.pedestrians.scene", None if ped is None else ped.scene,
                          "a drawn member (scene and window_start_s set): run the family "
                          "(scenario=pedestrians), not its base")
    tracks = load_scene(ped, ped.scene)
    key = (tuple(cfg.start_xy_m), tuple(cfg.goal_xy_m), float(ped.window_start_s),
           float(cfg.n_steps * cfg.sample_time_s), float(ped.corridor_m),
           float(ped.track_extension_s))
    which = tracks.near.get(key)
    if which is None:
        which = pedestrians_near(tracks, np.asarray(cfg.start_xy_m, float),
                                 np.asarray(cfg.goal_xy_m, float), ped.window_start_s,
                                 cfg.n_steps * cfg.sample_time_s, ped.corridor_m,
                                 ped.track_extension_s)
        if len(tracks.near) >= 1024:
            tracks.near.clear()
        tracks.near[key] = which
    return tracks.motion(which, ped.window_start_s, ped.track_extension_s), int(which.size)


@dataclass(frozen=True)
class CrossingDifficulty:
    """How hard a crossing is, from the recording alone (no method involved): whether the
    straight start-goal line driven at the drawn speed meets a walker before the goal
    (``straight_line_meets``), and whether a platform standing still at the start is touched
    during the run's time (``standing_touched``); a touch: a present walker's centre within
    the two radii of the platform's."""

    straight_line_meets: bool
    standing_touched: bool


def crossing_difficulty(cfg: ScenarioConfig, vehicle_radius_m: float) -> CrossingDifficulty:
    """:class:`CrossingDifficulty` of a drawn member ``cfg`` (its recorded walkers near the
    crossing, :func:`recorded_motion`, sampled at the scenario's sample time)."""
    ped = cfg.pedestrians
    assert ped is not None
    motion, _ = recorded_motion(cfg)
    start, goal = np.asarray(cfg.start_xy_m, float), np.asarray(cfg.goal_xy_m, float)
    length = float(np.linalg.norm(goal - start))
    direction = (goal - start) / max(length, 1e-12)
    arrive_s = length / float(cfg.speed_mps)
    reach = vehicle_radius_m + ped.radius_m
    # every step of the run at once: the walkers present then, the platform on the line
    # (until it arrives) and standing at the start
    times = np.arange(int(cfg.n_steps) + 1) * float(cfg.sample_time_s)
    positions, present = motion.positions_over(times)
    on_line = start + np.minimum(float(cfg.speed_mps) * times, length)[:, None] * direction
    to_line = np.hypot(positions[:, :, 0] - on_line[:, None, 0],
                       positions[:, :, 1] - on_line[:, None, 1])
    to_start = np.hypot(positions[:, :, 0] - start[0], positions[:, :, 1] - start[1])
    meets = bool(np.any(present & (to_line < reach) & (times <= arrive_s)[:, None]))
    touched = bool(np.any(present & (to_start < reach)))
    return CrossingDifficulty(meets, touched)


def pedestrian_scenario(cfg: ScenarioConfig) -> Scenario:
    """A member of the pedestrian family: its recorded pedestrians as the obstacles (true
    tracks), seen within the sensor range, handed to the MPC nearest first."""
    ped = cfg.pedestrians
    assert ped is not None
    recorded, n = recorded_motion(cfg)
    start_positions, _, _ = recorded.states_at(0.0)
    # replayed: every step's walkers at once (the loop asks at k * sample_time_s)
    motion: ObstacleMotion = SteppedTrackMotion.of(recorded, float(cfg.sample_time_s),
                                                   int(cfg.n_steps))
    if ped.walkers == "reactive":
        from pipeline.loop.social_force import SocialForceMotion, SocialForceSettings

        motion = SocialForceMotion(recorded, float(cfg.sample_time_s), SocialForceSettings(
            ped.social_tau_s, ped.social_lookahead_s, ped.social_strength_mps2,
            ped.social_range_m, ped.social_max_speed_factor, ped.radius_m))
    return Scenario(
        name=cfg.name, start_m=np.asarray(cfg.start_xy_m, dtype=float),
        start_heading_rad=math.remainder(float(cfg.start_heading_rad), 2.0 * math.pi),
        goal_m=np.asarray(cfg.goal_xy_m, dtype=float),
        goal_tolerance_m=float(cfg.goal_tolerance_m), speed_mps=float(cfg.speed_mps),
        initial_speed_mps=float(cfg.speed_mps if cfg.initial_speed_mps is None
                                else cfg.initial_speed_mps),
        sample_time_s=float(cfg.sample_time_s), n_steps=int(cfg.n_steps),
        plant_substeps=int(cfg.plant_substeps), obstacle_start_m=start_positions,
        obstacle_velocity_mps=np.zeros((n, 2)), obstacle_radius_m=np.full(n, ped.radius_m),
        obstacle_appear_s=np.zeros(n), obstacle_motion=motion,
        sensor_range_m=float(ped.sensor_range_m), nearest_first=True,
        end_at_contact=bool(ped.end_at_contact))


class PedestrianSource:
    """The recorded pedestrians' source (``conf/scenario/pedestrians.yaml``): members drawn by
    :func:`draw_pedestrian_member`, each built by :func:`pedestrian_scenario`. Its family
    splits by scene: the tune trains on some scenes and judges on others
    (``parts_key``)."""

    needs_extra: ClassVar[Extra | None] = None
    #: the list the tune splits into its training and held-out scenes
    parts_key = "scenario.pedestrians.scenes"

    def __init__(self, scenario: ScenarioConfig, vehicle_radius_m: float = 1.0) -> None:
        target = ScenarioSourceConfig.PEDESTRIANS
        if scenario.pedestrians is None:
            raise ConfigError("scenario.source._target_", target, "another source, or a "
                              "scenario.pedestrians block (scenario=pedestrians), which this "
                              "source reads")
        refuse_blocks(scenario, target, {"commonroad": ScenarioSourceConfig.COMMONROAD})
        self.base, self.vehicle_radius_m = scenario, float(vehicle_radius_m)

    def build(self, cfg: ScenarioConfig) -> Scenario:
        return pedestrian_scenario(cfg)

    def member(self, seed: int, index: int) -> ScenarioConfig:
        return draw_pedestrian_member(with_family_seed(self.base, seed), index,
                                      self.vehicle_radius_m)
