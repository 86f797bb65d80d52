"""The road's edges as soft half-planes of the lateral MPC (``controller.road_edge_weight``):
at each station of the path frame, how far the road reaches to either side along the path's
normal, and the two rows that keep the ego's disc inside it.

A road is a set of polygons (a scenario's ``road_polygons_m``: a Euro NCAP test's two lanes as
one rectangle, a CommonRoad file's lanelets); the drivable set along a station's normal line is
the union of the polygons' intervals on it (each polygon's by the even-odd rule over its edges;
adjacent lanelets share an edge, so touching intervals merge). The interval holding the station
(else the nearest) gives ``low <= 0 <= high``, the road's reach to the right and to the left
in the path's lateral offset ``d``; the rows are ``w d >= w (low + reach)`` and
``-w d >= -w (high - reach)`` with ``reach`` the ego's disc radius plus the safety margin
(stretched by ``1 / sin`` of the angle where the normal meets an edge at a slant) and ``w``
the weight (the slack of a row so scaled costs ``w`` times a collision row's). A station
whose normal meets no road gets empty rows.
"""

from __future__ import annotations

import numpy as np

_EPS = 1e-9


#: The most the disc's reach is stretched where the normal line meets an edge at a slant
#: (1 / sin of the angle between them; 5: an edge within 11.5 degrees of the normal).
STRETCH_MAX = 5.0

Interval = tuple[float, float, float, float]   # start, end, and the reach's stretch at each


def polygon_intervals(points_m: np.ndarray, normals: np.ndarray, polygon_m: np.ndarray
                      ) -> list[list[Interval]]:
    """Per station, the intervals of ``t`` where ``point + t normal`` is inside the polygon
    (shape (P, 2), closed implicitly), by the even-odd rule over its edges; with each end the
    stretch of a disc's reach there, ``1 / |sin|`` of the angle between the normal line and
    the edge it crosses (a disc touches a slanted edge farther along the line)."""
    a = polygon_m
    b = np.roll(polygon_m, -1, axis=0)
    edge = b - a                                                   # (P, 2)
    rel = a[None, :, :] - points_m[:, None, :]                     # (N, P, 2)
    denom = normals[:, None, 0] * edge[None, :, 1] - normals[:, None, 1] * edge[None, :, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (rel[..., 0] * edge[None, :, 1] - rel[..., 1] * edge[None, :, 0]) / denom
        u = (rel[..., 0] * normals[:, None, 1] - rel[..., 1] * normals[:, None, 0]) / denom
        stretch = np.minimum(np.linalg.norm(edge, axis=1)[None, :] / np.abs(denom),
                             STRETCH_MAX)
    # half-open on the edge's parameter, so a vertex shared by two edges counts once
    hit = (np.abs(denom) > _EPS) & (u >= 0.0) & (u < 1.0)
    out = []
    for k in range(points_m.shape[0]):
        order = np.argsort(t[k][hit[k]])
        crossings, slant = t[k][hit[k]][order], stretch[k][hit[k]][order]
        out.append([(float(crossings[i]), float(crossings[i + 1]), float(slant[i]),
                     float(slant[i + 1])) for i in range(0, crossings.size - 1, 2)])
    return out


def road_interval(points_m: np.ndarray, normals: np.ndarray,
                  polygons_m: tuple[np.ndarray, ...]
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per station the road's reach ``(low, high)`` along its normal (m; ``low <= 0 <= high``
    when the station is on the road; the nearest interval otherwise; NaN where the normal
    line meets no road) and the stretch of a disc's reach at each end
    (:func:`polygon_intervals`)."""
    n = points_m.shape[0]
    pieces: list[list[Interval]] = [[] for _ in range(n)]
    for polygon in polygons_m:
        for k, intervals in enumerate(polygon_intervals(points_m, normals, polygon)):
            pieces[k] += intervals
    low, high = np.full(n, np.nan), np.full(n, np.nan)
    stretch_low, stretch_high = np.ones(n), np.ones(n)
    for k in range(n):
        merged: list[list[float]] = []
        for start, end, at_start, at_end in sorted(pieces[k]):
            if merged and start <= merged[-1][1] + 1e-6:
                if end > merged[-1][1]:
                    merged[-1][1], merged[-1][3] = end, at_end
            else:
                merged.append([start, end, at_start, at_end])
        if not merged:
            continue
        best = min(merged, key=lambda iv: 0.0 if iv[0] <= 0.0 <= iv[1]
                   else min(abs(iv[0]), abs(iv[1])))
        low[k], high[k], stretch_low[k], stretch_high[k] = best
    return low, high, stretch_low, stretch_high


def road_halfplanes(points_m: np.ndarray, headings_rad: np.ndarray,
                    polygons_m: tuple[np.ndarray, ...], reach_m: float, weight: float
                    ) -> tuple[np.ndarray, np.ndarray]:
    """The road's rows ``G d + s >= h`` at the stations (``points_m`` (N, 2) on the path,
    its ``headings_rad`` there): shape (N, 2) each, the right edge's column then the left's;
    empty rows (0 d + s >= 0) where no road is met or there is none. The disc's reach is
    stretched where the normal meets an edge at a slant (:func:`polygon_intervals`)."""
    n = points_m.shape[0]
    G, h = np.zeros((n, 2)), np.zeros((n, 2))
    if not polygons_m:
        return G, h
    normals = np.stack([-np.sin(headings_rad), np.cos(headings_rad)], axis=1)
    low, high, stretch_low, stretch_high = road_interval(points_m, normals, polygons_m)
    known = np.isfinite(low)
    G[known, 0] = weight
    h[known, 0] = weight * (low[known] + reach_m * stretch_low[known])
    G[known, 1] = -weight
    h[known, 1] = -weight * (high[known] - reach_m * stretch_high[known])
    return G, h
