"""Report stage: gather run folders into tables, figures and one self-contained HTML page.

``python -m pipeline.report RUNS_DIR [--out reports/latest]`` reads every complete run folder
under ``RUNS_DIR`` (it never simulates), writes ``index.html`` with figures inlined, and puts the
SVG/PNG figures and CSV tables beside it.
"""

from __future__ import annotations

import base64
import dataclasses
import datetime as dt
import functools
import html
import importlib.metadata
import logging
import math
import os
import platform
import subprocess
import time
import sys
from pathlib import Path

import jinja2
import numpy as np
import pandas as pd
import yaml

from pipeline.store.collection import RunCollection, load_runs
from pipeline.store.runs import Skipped, check, write_text_atomic
from pipeline.analysis.claims import (ALL_CLAIMS, OUTCOME_RULE, OUTCOMES, SINGLE_RULE, claims_table,
                             family_ledger, outcome_counts)
from pipeline.analysis.tally import Tally
from pipeline.config import INTERPRETATION_REGISTER, ClaimsConfig
from pipeline.reporting.figures import (apf_force_figure, claim_differences_figure,
                              family_distribution_figure, overlay_figure, paths_figure,
                              FigureWriter, timeseries_figure)
from pipeline.reporting.style import FigureStyle

log = logging.getLogger(__name__)

PACKAGES = ("numpy", "scipy", "pandas", "matplotlib", "control", "cvxpy", "clarabel",
            "hydra-core", "omegaconf", "jinja2")
METHOD_ORDER = ("baseline", "baseline_matched", "improved", "velocity_aware", "mpc_no_apf",
                "apf_pursuit")


def _rules(cfg: ClaimsConfig | None) -> dict:
    """Template values shared by every page: the rules and the margins with their reasons
    (none listed when no run carries claims settings, e.g. a sweep-only page)."""
    return {"family_rule": OUTCOME_RULE, "verdict_rule": SINGLE_RULE,
            "margins": [{"claim": c.claim_id, "margin": _fmt(cfg.margins[c.claim_id]),
                         "reason": cfg.margin_reasons[c.claim_id]} for c in ALL_CLAIMS]
            if cfg is not None else [],
            "claim_defs": ALL_CLAIMS}


def _git(*args: str) -> str:
    try:
        return subprocess.run(["git", *args], capture_output=True, text=True, check=True,
                              cwd=Path(__file__).resolve().parent).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def provenance(command: str) -> dict:
    """Command, git commit and dirty flag, package versions, date and machine."""
    versions = {}
    for name in PACKAGES:
        try:
            versions[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            versions[name] = "not installed"
    status = _git("status", "--porcelain")
    return {
        "command": command,
        "git_commit": _git("rev-parse", "HEAD"),
        "git_dirty": bool(status) and status != "unknown",
        "python": sys.version.split()[0],
        "packages": versions,
        "date_utc": dt.datetime.now(dt.timezone.utc).strftime("%Y-%m-%d %H:%M:%S UTC"),
        "machine": f"{platform.system()} {platform.machine()}, {os.cpu_count()} cores",
    }


def _lookup(config: dict, dotted: str):
    node = config
    for part in dotted.split("."):
        if not isinstance(node, dict) or part not in node:
            return None
        node = node[part]
    return node


def register_rows(configs_by_method: dict[str, dict]) -> list[dict]:
    """Interpretation register with the value each method's run used."""
    rows = []
    for entry in INTERPRETATION_REGISTER:
        keys = [k.strip() for k in entry.config_key.split(",")]
        # the value each run used, one line per distinct value ("all runs" when they agree)
        groups: dict[str, list[str]] = {}
        for method, config in configs_by_method.items():
            value = "; ".join(f"{_lookup(config, k)!s}" for k in keys)
            groups.setdefault(value, []).append(method)
        used = [("all runs" if len(groups) == 1 else ", ".join(methods), value)
                for value, methods in groups.items()]
        rows.append({"topic": entry.topic, "paper says": entry.paper_says,
                     "default reading": entry.default, "alternatives": entry.alternatives,
                     "config key": entry.config_key, "used": used})
    return rows


def _png_data_uri(path: Path) -> str:
    return "data:image/png;base64," + base64.b64encode(Path(path).read_bytes()).decode()


def _fmt(value) -> str:
    if value is None:
        return "—"
    if isinstance(value, (bool, np.bool_)):
        return "yes" if value else "no"
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    if isinstance(value, (float, np.floating)):
        if not np.isfinite(value):
            return "—"
        return f"{value:.3g}" if abs(value) >= 1e-3 or value == 0 else f"{value:.2e}"
    return html.escape(str(value))


def _ordered(methods) -> list[str]:
    """Known methods first in their order, labelled variants right after their method."""
    def rank(label: str) -> tuple:
        base = label.split(" (")[0].split(" #")[0]
        return (METHOD_ORDER.index(base) if base in METHOD_ORDER else len(METHOD_ORDER),
                base, label != base, label)

    return sorted(dict.fromkeys(methods), key=rank)


def _label(run: dict) -> str:
    return run["metrics"].get("label") or run["metrics"].get("method", "")


#: Where make reproduce writes each method's run: ``<runs>/<section>/<method>``. A run there is
#: the method's default and is judged before any other run of the same method.
CANONICAL_SECTIONS = ("paper", "family", "kinematic")


def _canonical(folder, method: str) -> bool:
    path = Path(str(folder)) if folder else None
    return path is not None and path.name == method and path.parent.name in CANONICAL_SECTIONS


def _choose_per_method(items: dict, method_of, kind: str, use: str, folder_of=None
                       ) -> tuple[dict, list[str]]:
    """One item per method and a note for every method given more than once. The pick: the
    run make reproduce wrote (``<section>/<method>``), else the one labelled with the bare
    method name, else the first; the note names it and the ones left out."""
    groups: dict[str, list[str]] = {}
    for label, item in items.items():
        groups.setdefault(method_of(label, item), []).append(label)
    chosen, notes = {}, []
    for method, labels in groups.items():
        canonical = [label for label in labels
                     if folder_of is not None and _canonical(folder_of(label, items[label]),
                                                             method)]
        pick = canonical[0] if canonical else method if method in labels else labels[0]
        chosen[method] = items[pick]
        if len(labels) > 1:
            why = "the run make reproduce wrote" if canonical else \
                "no run in make reproduce's place: the first"
            notes.append(f"{len(labels)} {kind} of {method} were given; {use} '{pick}' ({why}); "
                         f"left out of the claims: {'; '.join(x for x in labels if x != pick)} "
                         "(shown apart).")
    return chosen, notes


def _primary_tables(tables: dict[str, pd.DataFrame], info: dict[str, dict]
                    ) -> tuple[dict[str, pd.DataFrame], list[str]]:
    """One family table per method for the ledger."""
    return _choose_per_method(tables, lambda label, _: info.get(label, {}).get("method", label),
                              "families", "the ledger uses",
                              folder_of=lambda label, _: info.get(label, {}).get("dir"))


def _skipped_rows(skipped: list[Skipped], root: Path) -> list[dict]:
    rows = []
    for item in skipped:
        try:
            where = str(Path(item.folder).relative_to(root))
        except ValueError:
            where = str(item.folder)
        rows.append({"folder": where, "reason": item.reason})
    return rows


def _other_rows(runs: list[dict]) -> list[dict]:
    keys = ("collision", "min_clearance_m", "reaction_delay_s", "recovery_time_s",
            "time_to_goal_s")
    return [{"label": _label(r), "scenario": r["metrics"].get("scenario"),
             "track": r["metrics"].get("track"), "folder": str(r["dir"]),
             "values": [_fmt(r["metrics"].get(k)) for k in keys]} for r in runs]


def _primary(runs_by_label: dict[str, dict]) -> tuple[dict[str, dict], list[str]]:
    """One run per method for the claims."""
    return _choose_per_method(runs_by_label,
                              lambda label, run: run["metrics"].get("method", label), "runs",
                              "the claims use", folder_of=lambda label, run: run.get("dir"))


def is_sweep_folder(folder: Path) -> bool:
    """A multirun folder whose swept keys go beyond the method (a parameter sweep)."""
    import json

    path = Path(folder) / "swept_keys.json"
    if not path.is_file():
        return False
    swept = set(json.loads(path.read_text())["swept_keys"])
    return bool(swept - {"method", "run.method", "planner"})


def _ablation_section(run_root: Path, fig_dir: Path, table_dir: Path,
                      cfg: ClaimsConfig, writer: FigureWriter | None = None) -> dict | None:
    """Effects of each revision alone and left out, attribution sentences, interpretation flips."""
    writer = writer if writer is not None else FigureWriter(max_workers=1)
    from pipeline.studies.ablation import (ablation_effects, attribution_sentences, interpretation_flips,
                                   load_family_jobs)
    from pipeline.reporting.figures import ablation_forest_figure

    run_root = Path(run_root)
    from pipeline.studies.ablation import ablation_roles

    tables = load_family_jobs(run_root / "ablation") if (run_root / "ablation").is_dir() else {}
    flips = interpretation_flips(run_root / "interpretations", cfg)
    bundle, reference = ablation_roles(tables, cfg)
    if reference not in tables and flips is None:
        return None
    section = {"effects": [], "sentences": {}, "figures": [], "counts": [], "flips": [],
               "bundle": bundle, "reference": reference}
    if reference in tables and bundle in tables:
        effects = ablation_effects(tables, cfg)
        effects.to_csv(table_dir / "ablation_effects.csv", index=False)
        section["sentences"] = attribution_sentences(effects, tables, cfg)
        section["effects"] = [{**{k: _fmt(v) for k, v in r.items()},
                               "ci": f"[{_fmt(r['ci_low'])}, {_fmt(r['ci_high'])}]"}
                              for r in effects.to_dict("records")]
        section["counts"] = [{"configuration": label, "collisions": Tally.of(t).collisions,
                              "not_recovered": Tally.of(t).not_recovered,
                              "scenarios": len(t)} for label, t in tables.items()]
        section["figures"].append({
            "id": "ablation_forest", "group": "ablation",
            "paths": writer.save(ablation_forest_figure(effects, reference, bundle), fig_dir,
                                 "ablation_forest"),
            "caption": "Median paired effect versus the baseline with its 95 % bootstrap "
                       "interval, per claim: the improved bundle (blue), each revision added "
                       "alone to the baseline (green), the bundle without each revision (orange).",
            "alt": "Forest plot of ablation effects per claim"})
    if flips is not None:
        flips.to_csv(table_dir / "interpretation_flips.csv", index=False)
        section["flips"] = flips.to_dict("records")
    return section


def _robustness_section(multiverse_dir: Path | None, fig_dir: Path,
                        table_dir: Path) -> dict | None:
    """The multiverse (``make multiverse``), if it was run: per claim the default outcome, its
    robustness and the choice that moves it most; specification curves; per-dimension effects."""
    import json
    import shutil

    if multiverse_dir is None or not (Path(multiverse_dir) / "robustness.csv").is_file():
        return None
    folder = Path(multiverse_dir)
    reason = check(folder, "multiverse")
    if reason:
        raise ValueError(f"multiverse tables not trusted: {reason}")
    robust = pd.read_csv(folder / "robustness.csv")
    info = json.loads((folder / "space.json").read_text()) \
        if (folder / "space.json").is_file() else {}
    dims = pd.read_csv(folder / "dimensions.csv") if (folder / "dimensions.csv").is_file() \
        else pd.DataFrame()
    robust.to_csv(table_dir / "multiverse_robustness.csv", index=False)
    rows = {}
    for r in robust.to_dict("records"):
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
            "holds_with": r["holds_with"] if isinstance(r.get("holds_with"), str)
            and r["holds_with"] else "no single choice"}
    figures = []
    for claim in ALL_CLAIMS:
        png = folder / "figures" / f"specification_curve_{claim.claim_id}.png"
        if not png.is_file():
            continue
        fig_dir.mkdir(parents=True, exist_ok=True)
        stem = f"specification_curve_{claim.claim_id}"
        shutil.copyfile(png, fig_dir / f"{stem}.png")
        svg = folder / "figures" / f"{stem}.svg"
        if svg.is_file():
            shutil.copyfile(svg, fig_dir / f"{stem}.svg")
        figures.append({"id": stem, "group": "robustness",
                        "paths": {"png": fig_dir / f"{stem}.png", "svg": fig_dir / f"{stem}.svg"},
                        "caption": f"{claim.claim_id} ({claim.text}): the estimate with its 95 % "
                                   "interval in every specification, sorted, coloured by outcome, "
                                   "against each comparison; below, which choices each "
                                   "specification changes from the default.",
                        "alt": f"Specification curve of {claim.claim_id}"})
    dim_rows = []
    if len(dims):
        for (claim, comparison), part in dims.groupby(["claim", "comparison"], sort=False):
            if comparison != "baseline":
                continue
            for r in part.to_dict("records"):
                if r["default"] or r["flipped_share"] < 0.5:
                    continue
                dim_rows.append({"claim": claim, "dimension": r["dimension"],
                                 "value": r["value"], "flipped": f"{100 * r['flipped_share']:.0f} %",
                                 "outcome": r["modal_outcome"],
                                 "estimate": _fmt(r["median_estimate"])})
    return {"rows": list(rows.values()), "figures": figures, "dims": dim_rows,
            "n": info.get("n_specifications"), "n_sim": info.get("n_simulation_configurations"),
            "size": info.get("family_size"), "name": info.get("name"),
            "rule": info.get("rule", ""), "dimensions": info.get("dimensions", []),
            "backends": _backends_text(info.get("backends") or {})}


