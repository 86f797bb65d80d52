"""The report's tables (``tables/*.csv`` beside the page): every number the page shows, as
CSV, written in one place from the inputs and the verdicts."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pandas as pd

from pipeline.reporting.inputs import ReportInputs, TrackRuns
from pipeline.reporting.verdicts import TrackClaims, Verdicts
from pipeline.studies.results.tune import HELDOUT, LEDGER_TUNED, SETTINGS_OUTCOMES, TRIALS

#: the published ledgers ``make verify`` checks, by their file name under ``tables/``
PUBLISHED_LEDGERS = ("claims_ledger.csv", "claims_ledger_kinematic_family.csv",
                     "claims_ledger_apf_alone.csv")


def published_ledgers(verdicts: Verdicts) -> dict[str, pd.DataFrame]:
    """The ledgers the report publishes that ``make verify`` compares with the reference
    (:data:`PUBLISHED_LEDGERS`, those present), after the answer's family-wise rule."""
    found = {}
    if verdicts.family is not None:
        found[PUBLISHED_LEDGERS[0]] = verdicts.family.ledger.to_frame()
    if verdicts.kinematic_family is not None:
        found[PUBLISHED_LEDGERS[1]] = verdicts.kinematic_family.ledger.to_frame()
    if verdicts.apf_alone is not None:
        found[PUBLISHED_LEDGERS[2]] = verdicts.apf_alone.ledger.to_frame()
    return found


def answer_outcomes(verdicts: Verdicts) -> pd.DataFrame:
    """Every row the answer publishes, its ledger named: ``ledger, claim, comparison,
    outcome`` (what must not depend on the bootstrap's seed)."""
    parts: list[tuple[str, object]] = []
    if verdicts.family is not None:
        parts.append(("family", verdicts.family.ledger))
        if verdicts.family.apf_adds is not None:
            parts.append(("family: baseline vs no APF", verdicts.family.apf_adds))
        windows = verdicts.family.c2_windows
        if windows is not None:
            other = windows.common if windows.in_ledger == "own" else windows.own
            parts.append(("family: C2 on the other window", other))
    if verdicts.kinematic_family is not None:
        parts.append(("Appendix-A family", verdicts.kinematic_family.ledger))
        if verdicts.kinematic_family.apf_adds is not None:
            parts.append(("Appendix-A: baseline vs no APF", verdicts.kinematic_family.apf_adds))
    if verdicts.apf_alone is not None:
        parts.append(("APF alone", verdicts.apf_alone.ledger))
    parts += [(f"peers ({p.track})", p.ledger) for p in verdicts.peers]
    if verdicts.nmpc is not None:
        parts.append(("nonlinear MPC", verdicts.nmpc.ledger))
    rows = [{"ledger": name, "claim": row.claim_id, "comparison": row.comparison,
             "outcome": str(row.outcome)} for name, ledger in parts
            for row in ledger]  # type: ignore[attr-defined]
    return pd.DataFrame(rows, columns=["ledger", "claim", "comparison", "outcome"])


def write_tables(inputs: ReportInputs, verdicts: Verdicts, table_dir: Path) -> None:
    """Write every table of the page into ``table_dir`` (see the module docstring)."""
    table_dir.mkdir(parents=True, exist_ok=True)
    if inputs.lateral is not None and verdicts.paper is not None:
        _track(inputs.lateral, verdicts.paper, "metrics_paper_scenario.csv",
               "claims_paper_scenario.csv", table_dir)
    if verdicts.ablation_effects is not None:
        verdicts.ablation_effects.to_csv(table_dir / "ablation_effects.csv", index=False)
    if verdicts.flips is not None:
        verdicts.flips.to_csv(table_dir / "interpretation_flips.csv", index=False)
    if inputs.kinematic is not None and verdicts.kinematic is not None:
        _track(inputs.kinematic, verdicts.kinematic, "metrics_kinematic_track.csv",
               "claims_kinematic_track.csv", table_dir)
    _ledgers(inputs, verdicts, table_dir)
    if inputs.collision_labels is not None:
        # every collision: the run's own label, the published one, who avoided it
        inputs.collision_labels.to_csv(table_dir / "collision_labels.csv", index=False)
    for sweep in inputs.sweeps:
        _sweep(sweep, table_dir)
    if inputs.multiverse is not None:
        inputs.multiverse.robustness.to_csv(table_dir / "multiverse_robustness.csv",
                                            index=False)
    if inputs.tune is not None:
        files = inputs.tune.table_files()
        for name in (TRIALS, HELDOUT, LEDGER_TUNED, SETTINGS_OUTCOMES):
            shutil.copyfile(files[name], table_dir / f"tune_{name}")


