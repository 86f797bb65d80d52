"""The command layer: every ``python -m pipeline.<name>`` runs its work through
:func:`run_command` (lightning-hydra-template's ``task_wrapper``, click's exit-code table).

One table (:data:`EXIT_TABLE`) turns what a command's work raises into one line on stderr and
an exit code: Ctrl-C or SIGTERM stops it with 130 or 143 (what is complete is kept, the same
command resumes), a usage or configuration error, a study that cannot go on, a busy or missing
folder and an unwritable path exit 2, anything else is a code error and keeps its traceback.
Progress and notes go through :mod:`logging` (one line each on stderr, as printed before);
a command prints only its result (stdout) and its one error line.
"""

from __future__ import annotations

import argparse
import errno
import logging
import sys
from collections.abc import Callable
from pathlib import Path
from typing import TypeVar

from pipeline.errors import (
    EnvironmentFault,
    FolderBusyError,
    IncompleteSweepError,
    Interrupted,
    StudyError,
    describe_config_error,
    interrupted_exit_code,
    raise_if_stopped,
    signal_received,
    stop_on_signals,
    stopped_line,
)

log = logging.getLogger("pipeline")
T = TypeVar("T")


class CommandError(Exception):
    """A usage error a command found itself (an option out of range, a path that cannot be
    the output): its message is the one line printed, the exit code 2."""


class _StderrHandler(logging.Handler):
    """Each record as its message on the current ``sys.stderr`` (looked up when written, so a
    test's captured stream receives it)."""

    def emit(self, record: logging.LogRecord) -> None:
        try:
            sys.stderr.write(self.format(record) + "\n")
            sys.stderr.flush()
        except Exception:  # logging must never take a command down
            self.handleError(record)


def configure_logging(level: int = logging.INFO) -> None:
    """The pipeline's log records as plain lines on stderr (once per process). They still
    propagate: a test's ``caplog`` sees them; a plain command has no root handler to repeat
    them (the Hydra entry, whose job logging is Hydra's, does not call this)."""
    if not any(isinstance(h, _StderrHandler) for h in log.handlers):
        handler = _StderrHandler()
        handler.setFormatter(logging.Formatter("%(message)s"))
        log.addHandler(handler)
    log.setLevel(level)


def output_folder(text: str) -> Path:
    """``--out``'s argparse type: a path, never the empty one (``--out "$OUT"`` with ``OUT``
    unset wrote a study or a report into the current folder, the repository's root)."""
    if not text.strip():
        raise argparse.ArgumentTypeError("'' is invalid; allowed: a folder path (an empty one "
                                         "would write into the current folder)")
    return Path(text)


def checked_family_size(value: int) -> int:
    """``--family-size`` of a study command: an integer in [1, 10000] (else the one-line
    refusal)."""
    if not 1 <= value <= 10_000:
        raise CommandError(f"--family-size: {value} is not allowed; allowed: an integer in "
                           "[1, 10000]")
    return value


def comma_choices(option: str, text: str, allowed: tuple[str, ...]) -> tuple[str, ...]:
    """A comma-separated subset of ``allowed`` given to ``option`` (``--variants``,
    ``--tracks``): the names in their given order, or the one-line refusal naming the unknown
    ones (``(none)`` for an empty list)."""
    names = tuple(name.strip() for name in text.split(",") if name.strip())
    unknown = [name for name in names if name not in allowed]
    if unknown or not names:
        raise CommandError(f"{option}: {','.join(unknown) or '(none)'} is not allowed; "
                           "allowed: " + ", ".join(allowed))
    return names


def _os_error_line(exc: OSError) -> str:
    return f"error: {exc.filename}: {exc.strerror or type(exc).__name__}"


def cannot(what: str, default: object) -> Callable[[OSError], str]:
    """An ``os_error`` for :func:`run_command`: ``error: PATH: cannot WHAT (reason)``, PATH
    being the failing file or ``default`` (the command's output)."""
    return lambda exc: f"error: {exc.filename or default}: cannot {what} ({exc.strerror or exc})"


#: What a command's work may raise on purpose, in the order tried, and what becomes of it:
#: the one line it prints (None: the exception's own) and the exit code.
EXIT_TABLE: tuple[tuple[tuple[type[BaseException], ...], Callable | None, int], ...] = (
    ((CommandError,), lambda exc: str(exc), 2),
    ((IncompleteSweepError,), lambda exc: str(exc), 2),
    ((StudyError, FolderBusyError, EnvironmentFault), lambda exc: f"error: {exc}", 2),
    ((FileNotFoundError,), lambda exc: f"error: {exc}" if exc.filename is None
     else _os_error_line(exc), 2),
)


