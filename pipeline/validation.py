"""Range checks shared by every settings schema; each raises :class:`ConfigError` naming the
dotted key, the value and what is allowed."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from omegaconf import MISSING

from pipeline.errors import ConfigError


def finite(key: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ConfigError(key, value, "a finite number")
    if not math.isfinite(float(value)):
        raise ConfigError(key, value, "a finite number (not NaN or inf)")
    return float(value)


def at_least(key: str, value: Any, low: float, inclusive: bool = True) -> None:
    v = finite(key, value)
    if (v < low) if inclusive else (v <= low):
        raise ConfigError(key, value, f"{'>=' if inclusive else '>'} {low}")


def integer_in(key: str, value: Any, low: int, high: int, allowed: str | None = None) -> None:
    """``value`` an integer (not a bool) in ``[low, high]``; else refused, with ``allowed``
    as what is allowed (by default ``an integer in [low, high]``)."""
    if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
        raise ConfigError(key, value, allowed or f"an integer in [{low}, {high}]")


def flag(key: str, value: Any) -> None:
    """``value`` a bool (a YAML true or false); else refused."""
    if not isinstance(value, bool):
        raise ConfigError(key, value, "true or false")


def without_earlier_readings(data: Mapping[str, Any], before: Mapping[str, Any]
                             ) -> dict[str, Any]:
    """``data`` (a settings section as the config hash reads it) without each key of
    ``before`` that holds the reading from before the key existed (equal and of the same type),
    so that a configuration's hash does not move when the key is added."""
    return {k: v for k, v in data.items()
            if not (k in before and v == before[k] and type(v) is type(before[k]))}


def between(key: str, value: Any, low: float, high: float) -> None:
    v = finite(key, value)
    if not low <= v <= high:
        raise ConfigError(key, value, f"a number in [{low}, {high}]")


def choice(key: str, value: Any, options: tuple, removed: Mapping[str, str] | None = None
           ) -> None:
    """``value`` one of ``options``; ``removed``: values that were allowed once, each with why it
    is gone, added to the refusal of that value."""
    if value not in options:
        why = (removed or {}).get(value) if isinstance(value, str) else None
        raise ConfigError(key, value, "one of " + ", ".join(str(o) for o in options)
                          + (f" ({value} was removed: {why})" if why else ""))


def safe_name(key: str, value: Any) -> None:
    """A name that becomes a folder name: letters, digits and ``_ - . + = ,`` only."""
    import re

    if value is MISSING or value is None:
        return
    text = str(value)
    if not text or text in (".", "..") or not re.fullmatch(r"[A-Za-z0-9_.+=,-]{1,100}", text):
        raise ConfigError(key, value, "a name of 1-100 letters, digits or _ - . + = , "
                          "(it becomes a folder name; no '/' or '..')")


def pair(key: str, value: Any) -> None:
    if len(value) != 2:
        raise ConfigError(key, list(value), "a list of two finite numbers [x_m, y_m]")
    for i, v in enumerate(value):
        finite(f"{key}[{i}]", v)


TARGET_PATTERN = r"[A-Za-z_][A-Za-z0-9_]*(\.[A-Za-z_][A-Za-z0-9_]*)+"


def target_path(key: str, value) -> None:
    """A Hydra-style ``_target_``: a dotted ``module.Class`` path (or None: the built-in)."""
    import re

    if value is None:
        return
    if not isinstance(value, str) or not re.fullmatch(TARGET_PATTERN, value):
        raise ConfigError(key, value, "a dotted path module.Class (e.g. my_planner.MyPlanner) "
                          "or null for the built-in")


def resolve_target(key: str, value: str):
    """The class a ``_target_`` names, imported (the user's module must be importable: on
    PYTHONPATH or installed); a :class:`ConfigError` naming the key otherwise."""
    import importlib

    module_name, _, name = value.rpartition(".")
    try:
        module = importlib.import_module(module_name)
    except ImportError as exc:
        raise ConfigError(key, value, f"a class importable as module.Class ({exc}; put its "
                          "folder on PYTHONPATH)") from None
    target = getattr(module, name, None)
    if not callable(target):
        raise ConfigError(key, value, f"a class importable as module.Class (module "
                          f"{module_name} has no {name})")
    return target


def build_target(key: str, value: str, args: tuple, call: str):
    """An instance of the class ``value`` names (:func:`resolve_target`), built with
    ``args``; a class whose constructor cannot take them (``call`` says how it is called) is
    a :class:`ConfigError` naming the key, before anything runs."""
    import inspect

    cls = resolve_target(key, value)
    try:
        inspect.signature(cls).bind(*args)
    except TypeError as exc:
        raise ConfigError(key, value, f"a class built as {call} ({exc})") from None
    except ValueError:  # no signature to read (a builtin): let the call decide
        pass
    return cls(*args)


class FrozenAfterValidation:
    """Mixin of the settings dataclasses: mutable while Hydra and OmegaConf build and check
    them, read-only once :meth:`freeze` runs (the composed :class:`ExperimentConfig` freezes
    itself after its checks). A changed setting is a new, checked object:
    ``dataclasses.replace(cfg.planner, beta=0.5)`` or a compose with overrides."""

    def __setattr__(self, name: str, value: Any) -> None:
        if self.__dict__.get("_frozen", False):
            import dataclasses

            raise dataclasses.FrozenInstanceError(
                f"cannot assign {type(self).__name__}.{name}: a validated configuration is "
                "read-only (use dataclasses.replace, or compose with an override)")
        object.__setattr__(self, name, value)

    def freeze(self) -> FrozenAfterValidation:
        """Make this object and every settings object inside it read-only; returns it."""
        import dataclasses

        for f in dataclasses.fields(self):  # type: ignore[arg-type]
            value = getattr(self, f.name)
            for item in value if isinstance(value, (list, tuple)) else (value,):
                # one frozen already froze everything inside it (a member's config: the
                # family's sections, a drawn scenario)
                if isinstance(item, FrozenAfterValidation) \
                        and not item.__dict__.get("_frozen", False):
                    item.freeze()
        object.__setattr__(self, "_frozen", True)
        return self