def _backends_text(backends: dict) -> str:
    """``daqp (baseline, improved); no QP (apf_pursuit)``: each QP backend with the methods
    whose runs used it (a multiverse's ``space.json``)."""
    by_backend: dict[str, list] = {}
    for method, backend in backends.items():
        by_backend.setdefault(str(backend), []).append(str(method))
    return "; ".join(f"{b} ({', '.join(m)})" for b, m in by_backend.items())


def _performance_section(bench_dir: Path | None, fig_dir: Path) -> dict | None:
    """The benchmark's summary (``make bench``), if it was run."""
    import json
    import shutil

    if bench_dir is None or not (Path(bench_dir) / "bench_summary.json").is_file():
        return None
    summary = json.loads((Path(bench_dir) / "bench_summary.json").read_text())
    figures = []
    png = Path(bench_dir) / "scaling.png"
    if png.is_file():
        fig_dir.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(png, fig_dir / "bench_scaling.png")
        svg = Path(bench_dir) / "scaling.svg"
        if svg.is_file():
            shutil.copyfile(svg, fig_dir / "bench_scaling.svg")
        figures.append({"id": "bench_scaling", "group": "performance",
                        "paths": {"png": fig_dir / "bench_scaling.png",
                                  "svg": fig_dir / "bench_scaling.svg"},
                        "caption": "Median controller step (APF rollout + QP) of both backends "
                                   "and the Clarabel floor versus the horizon N, per obstacle "
                                   "count.", "alt": "Step time versus horizon"})
    rows = [{k: _fmt(v) for k, v in r.items()} for r in summary["lateral"]]
    peers = [{"N": p["N"], "kept": _fmt(p["kept_cvxpy"]["median_ms"]),
              "rebuild": _fmt(p["rebuild_cvxpy"]["median_ms"]),
              "python_control": _fmt(p["python_control"]["median_ms"]),
              "ratio": _fmt(p["python_control_over_kept"]),
              "diff": _fmt(p["max_u0_diff_python_control"])} for p in summary["peers"]]
    return {"rows": rows, "peers": peers, "figures": figures,
            "pipeline": {k: _fmt(v) for k, v in summary["pipeline"].items()},
            "kinematic": {k: _fmt(v) for k, v in summary["kinematic"].items()},
            "n50": _fmt(summary.get("n50_over_n10_direct")),
            "headline": {k: _fmt(summary.get(k)) for k in (
                "closed_loop_over_floor", "step_over_floor", "compiles_per_family",
                "family_scenarios_per_s", "step_over_sparse_floor",
                "step_over_sparse_floor_daqp", "outside_qp_over_qp",
                "outside_qp_over_qp_python_kernels", "family_member_over_sparse_floor",
                "family_member_over_sparse_floor_daqp")}}


