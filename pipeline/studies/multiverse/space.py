"""The multiverse's space: its dimensions (a config key, its defensible values, the first the
default, and the stage that uses it) and how it is sampled and judged, read from a space file
(``conf/multiverse/<name>.yaml``) through the project's own strict reader
(:func:`pipeline.config.schema_from_data`: unknown keys and wrong shapes are one line naming
the key, before any work starts)."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any, List, Optional

from pipeline.config import schema_from_data
from pipeline.errors import ConfigError
from pipeline.validation import between

#: The methods simulated by default: the claims' controls and treatment (claims.treatment,
#: claims.controls of the user's configuration choose others).
METHODS = ("baseline", "baseline_matched", "improved")
STAGES = ("simulation", "analysis")
#: the lateral MPC's QP backends a space may choose (``controller.backend``)
QP_BACKENDS = ("clarabel_direct", "daqp", "cvxpy")
ANALYSIS_PREFIXES = ("metrics.", "claims.")


#: Config sections whose keys describe the world the methods meet (the scenario distribution
#: and the vehicle): a dimension that sets one sets it for every method, so pairs stay paired.
SHARED_SECTIONS = ("scenario.", "vehicle.")


@dataclass(frozen=True)
class Dimension:
    """One choice of the multiverse: a config key and its defensible values.

    ``key`` names the dimension (a column of the design); ``config_key`` is the Hydra key it
    sets when that differs, e.g. the baseline's own ``planner.rho0_m`` beside the improved
    APF's (``key: planner.rho0_m[baseline]``). A *labelled* dimension (simulation only) holds
    readable labels in ``values`` (what the design and the robustness tables show) and the
    setting behind each in ``settings``: a value of ``config_key`` (a list too, e.g. a range
    ``[1.0, 2.0]``) or a mapping of several config keys to their values (a bundle, e.g. both
    obstacle-kind probabilities at once).
    """

    key: str
    stage: str
    values: tuple
    applies_to: tuple | None = None
    cap: bool = False
    why: str = ""
    config_key: str = ""
    settings: tuple | None = None

    @property
    def target(self) -> str:
        """The config key the dimension sets."""
        return self.config_key or self.key

    @property
    def default(self) -> Any:
        return self.values[0]

    def setting(self, choice: Any) -> Any:
        """The setting behind a design cell: the value itself, or a labelled choice's
        setting."""
        if self.settings is None:
            return choice
        return self.settings[[str(v) for v in self.values].index(str(choice))]

    def overrides(self, choice: Any) -> list[str]:
        """The Hydra overrides of one choice (one per key of a bundle)."""
        value = self.setting(choice)
        if isinstance(value, dict):
            return [f"{k}={hydra_value(v)}" for k, v in value.items()]
        return [f"{self.target}={hydra_value(value)}"]

    @property
    def config_keys(self) -> tuple[str, ...]:
        """Every config key the dimension sets (a bundle's keys)."""
        bundles = [v for v in self.settings or () if isinstance(v, dict)]
        if not bundles:
            return (self.target,)
        return tuple(sorted({k for value in bundles for k in value}))

    @property
    def group(self) -> str:
        """What the dimension varies: ``scenario`` (the scenario distribution), ``vehicle``,
        ``method`` (planner, controller and anything else simulated) or ``analysis``
        (readings and statistics)."""
        if self.stage == "analysis":
            return "analysis"
        for section in SHARED_SECTIONS:
            if all(k.startswith(section) for k in self.config_keys):
                return section.rstrip(".")
        return "method"


def hydra_value(value: Any) -> str:
    """A value as a Hydra override writes it (lists without spaces, None as null)."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (list, tuple)):
        return "[" + ",".join(hydra_value(v) for v in value) + "]"
    return str(value)


@dataclass(frozen=True)
class Space:
    """A multiverse: its dimensions and how to sample and judge it."""

    name: str
    dimensions: tuple[Dimension, ...] = ()
    family_size: int = 100
    family_seed: int = 0
    n_specifications: int = 128
    sample_seed: int = 0
    simulation_pool: int = 12
    n_resamples: int = 499
    robust_share: float = 0.9
    fragile_share: float = 0.5
    min_pairs: int = 10
    #: the lateral MPC's QP backend of the runs (like the tuning's: DAQP, the reference
    #: Clarabel's QP solved about 3x faster, the first input within 1e-6)
    backend: str = "daqp"

    def __post_init__(self) -> None:
        # a space file's values arrive as YAML gives them: each setting's type is checked here
        for f in fields(self):
            kinds: dict[str, type | tuple[type, ...]] = {"int": int, "float": (int, float)}
            kind = kinds.get(str(f.type))
            value = getattr(self, f.name)
            if kind is not None and (isinstance(value, bool) or not isinstance(value, kind)):
                raise ConfigError(f"multiverse space: {f.name}", value,
                                  f"a number ({str(f.type)})")
        if self.family_size < 1 or self.n_specifications < 1:
            raise ConfigError("family_size / n_specifications",
                              [self.family_size, self.n_specifications], "positive integers")
        if self.backend not in QP_BACKENDS:
            raise ConfigError("multiverse space: backend", self.backend,
                              f"one of {list(QP_BACKENDS)} (the lateral MPC's QP backend)")
        self._check_ranges()

    def _check_ranges(self) -> None:
        """Each count and seed in its range, each share in [0, 1] with the fragile one at most
        the robust one (``robust_share: 5`` labelled every verdict 'sensitive', even at 100 %
        agreement)."""
        for key, low, high in (("family_seed", 0, 2**31 - 1), ("sample_seed", 0, 2**31 - 1),
                               ("simulation_pool", 1, 100_000), ("n_resamples", 99, 1_000_000),
                               ("min_pairs", 0, 1_000_000)):
            value = getattr(self, key)
            if not low <= value <= high:
                raise ConfigError(f"multiverse space: {key}", value,
                                  f"an integer in [{low}, {high}]")
        between("multiverse space: robust_share", self.robust_share, 0.0, 1.0)
        between("multiverse space: fragile_share", self.fragile_share, 0.0, self.robust_share)
        if self.dimensions and self.n_specifications > self.drawable():
            raise ConfigError("multiverse space: n_specifications", self.n_specifications,
                              f"an integer in [1, {self.drawable()}] (the distinct "
                              "specifications this space can draw: the default, each value "
                              "one at a time, and up to simulation_pool simulation choices "
                              "times every analysis combination)")

    def drawable(self) -> int:
        """How many distinct specifications :func:`~.design.build_design` can draw at most:
        the default, each other value one at a time, and sampled ones from a pool of
        ``simulation_pool`` simulation choices times every combination of the analysis
        choices."""
        sizes = {stage: math.prod(len(d.values) for d in self.of(stage))
                 for stage in ("simulation", "analysis")}
        one_at_a_time = 1 + sum(len(d.values) - 1 for d in self.dimensions)
        return min(sizes["simulation"] * sizes["analysis"],  # every combination, at most
                   one_at_a_time + min(sizes["simulation"], self.simulation_pool)
                   * sizes["analysis"])

    def check_methods(self, methods: tuple[str, ...]) -> None:
        """Every ``applies_to`` names only methods the study runs (``methods``); one line
        naming the dimension otherwise (a dimension that applies to nothing ran, silently
        changing no run)."""
        for i, dim in enumerate(self.dimensions):
            unknown = [m for m in dim.applies_to or () if m not in methods]
            if unknown:
                raise ConfigError(f"multiverse space: dimensions[{i}].applies_to",
                                  list(dim.applies_to or ()),
                                  f"methods the multiverse runs: {', '.join(methods)} "
                                  "(claims.treatment and claims.controls)")

    def of(self, stage: str) -> list[Dimension]:
        return [d for d in self.dimensions if d.stage == stage]


@dataclass
class DimensionFile:
    """One dimension as a space file writes it: ``key`` is the config key; ``name`` (optional)
    names the dimension when it differs, e.g. the baseline's own ``planner.rho0_m`` beside the
    improved APF's (``name: planner.rho0_m[baseline]``). ``labels`` (simulation only) names
    each value readably; a value that is a mapping of config keys to values (a bundle) needs
    them and a ``name`` (its ``key`` may then be left out)."""

    key: str = ""
    stage: str = ""
    values: List[Any] = field(default_factory=list)
    name: str = ""
    applies_to: Optional[List[str]] = None
    cap: bool = False
    why: str = ""
    labels: Optional[List[str]] = None

    def check(self, where: str) -> Dimension:
        """The dimension, or :class:`ConfigError` naming ``where`` (``dimensions[i]``)."""
        if self.stage not in STAGES:
            raise ConfigError(f"{where}.stage", self.stage, "simulation or analysis")
        if len(self.values) < 2:
            raise ConfigError(f"{where}.values", list(self.values), "two or more values, the "
                              "first the default")
        key = str(self.name or self.key)
        config_key = str(self.key) if self.name else ""
        if not key:
            raise ConfigError(f"{where}.key", key, "a config key (or a name)")
        if self.stage == "analysis" and not (config_key or key).startswith(ANALYSIS_PREFIXES):
            raise ConfigError(f"{where}.key", key, "a metrics.* or claims.* key for an "
                              "analysis dimension")
        settings = self._settings(where, key, config_key)
        labels = tuple(str(label) for label in self.labels or ())
        dim = Dimension(key, self.stage, labels if settings else tuple(self.values),
                        tuple(self.applies_to) if self.applies_to else None, bool(self.cap),
                        str(self.why), config_key, settings)
        shared = [k for k in dim.config_keys if k.startswith(SHARED_SECTIONS)]
        if dim.applies_to and shared:
            raise ConfigError(f"{where}.applies_to", list(dim.applies_to),
                              f"none: {shared[0]} describes the world every method meets "
                              "(set for one method only, its pairs would not be paired)")
        return dim

    def _settings(self, where: str, key: str, config_key: str) -> tuple | None:
        """The settings behind labelled values (None for a dimension without labels)."""
        bundles = [v for v in self.values if isinstance(v, dict)]
        if self.labels is None:
            if bundles:
                raise ConfigError(f"{where}.labels", None, "a readable label per value (a "
                                  "value that sets several keys needs one)")
            return None
        if self.stage != "simulation":
            raise ConfigError(f"{where}.labels", list(self.labels), "labels on a simulation "
                              "dimension only")
        labels = [str(label) for label in self.labels]
        if len(labels) != len(self.values) or len(set(labels)) != len(labels):
            raise ConfigError(f"{where}.labels", labels, f"{len(self.values)} distinct labels, "
                              "one per value")
        if bundles and (len(bundles) != len(self.values) or not self.name):
            raise ConfigError(f"{where}.values", list(self.values), "every value a mapping of "
                              "config keys to values, and a name for the dimension")
        for value in bundles:
            if not value or not all(isinstance(k, str) and "." in k for k in value):
                raise ConfigError(f"{where}.values", value, "a mapping of config keys "
                                  "(section.key) to values")
        if not bundles and not (config_key or key):
            raise ConfigError(f"{where}.key", key, "the config key the values set")
        return tuple(self.values)


def load_space(path: Path) -> Space:
    """Read and check a space file; a bad one raises :class:`ConfigError` (one line)."""
    from pipeline.store.safe_load import load_yaml

    path = Path(path)
    if not path.exists():
        raise ConfigError("multiverse space", str(path), "a file in conf/multiverse/ "
                          "(default, quick) or a path to one")
    # size, UTF-8 and alias limits: one line naming the file (pipeline.store.safe_load)
    data = load_yaml(path, "a multiverse space (conf/multiverse/<name>.yaml)") or {}
    if not isinstance(data, dict):
        raise ConfigError("multiverse space", type(data).__name__,
                          "a mapping with 'dimensions' and the space's settings")
    items = data.get("dimensions", [])
    if not isinstance(items, list):
        raise ConfigError("multiverse space.dimensions", items, "a list of dimensions")
    dims = [schema_from_data(DimensionFile, item, f"multiverse space.dimensions[{i}]")
            .check(f"dimensions[{i}]") for i, item in enumerate(items)]
    if not dims:
        raise ConfigError("dimensions", [], "at least one dimension")
    if len({d.key for d in dims}) != len(dims):
        raise ConfigError("dimensions", [d.key for d in dims], "each key once")
    # the settings through the same strict reader (unknown keys named), Space checks them
    settings = {k: v for k, v in data.items() if k != "dimensions"}
    space = schema_from_data(Space, {**settings, "name": str(data.get("name") or path.stem)},
                             "multiverse space")
    return dataclasses.replace(space, dimensions=tuple(dims))
