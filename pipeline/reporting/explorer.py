"""The scenario explorer: every member of every experiment, animated, in the report folder.

``explorer.html`` (beside ``index.html``) plays one member at a time, every method of the
experiment side by side: the vehicle and its footprint, the obstacles (true and as predicted),
the APF path, the MPC's predicted horizon and its collision half-planes at each step, the
steering against its bound, and a time cursor shared with the member's signals (steering,
lateral offset, clearance). A member is opened with ``explorer.html#<experiment>/<member>``
(:func:`explorer_href`): ``<experiment>`` is the outputs subfolder (``family``, ``peers``,
``paper``, ...), ``<member>`` the family member's index (0 for a single run).

No server and no network: the page is plain HTML with its script inline, and each member's data
is a file ``explorer_data/<experiment>/<member>.js`` beside it, loaded on demand by a
``<script>`` tag (a browser refuses ``fetch`` of local files from ``file://``). The file sets
``window.__explorerData["<experiment>/<member>"]`` to the member's data: JSON, gzip-compressed
and base64-encoded (the browser's ``DecompressionStream`` undoes it), positions rounded to the
centimetre and angles to the milliradian, what the picture needs and no more.

The data come from the run folders: the trajectory (pose, steering, obstacles) and the horizon
record each run keeps (:mod:`pipeline.loop.horizon`). A run written before the horizon was
recorded still animates, without its plan and half-planes (the page says so).
"""

from __future__ import annotations

import base64
import functools
import gzip
import hashlib
import json
import logging
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from pipeline.errors import ConfigError, RunFolderError
from pipeline.reporting.clip import CLIPS_FOLDER
from pipeline.reporting.figures.colors import method_color
from pipeline.store.files import write_text_atomic
from pipeline.store.layout import OutputsLayout
from pipeline.store.runs import (
    folder_kind,
    member_folders,
    read_horizon,
    read_run,
    read_run_trajectory,
    run_scenario_data,
)

log = logging.getLogger("pipeline.reporting")

#: The explorer's page (beside ``index.html``) and the folder of its members' data.
PAGE = "explorer.html"
DATA_FOLDER = "explorer_data"
#: Per experiment and member, the digest of the runs its data file was made from and of the
#: file's own bytes (reuse only when both match).
SOURCES = "sources.json"
#: Outputs sections that hold studies, not experiments of runs (never in the explorer).
STUDY_SECTIONS = ("sweeps", "ablation", "interpretations", "multiverse", "tune",
                  "tune_unpruned", "tune_peers", "member_cache", "kinematic_readings",
                  "nmpc_check", "speed", "euro_ncap")
#: Study sections whose subfolders are experiments of their own (a study of several tracks,
#: each a folder of method families: ``make euro-ncap``'s), shown as ``<section>-<track>``.
NESTED_SECTIONS = ("euro_ncap",)
#: Experiments run on another one's scenarios (the same seed, the first members): their
#: members are shown beside that one's treatment and control (section -> its family's section).
COMPANIONS = {"peers": "family", "kinematic_peers": "kinematic_family"}
#: The companion family's methods shown beside a peer (when it holds them).
COMPANION_METHODS = ("improved", "baseline")
#: Sections shown first, in this order (any other experiment folder follows by name).
ORDER = ("paper", "family", "kinematic", "kinematic_family", "frames", "apf_alone", "peers",
         "kinematic_peers")


def explorer_href(experiment: str, member_index: int) -> str:
    """The link that opens one member in the explorer (relative to ``index.html``).

    Parameters
    ----------
    experiment : str
        The outputs subfolder (``family``, ``kinematic_family``, ``frames``, ``apf_alone``,
        ``peers``, ``kinematic_peers``, ``paper``, ``kinematic``, ...).
    member_index : int
        The family member's index (0 for a single-scenario experiment).
    """
    return f"{PAGE}#{experiment}/{int(member_index)}"


@dataclass
class ExplorerIndex:
    """What the explorer holds: per experiment its methods and members, and the bytes written.

    Attributes
    ----------
    experiments : dict of str to dict
        ``{"methods": [...], "members": [...], "single": bool}`` per experiment.
    data_bytes : int
        The members' data files, together.
    page_bytes : int
    """

    experiments: dict[str, dict] = field(default_factory=dict)
    data_bytes: int = 0
    page_bytes: int = 0

    def has(self, experiment: str, member_index: int) -> bool:
        entry = self.experiments.get(experiment)
        return entry is not None and int(member_index) in entry["members"]

    def to_json(self) -> dict:
        return {"experiments": self.experiments}


