"""The tune's trial store: Optuna's journal (one JSON line per operation on a study, appended
to one file; Optuna's :class:`~optuna.storages.JournalStorage` replays it), written without a
disk sync per line and read back strictly (imported when a tune opens its store: Optuna is
imported here).

Optuna's own file backend syncs the disk after every line (a dozen per trial); a killed
process loses nothing written without it (the lines are in the operating system's cache), only
a crash of the machine itself could cut the file, which the next tune reports
(:func:`read_journal`). Appends take an exclusive lock of the file, so that several processes
may share one study (each of them replays the others' lines).
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
from collections.abc import Generator
from pathlib import Path
from typing import Any

from optuna.storages.journal import BaseJournalBackend


class JournalCutError(ValueError):
    """The journal's lines cannot be read as Optuna's: ``line`` (1-based) is the first bad
    one; ``last`` when it is the file's last line, cut without its end of line."""

    def __init__(self, line: int, last: bool, what: str) -> None:
        super().__init__(what)
        self.line, self.last = line, last


class TrialJournal(BaseJournalBackend):
    """Optuna's journal in the file ``path``: lines appended under an exclusive lock of the
    file (``flock``, which Linux also takes on NFS) without a disk sync, read from where the
    last read stopped. The file stays open for appending (an append is one write at its end:
    tens of microseconds, against a millisecond to open a lock file and the journal each
    time)."""

    def __init__(self, path: Path) -> None:
        self.path = Path(path)
        self._fd = os.open(self.path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
        #: the byte offset of each log number read so far (a read resumes there: Optuna
        #: reads on from where it stopped)
        self._offsets: dict[int, int] = {0: 0}

    def __del__(self) -> None:
        fd = getattr(self, "_fd", None)
        if fd is not None:
            with contextlib.suppress(OSError):
                os.close(fd)

    def read_logs(self, log_number_from: int) -> Generator[dict[str, Any], None, None]:
        start = log_number_from if log_number_from in self._offsets else \
            max(n for n in self._offsets if n <= log_number_from)
        with open(self.path, "rb") as handle:
            handle.seek(self._offsets[start])
            number, offset = start, self._offsets[start]
            for line in handle:
                if not line.endswith(b"\n"):
                    return  # a line still being written by another process: read it next time
                offset += len(line)
                try:
                    log = json.loads(line)
                except json.JSONDecodeError:
                    raise JournalCutError(number + 1, False,
                                          f"line {number + 1} is not an operation") from None
                self._offsets[number + 1] = offset
                if number >= log_number_from:
                    yield log
                number += 1

    def append_logs(self, logs: list[dict[str, Any]]) -> None:
        data = "".join(json.dumps(log, separators=(",", ":")) + "\n" for log in logs).encode()
        fcntl.flock(self._fd, fcntl.LOCK_EX)
        try:
            written = 0
            while written < len(data):
                written += os.write(self._fd, data[written:])
        finally:
            fcntl.flock(self._fd, fcntl.LOCK_UN)


def read_journal(path: Path) -> list[dict[str, Any]]:
    """Every operation of the journal at ``path``, strictly: :class:`JournalCutError` for a
    line that is not a JSON object with Optuna's ``op_code`` (``last``: the file's last line,
    cut without its end of line, as a crash of the machine mid-write leaves it)."""
    data = Path(path).read_bytes()
    lines = data.split(b"\n")
    tail = lines.pop()  # b"" when the file ends with its end of line
    logs = []
    for number, line in enumerate(lines, start=1):
        try:
            log = json.loads(line)
        except (json.JSONDecodeError, UnicodeDecodeError):
            raise JournalCutError(number, False, f"line {number} is not an operation") from None
        if not isinstance(log, dict) or "op_code" not in log:
            raise JournalCutError(number, False, f"line {number} is not an operation")
        logs.append(log)
    if tail:
        raise JournalCutError(len(lines) + 1, True, f"its last line ({len(lines) + 1}) is cut")
    return logs


class LogsInMemory(BaseJournalBackend):
    """A journal's operations held in memory (a store replayed without touching its file)."""

    def __init__(self, logs: list[dict[str, Any]]) -> None:
        self.logs = list(logs)

    def read_logs(self, log_number_from: int) -> Generator[dict[str, Any], None, None]:
        yield from self.logs[log_number_from:]

    def append_logs(self, logs: list[dict[str, Any]]) -> None:
        self.logs.extend(logs)
