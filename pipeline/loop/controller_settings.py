"""Each controller kind's schema: the settings Hydra composes, checks and hashes, and the
built-in controller of that kind is handed (do-mpc's per-controller settings classes).

``controller.kind`` names the kind, and each kind has its own schema with only the keys its
controller reads: :class:`MpcSettings` (the lateral MPC, ``kind=mpc``;
``conf/controller/lateral_mpc.yaml``), :class:`PurePursuitSettings` (``kind=pure_pursuit``;
``conf/controller/pure_pursuit.yaml``) and :class:`KinematicMpcSettings` (Appendix A's
kinematic MPC, ``kind=kinematic_mpc``; ``conf/controller/kinematic.yaml``). A key of another
kind is refused naming the key and the kind's keys (it used to be carried along, unread, and
entered the run's hash). The choices are words checked against the enums below (string enums:
a member equals its word, ``Frame.PATH == "path"``). :data:`ControllerConfig` is the union of
the three, :func:`controller_schema` the schema of a kind.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import StrEnum
from typing import Any, ClassVar, Dict, List, NamedTuple, Optional, TypeVar

from omegaconf import MISSING

from pipeline.errors import ConfigError
from pipeline.loop.qp_memory import MAX_HORIZON, qp_memory_gib
from pipeline.validation import (
    FrozenAfterValidation,
    at_least,
    between,
    choice,
    flag,
    integer_in,
    pair,
    safe_name,
    target_path,
)


class ControllerKind(StrEnum):
    """``controller.kind``: which controller closes the loop."""

    MPC = "mpc"
    PURE_PURSUIT = "pure_pursuit"
    KINEMATIC_MPC = "kinematic_mpc"


class Backend(StrEnum):
    """``controller.backend``: what solves the MPC's problem."""

    CVXPY = "cvxpy"
    CLARABEL_DIRECT = "clarabel_direct"
    DAQP = "daqp"
    NMPC = "nmpc"


class Formulation(StrEnum):
    """``controller.formulation``: how the lateral QP is stated; one value since the sparse
    statement (the states as variables) was removed, no experiment used it (issue 58). The key
    stays: it is part of every run's settings and of its config hash."""

    CONDENSED = "condensed"


class InputHold(StrEnum):
    """``controller.input_hold``: the input after the control horizon."""

    HOLD_LAST = "hold_last"
    ZERO_RATE = "zero_rate"


class HalfplaneNormal(StrEnum):
    """``controller.halfplane_normal``: the lateral MPC's obstacle half-planes."""

    LATERAL_SIDE = "lateral_side"
    RADIAL = "radial"


class HeadingReference(StrEnum):
    """``controller.heading_reference``: the lateral MPC's heading reference."""

    PATH_SLOPE = "path_slope"
    APF_FORCE = "apf_force"


class PathBeyondEnd(StrEnum):
    """``controller.path_beyond_end``: the APF path past its last point."""

    EXTEND = "extend"
    HOLD = "hold"


class Frame(StrEnum):
    """``controller.frame``: what the lateral MPC's state is measured against."""

    PATH = "path"
    FIXED = "fixed"


class PathReference(StrEnum):
    """``controller.path_reference``: which path the path frame measures the state against."""

    ROLLOUT = "rollout"
    PURSUIT = "pursuit"


class PathStateReference(StrEnum):
    """``controller.path_state_reference``: the path frame's state references."""

    STEADY_STATE = "steady_state"
    ZERO = "zero"


class ReferenceAlignment(StrEnum):
    """``controller.reference_alignment``: the kinematic MPC's position reference."""

    LITERAL = "literal"
    SHIFTED = "shifted"
    PATH_SPEED = "path_speed"