def _features_section(lateral: dict[str, dict], kinematic_runs: list[dict], run_root: Path,
                      clearance_m: float) -> dict | None:
    """'Does it look like the paper?': each phrase of the paper about its figures as a
    feature, present or absent, for baseline and improved on each track and reading; the
    rule that picks the Appendix-A reading (both methods meet the obstacle, most phrases
    matched) and whether the configured default is its pick."""
    from pipeline.analysis.features import FEATURES, FeatureConfig, feature_row, paper_likeness
    def pair(runs: list[dict]) -> dict[str, dict]:
        return {r["metrics"].get("method"): r for r in runs
                if r["metrics"].get("method") in ("baseline", "improved")}

    columns = [("lateral track", "default", {m: lateral[m] for m in ("baseline", "improved")
                                             if m in lateral})]
    kin = pair(kinematic_runs)
    if "baseline" in kin:
        columns.append(("Appendix-A track", _reading_of(kin["baseline"]["config"])
                        + " (default)", kin))
    for variant, runs in _readings_runs(run_root).items():
        columns.append(("Appendix-A track", variant, pair(runs)))
    columns = [c for c in columns if {"baseline", "improved"} <= set(c[2])]
    if not columns:
        return None
    settings = columns[0][2]["improved"]["config"].get("features") or {}
    cfg = FeatureConfig(**settings)
    cells = []
    for track, reading, runs in columns:
        rows = {m: feature_row(runs[m]["metrics"], cfg) for m in ("baseline", "improved")}
        met = all((runs[m]["metrics"].get("min_clearance_m") or math.inf) <= clearance_m
                  for m in ("baseline", "improved"))
        cells.append({"track": track, "reading": reading, "rows": rows, "met": met,
                      "score": paper_likeness(rows["baseline"], rows["improved"])})
    word = {True: "yes", False: "no", None: "—"}
    table = [{"phrase": f.phrase, "describes": f.describes, "rule": f.rule,
              "cells": [[word[c["rows"][m][f.key]] for m in ("baseline", "improved")]
                        for c in cells]} for f in FEATURES]
    kinematic = [c for c in cells if c["track"] == "Appendix-A track"]
    eligible = [c for c in kinematic if c["met"]]
    pick = max(eligible, key=lambda c: c["score"]) if eligible else None
    default = next((c for c in kinematic if c["reading"].endswith("(default)")), None)
    rule = ("The register's rule for the Appendix-A reading: among the readings under which "
            "both methods meet the obstacle, the one whose runs match most of the paper's "
            "phrases. ")
    if pick is None:
        rule_note = (rule + "No Appendix-A reading lets both methods meet the obstacle (within "
                     f"{clearance_m:g} m).") if kinematic else ""
    elif default is not None and pick["score"] == default["score"] and default["met"]:
        rule_note = rule + ("It picks the configured default ("
                            + default["reading"].replace(" (default)", "") + ").")
    else:
        rule_note = (rule + f"It picks <code>{pick['reading']}</code> ({pick['score']} of "
                     f"{len(FEATURES)} phrases); the configured default "
                     + (f"({default['reading']}) " if default else "") + "differs: change "
                     "conf/experiment/kinematic.yaml.")
    return {"columns": [{"track": c["track"], "reading": c["reading"], "score": c["score"],
                         "met": "yes" if c["met"] else "no"} for c in cells],
            "rows": table, "n": len(FEATURES), "rule_note": rule_note,
            "clearance": f"{clearance_m:g}"}


def _readings_runs(run_root: Path) -> dict[str, list[dict]]:
    """The Appendix-A readings' runs (``kinematic_readings``) by reading, in name order."""
    root = Path(run_root) / "kinematic_readings"
    by_variant: dict[str, list] = {}
    if root.is_dir():
        for r in load_runs(root, []).runs:
            by_variant.setdefault(r["config"]["run"].get("variant", "?"), []).append(r)
    return dict(sorted(by_variant.items()))


def _reading_of(baseline_config: dict) -> str:
    """Which Appendix-A reading a kinematic baseline run was made under."""
    if baseline_config.get("scenario", {}).get("obstacle_anchor", "world") == "vehicle":
        return "vehicle_anchor"
    alignment = baseline_config.get("controller", {}).get("reference_alignment", "literal")
    if alignment != "literal":
        return alignment
    return "literal" if baseline_config.get("planner", {}).get("normalize_step", True) \
        else "printed"


def _nmpc_check(folder: Path) -> dict:
    """The LTV-QP against the nonlinear MPC on the kinematic track (``make nmpc-check``)."""
    import json

    summary = json.loads((Path(folder) / "summary.json").read_text())
    summary = summary["tracks"].get("kinematic") if "tracks" in summary else summary
    if not summary:
        return None  # the check ran on the lateral track only
    differ = [f"{v['claim']} vs {v['comparison']}: {v['ltv']} (LTV) / {v['nmpc']} (NMPC)"
              for v in summary["verdicts"] if v["ltv"] != v["nmpc"]]
    return {"paper_path": _fmt(summary["paper"]["max_path_difference_m"]),
            "paper_steer": _fmt(summary["paper"]["max_steering_difference_rad"]),
            "paper_accel": _fmt(summary["paper"]["max_accel_difference_mps2"]),
            "family_path": _fmt(summary["family"]["max_path_difference_m"]),
            "family_median": _fmt(summary["family"]["median_of_max_path_difference_m"]),
            "family_apart": summary["family"].get("runs_over_half_metre"),
            "family_runs": summary["family"].get("runs"),
            "n_members": summary["n_members"], "agree": summary["verdicts_agree"],
            "differ": "; ".join(differ), "solve_median": _fmt(summary["nmpc_solve_median_ms"]),
            "solve_max": _fmt(summary["nmpc_solve_max_ms"]),
            "ltv_median": _fmt(summary["ltv_solve_median_ms"])}


def _fair_fight_section(tune_dir: Path | None, fig_dir: Path, table_dir: Path) -> dict | None:
    """The fair fight (``make tune``), if it was run: the budget and search spaces, per claim
    the default verdict beside the tuned-vs-tuned verdict on held-out scenarios, the settings
    that make each claim hold, the Pareto fronts on shared axes."""
    import json
    import shutil

    if tune_dir is None or not (Path(tune_dir) / "summary.json").is_file():
        return None
    folder = Path(tune_dir)
    reason = check(folder, "tune")
    if reason:
        raise ValueError(f"tuning tables not trusted: {reason}")
    summary = json.loads((folder / "summary.json").read_text())
    for name in ("trials.csv", "heldout.csv", "ledger_tuned.csv", "settings_outcomes.csv"):
        shutil.copyfile(folder / name, table_dir / f"tune_{name}")
    figures = []
    for part, words in (("training", "training family (where the settings were tuned)"),
                        ("heldout", "held-out family (scenarios the tuning never saw)")):
        stem = f"pareto_fronts_{part}"
        png = folder / "figures" / f"{stem}.png"
        if not png.is_file():
            continue
        fig_dir.mkdir(parents=True, exist_ok=True)
        for ext in ("png", "svg"):
            if (folder / "figures" / f"{stem}.{ext}").is_file():
                shutil.copyfile(folder / "figures" / f"{stem}.{ext}", fig_dir / f"{stem}.{ext}")
        figures.append({"id": f"tune_{stem}", "group": "fair fight",
                        "paths": {"png": fig_dir / f"{stem}.png", "svg": fig_dir / f"{stem}.svg"},
                        "caption": f"Each method's Pareto settings on the {words}, every pair "
                                   "of tuning objectives on shared axes (smaller is better).",
                        "alt": f"Pareto fronts of the tuned methods, {part}"})
    dominance = summary.get("dominance", {})
    methods = summary["settings"]["methods"]
    dom_text = []
    for part, words in (("training", "on the training family"),
                        ("heldout", "on the held-out family")):
        d = dominance.get(part)
        if d:
            dom_text.append(f"{words}, {methods[0]}'s Pareto settings dominate "
                            f"{d['treatment_dominates']} of {d['control_points']} of "
                            f"{methods[1]}'s, and {methods[1]}'s dominate "
                            f"{d['control_dominates']} of {d['treatment_points']} of "
                            f"{methods[0]}'s")
    rows = []
    for c in summary["claims"]:
        holds = c.get("holds_with_trials", [])
        rows.append({**c, "tuned_fmt": f"{_fmt(c['tuned_estimate'])} "
                                       f"[{_fmt(c['tuned_ci'][0])}, {_fmt(c['tuned_ci'][1])}] "
                                       f"{_unit(c['metric'])}",
                     "default_fmt": f"{_fmt(c['default_estimate'])} {_unit(c['metric'])}",
                     "holds": ("trials " + ", ".join(str(t) for t in holds)) if holds
                     else "none of the judged settings"})
    spaces = [{"method": m, "params": [{"key": k, "range": v} for k, v in space.items()]}
              for m, space in summary["search_spaces"].items()]
    return {"summary": summary, "rows": rows, "figures": figures, "spaces": spaces,
            "dominance": "; ".join(dom_text), "methods": methods,
            "compromise": {m: ", ".join(f"{k.split('.')[-1]} = {_fmt(v) if isinstance(v, float) else v}"
                                        for k, v in p.items())
                           for m, p in summary["compromise"].items()}}


