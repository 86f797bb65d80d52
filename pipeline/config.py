"""The composed configuration of one run: the stage settings put together, cross-stage checks,
the config hash, and Hydra's schema registration.

The schemas live beside their stages (:mod:`pipeline.loop.settings`,
:mod:`pipeline.analysis.settings`) and are re-exported here for convenience. Only the entry
points call :func:`register_configs`; stages receive the typed dataclasses.
"""

from __future__ import annotations

import functools
import hashlib
import json
import math
from dataclasses import asdict, dataclass, field, fields, is_dataclass, replace
from typing import Any

from omegaconf import MISSING

from pipeline.analysis.features import FeatureConfig
from pipeline.analysis.objectives import Objective, TuneConfig
from pipeline.analysis.settings import ClaimsConfig, MetricsConfig
from pipeline.conf_dir import CONF_DIR
from pipeline.errors import ConfigError
from pipeline.loop.controller_settings import (
    KIND_SETTINGS,
    KinematicMpcSettings,
    MpcSettings,
    PurePursuitSettings,
    controller_schema,
)
from pipeline.loop.qp_memory import MAX_HORIZON
from pipeline.loop.settings import (
    ControllerConfig,
    FamilyConfig,
    ModelConfig,
    ObstacleConfig,
    PlannerConfig,
    ScenarioConfig,
    VehicleConfig,
)
from pipeline.register import INTERPRETATION_REGISTER, RegisterEntry
from pipeline.validation import FrozenAfterValidation, choice, safe_name

__all__ = ["CONF_DIR", "ClaimsConfig", "Objective", "TuneConfig", "schema_from_data", "ConfigError", "ControllerConfig", "ExperimentConfig", "FamilyConfig",
           "INTERPRETATION_REGISTER", "MAX_HORIZON", "MetricsConfig", "ModelConfig",
           "ObstacleConfig", "PlannerConfig", "RegisterEntry", "RunConfig", "ScenarioConfig",
           "VehicleConfig", "experiment_config_from_data", "register_configs", "to_experiment_config"]




@dataclass
class RunConfig(FrozenAfterValidation):
    """Bookkeeping of one run."""

    seed: int = 0
    method: str = ""
    variant: str = "default"
    # presentation (pipeline.methods): a method's label, the work it comes from, what it is in
    # one sentence (the report's glossary), its colour (#rrggbb), its place in tables and
    # legends and its role; never in the config hash
    label: str = ""
    citation: str = ""
    description: str = ""
    color: str = ""
    order: int = 1000
    role: str = ""

    def __post_init__(self) -> None:
        if self.method:
            safe_name("run.method", self.method)
        safe_name("run.variant", self.variant)
        if self.color and not (len(self.color) == 7 and self.color[0] == "#"
                               and all(c in "0123456789abcdefABCDEF" for c in self.color[1:])):
            raise ConfigError("run.color", self.color, "a colour #rrggbb, or empty")
        choice("run.role", self.role, ("", "treatment", "control", "peer", "reference"))
        if isinstance(self.order, bool) or not isinstance(self.order, int) \
                or not 0 <= self.order <= 1000:
            raise ConfigError("run.order", self.order, "an integer in [0, 1000]")


