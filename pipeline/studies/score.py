"""Score any trajectory CSV with the Table 1 metrics (``python -m pipeline.score FILE.csv``, the
command in :mod:`pipeline.score`).

Required columns: ``time_s``, ``X_m``, ``Y_m`` (strictly increasing time, at least two rows,
numbers only). Optional: ``psi_rad``, ``vx_mps``, ``vy_mps``, ``r_rad_s``, ``delta_rad``,
``steering_rate_rad_s`` (derived from the path where missing; steering metrics need
``delta_rad``), ``apf_rep_norm`` (C3a and C3b need it), and obstacles as ``obs{j}_x_m, obs{j}_y_m, obs{j}_radius_m, obs{j}_visible`` or
through ``--obstacle``. Other tools' column names are mapped with ``--columns``, e.g.
``--columns time_s=t,X_m=x,Y_m=y,psi_rad=theta`` for the paper's MATLAB state ``[x y theta v]``.

The output says which metrics the file could not give (``missing``: set to null, e.g. C1
without a steering column) and which it gave only derived from the path (``derived``, e.g. C2
without the lateral velocity), one line each on stderr and under ``score_quality`` in the JSON.
"""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import pandas as pd

from pipeline.analysis.claims.catalogue import CLAIM_OF_METRIC
from pipeline.loop.trajectory import OBSTACLE_COLUMN, REQUIRED, STATE

#: Optional columns a scored file may carry: the state (else derived from the path) and the APF
#: repulsion at the vehicle (C3a and C3b need it).
OPTIONAL = STATE + ("apf_rep_norm",)



class TrajectoryFileError(ValueError):
    """A trajectory file that cannot be scored; the message says why."""


def parse_pairs(text: str, option: str) -> dict[str, str]:
    mapping = {}
    for item in filter(None, (part.strip() for part in text.split(","))):
        ours, sep, theirs = item.partition("=")
        if not sep or not ours or not theirs:
            raise TrajectoryFileError(f"{option}: expected OUR=THEIRS pairs, got {item!r}")
        mapping[ours] = theirs
    return mapping


def parse_floats(text: str, count: tuple[int, ...], option: str) -> list[float]:
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        raise TrajectoryFileError(f"{option}: expected comma-separated numbers, got {text!r}") from None
    if len(values) not in count or not all(np.isfinite(values)):
        raise TrajectoryFileError(f"{option}: expected {' or '.join(map(str, count))} finite "
                                  f"numbers, got {text!r}")
    # the trajectory's own plausibility bound: beyond it squared distances overflow and the
    # clearance came out null, read as "missing" (--obstacle 1e200,2,1)
    limit = PLAUSIBLE["X_m"]
    if any(abs(v) > limit for v in values):
        raise TrajectoryFileError(f"{option}: {text!r} is out of range; allowed: numbers "
                                  f"within +-{limit:.0e} (m, m/s)")
    return values


def _decode(raw: bytes, source: str) -> str:
    """Text of a trajectory file: UTF-8 (a BOM is dropped), else Latin-1 (every byte is one)."""
    if b"\x00" in raw[:4096]:
        raise TrajectoryFileError(f"{source}: binary data (a NUL byte), not a CSV text file")
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        return raw.decode("latin-1")


def _separator(text: str, source: str) -> str:
    """The field separator of the header line: comma, semicolon or tab."""
    header = next((line for line in text.splitlines() if line.strip()
                   and not line.lstrip().startswith("#")), "")
    if not header:
        raise TrajectoryFileError(f"{source}: no header line (only comments or blank lines)")
    counts = {sep: header.count(sep) for sep in (",", ";", "\t")}
    best = max(counts, key=lambda sep: counts[sep])
    if counts[best] == 0:
        raise TrajectoryFileError(f"{source}: the header {header[:60]!r} has no comma, semicolon "
                                  "or tab between column names")
    return best


#: Magnitudes beyond these are not a vehicle trajectory (and overflow the metrics).
PLAUSIBLE = {"time_s": 1e7, "X_m": 1e7, "Y_m": 1e7}
PLAUSIBLE_DEFAULT = 1e6
BOOLEAN_WORDS = {"true": True, "false": False, "1": True, "0": False, "1.0": True, "0.0": False}


def _bad_cell(source: str, column: str, row: int, value) -> TrajectoryFileError:
    return TrajectoryFileError(f"{source}: column {column!r}, data row {row + 1}: {value!r} is "
                               "not a finite number")


