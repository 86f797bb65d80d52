"""A rectangle covered by equal discs: how the ego and each CommonRoad obstacle are shaped for
the half-planes and the collision check (``scenario.commonroad.obstacle_disc=cover``,
``vehicle.footprint_discs``).

The cover is the standard one of motion planning (Ziegler and Stiller's, also CommonRoad's
"three circles" for a car): ``n`` discs with their centres on the rectangle's long axis, spaced
``length / n`` apart, each holding one of ``n`` equal slices of the rectangle, so its radius is
the slice's half-diagonal ``sqrt((length / 2n)^2 + (width / 2)^2)``. Among covers by ``n`` equal
discs centred on the long axis it has the smallest radius (a slice's corners must be inside some
disc, and the slices' corners are ``length / n`` apart along the axis); for ``n = 1`` it is the
circumscribed disc, the smallest disc holding the rectangle. This module imports nothing of the
pipeline.
"""

from __future__ import annotations

import math

import numpy as np


def rectangle_cover(length_m: float, width_m: float, n_discs: int
                    ) -> tuple[np.ndarray, float]:
    """The ``n_discs`` discs covering a ``length_m`` x ``width_m`` rectangle (its long side
    along x, centred on the origin): the centres' offsets along the long side (ascending, shape
    (n,)) and the common radius.

    A rectangle given with its long side across (``width_m > length_m``) is covered along that
    side: the offsets are then along y, which :func:`cover_centres` takes as ``along_y``."""
    if n_discs < 1:
        raise ValueError(f"n_discs is {n_discs}; allowed: an integer >= 1")
    long_side, short_side = max(length_m, width_m), min(length_m, width_m)
    piece = long_side / n_discs
    offsets = -long_side / 2.0 + piece * (np.arange(n_discs) + 0.5)
    return offsets, math.hypot(piece / 2.0, short_side / 2.0)


def cover_centres(length_m: float, width_m: float, n_discs: int
                  ) -> tuple[np.ndarray, float]:
    """:func:`rectangle_cover` as points in the rectangle's own frame (x along ``length_m``):
    centres shape (n, 2) and the radius."""
    offsets, radius = rectangle_cover(length_m, width_m, n_discs)
    centres = np.zeros((n_discs, 2))
    centres[:, 0 if length_m >= width_m else 1] = offsets
    return centres, radius


def footprint_offsets_m(n_discs: int, span_m: float) -> np.ndarray:
    """The ego's disc centres along its heading (m, ascending): ``n_discs`` evenly over
    ``span_m`` centred on the logged position (``[0.0]`` for one disc)."""
    if n_discs == 1:
        return np.zeros(1)
    return np.linspace(-span_m / 2.0, span_m / 2.0, n_discs)
