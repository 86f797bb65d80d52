"""'Real motion: recorded pedestrians': the claims judged on a family whose obstacles are
recorded ETH/UCY pedestrians (``make pedestrians``), overall and per scene
(``tables/claims_ledger_pedestrians.csv``), the collisions with them on their true tracks
(``tables/pedestrians_collisions.csv``), a figure of one member, and every member's row linked
to the scenario explorer (``explorer.html#pedestrians/<member_index>``)."""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from pipeline.errors import RunFolderError
from pipeline.reporting.figure import Figure, Figures
from pipeline.reporting.inputs import UNREADABLE, ReportInputs
from pipeline.reporting.sections.family import ledger_groups
from pipeline.reporting.verdicts import PedestrianVerdicts, Verdicts

log = logging.getLogger(__name__)

#: The scenario explorer's address of a member (the explorer page sits beside index.html).
EXPLORER_LINK = "explorer.html#pedestrians/{index}"


@dataclass(frozen=True)
class PedestriansSection:
    """What the page shows (see the module docstring). ``verdicts``: per claim and comparison
    the outcome overall and per scene; ``members``: per member its scene, each method's
    collision and closest clearance, and its explorer link."""

    treatment: str
    comparisons: tuple[str, ...]
    methods: tuple[str, ...]
    size: int
    seed: object
    scenes: tuple[tuple[str, int], ...]
    settings: dict
    verdicts: tuple[dict, ...]
    ledger: tuple[dict, ...]
    collisions: tuple[dict, ...]
    members: tuple[dict, ...]
    figure: Figure | None
    sentence: str
    #: members whose run could not be read for the figure: member, folder, reason
    damaged: tuple[dict, ...] = ()
    #: the crowd-navigation metrics: one row per family (default, variants) and method
    metrics: tuple[dict, ...] = ()
    #: per family its description and difficulty from the recording alone
    families: tuple[dict, ...] = ()
    #: per variant and claim the outcome against the first comparison, with its pairs
    variant_outcomes: tuple[dict, ...] = ()
    #: the fewest pairs any of C1-C5 rests on in the default family
    fewest_pairs: int | None = None
    #: C1 and C4 of the default family by the other rule of their pairs (:func:`~pipeline.
    #: reporting.verdicts._other_pairs`)
    other_pairs: tuple[dict, ...] = ()


def _verdict_rows(judged: PedestrianVerdicts) -> tuple[dict, ...]:
    by_scene = dict(judged.by_scene)
    rows = []
    for row in judged.ledger:
        entry = {"claim": row.claim_id, "comparison": row.comparison,
                 "all": str(row.outcome), "n": row.result.n_pairs}
        for scene in judged.scenes:
            scene_row = by_scene[scene].get(row.key) if scene in by_scene else None
            entry[scene] = (f"{scene_row.outcome} ({scene_row.result.n_pairs})"
                            if scene_row is not None else "—")
        rows.append(entry)
    return tuple(rows)


def _members(judged: PedestrianVerdicts, methods: tuple[str, ...]) -> tuple[dict, ...]:
    first = judged.tables[methods[0]]
    by_method = {m: judged.tables[m].set_index("member") for m in methods}
    rows = []
    for member, scene, name in zip(first["member"], first["scene"], first["scenario"],
                                   strict=True):
        row = {"member": int(member), "scene": scene, "scenario": name,
               "link": EXPLORER_LINK.format(index=int(member))}
        for m in methods:
            t = by_method[m]
            hit = bool(t.at[member, "collision"]) if member in t.index else None
            clearance = float(t.at[member, "min_clearance_m"]) if member in t.index \
                and "min_clearance_m" in t else float("nan")
            row[m] = ("collision" if hit else "clear") if hit is not None else "—"
            row[f"{m}_clearance"] = clearance
        rows.append(row)
    return tuple(rows)


def _figure_member(judged: PedestrianVerdicts, methods: tuple[str, ...]) -> int | None:
    """The first member where no method collided and the methods' closest clearances differ
    most among the first 20 such (a scene where the choice of method shows); else member 0."""
    tables = [judged.tables[m].set_index("member") for m in methods]
    common = sorted(set.intersection(*(set(t.index) for t in tables)))
    if not common:
        return None
    clear = [i for i in common if not any(bool(t.at[i, "collision"]) for t in tables)][:20]
    if not clear:
        return int(common[0])
    spread = [np.ptp([float(t.at[i, "min_clearance_m"]) for t in tables]) for i in clear]
    return int(clear[int(np.nanargmax(spread))]) if np.isfinite(spread).any() else clear[0]


def _figure(inputs: ReportInputs, judged: PedestrianVerdicts, methods: tuple[str, ...],
            figures: Figures, damaged: list[dict]) -> Figure | None:
    """The scene figure of :func:`_figure_member`'s member, else of the next member whose
    runs can all be read; a member that cannot be read is added to ``damaged`` (its folder
    and why) and costs only itself (it once took the whole page down)."""
    family = inputs.pedestrians
    member = _figure_member(judged, methods)
    if family is None or member is None:
        return None
    dirs = [family.info.get(family.label_of(m) or "", {}).get("dir") for m in methods]
    if not all(dirs):
        return None
    folders = [Path(d) for d in dirs if d]
    others = sorted(set(judged.tables[methods[0]]["member"].astype(int)) - {member})
    for candidate in [member, *others]:
        read = _read_members(folders, candidate, damaged)
        if read is not None:
            return _draw(dict(zip(methods, read[0], strict=True)), read[1], candidate,
                         methods, figures)
    return None


