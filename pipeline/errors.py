"""Every error the pipeline raises on purpose, in one module so that nothing imports back up.

Each carries a message meant for a person: one line naming the key (or file) and what is
allowed. :func:`describe_config_error` turns any of them (and Hydra's and OmegaConf's own
configuration errors) into that line; the entry points print it and exit 2.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator
from typing import Any


class ConfigError(ValueError):
    """An invalid configuration value.

    Parameters
    ----------
    key : str
        Dotted config key, e.g. ``controller.horizon``.
    value : Any
        The offending value.
    allowed : str
        Human-readable description of the allowed values.
    """

    def __init__(self, key: str, value: Any, allowed: str) -> None:
        self.key = key
        self.value = value
        self.allowed = allowed
        super().__init__(f"config error: {key}={plain_value(value)} is invalid; "
                         f"allowed: {allowed}")

    def __reduce__(self):
        # rebuilt from its three arguments (a worker's error reaches its parent as itself);
        # a subclass with other arguments keeps the default
        if type(self) is not ConfigError:
            return super().__reduce__()
        return (ConfigError, (self.key, self.value, self.allowed))


def plain_value(value: Any, limit: int = 60) -> str:
    """A value as a person would write it: numpy scalars as plain numbers (``-0.5``, not
    ``np.float64(-0.5)``), containers element by element, anything longer than ``limit``
    characters cut with its length (a 400-digit number stays one short line)."""
    if hasattr(value, "item") and getattr(value, "shape", None) == ():
        value = value.item()  # a numpy scalar
    if isinstance(value, (list, tuple)):
        text = "[" + ", ".join(plain_value(v, limit) for v in value) + "]"
    elif isinstance(value, dict):
        text = "{" + ", ".join(f"{k}: {plain_value(v, limit)}" for k, v in value.items()) + "}"
    else:
        text = repr(value)
    if len(text) > limit:
        text = f"{text[:limit - 20]}... ({len(text)} characters)"
    return text


class MissingExtraError(ConfigError):
    """A configuration that needs an optional extra which is not installed; the message is
    the one line saying how to install it."""

    def __init__(self, message: str) -> None:  # the message is the whole story
        ValueError.__init__(self, message)
        self.key, self.value, self.allowed = "", None, ""

    def __str__(self) -> str:
        return str(self.args[0])


class OutputPathError(OSError):
    """An output path that a write must not replace (a folder, a device, a pipe, or an input of
    the same command). ``strerror`` says why, ``filename`` names the path."""


class FolderBusyError(RuntimeError):
    """Another run is writing into the same output folder (its lock is held)."""


class EnvironmentFault(RuntimeError):
    """The machine cannot do what was asked (no SLURM for ``hydra/launcher=slurm``, a full
    disk, a read-only folder); the message names what is missing and where."""


class NotACacheError(EnvironmentFault):
    """A folder named as the member cache that is not one (no marker, other files): the cache
    neither writes into it nor deletes from it."""


class PluginOutputError(ValueError):
    """A planner or controller of the user's own (``_target_``) returned something the loop
    cannot use: the message names the plug-in, the field, what it was and what is allowed."""


class RunFolderError(ValueError):
    """A run or family folder that cannot be trusted; the message says why."""


class NonFiniteResultError(ValueError):
    """A run produced a non-finite number where the record needs a finite one (the run folder
    is not written). The message names the file (stage) and the key."""


class StudyError(RuntimeError):
    """A study that cannot go on, for a reason its message states (e.g. a tuning in which no
    setting was safe enough)."""


class IncompleteSweepError(RuntimeError):
    """Some tasks of a sweep did not finish; the message lists them and how to resume."""


class SweepConfigError(ConfigError):
    """A job of a sweep has an invalid configuration (nothing was submitted)."""

    def __init__(self, message: str) -> None:  # the message is the whole story
        ValueError.__init__(self, message)
        self.key, self.value, self.allowed = "", None, ""

    def __str__(self) -> str:
        return str(self.args[0])


class TrackFileError(ConfigError):
    """A recorded-track file (``scenario=pedestrians``) that is missing or cannot be read:
    the message names the file (and line) and what is expected."""

    def __init__(self, message: str) -> None:  # the message is the whole story
        ValueError.__init__(self, message)
        self.key, self.value, self.allowed = "", None, ""

    def __str__(self) -> str:
        return str(self.args[0])


def describe_config_error(exc: BaseException) -> str | None:
    """One line for a configuration error, or None if ``exc`` is not one."""
    chain: list[BaseException] = []
    current: BaseException | None = exc
    while current is not None and current not in chain:
        chain.append(current)
        current = current.__cause__ or current.__context__
    for err in chain:
        if isinstance(err, (ConfigError, NonFiniteResultError, IncompleteSweepError,
                            PluginOutputError)):
            return str(err)
    # the readers in order: the first that words any exception of the chain wins
    for reader in (_missing_config_line, _other_kind_key_line, _omegaconf_line,
                   _composition_line, _override_under_null_line):
        for err in chain:
            line = reader(err)
            if line is not None:
                return line
    return None


def _missing_config_line(err: BaseException) -> str | None:
    """A config group's option that does not exist (``planner=nope``)."""
    from hydra.errors import MissingConfigException

    if not isinstance(err, MissingConfigException):
        return None
    missing = err.missing_cfg_file or ""
    group, _, name = missing.rpartition("/")
    options = ", ".join(o for o in (err.options or []) if not o.endswith("_schema"))
    options = options or "see conf/" + group
    if group:
        return f"config error: {group}={name!r} is not a known option; allowed: {options}"
    return "config error: " + str(err).splitlines()[0]


