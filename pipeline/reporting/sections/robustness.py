"""The multiverse (``make multiverse``), if it was run: per claim the default outcome, its
robustness and the choice that moves it most; the specification curves; the choices that
flip most of their specifications."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from pipeline.analysis.claims import ALL_CLAIMS, OUTCOMES
from pipeline.reporting.figure import Figure, Figures
from pipeline.reporting.inputs import ReportInputs
from pipeline.studies.results import MultiverseResult


@dataclass(frozen=True)
class RobustnessSection:
    rows: tuple[dict, ...]
    figures: tuple[Figure, ...]
    dims: tuple[dict, ...]
    n: int | None
    n_sim: int | None
    size: int | None
    name: str | None
    rule: str
    dimensions: tuple[dict, ...]
    backends: str
    #: per value of a scenario or vehicle dimension, each claim's usual outcome vs baseline
    worlds: tuple[dict, ...] = ()
    world_claims: tuple[str, ...] = ()
    #: may it speak in the opening summary: at least the default space's family size and
    #: number of specifications (a smaller one, such as quick, is exploratory)
    headline: bool = True
    #: why not ("" when it may)
    label: str = ""


def below_default_space(family_size: int, n_specifications: int) -> str:
    """Why a multiverse is below the default space's budget (``conf/multiverse/default.yaml``:
    its family size and number of specifications), "" when it is not."""
    import yaml

    from pipeline.config import CONF_DIR

    try:
        default = yaml.safe_load((CONF_DIR / "multiverse" / "default.yaml").read_text())
    except (OSError, yaml.YAMLError):
        return ""
    short = [f"{key} {have} < {default[key]}" for key, have in
             (("family_size", family_size), ("n_specifications", n_specifications))
             if isinstance(default.get(key), int) and have < default[key]]
    return ("below the default space's budget (" + ", ".join(short) + ")") if short else ""


def backends_text(backends: dict) -> str:
    """``daqp (baseline, improved); no QP (apf_pursuit)``: each QP backend with the methods
    whose runs used it (a multiverse's ``space.json``)."""
    by_backend: dict[str, list] = {}
    for method, backend in backends.items():
        by_backend.setdefault(str(backend), []).append(str(method))
    return "; ".join(f"{b} ({', '.join(m)})" for b, m in by_backend.items())


def _cells(result: MultiverseResult) -> list[dict]:
    rows: dict[str, dict] = {}
    for r in result.robustness.to_dict("records"):
        entry = rows.setdefault(r["claim"], {"claim": r["claim"], "cells": {}})
        if r["influence"] > 0:
            moved = (f"{r['most_influential']}"
                     + (f" = {r['flipping_values']}" if isinstance(r["flipping_values"], str)
                        and r["flipping_values"] else "")
                     + f" (flips {100 * r['influence']:.0f} % of its specifications)")
        else:
            moved = f"nothing flips it; largest shift: {r['most_influential']}"
        entry["cells"][r["comparison"]] = {
            "outcome": r["default_outcome"], "label": r["label"],
            "agree": f"{100 * r['agree_share']:.0f} %", "moved": moved,
            "shares": ", ".join(f"{o} {100 * r[f'share_{o}']:.0f} %"
                                for o in OUTCOMES if r.get(f"share_{o}", 0) > 0),
            # the three choices with the largest share (the whole list: the robustness table)
            "holds_with": "; ".join(r["holds_with"].split("; ")[:3])
            if isinstance(r.get("holds_with"), str)
            and r["holds_with"] else "no single choice"}
    return list(rows.values())


def _flipping_choices(result: MultiverseResult) -> list[dict]:
    """Against the baseline: each non-default value that flips most of its specifications."""
    rows: list[dict[str, Any]] = []
    dims = result.dimensions
    if not len(dims):
        return rows
    for (claim, comparison), part in dims.groupby(["claim", "comparison"], sort=False):
        if comparison != "baseline":
            continue
        for r in part.to_dict("records"):
            if r["default"] or r["flipped_share"] < 0.5:
                continue
            rows.append({"claim": claim, "dimension": r["dimension"], "value": r["value"],
                         "flipped": f"{100 * r['flipped_share']:.0f} %",
                         "outcome": r["modal_outcome"], "estimate": r["median_estimate"]})
    return rows


#: the groups of dimensions that vary the world the methods meet (not the methods)
WORLD_GROUPS = ("scenario", "vehicle")


def _group(dimension: dict) -> str:
    """A dimension's group as ``space.json`` records it (inferred from its config keys for
    a result written before groups were recorded)."""
    if dimension.get("group"):
        return str(dimension["group"])
    keys = [k.strip() for k in str(dimension.get("config_key") or dimension["key"]).split(",")]
    for group in WORLD_GROUPS:
        if all(k.startswith(group + ".") for k in keys):
            return group
    return str(dimension.get("stage", ""))


def _world_rows(result: MultiverseResult) -> tuple[list[dict], list[str]]:
    """Against the baseline, per value of every scenario and vehicle dimension: each claim's
    usual outcome over that value's specifications and the share that differ from the
    default's (what the section says about the scenario distributions each claim flips
    under); and the claims, in order."""
    dims = result.dimensions
    world = {d["key"]: _group(d) for d in result.info.dimensions
             if _group(d) in WORLD_GROUPS}
    if not len(dims) or not world:
        return [], []
    part = dims[(dims["comparison"] == "baseline") & dims["dimension"].isin(list(world))]
    claims = [c.claim_id for c in ALL_CLAIMS if c.claim_id in set(part["claim"])]
    rows: dict[tuple[str, str], dict[str, Any]] = {}
    for r in part.to_dict("records"):
        entry = rows.setdefault((r["dimension"], str(r["value"])), {
            "group": world[r["dimension"]], "dimension": r["dimension"],
            "value": str(r["value"]), "default": bool(r["default"]), "cells": {}})
        entry["cells"][r["claim"]] = {
            "outcome": r["modal_outcome"], "flipped": f"{100 * r['flipped_share']:.0f} %",
            "flips": r["flipped_share"] >= 0.5, "estimate": r["median_estimate"]}
    return list(rows.values()), claims


def robustness_section(inputs: ReportInputs, figures: Figures) -> RobustnessSection | None:
    result = inputs.multiverse
    if result is None:
        return None
    drawn = []
    for claim in ALL_CLAIMS:
        stem = MultiverseResult.curve_stem(claim.claim_id)
        figure = figures.copy(
            result.curve_figure(claim.claim_id), stem, "robustness",
            f"{claim.claim_id} ({claim.text}): the estimate with its interval (1 - alpha / 7) in every "
            "specification, sorted, coloured by outcome, against each comparison; below, "
            "which choices each specification changes from the default.",
            f"Specification curve of {claim.claim_id}")
        if figure is not None:
            drawn.append(figure)
    info = result.info
    worlds, world_claims = _world_rows(result)
    label = below_default_space(info.family_size, info.n_specifications)
    return RobustnessSection(
        tuple(_cells(result)), tuple(drawn), tuple(_flipping_choices(result)),
        info.n_specifications, info.n_simulation_configurations, info.family_size, info.name,
        info.rule, info.dimensions, backends_text(info.backends or {}), tuple(worlds),
        tuple(world_claims), not label, label)