def experiment_folders(run_root: Path) -> list[Path]:
    """The experiment folders under ``run_root`` (the studies' sections left out), in the
    report's order: each holds one folder per method, a family or a single run."""
    run_root = Path(run_root)
    if not run_root.is_dir():
        return []
    try:
        layout = OutputsLayout.load(run_root)
        studies = {getattr(layout, name) for name in STUDY_SECTIONS}
        order = [getattr(layout, name) for name in ORDER]
    except (ConfigError, OSError, ValueError, TypeError):
        # a bad paths file is the report's to say; keep the default names
        studies, order = set(STUDY_SECTIONS), list(ORDER)
    found = []
    for folder in sorted(p for p in run_root.iterdir() if p.is_dir()):
        if folder.name in studies or folder.name.startswith("."):
            continue
        if any(folder_kind(m) for m in folder.iterdir() if m.is_dir()):
            found.append(folder)
    if not found and any(folder_kind(m) for m in run_root.iterdir()
                         if m.is_dir() and m.name not in studies):
        return [run_root]  # the report of one experiment's folder (e.g. outputs/paper)
    return sorted(found, key=lambda p: (order.index(p.name) if p.name in order else len(order),
                                        p.name))


def experiment_entries(run_root: Path) -> list[tuple[str, Path]]:
    """Every experiment the explorer shows, as ``(name, folder)``: those of
    :func:`experiment_folders` by their folder's name, then each track of a
    :data:`NESTED_SECTIONS` study as ``<section>-<track>`` (its name in the page's addresses,
    ``explorer.html#euro_ncap-lateral/3``)."""
    run_root = Path(run_root)
    entries = [(folder.name, folder) for folder in experiment_folders(run_root)]
    if entries == [(run_root.name, run_root)] or not run_root.is_dir():
        return entries  # the report of one experiment's folder
    for section in NESTED_SECTIONS:
        top = run_root / _section_folder(run_root, section)
        if not top.is_dir():
            continue
        for track in sorted(p for p in top.iterdir()
                            if p.is_dir() and not p.name.startswith(".")):
            if any(folder_kind(m) for m in track.iterdir() if m.is_dir()):
                entries.append((f"{top.name}-{track.name}", track))
    return entries


def _method_members(method_dir: Path) -> dict[int, Path] | None:
    """A method folder's members (index -> run folder); None when it holds neither a family
    nor a run."""
    kind = folder_kind(method_dir)
    if kind == "family":
        try:
            return {int(m.name.split("_")[1]): m for m in member_folders(method_dir)}
        except (RunFolderError, ValueError, IndexError):
            return None
    if kind == "run":
        return {0: method_dir}
    return None


def _ints(values, scale: float) -> list:
    """``values * scale`` rounded to integers (nested lists for a 2-D array), None where not
    finite (JSON null)."""
    array = np.asarray(values, float) * scale
    finite = np.isfinite(array)
    out = np.where(finite, np.round(np.where(finite, array, 0.0)), 0).astype(np.int64).tolist()
    if finite.all():
        return out
    if array.ndim == 1:
        return [v if ok else None for v, ok in zip(out, finite.tolist(), strict=True)]
    return [[v if ok else None for v, ok in zip(row, flags, strict=True)]
            for row, flags in zip(out, finite.tolist(), strict=True)]


def _column(frame: pd.DataFrame, name: str) -> np.ndarray:
    if name in frame:
        return pd.to_numeric(frame[name], errors="coerce").to_numpy(float)
    return np.full(len(frame), np.nan)


def _columns(frame: pd.DataFrame, names: list[str]) -> np.ndarray:
    """:func:`_column` of each of ``names`` as the columns of one ``(rows, names)`` array (a
    numeric column converted as it is, any other through ``pd.to_numeric``: the same
    numbers)."""
    out = np.full((len(frame), len(names)), np.nan)
    for k, name in enumerate(names):
        if name not in frame:
            continue
        column = frame[name]
        out[:, k] = column.to_numpy(float) if column.dtype.kind in "fiub" \
            else pd.to_numeric(column, errors="coerce").to_numpy(float)
    return out


