"""The lock a study (a tune, a multiverse) holds on its output folder for as long as it runs
(:func:`study_lock`): a second study on the same folder is refused in one line instead of both
writing one trial store and one set of tables.

A kernel lock (``fcntl.flock`` on ``<folder>/.study.lock``, what the ``filelock`` package's
Unix lock does): the kernel releases it when the process ends, however it ends, so a killed
study never leaves a stale lock behind, and no process id is ever tested.
"""

from __future__ import annotations

import contextlib
import os
from pathlib import Path

from pipeline.errors import FolderBusyError

STUDY_LOCK = ".study.lock"


@contextlib.contextmanager
def study_lock(folder: Path, study: str):
    """Hold ``folder``'s study lock while the body runs; :class:`FolderBusyError` (one line:
    the folder, the other study's process) when another process holds it."""
    import fcntl

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / STUDY_LOCK
    fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.read(fd, 200).decode("utf-8", "replace").strip() or "another process"
            raise FolderBusyError(f"{folder} is in use by another study ({holder}); wait for "
                                  f"it to finish or choose another --out") from None
        os.ftruncate(fd, 0)
        os.write(fd, f"{study}, pid {os.getpid()} on {os.uname().nodename}\n".encode())
        yield folder
    finally:
        os.close(fd)  # releases the lock (the file stays: it is not part of any result)