def build_report(run_root: Path, out_dir: Path, command: str,
                 sweep_dirs: tuple[Path, ...] = (), bench_dir: Path | None = None,
                 multiverse_dir: Path | None = None,
                 skipped: list[Skipped] | None = None, tune_dir: Path | None = None,
                 treatment: str | None = None, controls: tuple[str, ...] = (),
                 style: FigureStyle | None = None, figure_jobs: int | None = None) -> Path:
    """Write ``out_dir/index.html`` (plus figures/ and tables/) from the runs under ``run_root``.

    Parameters
    ----------
    run_root : Path
        Folder with the paper, kinematic and family runs (``make reproduce``'s ``outputs``), or a
        parameter-sweep folder on its own.
    sweep_dirs : tuple of Path
        Aggregated sweep folders (``summary.csv``) to add as Sweep sections.
    skipped : list, optional
        Receives every folder passed over (:class:`pipeline.store.runs.Skipped`); they are also listed
        in the page and on stderr.

    style : FigureStyle, optional
        How figures are written (:func:`load_figure_style`); the default when omitted.
    figure_jobs : int, optional
        Figures drawn at the same time, each in a forked child (:class:`FigureWriter`); None:
        the machine's cores; 1: one after the other in this process. The files are the same.

    Returns
    -------
    Path
        The HTML file.
    """
    import matplotlib

    style = style or FigureStyle()
    # figures drawn in forked children beside the ledgers' bootstraps (the writer waits for
    # them before the page inlines the PNGs, and on any way out of this block)
    with matplotlib.rc_context(style.rc()), FigureWriter(style, figure_jobs) as writer:
        return _build_report(run_root, out_dir, command, sweep_dirs, bench_dir,
                             multiverse_dir, skipped, tune_dir, treatment, controls, writer)


def _build_report(run_root, out_dir, command, sweep_dirs, bench_dir, multiverse_dir, skipped,
                  tune_dir, treatment, controls, writer: FigureWriter) -> Path:
    """:func:`build_report` inside the figure style's matplotlib settings, its figures written
    by ``writer``."""
    out_dir = Path(out_dir)
    fig_dir, table_dir = out_dir / "figures", out_dir / "tables"
    table_dir.mkdir(parents=True, exist_ok=True)
    started = time.perf_counter()

    def progress(step: str) -> None:
        """A plain line per stage on stderr, with the time so far (the report takes a while)."""
        log.info("report: %s (%.0f s)", step, time.perf_counter() - started)

    sweep_dirs = tuple(Path(d) for d in sweep_dirs)
    skipped = skipped if skipped is not None else []
    if is_sweep_folder(run_root):
        sweep_dirs, collection = (Path(run_root),) + sweep_dirs, RunCollection()
    else:
        progress("reading the run folders")
        collection = load_runs(run_root, skipped)
    runs, family_tables, family_info = (collection.runs, collection.family_tables,
                                        collection.family_info)
    for item in skipped:
        log.warning("skipped %s: %s", item.folder, item.reason)
    def optional(section, folder, *args):
        """An optional section whose files are broken is left out and listed, not a crash."""
        try:
            return section(folder, *args)
        except (OSError, ValueError, KeyError, TypeError, IndexError,
                pd.errors.ParserError) as exc:
            reason = f"{section.__name__.strip('_').replace('_', ' ')} left out " \
                     f"({type(exc).__name__}: {str(exc).splitlines()[0][:120] if str(exc) else ''})"
            skipped.append(Skipped(Path(folder), reason))
            log.warning("skipped %s: %s", folder, reason)
            return None

    sweeps = [sw for sw in (optional(_sweep_section, d, fig_dir, table_dir) for d in sweep_dirs)
              if sw is not None]
    performance = optional(_performance_section, bench_dir, fig_dir) if bench_dir else None
    if multiverse_dir is None and (Path(run_root) / "multiverse" / "robustness.csv").is_file():
        multiverse_dir = Path(run_root) / "multiverse"
    robustness = optional(_robustness_section, multiverse_dir, fig_dir, table_dir) \
        if multiverse_dir else None
    if tune_dir is None and (Path(run_root) / "tune" / "summary.json").is_file():
        tune_dir = Path(run_root) / "tune"
    fair_fight = optional(_fair_fight_section, tune_dir, fig_dir, table_dir) \
        if tune_dir else None
    env = jinja2.Environment(loader=jinja2.PackageLoader("pipeline.reporting", "templates"),
                             autoescape=jinja2.select_autoescape(["html", "j2"]),
                             undefined=jinja2.StrictUndefined)
    if not runs:
        if not sweeps:
            raise FileNotFoundError(f"no single runs (the paper scenario) under {run_root}")
        figures = [f for sw in sweeps for f in sw["figures"]]
        figures += performance["figures"] if performance else []
        writer.close()  # every figure on disk before the page inlines them
        _inline(figures, out_dir)
        page = env.get_template("report.html.j2").render(
            answer=[], caveat="", paper=False, sweeps=sweeps, performance=performance, robustness=None, fair_fight=None, looks=None, ablation=None, figures=figures, family=None, kinematic=None, validity=None,
            skipped=_skipped_rows(skipped, run_root), other_runs=[], run_notes=[],
            methods=[], scenario="(sweep only)", prov=provenance(command),
            register=register_rows({}), metrics_doc=_metrics_doc(), **_rules(None))
        path = out_dir / "index.html"
        write_text_atomic(path, page)
        return path
    scenario = "paper_sudden_obstacle"
    kinematic_runs = [r for r in runs if r["metrics"].get("track") == "kinematic"]
    runs = [r for r in runs if r["metrics"].get("track", "lateral") == "lateral"] or runs
    paper_runs = [r for r in runs if r["metrics"]["scenario"] == scenario] or runs
    scenario = paper_runs[0]["metrics"]["scenario"]
    other_runs = [r for r in runs if r["metrics"]["scenario"] != scenario]
    by_label = {_label(r): r for r in paper_runs}
    primary, run_notes = _primary({m: by_label[m] for m in _ordered(by_label)})
    # the judged run of each method everywhere; extra runs of a method apart ("other runs":
    # their own colour and label in the overlay, their numbers under "Runs given")
    order = _ordered(primary)
    by_method = {m: primary[m] for m in order}
    judged = {id(r) for r in by_method.values()}
    extra_runs = [r for r in by_label.values() if id(r) not in judged]
    other_runs = extra_runs + other_runs
    first_cfg = next(iter(by_method.values()))["config"]
    goal = tuple(first_cfg["scenario"]["goal_xy_m"])
    radius = first_cfg["vehicle"]["footprint_radius_m"]
    appear = next(iter(by_method.values()))["metrics"].get("obstacle_appear_time_s")
    progress("paper-scenario figures")
    figures = _paper_figures(by_method, scenario, goal, radius, appear, fig_dir,
                             treatment=treatment or "improved",
                             control=controls[0] if controls else "baseline",
                             extras={_label(r): r["trajectory"] for r in extra_runs},
                             writer=writer)

    metrics_by_method = {m: r["metrics"] for m, r in by_method.items()}
    metrics_frame = pd.DataFrame(metrics_by_method)
    metrics_frame.index.name = "metric"
    metrics_frame.to_csv(table_dir / "metrics_paper_scenario.csv")
    skip = {"method", "scenario", "config_hash", "track"}
    metric_rows = [{"metric": k, "values": [_fmt(metrics_by_method[m].get(k)) for m in order]}
                   for k in metrics_frame.index if k not in skip]
    timing_rows = [{"method": m,
                    "median_ms": _fmt(_ms(r["timing"]["solve_time_median_s"])),
                    "p95_ms": _fmt(_ms(r["timing"]["solve_time_p95_s"])),
                    "max_ms": _fmt(_ms(r["timing"]["solve_time_max_s"])),
                    "compile_s": _fmt(r["timing"]["compile_time_s"]),
                    "compiles": _fmt(r["metrics"].get("compile_count"))}
                   for m, r in by_method.items()]
    # the claims settings the runs were made with, never defaults rebuilt from text; what is
    # compared with what: the command's --treatment/--controls, else those settings'
    cfg_claims = collection.claims_settings(treatment or "improved") \
        or collection.claims_settings("improved") or ClaimsConfig()
    cfg_claims = dataclasses.replace(
        cfg_claims, treatment=treatment or cfg_claims.treatment,
        controls=list(controls) if controls else list(cfg_claims.controls))
    comparisons = tuple(c for c in cfg_claims.controls if c in primary)
    claim_metrics = {**metrics_by_method, **{m: r["metrics"] for m, r in primary.items()}}
    claims = claims_table(claim_metrics, cfg_claims.margins, comparisons,
                          improved=cfg_claims.treatment)
    pd.DataFrame(claims).to_csv(table_dir / "claims_paper_scenario.csv", index=False)
    for row in claims:
        row["values"] = [_fmt(row.get(m)) for m in order]
    claim_secondary = {c.claim_id: ", ".join(c.secondary_metrics) for c in ALL_CLAIMS}

    ablation = _ablation_section(run_root, fig_dir, table_dir, cfg_claims, writer)
    if ablation:
        figures.extend(ablation["figures"])

    kinematic = None
    if kinematic_runs:
        progress("Appendix-A track")
        kinematic = _track_section(kinematic_runs, "kinematic", fig_dir, table_dir, claims,
                                   cfg_claims, writer)
        kinematic["nmpc"] = optional(_nmpc_check, Path(run_root) / "nmpc_check") \
            if (Path(run_root) / "nmpc_check" / "summary.json").is_file() else None
        figures.extend(kinematic["figures"])
    looks = _features_section(by_method, kinematic_runs, run_root,
                              cfg_claims.comparable_clearance_m)

    family = None
    family_primary, family_notes = _primary_tables(family_tables, family_info)
    run_notes += family_notes
    if cfg_claims.treatment in family_primary \
            and any(c in family_primary for c in cfg_claims.controls):
        progress("family ledger (bootstrap intervals) and figures")
        family = _family_section(family_primary, family_info, claim_metrics, fig_dir,
                                 table_dir, cfg_claims, all_tables=family_tables,
                                 settings=collection.family_settings, writer=writer)
        for f in family["figures"]:
            figures.append(f)
    validity = None
    if family is not None:
        progress("does the MPC's model hold? (model checks of every family)")
        from pipeline.reporting.validity_section import validity_section

        validity = optional(validity_section, Path(run_root), family_primary, cfg_claims,
                            table_dir)
    if kinematic is not None:
        lateral_outcomes = {c: str(r.get("outcome")) for c, r in
                            (family["by_claim"].items() if family else ())}
        kin_family_dir = Path(run_root) / "kinematic_family"
        kinematic["family"] = optional(_kinematic_family_section, kin_family_dir, cfg_claims,
                                       table_dir, lateral_outcomes) \
            if kin_family_dir.is_dir() else None
        kinematic["readings"] = _reading_sensitivity(run_root, kinematic_runs, cfg_claims)
    for sw in sweeps:
        figures.extend(sw["figures"])
    figures += performance["figures"] if performance else []
    figures += robustness["figures"] if robustness else []
    figures += fair_fight["figures"] if fair_fight else []
    writer.close()  # every figure on disk before the page inlines them
    _inline(figures, out_dir)
    progress("writing the page")
    answer = answer_rows(family, robustness, fair_fight, kinematic, cfg_claims)
    caveat = validity_caveat(family["raw_counts"]) if family else ""
    page = env.get_template("report.html.j2").render(
        answer=answer, caveat=caveat, paper=True, sweeps=sweeps, performance=performance, robustness=robustness,
        fair_fight=fair_fight, looks=looks, scenario=scenario, ablation=ablation, methods=order, figures=figures, metric_rows=metric_rows,
        timing_rows=timing_rows, claims=claims, claim_secondary=claim_secondary,
        comparisons=comparisons, family=family, kinematic=kinematic, validity=validity,
        register=register_rows({m: r["config"] for m, r in by_method.items()}),
        configs={m: yaml.safe_dump(r["config"], sort_keys=False) for m, r in by_method.items()},
        hashes={m: r["metrics"]["config_hash"] for m, r in by_method.items()},
        run_dirs={m: str(r["dir"]) for m, r in by_method.items()},
        metrics_doc=_metrics_doc(), prov=provenance(command),
        skipped=_skipped_rows(skipped, run_root), other_runs=_other_rows(other_runs),
        run_notes=run_notes, **_rules(cfg_claims))
    path = out_dir / "index.html"
    write_text_atomic(path, page)
    # the answer in words, for the command line (make reproduce prints it at its end)
    answer = list(family["answer"]) if family else []
    if fair_fight:
        answer += [c["sentence"] for c in fair_fight["rows"]]
    if family:
        # before the verdicts: the last lines stay the verdicts in words
        answer.insert(0, "Collisions: " + ", ".join(f"{c['method']} {c['collisions']}"
                                                    for c in family["raw_counts"]) + "."
                      + (f" {caveat}" if caveat else ""))
    if kinematic and kinematic.get("family"):
        kf = kinematic["family"]
        answer.append(f"Appendix-A track ({kf['size']} scenarios): {kf['treatment']} vs baseline "
                      + "; ".join(f"{r['claim']} {r['outcome']}" for r in kf["rows"]
                                  if r["comparison"] == "baseline")
                      + (f". {kf['apf_adds']['sentence']}" if kf["apf_adds"] else "."))
    write_text_atomic(out_dir / "answer.txt", "\n".join(answer) + "\n" if answer else "")
    return path


