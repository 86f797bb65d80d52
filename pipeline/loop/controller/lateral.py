"""The lateral MPC (paper Section 3): one step's data in its frame, a QP compiled once per
structure, the fallback.

``controller.frame`` says what the state is measured against
(:mod:`~pipeline.loop.controller.frames`): ``path`` (the default), the offset and heading error
from a drivable path built from the APF rollout each step, the path's curvature previewed as
the disturbance ``r_d`` and the references the model's equilibrium on it; ``fixed``, the
position and heading against the start-goal line (the earlier reading). Both hand the same QP
(:mod:`~pipeline.loop.controller.lateral_qp`) other data; ``controller.backend`` solves it
(:mod:`~pipeline.loop.controller.lateral_backends`). A failed solve never raises: the
controller takes :class:`~pipeline.loop.controller.base.PlanFallback`. Each step's prediction is
kept and checked against the plant after the run
(:mod:`~pipeline.loop.controller.prediction_check`).
"""

from __future__ import annotations

import functools
from dataclasses import replace
from math import isfinite
from typing import Any

import numpy as np

from pipeline.loop.controller.base import ControlStep, Observation, PlanFallback
from pipeline.loop.controller.frames import ModelBank, make_frame
from pipeline.loop.controller.lateral_backends import (
    CompiledCondensedQp,
    DaqpCondensedQp,
    LateralQp,
)
from pipeline.loop.controller.lateral_qp import (
    CondensedPrediction,
    LateralQpStructure,
    MpcInputs,
    blocking_matrix,
    build_condensed_lateral_problem,
    condensed_data,
    friction_steering_bound_rad,
    slots_used,
    steering_bounds_from,
)
from pipeline.loop.controller.prediction_check import PredictionRecord, prediction_check
from pipeline.loop.controller.qp import QpCache, QpSolution, compiled_backend
from pipeline.loop.controller_settings import MpcSettings, settings_of
from pipeline.loop.horizon import lateral_horizon_view
from pipeline.loop.kernels import Kernels
from pipeline.loop.model import LateralModel, vehicle_key
from pipeline.loop.settings import ModelConfig, VehicleConfig

__all__ = ["LateralMpc", "LateralQpStructure", "MpcInputs", "blocking_matrix",
           "condensed_data"]


