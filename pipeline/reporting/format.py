"""How the report writes numbers: the page's Jinja filters, and the same functions for the
sentences the sections compose (one place, so a number reads the same everywhere)."""

from __future__ import annotations

from typing import Any

import numpy as np


def fmt(value: Any) -> str:
    """A value as the page shows it: three significant digits (scientific below 1e-3), yes/no
    for a flag, "—" for a value that does not exist (None, NaN, infinite)."""
    if value is None:
        return "—"
    if isinstance(value, (bool, np.bool_)):
        return "yes" if value else "no"
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    if isinstance(value, (float, np.floating)):
        number = float(value)
        if not np.isfinite(number):
            return "—"
        return f"{number:.3g}" if abs(number) >= 1e-3 or number == 0 else f"{number:.2e}"
    return str(value)


def fmt_spec(value: Any, digits: str = ".3g") -> str:
    """A number with a format spec (``.2f``, ``.2g``), "—" when it does not exist."""
    if value is None or (isinstance(value, float) and not np.isfinite(value)):
        return "—"
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    return format(float(value), digits)


def interval(low: Any, high: Any) -> str:
    """``[low, high]`` as :func:`fmt` writes each end."""
    return f"[{fmt(low)}, {fmt(high)}]"


def unit(metric: str) -> str:
    """The unit of a metric, read off its name."""
    for suffix, name in (("_mps3", "m/s^3"), ("_rad_s", "rad/s"), ("_s", "s"), ("_m", "m")):
        if metric.endswith(suffix):
            return name
    if metric == "collision":
        return "collision rate"
    if "share" in metric:
        return "share"
    return "count" if metric.endswith("count") else ""


def ms(seconds: float | None) -> float | None:
    """Seconds as milliseconds (None stays None)."""
    return None if seconds is None else 1e3 * seconds


def percent(share: float) -> str:
    """A share as a whole percentage: ``0.875`` -> ``88 %``."""
    return f"{100 * share:.0f} %"


#: The page's filters: ``{{ x | fmt }}``, ``{{ m | unit }}``, ``{{ s | percent }}``.
FILTERS = {"fmt": fmt, "fmt_spec": fmt_spec, "unit": unit, "percent": percent, "ms": ms}