def _read_members(folders: list[Path], member: int, damaged: list[dict]
                  ) -> tuple[list[pd.DataFrame], object] | None:
    """Every method's trajectory of ``member`` and the config, or None (each unreadable run
    added to ``damaged``)."""
    from pipeline.store.runs import read_member

    runs, config, ok = [], None, True
    for folder in folders:
        try:
            record = read_member(folder, member)
        except (RunFolderError, *UNREADABLE) as exc:
            log.warning("pedestrians: member %d of %s cannot be read: %s", member, folder, exc)
            damaged.append({"member": member, "folder": str(folder), "reason": str(exc)})
            ok = False
            continue
        runs.append(record.trajectory)
        config = record.config
    if not ok or config is None or any(t is None for t in runs):
        return None
    return runs, config


def _draw(runs: dict, config, member: int, methods: tuple[str, ...], figures: Figures
          ) -> Figure | None:
    from pipeline.reporting.figures.pedestrians import pedestrian_scene_figure

    scenario = config.scenario
    ped = scenario.pedestrians
    if ped is None:
        return None
    title = (f"member {member}: scene {ped.scene}, recording from "
             f"{float(ped.window_start_s or 0.0):.1f} s, platform at "
             f"{scenario.speed_mps:.2f} m/s")
    return figures.draw(
        pedestrian_scene_figure(runs, (scenario.start_xy_m[0], scenario.start_xy_m[1]),
                                (scenario.goal_xy_m[0], scenario.goal_xy_m[1]),
                                ped.sensor_range_m, config.vehicle.footprint_radius_m, title),
        "pedestrians_scene", "pedestrians",
        f"Member {member} of the pedestrian family (scene {ped.scene}): every simulated "
        "pedestrian's recorded track over the run (grey; dark where the vehicle saw it, "
        "arrow: where it was last) and each method's path, with its footprint where it "
        "stopped.",
        f"Recorded pedestrian tracks of scene {ped.scene} and the paths of "
        f"{', '.join(methods)} crossing it.", member=member)


def pedestrians_section(inputs: ReportInputs, verdicts: Verdicts, figures: Figures
                        ) -> PedestriansSection | None:
    """The section; None when no pedestrian family was given or could be judged."""
    judged = verdicts.pedestrians
    family = inputs.pedestrians
    if judged is None or family is None:
        return None
    treatment = verdicts.claims.treatment
    methods = (treatment, *judged.comparisons)
    info = next(iter(family.info.values()), {})
    settings_cfg = next(iter(family.settings.values()), None)
    ped = settings_cfg.scenario.pedestrians if settings_cfg is not None else None
    settings = {} if ped is None else {
        "radius_m": ped.radius_m, "sensor_range_m": ped.sensor_range_m,
        "crossing_length_m": ped.crossing_length_m,
        "platform_speed_mps": list(ped.platform_speed_mps),
        "vehicle_radius_m": settings_cfg.vehicle.footprint_radius_m if settings_cfg else None,
        "max_obstacles": getattr(settings_cfg.controller, "max_obstacles", None)
        if settings_cfg else None,
        "personal_space_m": ped.personal_space_m,
        # C4's and C5's clock: when every walker counts as passed (register)
        "pass_reading": settings_cfg.metrics.pass_reading if settings_cfg else None,
        # the pairs C1-C5 rest on (register: claims.pairs): the rule the ledger used
        "pairs_rule": judged.pairs_rule}
    scene_sizes = tuple((s, int((judged.tables[treatment]["scene"] == s).sum()))
                        for s in judged.scenes)
    collisions = tuple([{"scene": "all", **c} for c in judged.counts]
                       + list(judged.scene_counts))
    outcomes = ", ".join(f"{row.claim_id} {row.outcome}" for row in judged.ledger)
    hits = {c["method"]: c["collisions"] for c in judged.counts}
    sentence = (f"Among recorded pedestrians (ETH/UCY, {len(judged.tables[treatment])} "
                f"crossings over {len(judged.scenes)} scenes), {treatment} against "
                f"{', '.join(judged.comparisons)}: {outcomes}; collisions "
                + ", ".join(f"{m} {hits.get(m, '?')}" for m in methods) + ".")
    damaged: list[dict] = []
    figure = _figure(inputs, judged, methods, figures, damaged)
    everyone = (judged, *verdicts.pedestrian_variants)
    from pipeline.reporting.tables import pedestrian_metrics_frame

    metrics = tuple(pedestrian_metrics_frame(everyone).to_dict("records"))
    families = tuple({**j.about, **j.difficulty, "size": len(j.tables[treatment])}
                     for j in everyone)
    variant_outcomes = tuple(
        {"family": j.about.get("family"), "claim": row.claim_id,
         "comparison": row.comparison, "outcome": str(row.outcome),
         "pairs": row.result.n_pairs}
        for j in everyone for row in j.ledger.rows
        if row.comparison == (j.comparisons[0] if j.comparisons else None))
    pairs = [row.result.n_pairs for row in judged.ledger.rows
             if row.claim_id not in ("C0",) and row.comparison == judged.comparisons[0]] \
        if judged.comparisons else []
    return PedestriansSection(
        treatment, judged.comparisons, methods, int(info.get("size", 0) or 0),
        info.get("seed", "?"), scene_sizes, settings, _verdict_rows(judged),
        tuple(ledger_groups(judged.ledger)), collisions, _members(judged, methods),
        figure, sentence, tuple(damaged), metrics, families, variant_outcomes,
        min(pairs) if pairs else None, judged.other_pairs)