def _ledgers(inputs: ReportInputs, verdicts: Verdicts, table_dir: Path) -> None:
    """The family ledgers (lateral, Appendix-A track, the baseline against no APF, the APF by
    itself with its collisions with and without the MPC's half-planes), C2 on each run's own
    and on a common window, the outcome counts, and the model-validity tables."""
    if verdicts.family is not None:
        verdicts.family.ledger.to_frame().to_csv(table_dir / "claims_ledger.csv", index=False)
        pd.DataFrame(list(verdicts.family.counts)).to_csv(table_dir / "family_outcomes.csv",
                                                          index=False)
        if verdicts.family.apf_adds is not None:
            verdicts.family.apf_adds.to_frame().to_csv(
                table_dir / "claims_ledger_baseline_vs_no_apf.csv", index=False)
        windows = verdicts.family.c2_windows
        if windows is not None and windows.common:
            pd.DataFrame(windows.rows()).to_csv(table_dir / "claims_c2_common_window.csv",
                                                index=False)
    if verdicts.nmpc is not None:
        verdicts.nmpc.ledger.to_frame().to_csv(table_dir / "claims_ledger_nmpc.csv",
                                               index=False)
    if verdicts.kinematic_family is not None:
        kf = verdicts.kinematic_family
        kf.ledger.to_frame().to_csv(table_dir / "claims_ledger_kinematic_family.csv",
                                    index=False)
        if kf.apf_adds is not None:
            kf.apf_adds.to_frame().to_csv(
                table_dir / "claims_ledger_baseline_vs_no_apf_kinematic_family.csv",
                index=False)
    if verdicts.apf_alone is not None:
        alone = verdicts.apf_alone
        alone.ledger.to_frame().to_csv(table_dir / "claims_ledger_apf_alone.csv", index=False)
        with_ = {c["method"]: c["collisions"] for c in alone.counts_with}
        pd.DataFrame([{"method": c["method"], "scenarios": c["scenarios"],
                       "collisions_without_halfplanes": c["collisions"],
                       "collisions_unavoidable_without_halfplanes": c["collisions_unavoidable"],
                       "collisions_unavoidable_run_without_halfplanes":
                           c["collisions_unavoidable_run"],
                       "collisions_with_halfplanes": with_.get(c["method"])}
                      for c in alone.counts]).to_csv(table_dir / "apf_alone_collisions.csv",
                                                     index=False)
    if verdicts.peers:
        frames = []
        for judged in verdicts.peers:
            frame = judged.ledger.to_frame()
            frame.insert(0, "track", judged.track)
            frames.append(frame)
        pd.concat(frames, ignore_index=True).to_csv(table_dir / "claims_ledger_peers.csv",
                                                    index=False)
        pd.DataFrame([{"track": judged.track, "method": c["method"],
                       "scenarios": c["scenarios"], "collisions": c["collisions"],
                       "collisions_unavoidable": c["collisions_unavoidable"],
                       "collisions_unavoidable_run": c["collisions_unavoidable_run"],
                       "solve_time_median_s": inputs.solve_times.get(judged.track, {}).get(
                           c["method"], (None, None))[0],
                       "solve_time_p95_s": inputs.solve_times.get(judged.track, {}).get(
                           c["method"], (None, None))[1]}
                      for judged in verdicts.peers for c in judged.counts]
                     ).to_csv(table_dir / "peers_collisions.csv", index=False)
    if verdicts.pedestrians is not None:
        walkers = (verdicts.pedestrians, *verdicts.pedestrian_variants)
        pd.concat([j.frame() for j in walkers], ignore_index=True).to_csv(
            table_dir / "claims_ledger_pedestrians.csv", index=False)
        pd.DataFrame([{"scene": "all", **c} for c in verdicts.pedestrians.counts]
                     + list(verdicts.pedestrians.scene_counts)).to_csv(
            table_dir / "pedestrians_collisions.csv", index=False)
        pedestrian_metrics_frame(walkers).to_csv(table_dir / "pedestrians_metrics.csv",
                                                index=False)
        pd.DataFrame([row for j in walkers for row in j.other_pairs]).to_csv(
            table_dir / "claims_pedestrians_other_pairs.csv", index=False)
    if verdicts.validity is not None and inputs.validity is not None and has_validity(inputs):
        inputs.validity.table.to_frame().to_csv(table_dir / "model_validity.csv", index=False)
        pd.DataFrame(verdicts.validity.rows()).to_csv(table_dir / "claims_model_validity.csv",
                                                      index=False)


