"""Each controller kind's own settings, typed (do-mpc's per-controller settings classes).

:class:`~pipeline.loop.settings.ControllerConfig` stays the one flat schema Hydra composes,
checks and hashes (its keys are the YAML's). :meth:`ControllerConfig.settings()
<pipeline.loop.settings.ControllerConfig.settings>` reads it once into the frozen settings of
its kind, the ones the built-in controllers are handed: :class:`MpcSettings` (the lateral MPC,
``kind=mpc``), :class:`PurePursuitSettings` (``kind=pure_pursuit``) and
:class:`KinematicMpcSettings` (Appendix A's kinematic MPC, ``kind=kinematic_mpc``). Each holds
the fields its controller reads, the choices as the enums below (string enums: a member equals
its word, ``Frame.PATH == "path"``); ``ControllerConfig`` checks its words against the same
enums.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from enum import StrEnum
from typing import Any, ClassVar, Optional, TypeVar


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

Settings = TypeVar("Settings", "MpcSettings", "PurePursuitSettings", "KinematicMpcSettings")


class _KindSettings:
    """What the three settings classes share: read from a ``ControllerConfig``."""

    kind: ClassVar[ControllerKind]

    @classmethod
    def of(cls: type[Settings], controller: Any) -> Settings:
        """The fields of this class read off ``controller`` (a ``ControllerConfig``, or
        settings with these fields), choices as their enums, lists as tuples."""
        values: dict[str, Any] = {}
        for f in fields(cls):
            value = getattr(controller, f.name)
            if f.name in CHOICES:
                value = CHOICES[f.name](value)
            elif isinstance(value, list):
                value = tuple(value)
            values[f.name] = value
        return cls(**values)


@dataclass(frozen=True)
class MpcSettings(_KindSettings):
    """The lateral MPC's settings (:class:`~pipeline.loop.controller.lateral.LateralMpc`, on
    the nonlinear model :class:`~pipeline.loop.controller.lateral_nmpc.LateralNmpc`); the
    meaning of each field is ``ControllerConfig``'s."""

    kind: ClassVar[ControllerKind] = ControllerKind.MPC

    name: str
    backend: Backend
    horizon: int
    control_horizon: int
    input_hold: InputHold
    q_lateral: float
    q_heading: float
    q_yaw_rate: float
    q_steering: float
    r_steering_rate: float
    slack_weight_linear: float
    slack_weight_quadratic: float
    safety_margin_m: float
    constraint_activation_m: float
    collision_constraints: bool
    halfplane_normal: HalfplaneNormal
    max_obstacles: int
    heading_reference: HeadingReference
    heading_ref_max_rad: float
    yaw_rate_ref_max_rad_s: float
    path_beyond_end: PathBeyondEnd
    frame: Frame
    path_reference: PathReference
    path_lookahead_m: float
    path_curvature_clip: bool
    path_curvature_max_1_per_m: Optional[float]
    path_state_reference: PathStateReference
    horizon_reach_m: Optional[float]
    nmpc_substeps: int
    solver_max_iter: int


@dataclass(frozen=True)
class PurePursuitSettings(_KindSettings):
    """Pure pursuit's settings (:class:`~pipeline.loop.controller.pursuit.PurePursuit`): the
    look-ahead, and the horizon and references it logs as an MPC would."""

    kind: ClassVar[ControllerKind] = ControllerKind.PURE_PURSUIT

    name: str
    horizon: int
    lookahead_min_m: float
    lookahead_time_s: float
    heading_ref_max_rad: float
    path_beyond_end: PathBeyondEnd


@dataclass(frozen=True)
class KinematicMpcSettings(_KindSettings):
    """Appendix A's kinematic MPC's settings
    (:class:`~pipeline.loop.controller.kinematic.KinematicLtvMpc`, as an NLP
    :class:`~pipeline.loop.controller.nmpc.KinematicNmpc`)."""

    kind: ClassVar[ControllerKind] = ControllerKind.KINEMATIC_MPC

    name: str
    backend: Backend
    horizon: int
    control_horizon: int
    input_hold: InputHold
    max_obstacles: int
    output_weights: tuple[float, ...]
    input_weights: tuple[float, ...]
    input_rate_weights: tuple[float, ...]
    slack_weight_linear: float
    slack_weight_quadratic: float
    accel_bounds_mps2: tuple[float, ...]
    ltv_iterations: int
    reference_alignment: ReferenceAlignment
    safety_margin_m: float
    constraint_activation_m: float
    collision_constraints: bool
    solver_max_iter: int


#: The settings class of each controller kind.
KIND_SETTINGS: dict[ControllerKind, type[MpcSettings] | type[PurePursuitSettings]
                    | type[KinematicMpcSettings]] = {
    ControllerKind.MPC: MpcSettings, ControllerKind.PURE_PURSUIT: PurePursuitSettings,
    ControllerKind.KINEMATIC_MPC: KinematicMpcSettings}


def settings_of(controller: Any, kind: type[Settings]) -> Settings:
    """``controller`` as the settings class ``kind``: settings of that class as they are, a
    ``ControllerConfig`` (a test's, the bench's) read into them (:meth:`_KindSettings.of`)."""
    return controller if isinstance(controller, kind) else kind.of(controller)