def _omegaconf_line(err: BaseException) -> str | None:
    """A value OmegaConf refuses (missing, wrong type), with its key."""
    from omegaconf.errors import MissingMandatoryValue, OmegaConfBaseException

    if isinstance(err, MissingMandatoryValue):
        key = getattr(err, "full_key", None) or "?"
        return f"config error: {key} is missing; allowed: a value (required, set {key}=...)"
    if isinstance(err, OmegaConfBaseException):
        key = getattr(err, "full_key", None) or "?"
        message = str(getattr(err, "msg", err)).splitlines()[0]
        return f"config error: {key}: {message}"
    return None


def _other_kind_key_line(err: BaseException) -> str | None:
    """An override of a controller key that its kind's schema does not have (a key of another
    controller kind: ``controller.q_lateral`` on pure pursuit): the key and the keys of the
    schema it was composed with."""
    from omegaconf.errors import ConfigAttributeError, ConfigKeyError

    if not isinstance(err, (ConfigAttributeError, ConfigKeyError)):
        return None
    key, schema = getattr(err, "full_key", None), getattr(err, "object_type", None)
    if not isinstance(key, str) or not key.startswith("controller.") or schema is None:
        return None
    from dataclasses import fields, is_dataclass

    # a controller kind's schema (pipeline.loop.controller_settings) names its kind and file
    kind_word, kind_file = getattr(schema, "kind_word", None), getattr(schema, "kind_file", None)
    if not isinstance(schema, type) or not is_dataclass(schema) or kind_word is None \
            or kind_file is None:
        return None
    keys = ", ".join(sorted(f.name for f in fields(schema)))
    return (f"config error: {key} is invalid; allowed: a key of {schema.__name__}, the "
            f"schema of controller={kind_file} (kind {kind_word}): {keys}")


def _composition_line(err: BaseException) -> str | None:
    """An override Hydra cannot parse or compose."""
    from hydra.errors import ConfigCompositionException, OverrideParseException

    if isinstance(err, (OverrideParseException, ConfigCompositionException)):
        return "config error: " + " ".join(str(err).split())
    return None


