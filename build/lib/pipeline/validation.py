"""Range checks shared by every settings schema; each raises :class:`ConfigError` naming the
dotted key, the value and what is allowed."""

from __future__ import annotations

import math
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


def between(key: str, value: Any, low: float, high: float) -> None:
    v = finite(key, value)
    if not low <= v <= high:
        raise ConfigError(key, value, f"a number in [{low}, {high}]")


def choice(key: str, value: Any, options: tuple) -> None:
    if value not in options:
        raise ConfigError(key, value, "one of " + ", ".join(str(o) for o in options))


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