def load_trajectory(path: Path | str, columns: dict[str, str] | None = None,
                    obstacles: list[list[float]] | None = None,
                    stdin_text: str | None = None) -> pd.DataFrame:
    """Read and check a trajectory CSV, renaming mapped columns and adding obstacle columns.

    UTF-8 (with or without BOM) or Latin-1 text; comma, semicolon or tab separated; lines
    starting with ``#`` are comments. ``path == "-"`` reads ``stdin_text``.

    Raises
    ------
    TrajectoryFileError
        One line naming the file and what is wrong: a missing file or column, an empty file, a
        single row, a malformed cell (by column and data row), a boolean that is not true/false,
        a radius that is not positive, time not strictly increasing, a mapping key that is not a
        known column or clashes with a column already in the file.
    """
    source, text = _read_text(path, stdin_text)
    sep = _separator(text, source)
    trailing = _trailing_empty_names(text, sep, source)
    frame = _read_table(text, sep, source, trailing)
    frame = _rename_mapped(frame, columns or {}, source)
    _check_required(frame, source)
    obstacle_ids = _obstacle_ids(frame, source)
    numeric = [c for c in frame.columns if c in REQUIRED + OPTIONAL
               or (OBSTACLE_COLUMN.fullmatch(c) and not c.endswith("_visible"))]
    for column in numeric:
        _check_numeric_column(frame, column, source)
    for j in obstacle_ids:
        _check_obstacle_radius(frame, j, source)
        _read_visible_column(frame, f"obs{j}_visible", source)
    _check_time_increases(frame, source)
    if obstacles:
        if obstacle_ids:
            raise TrajectoryFileError("--obstacle given but the file already has obs0_* columns")
        _add_obstacles(frame, obstacles)
    return frame


def _read_text(path: Path | str, stdin_text: str | None) -> tuple[str, str]:
    """The name to quote in messages and the text of the file (``stdin_text`` for ``-``)."""
    source = "stdin" if str(path) == "-" else str(path)
    if str(path) == "-":
        text = stdin_text if stdin_text is not None else ""
    else:
        path = Path(path)
        if not path.is_file():
            raise TrajectoryFileError(f"{path}: no such file")
        try:
            text = _decode(path.read_bytes(), source)
        except OSError as exc:
            raise TrajectoryFileError(f"{path}: cannot be read ({exc.strerror})") from None
    if not text.strip():
        raise TrajectoryFileError(f"{source}: the file is empty")
    return source, text


def _trailing_empty_names(text: str, sep: str, source: str) -> int:
    """How many empty names end the header (refusing a name given twice)."""
    header = next(line for line in text.splitlines() if line.strip()
                  and not line.lstrip().startswith("#"))
    names = [n.strip().strip('"') for n in header.split(sep)]
    # empty columns at the end of the header (a spreadsheet's trailing separators) are no
    # columns at all; an empty name elsewhere is
    trailing = 0
    while names and names[-1] == "":
        names.pop()
        trailing += 1
    repeated = sorted({n for n in names if names.count(n) > 1})
    if repeated:
        raise TrajectoryFileError(f"{source}: column(s) {repeated} appear more than once in the "
                                  "header")
    return trailing


def _read_table(text: str, sep: str, source: str, trailing: int) -> pd.DataFrame:
    """The table of the text, without the ``trailing`` unnamed (and empty) columns."""
    try:
        frame = pd.read_csv(io.StringIO(text), sep=sep, comment="#", skipinitialspace=True)
    except pd.errors.EmptyDataError:
        raise TrajectoryFileError(f"{source}: the file is empty") from None
    except pd.errors.ParserError as exc:
        raise TrajectoryFileError(f"{source}: not a CSV table ({str(exc).splitlines()[0]})") from None
    if trailing:
        tail = frame.iloc[:, len(frame.columns) - trailing:]
        if tail.notna().any().any():
            raise TrajectoryFileError(f"{source}: a column without a name in the header holds "
                                      "values (name it, or remove it)")
        frame = frame.iloc[:, :len(frame.columns) - trailing]
    frame.columns = [str(c).strip() for c in frame.columns]
    duplicated = sorted({c for c in frame.columns if list(frame.columns).count(c) > 1})
    if duplicated:
        raise TrajectoryFileError(f"{source}: column(s) {duplicated} appear more than once")
    return frame