def _inline(figures: list[dict], out_dir: Path) -> None:
    for f in figures:
        f["src"] = _png_data_uri(f["paths"]["png"])
        f["svg"] = os.path.relpath(f["paths"]["svg"], out_dir)


def _sweep_section(sweep_dir: Path, fig_dir: Path, table_dir: Path) -> dict:
    """Summary table, metric-vs-parameter figures and verdicts per swept value of a sweep."""
    import json
    import shutil

    from pipeline.studies.aggregate import aggregate, summary_reason

    sweep_dir = Path(sweep_dir)
    reason = summary_reason(sweep_dir)
    if reason is not None:
        # a summary is a cache of its jobs: recomputed, never trusted without its manifest
        if reason != "not computed yet":
            log.warning("report: re-aggregating %s: summary.csv %s", sweep_dir, reason)
        aggregate(sweep_dir, progress=False)
    summary = pd.read_csv(sweep_dir / "summary.csv")
    keys = json.loads((sweep_dir / "swept_keys.json").read_text())
    swept = keys["swept_keys"]
    name = sweep_dir.name
    # the claims' primary metrics and safety; the full table is summary.csv
    shown = [k for k in swept if k in summary] + [c for c in ("method", "kind", "status",
                                                              "collisions",
                                                              "reaction_delay_s",
                                                              "lateral_jerk_rms_mps3",
                                                              "repulsion_unneeded_share",
                                                              "recovery_time_s",
                                                              "oscillation_count",
                                                              "min_clearance_m", "reason")
                                                  if c in summary and c not in swept]
    table = summary[shown]
    table.to_csv(table_dir / f"sweep_{name}_summary.csv", index=False)
    figures = []
    for png in sorted((sweep_dir / "figures").glob("*.png")):
        svg = png.with_suffix(".svg")
        fig_dir.mkdir(parents=True, exist_ok=True)
        target_png, target_svg = fig_dir / f"{name}_{png.name}", fig_dir / f"{name}_{svg.name}"
        shutil.copyfile(png, target_png)
        if svg.is_file():
            shutil.copyfile(svg, target_svg)
        figures.append({"id": f"{name}_{png.stem}", "group": f"sweep_{name}",
                        "paths": {"png": target_png, "svg": target_svg},
                        "caption": f"Sweep {name}: claim metrics versus "
                                   f"{', '.join(k for k in swept if k != 'method')} "
                                   "(lines: median per method, band: range over family seeds; "
                                   "heatmaps: median per cell).",
                        "alt": f"Metrics versus swept parameters of sweep {name}"})
    verdict_rows, verdict_cols = [], []
    if (sweep_dir / "verdicts.csv").is_file():
        verdicts = pd.read_csv(sweep_dir / "verdicts.csv")
        value_keys = [k for k in swept if k in verdicts and k != "method"]
        verdicts["setting"] = verdicts[value_keys].astype(str).agg(", ".join, axis=1) \
            if value_keys else verdicts["job"]
        pivot = verdicts.pivot_table(index="setting", columns="claim", values="verdict",
                                     aggfunc="first")
        verdict_cols = list(pivot.columns)
        verdict_rows = [{"setting": idx, "verdicts": [str(v) for v in row.values],
                         "basis": verdicts.loc[verdicts["setting"] == idx, "basis"].iloc[0]}
                        for idx, row in pivot.iterrows()]
        verdicts.to_csv(table_dir / f"sweep_{name}_verdicts.csv", index=False)
    return {"name": name, "dir": str(sweep_dir), "swept": swept, "columns": shown,
            "rows": [[_fmt(v) for v in r] for r in table.itertuples(index=False)],
            "figures": figures, "verdict_cols": verdict_cols, "verdict_rows": verdict_rows,
            "value_keys": ", ".join(k for k in swept if k != "method")}


