"""Run records: one owner of the folder layout; manifests prove a folder whole; every folder
passed over is named with its reason; damaged folders are re-run, never trusted."""

from __future__ import annotations

import json
import os
import shutil

import numpy as np
import pandas as pd
import pytest

from pipeline.analysis.metrics.results import RunMetrics
from pipeline.errors import NonFiniteResultError, RunFolderError
from pipeline.report import main as report_main
from pipeline.reporting.page import build_report
from pipeline.store.manifest import MANIFEST, check
from pipeline.store.runs import RunInfo, discover, read_run, write_run
from pipeline.studies.experiment import run_experiment, run_family


@pytest.fixture(scope="module")
def pristine_paper(small_reproduce):
    """The paper scenario's baseline and improved runs: those of the session's
    :func:`small_reproduce`, read-only (a test damages its own copy, :func:`paper`)."""
    return small_reproduce


@pytest.fixture()
def paper(tmp_path, pristine_paper):
    """A test's own copy of :func:`pristine_paper` (files and their times), free to damage."""
    root = tmp_path / "outputs"
    shutil.copytree(pristine_paper / "paper", root / "paper")
    return root


def test_manifest_lists_every_file_with_size_and_hash(paper):
    manifest = json.loads((paper / "paper" / "baseline" / MANIFEST).read_text())
    assert set(manifest["files"]) == {"config.yaml", "model.json", "trajectory.csv",
                                      "timing.json", "metrics.json", "horizon.npz"}
    assert all(len(e["sha256"]) == 64 and e["bytes"] > 0 for e in manifest["files"].values())
    assert manifest["config_hash"] and manifest["code_version"]
    assert check(paper / "paper" / "baseline") is None


def test_a_run_without_its_horizon_record_is_the_same_run(tmp_path, paper, make_config):
    """record_horizon=False (a tune's training members) writes every file but horizon.npz,
    byte for byte as the run that keeps it, and a complete record without it."""
    folder = tmp_path / "no_horizon"
    run_experiment(make_config(["method=baseline"]), folder, record_horizon=False)
    kept = paper / "paper" / "baseline"
    assert not (folder / "horizon.npz").exists() and (kept / "horizon.npz").is_file()
    for name in ("config.yaml", "model.json", "trajectory.csv", "metrics.json"):
        assert (folder / name).read_bytes() == (kept / name).read_bytes(), name
    assert set(json.loads((folder / MANIFEST).read_text())["files"]) == {
        "config.yaml", "model.json", "trajectory.csv", "timing.json", "metrics.json"}
    assert check(folder) is None


@pytest.mark.parametrize("damage, reason", [
    ("cut", "trajectory.csv differs"), ("swap", "trajectory.csv differs"),
    ("metrics_truncated", "metrics.json differs"), ("metrics_empty", "metrics.json differs"),
    ("config_garbage", "config.yaml differs"), ("no_timing", "timing.json is missing"),
    ("only_config", "no manifest.json")])