#: Choice values that were removed, with why (issue 58: no experiment used them), so that a
#: configuration that still names one is told so in its refusal.
REMOVED_CHOICES: dict[str, dict[str, str]] = {
    "controller.backend": {"clarabel_dense": "no experiment used it; clarabel_direct and daqp "
                                             "solve the same condensed QP"},
    "controller.formulation": {"sparse": "no experiment used it; condensed is the same QP "
                                         "with the states eliminated"}}

#: The choice fields of ``ControllerConfig`` and their enums.
CHOICES: dict[str, type[StrEnum]] = {
    "kind": ControllerKind, "backend": Backend, "formulation": Formulation,
    "input_hold": InputHold, "halfplane_normal": HalfplaneNormal,
    "heading_reference": HeadingReference, "path_beyond_end": PathBeyondEnd, "frame": Frame,
    "path_reference": PathReference, "path_state_reference": PathStateReference, "reference_alignment": ReferenceAlignment}



@dataclass
class _ControllerSchema(FrozenAfterValidation):
    """What every kind's schema has: its name, its kind, and a controller of one's own.

    ``_target_`` (Hydra's convention) names a class ``module.Class`` built with (these
    settings, the vehicle, the sample time, the QP cache) and stepped as
    ``step(Observation) -> ControlStep``, on this kind's track; ``params`` are its own
    settings. Both enter the run hash only when set."""

    kind_word: ClassVar[ControllerKind]
    kind_file: ClassVar[str]  # its file in conf/controller/ (what a refusal points to)

    name: str = MISSING
    kind: str = "mpc"
    _target_: Optional[str] = None
    params: Dict[str, Any] = field(default_factory=dict)

    def _check_common(self) -> None:
        """The name, the kind (this schema's), the plug-in's path and the horizon (every kind
        has one: pure pursuit logs its references over it)."""
        target_path("controller._target_", self._target_)
        choice("controller.kind", self.kind, tuple(ControllerKind))
        if self.kind != self.kind_word:
            raise ConfigError("controller.kind", self.kind,
                              f"{self.kind_word} in {type(self).__name__} (another kind is "
                              f"another schema: controller="
                              f"{KIND_SETTINGS[ControllerKind(self.kind)].kind_file})")
        safe_name("controller.name", self.name)
        horizon = self.horizon  # type: ignore[attr-defined]  # every kind has one
        memory = ""
        if isinstance(horizon, int) and horizon > MAX_HORIZON:
            slots = getattr(self, "max_obstacles", 1)
            memory = (f" (the compiled QP grows with N: N = {horizon} would need about "
                      f"{qp_memory_gib(horizon, slots):.3g} GiB)")
        integer_in("controller.horizon", horizon, 1, MAX_HORIZON,
                   f"an integer in [1, {MAX_HORIZON}]{memory}")


