"""Peer "cbf_filter": the MPC without APF, its first input filtered by a control-barrier-function
QP (Ames, Coogan, Egerstedt, Notomista, Sreenath and Tabuada, "Control barrier functions:
theory and applications", ECC 2019).

The nominal controller is the built-in MPC of the track with the straight-to-goal reference
(``planner: straight_to_goal``) and, as the method configs set it, without its collision
half-planes (``controller.collision_constraints: false``): it only tracks the goal line. Its
first input ``u_nom`` is then replaced by the solution of::

    min_u,s   |W (u - u_nom)|^2 + w1 sum(s) + w2 |s|^2
    s.t.      h_j(p_i(u_nom)) + g_ij (u - u_nom) + s_ij >= (1 - gamma)^m h_j(x_k)
                  (each obstacle j, each preview step i = 1..m)
              u_low <= u <= u_high,  s >= 0

* **Barrier.** ``h_j(p, t) = |p - o_j(t)| - (R_j + vehicle.footprint_radius_m +
  controller.safety_margin_m)``: the clearance of the vehicle's collision circle to obstacle
  ``j``'s circle, with the MPC's own safety margin. Only visible obstacles
  (``obs.obstacles``) get rows; at most ``controller.max_obstacles`` of them, those of the
  smallest ``h`` now.
* **Discrete-time CBF over a preview** (the inputs reach the position through integrators:
  on the lateral track steering rate -> steering -> yaw -> lateral position, relative degree
  3; on the kinematic track steering angle -> heading -> position and acceleration -> speed
  -> position, relative degree 2, so the input has no effect on ``h`` one step ahead worth a
  constraint). The candidate input ``u`` is held for ``m = params.preview_steps`` steps
  (default 10: 1 s, the MPC's horizon) of the controller's own prediction model, the obstacle
  is moved with its velocity (``obs.obstacles.velocities_mps``) over the same steps, and the
  condition is the discrete-time CBF condition ``h(x_{k+m}) >= (1 - gamma)^m h(x_k)`` with
  ``gamma = params.decay_rate`` per step (default 0.1: ``h`` may shrink by at most the share
  ``1 - (1 - gamma)^m = 65 %`` over the preview, so it never crosses zero while the condition
  holds). With ``params.preview_rows=every_step`` (the default) the same bound is asked of
  every preview step, ``h(x_{k+i}) >= (1 - gamma)^m h(x_k)`` for ``i = 1..m``: a vehicle that
  passes an obstacle within the preview is held at its closest point, which the end of the
  preview alone misses (``terminal``, the condition at ``i = m`` only: 4 of 20 family members
  cut an obstacle's edge where ``every_step`` kept all 20 clear). The bound is
  ``(1 - gamma)^m h`` at every ``i``, not ``(1 - gamma)^i h``: at small ``i`` the held input has
  hardly acted yet (the relative degree), and a first-order decay there would ask the
  impossible of it.
* **Linearization.** Each preview position is affine in the held input
  (``p_i(u) = p_i(u_nom) + J_i (u - u_nom)``, ``J_i`` the preview's sensitivity to the held
  input); ``h_j`` is linearized in ``u`` at ``u_nom``: ``g_ij = n_ij' J_i`` with ``n_ij`` the
  unit vector from the moved obstacle to ``p_i(u_nom)``. ``h_j(p_i(u))`` is convex in ``u``
  (a distance of an affine map), so the linearized row is a conservative (inner) version of
  the nonlinear one about any point; without the side rule (below) linearizing at ``u_nom``
  picks the side of the obstacle the nominal input heads for.

  - Lateral track (:class:`LateralCbfFilter`): the lateral MPC's discrete model ``Ad, Bd`` at
    the measured speed (the controller's model bank, sample time ``Ts``) in the start-goal
    line's frame, state ``[y, vy, epsi, r, delta]`` measured against the line (what
    ``controller.frame=fixed`` hands the MPC), whatever frame the nominal MPC uses; the
    station along the line advances at the measured along-line speed
    ``vx cos(epsi) - vy sin(epsi)`` (the lateral model has none). The model is linear, so
    ``J_i = sum_{l<i} Ad^l Bd`` (its lateral row) is exact for it. The held rate is not
    clipped at the steering bound in the preview (the linear model has none): near the bound
    the preview is optimistic.
  - Kinematic track (:class:`KinematicCbfFilter`): the kinematic LTV-MPC's Euler model
    (:func:`~pipeline.loop.model.kinematic_euler_step`) rolled out from the measured state with
    ``u_nom`` held, ``J_i`` the product of its Jacobians along that rollout
    (:func:`~pipeline.loop.model.kinematic_jacobians`, ``S_{i+1} = A_i S_i + B_i``).
* **Side rule** (``params.min_lateral_offset_ratio``, ``rho``; 0 turns it off). With an
  obstacle dead ahead, on the start-goal line in the vehicle's path, ``n_ij`` has no lateral
  part: steering cannot raise the linearized ``h``. On the lateral track (the speed is not an
  input) the QP then pays slack; on a static obstacle on the line 14 m ahead it paid slack on
  24 steps, the first 0.7 s of them without steering, then with its steering rate
  alternating between its bounds, and collided (min clearance -0.87 m) where every other
  method of the lateral track passes. This is the CBF-QP's known undesired equilibrium on
  symmetric geometry (Reis, Aguiar and Tabuada, "Control barrier function-based quadratic
  programs introduce undesirable asymptotically stable equilibria", IEEE L-CSS 2021; Tan and
  Dimarogonas, "On the undesired equilibria induced by control barrier function based
  quadratic programs", Automatica 2024), and the fix is MPC-DCBF's side rule
  (:mod:`pipeline.peers.side_rule`, the same functions): each obstacle is passed on one side,
  and the linearization point's lateral offset from it is taken as at least ``rho R_j`` on
  that side. The row becomes the tangent ``n_ij' (p_i(u) - o_ij) - R_j`` at that
  point, which never exceeds ``h_j`` (``|n_ij| = 1``): still conservative. The side is the one
  the preview under the input applied last step (held) is on where it comes closest to the
  obstacle (dead ahead there: the side the vehicle is on now; a tie: the left). Not
  ``u_nom``'s preview: the nominal MPC steers back towards the goal line, its preview crosses
  the obstacle's line and the side flipped from step to step (measured on the same case: the
  rate again alternating between its bounds); the input the filter applied keeps the side it
  chose. With the rule the dead-ahead run passes at 0.63 m (slack on 2 steps).
  On the kinematic track the rule is needed but not enough: braking slows the fall of ``h``
  at a far smaller cost than steering (whose reach shrinks with the speed), so the QP brakes
  to a stop in front of the obstacle, with or without the rule (as MPC-DCBF does on this
  track). ``params.accel_cost_ratio`` (Cost, below) makes it steer first.
* **Cost.** ``W = diag(1 / u_scale)`` with ``u_scale`` the input bound of each input (lateral:
  ``vehicle.steering_rate_max_rad_s``; kinematic: the larger magnitude of
  ``controller.accel_bounds_mps2`` and ``vehicle.steering_max_rad``), so that a change of an
  acceleration and of a steering angle cost alike per share of their range, the acceleration's
  scale divided by ``params.accel_cost_ratio`` (kinematic preset: 10, an acceleration change
  costs 100 times a steering change of the same share of its range: the filter steers around
  and brakes where steering cannot meet the rows; at 1 it brakes to a standstill in front of
  an obstacle dead ahead, the undesired equilibrium above); the slack (m of ``h``) carries the
  linear weight ``params.slack_weight_linear`` (an exact penalty: no slack where the rows can
  be met) and the quadratic ``params.slack_weight_quadratic``.
* **Solver.** The QP is stated in CVXPY with ``u_nom``, the rows' gains ``G`` and bounds ``b``
  as DPP parameters, compiled once per structure (:class:`CbfQpStructure`, the cache key)
  into the loop's kept-Clarabel backend (:func:`~pipeline.loop.controller.qp.compiled_backend`;
  ``controller.backend=cvxpy`` solves it through CVXPY instead); the nominal MPC's own backend
  is whatever ``controller.backend`` says. Unused obstacle slots get rows ``0 u + s >= -1``
  that cannot bind.
* **No active row.** When ``u_nom`` meets every row (or there is none), ``u_nom`` is the QP's
  optimum: the filter returns the nominal step's input unchanged (the same array) without
  solving.
* **Fallback.** When the filter's QP fails (its status is not optimal), the nominal input is
  applied and ``solver_status`` says ``cbf_<status>``.

The step's ``planned`` is the nominal plan with its first input replaced; its predicted states
are the controller's model rolled out under that plan. Log columns: ``cbf_active`` (a row bound
at ``u_nom``, the QP was solved), ``cbf_rows`` (obstacles with a row), ``cbf_min_h_m`` (the
smallest ``h`` now), ``cbf_slack_m`` (the QP's largest slack, also ``max_slack_m``), the
correction ``u - u_nom`` (``cbf_correction_rad_s``; kinematic ``cbf_correction_accel_mps2``,
``cbf_correction_delta_rad``) and ``cbf_solve_time_s`` (rows and QP; the step's
``solve_time_s`` is the nominal MPC's plus this).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from math import cos, sin
from typing import TYPE_CHECKING, Any, TypeVar

import numpy as np

from pipeline.errors import ConfigError
from pipeline.loop.controller.base import ControlStep, Observation
from pipeline.loop.controller.kinematic import KinematicLtvMpc
from pipeline.loop.controller.lateral import LateralMpc
from pipeline.loop.controller.qp import CvxpyQp, DirectQp, QpCache, compiled_backend
from pipeline.loop.controller_settings import KinematicMpcSettings, MpcSettings, settings_of
from pipeline.loop.model import kinematic_euler_step, kinematic_jacobians
from pipeline.loop.scenario import LineFrame
from pipeline.loop.settings import ControllerConfig, VehicleConfig
from pipeline.peers.side_rule import sided_normals
from pipeline.validation import between, choice, finite

if TYPE_CHECKING:
    import cvxpy as cp

__all__ = ["CbfFilterSettings", "CbfQpStructure", "CbfRows", "CbfSafetyFilter",
           "FilterResult", "KinematicCbfFilter", "LateralCbfFilter", "build_cbf_problem",
           "barrier_rows"]


@dataclass(frozen=True)
class CbfFilterSettings:
    """The filter's settings (``controller.params``).

    Attributes
    ----------
    preview_steps : int
        ``m``: steps the candidate input is held for in the preview, in [1, 50].
    decay_rate : float
        ``gamma`` per step of the discrete-time CBF condition, in (0, 1].
    slack_weight_linear : float
        Linear weight of the slack (per m of ``h``), > 0 (an exact penalty).
    slack_weight_quadratic : float
        Quadratic weight of the slack (per m^2), >= 0.
    preview_rows : str
        ``every_step``: a row per obstacle at each preview step ``i = 1..m``, ``h(x_{k+i}) >=
        (1 - gamma)^m h(x_k)`` (an obstacle passed within the preview is seen at its closest);
        ``terminal``: at step ``m`` only.
    min_lateral_offset_ratio : float
        ``rho`` in [0, 1] of the side rule (:mod:`pipeline.peers.side_rule`): least lateral
        offset of a linearization point from the obstacle, as a share of the keep-out radius,
        on the side it is passed; 0: no side rule (the plain gradient of ``h``).
    accel_cost_ratio : float
        Kinematic track, in [0.1, 100]: the acceleration's weight in the cost over the
        steering angle's, per share of each one's range (``W = diag(ratio / a_scale,
        1 / delta_max)``); 1: alike. The lateral track's one input (the steering rate) takes
        only 1.
    """

    preview_steps: int = 10
    decay_rate: float = 0.1
    slack_weight_linear: float = 1.0e4
    slack_weight_quadratic: float = 1.0e3
    preview_rows: str = "every_step"
    min_lateral_offset_ratio: float = 0.5
    accel_cost_ratio: float = 1.0

    def rows_for(self, slots: int) -> int:
        """Rows of the QP for ``slots`` obstacle slots."""
        return slots * (self.preview_steps if self.preview_rows == "every_step" else 1)

    @classmethod
    def of(cls, params: dict[str, Any]) -> CbfFilterSettings:
        """The settings in ``params`` (defaults for missing keys); a :class:`ConfigError`
        (a ``ValueError``, one line) naming ``controller.params.<key>`` for an unknown key or a
        value out of range."""
        known = cls.__dataclass_fields__
        for key in params:
            if key not in known:
                raise ConfigError(f"controller.params.{key}", params[key],
                                  "one of the keys " + ", ".join(known))
        values = {**{k: f.default for k, f in known.items()}, **dict(params)}
        steps = values["preview_steps"]
        if isinstance(steps, bool) or not isinstance(steps, int) or not 1 <= steps <= 50:
            raise ConfigError("controller.params.preview_steps", steps, "an integer in [1, 50]")
        if not 0.0 < finite("controller.params.decay_rate", values["decay_rate"]) <= 1.0:
            raise ConfigError("controller.params.decay_rate", values["decay_rate"],
                              "a number in (0, 1]")
        between("controller.params.slack_weight_linear", values["slack_weight_linear"],
                1e-6, 1e9)
        between("controller.params.slack_weight_quadratic", values["slack_weight_quadratic"],
                0.0, 1e9)
        choice("controller.params.preview_rows", values["preview_rows"],
               ("every_step", "terminal"))
        between("controller.params.min_lateral_offset_ratio",
                values["min_lateral_offset_ratio"], 0.0, 1.0)
        between("controller.params.accel_cost_ratio", values["accel_cost_ratio"], 0.1, 100.0)
        return cls(int(steps), float(values["decay_rate"]),
                   float(values["slack_weight_linear"]), float(values["slack_weight_quadratic"]),
                   str(values["preview_rows"]), float(values["min_lateral_offset_ratio"]),
                   float(values["accel_cost_ratio"]))


@dataclass(frozen=True)
class CbfQpStructure:
    """Everything that enters the filter's QP as a constant (the key of its compilation).

    Attributes
    ----------
    input_low, input_high : tuple of float
        Input bounds.
    input_scale : tuple of float
        ``u_scale``: the cost is ``sum ((u - u_nom) / u_scale)^2``.
    n_rows : int
        Rows: obstacle slots times rows per slot (``m`` for ``preview_rows=every_step``, else
        1).
    slack_weights : tuple of float
        Linear and quadratic slack weights.
    """

    input_low: tuple[float, ...]
    input_high: tuple[float, ...]
    input_scale: tuple[float, ...]
    n_rows: int
    slack_weights: tuple[float, float]

    @property
    def n_inputs(self) -> int:
        return len(self.input_low)


def build_cbf_problem(s: CbfQpStructure) -> tuple[cp.Problem, list[Any], dict[str, Any]]:
    """The filter's QP in CVXPY (DPP): problem, parameters in ``theta`` order (``u_nom``,
    ``G`` column-major, ``b``), variables to read (``u``, ``s``).

    The cost ``|W (u - u_nom)|^2`` is written as ``|W u|^2 - 2 (W^2 u_nom)' u`` (the same up to
    a constant) so that the quadratic part is constant and no auxiliary variable appears."""
    import cvxpy as cp

    n, M = s.n_inputs, s.n_rows
    weight = 1.0 / np.asarray(s.input_scale, float)
    u_nom = cp.Parameter(n, name="u_nom")
    G = cp.Parameter((M, n), name="cbf_gain")
    b = cp.Parameter(M, name="cbf_bound")
    u = cp.Variable(n, name="u")
    slack = cp.Variable(M, name="s")  # s >= 0 as a row (a nonneg variable is renamed)
    w1, w2 = s.slack_weights
    cost = (cp.sum_squares(cp.multiply(weight, u)) - 2.0 * (cp.multiply(weight**2, u_nom) @ u)
            + w1 * cp.sum(slack) + w2 * cp.sum_squares(slack))
    constraints = [G @ u + slack >= b, slack >= 0, u >= np.asarray(s.input_low, float),
                   u <= np.asarray(s.input_high, float)]
    problem = cp.Problem(cp.Minimize(cost), constraints)
    if not problem.is_dcp(dpp=True):
        raise RuntimeError("the CBF filter's QP is not DPP; it would recompile every step")
    return problem, [u_nom, G, b], {"u": u, "s": slack}


@dataclass(frozen=True)
class CbfRows:
    """One step's CBF rows ``G u + s >= b`` (slot-major: an obstacle's preview steps together).

    Attributes
    ----------
    gain : ndarray, shape (n_rows, n_u)
        ``g_ij`` (unused slots: 0).
    bound : ndarray, shape (n_rows,)
        ``(1 - gamma)^m h_j(x_k) - h_j(p_i(u_nom)) + g_ij u_nom`` (unused slots: -1).
    n_used : int
        Obstacles with a row.
    h_now_m : ndarray, shape (n_used,)
        ``h_j(x_k)``.
    """

    gain: np.ndarray
    bound: np.ndarray
    n_used: int
    h_now_m: np.ndarray

    def met_by(self, u: np.ndarray) -> bool:
        """Whether ``u`` meets every row without slack."""
        return bool(np.all(self.gain @ u >= self.bound))


def barrier_rows(position_m: np.ndarray, preview_positions_m: np.ndarray,
                 sensitivities: np.ndarray, u_nom: np.ndarray, obstacles_now_m: np.ndarray,
                 obstacles_preview_m: np.ndarray, reach_m: np.ndarray, n_slots: int,
                 settings: CbfFilterSettings, frame: LineFrame | None = None,
                 side_preview_m: np.ndarray | None = None) -> CbfRows:
    """The linearized discrete-time CBF rows of one step (see the module docstring).

    Parameters
    ----------
    position_m : ndarray, shape (2,)
        Vehicle position now.
    preview_positions_m : ndarray, shape (m, 2)
        ``p_i(u_nom)``, ``i = 1..m``: positions over the preview with ``u_nom`` held.
    sensitivities : ndarray, shape (m, 2, n_u)
        ``J_i``: ``p_i(u) = p_i(u_nom) + J_i (u - u_nom)``.
    u_nom : ndarray, shape (n_u,)
    obstacles_now_m : ndarray, shape (n, 2)
        Obstacle centres now (same frame as the positions).
    obstacles_preview_m : ndarray, shape (m, n, 2)
        The centres moved with their velocities to the preview's steps.
    reach_m : ndarray, shape (n,)
        ``R_j + footprint radius + safety margin``.
    n_slots : int
        Obstacle slots ``M`` (the ``M`` obstacles of smallest ``h`` now get rows).
    settings : CbfFilterSettings
    frame : LineFrame, optional
        The start-goal line's frame when the positions are global (the side rule takes its
        sides in it); None when they are in it already.
    side_preview_m : ndarray, shape (m, 2), optional
        The positions over the preview with the previously applied input held: the side rule
        takes its sides on them (None: on ``p_i(u_nom)``).

    Returns
    -------
    CbfRows
        ``M`` rows (``params.preview_rows=terminal``: step ``m`` only) or ``M m`` rows
        (``every_step``: steps ``1..m``, slot-major), each ``h_j(p_i(u)) >= (1 - gamma)^m
        h_j(x_k)``.
    """
    n_u, m = u_nom.shape[0], settings.preview_steps
    steps = np.arange(m) if settings.preview_rows == "every_step" else np.array([m - 1])
    per_slot = steps.shape[0]
    gain, bound = np.zeros((n_slots * per_slot, n_u)), np.full(n_slots * per_slot, -1.0)
    h_now = np.hypot(*(position_m[None, :] - obstacles_now_m).T) - reach_m \
        if reach_m.shape[0] else np.zeros(0)
    order = np.argsort(h_now, kind="stable")[:n_slots]
    used = order.shape[0]
    if used:
        # (step, obstacle) pairs: offsets from the moved obstacles to p_i(u_nom)
        offsets = preview_positions_m[steps][:, None, :] - obstacles_preview_m[steps][:, order]
        if settings.min_lateral_offset_ratio > 0.0:
            # the side rule's normals (the vehicle now, then the preview); the row is the
            # tangent n . (p - o) - R, never above h (module docstring)
            normal = sided_normals(
                np.concatenate([position_m[None, :], preview_positions_m]),
                np.concatenate([obstacles_now_m[None, order], obstacles_preview_m[:, order]]),
                reach_m[order], settings.min_lateral_offset_ratio, frame,
                None if side_preview_m is None
                else np.concatenate([position_m[None, :], side_preview_m]))[1:][steps]
            projected = np.sum(normal * offsets, axis=2)
        else:
            projected = np.hypot(offsets[..., 0], offsets[..., 1])   # the distance itself
            safe = np.where(projected > 1e-9, projected, 1.0)
            normal = np.where((projected > 1e-9)[..., None], offsets / safe[..., None], 0.0)
        g = np.einsum("skc,scu->sku", normal, sensitivities[steps])     # (steps, slots, n_u)
        target = (1.0 - settings.decay_rate) ** m * h_now[order]
        b = target[None, :] - (projected - reach_m[order][None, :]) + g @ u_nom
        gain[:used * per_slot] = g.transpose(1, 0, 2).reshape(-1, n_u)   # slot-major
        bound[:used * per_slot] = b.T.reshape(-1)
    return CbfRows(gain, bound, int(order.shape[0]), h_now[order])


@dataclass(frozen=True)
class FilterResult:
    """What the filter made of one nominal input.

    Attributes
    ----------
    command : ndarray, shape (n_u,)
        The input to apply (``u_nom`` itself when no row was active or the QP failed).
    active : bool
        A row bound at ``u_nom`` (the QP was solved).
    status : str
        ``inactive``, or the QP's status.
    slack_m : float
        Largest slack of the QP's solution (0 when not solved).
    iterations : int
    solve_time_s : float
        Rows and solve (s).
    """

    command: np.ndarray
    active: bool
    status: str
    slack_m: float
    iterations: int
    solve_time_s: float

    @property
    def failed(self) -> bool:
        return self.active and self.status not in ("optimal", "optimal_inaccurate")


class CbfSafetyFilter:
    """The CBF-QP of one track: compiled once (from ``qp_cache``), solved where a row binds.

    Parameters
    ----------
    structure : CbfQpStructure
    backend : str
        ``cvxpy`` solves through CVXPY; anything else the kept Clarabel
        (``clarabel_direct``).
    max_iter : int
    qp_cache : QpCache or None
    """

    def __init__(self, structure: CbfQpStructure, backend: str, max_iter: int,
                 qp_cache: QpCache | None) -> None:
        self.structure = structure
        backend = "cvxpy" if backend == "cvxpy" else "clarabel_direct"
        self.qp: DirectQp | CvxpyQp
        self.qp, self.compile_count, self.compile_time_s = compiled_backend(
            qp_cache, "cbf_filter", structure, lambda: build_cbf_problem(structure), backend,
            max_iter)

    def apply(self, u_nom: np.ndarray, rows: CbfRows, started_s: float) -> FilterResult:
        """The filtered input: ``u_nom`` unchanged when it meets every row, else the QP's
        solution (``u_nom`` with the status when the QP fails). ``started_s``: when the rows'
        computation began (``time.perf_counter``)."""
        if rows.met_by(u_nom):
            return FilterResult(u_nom, False, "inactive", 0.0, 0,
                                time.perf_counter() - started_s)
        theta = np.concatenate([u_nom, rows.gain.ravel(order="F"), rows.bound])
        solution = self.qp.solve(theta)
        elapsed = time.perf_counter() - started_s
        if not solution.ok:
            return FilterResult(u_nom, True, solution.status, float("nan"),
                                solution.iterations, elapsed)
        u = solution.value("u").reshape(-1)
        low, high = self.structure.input_low, self.structure.input_high
        u = np.clip(u, np.asarray(low), np.asarray(high))  # Clarabel's last 1e-9
        slack = float(np.max(rows.bound - rows.gain @ u, initial=0.0))
        return FilterResult(u, True, solution.status, max(slack, 0.0), solution.iterations,
                            elapsed)


def _attach_filter(peer: Any, controller_cfg: MpcSettings | KinematicMpcSettings, nominal: Any,
                   lower: tuple[float, ...], upper: tuple[float, ...],
                   scale: tuple[float, ...], qp_cache: QpCache | None) -> None:
    """What both filters share: the nominal controller, the CBF-QP for inputs within
    ``lower``..``upper`` (``scale``: the cost's units) and the compile counts of both."""
    peer.nominal = nominal
    structure = CbfQpStructure(lower, upper, scale, peer.settings.rows_for(peer.n_slots),
                               (peer.settings.slack_weight_linear,
                                peer.settings.slack_weight_quadratic))
    peer.filter = CbfSafetyFilter(structure, controller_cfg.backend,
                                  controller_cfg.solver_max_iter, qp_cache)
    peer.compile_count = nominal.compile_count + peer.filter.compile_count
    peer.compile_time_s = nominal.compile_time_s + peer.filter.compile_time_s


#: The settings a filter's nominal MPC has (either track's).
NominalSettings = TypeVar("NominalSettings", MpcSettings, KinematicMpcSettings)


def _check_kind(controller_cfg: ControllerConfig, kind: type[NominalSettings], cls: str
                ) -> NominalSettings:
    """The nominal controller's settings this filter wraps: of its kind, on a QP backend."""
    if controller_cfg.kind != kind.kind_word:
        raise ConfigError("controller.kind", controller_cfg.kind,
                          f"{kind.kind_word} with controller._target_={cls}")
    settings = settings_of(controller_cfg, kind)
    if settings.backend == "nmpc":
        raise ConfigError("controller.backend", settings.backend,
                          f"a QP backend (not nmpc) with controller._target_={cls}")
    return settings


def _log_columns(result: FilterResult, rows: CbfRows, correction: dict[str, float]
                 ) -> dict[str, Any]:
    return {"cbf_active": result.active, "cbf_rows": rows.n_used,
            "cbf_min_h_m": float(rows.h_now_m.min()) if rows.n_used else float("nan"),
            "cbf_slack_m": result.slack_m, **correction,
            "cbf_solve_time_s": result.solve_time_s}


def _filtered_step(nominal: ControlStep, result: FilterResult, log: dict[str, Any],
                   predicted: Callable[[np.ndarray], np.ndarray]) -> ControlStep:
    """The nominal step with the filter's input, time and log (``predicted(plan)``: the
    states of the model under a plan, for a changed first input). Without an active row the
    command is the nominal step's own array."""
    solve_time_s = nominal.solve_time_s + result.solve_time_s
    if not result.active:
        return replace(nominal, solve_time_s=solve_time_s, log={**nominal.log, **log})
    if result.failed:
        return replace(nominal, status=f"cbf_{result.status}", solve_time_s=solve_time_s,
                       log={**nominal.log, **log})
    plan = nominal.planned.copy()
    plan[:, 0] = result.command
    states = predicted(plan) if nominal.predicted_states is not None else None
    return ControlStep(result.command.copy(), plan, states, nominal.status,
                       nominal.iterations + max(result.iterations, 0), solve_time_s,
                       nominal.fallback, result.slack_m, {**nominal.log, **log})


class LateralCbfFilter:
    """The lateral MPC without APF and collision half-planes, its first input (steering rate)
    filtered by the CBF-QP (lateral track; ``controller._target_``).

    Parameters
    ----------
    controller_cfg : ControllerConfig
        The nominal lateral MPC's settings (``kind: mpc``); the filter's in ``params``
        (:class:`CbfFilterSettings`).
    vehicle : VehicleConfig
    sample_time_s : float
    qp_cache : QpCache, optional

    Attributes
    ----------
    nominal : LateralMpc
    filter : CbfSafetyFilter
    compile_count : int
    compile_time_s : float
    """

    nominal: LateralMpc
    filter: CbfSafetyFilter
    compile_count: int
    compile_time_s: float

    def __init__(self, controller_cfg: ControllerConfig, vehicle: VehicleConfig,
                 sample_time_s: float, qp_cache: QpCache | None = None) -> None:
        from pipeline.loop.simulate import run_kernels

        controller_cfg = _check_kind(controller_cfg, MpcSettings,
                                     "pipeline.peers.cbf_filter.LateralCbfFilter")
        self.settings = CbfFilterSettings.of(dict(controller_cfg.params))
        if self.settings.accel_cost_ratio != 1.0:
            raise ConfigError("controller.params.accel_cost_ratio",
                              controller_cfg.params["accel_cost_ratio"],
                              "1 on the lateral track (its one input is the steering rate)")
        self.vehicle, self.ts = vehicle, float(sample_time_s)
        self.margin_m = controller_cfg.safety_margin_m
        self.n_slots = controller_cfg.max_obstacles
        rate = vehicle.steering_rate_max_rad_s
        _attach_filter(self, controller_cfg, LateralMpc(controller_cfg, vehicle, None,
                                                         sample_time_s, qp_cache,
                                                         run_kernels(qp_cache)),
                       (-rate,), (rate,), (rate,), qp_cache)
        self.applied = np.zeros(1)   # the steering rate applied last step (the side rule's)

    def preview(self, obs: Observation) -> tuple[np.ndarray, np.ndarray]:
        """The preview in the start-goal line's frame (see the module docstring): positions
        at steps ``1..m`` with zero input held (the free response), shape (m, 2), and their
        sensitivities ``J_i`` to the held steering rate, shape (m, 2, 1)."""
        st = obs.plant_state
        vx, vy = max(float(st[3]), self.vehicle.min_model_speed_mps), float(st[4])
        model = self.nominal.bank.at(vx)
        e_psi = obs.heading_line_rad
        x = np.array([obs.position_line_m[1], st[4], e_psi, st[5], st[6]], dtype=float)
        sens = np.zeros(5)
        Ad, Bd = model.Ad, model.Bd[:, 0]
        m = self.settings.preview_steps
        free, sensitivities = np.empty((m, 2)), np.zeros((m, 2, 1))
        along = float(st[3]) * cos(e_psi) - vy * sin(e_psi)
        for i in range(m):
            x = Ad @ x
            sens = Ad @ sens + Bd
            free[i] = obs.position_line_m[0] + along * (i + 1) * self.ts, x[0]
            sensitivities[i, 1, 0] = sens[0]
        return free, sensitivities

    def rows(self, obs: Observation, u_nom: np.ndarray) -> CbfRows:
        """This step's CBF rows at ``u_nom`` (line frame; the side rule's sides on the
        preview with the steering rate applied last step held)."""
        free, sensitivities = self.preview(obs)
        visible = obs.obstacles
        times = self.ts * np.arange(1, self.settings.preview_steps + 1)
        if visible.radii_m.shape[0]:
            now = obs.frame.to_line(visible.positions_m)
            moved = obs.frame.to_line(visible.predicted_positions(times))
        else:
            now, moved = np.zeros((0, 2)), np.zeros((times.shape[0], 0, 2))
        reach = visible.radii_m + self.vehicle.footprint_radius_m + self.margin_m
        return barrier_rows(obs.position_line_m.astype(float), free + sensitivities @ u_nom,
                            sensitivities, u_nom, now, moved, reach, self.n_slots,
                            self.settings, side_preview_m=free + sensitivities @ self.applied)

    def step(self, obs: Observation) -> ControlStep:
        """The nominal MPC's step, its first input filtered (the nominal's frame, fallback and
        prediction record kept as :meth:`LateralMpc.step` keeps them, with the applied
        plan)."""
        nominal = self.nominal
        inputs, log = nominal.frame.inputs(obs)
        nominal_step = nominal.solve(inputs, log)
        started = time.perf_counter()
        u_nom = np.asarray(nominal_step.command, dtype=float)
        rows = self.rows(obs, u_nom)
        result = self.filter.apply(u_nom, rows, started)
        columns = _log_columns(result, rows, {"cbf_correction_rad_s": float(
            result.command[0] - u_nom[0]) if result.active and not result.failed else 0.0})

        def predicted(plan: np.ndarray) -> np.ndarray:
            model = inputs.model
            states = np.empty((5, plan.shape[1] + 1))
            states[:, 0] = inputs.x0
            for k in range(plan.shape[1]):
                states[:, k + 1] = model.Ad @ states[:, k] + model.Bd[:, 0] * plan[0, k] \
                    + model.Ed[:, 0] * inputs.disturbance_rad_s[k]
            return states

        step = _filtered_step(nominal_step, result, columns, predicted)
        if result.active and not result.failed and step.fallback == "none":
            nominal.fallback.accept(step.planned)   # the applied plan, for a later fallback
        self.applied = np.asarray(step.command, dtype=float).copy()
        nominal.frame.after_step(step)
        nominal.keep_record(inputs, step.predicted_states[0] if step.predicted_states
                            is not None and step.fallback == "none" else None)
        return step

    def model_check(self, log: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """The nominal MPC's prediction check (:meth:`LateralMpc.model_check`), on the plans
        applied."""
        return self.nominal.model_check(log)

    def horizon_view(self, rows: int) -> dict[str, np.ndarray]:
        """The nominal MPC's plan and half-planes (the report's scenario explorer)."""
        return self.nominal.horizon_view(rows)


class KinematicCbfFilter:
    """Appendix A's kinematic LTV-MPC without APF and collision half-planes, its first input
    (acceleration, steering angle) filtered by the CBF-QP (kinematic track;
    ``controller._target_``).

    Parameters
    ----------
    controller_cfg : ControllerConfig
        The nominal kinematic MPC's settings (``kind: kinematic_mpc``); the filter's in
        ``params`` (:class:`CbfFilterSettings`).
    vehicle : VehicleConfig
    sample_time_s : float
    qp_cache : QpCache, optional
    """

    nominal: KinematicLtvMpc
    filter: CbfSafetyFilter
    compile_count: int
    compile_time_s: float

    def __init__(self, controller_cfg: ControllerConfig, vehicle: VehicleConfig,
                 sample_time_s: float, qp_cache: QpCache | None = None) -> None:
        controller_cfg = _check_kind(controller_cfg, KinematicMpcSettings,
                                     "pipeline.peers.cbf_filter.KinematicCbfFilter")
        self.settings = CbfFilterSettings.of(dict(controller_cfg.params))
        self.vehicle, self.ts = vehicle, float(sample_time_s)
        self.margin_m = controller_cfg.safety_margin_m
        self.n_slots = controller_cfg.max_obstacles
        a_lo, a_hi = (float(v) for v in controller_cfg.accel_bounds_mps2)
        steer = vehicle.steering_max_rad
        _attach_filter(self, controller_cfg,
                       KinematicLtvMpc(controller_cfg, vehicle, sample_time_s, qp_cache),
                       (a_lo, -steer), (a_hi, steer),
                       (max(abs(a_lo), abs(a_hi)) / self.settings.accel_cost_ratio, steer),
                       qp_cache)
        self._steps_ahead_s = np.arange(1, controller_cfg.horizon + 1) * self.ts

    def preview(self, state: np.ndarray, u_nom: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The Euler model rolled out ``m`` steps from ``state`` with ``u_nom`` held: the
        positions at steps ``1..m``, shape (m, 2), and their sensitivities ``J_i`` to the held
        input, shape (m, 2, 2)."""
        L = self.vehicle.wheelbase_m
        x = np.asarray(state, dtype=float)
        m = self.settings.preview_steps
        sens = np.zeros((4, 2))
        positions, sensitivities = np.empty((m, 2)), np.empty((m, 2, 2))
        for i in range(m):
            A, B, _ = kinematic_jacobians(x, u_nom, L, self.ts)
            sens = A @ sens + B
            x = kinematic_euler_step(x, u_nom, L, self.ts)
            positions[i], sensitivities[i] = x[:2], sens[:2]
        return positions, sensitivities

    def rows(self, obs: Observation, u_nom: np.ndarray) -> CbfRows:
        """This step's CBF rows at ``u_nom`` (global frame; the side rule's sides on the
        preview with the input applied last step held)."""
        state = np.asarray(obs.plant_state, dtype=float)
        positions, sensitivities = self.preview(state, u_nom)
        visible = obs.obstacles
        times = self.ts * np.arange(1, self.settings.preview_steps + 1)
        reach = visible.radii_m + self.vehicle.footprint_radius_m + self.margin_m
        applied = self.nominal.u_prev
        sided = self.settings.min_lateral_offset_ratio > 0.0 and visible.radii_m.shape[0] > 0 \
            and not np.array_equal(applied, u_nom)
        return barrier_rows(state[:2], positions, sensitivities, u_nom, visible.positions_m,
                            visible.predicted_positions(times), reach, self.n_slots,
                            self.settings, obs.frame,
                            self.preview(state, applied)[0] if sided else None)

    def step(self, obs: Observation) -> ControlStep:
        """One closed-loop step as :meth:`KinematicTrack.step
        <pipeline.loop.controller.kinematic.KinematicTrack.step>` takes it, the nominal input
        filtered before it is applied (the rate penalty's previous input and the prediction
        record are the applied ones)."""
        nominal = self.nominal
        reference = nominal.reference(obs)
        predicted_obstacles = obs.obstacles.predicted_positions(self._steps_ahead_s)
        ref_line = obs.frame.to_line(reference[:, 0])
        u_prev = nominal.u_prev
        state = np.asarray(obs.plant_state, dtype=float)
        nominal_step = nominal.solve(state, u_prev, reference, predicted_obstacles,
                                     obs.obstacles.radii_m,
                                     log={"y_ref_m": ref_line[1], "psi_ref_rad": np.nan})
        started = time.perf_counter()
        u_nom = np.asarray(nominal_step.command, dtype=float)
        rows = self.rows(obs, u_nom)
        result = self.filter.apply(u_nom, rows, started)
        changed = result.active and not result.failed
        columns = _log_columns(result, rows, {
            "cbf_correction_accel_mps2": float(result.command[0] - u_nom[0]) if changed
            else 0.0,
            "cbf_correction_delta_rad": float(result.command[1] - u_nom[1]) if changed
            else 0.0})
        step = _filtered_step(nominal_step, result, columns,
                              lambda plan: nominal.rollout(state, plan))
        if changed and step.fallback == "none":
            nominal.fallback.accept(step.planned)
        step.log["steering_rate_rad_s"] = (step.command[1] - u_prev[1]) / self.ts
        step.log["accel_mps2"] = step.command[0]
        nominal.u_prev = step.command
        nominal.records.append((state.copy(), step.predicted_states
                                if step.fallback == "none" else None))
        return step

    def model_check(self, log: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """The nominal MPC's prediction check (:meth:`KinematicTrack.model_check
        <pipeline.loop.controller.kinematic.KinematicTrack.model_check>`)."""
        return self.nominal.model_check(log)

    def horizon_view(self, rows: int) -> dict[str, np.ndarray]:
        """The nominal MPC's plan and half-planes (the report's scenario explorer)."""
        return self.nominal.horizon_view(rows)
