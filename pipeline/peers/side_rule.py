"""The side rule the two barrier peers share (MPC-DCBF, :mod:`pipeline.peers.mpc_dcbf`; the
CBF-QP filter, :mod:`pipeline.peers.cbf_filter`).

Both peers linearize the barrier ``h = |p - o| - R`` about a point ``pbar`` (MPC-DCBF: its
linearization trajectory; the filter: its preview under the nominal input). Its gradient there
is the unit vector from the obstacle to ``pbar``. Where ``pbar`` lies on the obstacle's line
along the start-goal direction (an obstacle dead ahead), that gradient is purely longitudinal:
steering cannot raise ``h``, only braking can (kinematic track) or nothing can (lateral track,
fixed speed), and the barrier condition is met with slack or a standstill instead of a turn.
This is the CBF-QP's known undesired equilibrium on symmetric geometry: Reis, Aguiar and
Tabuada, "Control barrier function-based quadratic programs introduce undesirable
asymptotically stable equilibria", IEEE Control Systems Letters 5(2), 2021; Tan and
Dimarogonas, "On the undesired equilibria induced by control barrier function based quadratic
programs", Automatica 159, 2024.

The rule breaks the symmetry by choosing a side and keeping it:

* :func:`pass_sides`: each obstacle is passed on one side ``sigma`` (+1 left, -1 right of the
  start-goal line): the side the linearization trajectory is on where it comes closest to the
  obstacle; where it is dead ahead there (within :data:`TIE_M`), the side the vehicle is on
  now; on a tie, the left;
* :func:`side_rule_normals`: the linearization point's lateral offset from the obstacle is
  taken as ``sigma max(sigma dy, rho R)`` (``rho``: the peer's
  ``params.min_lateral_offset_ratio``), at least a share of the keep-out radius on the chosen
  side, so the gradient always has a lateral part. ``h`` is convex in ``p`` and any unit vector
  ``n`` gives ``n . (p - o) - R <= h(p)``: a row written with these normals stays conservative.
"""

from __future__ import annotations

import numpy as np

from pipeline.loop.scenario import LineFrame

__all__ = ["TIE_M", "pass_sides", "side_rule_normals", "sided_normals"]

#: Lateral offset (m) below which a point counts as dead ahead of an obstacle.
TIE_M = 1e-6


def pass_sides(points_line_m: np.ndarray, centres_line_m: np.ndarray,
               vehicle_line_m: np.ndarray) -> np.ndarray:
    """The side rule: the side (+1 left, -1 right of the start-goal line) each obstacle is
    passed on.

    The side the linearization trajectory is on where it comes closest to the obstacle; where
    it is dead ahead there (lateral offset within 1e-6 m), the side the vehicle is on now
    (against the obstacle's present centre); left on a tie.

    Parameters
    ----------
    points_line_m : ndarray, shape (K, 2)
        Linearization trajectory (row 0: the vehicle now), line frame.
    centres_line_m : ndarray, shape (K, n, 2)
        Obstacle centres at the same instants, line frame.
    vehicle_line_m : ndarray, shape (2,)
        Vehicle position now, line frame.

    Returns
    -------
    ndarray, shape (n,)
    """
    offset = points_line_m[:, None, :] - centres_line_m
    closest = np.argmin(np.hypot(offset[..., 0], offset[..., 1]), axis=0)
    lateral = offset[closest, np.arange(centres_line_m.shape[1]), 1]
    now = vehicle_line_m[1] - centres_line_m[0, :, 1]
    side = np.where(now < -TIE_M, -1.0, 1.0)
    return np.where(lateral > TIE_M, 1.0, np.where(lateral < -TIE_M, -1.0, side))


def side_rule_normals(points_line_m: np.ndarray, centres_line_m: np.ndarray,
                      reach_m: np.ndarray, sides: np.ndarray,
                      min_lateral_offset_ratio: float) -> np.ndarray:
    """Unit gradients of ``h`` at the linearization points after the side rule (line frame).

    The point's lateral offset from each obstacle is taken as ``sigma max(sigma dy, rho R)``
    (module docstring); its longitudinal offset as it is.

    Parameters
    ----------
    points_line_m : ndarray, shape (K, 2)
    centres_line_m : ndarray, shape (K, n, 2)
    reach_m : ndarray, shape (n,)
    sides : ndarray, shape (n,)
        :func:`pass_sides`.
    min_lateral_offset_ratio : float

    Returns
    -------
    ndarray, shape (K, n, 2)
        ``n_kj``: the tangent of ``h_j`` at step ``k`` is ``n_kj . (p - o_kj) - R_j``.
    """
    offset = points_line_m[:, None, :] - centres_line_m
    floor = np.maximum(min_lateral_offset_ratio * reach_m, 1e-6)[None, :]
    lateral = sides[None, :] * np.maximum(sides[None, :] * offset[..., 1], floor)
    vector = np.stack([offset[..., 0], lateral], axis=-1)
    return vector / np.linalg.norm(vector, axis=-1, keepdims=True)


def sided_normals(points_m: np.ndarray, centres_m: np.ndarray, reach_m: np.ndarray,
                  min_lateral_offset_ratio: float, frame: LineFrame | None = None,
                  side_points_m: np.ndarray | None = None) -> np.ndarray:
    """The rule in one call: :func:`pass_sides` on a trajectory, then :func:`side_rule_normals`
    at each linearization point, in the frame the points are given in.

    Parameters
    ----------
    points_m : ndarray, shape (K, 2)
        Linearization points, row 0 the vehicle now.
    centres_m : ndarray, shape (K, n, 2)
        Obstacle centres at the same instants.
    reach_m : ndarray, shape (n,)
        Keep-out radii ``R``.
    min_lateral_offset_ratio : float
        ``rho``.
    frame : LineFrame, optional
        The start-goal line's frame when the points are global (the sides are taken in it and
        the normals turned back); None when they are in it already.
    side_points_m : ndarray, shape (K, 2), optional
        The trajectory the sides are taken on (row 0 the vehicle now), when it is not the
        linearization points' own.

    Returns
    -------
    ndarray, shape (K, n, 2)
        Unit normals ``n_kj`` in the points' frame.
    """
    def line(points: np.ndarray) -> np.ndarray:
        return points if frame is None else frame.to_line(points)

    points_line, centres_line = line(points_m), line(centres_m)
    on = points_line if side_points_m is None else line(side_points_m)
    sides = pass_sides(on, centres_line, on[0])
    normals = side_rule_normals(points_line, centres_line, reach_m, sides,
                                min_lateral_offset_ratio)
    if frame is None:
        return normals
    c, s = frame.cos_sin
    return normals @ np.array([[c, -s], [s, c]]).T   # line-frame vectors to global ones