@dataclass
class ExperimentConfig(FrozenAfterValidation):
    """The composed configuration of one closed-loop run."""

    vehicle: VehicleConfig = MISSING
    planner: PlannerConfig = MISSING
    # one kind's schema (ControllerConfig: MpcSettings, PurePursuitSettings or
    # KinematicMpcSettings), chosen by the section's kind (controller_schema)
    controller: Any = field(default=MISSING, metadata={"schema_of": controller_schema})
    scenario: ScenarioConfig = MISSING
    model: ModelConfig = field(default_factory=ModelConfig)
    metrics: MetricsConfig = field(default_factory=MetricsConfig)
    claims: ClaimsConfig = field(default_factory=ClaimsConfig)
    run: RunConfig = field(default_factory=RunConfig)
    tune: TuneConfig = field(default_factory=TuneConfig)
    features: FeatureConfig = field(default_factory=FeatureConfig)

    def __post_init__(self) -> None:
        # cross-group checks need the whole config
        for i, obs in enumerate(self.scenario.obstacles):
            gap = math.dist(self.scenario.start_xy_m, (obs.x_m, obs.y_m))
            if obs.appear_time_s == 0.0 and gap < obs.radius_m + self.vehicle.footprint_radius_m:
                raise ConfigError(f"scenario.obstacles[{i}]", [obs.x_m, obs.y_m],
                                  "an obstacle that does not overlap the vehicle at the start "
                                  f"(centre distance >= {obs.radius_m + self.vehicle.footprint_radius_m} m)")
        goal_tol = self.metrics.goal_tolerance_m
        if goal_tol is None:
            self.metrics = replace(self.metrics,
                                   goal_tolerance_m=self.scenario.goal_tolerance_m)
        elif not math.isclose(goal_tol, self.scenario.goal_tolerance_m):
            raise ConfigError("metrics.goal_tolerance_m", goal_tol,
                              f"equal to scenario.goal_tolerance_m "
                              f"({self.scenario.goal_tolerance_m}) or null (follows it): the run "
                              "stops at one, the metrics judge with the other")
        self.scenario.check_with_vehicle(self.vehicle.footprint_radius_m)
        slots = getattr(self.controller, "max_obstacles", None)  # pure pursuit has none
        if slots is not None and len(self.scenario.obstacles) > slots:
            raise ConfigError("controller.max_obstacles", self.controller.max_obstacles,
                              f">= the number of obstacles ({len(self.scenario.obstacles)})")
        # the lateral model's 1/v_x terms forbid slower references; the kinematic bicycle
        # (Appendix A) has none and may be asked to stop, and so may the lateral track when it
        # hands over to the kinematic single-track below vehicle.kinematic_below_mps
        if self.controller.kind != "kinematic_mpc" and self.vehicle.kinematic_below_mps is None \
                and self.planner.speed_floor_mps < self.vehicle.min_model_speed_mps:
            raise ConfigError("planner.speed_floor_mps", self.planner.speed_floor_mps,
                              f">= vehicle.min_model_speed_mps ({self.vehicle.min_model_speed_mps}),"
                              " or any with vehicle.kinematic_below_mps set (the hand-over to "
                              "the kinematic model)")
        self.freeze()  # checked: from here on read-only (a change is a new, checked object)

    @property
    def method_name(self) -> str:
        """Label of the compared method (``run.method``, else the planner's name)."""
        return self.run.method or self.planner.name

    def to_dict(self) -> dict:
        return asdict(self)

    def config_hash(self) -> str:
        """Stable SHA-256 (first 16 hex digits) of what a run depends on: the resolved
        configuration without ``claims`` (how runs are compared re-scores, never re-simulates),
        ``tune`` (what the run returns to a tuner) and ``features`` (how runs are described).

        Kept with the object once it is frozen (validated: read-only from then on, a change is
        a new object), so that a tune asking it of one family's config several times per rung
        computes it once."""
        memo = self.__dict__.get("_config_hash_memo")
        if memo is not None:
            return memo
        value = _hash_of(self.to_dict())
        if self.__dict__.get("_frozen", False):
            object.__setattr__(self, "_config_hash_memo", value)
        return value

    def with_member(self, scenario: ScenarioConfig, config_hash: str | None = None
                    ) -> ExperimentConfig:
        """``dataclasses.replace(self, scenario=scenario)``: a member of this family. With
        ``config_hash`` (the member's, from :meth:`member_config_hashes`) its
        :meth:`config_hash` is known without converting it again (a worker asks it of every
        member it runs: 1.2 ms each), and travels with it to the worker."""
        member = replace(self, scenario=scenario)
        if config_hash is not None and member.__dict__.get("_frozen", False):
            object.__setattr__(member, "_config_hash_memo", config_hash)
        return member

    def member_config_hashes(self, members: list) -> list[str]:
        """``replace(self, scenario=m).config_hash()`` for every scenario ``m`` of
        ``members`` (a family's), with the rest of the configuration converted once (a
        family of 40 members in a twentieth of the time)."""
        rest = {f.name: getattr(self, f.name) for f in fields(self) if f.name != "scenario"}
        base = {name: asdict(value) if is_dataclass(value) and not isinstance(value, type)
                else value for name, value in rest.items()}
        return [_hash_of({**base, "scenario": asdict(member)}) for member in members]


