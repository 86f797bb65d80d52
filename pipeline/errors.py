"""Every error the pipeline raises on purpose, in one module so that nothing imports back up.

Each carries a message meant for a person: one line naming the key (or file) and what is
allowed. :func:`describe_config_error` turns any of them (and Hydra's and OmegaConf's own
configuration errors) into that line; the entry points print it and exit 2.
"""

from __future__ import annotations

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


class OutputPathError(OSError):
    """An output path that a write must not replace (a folder, a device, a pipe, or an input of
    the same command). ``strerror`` says why, ``filename`` names the path."""


class FolderBusyError(RuntimeError):
    """Another run is writing into the same output folder (its lock is held)."""


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

    def __init__(self, message: str) -> None:  # noqa: D107 - the message is the whole story
        ValueError.__init__(self, message)
        self.key, self.value, self.allowed = "", None, ""

    def __str__(self) -> str:
        return str(self.args[0])


class TrackFileError(ConfigError):
    """A recorded-track file (``scenario=pedestrians``) that is missing or cannot be read:
    the message names the file (and line) and what is expected."""

    def __init__(self, message: str) -> None:  # noqa: D107 - the message is the whole story
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
        if isinstance(err, (ConfigError, NonFiniteResultError, IncompleteSweepError)):
            return str(err)
    # the readers in order: the first that words any exception of the chain wins
    for reader in (_missing_config_line, _omegaconf_line, _composition_line,
                   _override_under_null_line):
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


def stop_on_signals() -> None:
    """Turn SIGTERM (a scheduler, ``kill``) into :class:`Interrupted`, as SIGINT already is a
    KeyboardInterrupt: the running study stops between members, joblib tears its workers
    down, atomic writes remove their temporaries, and the command exits 143 (130 for SIGINT)
    with one line. Without it a SIGTERM killed the parent and left its workers writing."""
    import signal

    def _raise(signum, frame):  # noqa: ARG001 - the signal module's signature
        raise Interrupted(signum)

    signal.signal(signal.SIGTERM, _raise)


def interrupted_exit_code(exc: BaseException) -> int:
    """130 for Ctrl-C (SIGINT), 143 for SIGTERM."""
    return getattr(exc, "exit_code", 130)


def stopped_line(exc: BaseException, kept: str) -> str:
    """The one line a command prints when a signal stopped it (``kept``: what it keeps)."""
    how = "SIGTERM" if interrupted_exit_code(exc) == 143 else "interrupted"
    return f"stopped ({how}): {kept} are kept; the same command resumes"
