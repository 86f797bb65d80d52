"""Pareto sets, the compromise, the hypervolume and the convergence rule of a tuning.

Every function takes objective values as rows (one per trial) with the objectives'
directions; "signed" values are turned so that smaller is better in every column.
"""

from __future__ import annotations

import numpy as np

from pipeline.analysis.objectives import Objective

#: The rule that picks one setting per method from its Pareto set.
COMPROMISE_RULE = ("closest_to_ideal: among the method's feasible Pareto settings, the one with "
                   "the smallest Euclidean distance to the ideal point (the best value of every "
                   "objective), each objective min-max scaled over both methods' feasible "
                   "trials of the replicate (one scale for both methods)")


def signed(values: np.ndarray, objectives: list[Objective]) -> np.ndarray:
    """Objective values turned so that smaller is better in every column."""
    signs = np.array([1.0 if o.direction == "minimize" else -1.0 for o in objectives])
    return np.asarray(values, float).reshape(-1, len(objectives)) * signs


def dominates(a: np.ndarray, b: np.ndarray) -> bool:
    """``a`` at least as good as ``b`` everywhere and better somewhere (smaller is better)."""
    return bool(np.all(a <= b) and np.any(a < b))


def pareto_mask(values: np.ndarray, objectives: list[Objective]) -> np.ndarray:
    """Which rows are not dominated by another row."""
    rows = signed(values, objectives)
    return np.array([not any(dominates(other, row) for j, other in enumerate(rows) if j != i)
                     for i, row in enumerate(rows)], dtype=bool)


def distances_to_ideal(candidates: np.ndarray, scale_rows: np.ndarray,
                       objectives: list[Objective]) -> np.ndarray:
    """Each candidate's distance to the ideal point, every objective min-max scaled over
    ``scale_rows`` (see :data:`COMPROMISE_RULE`)."""
    scale = signed(scale_rows, objectives)
    low, high = scale.min(axis=0), scale.max(axis=0)
    span = np.where(high > low, high - low, 1.0)
    return np.linalg.norm((signed(candidates, objectives) - low) / span, axis=1)


def closest_to_ideal(candidates: np.ndarray, scale_rows: np.ndarray,
                     objectives: list[Objective]) -> int:
    """Index of the candidate nearest the ideal point (see :data:`COMPROMISE_RULE`)."""
    return int(np.argmin(distances_to_ideal(candidates, scale_rows, objectives)))


def front_dominance(treatment: np.ndarray, control: np.ndarray,
                    objectives: list[Objective]) -> dict[str, int]:
    """How many of the control's points some treatment point dominates, and the reverse."""
    a, b = signed(treatment, objectives), signed(control, objectives)
    return {"treatment_dominates": int(sum(any(dominates(p, q) for p in a) for q in b)),
            "control_points": int(len(b)),
            "control_dominates": int(sum(any(dominates(q, p) for q in b) for p in a)),
            "treatment_points": int(len(a))}


# --- hypervolume ----------------------------------------------------------------------------

def _hypervolume_2d(points: np.ndarray, reference: np.ndarray) -> float:
    order = np.argsort(points[:, 0], kind="stable")
    total, best_y = 0.0, reference[1]
    for x, y in points[order]:
        if y < best_y:
            total += (reference[0] - x) * (best_y - y)
            best_y = y
    return float(total)


def hypervolume(points: np.ndarray, reference: np.ndarray) -> float:
    """The volume dominated by ``points`` (smaller is better) and bounded by ``reference``.

    Exact, by slicing along the last objective (Hypervolume by Slicing Objectives, While et al.,
    IEEE TEC 2006) down to a sweep in two dimensions; points not strictly better than the
    reference in every objective add nothing. Fronts here hold tens of points.
    """
    pts = np.asarray(points, float)
    reference = np.asarray(reference, float)
    if pts.size == 0:
        return 0.0
    pts = pts.reshape(-1, reference.size)
    pts = pts[np.all(pts < reference, axis=1)]
    if not len(pts):
        return 0.0
    if reference.size == 1:
        return float(reference[0] - pts[:, 0].min())
    if reference.size == 2:
        return _hypervolume_2d(pts, reference)
    pts = pts[np.argsort(pts[:, -1], kind="stable")]
    total = 0.0
    for i in range(len(pts)):
        upper = pts[i + 1, -1] if i + 1 < len(pts) else reference[-1]
        if upper > pts[i, -1]:
            total += (upper - pts[i, -1]) * hypervolume(pts[:i + 1, :-1], reference[:-1])
    return float(total)