def pedestrian_metrics_frame(judged) -> pd.DataFrame:
    """``tables/pedestrians_metrics.csv``: per family (the default and each variant) and
    method, the crowd-navigation metrics with their intervals, after the family's description
    (``family, track, platform, draw, walkers``) and its difficulty from the recording alone
    (``straight_line_meets_share, standing_touched_share``, and the method's collision rate on
    the crossings where standing still is safe: all contacts, the avoidable ones, and those
    with a walker seen before the contact)."""
    rows = []
    for family in judged:
        if family.metrics is None:
            continue
        about = {k: family.about.get(k) for k in ("family", "track", "platform", "draw",
                                                   "walkers")}
        hard = family.difficulty
        for row in family.metrics.to_dict("records"):
            method = row.pop("method")
            rows.append({**about, "method": method, **row,
                         "straight_line_meets_share": hard.get("straight_line_meets_share"),
                         "standing_touched_share": hard.get("standing_touched_share"),
                         "collision_rate_standing_safe":
                             hard.get(f"collision_rate_standing_safe_{method}"),
                         "collision_rate_standing_safe_avoidable":
                             hard.get(f"collision_rate_standing_safe_avoidable_{method}"),
                         "collision_rate_standing_safe_seen":
                             hard.get(f"collision_rate_standing_safe_seen_{method}")})
    return pd.DataFrame(rows)


def has_validity(inputs: ReportInputs) -> bool:
    """Whether any family carries model checks (else there is no validity section)."""
    rows = inputs.validity.table.rows if inputs.validity is not None else ()
    return bool(rows) and any(np.isfinite(r.prediction_error_1s_p95_m) for r in rows)


def _track(runs: TrackRuns, claims: TrackClaims, metrics_name: str, claims_name: str,
           table_dir: Path) -> None:
    """A track's metrics on the paper scenario (a column per method) and its claims."""
    frame = pd.DataFrame(runs.metrics())
    frame.index.name = "metric"
    frame.to_csv(table_dir / metrics_name)
    pd.DataFrame(list(claims.rows)).to_csv(table_dir / claims_name, index=False)


#: A sweep's columns shown beside its swept keys (the claims' primary metrics and safety;
#: the full table is the sweep's own summary).
SWEEP_COLUMNS = ("method", "kind", "status", "collisions", "reaction_delay_s",
                 "lateral_jerk_rms_mps3", "repulsion_unneeded_share", "recovery_time_s",
                 "oscillation_count", "min_clearance_m", "reason")


def sweep_table(sweep) -> pd.DataFrame:
    """The columns of a sweep's summary the page shows."""
    swept = list(sweep.swept_keys)
    summary = sweep.summary
    shown = [k for k in swept if k in summary] + [c for c in SWEEP_COLUMNS
                                                  if c in summary and c not in swept]
    return summary[shown]


def sweep_verdicts(sweep) -> pd.DataFrame | None:
    """A sweep's verdicts with a ``setting`` column (the swept values, or the job)."""
    if sweep.verdicts is None:
        return None
    verdicts = sweep.verdicts.copy()
    value_keys = [k for k in sweep.swept_keys if k in verdicts and k != "method"]
    verdicts["setting"] = verdicts[value_keys].astype(str).agg(", ".join, axis=1) \
        if value_keys else verdicts["job"]
    return verdicts


def _sweep(sweep, table_dir: Path) -> None:
    sweep_table(sweep).to_csv(table_dir / f"sweep_{sweep.name}_summary.csv", index=False)
    verdicts = sweep_verdicts(sweep)
    if verdicts is not None:
        verdicts.to_csv(table_dir / f"sweep_{sweep.name}_verdicts.csv", index=False)