def _rename_mapped(frame: pd.DataFrame, columns: dict[str, str], source: str) -> pd.DataFrame:
    """The table with the ``--columns`` mapping (ours=theirs) applied, after checking it."""
    allowed = set(REQUIRED) | set(OPTIONAL)
    unknown = [k for k in columns if k not in allowed and not OBSTACLE_COLUMN.fullmatch(k)]
    if unknown:
        raise TrajectoryFileError(f"--columns: unknown name(s) {unknown}; allowed: "
                                  f"{', '.join(REQUIRED + OPTIONAL)}, obs<j>_x_m, obs<j>_y_m, "
                                  "obs<j>_radius_m, obs<j>_visible")
    missing_mapped = [theirs for theirs in columns.values() if theirs not in frame.columns]
    if missing_mapped:
        raise TrajectoryFileError(f"{source}: mapped column(s) {missing_mapped} not in the file; "
                                  f"it has {list(frame.columns)}")
    clashes = [ours for ours, theirs in columns.items()
               if ours in frame.columns and ours != theirs]
    if clashes:
        raise TrajectoryFileError(f"--columns: {clashes} already in the file; map another column "
                                  "onto them only after renaming or dropping it")
    return frame.rename(columns={theirs: ours for ours, theirs in columns.items()})


def _check_required(frame: pd.DataFrame, source: str) -> None:
    """Refuse a table without a required column or with fewer than two rows."""
    missing = [c for c in REQUIRED if c not in frame.columns]
    if missing:
        raise TrajectoryFileError(f"{source}: missing required column(s) {missing}; it has "
                                  f"{list(frame.columns)} (map names with --columns)")
    if len(frame) == 0:
        raise TrajectoryFileError(f"{source}: the file has a header but no rows")
    if len(frame) < 2:
        raise TrajectoryFileError(f"{source}: a single row; at least two are needed")


def _obstacle_ids(frame: pd.DataFrame, source: str) -> list[int]:
    """The obstacles the table has columns of, each with its x, y and radius."""
    obstacle_ids = sorted({int(m.group(1)) for c in frame.columns
                           if (m := OBSTACLE_COLUMN.fullmatch(c))})
    for j in obstacle_ids:
        needed = [f"obs{j}_{n}" for n in ("x_m", "y_m", "radius_m")]
        absent = [c for c in needed if c not in frame.columns]
        if absent:
            raise TrajectoryFileError(f"{source}: obstacle {j} has no {', '.join(absent)} "
                                      "column (x, y and radius are needed)")
    return obstacle_ids


def _check_numeric_column(frame: pd.DataFrame, column: str, source: str) -> None:
    """Check a numeric column's cells and store it as floats (blank cells noted in ``attrs``)."""
    raw = frame[column].map(lambda v: "" if pd.isna(v) else str(v).strip())
    values = pd.to_numeric(raw.replace("", np.nan), errors="coerce").astype(float)
    # text that is not a number is always an error; an empty cell only in required columns
    bad = (values.isna() & (raw != "")) | np.isinf(values)
    if column in REQUIRED or column.startswith("obs"):
        bad |= values.isna()
    if bad.any():
        row = int(np.argmax(bad.to_numpy()))
        raise _bad_cell(source, column, row, raw.iloc[row])
    limit = PLAUSIBLE.get(column, PLAUSIBLE_DEFAULT)
    outside = values.abs() > limit
    if outside.any():
        row = int(np.argmax(outside.to_numpy()))
        raise TrajectoryFileError(f"{source}: column {column!r}, data row {row + 1}: "
                                  f"{raw.iloc[row]!r} is outside the plausible range "
                                  f"[-{limit:g}, {limit:g}]")
    frame[column] = values
    # an empty cell in an optional column (the last row excepted: it logs the end state,
    # without an input) is counted and said, never dropped silently
    blank = values.isna().to_numpy()[:-1]
    if blank.any():
        rows = np.flatnonzero(blank) + 1
        frame.attrs.setdefault("blank_cells", {})[column] = (int(blank.sum()),
                                                             int(rows[0]), int(rows[-1]))


def _check_obstacle_radius(frame: pd.DataFrame, j: int, source: str) -> None:
    """Refuse an obstacle radius that is not positive."""
    radius = frame[f"obs{j}_radius_m"]
    if (radius <= 0).any():
        row = int(np.argmax((radius <= 0).to_numpy()))
        raise TrajectoryFileError(f"{source}: column 'obs{j}_radius_m', data row {row + 1}: "
                                  f"{radius.iloc[row]!r} is not a positive radius")


