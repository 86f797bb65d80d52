"""The lock a run or family holds on the folder it writes into (:func:`folder_lock`)."""

from __future__ import annotations

import contextlib
import os
from pathlib import Path

from pipeline.errors import FolderBusyError

LOCK = ".lock"


def _pid_alive(pid: int) -> bool:
    """Whether process ``pid`` exists (signal 0; another user's process counts as alive)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        pass
    return True


@contextlib.contextmanager
def folder_lock(folder: Path):
    """Hold ``folder/.lock`` (the writer's pid) while a run or family writes into ``folder``.
    A second writer raises :class:`FolderBusyError` naming the first; a lock whose process is
    gone (killed) is taken over. The lock is not part of any manifest."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    lock = folder / LOCK
    for _ in range(2):
        try:
            fd = os.open(lock, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
            break
        except FileExistsError:
            try:
                pid = int(lock.read_text().split()[0])
            except (OSError, ValueError, IndexError):
                pid = None
            if pid is not None and pid != os.getpid() and _pid_alive(pid):
                raise FolderBusyError(f"{folder} is being written by another run (pid {pid}); "
                                      "wait for it to finish or choose another output folder") from None
            lock.unlink(missing_ok=True)  # left by a killed run
    else:
        raise FolderBusyError(f"{folder}: cannot take its lock ({lock})")
    try:
        os.write(fd, f"{os.getpid()}\n".encode())
    finally:
        os.close(fd)
    try:
        yield folder
    finally:
        lock.unlink(missing_ok=True)