def _ms(seconds) -> float | None:
    return None if seconds is None else 1e3 * seconds


def _track_section(runs: list[dict], track: str, fig_dir: Path, table_dir: Path,
                   lateral_claims: list[dict], cfg: ClaimsConfig,
                   writer: FigureWriter | None = None) -> dict:
    """Figures, metrics and claims of a second track, and how its outcomes compare.

    A comparison is made only when both methods come within ``cfg.comparable_clearance_m`` of
    the obstacle: otherwise they did not meet the same threat and the claim is "not comparable".
    """
    by_label = {_label(r): r for r in runs}
    primary, _ = _primary({m: by_label[m] for m in _ordered(by_label)})
    order = _ordered(primary)
    by_method = {m: primary[m] for m in order}
    first = next(iter(by_method.values()))
    config = first["config"]
    figures = _paper_figures(by_method, first["metrics"]["scenario"],
                             tuple(config["scenario"]["goal_xy_m"]),
                             config["vehicle"]["footprint_radius_m"],
                             first["metrics"].get("obstacle_appear_time_s"), fig_dir,
                             prefix=f"{track}_", group_prefix=f"{track}_", writer=writer)
    metrics_by_method = {m: r["metrics"] for m, r in by_method.items()}
    frame = pd.DataFrame(metrics_by_method)
    frame.index.name = "metric"
    frame.to_csv(table_dir / f"metrics_{track}_track.csv")
    skip = {"method", "scenario", "config_hash", "track"}
    metric_rows = [{"metric": k, "values": [_fmt(metrics_by_method[m].get(k)) for m in order]}
                   for k in frame.index if k not in skip]
    comparisons = tuple(c for c in cfg.controls if c in primary)
    claim_metrics = {**metrics_by_method, **{m: r["metrics"] for m, r in primary.items()}}
    claims = claims_table(claim_metrics, cfg.margins, comparisons, improved=cfg.treatment)

    def met(method: str) -> bool:
        clearance = claim_metrics.get(method, {}).get("min_clearance_m")
        return clearance is not None and clearance <= cfg.comparable_clearance_m

    comparability = []
    for comparison in comparisons:
        if not (met(comparison) and met(cfg.treatment)):
            far = [m for m in (comparison, cfg.treatment) if not met(m)]
            comparability.append(f"vs {comparison}: not comparable ({', '.join(far)} never "
                                 f"came within {cfg.comparable_clearance_m:g} m).")
            rates = {c.claim_id for c in ALL_CLAIMS if c.is_rate}
            for row in claims:
                if row["claim"] not in rates:
                    row[f"vs {comparison}"] = "not comparable"
        else:
            comparability.append(f"vs {comparison}: comparable.")
    for row in claims:
        row["values"] = [_fmt(row.get(m)) for m in order]
    lateral = {r["claim"]: r.get("vs baseline", "n/a") for r in lateral_claims}
    comparison_rows = []
    for r in claims:
        ours = r.get("vs baseline", "n/a")
        agree = "n/a" if ours == "not comparable" else ("yes" if lateral.get(r["claim"]) == ours
                                                        else "no")
        comparison_rows.append({"claim": r["claim"], "lateral": lateral.get(r["claim"], "n/a"),
                                "other": ours, "agree": agree})
    pd.DataFrame(claims).drop(columns=["values"]).to_csv(table_dir / f"claims_{track}_track.csv",
                                                          index=False)
    return {"methods": order, "figures": figures, "metric_rows": metric_rows, "claims": claims,
            "comparison": comparison_rows, "comparability": comparability,
            "comparable_clearance": _fmt(cfg.comparable_clearance_m),
            "n_steps": config["scenario"]["n_steps"],
            "initial_speed": config["scenario"].get("initial_speed_mps")}


def _paper_figures(by_method: dict, scenario: str, goal: tuple, radius: float, appear,
                   fig_dir: Path, prefix: str = "", group_prefix: str = "",
                   treatment: str = "improved", control: str = "baseline",
                   extras: dict | None = None, writer: FigureWriter | None = None
                   ) -> list[dict]:
    """Figure 2/3 analogues (control above treatment, shared limits, time colours), overlay
    of every method (and of ``extras``, other runs by label, each in its own colour), time
    series with the avoidance window, APF forces."""
    writer = writer if writer is not None else FigureWriter(max_workers=1)
    pair = [m for m in (control, treatment) if m in by_method] or list(by_method)[:2]
    names = {control: "Figure 2 analogue", treatment: "Figure 3 analogue"} \
        if (control, treatment) == ("baseline", "improved") else {}
    titles = {m: f"{names.get(m, m)}: {m}" if m in names else m for m in pair}
    figures = [{"id": f"{prefix}trajectory_pair", "group": f"{group_prefix}paths",
                "paths": writer.save(functools.partial(
                    paths_figure, {m: by_method[m]["trajectory"] for m in pair}, goal, radius,
                    appear, titles=titles), fig_dir, f"{prefix}trajectory_pair"),
                "caption": f"{' and '.join(titles.values())} on {scenario}, on shared axes: the "
                           "path; the footprint and the obstacles at the same instants in the "
                           "same colour (colour bar: time from the obstacle's appearance); x "
                           "where an obstacle appears; the segment at the closest approach with "
                           "its clearance and time.",
                "alt": f"Paths of {' and '.join(pair)} with the obstacle at the same instants"}]
    tr_by_method = {m: r["trajectory"] for m, r in by_method.items()}
    for stem, fig, caption, alt in (
            ("overlay", functools.partial(overlay_figure, {**tr_by_method, **(extras or {})},
                                          goal),
             "Every method's path on the same axes, each in its own colour and line style"
             + (" (other runs, not judged, labelled by what differs)" if extras else "")
             + "; the grey band is the obstacle's track while visible.",
             "Paths of all methods overlaid"),
            ("timeseries", functools.partial(timeseries_figure, tr_by_method, appear),
             "Steering angle, steering rate (the input), heading and lateral deviation over "
             "time; shaded: the avoidance window, from the obstacle's appearance until every "
             "vehicle has passed it.", "Time series of steering, heading and lateral deviation"),
            ("apf_forces", functools.partial(apf_force_figure, tr_by_method),
             "Magnitude of the APF's repulsive and attractive forces at the vehicle's position "
             "(first rollout point).", "APF force magnitudes over time")):
        figures.append({"id": prefix + stem,
                        "group": f"{group_prefix}{'paths' if stem == 'overlay' else 'series'}",
                        "paths": writer.save(fig, fig_dir, prefix + stem),
                        "caption": caption, "alt": alt})
    return figures


def _unit(metric: str) -> str:
    """The unit of a metric, read off its name."""
    for suffix, unit in (("_mps3", "m/s^3"), ("_rad_s", "rad/s"), ("_s", "s"), ("_m", "m")):
        if metric.endswith(suffix):
            return unit
    if metric == "collision":
        return "collision rate"
    if "share" in metric:
        return "share"
    return "count" if metric.endswith("count") else ""


def answer_rows(family: dict | None, robustness: dict | None, fair_fight: dict | None,
                kinematic: dict | None, cfg: ClaimsConfig) -> list[dict]:
    """The answer in words for the top of the report: per claim its words, the family outcome
    against the first control with the estimate, unit and interval, the other controls'
    outcomes, and (when run) its robustness over the multiverse, the tuned-vs-tuned outcome
    and the Appendix-A track's outcome."""
    if not family:
        return []
    by_claim: dict[str, list[dict]] = {}
    for row in family["ledger"]:
        by_claim.setdefault(row["claim"], []).append(row)
    robust = {r["claim"]: r["cells"] for r in (robustness or {}).get("rows", [])}
    tuned = {r["claim"]: r for r in (fair_fight or {}).get("rows", [])}
    kin = {r["claim"]: r for r in ((kinematic or {}).get("family") or {}).get("rows", [])
           if r["comparison"] == (cfg.controls[0] if cfg.controls else "baseline")}
    out = []
    for claim in ALL_CLAIMS:
        rows = by_claim.get(claim.claim_id)
        if not rows:
            continue
        main, others = rows[0], rows[1:]
        unit = _unit(claim.primary_metric)
        extra = [f"vs {r['comparison']}: {r['outcome']}" for r in others]
        cell = robust.get(claim.claim_id, {}).get(main["comparison"])
        if cell:
            extra.append(f"{cell['agree']} of the multiverse's specifications agree")
        if claim.claim_id in tuned:
            extra.append(f"tuned vs tuned: {tuned[claim.claim_id]['tuned']}")
        if claim.claim_id in kin:
            extra.append(f"Appendix-A track: {kin[claim.claim_id]['outcome']}")
        out.append({"claim": claim.claim_id, "words": claim.text, "outcome": main["outcome"],
                    "comparison": main["comparison"],
                    "effect": f"{_fmt(main['estimate'])} {unit} [{_fmt(main['ci_low'])}, "
                              f"{_fmt(main['ci_high'])}]".replace("  ", " "),
                    "extra": "; ".join(extra)})
    return out