#: Sections that are null unless a config group sets them, and the group that does.
NULL_SECTION_SOURCES = {"scenario.family": "scenario=family"}


def _override_under_null_line(err: BaseException) -> str | None:
    """One line for an override of or below a null section (``scenario.family.n_jobs=1`` or
    ``scenario.family={size: 3}`` on the paper scenario, whose ``scenario.family`` is null):
    OmegaConf's ``update``, which Hydra calls for each override, stops there with a bare
    ``AssertionError`` or ``AttributeError`` that Hydra passes on. The key and the null section
    come from that call's frame."""
    if not isinstance(err, (AssertionError, AttributeError)):
        return None
    from omegaconf import OmegaConf

    tb = err.__traceback__
    while tb is not None:
        frame = tb.tb_frame
        if frame.f_code.co_name == "update" and "omegaconf" in frame.f_code.co_filename:
            key, cfg = frame.f_locals.get("key"), frame.f_locals.get("cfg")
            if not isinstance(key, str) or cfg is None:
                return None
            parts = key.split(".")
            section = next((".".join(parts[:i]) for i in range(1, len(parts) + 1)
                            if OmegaConf.select(cfg, ".".join(parts[:i])) is None), None)
            if section is None:
                return None
            source = NULL_SECTION_SOURCES.get(section, f"a config group that sets {section}")
            return (f"config error: {key} cannot be set: {section} is null in this "
                    f"configuration; allowed: choose {source} first")
        tb = tb.tb_next
    return None


class Interrupted(KeyboardInterrupt):
    """The process was asked to stop (SIGINT or SIGTERM); ``exit_code`` is 128 + the signal."""

    def __init__(self, signum: int) -> None:
        super().__init__(signum)
        self.signum = signum
        self.exit_code = 128 + signum


class SignalStop:
    """The handler :func:`stop_on_signals` installs for SIGINT and SIGTERM: it remembers the
    first signal (``received``) and raises :class:`Interrupted`.

    Remembering is what makes an interrupt impossible to lose: Python runs a signal handler at
    whatever bytecode comes next, and an exception raised there can be swallowed (CasADi's
    IPOPT turns it into a failed solve; one raised inside a weakref callback or a ``__del__``,
    such as matplotlib's, is printed and dropped). :func:`raise_if_stopped` raises it again at
    the next commit point and the command layer checks it when the work returns."""

    def __init__(self) -> None:
        self.received: int | None = None

    def __call__(self, signum: int, frame: Any) -> None:  # signal's signature
        if self.received is None:
            self.received = signum
        raise Interrupted(signum)


def stop_on_signals() -> Callable[[], None]:
    """Turn SIGINT (Ctrl-C) and SIGTERM (a scheduler, ``kill``) into :class:`Interrupted`
    through a fresh :class:`SignalStop`: the running study stops between members, joblib
    tears its workers down, atomic writes remove their temporaries, and the command exits 130
    or 143 with one line. Without it a SIGTERM killed the parent and left its workers writing.
    Returns the function that puts the previous handlers back (a no-op outside the main
    thread, where signals cannot be handled)."""
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        return lambda: None
    handler = SignalStop()
    previous = {signum: signal.signal(signum, handler)
                for signum in (signal.SIGINT, signal.SIGTERM)}

    def restore() -> None:
        for signum, old in previous.items():
            if signal.getsignal(signum) is handler:
                signal.signal(signum, old if old is not None else signal.SIG_DFL)

    return restore


def leave_interrupts_to(parent_pid: int | None) -> None:
    """In a worker process (any process but ``parent_pid``, in its main thread; nothing with
    None): ignore SIGINT, so that a Ctrl-C to the process group stops the command alone,
    which stops its workers (joblib's loky kills their tree). A worker interrupted itself
    inside IPOPT or on its way out once printed "Fatal Python error" into the command's one
    line."""
    import os
    import signal
    import threading

    # a task run in a thread (a Dask worker's) cannot set a handler, and its process is the
    # cluster's to stop
    if parent_pid is not None and os.getpid() != parent_pid \
            and threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.SIG_IGN)


