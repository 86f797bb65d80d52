"""Each method's colour, the same in every figure."""

from __future__ import annotations

METHOD_COLORS = {"baseline": "#d62728", "improved": "#1f77b4", "velocity_aware": "#2ca02c",
                 "mpc_no_apf": "#9467bd", "apf_pursuit": "#8c564b",
                 "baseline_matched": "#ff7f0e"}
#: colours for methods without their own (a user's method, extra runs): stable by name
EXTRA_COLORS = ("#17becf", "#bcbd22", "#e377c2", "#7f7f7f", "#393b79", "#8c6d31")


def method_color(method: str) -> str:
    """A method's colour; any other name gets one of :data:`EXTRA_COLORS`, the same on every
    call (a stable hash of the name, not Python's salted one)."""
    if method in METHOD_COLORS:
        return METHOD_COLORS[method]
    import zlib

    return EXTRA_COLORS[zlib.crc32(method.encode()) % len(EXTRA_COLORS)]