def _flags(frame: pd.DataFrame, names: list[str]) -> np.ndarray:
    """:func:`_flag` of each of ``names`` as the columns of one ``(rows, names)`` array."""
    out = np.zeros((len(frame), len(names)), bool)
    for k, name in enumerate(names):
        out[:, k] = _flag(frame, name)
    return out


def _flag(frame: pd.DataFrame, name: str) -> np.ndarray:
    if name not in frame:
        return np.zeros(len(frame), bool)
    column = frame[name]
    if column.dtype == bool:  # read_csv's True/False column: the same flags, without a map
        return column.to_numpy()
    return column.map(lambda v: str(v).strip().lower() in ("true", "1", "1.0")).to_numpy()


def method_data(trajectory: pd.DataFrame, horizon: dict[str, np.ndarray] | None,
                footprint_m: float) -> dict:
    """One run's part of a member's data: series per step, rounded (positions in cm, angles
    in mrad, times in ms), the APF path and the plan relative to the vehicle, the half-planes
    as ``[step, horizon step, slot, normal mrad, offset cm]``."""
    from pipeline.loop.trajectory import obstacle_column, obstacle_indices

    n = len(trajectory)
    x, y = _column(trajectory, "X_m"), _column(trajectory, "Y_m")
    out: dict = {"n": n, "t": _ints(_column(trajectory, "time_s"), 1000),
                 "x": _ints(x, 100), "y": _ints(y, 100),
                 "psi": _ints(_column(trajectory, "psi_rad"), 1000),
                 "delta": _ints(_column(trajectory, "delta_rad"), 1000),
                 "ey": _ints(_column(trajectory, "e_y_m"), 100)}
    # every obstacle's columns at once (a crowd logs 50 slots: 200 columns)
    slots = obstacle_indices(trajectory.columns)
    ox = _columns(trajectory, [obstacle_column(j, "x_m") for j in slots])
    oy = _columns(trajectory, [obstacle_column(j, "y_m") for j in slots])
    radius = _columns(trajectory, [obstacle_column(j, "radius_m") for j in slots])
    seen = _flags(trajectory, [obstacle_column(j, "visible") for j in slots])
    gap = np.hypot(x[:, None] - ox, y[:, None] - oy) - radius - footprint_m
    # the least gap to a seen obstacle (min is exact: the same number in any order)
    clearance = np.min(np.where(seen & np.isfinite(gap), gap, np.inf), axis=1, initial=np.inf)
    xs, ys, flags = _ints(ox.T, 100), _ints(oy.T, 100), seen.T.astype(np.int64).tolist()
    # the predictions' obstacle velocities by slot (the horizon's slots may be fewer)
    velocity = horizon.get("obstacle_velocity_mps") if horizon is not None else None
    with_velocity = 0 if velocity is None else int(velocity.shape[1])
    vxs = _ints(velocity[:n, :, 0].T, 100) if velocity is not None and with_velocity else []
    vys = _ints(velocity[:n, :, 1].T, 100) if velocity is not None and with_velocity else []
    obstacles = []
    for k, j in enumerate(slots):
        column = radius[:, k]
        entry = {"x": xs[k], "y": ys[k],
                 "r": _ints([np.nanmax(column) if np.isfinite(column).any() else 0.0], 100)[0],
                 "vis": flags[k]}
        if j < with_velocity:
            entry["vx"], entry["vy"] = vxs[j], vys[j]
        obstacles.append(entry)
    out["clear"] = _ints(np.where(np.isfinite(clearance), clearance, np.nan), 100)
    out["obs"] = obstacles
    if horizon is None:
        return out
    here = np.column_stack([x, y])[:, None, :]
    for name, key in (("apf_path_m", "apf"), ("plan_xy_m", "plan")):
        if name in horizon:
            points = horizon[name][:n] - here[:horizon[name].shape[0]]
            out[key] = _ints(points.reshape(points.shape[0], -1), 100)
    if "prediction_step_s" in horizon:
        out["dtp"] = _ints(horizon["prediction_step_s"][:n], 1000)
    if "constraint_normal_rad" in horizon and "constraint_offset_m" in horizon:
        normal, offset = horizon["constraint_normal_rad"][:n], horizon["constraint_offset_m"][:n]
        where = np.nonzero(np.isfinite(normal) & np.isfinite(offset))
        out["cons"] = np.column_stack([
            *where, np.round(normal[where] * 1000), np.round(offset[where] * 100)
        ]).astype(np.int64).tolist()
    return out