@dataclass
class _MpcSchema(_ControllerSchema):
    """What both MPC kinds have: the QP backend, horizons and move blocking, obstacle slots and
    their soft collision half-planes, the solver's iteration limit."""

    backend: str = "clarabel_direct"
    horizon: int = 10
    control_horizon: int = 3
    input_hold: str = "hold_last"
    max_obstacles: int = 3
    slack_weight_linear: float = 1.0e4
    slack_weight_quadratic: float = 1.0e3
    safety_margin_m: float = 0.2
    constraint_activation_m: float = 12.0
    # the MPC's soft collision half-planes (every backend, both tracks); false: none, so what
    # avoids the obstacle is the reference alone ("APF by itself", make reproduce)
    collision_constraints: bool = True
    solver_max_iter: int = 200
    # Clarabel's iterative refinement of each KKT solve (its default, on); off: about a third
    # cheaper per QP and no less accurate at the optimum, but a run's last digits change and
    # a chaotic run carries them on (docs/performance.md); clarabel_direct and cvxpy only
    solver_refinement: bool = True

    def _check_mpc(self) -> None:
        """The common checks; the control horizon, slots and iterations; the backend and which
        kinds it goes with; the half-planes' weights, margin, reach and switch; the input
        hold."""
        self._check_common()
        integer_in("controller.control_horizon", self.control_horizon, 1, self.horizon,
                   f"an integer in [1, controller.horizon={self.horizon}]")
        integer_in("controller.max_obstacles", self.max_obstacles, 1, 50)
        integer_in("controller.solver_max_iter", self.solver_max_iter, 1, 100000)
        choice("controller.backend", self.backend, tuple(Backend),
               REMOVED_CHOICES["controller.backend"])
        if self.backend == "daqp" and self.kind_word != ControllerKind.MPC:
            raise ConfigError("controller.backend", self.backend,
                              "daqp only with controller.kind=mpc (else cvxpy or clarabel_direct)")
        for key in ("slack_weight_linear", "slack_weight_quadratic", "safety_margin_m",
                    "constraint_activation_m"):
            at_least(f"controller.{key}", getattr(self, key), 0.0)
        flag("controller.collision_constraints", self.collision_constraints)
        flag("controller.solver_refinement", self.solver_refinement)
        if self.backend == "daqp" and self.solver_refinement is not True:
            raise ConfigError("controller.solver_refinement", self.solver_refinement,
                              "true with controller.backend=daqp (Clarabel's refinement; "
                              "false only with clarabel_direct or cvxpy)")
        choice("controller.input_hold", self.input_hold, tuple(InputHold))