def _read_visible_column(frame: pd.DataFrame, column: str, source: str) -> None:
    """Store an obstacle's visibility as booleans (always visible without the column)."""
    if column in frame.columns:
        words = frame[column].map(lambda v: "" if pd.isna(v) else str(v).strip().lower())
        bad = ~words.isin(list(BOOLEAN_WORDS))
        if bad.any():
            row = int(np.argmax(bad.to_numpy()))
            cell = frame[column].iloc[row]
            raise TrajectoryFileError(f"{source}: column {column!r}, data row {row + 1}: "
                                      f"{'' if pd.isna(cell) else cell!r} is not a boolean "
                                      "(allowed: true, false, 1, 0)")
        frame[column] = words.map(BOOLEAN_WORDS).astype(bool)
    else:
        frame[column] = True


def _check_time_increases(frame: pd.DataFrame, source: str) -> None:
    """Refuse a time column that does not increase strictly."""
    dt = np.diff(frame["time_s"].to_numpy())
    if np.any(dt <= 0):
        row = int(np.argmax(dt <= 0)) + 1
        raise TrajectoryFileError(f"{source}: time_s must increase strictly; it does not at data "
                                  f"row {row + 1}")


def _add_obstacles(frame: pd.DataFrame, obstacles: list[list[float]]) -> None:
    """Add the ``--obstacle`` specifications (x, y, r[, appear[, vx, vy]]) as obstacle columns."""
    t = frame["time_s"].to_numpy()
    for j, spec in enumerate(obstacles):
        x, y, r = spec[:3]
        if not r > 0:
            raise TrajectoryFileError(f"--obstacle {j + 1}: radius {r!r} is not positive")
        appear = spec[3] if len(spec) > 3 else 0.0
        vx, vy = (spec[4], spec[5]) if len(spec) > 5 else (0.0, 0.0)
        elapsed = np.maximum(t - appear, 0.0)
        frame[f"obs{j}_x_m"] = x + vx * elapsed
        frame[f"obs{j}_y_m"] = y + vy * elapsed
        frame[f"obs{j}_radius_m"] = r
        frame[f"obs{j}_visible"] = t + 1e-9 >= appear


#: Metrics that cannot be computed without a column: (column, what it is, metrics).
NEEDS_COLUMN = (
    ("delta_rad", "no steering-angle column (delta_rad)",
     ("reaction_delay_s", "reaction_delay_threat_s", "reaction_delay_first_visible_s", "reacted",
      "steering_rate_rms_rad_s", "steering_rate_max_rad_s", "steering_rate_rms_window_rad_s")),
    ("apf_rep_norm", "no APF repulsion column (apf_rep_norm)",
     ("repulsive_impulse", "repulsion_unneeded_impulse", "repulsion_unneeded_share",
      "repulsion_unneeded_share_threat", "repulsive_impulse_far_share", "repulsive_force_peak",
      "repulsion_onset_clearance_m", "repulsion_onset_ttc_s")),
)
#: Metrics derived from the path where a column is missing: (columns, how, metrics).
DERIVED_FROM_PATH = (
    (("vx_mps", "vy_mps", "r_rad_s"), "lateral acceleration as v r of the path (no vx_mps, "
     "vy_mps, r_rad_s): not the report's vy_dot + vx r",
     ("lateral_accel_max_mps2", "lateral_jerk_rms_run_mps3", "lateral_jerk_max_mps3",
      "lateral_jerk_rms_window_mps3", "lateral_jerk_max_window_mps3", "lateral_jerk_rms_mps3",
      "curvature_rate_rms_1_per_ms")),
    (("r_rad_s",), "yaw rate from the path's heading (no r_rad_s)",
     ("yaw_rate_sign_changes", "yaw_rate_sign_changes_after_pass",
      "oscillation_whole_run_count")),
    (("psi_rad",), "heading from the path's direction (no psi_rad)",
     ("recovery_heading_s", "max_abs_heading_error_rad", "heading_step_max_rad",
      "heading_validity_exceeded")),
)
#: The claim whose primary metric a key is (for the messages): the catalogue's.
CLAIM_OF = CLAIM_OF_METRIC


def score_quality(columns) -> tuple[dict[str, str], dict[str, str]]:
    """Which metrics a file with these columns cannot give (``missing``, reason) and which it
    gives only derived from the path (``derived``, how): what makes an outside method's scores
    comparable with the report's, or not."""
    present = set(columns)
    missing: dict[str, str] = {}
    derived: dict[str, str] = {}
    for column, reason, keys in NEEDS_COLUMN:
        if column not in present:
            for key in keys:
                if column == "delta_rad" and key.startswith("steering_rate") \
                        and "steering_rate_rad_s" in present:
                    continue
                missing[key] = reason
    for needed, how, derived_keys in DERIVED_FROM_PATH:
        if not all(c in present for c in needed):
            for key in derived_keys:
                derived.setdefault(key, how)
    return missing, derived