@dataclass(frozen=True)
class MethodSettings:
    """What the explorer needs of a method's settings (read once per method folder)."""

    start: tuple[float, float]
    goal: tuple[float, float]
    footprint_m: float
    steering_max_rad: float
    sample_time_s: float
    scenario: str
    controller: str

    @classmethod
    def of(cls, run_folder: Path) -> MethodSettings:
        cfg = read_run(run_folder, trajectory=False).config
        start, goal = cfg.scenario.start_xy_m, cfg.scenario.goal_xy_m
        return cls((float(start[0]), float(start[1])), (float(goal[0]), float(goal[1])),
                   float(cfg.vehicle.footprint_radius_m), float(cfg.vehicle.steering_max_rad),
                   float(cfg.scenario.sample_time_s), str(cfg.scenario.name),
                   # a plug-in's class (a peer's), else the built-in kind
                   str(cfg.controller._target_ or cfg.controller.kind).rsplit(".", 1)[-1])

    def for_member(self, run_folder: Path) -> MethodSettings:
        """These settings with the scenario of the run in ``run_folder`` (its name, start,
        goal and sample time: a family's members differ in their scenario alone, and a drawn
        pedestrian crossing has its own start and goal), read from its ``config.yaml`` as
        written instead of typing every member's settings again (that was a sixth of the
        explorer's time); :class:`RunFolderError` when they cannot be read."""
        scenario = run_scenario_data(run_folder)
        try:
            start, goal = scenario["start_xy_m"], scenario["goal_xy_m"]
            return replace(
                self, start=(float(start[0]), float(start[1])),
                goal=(float(goal[0]), float(goal[1])),
                sample_time_s=float(scenario["sample_time_s"]), scenario=str(scenario["name"]))
        except (KeyError, IndexError, TypeError, ValueError) as exc:
            raise RunFolderError(f"{run_folder}: settings in config.yaml cannot be read "
                                 f"(scenario: {type(exc).__name__})") from None


#: The numbers the explorer shows beside a member's scenes: each claim's primary metric (the
#: package's catalogue, C0's collision first) and the least clearance.
def _claim_metrics() -> tuple[tuple[str, str], ...]:
    from pipeline.analysis.claims.catalogue import ALL_CLAIMS

    return tuple((c.claim_id, c.primary_metric) for c in ALL_CLAIMS) + (("", "min_clearance_m"),)


def claim_numbers(metrics: dict) -> dict[str, float | None]:
    """A run's claim metrics (:func:`_claim_metrics`) from its ``metrics.json``: a number
    rounded to 4 significant digits, None where missing or not finite (collision as 0/1)."""
    return {name: _number(metrics.get(name)) for _, name in _claim_metrics()}


def _number(value: object) -> float | None:
    """One metric value as the explorer shows it: 4 significant digits, a flag as 0/1, None
    where missing or not finite."""
    if isinstance(value, str):
        value = {"true": 1.0, "false": 0.0}.get(value.strip().lower(), value)
    try:
        number = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        return None
    return float(f"{number:.4g}") if np.isfinite(number) else None


def difference_pair(methods: list[str]) -> list[str]:
    """The two methods whose per-member difference the explorer's member list sorts by: the
    registry's treatment and its first control (by ``run.order``), else the first two."""
    from pipeline.methods import method_info

    by_role: dict[str, list[str]] = {}
    for name in sorted(methods, key=lambda m: (method_info(m).order, m)):
        by_role.setdefault(method_info(name).role, []).append(name)
    pair = by_role.get("treatment", [])[:1] + by_role.get("control", [])[:1]
    return pair if len(pair) == 2 else methods[:2]


def member_numbers(folder: Path, methods: list[str], members: list[int]
                   ) -> dict[str, dict[str, list]]:
    """Per method of a family experiment, each claim metric over ``members`` (in that order;
    None where a member has no number), from its ``family_metrics.csv``: what the explorer's
    member list sorts and filters by. A method without the table is left out."""
    from pipeline.store.runs import read_family

    out: dict[str, dict[str, list]] = {}
    for method in methods:
        if folder_kind(Path(folder) / method) != "family":
            continue
        try:
            frame = read_family(Path(folder) / method, members=False, settings=False
                                ).table.set_index("member")
        except (RunFolderError, KeyError):
            continue
        columns = {}
        for _, name in _claim_metrics():
            if name not in frame.columns:
                continue
            columns[name] = [_number(frame.at[i, name]) if i in frame.index else None
                             for i in members]
        if columns:
            out[method] = columns
    return out


