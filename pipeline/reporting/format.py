"""How the report writes numbers: the page's Jinja filters, and the same functions for the
sentences the sections compose (one place, so a number reads the same everywhere)."""

from __future__ import annotations

import math
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


#: An interval narrower than this has no width the page can print at its six decimals at most
#: (a resample whose differences are all but zero gave "0.000000 [0.000000, 0.000000]").
MIN_WIDTH = 1e-6


def decimals_for(low: Any, high: Any) -> int | None:
    """The decimals an interval supports: two significant digits of its width (0 to 6); None
    for an interval that does not exist or has no width (below :data:`MIN_WIDTH`)."""
    try:
        width = float(high) - float(low)
    except (TypeError, ValueError):
        return None
    if not np.isfinite(width) or width <= MIN_WIDTH:
        return None
    return int(min(6, max(0, 1 - math.floor(math.log10(width)))))


def _fixed(value: float, decimals: int) -> str:
    text = f"{value:.{decimals}f}"
    # a value rounded to zero reads 0, never -0.00
    return text.lstrip("-") if float(text) == 0 else text


def effect(estimate: Any, low: Any, high: Any, unit_name: str = "", n_pairs: Any = None,
           n_tied: Any = None) -> str:
    """An estimate with its interval, each to the precision the interval supports
    (``-0.35 [-0.40, -0.29] s``); in words where numbers would mislead: no pairs, every pair
    tied (``0 [0, 0]``), or too few pairs for an interval."""
    unit_text = f" {unit_name}" if unit_name else ""
    if n_pairs is not None and int(n_pairs) == 0:
        return "no pairs to compare"
    if estimate is None or not np.isfinite(float(estimate)):
        return "no estimate (no pair has both values)"
    estimate = float(estimate)
    places = decimals_for(low, high)
    if places is None:
        if n_pairs is not None and n_tied is not None and int(n_tied) == int(n_pairs):
            return f"no difference: all {int(n_pairs)} pairs tied"
        ends = (low, high)
        if all(v is not None and np.isfinite(float(v)) for v in ends):
            tied = (f", {int(n_tied)} of {int(n_pairs)} pairs tied"
                    if n_pairs is not None and n_tied is not None else "")
            return f"{fmt(estimate)}{unit_text} in every resample (no spread{tied})"
        return f"{fmt(estimate)}{unit_text} (too few pairs for an interval)"
    return (f"{_fixed(estimate, places)} [{_fixed(float(low), places)}, "
            f"{_fixed(float(high), places)}]{unit_text}")


def unit(metric: str) -> str:
    """The unit of a metric, read off its name."""
    for suffix, name in (("_mps3", "m/s³"), ("_rad_s", "rad/s"), ("_s", "s"), ("_m", "m")):
        if metric.endswith(suffix):
            return name
    if metric == "collision":
        return "collision rate"
    if "share" in metric:
        return "share"
    return "count" if metric.endswith("count") else ""


def override_value(value: Any) -> str:
    """A config value as a Hydra override writes it: ``null``, ``true``/``false``, else as
    it prints."""
    if value is None:
        return "null"
    if isinstance(value, (bool, np.bool_)):
        return "true" if value else "false"
    return str(value)


def p_value(value: Any) -> str:
    """A p-value as the page shows it: three significant digits, ``< 0.001`` below that
    (never ``6.33e-08``: its digits past the test's own precision mean nothing)."""
    if value is None:
        return "—"
    try:
        number = float(value)
    except (TypeError, ValueError):
        return str(value)
    if not np.isfinite(number):
        return "—"
    return "< 0.001" if number < 1e-3 else f"{number:.3g}"


def ms(seconds: float | None) -> float | None:
    """Seconds as milliseconds (None stays None)."""
    return None if seconds is None else 1e3 * seconds


def percent(share: float) -> str:
    """A share as a whole percentage: ``0.875`` -> ``88 %``."""
    return f"{100 * share:.0f} %"


def collision_words(counts, key: str = "collisions") -> str:
    """Each method's collisions "of" its scenarios: ``in 200 scenarios each: baseline 18,
    improved 21``; where the families differ in size each count keeps its own total and the
    sentence says they are not comparable as counts."""
    sizes = {int(c["scenarios"]) for c in counts}
    if len(sizes) == 1:
        return (f"in {sizes.pop()} scenarios each: "
                + ", ".join(f"{c['method']} {c[key]}" for c in counts))
    return (", ".join(f"{c['method']} {c[key]} of {c['scenarios']}" for c in counts)
            + " (families of different sizes: compare the rates, not the counts)")


def row_effect(row: dict) -> str:
    """:func:`effect` of a ledger record (``estimate``, ``ci_low``, ``ci_high``, ``metric``,
    ``n_pairs``, ``n_tied``)."""
    return effect(row.get("estimate"), row.get("ci_low"), row.get("ci_high"),
                  unit(str(row.get("metric", ""))), row.get("n_pairs"), row.get("n_tied"))


#: The page's filters: ``{{ x | fmt }}``, ``{{ m | unit }}``, ``{{ s | percent }}``,
#: ``{{ row | row_effect }}``.
FILTERS = {"fmt": fmt, "fmt_spec": fmt_spec, "unit": unit, "percent": percent, "ms": ms,
           "row_effect": row_effect, "p_value": p_value}
