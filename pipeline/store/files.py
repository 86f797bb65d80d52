"""Files of the store: every write atomic (a hidden temporary, then a rename) and never onto a
folder, a device or one of the command's own inputs; CSV text byte for byte as pandas writes it;
the temporaries a killed write left behind removed (:func:`clean_leftovers`)."""

from __future__ import annotations

import errno
import json
import os
import tempfile
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from pipeline.errors import OutputPathError, raise_if_stopped
from pipeline.loop.trajectory import TrajectoryTable


def output_target(path: Path) -> Path:
    """Where a write to ``path`` lands: a symbolic link is followed to its target (the link
    stays a link); a path that exists and is not a regular file (a folder, a device, a pipe)
    is refused with :class:`OutputPathError`, so a write never replaces it."""
    import stat

    path = Path(path)
    if path.is_symlink():
        path = Path(os.path.realpath(path))
    try:
        mode = path.stat().st_mode
    except FileNotFoundError:
        return path
    if stat.S_ISDIR(mode):
        raise OutputPathError(errno.EISDIR, "a folder, not a file", str(path))
    if not stat.S_ISREG(mode):
        raise OutputPathError(errno.EINVAL, "not a regular file (a device or a pipe)",
                              str(path))
    return path


def refuse_input_as_output(out: Path, inputs: list[Path], option: str = "--out") -> None:
    """Raise :class:`OutputPathError` when ``out`` is one of the command's ``inputs`` (the
    same file or folder, links followed): the output would destroy what it is computed from."""
    target = Path(os.path.realpath(out))
    for item in inputs:
        if item is None:
            continue
        if target == Path(os.path.realpath(item)):
            raise OutputPathError(errno.EINVAL, f"{option} is an input of this command "
                                  f"({item})", str(out))