class LateralMpc:
    """The lateral MPC: its frame, one compiled QP (from ``qp_cache``), a kept solver, the
    fallback.

    Parameters
    ----------
    controller : MpcSettings
        Its settings (its kind's schema, as composed).
    vehicle : VehicleConfig
    model : ModelConfig
        The lateral model's settings (B2 entry, speed grid).
    sample_time_s : float
    qp_cache : QpCache, optional
        Compiled problems shared across runs; a private one when omitted.
    kernels : Kernels, optional
        The loop's kernels (:mod:`pipeline.loop.kernels`); CPython's when omitted.

    Attributes
    ----------
    compile_count : int
        Compilations this controller caused (0 when the cache already held its structure).
    compile_time_s : float
    records : list of PredictionRecord
        What each step predicted with (:meth:`model_check`).
    qp_by_slots : dict
        The QP by its number of obstacle slots (:meth:`qp_for`): one statement for each count
        up to ``max_obstacles`` (its ``qp`` the largest; on DAQP each with its kept
        workspace).
    """

    def __init__(self, controller: MpcSettings, vehicle: VehicleConfig,
                 model: ModelConfig | None = None, sample_time_s: float = 0.1,
                 qp_cache: QpCache | None = None, kernels: Kernels | None = None) -> None:
        controller = settings_of(controller, MpcSettings)
        if kernels is None:
            from pipeline.loop.python_kernels import PYTHON_KERNELS

            kernels = PYTHON_KERNELS
        self.cfg, self.vehicle, self.kernels = controller, vehicle, kernels
        self.model_cfg = model if model is not None else ModelConfig()
        self.horizon = controller.horizon
        self.sample_time_s = float(sample_time_s)
        self.blocking = blocking_matrix(controller.horizon, controller.control_horizon,
                                        controller.input_hold)
        self.bank = ModelBank(vehicle, self.model_cfg, self.sample_time_s, qp_cache)
        self.models = self.bank.models
        self.frame = make_frame(controller, vehicle, self.bank, kernels)
        structure = LateralQpStructure.of(controller, vehicle)
        self.weights = structure.weights
        self.qp: LateralQp
        #: the QP by its number of obstacle slots (qp_for): a step whose half-planes fill
        #: fewer slots solves the smallest statement that holds them (slots_used; most steps
        #: have no obstacle within reach and solve the 3-variable QP: on Clarabel about a
        #: third of the 33-variable one's time, on DAQP a fifth)
        self.qp_by_slots: dict[int, LateralQp] = {}
        if controller.backend == "daqp":
            # no compilation: the condensed data go to the solver as numpy matrices; one kept
            # workspace per statement
            self.qp_by_slots = {
                slots: DaqpCondensedQp(replace(structure, max_obstacles=slots),
                                       controller.solver_max_iter)
                for slots in range(structure.max_obstacles + 1)}
            self.qp = self.qp_by_slots[structure.max_obstacles]
            self.compile_count, self.compile_time_s = 0, 0.0
        else:
            compiled, self.compile_count, self.compile_time_s = compiled_backend(
                qp_cache, "lateral", structure,
                lambda: build_condensed_lateral_problem(structure), controller.backend,
                controller.solver_max_iter, controller.solver_refinement)
            self.qp = CompiledCondensedQp(compiled)
        # every size compiled here, through the shared cache: a family's workers get them
        # with it and compile nothing; about 20 ms each
        if isinstance(self.qp, CompiledCondensedQp):
            self.qp_by_slots[structure.max_obstacles] = self.qp
            for slots in range(structure.max_obstacles):
                smaller = replace(structure, max_obstacles=slots)
                compiled, count, seconds = compiled_backend(
                    qp_cache, "lateral", smaller,
                    functools.partial(build_condensed_lateral_problem, smaller),
                    controller.backend, controller.solver_max_iter,
                    controller.solver_refinement)
                self.compile_count += count
                self.compile_time_s += seconds
                self.qp_by_slots[slots] = CompiledCondensedQp(compiled, slots)
        # condensed predictions by model, shared like the models (built once per speed, step)
        key = ("lateral_predictions", vehicle_key(vehicle), self.sample_time_s,
               self.model_cfg.b2_heading_entry, self.model_cfg.speed_grid_mps,
               controller.horizon, controller.control_horizon, controller.input_hold,
               self.weights.tracking, controller.steering_friction_share)
        self._predictions: dict[tuple[Any, ...], CondensedPrediction] = \
            qp_cache.memo(key, dict) if qp_cache is not None else {}
        self.fallback = PlanFallback(controller.horizon)
        self.records: list[PredictionRecord] = []

    def prediction(self, model: LateralModel) -> CondensedPrediction:
        """The condensed prediction of ``model`` (built once per model: speed and step)."""
        key = (model.speed_mps, model.sample_time_s)
        entry = self._predictions.get(key)
        if entry is None or entry.model is not model:
            share = self.cfg.steering_friction_share
            bound = None if share is None \
                else friction_steering_bound_rad(self.vehicle, share, model.speed_mps)
            entry = self._predictions[key] = CondensedPrediction.of(
                model, self.blocking, self.weights.tracking, self.vehicle.steering_max_rad,
                bound)
        return entry

    def solve(self, inputs: MpcInputs, log: dict[str, Any] | None = None) -> ControlStep:
        """Solve the QP for one step's data, falling back safely on any failure."""
        solution = QpSolution("not_solved", -1, 0.0, None)
        data = None
        if isfinite(sum(inputs.x0.tolist())):  # inf or nan anywhere makes the sum non-finite
            prediction = self.prediction(inputs.model)
            data = condensed_data(prediction, inputs, self.weights)
            if prediction.steering_bound_rad is not None:
                # the steering now beyond the friction bound: it may come down at its rate
                bounds = steering_bounds_from(
                    prediction.steering_bound_rad, float(inputs.x0[4]),
                    self.vehicle.steering_rate_max_rad_s, inputs.model.sample_time_s,
                    self.horizon)
                if bounds is not None:
                    data = replace(data, steering_bounds_rad=bounds)
            solution = self.qp_for(inputs).solve(data)
        if solution.ok and data is not None:
            U = solution.value("U").reshape(-1)
            plan = U @ self.blocking
            if isfinite(sum(plan.tolist())):
                # the eliminated states, for the log and the slack: X = free + Gamma U
                predicted = data.free + data.prediction.gamma @ U
                states = np.concatenate([inputs.x0[:, None], predicted.T], axis=1)
                # slack needed by the optimal plan (what the QP's slack variable holds); rows
                # of idle slots and far obstacles are 0 y + s >= 0 and need none
                slack = 0.0
                slots = self.cfg.max_obstacles  # the obstacles' (the road's after them)
                gain, bound = inputs.constraint_gain[:, :slots], inputs.constraint_bound[:, :slots]
                if np.count_nonzero(gain) or np.count_nonzero(bound):
                    lateral = states[0, 1:][:, None]
                    slack = (bound - gain * lateral).max()
                return self.accepted(plan, states, solution, slack, log)
        return self.fall_back(inputs, solution, log)

    def qp_for(self, inputs: MpcInputs) -> LateralQp:
        """The QP of the fewest obstacle slots that holds every half-plane of ``inputs``
        (:func:`~pipeline.loop.controller.lateral_qp.slots_used`)."""
        return self.qp_by_slots[slots_used(inputs.constraint_gain, inputs.constraint_bound)]

    def accepted(self, plan: np.ndarray, states: np.ndarray, solution: QpSolution,
                 slack: float, log: dict[str, Any] | None) -> ControlStep:
        """The step of a solved QP: its plan (``U`` blocked, shape (N,)), the predicted
        states (5, N + 1) and the slack the plan needs."""
        plan = plan[None, :]
        self.fallback.accept(plan)
        return ControlStep(plan[:, 0].copy(), plan, states, solution.status,
                           solution.iterations, solution.solve_time_s, "none",
                           float(max(slack, 0.0)), log or {})

    def fall_back(self, inputs: MpcInputs, solution: QpSolution,
                  log: dict[str, Any] | None) -> ControlStep:
        """The step of a failed solve (:class:`~pipeline.loop.controller.base.PlanFallback`)."""
        delta = inputs.x0[4] if np.isfinite(inputs.x0[4]) else 0.0
        rate_max = self.vehicle.steering_rate_max_rad_s
        ts = self.sample_time_s
        return self.fallback.step(
            solution.status, solution.iterations, solution.solve_time_s,
            lambda: np.array([float(np.clip(-delta / ts, -rate_max, rate_max))]), log)

    def inputs_from(self, obs: Observation) -> tuple[MpcInputs, dict[str, Any]]:
        """The QP data of one observation in the configured frame (``controller.frame``)."""
        return self.frame.inputs(obs)

    def step(self, obs: Observation) -> ControlStep:
        """One closed-loop step (its prediction kept for :meth:`model_check`)."""
        inputs, log = self.frame.inputs(obs)
        step = self.solve(inputs, log)
        self.frame.after_step(step)
        self.keep_record(inputs, step.predicted_states[0] if step.predicted_states is not None
                         and step.fallback == "none" else None)
        return step

    def keep_record(self, inputs: MpcInputs, plan_lateral_m: np.ndarray | None) -> None:
        """Keep what this step predicted with (its frame, state, model at the log's sample
        time, previewed ``r_d``, plan) for :meth:`model_check`."""
        model = inputs.model if inputs.model.sample_time_s == self.sample_time_s \
            else self.models.at_speed(inputs.model.speed_mps)  # the replay's, at the log's rate
        self.records.append(PredictionRecord(self.frame.record, inputs.x0, model,
                                             inputs.disturbance_rad_s, plan_lateral_m,
                                             inputs.constraint_gain, inputs.constraint_bound,
                                             self.frame.plan_xy_m if plan_lateral_m is not None
                                             else None))

    def horizon_view(self, rows: int) -> dict[str, np.ndarray]:
        """Each step's plan and half-planes in the global frame, one row per log row (the
        report's scenario explorer; :func:`~pipeline.loop.horizon.lateral_horizon_view`)."""
        return lateral_horizon_view(self.records, rows, self.horizon, self.cfg.max_obstacles)

    def model_check(self, log: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """How well each step's prediction held (:func:`prediction_check`), one value per row
        of the run's log (``log``: its columns)."""
        plant = np.column_stack([log[name] for name in ("X_m", "Y_m", "psi_rad", "delta_rad")])
        kernel = self.kernels.check_record if self.kernels.compiled else None
        return prediction_check(self.records, log["time_s"], plant, self.sample_time_s, kernel)