def validity_caveat(counts: list[dict]) -> str:
    """How often each method left the MPC model's small-angle validity (family counts)."""
    parts = [f"{c['method']} in {c['heading_validity_exceeded']} of {c['scenarios']}"
             for c in counts if c.get("heading_validity_exceeded")]
    if not parts:
        return ""
    return ("Caveat: the MPC's model leaves its small-angle validity bound "
            "(model.validity_heading_rad: the plant's heading error in the model's own frame "
            "over a prediction's second) in some scenarios: " + ", ".join(parts)
            + "; the predictions there are the linear model's, not the plant's (see "
            "\"Does the MPC's model hold?\").")


def answer_lines(ledger) -> list[str]:
    """The answer in words: one line per claim, its outcome against each comparison with the
    estimate, its unit and interval (what ``make reproduce`` prints at its end)."""
    lines = []
    for claim in ALL_CLAIMS:
        parts = []
        for row in ledger:
            if row.claim_id != claim.claim_id:
                continue
            r = row.result
            parts.append(f"{row.outcome} vs {row.comparison} ({_fmt(r.estimate)} "
                         f"[{_fmt(r.ci_low)}, {_fmt(r.ci_high)}] {_unit(claim.primary_metric)})")
        if parts:
            lines.append(f"{claim.claim_id} {claim.text}: " + "; ".join(parts))
    return lines


def _family_section(tables: dict, info: dict, paper_metrics: dict, fig_dir: Path,
                    table_dir: Path, cfg: ClaimsConfig, all_tables: dict | None = None,
                    settings: dict | None = None, writer: FigureWriter | None = None) -> dict:
    """Claims ledger over the family (C0-C5 against each comparison), outcome counts,
    distribution plots and what the step cap does."""
    writer = writer if writer is not None else FigureWriter(max_workers=1)
    order = _ordered(tables)
    tables = {m: tables[m] for m in order}
    typed = family_ledger(tables, cfg, paper_metrics, cfg.treatment, tuple(cfg.controls))
    typed.to_frame().to_csv(table_dir / "claims_ledger.csv", index=False)
    ledger = typed.records()
    counts = outcome_counts({m: all_tables[m] for m in _ordered(all_tables)}
                            if all_tables else tables)
    pd.DataFrame(counts).to_csv(table_dir / "family_outcomes.csv", index=False)
    for row in ledger:
        row["unit"] = _unit(row["metric"])
        row["estimate_fmt"] = _fmt(row["estimate"])
        row["ci_fmt"] = f"[{_fmt(row['ci_low'])}, {_fmt(row['ci_high'])}]"
        row["p_fmt"] = _fmt(row["p_holm"])
        row["pi_fmt"] = (f"{_fmt(row['prob_improvement'])} [{_fmt(row['pi_low'])}, "
                         f"{_fmt(row['pi_high'])}]")
        row["pi_main"] = _fmt(row["prob_improvement"])
        row["pi_ci"] = f"[{_fmt(row['pi_low'])}, {_fmt(row['pi_high'])}]"
        row["counts_fmt"] = (f"{row['n_better']} / {row['n_tied']} / {row['n_worse']} / "
                             f"{row['n_missing']}")
        row["margin_fmt"] = _fmt(row["margin"])
    # group the rows by claim for the table (one row group per claim)
    by_claim_rows = {}
    for row in ledger:
        by_claim_rows.setdefault(row["claim"], []).append(row)
    grouped = []
    for claim_rows in by_claim_rows.values():
        for i, row in enumerate(claim_rows):
            row["first"], row["span"] = i == 0, len(claim_rows)
            grouped.append(row)
    comparisons = [{"name": c, "rows": [r for r in ledger if r["comparison"] == c]}
                   for c in cfg.controls if any(r["comparison"] == c for r in ledger)]
    cap = {c["method"]: c["step_cap_binding_share"] for c in counts}
    cap_note = ""
    share = cap.get("improved")
    if share is not None and np.isfinite(share):
        cap_note = (f"The improved rollout's step cap binds on {100 * share:.0f} % of its steps "
                    f"over the family.")
        if share >= cfg.cap_binding_share:
            cap_note += (" On those steps two of the paper's revisions are inactive: 'no "
                         "normalization' and 'a larger step' change nothing, and the rollout is a "
                         "normalized step of the cap's length; the comparison with "
                         "baseline_matched isolates the remaining revisions.")
    differences = typed.differences
    intervals = {row.key: (row.result.ci_low, row.result.ci_high, row.result.estimate)
                 for row in typed}
    names = {c.claim_id: c.primary_metric for c in ALL_CLAIMS}
    figures = [
        {"id": "claim_differences", "group": "claims",
         "paths": writer.save(claim_differences_figure(differences, names, intervals), fig_dir,
                              "claim_differences"),
         "caption": "Per-scenario paired differences improved − comparison on each claim's "
                    "primary metric (below zero: improved better), with the estimate's 95 % "
                    "bootstrap interval, against each comparison.",
         "alt": "Scatter of paired differences per claim with estimate and confidence interval"},
        {"id": "family_distributions", "group": "family",
         "paths": writer.save(family_distribution_figure(tables, [c.primary_metric
                                                                  for c in ALL_CLAIMS[1:]]
                                                         + ["min_clearance_m"]),
                              fig_dir, "family_distributions"),
         "caption": "Distribution of each claim's metric and of the minimum clearance per method "
                    "over the scenario family (missing values, e.g. never recovered, are "
                    "left out of the boxes and counted in the outcomes table).",
         "alt": "Box plots of metrics per method over the scenario family"},
    ]
    first = next(iter(info.values())) if info else {"seed": "?", "size": len(
        next(iter(tables.values())))}
    solvers = "; ".join(
        f"{label}: {s.controller.kind}"
        + (f" ({s.controller.formulation} QP, {s.controller.backend})"
           if s.controller.kind == "mpc" else f" ({s.controller.backend})"
           if s.controller.kind == "kinematic_mpc" else "")
        for label, s in (settings or {}).items() if label in tables) or "not recorded"
    apf_adds = _baseline_apf_adds(tables, cfg, table_dir)
    answer = answer_lines(typed) + ([apf_adds["sentence"]] if apf_adds else [])
    gallery = _gallery(tables, info, cfg, fig_dir, writer)
    figures.extend(gallery)
    return {"gallery": gallery, "ledger": grouped, "comparisons": comparisons, "solvers": solvers,
            "answer": answer, "apf_adds": apf_adds, "treatment": cfg.treatment,
            "by_claim": {r["claim"]: r for r in ledger if r["comparison"] == cfg.controls[0]},
            "counts": [{k: _fmt(v) for k, v in c.items()} for c in counts],
            "raw_counts": counts,
            "cap_note": cap_note, "figures": figures, "seed": first["seed"],
            "size": first["size"], "methods": order}


