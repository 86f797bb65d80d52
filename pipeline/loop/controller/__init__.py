"""Controller stage: every controller behind one ``step(observation) -> ControlStep``.

* :mod:`~pipeline.loop.controller.qp`: QP plumbing (compile once, affine parameter-to-data map,
  kept Clarabel solver, CVXPY reference backend, the cache of compiled structures);
* :mod:`~pipeline.loop.controller.base`: observation, result type, the fallback written once;
* :mod:`~pipeline.loop.controller.references`: APF path to references and half-planes;
* :mod:`~pipeline.loop.controller.lateral`: the paper's lateral MPC, its QP
  (:mod:`~pipeline.loop.controller.lateral_qp`, :mod:`~pipeline.loop.controller.lateral_backends`),
  its frames (:mod:`~pipeline.loop.controller.frames`, :mod:`~pipeline.loop.controller.path`) and
  its prediction check (:mod:`~pipeline.loop.controller.prediction_check`);
* :mod:`~pipeline.loop.controller.kinematic`: Appendix A's kinematic LTV-MPC;
* :mod:`~pipeline.loop.controller.nmpc`: Appendix A's ``nlmpc`` as a nonlinear MPC (CasADi);
* :mod:`~pipeline.loop.controller.lateral_nmpc`: the lateral MPC's problem on the nonlinear
  single-track model (CasADi), the check of its linearization;
* :mod:`~pipeline.loop.controller.pursuit`: the pure-pursuit peer.

:func:`make_controller` picks one from the configuration.
"""

from __future__ import annotations

from pipeline.loop.controller.base import Controller, ControlStep, Observation, PlanFallback
from pipeline.loop.controller.kinematic import KinematicLtvMpc
from pipeline.loop.controller.lateral import LateralMpc
from pipeline.loop.controller.lateral_qp import MpcInputs, blocking_matrix
from pipeline.loop.controller.pursuit import PurePursuit, pure_pursuit_steering_rate
from pipeline.loop.controller.qp import OPTIMAL_STATUSES, QpCache, QpSolution
from pipeline.loop.controller.references import (
    collision_halfplanes,
    force_heading_reference,
    kinematic_halfplanes,
    lateral_reference,
)
from pipeline.loop.controller_settings import Backend, KinematicMpcSettings, PurePursuitSettings
from pipeline.loop.kernels import Kernels
from pipeline.loop.settings import LoopSettings

__all__ = ["ControlStep", "Controller", "Observation", "PlanFallback", "KinematicLtvMpc",
           "LateralMpc", "MpcInputs", "blocking_matrix", "PurePursuit",
           "pure_pursuit_steering_rate", "OPTIMAL_STATUSES", "QpCache", "QpSolution",
           "collision_halfplanes", "force_heading_reference", "kinematic_halfplanes",
           "lateral_reference", "make_controller"]


def make_controller(cfg: LoopSettings, sample_time_s: float,
                    qp_cache: QpCache | None = None, kernels: Kernels | None = None
                    ) -> Controller:
    """The controller ``cfg.controller._target_`` names (a user's class, built with its
    kind's settings), else the built-in named by ``cfg.controller.kind``, built with the
    settings of its kind (:mod:`pipeline.loop.controller_settings`), its QP taken from
    ``qp_cache``, its innermost arithmetic run by ``kernels`` (CPython's when omitted)."""
    if cfg.controller._target_:
        # a controller of your own: step(Observation) -> ControlStep (see base.Controller)
        from pipeline.validation import build_target

        return build_target("controller._target_", cfg.controller._target_,
                            (cfg.controller, cfg.vehicle, sample_time_s, qp_cache),
                            "Controller(settings, vehicle, sample_time_s, qp_cache)")
    settings = cfg.controller
    if isinstance(settings, KinematicMpcSettings):
        if settings.backend == Backend.NMPC:
            from pipeline.loop.controller.nmpc import KinematicNmpc

            return KinematicNmpc(settings, cfg.vehicle, sample_time_s, qp_cache)
        return KinematicLtvMpc(settings, cfg.vehicle, sample_time_s, qp_cache)
    if isinstance(settings, PurePursuitSettings):
        # (pure pursuit has no backend: no nonlinear program without a model)
        return PurePursuit(settings, cfg.vehicle, sample_time_s, cfg.model.speed_grid_mps)
    if settings.backend == Backend.NMPC:
        from pipeline.loop.controller.lateral_nmpc import LateralNmpc

        return LateralNmpc(settings, cfg.vehicle, cfg.model, sample_time_s, qp_cache, kernels)
    return LateralMpc(settings, cfg.vehicle, cfg.model, sample_time_s, qp_cache, kernels)