def member_payload(experiment: str, member: int, runs: dict[str, Path],
                   settings: dict[str, MethodSettings]) -> dict | None:
    """Every method's data on one member (``runs``: method -> run folder, ``settings``: method
    -> its settings); None when no run can be read."""
    methods, first = [], None
    for method, folder in runs.items():
        try:
            trajectory, metrics = read_run_trajectory(folder)
            # the member's own scenario (its name, start and goal: a drawn pedestrian crossing
            # has its own), read from its first readable run
            cfg = settings[method]
            own = cfg.for_member(folder) if first is None else None
        except RunFolderError as exc:
            log.warning("explorer: %s", exc)
            continue
        first = first or own
        data = method_data(trajectory, read_horizon(folder), cfg.footprint_m)
        # its colour in every experiment and in the report: the method's (a companion run,
        # "improved (family)", the method's own)
        data.update(name=method, color=method_color(method.split(" (")[0].split(" #")[0]),
                    controller=cfg.controller,
                    collision=str(metrics.get("collision")).lower() in ("true", "1", "1.0"),
                    metrics=claim_numbers(metrics))
        methods.append(data)
    if not methods or first is None:
        return None
    return {"key": f"{experiment}/{member}", "experiment": experiment, "member": member,
            "start": list(first.start), "goal": list(first.goal), "footprint": first.footprint_m,
            "steer_max": first.steering_max_rad, "dt": first.sample_time_s,
            "scenario": first.scenario, "methods": methods}


def member_data(run_root: Path, experiment: str, member: int) -> dict | None:
    """The explorer's data of one member, ``<experiment>/<member>`` under ``run_root`` (the
    payload :func:`member_payload` builds, its companions included), read from the run
    folders; None when the experiment or the member is not there."""
    folder = dict(experiment_entries(run_root)).get(experiment, Path(run_root) / experiment)
    if not folder.is_dir():
        return None
    # no data folder is written: the plan's targets are only named
    plan = _experiment_plan(Path(run_root), folder, Path(run_root) / DATA_FOLDER, experiment)
    task = None if plan is None else next(
        (t for t in plan["tasks"] if t["member"] == int(member)), None)
    if task is None:
        return None
    return member_payload(experiment, int(member), task["runs"], task["settings"])


def experiment_members(run_root: Path) -> dict[str, list[int]]:
    """Every experiment under ``run_root`` the explorer shows, with its members' indices."""
    found = {}
    for name, folder in experiment_entries(run_root):
        indices: set[int] = set()
        for method_dir in (p for p in folder.iterdir() if p.is_dir()):
            indices |= set(_method_members(method_dir) or {})
        if indices:
            found[name] = sorted(indices)
    return found


def data_script(key: str, payload: dict) -> str:
    """A member's data file: the payload as gzip-compressed, base64-encoded JSON assigned to
    ``window.__explorerData[key]`` (the same bytes for the same payload). gzip's fastest level:
    a walker crossing's 1.5 MB of JSON packs in 11 ms to 436 kB, against 73 ms to 356 kB at
    level 6 (the browser inflates either in milliseconds)."""
    text = json.dumps(payload, separators=(",", ":"), allow_nan=False)
    packed = base64.b64encode(gzip.compress(text.encode(), compresslevel=1, mtime=0)).decode()
    return ("(window.__explorerData = window.__explorerData || {})"
            f"[{json.dumps(key)}] = \"{packed}\";\n")


def remove_explorer_temporaries(out_dir: Path) -> list[Path]:
    """Remove the temporaries a killed explorer writer leaves in ``out_dir`` (its page's and
    its data files', :func:`~pipeline.store.files.write_text_atomic`'s ``.<name>.*.tmp``);
    returns them. The files it finished are whole and stay."""
    out_dir = Path(out_dir)
    left = list(out_dir.glob(f".{PAGE}.*.tmp"))
    if (out_dir / DATA_FOLDER).is_dir():
        left += list((out_dir / DATA_FOLDER).rglob(".*.tmp"))
    for path in left:
        path.unlink(missing_ok=True)
    return left