def _gallery(tables: dict, info: dict, cfg: ClaimsConfig, fig_dir: Path,
             writer: FigureWriter | None = None) -> list[dict]:
    """Family members picked by :func:`pipeline.reporting.gallery.gallery_members`, each drawn
    as the Figure 2/3 analogue (first control above the treatment). Members that cannot be
    read are left out (the report says which in the caption of the rest)."""
    writer = writer if writer is not None else FigureWriter(max_workers=1)
    from pipeline.errors import RunFolderError
    from pipeline.reporting.gallery import gallery_members
    from pipeline.store.runs import read_member

    if not cfg.controls:
        return []
    treatment, control = cfg.treatment, cfg.controls[0]
    picks = gallery_members(tables, treatment, control,
                            {c.claim_id: c.primary_metric for c in ALL_CLAIMS})
    figures = []
    for pick in picks:
        member = pick["member"]
        try:
            runs = {m: read_member(Path(info[m]["dir"]), member) for m in (control, treatment)}
        except (RunFolderError, KeyError, OSError):
            continue
        first = runs[treatment]
        stem = f"gallery_member_{member:04d}"
        # built in the writer's child (the parent goes on to the next member)
        fig = functools.partial(paths_figure, {m: r.trajectory for m, r in runs.items()},
                                tuple(first.config.scenario.goal_xy_m),
                                first.config.vehicle.footprint_radius_m,
                                first.config.scenario.obstacles[0].appear_time_s,
                                titles={m: f"{m}, member {member}" for m in runs},
                                width_in=6.0)
        figures.append({"id": stem, "group": "gallery", "member": member,
                        "why": "; ".join(pick["why"]),
                        "paths": writer.save(fig, fig_dir, stem),
                        "caption": f"Family member {member} ({first.config.scenario.name}): "
                                   + "; ".join(pick["why"]) + ".",
                        "alt": f"Paths of {control} and {treatment} on family member {member}"})
    return figures


def _kinematic_family_section(folder: Path, cfg: ClaimsConfig, table_dir: Path,
                              lateral_by_claim: dict[str, str]) -> dict | None:
    """The Appendix-A track's own ledger over its family (``outputs/kinematic_family``, the
    default reading): the treatment against each control, the baseline against mpc_no_apf,
    collision counts per method, and whether each outcome agrees with the lateral family's."""
    found = load_runs(folder, [])
    tables, notes = _primary_tables(found.family_tables, found.family_info)
    if cfg.treatment not in tables or not any(c in tables for c in cfg.controls):
        return None
    typed = family_ledger(tables, cfg, None, cfg.treatment, tuple(cfg.controls),
                          sensitivity=False)
    typed.to_frame().to_csv(table_dir / "claims_ledger_kinematic_family.csv", index=False)
    rows = [{"claim": r.claim_id, "words": r.claim.text,
             "comparison": r.comparison, "outcome": str(r.outcome),
             "estimate": f"{_fmt(r.result.estimate)} [{_fmt(r.result.ci_low)}, "
                         f"{_fmt(r.result.ci_high)}] {_unit(r.claim.primary_metric)}",
             "n_pairs": r.result.n_pairs,
             "lateral": lateral_by_claim.get(r.claim_id, "n/a") if r.comparison
             == cfg.controls[0] else "",
             "agree": ("yes" if lateral_by_claim.get(r.claim_id) == str(r.outcome) else "no")
             if r.comparison == cfg.controls[0] and r.claim_id in lateral_by_claim else ""}
            for r in typed]
    collisions = [{"method": m, "collisions": int(pd.to_numeric(t.get("collision"),
                                                                errors="coerce").fillna(0).sum())
                   if "collision" in t else "n/a", "members": len(t)}
                  for m, t in ((m, tables[m]) for m in _ordered(tables))]
    apf_adds = _baseline_apf_adds(tables, cfg, table_dir, suffix="_kinematic_family")
    size = next(iter(found.family_info.values()), {}).get("size", len(tables[cfg.treatment]))
    agree = [r for r in rows if r["agree"]]
    # one row per claim: each comparison a column (and the baseline against no APF)
    columns = [c for c in cfg.controls if any(r["comparison"] == c for r in rows)]
    apf = {r["claim"]: r for r in (apf_adds or {}).get("rows", [])}
    grid = []
    for claim in dict.fromkeys(r["claim"] for r in rows):
        cells = {r["comparison"]: r for r in rows if r["claim"] == claim}
        first = cells.get(columns[0], {}) if columns else {}
        grid.append({"claim": claim, "words": first.get("words", ""),
                     "cells": [cells.get(c) for c in columns], "apf": apf.get(claim),
                     "lateral": first.get("lateral", ""), "agree": first.get("agree", "")})
    return {"rows": rows, "grid": grid, "columns": columns,
            "collisions": collisions, "apf_adds": apf_adds, "size": size,
            "notes": notes, "n_agree": sum(r["agree"] == "yes" for r in agree),
            "n_compared": len(agree), "treatment": cfg.treatment}


def _reading_sensitivity(run_root: Path, kinematic_runs: list[dict], cfg: ClaimsConfig
                         ) -> list[dict]:
    """The paper scenario's claims on the Appendix-A track under each reading of the
    baseline (the default and ``kinematic_readings``): treatment against baseline, "not
    comparable" where either method stays farther than ``comparable_clearance_m``."""
    def outcomes(runs: list[dict]) -> dict[str, str] | None:
        by = {r["metrics"].get("method"): r["metrics"] for r in runs}
        if cfg.treatment not in by or "baseline" not in by:
            return None
        met = all((by[m].get("min_clearance_m") or math.inf) <= cfg.comparable_clearance_m
                  for m in (cfg.treatment, "baseline"))
        table = claims_table({m: by[m] for m in (cfg.treatment, "baseline")}, cfg.margins,
                             ("baseline",), improved=cfg.treatment)
        rates = {c.claim_id for c in ALL_CLAIMS if c.is_rate}
        return {row["claim"]: row.get("vs baseline", "n/a")
                if met or row["claim"] in rates else "not comparable" for row in table}

    columns = []
    default = [r for r in kinematic_runs if r["metrics"].get("method") in
               (cfg.treatment, "baseline")]
    base = next((r for r in default if r["metrics"].get("method") == "baseline"), None)
    if base is not None and (o := outcomes(default)) is not None:
        columns.append((_reading_of(base["config"]) + " (default)", o))
    for variant, runs in _readings_runs(run_root).items():
        if (o := outcomes(runs)) is not None:
            columns.append((variant, o))
    if len(columns) < 2:
        return []
    claims = list(columns[0][1])
    return [{"reading": name, "cells": [o.get(c, "n/a") for c in claims], "claims": claims}
            for name, o in columns]


def _baseline_apf_adds(tables: dict, cfg: ClaimsConfig, table_dir: Path,
                       suffix: str = "") -> dict | None:
    """What the paper's baseline APF contributes at all: the baseline judged against
    ``mpc_no_apf`` (the same MPC tracking a straight-to-goal reference) with the same ledger;
    the baseline is *indistinguishable from having no APF* when no claim's outcome is
    supported, contradicted or mixed against it."""
    if "baseline" not in tables or "mpc_no_apf" not in tables:
        return None
    ledger = family_ledger(tables, cfg, None, "baseline", ("mpc_no_apf",), sensitivity=False)
    ledger.to_frame().to_csv(table_dir / f"claims_ledger_baseline_vs_no_apf{suffix}.csv",
                             index=False)
    rows = [{"claim": r.claim_id, "outcome": str(r.outcome),
             "estimate": f"{_fmt(r.result.estimate)} [{_fmt(r.result.ci_low)}, "
                         f"{_fmt(r.result.ci_high)}] {_unit(r.claim.primary_metric)}"}
            for r in ledger]
    decisive = [r["claim"] for r in rows
                if r["outcome"] in ("supported", "contradicted", "mixed")]
    if decisive:
        sentence = ("The baseline's APF against no APF (mpc_no_apf, the same MPC on a "
                    "straight-to-goal reference): it differs on " + ", ".join(
                        f"{r['claim']} ({r['outcome']})" for r in rows
                        if r["claim"] in decisive) + ".")
    else:
        sentence = ("The baseline's APF is indistinguishable from having no APF (mpc_no_apf): "
                    "no claim is supported, contradicted or mixed against it, so 'improved vs "
                    "baseline' is close to 'improved APF vs no APF'.")
    return {"rows": rows, "sentence": sentence, "indistinguishable": not decisive}


def _metrics_doc() -> list[str]:
    """Bullet paragraphs of the metric definitions (from :mod:`pipeline.analysis.metrics`)."""
    import pipeline.analysis.metrics as metrics_module

    doc = metrics_module.__doc__ or ""
    bullets, current = [], []
    for line in doc.splitlines():
        if line.startswith("* "):
            if current:
                bullets.append(" ".join(current))
            current = [line[2:].strip()]
        elif current and line.strip():
            current.append(line.strip())
        elif current:
            bullets.append(" ".join(current))
            current = []
    if current:
        bullets.append(" ".join(current))
    import re

    from markupsafe import Markup, escape

    # the docstring's **Name** becomes bold; everything else is escaped text
    return [Markup(re.sub(r"\*\*(.+?)\*\*", r"<strong>\1</strong>",
                          str(escape(b.replace("``", ""))))) for b in bullets]