def error_line(exc: BaseException, os_error: Callable[[OSError], str] | None = None
               ) -> tuple[str, int] | None:
    """The one line and exit code :func:`run_command` gives ``exc``, or None for a code error
    (which keeps its traceback). ``os_error`` words an unwritable path for the command."""
    message = describe_config_error(exc)
    if message is not None:
        return message, 2
    for types, line, code in EXIT_TABLE:
        if isinstance(exc, types):
            return (line(exc) if line is not None else str(exc)), code
    if isinstance(exc, OSError) and exc.filename is not None:
        return (os_error or _os_error_line)(exc), 2
    fault = _disk_fault(exc)
    if fault is not None:
        if fault.filename is not None:
            return (os_error or _os_error_line)(fault), 2
        return (f"error: cannot write: {fault.strerror or fault} ({errno.errorcode.get(fault.errno or 0, '?')}); "
                "free some space or choose another output folder"), 2
    return None


#: What the machine, not the command, is short of: a full disk or quota, a read-only folder.
DISK_FAULTS = (errno.ENOSPC, errno.EDQUOT, errno.EROFS, errno.EACCES, errno.EPERM, errno.EFBIG)


def _disk_fault(exc: BaseException) -> OSError | None:
    """The full disk or read-only folder behind ``exc`` (itself, or what it was raised from,
    e.g. a worker's error re-raised by joblib), or None."""
    seen: list[BaseException] = []
    current: BaseException | None = exc
    while current is not None and current not in seen:
        seen.append(current)
        if isinstance(current, OSError) and current.errno in DISK_FAULTS:
            return current
        current = current.__cause__ or current.__context__
    return None


def run_command(work: Callable[[], int | None], kept: str = "completed runs and tables",
                os_error: Callable[[OSError], str] | None = None,
                code_error: Callable[[BaseException], str] | None = None,
                tracebacks: bool = False, log_to_stderr: bool = True) -> int:
    """Run a command's ``work`` and return its exit code (see the module docstring).

    Parameters
    ----------
    work : callable
        The command's work; returns its exit code (None: 0).
    kept : str
        What an interrupted command keeps (its stop line says so).
    os_error : callable, optional
        The line for an ``OSError`` naming a path (the default: ``error: PATH: reason``).
    code_error : callable, optional
        For a code error, a line and exit code 1 instead of the traceback (the Hydra entry,
        whose users ask for the traceback with ``HYDRA_FULL_ERROR=1``).
    tracebacks : bool
        Every error keeps its traceback (the table is not applied; signals still stop).
    log_to_stderr : bool
        Send the pipeline's log records to stderr (False under Hydra, which logs its jobs).
    """
    if log_to_stderr:
        configure_logging()
    restore_signals = stop_on_signals()
    restore_hook = _quiet_unraisable_interrupts()
    try:
        try:
            code = work()
            raise_if_stopped()  # a signal whose exception was swallowed on the way
        except KeyboardInterrupt as exc:
            print(stopped_line(exc, kept), file=sys.stderr)
            return interrupted_exit_code(exc)
        except Exception as exc:  # the table decides; code errors re-raise
            received = signal_received()
            if received is not None:  # a swallowed interrupt resurfacing as another error
                stopped = Interrupted(received)
                print(stopped_line(stopped, kept), file=sys.stderr)
                return interrupted_exit_code(stopped)
            if tracebacks:
                raise
            found = error_line(exc, os_error)
            if found is None:
                if code_error is None:
                    raise
                found = (code_error(exc), 1)
            print(found[0], file=sys.stderr)
            return found[1]
    finally:
        restore_signals()
        restore_hook()
    return 0 if code is None else int(code)


def _quiet_unraisable_interrupts() -> Callable[[], None]:
    """While a command runs, an interrupt raised where Python cannot raise it (a signal
    handled inside a ``__del__`` or a weakref callback: ``Exception ignored in ...`` and its
    traceback) is not printed: the handler remembered it and the command stops with its one
    line (:func:`~pipeline.errors.raise_if_stopped`). Every other unraisable exception is
    printed as before. Returns the function that puts the previous hook back."""
    previous = sys.unraisablehook

    def hook(unraisable) -> None:
        if isinstance(unraisable.exc_value, KeyboardInterrupt):
            return
        previous(unraisable)

    sys.unraisablehook = hook

    def restore() -> None:
        if sys.unraisablehook is hook:
            sys.unraisablehook = previous

    return restore


def run_task(work: Callable[[], T], **options) -> T:
    """:func:`run_command` for work whose result is a value, not an exit code (a Hydra job,
    whose return value is what a sweeper optimizes): ``work()``'s value, or ``SystemExit``
    with the table's exit code after its one line (SystemExit passes Hydra's job wrapper and
    its launchers untouched, even from a worker process)."""
    result: list[T] = []
    code = run_command(lambda: result.append(work()), **options)
    if code:
        raise SystemExit(code)
    return result[0]