def write_explorer(run_root: Path, out_dir: Path, experiments: list[Path] | None = None,
                   jobs: int | None = None) -> ExplorerIndex:
    """Write ``out_dir/explorer.html`` and one data file per member of every experiment under
    ``run_root`` (:func:`experiment_entries`); returns what was written.

    Parameters
    ----------
    run_root : Path
        The outputs root (``make reproduce``'s ``outputs``).
    out_dir : Path
        The report folder.
    experiments : list of Path, optional
        The experiment folders to include (default: all of :func:`experiment_entries`).
    jobs : int, optional
        Members written at the same time, in forked children (default: the machine's cores;
        1: one after the other here). The files are the same.
    """
    out_dir = Path(out_dir)
    index = ExplorerIndex()
    data_root = out_dir / DATA_FOLDER
    plans = []
    entries = [(folder.name, folder) for folder in experiments] if experiments is not None \
        else experiment_entries(run_root)
    for name, folder in entries:
        plan = _experiment_plan(run_root, folder, data_root, name)
        if plan is not None:
            plans.append(plan)
    todo = [task for plan in plans for task in plan["tasks"] if not task["kept"]]
    sizes = _write_members(todo, jobs)
    for plan in plans:
        written, sources = [], {}
        for task in plan["tasks"]:
            size = task["target"].stat().st_size if task["kept"] else sizes.get(task["key"])
            if size is None:
                continue
            index.data_bytes += size
            written.append(task["member"])
            if task["digest"] is not None:
                sources[str(task["member"])] = {"runs": task["digest"],
                                                "file": _file_digest(task["target"])}
        if sources:
            write_text_atomic(plan["sources"], json.dumps(sources, sort_keys=True) + "\n")
        if written:
            index.experiments[plan["name"]] = {
                "methods": plan["methods"], "members": written,
                "single": plan["single"] and written == [0]}
            numbers = member_numbers(plan["folder"], plan["methods"], written)
            if numbers:
                index.experiments[plan["name"]]["numbers"] = numbers
                index.experiments[plan["name"]]["pair"] = difference_pair(list(numbers))
    html = explorer_page(index)
    write_text_atomic(out_dir / PAGE, html)
    index.page_bytes = len(html.encode())
    log.info("explorer: %d experiments, %d members (%d written), %.1f MB of member data",
             len(index.experiments), sum(len(e["members"]) for e in index.experiments.values()),
             len(sizes), index.data_bytes / 1e6)
    return index


def _experiment_plan(run_root: Path, folder: Path, data_root: Path, name: str | None = None
                     ) -> dict | None:
    """One experiment's members to write: each with its runs, settings, target file and
    whether the file already there was made from the same runs (``kept``); ``name``: the
    experiment's name in the page (its folder's by default)."""
    name = name if name is not None else folder.name
    by_method, settings = {}, {}
    for method_dir in sorted(p for p in folder.iterdir() if p.is_dir()):
        members = _method_members(method_dir)
        if not members:
            continue
        try:
            settings[method_dir.name] = MethodSettings.of(members[min(members)])
        except RunFolderError as exc:
            log.warning("explorer: %s", exc)
            continue
        by_method[method_dir.name] = members
    if not by_method:
        return None
    single = all(len(m) == 1 for m in by_method.values())
    indices = sorted({i for members in by_method.values() for i in members})
    by_method, settings = _with_companions(run_root, name, by_method, settings, indices)
    sources = data_root / name / SOURCES
    known = _read_sources(sources)
    tasks = []
    for member in indices:
        runs = {m: members[member] for m, members in by_method.items() if member in members}
        target = data_root / name / f"{member}.js"
        digest = _runs_digest(runs)
        # kept only when made from the same runs and still the bytes then written (a damaged
        # data file is written again)
        entry = known.get(str(member))
        kept = digest is not None and isinstance(entry, dict) \
            and entry.get("runs") == digest and _file_digest(target) == entry.get("file")
        tasks.append({"key": f"{name}/{member}", "experiment": name,
                      "member": member, "runs": runs,
                      "settings": {m: settings[m] for m in runs}, "target": target,
                      "digest": digest, "kept": kept})
    return {"name": name, "folder": folder, "methods": list(by_method), "single": single,
            "sources": sources, "tasks": tasks}