def write_text_atomic(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` via a temporary file in the same folder and ``os.replace``;
    on any failure the previous file (if any) is left as it was. A symbolic link is written
    through to its target; a folder, device or pipe at ``path`` is refused
    (:func:`output_target`)."""
    path = output_target(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "w", encoding="utf-8", newline="\n") as handle:
            handle.write(text)
        os.chmod(tmp, 0o644)  # mkstemp creates 0600; results are meant to be shared
        raise_if_stopped()  # a signal whose exception was swallowed: commit nothing
        os.replace(tmp, path)
    except OSError as exc:
        Path(tmp).unlink(missing_ok=True)
        if exc.filename is None:  # a full disk while writing: name the file it was for
            raise OSError(exc.errno, exc.strerror or str(exc), str(path)) from exc
        raise
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def write_bytes_atomic(path: Path, data: bytes) -> None:
    """:func:`write_text_atomic` for bytes."""
    path = output_target(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as handle:
            handle.write(data)
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def npz_bytes(arrays: dict) -> bytes:
    """``arrays`` as a compressed ``.npz`` (float32; :func:`numpy.load` reads it), the same
    bytes for the same arrays: every member dated 1980-01-01, names in order."""
    import io
    import zipfile

    import numpy as np

    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", zipfile.ZIP_DEFLATED) as archive:
        for name in sorted(arrays):
            member = io.BytesIO()
            np.save(member, np.asarray(arrays[name], dtype=np.float32), allow_pickle=False)
            info = zipfile.ZipInfo(f"{name}.npy", date_time=(1980, 1, 1, 0, 0, 0))
            info.compress_type = zipfile.ZIP_DEFLATED
            archive.writestr(info, member.getvalue())
    return buffer.getvalue()


def write_json_atomic(path: Path, data: dict) -> None:
    write_text_atomic(path, json.dumps(data, indent=2, sort_keys=True, allow_nan=False) + "\n")


def json_safe(value):
    """A copy of nested dicts and lists with NaN and infinities as None (what a study's
    summary.json may hold where a number is undefined)."""
    import math

    if isinstance(value, dict):
        return {k: json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_safe(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def write_csv_atomic(path: Path, frame: pd.DataFrame) -> None:
    # fixed float format so identical runs give byte-identical files
    write_text_atomic(path, csv_text(frame))


_CSV_SPECIAL = (",", '"', "\r", "\n")
#: how a float is written into every table (printf's %g with 10 significant digits)
CSV_FLOAT_FORMAT = "%.10g"


def as_written(values: np.ndarray) -> np.ndarray:
    """Floats as a table written by :func:`write_csv_atomic` reads back (rounded to
    :data:`CSV_FLOAT_FORMAT`), so that a number taken from memory is the number a reader of
    the file gets."""
    return np.array([float(CSV_FLOAT_FORMAT % v) if v == v else np.nan
                     for v in np.asarray(values, float).tolist()], float)


def _csv_cells(kind: str, values: list[Any]) -> list[str] | None:
    """One column's cells as pandas writes them (``%.10g`` floats, empty for missing values),
    or None when the column needs pandas (quoting, an unusual dtype); ``kind`` is its dtype's
    kind, ``values`` its cells as Python objects."""
    if kind == "f":
        # printf's %g, the format every table was written with (byte-identical files)
        return ["" if v != v else CSV_FLOAT_FORMAT % v for v in values]
    if kind in "biu":
        return [str(v) for v in values]
    if kind in "OUT":
        cells = []
        for v in values:
            if v is None or (isinstance(v, float) and v != v):
                cells.append("")
            elif isinstance(v, (str, bool, int)):
                text = str(v)
                if any(c in text for c in _CSV_SPECIAL):
                    return None
                cells.append(text)
            else:
                return None
        return cells
    return None


def csv_text(frame: pd.DataFrame | TrajectoryTable) -> str:
    """``frame.to_csv(index=False, float_format="%.10g", lineterminator="\\n")``, byte for byte,
    at a fraction of its cost for the plain tables the pipeline writes (floats, flags, short
    words); anything else (cells that need quoting, other dtypes) goes through pandas itself.
    A simulated run's :class:`~pipeline.loop.trajectory.TrajectoryTable` is written from its
    arrays (the bytes of its DataFrame's, without building one)."""
    columns: list[list[str] | None] = [None]
    if isinstance(frame, TrajectoryTable):
        arrays = frame.arrays()
        names = list(arrays)
        if len(arrays) >= 2:  # each column's cells from its own array
            columns = [_csv_cells(values.dtype.kind, values.tolist())
                       for values in arrays.values()]
    else:
        names = [str(c) for c in frame.columns]
        if frame.shape[1] >= 2 and frame.columns.is_unique:
            # every cell as a Python object in one conversion (a column taken as a Series
            # costs more than formatting it); floats, ints and flags convert to the same
            # values ``column.to_numpy().tolist()`` gives
            cells = frame.to_numpy(dtype=object)
            columns = [_csv_cells(dtype.kind, cells[:, j].tolist())
                       for j, dtype in enumerate(frame.dtypes)]
    if any(c is None for c in columns) or any(ch in n for n in names for ch in _CSV_SPECIAL):
        if isinstance(frame, TrajectoryTable):
            frame = frame.to_frame()
        return frame.to_csv(index=False, float_format=CSV_FLOAT_FORMAT, lineterminator="\n")
    lines = [",".join(names)]
    lines.extend(",".join(row) for row in zip(*columns, strict=True))
    return "\n".join(lines) + "\n"


def clean_leftovers(folder: Path) -> list[Path]:
    """Remove the hidden temporaries (``.<name>.<random>.tmp``) that a killed write left in
    ``folder``; returns what was removed."""
    folder = Path(folder)
    removed = []
    if folder.is_dir():
        for path in folder.glob(".*.tmp"):
            if path.is_file():
                path.unlink(missing_ok=True)
                removed.append(path)
    return removed