def _hash_of(data: dict) -> str:
    """:meth:`ExperimentConfig.config_hash` of ``asdict(config)`` (``data`` is not changed)."""
    data = {k: v for k, v in data.items() if k not in ("claims", "tune", "features")}
    # a method's presentation (label, citation, description, colour, order, role) changes no
    # run (pipeline.methods.PRESENTATION_KEYS)
    data["run"] = {k: v for k, v in dict(data.get("run") or {}).items()
                   if k not in ("label", "citation", "description", "color", "order", "role")}
    for section in ("planner", "controller"):
        data[section] = dict(data[section])
    data["scenario"] = ScenarioConfig.hash_view(data["scenario"])
    data["vehicle"] = VehicleConfig.hash_view(data["vehicle"])
    if data["controller"].get("collision_constraints") is True:
        data["controller"].pop("collision_constraints")  # the default, as before the key
    if data["controller"].get("solver_refinement") is True:
        data["controller"].pop("solver_refinement")  # Clarabel's default, as before the key
    data["metrics"] = dict(data["metrics"])
    if data["metrics"].get("pass_reading") == "ahead_of_threats":
        data["metrics"].pop("pass_reading")  # the default, as before the key
    if "road_edge_weight" in data["controller"] and data["controller"]["road_edge_weight"] is None:
        data["controller"].pop("road_edge_weight")  # no road in the MPC, as before the key
    if "steering_friction_share" in data["controller"] \
            and data["controller"]["steering_friction_share"] is None:
        data["controller"].pop("steering_friction_share")  # the paper's bound, as before the key
    if "speed_bounds_mps" in data["controller"] and data["controller"]["speed_bounds_mps"] is None:
        data["controller"].pop("speed_bounds_mps")  # no speed rows, as before the key
    for section in ("planner", "controller"):
        # a plug-in's class and settings change the run; their absence does not
        if data[section].get("_target_") is None:
            data[section].pop("_target_", None)
        if not data[section].get("params"):
            data[section].pop("params", None)
    text = json.dumps(data, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def register_configs() -> None:
    """Register the schemas in Hydra's ConfigStore (called by entry points and tests)."""
    from hydra.core.config_store import ConfigStore

    store = ConfigStore.instance()
    store.store(name="experiment_schema", node=ExperimentConfig)
    store.store(group="vehicle", name="vehicle_schema", node=VehicleConfig)
    store.store(group="planner", name="planner_schema", node=PlannerConfig)
    # one schema per controller kind; controller_schema stays the lateral MPC's name (a
    # controller YAML of one's own written before the split names it)
    for name, schema in (("lateral_mpc_schema", MpcSettings), ("controller_schema", MpcSettings),
                         ("pure_pursuit_schema", PurePursuitSettings),
                         ("kinematic_mpc_schema", KinematicMpcSettings)):
        store.store(group="controller", name=name, node=schema)
    store.store(group="scenario", name="scenario_schema", node=ScenarioConfig)


def experiment_config_from_data(data: dict) -> ExperimentConfig:
    """Build the typed config from a plain mapping (a run folder's ``config.yaml``), with the
    same range checks as a fresh configuration (each schema's ``__post_init__``).

    Built directly from the schemas' type hints (about 1 ms; OmegaConf's structured merge takes
    about 60 ms, which an aggregate over thousands of jobs cannot afford). Unknown keys and
    values of the wrong shape raise :class:`ConfigError` naming the full key path.
    """
    from pipeline.analysis.settings import upgrade_claims_data

    if isinstance(data, dict) and isinstance(data.get("claims"), dict):
        # a run folder written before the claim catalogue: its margins tables read as entries
        data = {**data, "claims": upgrade_claims_data(data["claims"])}
    if isinstance(data, dict) and isinstance(data.get("controller"), dict):
        data = {**data, "controller": upgrade_controller_data(data["controller"])}
    return _build(ExperimentConfig, data, "")


#: Every key of the one flat controller schema that run folders were written with before each
#: kind had its own (issue 57): the union of the kinds' keys.
FLAT_CONTROLLER_KEYS = frozenset(f.name for schema in KIND_SETTINGS.values()
                                 for f in fields(schema))


def upgrade_controller_data(section: dict) -> dict:
    """A run folder's controller section as its kind's schema reads it: a section written
    with the one flat schema (every kind's keys) keeps its kind's keys; the others were never
    read by its controller. Any other unknown key stays, to be refused by name."""
    schema = controller_schema(section)
    if not set(section) <= FLAT_CONTROLLER_KEYS:
        return section
    own = {f.name for f in fields(schema)}
    return {key: value for key, value in section.items() if key in own}


def schema_from_data(schema, data: Any, path: str = ""):
    """An instance of the dataclass ``schema`` from a plain mapping (a settings file read outside
    Hydra), strictly: unknown keys and wrong shapes raise :class:`ConfigError` with the full key
    path, before any work starts; each schema's own range checks run as it is built."""
    return _build(schema, data, path)


@functools.cache
def _schema_fields(schema) -> tuple[dict[str, Any], frozenset[str], dict[str, Any]]:
    """The type hints, field names and ``schema_of`` builders of the dataclass ``schema``,
    read once per class (``typing.get_type_hints`` was half the time of reading a run's
    config: about 20 classes per run, 0.2 ms each)."""
    import typing

    schema_fields = fields(schema)
    return (typing.get_type_hints(schema), frozenset(f.name for f in schema_fields),
            {f.name: f.metadata["schema_of"] for f in schema_fields if "schema_of" in f.metadata})


def _build(schema, data: Any, path: str):
    """An instance of the dataclass ``schema`` from the mapping ``data`` (recursively)."""
    if not isinstance(data, dict):
        raise ConfigError(path or "config", data, f"a mapping for {schema.__name__}")
    hints, names, by_kind = _schema_fields(schema)
    unknown = sorted(set(data) - names)
    if unknown:
        key = f"{path}.{unknown[0]}" if path else unknown[0]
        raise ConfigError(key, data[unknown[0]], f"a key of {schema.__name__}: "
                          + ", ".join(sorted(names)))
    values = {name: _build(by_kind[name](value), value, f"{path}.{name}" if path else name)
              if name in by_kind else
              _coerce(hints[name], value, f"{path}.{name}" if path else name)
              for name, value in data.items()}
    return schema(**values)


def _coerce(hint, value: Any, path: str):
    """``value`` as the annotated type: nested schemas built, lists element-wise, ints as
    floats where a float is declared."""
    import typing

    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if origin is typing.Union:
        if value is None and type(None) in args:
            return None
        hint = next(a for a in args if a is not type(None))
        origin, args = typing.get_origin(hint), typing.get_args(hint)
    if is_dataclass(hint):
        return _build(hint, value, path)
    if origin in (list, typing.List) and args:
        if not isinstance(value, (list, tuple)):
            raise ConfigError(path, value, "a list")
        return [_coerce(args[0], v, f"{path}[{i}]") for i, v in enumerate(value)]
    if origin in (dict, typing.Dict):
        if not isinstance(value, dict):
            raise ConfigError(path, value, "a mapping")
        return {k: _coerce(args[1], v, f"{path}.{k}") if args else v for k, v in value.items()}
    if hint is float and isinstance(value, int) and not isinstance(value, bool):
        return float(value)
    return value


def to_experiment_config(cfg: Any) -> ExperimentConfig:
    """Build the typed config from a composed Hydra/OmegaConf config, running every range check.

    Parameters
    ----------
    cfg : omegaconf.DictConfig
        Composed config (``hydra`` node, if present, is ignored).

    Returns
    -------
    ExperimentConfig
    """
    from omegaconf import OmegaConf

    data, composed = _composed_data(cfg)
    built = _built_exactly(data, composed)
    if built is not None:
        return built
    # anything the direct build does not take as it stands (a value of another type, a
    # missing value, an unknown key, a range check, another kind's schema) goes OmegaConf's
    # way, which converts it or refuses it with its message, as before
    config = OmegaConf.to_object(_merged(data, composed))
    assert isinstance(config, ExperimentConfig)  # the structured schema's object
    return config


def _built_exactly(data: dict, composed: Any) -> ExperimentConfig | None:
    """:class:`ExperimentConfig` built directly from the composed ``data``
    (:func:`experiment_config_from_data`'s builder, about 1 ms) when every value already has
    its declared type, nothing is missing (in the data or as a schema's default), no string
    holds an interpolation and the controller's composed schema is its kind's:
    then OmegaConf's structured merge (about 60 ms a config) would give the same object
    (tested over every preset). None otherwise."""
    if _needs_omegaconf(data):
        return None
    try:
        if composed in KIND_SETTINGS.values() and composed is not controller_schema(
                data.get("controller")):
            return None
        built = _build(ExperimentConfig, data, "")
        return built if _of_declared_types(built) else None
    except Exception:  # whatever it is, OmegaConf's way says it as before
        return None


def _needs_omegaconf(value: Any) -> bool:
    """Whether ``value`` holds OmegaConf's missing value (``???``) or an interpolation's
    ``${`` (one escaped in the composition: OmegaConf's merge resolves it once more)."""
    if isinstance(value, dict):
        return any(_needs_omegaconf(v) for v in value.values())
    if isinstance(value, list):
        return any(_needs_omegaconf(v) for v in value)
    return isinstance(value, str) and (value == "???" or "${" in value)


def _of_declared_types(instance: Any) -> bool:
    """Whether every field of the dataclass ``instance`` (recursively) holds exactly its
    declared type: float, int (not bool), bool, str, None where optional, lists and
    mappings of them, nested schemas; False for anything else (OmegaConf would convert it,
    or refuse it)."""
    schema: Any = type(instance)
    hints, names, by_kind = _schema_fields(schema)
    for name in names:
        value = getattr(instance, name)
        if name in by_kind:
            if not (is_dataclass(value) and _of_declared_types(value)):
                return False
        elif not _is_declared(hints[name], value):
            return False
    return True


def _is_declared(hint: Any, value: Any) -> bool:
    import typing

    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if origin is typing.Union:
        if value is None:
            return type(None) in args
        rest = [a for a in args if a is not type(None)]
        return len(rest) == 1 and _is_declared(rest[0], value)
    if is_dataclass(hint):
        return type(value) is hint and _of_declared_types(value)
    if origin in (list, typing.List):
        return type(value) is list and all(_is_declared(args[0], v) for v in value)
    if origin in (dict, typing.Dict):
        return type(value) is dict and all(type(k) is str for k in value) \
            and all(_is_declared(args[1], v) for v in value.values())
    if hint is typing.Any:
        return True
    if hint is str:  # a schema's default may be OmegaConf's missing value
        return type(value) is str and value != "???"
    if hint in (float, int, bool):
        return type(value) is hint
    return False  # a type this check does not know: OmegaConf's way


def _composed_data(cfg: Any) -> tuple[dict, Any]:
    """The composed config as plain data (interpolations resolved, without Hydra's own node
    and the experiment's name) and the schema its controller section was composed with."""
    from omegaconf import OmegaConf

    # the hydra node is Hydra's own (some of its values exist only inside a running job)
    if "hydra" in cfg:
        cfg = OmegaConf.masked_copy(cfg, [k for k in cfg if k != "hydra"])
    data = OmegaConf.to_container(cfg, resolve=True)
    assert isinstance(data, dict)  # a composed config is a mapping
    data.pop("hydra", None)
    data.pop("experiment", None)
    composed = OmegaConf.get_type(cfg, "controller") if "controller" in cfg else None
    return data, composed


def typed_config(cfg: Any) -> Any:
    """The composed config merged into :class:`ExperimentConfig`'s structured schema (types
    checked, interpolations resolved; ``OmegaConf.to_object`` of it runs the range checks)."""
    return _merged(*_composed_data(cfg))


def _merged(data: dict, composed: Any) -> Any:
    """:func:`typed_config` of the composed ``data`` (:func:`_composed_data`)."""
    from omegaconf import OmegaConf
    from omegaconf.errors import ConfigKeyError

    schema = OmegaConf.structured(ExperimentConfig)
    # the controller section's schema is the one Hydra composed it with (its YAML's), so that
    # a kind set to another is refused by that schema, naming the file of the other kind; a
    # section composed without one is read by its kind's
    kind_schema = composed if composed in KIND_SETTINGS.values() \
        else controller_schema(data.get("controller"))
    schema.controller = OmegaConf.structured(kind_schema)
    try:
        merged = OmegaConf.merge(schema, data)
    except ConfigKeyError as exc:
        # inside a list (obstacles) OmegaConf names only the last key: give its full path
        key = str(getattr(exc, "full_key", "") or "")
        path = _path_of(data, key) if key and "." not in key and "[" not in key else None
        if path is None or path == key:
            raise  # OmegaConf's own message already names the whole key
        kind = getattr(exc, "object_type_str", None) or "this section"
        raise ConfigError(path, _value_at(data, path), f"one of the keys of {kind} (a "
                          "misspelled or unknown key)") from None
    return merged


def _path_of(data: Any, key: str, prefix: str = "") -> str | None:
    """The dotted path (list items as ``[i]``) of the first ``key`` in nested ``data``."""
    if isinstance(data, dict):
        if key in data:
            return f"{prefix}.{key}" if prefix else key
        items = ((f"{prefix}.{k}" if prefix else str(k), v) for k, v in data.items())
    elif isinstance(data, list):
        items = ((f"{prefix}[{i}]", v) for i, v in enumerate(data))
    else:
        return None
    for path, value in items:
        found = _path_of(value, key, path)
        if found is not None:
            return found
    return None


def _value_at(data: Any, path: str) -> Any:
    import re

    for part in re.findall(r"[^.\[\]]+|\[\d+\]", path):
        data = data[int(part[1:-1])] if part.startswith("[") else data[part]
    return data
