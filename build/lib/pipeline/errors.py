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
        super().__init__(f"config error: {key}={value!r} is invalid; allowed: {allowed}")



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


def describe_config_error(exc: BaseException) -> str | None:
    """One line for a configuration error, or None if ``exc`` is not one."""
    from hydra.errors import (ConfigCompositionException, MissingConfigException,
                              OverrideParseException)
    from omegaconf.errors import MissingMandatoryValue, OmegaConfBaseException

    chain = []
    current: BaseException | None = exc
    while current is not None and current not in chain:
        chain.append(current)
        current = current.__cause__ or current.__context__
    for err in chain:
        if isinstance(err, (ConfigError, NonFiniteResultError, IncompleteSweepError)):
            return str(err)
    for err in chain:
        if isinstance(err, MissingConfigException):
            missing = err.missing_cfg_file or ""
            group, _, name = missing.rpartition("/")
            options = ", ".join(o for o in (err.options or []) if not o.endswith("_schema"))
            options = options or "see conf/" + group
            if group:
                return (f"config error: {group}={name!r} is not a known option; allowed: "
                        f"{options}")
            return "config error: " + str(err).splitlines()[0]
    for err in chain:
        if isinstance(err, MissingMandatoryValue):
            key = getattr(err, "full_key", None) or "?"
            return f"config error: {key} is missing; allowed: a value (required, set {key}=...)"
        if isinstance(err, OmegaConfBaseException):
            key = getattr(err, "full_key", None) or "?"
            message = str(getattr(err, "msg", err)).splitlines()[0]
            return f"config error: {key}: {message}"
    for err in chain:
        if isinstance(err, (OverrideParseException, ConfigCompositionException)):
            return "config error: " + " ".join(str(err).split())
    return None


def study_error_line(exc: BaseException) -> str | None:
    """The one line a study's command prints for ``exc`` before exiting 2 (a configuration
    error, an incomplete SLURM sweep, a study that cannot go on), or None for a code error."""
    if isinstance(exc, (ConfigError, IncompleteSweepError)):
        return str(exc)
    if isinstance(exc, StudyError):
        return f"error: {exc}"
    return describe_config_error(exc)


def run_study(call):
    """``(0, call())``, or ``(2, None)`` after printing :func:`study_error_line`'s one line for
    a configuration error; code errors propagate with their traceback."""
    import sys

    try:
        return 0, call()
    except Exception as exc:  # noqa: BLE001 - configuration errors become one line
        message = study_error_line(exc)
        if message is None:
            raise
        print(message, file=sys.stderr)
        return 2, None