@dataclass
class MpcSettings(_MpcSchema):
    """The lateral MPC's schema (:class:`~pipeline.loop.controller.lateral.LateralMpc`, on
    the nonlinear model :class:`~pipeline.loop.controller.lateral_nmpc.LateralNmpc`;
    ``conf/controller/lateral_mpc.yaml`` says what each key means)."""

    kind_word: ClassVar[ControllerKind] = ControllerKind.MPC
    kind_file: ClassVar[str] = "lateral_mpc"

    kind: str = "mpc"
    # one value (the sparse statement was removed, issue 58); kept: it is in every run's
    # settings and config hash
    formulation: str = "condensed"
    q_lateral: float = 10.0
    q_heading: float = 5.0
    q_yaw_rate: float = 0.1
    q_steering: float = 0.5
    r_steering_rate: float = 1.0
    halfplane_normal: str = "lateral_side"
    heading_reference: str = "path_slope"
    heading_ref_max_rad: float = 0.5
    yaw_rate_ref_max_rad_s: float = 0.6
    path_beyond_end: str = "extend"
    # what the lateral MPC's state is measured against: the drivable path built from the APF
    # rollout each step (path), or the start-goal line (fixed, the earlier reading)
    frame: str = "path"
    # the path the path frame measures against: the APF rollout itself, each point at the time
    # the vehicle reaches it (rollout, Section 3.1's y_ref), or a pure-pursuit chase of it from
    # the vehicle at path_lookahead_m, its curvature clipped at the vehicle's limit when
    # path_curvature_clip (pursuit: a reading of ours, not the paper's)
    path_reference: str = "rollout"
    path_lookahead_m: float = 2.5
    path_curvature_clip: bool = True
    path_curvature_max_1_per_m: Optional[float] = None  # None: tan(steering_max) / wheelbase
    path_state_reference: str = "steady_state"
    horizon_reach_m: Optional[float] = 3.0
    nmpc_substeps: int = 5
    # the road's edges as two more soft half-planes per step (path frame; a scenario with a
    # road: Euro NCAP, CommonRoad), their rows scaled by this factor against the collision
    # half-planes' slack weights; null: no road in the MPC (the paper's scenario has none)
    road_edge_weight: Optional[float] = None
    # the steering bound at road speeds (a choice we add): each step's bound is the smaller of
    # vehicle.steering_max_rad and the steering at which a kinematic single-track at the
    # model's speed reaches this share of the tyres' friction (v^2 tan(delta) / L = share mu g);
    # null: vehicle.steering_max_rad at every speed (the paper's; no effect below about 7 m/s
    # at a share of 1 on the compact car)
    steering_friction_share: Optional[float] = None

    def __post_init__(self) -> None:
        self._check_mpc()
        integer_in("controller.nmpc_substeps", self.nmpc_substeps, 1, 100)
        choice("controller.formulation", self.formulation, tuple(Formulation),
               REMOVED_CHOICES["controller.formulation"])
        choice("controller.halfplane_normal", self.halfplane_normal, tuple(HalfplaneNormal))
        for key in ("q_lateral", "q_heading", "q_yaw_rate", "q_steering", "r_steering_rate"):
            at_least(f"controller.{key}", getattr(self, key), 0.0)
        at_least("controller.r_steering_rate", self.r_steering_rate, 0.0, inclusive=False)
        choice("controller.heading_reference", self.heading_reference, tuple(HeadingReference))
        between("controller.heading_ref_max_rad", self.heading_ref_max_rad, 0.0, math.pi / 2)
        at_least("controller.yaw_rate_ref_max_rad_s", self.yaw_rate_ref_max_rad_s, 0.0,
                  inclusive=False)
        choice("controller.path_beyond_end", self.path_beyond_end, tuple(PathBeyondEnd))
        choice("controller.frame", self.frame, tuple(Frame))
        choice("controller.path_reference", self.path_reference, tuple(PathReference))
        between("controller.path_lookahead_m", self.path_lookahead_m, 0.1, 100.0)
        flag("controller.path_curvature_clip", self.path_curvature_clip)
        if self.path_curvature_max_1_per_m is not None:
            between("controller.path_curvature_max_1_per_m", self.path_curvature_max_1_per_m,
                    1e-3, 10.0)
        choice("controller.path_state_reference", self.path_state_reference,
               tuple(PathStateReference))
        if self.horizon_reach_m is not None:
            between("controller.horizon_reach_m", self.horizon_reach_m, 0.1, 1000.0)
        if self.road_edge_weight is not None:
            between("controller.road_edge_weight", self.road_edge_weight, 1e-3, 1e3)
            if self.frame != "path":
                raise ConfigError("controller.road_edge_weight", self.road_edge_weight,
                                  "null with controller.frame=fixed (the road's rows are "
                                  "stated in the path frame)")
            if self._target_:
                raise ConfigError("controller.road_edge_weight", self.road_edge_weight,
                                  "null with a controller of one's own (controller._target_ "
                                  f"{self._target_}: its QP has no road rows)")
            if self.backend == "nmpc":
                raise ConfigError("controller.road_edge_weight", self.road_edge_weight,
                                  "null with controller.backend=nmpc (the nonlinear MPC has "
                                  "no road rows)")
        if self.steering_friction_share is not None:
            between("controller.steering_friction_share", self.steering_friction_share,
                    0.05, 1.0)
            if self._target_:
                raise ConfigError("controller.steering_friction_share",
                                  self.steering_friction_share,
                                  "null with a controller of one's own (controller._target_ "
                                  f"{self._target_}: its QP is its own)")
            if self.backend == "nmpc":
                raise ConfigError("controller.steering_friction_share",
                                  self.steering_friction_share,
                                  "null with controller.backend=nmpc (the nonlinear MPC's "
                                  "tyres have the friction limit themselves)")

    @property
    def road_slots(self) -> int:
        """Half-plane slots the road's edges take beyond the obstacles' (2 with
        ``road_edge_weight``, else 0)."""
        return 2 if self.road_edge_weight is not None else 0

    @property
    def weights(self) -> LateralWeights:
        """The cost weights by name (:class:`LateralWeights`, a named tuple numba takes)."""
        return LateralWeights.of(self)


