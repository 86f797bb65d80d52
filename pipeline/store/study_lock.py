"""The lock a study (a tune, a multiverse) holds on its output folder for as long as it runs
(:func:`study_lock`): a second study on the same folder is refused in one line instead of both
writing one trial store and one set of tables.

The lock is the ``filelock`` package's (a kernel ``flock`` on ``<folder>/.study.lock`` where
the file system has kernel locks): the kernel releases it when the process ends, however it
ends, so a killed study never leaves a stale lock behind, and no process id is ever tested.
Who holds it is written beside it (``<folder>/.study.holder``) for the refusal's line:
``filelock`` empties its own lock file whenever a contender opens it.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator
from pathlib import Path

from filelock import FileLock, Timeout

from pipeline.errors import FolderBusyError

STUDY_LOCK = ".study.lock"
#: The holder's description (the study, its pid and host), written once the lock is taken.
STUDY_HOLDER = ".study.holder"


@contextlib.contextmanager
def study_lock(folder: Path, study: str) -> Iterator[Path]:
    """Hold ``folder``'s study lock while the body runs.

    Parameters
    ----------
    folder : Path
        The study's output folder (made when missing).
    study : str
        What holds it (``tune quick``, ``multiverse default``): named in another study's
        refusal.

    Raises
    ------
    FolderBusyError
        When another study (another process, or another lock in this one) holds it; its
        line names the folder and the holder.
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    lock = FileLock(folder / STUDY_LOCK, blocking=False, thread_local=False)
    holder_file = folder / STUDY_HOLDER
    try:
        lock.acquire()
    except Timeout:
        try:
            holder = holder_file.read_text(encoding="utf-8", errors="replace").strip()
        except OSError:
            holder = ""
        raise FolderBusyError(f"{folder} is in use by another study ({holder or 'another process'}"
                              "); wait for it to finish or choose another --out") from None
    try:
        holder_file.write_text(f"{study}, pid {os.getpid()} on {os.uname().nodename}\n",
                               encoding="utf-8")
        yield folder
    finally:
        with contextlib.suppress(OSError):
            holder_file.unlink()
        lock.release()