@contextlib.contextmanager
def workers_start_deaf_to_ctrl_c() -> Iterator[None]:
    """Around a call that starts worker processes (joblib's ``Parallel`` in its generator mode,
    which returns once the first tasks are sent): SIGINT is blocked in this thread, so the
    workers started here, and the threads started here that start later ones (loky's
    manager), begin with it blocked: the mask survives fork and exec (loky's resource tracker
    starts the same way). A Ctrl-C to the process group then never reaches a worker in its
    start-up, before :func:`leave_interrupts_to`, where it printed a traceback into the
    command's one line; the parent stops the workers. A Ctrl-C arriving meanwhile is not lost:
    it is raised when the block ends (at once, as without the block, when another thread of
    this process takes it). Not for a call that does the work itself: its Ctrl-C would wait
    for the work. Nothing outside the main thread or without ``pthread_sigmask``."""
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread() \
            or not hasattr(signal, "pthread_sigmask"):
        yield
        return
    # multiprocessing's resource tracker, started with the first worker, unblocks SIGINT in
    # the thread that starts it (CPython 3.11's SIG_UNBLOCK, not a restore): started first
    from multiprocessing import resource_tracker

    resource_tracker.ensure_running()
    before = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, before)


def signal_received() -> int | None:
    """The signal the current :class:`SignalStop` has received (None: none, or no handler of
    ours is installed)."""
    import signal

    for signum in (signal.SIGINT, signal.SIGTERM):
        handler = signal.getsignal(signum)
        if isinstance(handler, SignalStop) and handler.received is not None:
            return handler.received
    return None


def raise_if_stopped() -> None:
    """Raise :class:`Interrupted` when a signal was received, even if the exception its
    handler raised was swallowed on the way (called before anything is committed)."""
    received = signal_received()
    if received is not None:
        raise Interrupted(received)


@contextlib.contextmanager
def signals_kept() -> Iterator[None]:
    """Around a call into a C extension that swallows ``KeyboardInterrupt`` (CasADi's IPOPT
    reports an interrupted solve as ``NonIpopt_Exception_Thrown`` and goes on): a SIGINT or
    SIGTERM received inside is raised when the block ends, so an interrupted solve is never
    taken for a failed one. Under :func:`stop_on_signals` this is one look at the handler;
    elsewhere (the API, a worker process) a recording handler is put in front of the current
    one for the block's duration (main thread only)."""
    import signal
    import threading

    if isinstance(signal.getsignal(signal.SIGINT), SignalStop) \
            or threading.current_thread() is not threading.main_thread():
        yield
        raise_if_stopped()
        return
    seen: list[int] = []
    previous: dict[int, Callable[..., Any]] = {}
    for signum in (signal.SIGINT, signal.SIGTERM):
        old = signal.getsignal(signum)
        if callable(old):
            previous[signum] = old

            def record(number, frame, old=old):
                seen.append(number)
                old(number, frame)

            signal.signal(signum, record)
    try:
        yield
    finally:
        for number, handler in previous.items():
            signal.signal(number, handler)
    if seen:
        previous[seen[0]](seen[0], None)  # the handler that was swallowed, once more
        raise KeyboardInterrupt  # (a handler that did not raise: stop all the same)


def interrupted_exit_code(exc: BaseException) -> int:
    """130 for Ctrl-C (SIGINT), 143 for SIGTERM."""
    return getattr(exc, "exit_code", 130)


def stopped_line(exc: BaseException, kept: str) -> str:
    """The one line a command prints when a signal stopped it (``kept``: what it keeps)."""
    how = "SIGTERM" if interrupted_exit_code(exc) == 143 else "interrupted"
    return f"stopped ({how}): {kept} are kept; the same command resumes"