@dataclass
class PurePursuitSettings(_ControllerSchema):
    """Pure pursuit's schema (:class:`~pipeline.loop.controller.pursuit.PurePursuit`): the
    look-ahead, and the horizon and references it logs as an MPC would
    (``conf/controller/pure_pursuit.yaml``)."""

    kind_word: ClassVar[ControllerKind] = ControllerKind.PURE_PURSUIT
    kind_file: ClassVar[str] = "pure_pursuit"

    kind: str = "pure_pursuit"
    horizon: int = 10
    lookahead_min_m: float = 2.0
    lookahead_time_s: float = 0.8
    heading_ref_max_rad: float = 0.5
    path_beyond_end: str = "extend"

    def __post_init__(self) -> None:
        self._check_common()
        at_least("controller.lookahead_min_m", self.lookahead_min_m, 0.0, inclusive=False)
        at_least("controller.lookahead_time_s", self.lookahead_time_s, 0.0)
        between("controller.heading_ref_max_rad", self.heading_ref_max_rad, 0.0, math.pi / 2)
        choice("controller.path_beyond_end", self.path_beyond_end, tuple(PathBeyondEnd))


@dataclass
class KinematicMpcSettings(_MpcSchema):
    """Appendix A's kinematic MPC's schema
    (:class:`~pipeline.loop.controller.kinematic.KinematicLtvMpc`, as an NLP
    :class:`~pipeline.loop.controller.nmpc.KinematicNmpc`; ``conf/controller/kinematic.yaml``).
    The weights are MATLAB's lists (``mpcobj.Weights``), by name in :attr:`weights`."""

    kind_word: ClassVar[ControllerKind] = ControllerKind.KINEMATIC_MPC
    kind_file: ClassVar[str] = "kinematic"

    kind: str = "kinematic_mpc"
    output_weights: List[float] = field(default_factory=lambda: [1.0, 1.0])
    input_weights: List[float] = field(default_factory=lambda: [0.1, 0.1])
    input_rate_weights: List[float] = field(default_factory=lambda: [0.01, 0.01])
    accel_bounds_mps2: List[float] = field(default_factory=lambda: [-3.0, 3.0])
    #: bounds on the predicted speed (m/s), or None: Appendix A's nlmpc bounds only the inputs,
    #: so its plan may reverse or exceed the platform's top speed (register)
    speed_bounds_mps: Optional[List[float]] = None
    ltv_iterations: int = 1
    reference_alignment: str = "literal"

    def __post_init__(self) -> None:
        self._check_mpc()
        for key in ("output_weights", "input_weights", "input_rate_weights"):
            pair(f"controller.{key}", getattr(self, key))
            for i, w in enumerate(getattr(self, key)):
                at_least(f"controller.{key}[{i}]", w, 0.0)
        pair("controller.accel_bounds_mps2", self.accel_bounds_mps2)
        if not self.accel_bounds_mps2[0] < self.accel_bounds_mps2[1]:
            raise ConfigError("controller.accel_bounds_mps2", list(self.accel_bounds_mps2),
                              "[low, high] with low < high")
        if self.speed_bounds_mps is not None:
            pair("controller.speed_bounds_mps", self.speed_bounds_mps)
            low, high = (float(v) for v in self.speed_bounds_mps)
            between("controller.speed_bounds_mps[0]", low, -50.0, 50.0)
            between("controller.speed_bounds_mps[1]", high, -50.0, 50.0)
            if not low < high:
                raise ConfigError("controller.speed_bounds_mps", list(self.speed_bounds_mps),
                                  "[low, high] with low < high, or null")
            if not self.accel_bounds_mps2[0] <= 0.0 <= self.accel_bounds_mps2[1]:
                raise ConfigError("controller.accel_bounds_mps2", list(self.accel_bounds_mps2),
                                  "[low, high] with low <= 0 <= high when "
                                  "controller.speed_bounds_mps is set (holding the speed keeps "
                                  "its rows feasible)")
            if self.backend == "nmpc":
                raise ConfigError("controller.speed_bounds_mps", list(self.speed_bounds_mps),
                                  "null with controller.backend=nmpc (the nonlinear MPC has "
                                  "no speed rows)")
        integer_in("controller.ltv_iterations", self.ltv_iterations, 1, 50)
        choice("controller.reference_alignment", self.reference_alignment,
               tuple(ReferenceAlignment))

    @property
    def weights(self) -> KinematicWeights:
        """The weights by name (:class:`KinematicWeights`, a named tuple numba takes)."""
        (x, y), (a, d), (da, dd) = (self.output_weights, self.input_weights,
                                    self.input_rate_weights)
        return KinematicWeights(float(x), float(y), float(a), float(d), float(da), float(dd),
                                float(self.slack_weight_linear),
                                float(self.slack_weight_quadratic))


