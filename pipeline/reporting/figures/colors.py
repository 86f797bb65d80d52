"""Each method's colour, the same in every figure: its preset's ``run.color``
(:mod:`pipeline.methods`), else a stable one of :data:`EXTRA_COLORS` from its name."""

from __future__ import annotations

#: colours for methods without their own (a user's method, extra runs): stable by name
EXTRA_COLORS = ("#17becf", "#bcbd22", "#e377c2", "#7f7f7f", "#393b79", "#8c6d31")


def method_color(method: str) -> str:
    """A method's colour: its registered one (``run.color``); any other name gets one of
    :data:`EXTRA_COLORS`, the same on every call (a stable hash of the name, not Python's
    salted one)."""
    from pipeline.methods import method_info

    color = method_info(method).color
    if color:
        return color
    import zlib

    return EXTRA_COLORS[zlib.crc32(method.encode()) % len(EXTRA_COLORS)]
