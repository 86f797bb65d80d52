"""Score any trajectory CSV with the Table 1 metrics: ``python -m pipeline.score FILE.csv``.

Required columns: ``time_s``, ``X_m``, ``Y_m`` (strictly increasing time, at least two rows,
numbers only). Optional: ``psi_rad``, ``vx_mps``, ``vy_mps``, ``r_rad_s``, ``delta_rad``,
``steering_rate_rad_s`` (derived from the path where missing; steering metrics need
``delta_rad``), and obstacles as ``obs{j}_x_m, obs{j}_y_m, obs{j}_radius_m, obs{j}_visible`` or
through ``--obstacle``. Other tools' column names are mapped with ``--columns``, e.g.
``--columns time_s=t,X_m=x,Y_m=y,psi_rad=theta`` for the paper's MATLAB state ``[x y theta v]``.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
import pandas as pd

from pipeline.config import MetricsConfig
from pipeline.metrics import TrajectoryContext, compute_metrics

REQUIRED = ("time_s", "X_m", "Y_m")
OPTIONAL = ("psi_rad", "vx_mps", "vy_mps", "r_rad_s", "delta_rad", "steering_rate_rad_s")


class TrajectoryFileError(ValueError):
    """A trajectory file that cannot be scored; the message says why."""


def _pairs(text: str, option: str) -> dict[str, str]:
    mapping = {}
    for item in filter(None, (part.strip() for part in text.split(","))):
        ours, sep, theirs = item.partition("=")
        if not sep or not ours or not theirs:
            raise TrajectoryFileError(f"{option}: expected OUR=THEIRS pairs, got {item!r}")
        mapping[ours] = theirs
    return mapping


def _floats(text: str, count: tuple[int, ...], option: str) -> list[float]:
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        raise TrajectoryFileError(f"{option}: expected comma-separated numbers, got {text!r}")
    if len(values) not in count or not all(np.isfinite(values)):
        raise TrajectoryFileError(f"{option}: expected {' or '.join(map(str, count))} finite "
                                  f"numbers, got {text!r}")
    return values


def load_trajectory(path: Path, columns: dict[str, str] | None = None,
                    obstacles: list[list[float]] | None = None) -> pd.DataFrame:
    """Read and check a trajectory CSV, renaming mapped columns and adding obstacle columns.

    Raises
    ------
    TrajectoryFileError
        Missing file or column, empty file, a single row, non-numeric cells, time not strictly
        increasing.
    """
    path = Path(path)
    if not path.is_file():
        raise TrajectoryFileError(f"{path}: no such file")
    try:
        frame = pd.read_csv(path)
    except pd.errors.EmptyDataError:
        raise TrajectoryFileError(f"{path}: the file is empty")
    except pd.errors.ParserError as exc:
        raise TrajectoryFileError(f"{path}: not a CSV table ({str(exc).splitlines()[0]})")
    columns = columns or {}
    missing_mapped = [theirs for theirs in columns.values() if theirs not in frame.columns]
    if missing_mapped:
        raise TrajectoryFileError(f"{path}: mapped column(s) {missing_mapped} not in the file; "
                                  f"it has {list(frame.columns)}")
    frame = frame.rename(columns={theirs: ours for ours, theirs in columns.items()})
    missing = [c for c in REQUIRED if c not in frame.columns]
    if missing:
        raise TrajectoryFileError(f"{path}: missing required column(s) {missing}; it has "
                                  f"{list(frame.columns)} (map names with --columns)")
    if len(frame) == 0:
        raise TrajectoryFileError(f"{path}: the file has a header but no rows")
    if len(frame) < 2:
        raise TrajectoryFileError(f"{path}: a single row; at least two are needed")
    for column in [c for c in REQUIRED + OPTIONAL if c in frame.columns]:
        values = pd.to_numeric(frame[column], errors="coerce").astype(float)
        # text that is not a number is always an error; an empty cell only in required columns
        bad = (values.isna() & frame[column].notna()) | np.isinf(values)
        if column in REQUIRED:
            bad |= values.isna()
        if bad.any():
            row = int(np.argmax(bad.to_numpy()))
            raise TrajectoryFileError(f"{path}: column {column!r} has a non-numeric or non-finite "
                                      f"cell at data row {row + 1} ({frame[column].iloc[row]!r})")
        frame[column] = values
    dt = np.diff(frame["time_s"].to_numpy())
    if np.any(dt <= 0):
        row = int(np.argmax(dt <= 0)) + 1
        raise TrajectoryFileError(f"{path}: time_s must increase strictly; it does not at data "
                                  f"row {row + 1}")
    if obstacles:
        if any(c.startswith("obs0_") for c in frame.columns):
            raise TrajectoryFileError("--obstacle given but the file already has obs0_* columns")
        t = frame["time_s"].to_numpy()
        for j, spec in enumerate(obstacles):
            x, y, r = spec[:3]
            appear = spec[3] if len(spec) > 3 else 0.0
            vx, vy = (spec[4], spec[5]) if len(spec) > 5 else (0.0, 0.0)
            elapsed = np.maximum(t - appear, 0.0)
            frame[f"obs{j}_x_m"] = x + vx * elapsed
            frame[f"obs{j}_y_m"] = y + vy * elapsed
            frame[f"obs{j}_radius_m"] = r
            frame[f"obs{j}_visible"] = t + 1e-9 >= appear
    return frame


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m pipeline.score", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("trajectory", type=Path, help="trajectory CSV")
    parser.add_argument("--columns", default="", help="OUR=THEIRS,... column name mapping")
    parser.add_argument("--start", default="0,0", help="start X,Y in m (default 0,0)")
    parser.add_argument("--goal", default="30,0", help="goal X,Y in m (default 30,0)")
    parser.add_argument("--vehicle-radius", type=float, default=1.0,
                        help="vehicle footprint radius in m (default 1.0)")
    parser.add_argument("--obstacle", action="append", default=[],
                        help="x,y,radius[,appear_s[,vx,vy]] (repeatable)")
    parser.add_argument("--out", type=Path, default=None, help="write metrics JSON here")
    args = parser.parse_args(argv)
    try:
        frame = load_trajectory(
            args.trajectory, _pairs(args.columns, "--columns"),
            [_floats(o, (3, 4, 6), "--obstacle") for o in args.obstacle])
        start = _floats(args.start, (2,), "--start")
        goal = _floats(args.goal, (2,), "--goal")
        if start == goal:
            raise TrajectoryFileError("--goal must differ from --start")
        if not np.isfinite(args.vehicle_radius) or args.vehicle_radius < 0:
            raise TrajectoryFileError("--vehicle-radius must be a finite number >= 0")
    except TrajectoryFileError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    metrics = compute_metrics(frame, TrajectoryContext(tuple(start), tuple(goal),
                                                       args.vehicle_radius), MetricsConfig())
    text = json.dumps(metrics, indent=2, sort_keys=True)
    if args.out:
        args.out.write_text(text + "\n")
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
