"""The one folder lock: what a run, a family or a study (a tune, a multiverse, a check) holds on
the folder it writes into (:func:`folder_lock`).

The lock is a kernel lock (``flock``, taken through ``filelock``'s descriptor lock, the same
primitive as its ``FileLock``) on ``folder/.lock``: the kernel releases it when the holding
process ends, however it ends, so a killed run never blocks the next one and no process
number is guessed at. The file says who holds it (``pid host [what]``), for the message, and
keeps the lock host-aware where a file system keeps ``flock`` to each node (some cluster file
systems do): a lock file written on another host is never taken over, even when this host's
kernel would grant it; that run's folder names the host to ask, and the file to remove once it
has ended.
"""

from __future__ import annotations

import contextlib
import errno
import os
import socket
from pathlib import Path

from pipeline.errors import FolderBusyError

LOCK = ".lock"

#: ``flock`` errors that mean the file system has no kernel locks (then the file alone decides).
NO_KERNEL_LOCKS = (errno.ENOLCK, errno.ENOSYS, errno.EOPNOTSUPP, errno.EINVAL)


def _pid_alive(pid: int) -> bool:
    """Whether process ``pid`` exists on this host (signal 0; another user's counts as
    alive)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        pass
    except (OverflowError, ValueError):
        return False
    return True


def _holder(fd: int) -> tuple[int | None, str | None, str]:
    """The pid, host and description a lock file names (None where it names none: an empty
    or damaged file; a lock of the earlier format names a pid only; a run names no
    description)."""
    try:
        os.lseek(fd, 0, os.SEEK_SET)
        words = os.read(fd, 512).decode("utf-8", "replace").split()
    except OSError:
        return None, None, ""
    # ASCII digits only: str.isdigit() also takes superscripts ('\u00b9'), which int() refuses
    first = words[0] if words else ""
    pid = int(first) if first.isascii() and first.isdigit() and len(first) < 12 else None
    host = words[1] if len(words) > 1 else None
    return pid, host, " ".join(words[2:])


def _busy(folder: Path, pid: int | None, host: str | None, here: str, what: str = ""
          ) -> FolderBusyError:
    who = f"pid {pid}" if pid is not None else "an unknown process"
    holder = f"another study ({what}, {who}" if what else f"another run ({who}"
    if host is not None and host != here:
        return FolderBusyError(
            f"{folder} is locked by {holder} on host {host}); wait for it to finish, or if "
            f"it has ended remove {folder / LOCK}, or choose another output folder")
    return FolderBusyError(f"{folder} is in use by {holder}); wait for it to finish or "
                           "choose another output folder")


def _kernel_lock(fd: int) -> bool | None:
    """Take ``flock`` on ``fd`` without waiting: True taken, False held by another process,
    None when the file system has no kernel locks."""
    from filelock import lock_descriptor

    try:
        if not lock_descriptor(fd, blocking=False):
            return False
    except BlockingIOError:
        return False
    except OSError as exc:
        if exc.errno in (errno.EAGAIN, errno.EACCES):
            return False
        if exc.errno in NO_KERNEL_LOCKS:
            return None
        raise
    return True


def _same_file(fd: int, lock: Path) -> bool:
    """Whether ``lock`` is still the file open as ``fd`` (a holder that just finished removes
    its file: a lock on the removed file would lock nothing)."""
    try:
        here, there = os.fstat(fd), os.stat(lock)
    except FileNotFoundError:
        return False
    return (here.st_dev, here.st_ino) == (there.st_dev, there.st_ino)


def _take(folder: Path, lock: Path, here: str, what: str) -> int | None:
    """Open and lock ``lock`` for this process: its descriptor, or None when this process
    already holds it (a nested lock: a run's, never a study's). Raises
    :class:`FolderBusyError` when another holds it, or when a study asks for a folder this
    process already holds for a study."""
    me = os.getpid()
    for _ in range(20):
        fd = os.open(lock, os.O_CREAT | os.O_RDWR, 0o644)
        try:
            kernel = _kernel_lock(fd)
            pid, host, holding = _holder(fd)
            if kernel is False:
                if pid == me and host == here and not (what and holding):
                    os.close(fd)
                    return None  # this process holds it already
                raise _busy(folder, pid, host, here, holding)
            if not _same_file(fd, lock):
                os.close(fd)
                continue  # removed or replaced by its holder meanwhile: start again
            if pid is not None and host is not None and host != here:
                raise _busy(folder, pid, host, here, holding)  # never break another host's
            if pid is not None and pid != me and (kernel is None or host is None) \
                    and _pid_alive(pid):
                # no kernel locks here, or a lock of the earlier format: the pid decides
                raise _busy(folder, pid, host, here, holding)
            if pid == me and host in (here, None) and kernel is None:
                if what and holding:
                    raise _busy(folder, pid, host, here, holding)
                os.close(fd)
                return None
            os.ftruncate(fd, 0)
            os.lseek(fd, 0, os.SEEK_SET)
            os.write(fd, f"{me} {here}{' ' + what if what else ''}\n".encode())
            return fd
        except BaseException:
            with contextlib.suppress(OSError):
                os.close(fd)
            raise
    raise FolderBusyError(f"{folder}: cannot take its lock ({lock}): it keeps changing")


@contextlib.contextmanager
def folder_lock(folder: Path, what: str = ""):
    """Hold ``folder/.lock`` while a run, a family or a study writes into ``folder``.

    Parameters
    ----------
    folder : Path
        The folder (made when missing).
    what : str
        What holds it, for another's refusal: empty for a run or family (the same process may
        nest the lock), a study's name (``tune quick``, ``multiverse default``): a second
        study on the folder is refused even in the same process.

    A second writer raises :class:`FolderBusyError` naming the first (its pid and what it
    is, and its host when that is another one); a lock left by a process that has ended on
    this host is taken over (the kernel released it); a lock written on another host is
    never taken. The lock is not part of any manifest and is removed on exit."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    lock = folder / LOCK
    what = " ".join(str(what).split())
    fd = _take(folder, lock, socket.gethostname(), what)
    if fd is None:
        yield folder
        return
    try:
        yield folder
    finally:
        try:
            lock.unlink(missing_ok=True)  # while still locked: the next writer starts afresh
        finally:
            os.close(fd)
