"""Hydra multiruns through the real launchers, aggregation, and resume."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys

import pandas as pd
import pytest

from pipeline.studies.aggregate import aggregate

SWEEP = ["method=baseline,improved", "scenario.obstacles.0.vy_mps=-0.4,-0.8"]


def multirun(sweep_dir, *extra):
    result = subprocess.run([sys.executable, "-m", "pipeline.run", "-m", *SWEEP,
                             f"hydra.sweep.dir={sweep_dir}", *extra],
                            capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr[-2000:]
    return result


def job_dirs(sweep_dir):
    return sorted(p for p in sweep_dir.iterdir() if (p / "metrics.json").is_file())


@pytest.fixture(scope="module")
def basic_sweep(tmp_path_factory):
    folder = tmp_path_factory.mktemp("sweep") / "basic"
    multirun(folder)
    return folder


def test_one_folder_per_job_named_from_overrides(basic_sweep):
    names = [p.name for p in job_dirs(basic_sweep)]
    assert names == ["method=baseline,scenario.obstacles.0.vy_mps=-0.4",
                     "method=baseline,scenario.obstacles.0.vy_mps=-0.8",
                     "method=improved,scenario.obstacles.0.vy_mps=-0.4",
                     "method=improved,scenario.obstacles.0.vy_mps=-0.8"]
    for job in job_dirs(basic_sweep):
        for name in ("config.yaml", "model.json", "trajectory.csv", "timing.json"):
            assert (job / name).is_file()


def test_callback_aggregated_the_sweep(basic_sweep):
    summary = pd.read_csv(basic_sweep / "summary.csv")
    assert len(summary) == 4
    assert {"method", "scenario.obstacles.0.vy_mps", "min_clearance_m",
            "reaction_delay_s"} <= set(summary.columns)
    assert sorted(summary["scenario.obstacles.0.vy_mps"].unique()) == [-0.8, -0.4]
    swept = json.loads((basic_sweep / "swept_keys.json").read_text())["swept_keys"]
    assert swept == ["method", "scenario.obstacles.0.vy_mps"]
    verdicts = pd.read_csv(basic_sweep / "verdicts.csv")
    assert len(verdicts) == 2 * 7  # two speeds x seven claims (C0-C5, C3 as C3a and C3b)
    assert (basic_sweep / "figures" / "sweep_lines.png").is_file()


def test_joblib_launcher_gives_identical_metrics(basic_sweep, tmp_path):
    folder = tmp_path / "joblib"
    multirun(folder, "hydra/launcher=joblib", "hydra.launcher.n_jobs=2")
    basic_jobs, joblib_jobs = job_dirs(basic_sweep), job_dirs(folder)
    assert [p.name for p in basic_jobs] == [p.name for p in joblib_jobs]
    for a, b in zip(basic_jobs, joblib_jobs, strict=True):
        for name in ("metrics.json", "trajectory.csv"):
            assert (a / name).read_bytes() == (b / name).read_bytes(), (a.name, name)


def test_submitit_local_launcher_runs_the_jobs(tmp_path):
    folder = tmp_path / "submitit"
    result = subprocess.run([sys.executable, "-m", "pipeline.run", "-m", "method=baseline",
                             "scenario.obstacles.0.vy_mps=-0.4", f"hydra.sweep.dir={folder}",
                             "hydra/launcher=submitit_local", "hydra.launcher.timeout_min=10"],
                            capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr[-2000:]
    jobs = job_dirs(folder)
    assert len(jobs) == 1
    assert json.loads((jobs[0] / "metrics.json").read_text())["method"] == "baseline"
    assert (folder / ".submitit").is_dir()


def test_resume_redoes_only_the_deleted_job(basic_sweep, tmp_path):
    folder = tmp_path / "resume"
    shutil.copytree(basic_sweep, folder)
    jobs = job_dirs(folder)
    victim = jobs[1]
    shutil.rmtree(victim)
    before = {p.name: (p / "metrics.json").stat().st_mtime_ns for p in jobs if p != victim}
    multirun(folder)
    after = {p.name: (p / "metrics.json").stat().st_mtime_ns for p in job_dirs(folder)}
    assert victim.name in after
    for name, stamp in before.items():
        assert after[name] == stamp, f"{name} was recomputed"
    assert (victim / "metrics.json").read_bytes() == \
        (basic_sweep / victim.name / "metrics.json").read_bytes()


def test_aggregate_without_jobs_is_a_clear_error(tmp_path):
    with pytest.raises(FileNotFoundError):
        aggregate(tmp_path, progress=False)


def test_a_job_copied_in_without_its_provenance_is_passed_over(basic_sweep, tmp_path):
    """A job folder without Hydra's record (.hydra/overrides.yaml) in a sweep cannot say which
    swept values it ran: aggregate lists it with that reason instead of calling it ok."""
    sweep = tmp_path / "sweep"
    shutil.copytree(basic_sweep, sweep)
    stray = sweep / "copied_in"
    shutil.copytree(job_dirs(sweep)[0], stray)
    shutil.rmtree(stray / ".hydra")
    summary = aggregate(sweep, progress=False).summary
    row = summary[summary["job"] == "copied_in"].iloc[0]
    assert row["status"] == "skipped" and "no provenance" in row["reason"]
    assert (summary["status"] == "ok").sum() == 4


def test_an_edited_or_stale_summary_is_refused_not_trusted(basic_sweep, tmp_path):
    """summary.csv carries a manifest tied to the jobs it was computed from: an edited summary,
    or a job removed since, is refused with the reason (the report never re-aggregates: it
    skips the sweep and says how to aggregate it again)."""
    from pipeline.reporting.page import build_report
    from pipeline.store.runs import Skipped
    from pipeline.studies.results import ResultError, SweepSummary
    from pipeline.studies.results.sweep import summary_reason

    sweep = tmp_path / "sweep"
    shutil.copytree(basic_sweep, sweep)
    aggregate(sweep, progress=False)
    assert summary_reason(sweep) is None
    assert len(SweepSummary.load(sweep).summary) == 4
    original = (sweep / "summary.csv").read_text()
    (sweep / "summary.csv").write_text(original.replace("improved", "forged", 1))
    assert "differs from its manifest" in summary_reason(sweep)
    with pytest.raises(ResultError, match="aggregate it again"):
        SweepSummary.load(sweep)
    # the report over the sweep alone: nothing it can trust to show, and it says why
    skipped: list[Skipped] = []
    with pytest.raises(FileNotFoundError):
        build_report(sweep, tmp_path / "report", "pytest", skipped=skipped)
    assert len(skipped) == 1 and "aggregate it again" in skipped[0].reason
    assert (sweep / "summary.csv").read_text() != original  # never re-aggregated by the report
    aggregate(sweep, progress=False)
    assert (sweep / "summary.csv").read_text() == original and summary_reason(sweep) is None
    shutil.rmtree(job_dirs(sweep)[0])
    assert "added or removed since" in summary_reason(sweep)
    assert len(aggregate(sweep, progress=False).summary) == 3
