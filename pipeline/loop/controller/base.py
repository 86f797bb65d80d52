"""What every controller shares: the observation it is given, the step it returns, and the
fallback it takes when its optimizer fails (written once, here).

The closed loop is do-mpc's ``u = controller.step(observation); x = plant.step(x, u)`` for every
controller (lateral MPC, kinematic LTV-MPC, pure pursuit).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from pipeline.loop.planner import ApfRollout
from pipeline.loop.scenario import LineFrame, ObstacleSnapshot


@dataclass(frozen=True)
class Observation:
    """What a controller sees at one step.

    Attributes
    ----------
    time_s : float
    plant_state : ndarray
        The plant's state (layout of the plant in use).
    frame : LineFrame
        Start-to-goal line frame.
    position_line_m : ndarray, shape (2,)
        Vehicle position in the line frame.
    heading_line_rad : float
        Heading relative to the line.
    rollout : ApfRollout
        The APF's reference path (global frame).
    obstacles : ObstacleSnapshot
        Visible obstacles only.
    speed_ref_mps : float
        Planned speed (the lateral model is built at this speed).
    road_polygons_m : tuple of ndarray
        The road (:mod:`pipeline.loop.controller.road`); empty where the scenario has none.
    """

    time_s: float
    plant_state: np.ndarray
    frame: LineFrame
    position_line_m: np.ndarray
    heading_line_rad: float
    rollout: ApfRollout
    obstacles: ObstacleSnapshot
    speed_ref_mps: float
    #: the road as polygons (a scenario's ``road_polygons_m``; empty: none), for the lateral
    #: MPC's road-edge rows (``controller.road_edge_weight``)
    road_polygons_m: tuple[np.ndarray, ...] = ()


@dataclass(frozen=True)
class ControlStep:
    """Result of one controller step (the same type for every controller).

    Attributes
    ----------
    command : ndarray, shape (n_u,)
        Input applied now (lateral: ``[steering rate rad/s]``; kinematic: ``[a m/s^2, delta rad]``).
    planned : ndarray, shape (n_u, N)
        Input sequence of the plan that was applied (after fallback, if any).
    predicted_states : ndarray or None
    status : str
        Solver status, ``not_solved`` when the state was not finite, ``pure_pursuit`` for the
        peer without optimizer.
    iterations : int
    solve_time_s : float
        Wall time of the QP data update and solve (s).
    fallback : str
        ``none``, ``shifted_plan`` or ``safe_input``.
    max_slack_m : float
    log : dict
        Controller-specific log columns (references, LTV passes, ...).
    """

    command: np.ndarray
    planned: np.ndarray
    predicted_states: np.ndarray | None
    status: str
    iterations: int
    solve_time_s: float
    fallback: str
    max_slack_m: float
    log: dict[str, Any] = field(default_factory=dict)

    @property
    def steering_rate_rad_s(self) -> float:
        """First input of a lateral controller (rad/s)."""
        return float(self.command[0])

    @property
    def planned_rates_rad_s(self) -> np.ndarray:
        """Planned input sequence of a lateral controller, shape (N,)."""
        return self.planned[0]


class Controller(Protocol):
    """Anything the closed loop can drive."""

    compile_count: int
    compile_time_s: float

    def step(self, observation: Observation) -> ControlStep: ...


class PlanFallback:
    """The fallback every optimizing controller takes: the previous plan shifted by one step
    while it lasts, then a bounded safe input.

    Parameters
    ----------
    horizon : int
    """

    def __init__(self, horizon: int) -> None:
        self.horizon = horizon
        self.last_plan: np.ndarray | None = None
        self.age = 0

    def accept(self, plan: np.ndarray) -> None:
        """Remember a plan that was solved and applied."""
        self.last_plan, self.age = plan, 0

    def step(self, status: str, iterations: int, solve_time_s: float,
             safe_input: Callable[[], np.ndarray], log: dict[str, Any] | None = None) -> ControlStep:
        """The fallback step after a failed solve (``status`` says why)."""
        if self.last_plan is not None and self.age + 1 < self.horizon:
            self.age += 1
            plan = self.last_plan
            shifted = np.concatenate([plan[:, self.age:],
                                      np.repeat(plan[:, -1:], self.age, axis=1)], axis=1)
            return ControlStep(shifted[:, 0].copy(), shifted, None, status, iterations,
                               solve_time_s, "shifted_plan", float("nan"), log or {})
        safe = np.asarray(safe_input(), dtype=float)
        return ControlStep(safe, np.repeat(safe[:, None], self.horizon, axis=1), None, status,
                           iterations, solve_time_s, "safe_input", float("nan"), log or {})