def _write_member(task: dict) -> tuple[str, int | None]:
    """Write one member's data file; its key and size (None: no run could be read)."""
    payload = member_payload(task["experiment"], task["member"], task["runs"],
                             task["settings"])
    if payload is None:
        return task["key"], None
    text = data_script(payload["key"], payload)
    write_text_atomic(task["target"], text)
    return task["key"], len(text.encode())


def _write_members(tasks: list[dict], jobs: int | None) -> dict[str, int]:
    """:func:`_write_member` of every task, in ``jobs`` forked children when there are many
    (the machine's cores by default); key -> size of each file written."""
    import multiprocessing
    import os
    from concurrent.futures import ProcessPoolExecutor

    jobs = jobs if jobs is not None else (os.cpu_count() or 1)
    if jobs <= 1 or len(tasks) < 40 or "fork" not in multiprocessing.get_all_start_methods():
        results = [_write_member(task) for task in tasks]
    else:
        with ProcessPoolExecutor(jobs, mp_context=multiprocessing.get_context("fork")) as pool:
            results = list(pool.map(_write_member, tasks, chunksize=16))
    return {key: size for key, size in results if size is not None}


def _with_companions(run_root: Path, experiment: str, by_method: dict, settings: dict,
                     indices: list[int]) -> tuple[dict, dict]:
    """``by_method`` and ``settings`` with the companion family's treatment and control first
    (:data:`COMPANIONS`; as ``<method> (<family>)``), on the members this experiment has."""
    section = next((s for s, f in COMPANIONS.items()
                    if _section_folder(run_root, s) == experiment), None)
    if section is None:
        return by_method, settings
    family = Path(run_root) / _section_folder(run_root, COMPANIONS[section])
    first, first_settings = {}, {}
    for method in COMPANION_METHODS:
        members = _method_members(family / method) if (family / method).is_dir() else None
        if not members:
            continue
        members = {i: members[i] for i in indices if i in members}
        if not members:
            continue
        name = f"{method} ({family.name})"
        try:
            first_settings[name] = MethodSettings.of(members[min(members)])
        except RunFolderError as exc:
            log.warning("explorer: %s", exc)
            continue
        first[name] = members
    return {**first, **by_method}, {**first_settings, **settings}


def _section_folder(run_root: Path, section: str) -> str:
    """The folder name of a layout section (its default name when the layout is unreadable)."""
    try:
        return str(getattr(OutputsLayout.load(run_root), section))
    except (ConfigError, OSError, ValueError, TypeError):
        return section


def _runs_digest(runs: dict[str, Path]) -> str | None:
    """SHA-256 of the runs' manifests (each names its files' hashes) and of this module's code
    version: a member's data file is written again only when one of them changed."""
    from pipeline.store.manifest import MANIFEST, code_version

    digest = hashlib.sha256(code_version().encode())
    try:
        for method, folder in sorted(runs.items()):
            digest.update(method.encode())
            digest.update((Path(folder) / MANIFEST).read_bytes())
    except OSError:
        return None
    return digest.hexdigest()[:32]


def _file_digest(path: Path) -> str | None:
    """SHA-256 (first 32 hex digits) of a data file's bytes, None when it cannot be read."""
    try:
        return hashlib.sha256(Path(path).read_bytes()).hexdigest()[:32]
    except OSError:
        return None


def _read_sources(path: Path) -> dict:
    try:
        data = json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}
    return data if isinstance(data, dict) else {}


@functools.lru_cache(maxsize=1)
def _explorer_environment() -> Any:
    """The explorer's own Jinja environment (the page's imports this module for
    explorer_href), one per process: its template compiled once."""
    import jinja2

    return jinja2.Environment(loader=jinja2.PackageLoader("pipeline.reporting", "templates"),
                              autoescape=jinja2.select_autoescape(["html", "j2"]),
                              undefined=jinja2.StrictUndefined)


def explorer_page(index: ExplorerIndex) -> str:
    """The explorer's HTML: its template with the index of experiments and members."""
    return _explorer_environment().get_template("explorer.html.j2").render(
        # no "</" inside the page's script element (a folder name cannot end it)
        index_json=json.dumps(index.to_json(), separators=(",", ":")).replace("</", "<\\/"),
        data_folder=DATA_FOLDER, clips_folder=CLIPS_FOLDER,
        claim_metrics_json=json.dumps([list(p) for p in _claim_metrics()]))