def normalized(values: np.ndarray, bounds: list[list[float]]) -> np.ndarray:
    """Objective values mapped by the fixed bounds: ``(v - ideal) / (nadir - ideal)`` per
    column, so 0 is the ideal and 1 the nadir whatever each objective's direction."""
    array = np.asarray(bounds, float)
    ideal, nadir = array[:, 0], array[:, 1]
    return (np.asarray(values, float).reshape(-1, len(ideal)) - ideal) / (nadir - ideal)


def hypervolume_history(values: np.ndarray, feasible: np.ndarray,
                        bounds: list[list[float]]) -> np.ndarray:
    """The normalized hypervolume of the feasible trials among the first ``n``, for ``n = 1,
    2, ...`` (rows in trial order; the reference point is the nadir, 1 in every column)."""
    return HypervolumeHistory(bounds).of(values, feasible)


class HypervolumeHistory:
    """:func:`hypervolume_history`, kept between calls: a study's history is asked again after
    every batch, and only the trials after the longest prefix it shares with the rows of the
    last call are computed again (the front and volume after each row are kept). The volume
    is computed only where the front changed; the numbers are those of a computation from
    scratch (the same operations on the same front).

    Parameters
    ----------
    bounds : list of [ideal, nadir]
        Per objective, the normalization of :func:`normalized`.
    """

    def __init__(self, bounds: list[list[float]]) -> None:
        self.bounds = [list(b) for b in bounds]
        self._rows = np.empty((0, len(self.bounds)))
        self._ok = np.zeros(0, bool)
        self._fronts: list[np.ndarray] = []
        self._volumes: list[float] = []

    def of(self, values: np.ndarray, feasible: np.ndarray) -> np.ndarray:
        """The history of ``values`` (rows in trial order) and their feasibility."""
        scaled = normalized(values, self.bounds)
        ok = np.asarray(feasible, bool) & np.all(np.isfinite(scaled), axis=1)
        # the rows this call shares with the last one (NaN rows compare by their bits)
        n = min(len(scaled), len(self._rows))
        same = (np.all((scaled[:n] == self._rows[:n]) | (np.isnan(scaled[:n])
                                                         & np.isnan(self._rows[:n])), axis=1)
                & (ok[:n] == self._ok[:n]))
        keep = n if same.all() else int(np.argmin(same))
        fronts, volumes = self._fronts[:keep], self._volumes[:keep]
        reference = np.ones(scaled.shape[1])
        front = fronts[-1] if fronts else np.empty((0, scaled.shape[1]))
        volume = volumes[-1] if volumes else None
        for i in range(keep, len(scaled)):
            if ok[i] and not any(dominates(p, scaled[i]) or np.array_equal(p, scaled[i])
                                 for p in front):
                kept = [p for p in front if not dominates(scaled[i], p)]
                front = np.vstack(kept + [scaled[i]]) if kept else scaled[i][None, :]
                volume = None
            if volume is None:
                volume = hypervolume(front, reference)
            fronts.append(front)
            volumes.append(volume)
        self._rows, self._ok, self._fronts, self._volumes = scaled.copy(), ok, fronts, volumes
        return np.asarray(volumes, float)


def convergence_point(history: np.ndarray, min_trials: int, window: int,
                      tolerance: float, effort: np.ndarray | None = None) -> int | None:
    """The first trial count ``n`` at which the hypervolume grew by at most ``tolerance``
    (relative to its value at ``n``) over the last ``window`` trials, at ``min_trials`` at the
    earliest, or None.

    With ``effort`` (per trial, the work done until it in whole-trial equivalents: simulated
    members over the training family's size), ``min_trials`` and ``window`` count that work,
    not trials: a trial stopped early at a quarter of its family is a quarter of a trial, so a
    tune that stops most trials early is not judged converged on fewer simulations than one
    that stops none. A front with no feasible point inside the bounds (hypervolume 0) has not
    converged.
    """
    history = np.asarray(history, float)
    if effort is None:
        effort = np.arange(1, len(history) + 1, dtype=float)
    effort = np.asarray(effort, float)
    for n in range(1, len(history) + 1):
        done = effort[n - 1]
        if done < min_trials or done < window + 1:
            continue
        # the last trial at or before `window` whole trials of work ago
        j = int(np.searchsorted(effort, done - window, side="right")) - 1
        if j < 0:
            continue
        now, before = history[n - 1], history[j]
        if now > 0.0 and now - before <= tolerance * now:
            return n
    return None