def test_damaged_folder_is_named_skipped_and_rerun(paper, make_config, capsys, damage, reason):
    folder = paper / "paper" / "improved"
    if damage == "cut":
        lines = (folder / "trajectory.csv").read_text().splitlines()[:10]
        (folder / "trajectory.csv").write_text("\n".join(lines) + "\n")
    elif damage == "swap":
        shutil.copyfile(paper / "paper" / "baseline" / "trajectory.csv", folder / "trajectory.csv")
    elif damage == "metrics_truncated":
        text = (folder / "metrics.json").read_text()
        (folder / "metrics.json").write_text(text[:len(text) // 2])
    elif damage == "metrics_empty":
        (folder / "metrics.json").write_text("{}")
    elif damage == "config_garbage":
        (folder / "config.yaml").write_text("{{{: not yaml")
    elif damage == "no_timing":
        (folder / "timing.json").unlink()
    else:
        for name in os.listdir(folder):
            if name != "config.yaml":
                (folder / name).unlink()
    assert reason in check(folder)
    # report: the folder is listed with its reason (page, stderr); --strict exits 1
    out = paper.parent / "report"
    assert report_main([str(paper), "--out", str(out)]) == 0
    page = (out / "index.html").read_text()
    assert 'id="skipped"' in page and "paper/improved" in page and reason.split()[0] in page
    assert "skipped" in capsys.readouterr().err
    assert report_main([str(paper), "--out", str(out), "--strict"]) == 1
    # resume re-runs the damaged folder instead of trusting it
    summary = run_experiment(make_config(["method=improved"]), folder)
    assert not summary.skipped and check(folder) is None


def test_resume_trusts_a_whole_folder_and_cleans_leftover_temporaries(paper, make_config):
    folder = paper / "paper" / "baseline"
    leftover = folder / ".trajectory.csv.abc123.tmp"
    leftover.write_text("half")
    before = (folder / MANIFEST).stat().st_mtime_ns
    assert run_experiment(make_config(["method=baseline"]), folder).skipped
    assert not leftover.exists() and (folder / MANIFEST).stat().st_mtime_ns == before


def test_report_shows_every_run_labelled_by_what_differs(tmp_path, make_config):
    root = tmp_path / "outputs"
    run_experiment(make_config(["method=baseline"]), root / "b")
    for beta in (0.1, 0.25, 0.5):
        run_experiment(make_config(["method=improved", f"planner.beta={beta}"]),
                       root / f"improved_{beta}")
    page = build_report(root, tmp_path / "report", "pytest").read_text()
    for beta in (0.1, 0.25, 0.5):
        assert f"improved (planner.beta={beta})" in page
    assert "3 runs of improved were given" in page


def test_family_with_a_cut_table_is_skipped_and_a_corrupt_member_is_rerun(tmp_path, make_config,
                                                                          caplog):
    cfg = make_config(["method=improved", "scenario=family", "scenario.family.size=3",
                       "scenario.family.n_jobs=1"])
    folder = tmp_path / "family" / "improved"
    run_family(cfg, folder, progress=False)
    text = (folder / "family_metrics.csv").read_text()
    (folder / "family_metrics.csv").write_text(text[: len(text) - 40])
    found = discover(tmp_path)
    assert found.families == [] and "family_metrics.csv differs" in found.skipped[0].reason
    member = folder / "member_0001" / "trajectory.csv"
    member.write_text(member.read_text()[:200])
    import logging

    with caplog.at_level(logging.WARNING):
        run_family(cfg, folder, progress=False)
    assert "member_0001" in caplog.text and "trajectory.csv differs" in caplog.text
    assert discover(tmp_path).families == [folder] and check(folder / "member_0001") is None


def test_a_non_finite_result_writes_no_folder(tmp_path):
    folder = tmp_path / "run"
    with pytest.raises(NonFiniteResultError, match=r"model.json at discrete.Ad\[0\]\[1\]"):
        write_run(folder, config_text="{}\n", model={"discrete": {"Ad": [[0.0, float("inf")]]}},
                  trajectory=pd.DataFrame({"time_s": [0.0]}), timing={},
                  metrics=RunMetrics.from_json({}), info=RunInfo.from_json({"config_hash": "h"}))
    assert not folder.exists()
    with pytest.raises(RunFolderError):
        read_run(folder)


def sweep_with_jobs(tmp_path, make_config):
    """A two-job sweep folder written the way Hydra lays it out."""
    sweep = tmp_path / "sweep"
    for method in ("baseline", "improved"):
        job = sweep / f"method={method}"
        run_experiment(make_config([f"method={method}"]), job)
        (job / ".hydra").mkdir()
        (job / ".hydra" / "overrides.yaml").write_text(f"- method={method}\n")
        (job / ".hydra" / "hydra.yaml").write_text("hydra: {}\n")
    return sweep


def test_aggregate_lists_failed_and_stale_jobs_next_to_the_good_ones(tmp_path, make_config,
                                                                     capsys):
    from pipeline.studies.aggregate import aggregate

    sweep = sweep_with_jobs(tmp_path, make_config)
    # a job of an earlier sweep into the same folder, and a failed (incomplete) job
    stale = sweep / "method=velocity_aware"
    run_experiment(make_config(["method=velocity_aware"]), stale)
    (stale / ".hydra").mkdir()
    (stale / ".hydra" / "overrides.yaml").write_text("- method=velocity_aware\n")
    (stale / ".hydra" / "hydra.yaml").write_text("hydra: {}\n")
    failed = sweep / "method=mpc_no_apf"
    (failed / ".hydra").mkdir(parents=True)
    (failed / ".hydra" / "overrides.yaml").write_text("- method=mpc_no_apf\n")
    (failed / "config.yaml").write_text("{}\n")
    # the sweep in this folder now: baseline and improved (and the job that failed)
    (sweep / "multirun.yaml").write_text(
        "hydra:\n  sweeper:\n    params:\n      method: baseline,improved,mpc_no_apf\n"
        "  overrides:\n    task: []\n")
    summary = aggregate(sweep, progress=False).summary
    status = dict(zip(summary["job"], summary["status"], strict=True))
    assert status == {"method=baseline": "ok", "method=improved": "ok",
                      "method=velocity_aware": "stale", "method=mpc_no_apf": "skipped"}
    written = pd.read_csv(sweep / "summary.csv")
    assert len(written) == 4 and (sweep / "skipped.csv").is_file()
    assert "stale" in capsys.readouterr().err


def test_nested_job_folders_are_found(tmp_path, make_config):
    from pipeline.studies.aggregate import aggregate

    sweep = sweep_with_jobs(tmp_path, make_config)
    nested = sweep / "deeper" / "method=improved"
    nested.parent.mkdir()
    shutil.move(str(sweep / "method=improved"), nested)
    summary = aggregate(sweep, progress=False).summary
    assert sorted(summary["job"]) == ["deeper/method=improved", "method=baseline"]


def test_verify_and_report_survive_every_broken_folder(paper, capsys):
    from pipeline.verify import main as verify_main

    (paper / "paper" / "improved" / "metrics.json").write_text("{")
    broken = paper / "paper" / "weird"
    broken.mkdir()
    (broken / "config.yaml").write_text("::: [")
    code = verify_main([str(paper), str(paper.parent / "no_reference")])
    err = capsys.readouterr().err
    assert code in (1, 2) and "Traceback" not in err and "skipped" in err
    assert report_main([str(paper), "--out", str(paper.parent / "r")]) == 0
    assert np.isfinite(len((paper.parent / "r" / "index.html").read_text()))
