"""The multiverse's design (the default specification, every one-at-a-time change, a seeded
sample) and what one specification means for the runs (Hydra overrides, the QP backend) and
for the analysis (metric and statistics settings)."""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np
import pandas as pd

from pipeline.config import ClaimsConfig, ExperimentConfig, MetricsConfig
from pipeline.errors import ConfigError
from pipeline.studies.multiverse.space import Space, hydra_value


def build_design(space: Space) -> pd.DataFrame:
    """Default, one-at-a-time changes, then a seeded sample (simulation choices from a pool).

    Returns
    -------
    DataFrame
        ``spec_id``, ``kind`` (default / one_at_a_time / sampled) and one column per dimension.
    """
    rng = np.random.default_rng(space.sample_seed)
    default = {d.key: d.default for d in space.dimensions}
    rows = [{"kind": "default", **default}]
    for dim in space.dimensions:
        for value in dim.values[1:]:
            rows.append({"kind": "one_at_a_time", **default, dim.key: value})
    sim_dims = space.of("simulation")
    pool = [{d.key: d.values[rng.integers(len(d.values))] for d in sim_dims}
            for _ in range(max(space.simulation_pool, 1))]
    seen = {tuple(str(r[d.key]) for d in space.dimensions) for r in rows}
    attempts = 0
    while len(rows) < space.n_specifications and attempts < 100 * space.n_specifications:
        attempts += 1
        row = {"kind": "sampled", **pool[rng.integers(len(pool))]}
        for dim in space.of("analysis"):
            row[dim.key] = dim.values[rng.integers(len(dim.values))]
        signature = tuple(str(row[d.key]) for d in space.dimensions)
        if signature not in seen:
            seen.add(signature)
            rows.append(row)
    design = pd.DataFrame(rows)
    design.insert(0, "spec_id", [f"s{i:04d}" for i in range(len(design))])
    return design


def simulation_overrides(row: dict, space: Space, method: str) -> list[str]:
    """Hydra overrides of one method's family run for a specification's simulation choices."""
    overrides = [f"method={method}", "scenario=family",
                 f"scenario.family.size={space.family_size}"]
    keys = {d.target for d in space.dimensions}
    if "scenario.family.seed" not in keys:
        overrides.append(f"scenario.family.seed={space.family_seed}")
    for dim in space.of("simulation"):
        value = dim.setting(row[dim.key])
        if dim.applies_to and method not in dim.applies_to:
            if dim.cap and method == "baseline_matched":
                overrides.append(f"planner.step_size={hydra_value(value)}")
            continue
        overrides.extend(dim.overrides(row[dim.key]))
    return overrides


def family_config(row: dict, space: Space, method: str, compose) -> ExperimentConfig:
    """One method's family configuration for a specification's simulation choices, its lateral
    MPC on ``space.backend`` (a condensed-QP MPC only; other controllers keep their own, and
    an explicit ``controller.backend`` among the run overrides wins: they come last)."""
    overrides = simulation_overrides(row, space, method)
    cfg = compose(overrides)
    if cfg.controller.kind == "mpc" and cfg.controller.backend != space.backend:
        cfg = compose(overrides + [f"controller.backend={space.backend}"])
    return cfg


def qp_backend(cfg: ExperimentConfig) -> str:
    """The QP backend a run's controller solves with (``no QP`` for a pure pursuit)."""
    return cfg.controller.backend if cfg.controller.kind in ("mpc", "kinematic_mpc") \
        else "no QP"


def value_text(value) -> str:
    """A dimension value as text, None and NaN alike as "null" (a design table turns None in a
    column of numbers into NaN)."""
    if value is None or (isinstance(value, float) and value != value):
        return "null"
    return str(value)


def matches(column: pd.Series, value) -> pd.Series:
    """Rows of a design column that hold ``value``."""
    return column.map(value_text) == value_text(value)


def simulation_key(row: dict[str, Any], space: Space) -> tuple[str, ...]:
    """The simulation choices of a specification (what its runs depend on)."""
    return tuple(value_text(row[d.key]) for d in space.of("simulation"))


def analysis_settings(row: dict, space: Space, base: ExperimentConfig
                      ) -> tuple[MetricsConfig, ClaimsConfig]:
    """The metric and statistics settings of one specification: the settings the runs were made
    with (``base``, the user's configuration) with the specification's analysis choices."""
    metrics: dict[str, Any] = {}
    claims: dict[str, Any] = {}
    scale = 1.0
    for dim in space.of("analysis"):
        section, _, name = dim.target.partition(".")
        value = None if value_text(row[dim.key]) == "null" else row[dim.key]
        if dim.target == "claims.margin_scale":
            if value is None:
                raise ConfigError("claims.margin_scale", value, "a number (the margins' factor)")
            scale = float(value)
        elif section == "metrics":
            metrics[name] = value
        else:
            claims[name] = value
    margins = {k: v * scale for k, v in base.claims.margins.items()}
    return (dataclasses.replace(base.metrics, **metrics),
            dataclasses.replace(base.claims.with_margins(margins),
                                **{**claims, "n_resamples": space.n_resamples,
                                   # no second draw: a specification whose outcome lies
                                   # within its interval's Monte-Carlo error reads the
                                   # widened interval
                                   "n_resamples_refine": space.n_resamples,
                                   "min_pairs": space.min_pairs}))


def with_user_defaults(space: Space, base: ExperimentConfig) -> Space:
    """The space with each analysis dimension's default (its first value) set to the user's
    configured value, so that the default specification is the user's configuration."""
    dims = []
    for dim in space.dimensions:
        section, _, name = dim.target.partition(".")
        if dim.stage == "analysis" and dim.target != "claims.margin_scale":
            value = getattr(getattr(base, section), name)
            dim = dataclasses.replace(dim, values=(value,) + tuple(
                v for v in dim.values if str(v) != str(value)))
        dims.append(dim)
    return dataclasses.replace(space, dimensions=tuple(dims))