class LateralWeights(NamedTuple):
    """The lateral MPC's cost weights by name (a named tuple: numba takes it, a cache key
    compares it as the tuple it is): the tracking weights on the lateral error, the heading
    error, the yaw rate and the steering angle, the steering-rate weight, and the soft
    collision constraints' linear and quadratic slack weights."""

    q_lateral: float
    q_heading: float
    q_yaw_rate: float
    q_steering: float
    r_steering_rate: float
    slack_linear: float
    slack_quadratic: float

    @classmethod
    def of(cls, controller: Any) -> LateralWeights:
        """The weights of a controller's settings (``q_lateral`` ... ``slack_weight_*``)."""
        c = controller
        return cls(float(c.q_lateral), float(c.q_heading), float(c.q_yaw_rate),
                   float(c.q_steering), float(c.r_steering_rate),
                   float(c.slack_weight_linear), float(c.slack_weight_quadratic))

    @property
    def tracking(self) -> tuple[float, float, float, float, float]:
        """The five weights of the tracking cost (the condensed prediction's)."""
        return (self.q_lateral, self.q_heading, self.q_yaw_rate, self.q_steering,
                self.r_steering_rate)


class KinematicWeights(NamedTuple):
    """The kinematic MPC's weights by name: the outputs (x, y), the inputs (acceleration,
    steering angle), their rates, and the soft collision constraints' slack weights."""

    x: float
    y: float
    accel: float
    steering: float
    accel_rate: float
    steering_rate: float
    slack_linear: float
    slack_quadratic: float


KindSettings = TypeVar("KindSettings", MpcSettings, PurePursuitSettings, KinematicMpcSettings)

#: Any kind's schema (the type of ``ExperimentConfig.controller``).
ControllerConfig = MpcSettings | PurePursuitSettings | KinematicMpcSettings

#: The schema of each controller kind.
KIND_SETTINGS: dict[ControllerKind, type[MpcSettings] | type[PurePursuitSettings]
                    | type[KinematicMpcSettings]] = {
    ControllerKind.MPC: MpcSettings, ControllerKind.PURE_PURSUIT: PurePursuitSettings,
    ControllerKind.KINEMATIC_MPC: KinematicMpcSettings}

def controller_schema(data: Any) -> type[MpcSettings] | type[PurePursuitSettings] \
        | type[KinematicMpcSettings]:
    """The schema of a controller section given as a mapping: its ``kind``'s (``mpc`` when
    the mapping names none); an unknown kind is refused naming the key and the kinds."""
    kind = data.get("kind", "mpc") if isinstance(data, dict) else "mpc"
    choice("controller.kind", kind, tuple(ControllerKind))
    return KIND_SETTINGS[ControllerKind(kind)]


def settings_of(controller: Any, kind: type[KindSettings]) -> KindSettings:
    """``controller`` when it is settings of the schema ``kind``; else refused, naming the
    kind it has and the one this controller needs."""
    if isinstance(controller, kind):
        return controller
    raise ConfigError("controller.kind", getattr(controller, "kind", type(controller).__name__),
                      f"{kind.kind_word} for this controller")
