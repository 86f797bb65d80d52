"""SLURM through the project's launcher on a real single-node cluster (`make test-slurm` starts
one with .ci/slurm-cluster): byte-identical results to the basic launcher, a cancelled task
that neither hangs the sweep nor loses anything, fail-fast config errors, and reruns that
submit nothing."""

from __future__ import annotations

import filecmp
import os
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pytest

pytestmark = pytest.mark.slurm
ROOT = Path(__file__).resolve().parents[2]


def _cluster_up() -> bool:
    if not os.environ.get("SLURM_CONF") or shutil.which("sinfo") is None:
        return False
    out = subprocess.run(["sinfo", "-h", "-o", "%T"], capture_output=True, text=True)
    return out.returncode == 0 and bool(out.stdout.strip())


@pytest.fixture(autouse=True, scope="module")
def cluster():
    """Only when these tests are selected (`make test-slurm`): a cluster must be up."""
    if not _cluster_up():
        if os.environ.get("CI") == "true":
            raise RuntimeError("CI runs the SLURM tests on the cluster of .ci/slurm-cluster "
                               "(`make test-slurm` starts it)")
        pytest.skip("no SLURM cluster (run `make test-slurm`)")

SLURM = ["hydra/launcher=slurm", "hydra.launcher.partition=cpu", "hydra.launcher.timeout_min=5",
         "hydra.launcher.poll_s=1", "hydra.launcher.lost_after_s=3",
         "hydra.launcher.cpus_per_task=1", "hydra.launcher.mem_gb=1"]
RESULT_FILES = ("config.yaml", "model.json", "trajectory.csv", "metrics.json",
                "family_metrics.csv", "family.json")


def sweep(folder: Path, args: list[str], launcher: list[str] | None = None,
          background: bool = False):
    command = [sys.executable, "-m", "pipeline.run", "-m", f"hydra.sweep.dir={folder}",
               *(launcher or []), *args]
    if background:
        return subprocess.Popen(command, cwd=ROOT, stdout=subprocess.PIPE,
                                stderr=subprocess.STDOUT, text=True)
    return subprocess.run(command, cwd=ROOT, capture_output=True, text=True, timeout=240)


def result_files(folder: Path) -> dict[str, Path]:
    return {str(p.relative_to(folder)): p for p in sorted(folder.rglob("*"))
            if p.name in RESULT_FILES and ".submitit" not in p.parts}


def assert_identical(a: Path, b: Path) -> None:
    files_a, files_b = result_files(a), result_files(b)
    assert files_a.keys() == files_b.keys() and files_a
    different = [k for k in files_a if not filecmp.cmp(files_a[k], files_b[k], shallow=False)]
    assert different == []
    summary_a = pd.read_csv(a / "summary.csv").sort_values("job").reset_index(drop=True)
    summary_b = pd.read_csv(b / "summary.csv").sort_values("job").reset_index(drop=True)
    pd.testing.assert_frame_equal(summary_a, summary_b)


def test_two_job_sweep_matches_the_basic_launcher(tmp_path):
    args = ["method=baseline,improved"]
    slurm = sweep(tmp_path / "slurm", args, SLURM)
    assert slurm.returncode == 0, slurm.stderr[-2000:]
    basic = sweep(tmp_path / "basic", args)
    assert basic.returncode == 0, basic.stderr[-2000:]
    assert_identical(tmp_path / "slurm", tmp_path / "basic")
    # a rerun of the finished sweep submits nothing and returns in seconds
    start = time.monotonic()
    again = sweep(tmp_path / "slurm", args, SLURM)
    assert again.returncode == 0 and "submitting 0 of 2 jobs" in again.stdout + again.stderr
    assert time.monotonic() - start < 30


def test_family_sweep_matches_the_basic_launcher(tmp_path):
    args = ["method=baseline,improved", "scenario=family", "scenario.family.size=4",
            "scenario.family.n_jobs=1"]
    assert sweep(tmp_path / "slurm", args, SLURM).returncode == 0
    assert sweep(tmp_path / "basic", args).returncode == 0
    assert_identical(tmp_path / "slurm", tmp_path / "basic")


def test_a_config_error_stops_before_anything_is_submitted(tmp_path):
    result = sweep(tmp_path / "bad", ["method=baseline,improved", "controller.horizon=0"], SLURM)
    assert result.returncode == 2
    line = [ln for ln in result.stderr.splitlines() if "config error" in ln]
    assert len(line) == 1 and "controller.horizon=0" in line[0] and "job #0" in line[0]
    assert "nothing was submitted" in line[0] and not (tmp_path / "bad" / ".submitit").exists()


def test_cancelled_tasks_end_the_wait_and_the_rerun_completes(tmp_path):
    args = ["method=baseline,improved,baseline_matched", "scenario=family",
            "scenario.family.size=24", "scenario.family.n_jobs=1"]
    launcher = SLURM + ["hydra.launcher.array_parallelism=1"]
    process = sweep(tmp_path / "slurm", args, launcher, background=True)
    tasks: list[str] = []
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and len(tasks) < 3:
        out = subprocess.run(["squeue", "-h", "-r", "-o", "%i %t"], capture_output=True,
                             text=True).stdout.split("\n")
        tasks = [line.split()[0] for line in out if line.strip()]
        time.sleep(0.5)
    assert len(tasks) == 3, tasks
    running = next(t for t in tasks if t.endswith("_0"))
    pending = next(t for t in tasks if t.endswith("_2"))
    subprocess.run(["scancel", pending], check=True)   # a pending task: no accounting record
    time.sleep(1.0)
    subprocess.run(["scancel", running], check=True)   # a running task
    output, _ = process.communicate(timeout=180)        # bounded: no hang
    assert process.returncode == 2, output[-3000:]
    assert "did not finish" in output and "#2" in output and "resume with" in output
    # nothing lost: the finished job is summarised; the rerun submits only what is missing
    again = sweep(tmp_path / "slurm", args, launcher)
    assert again.returncode == 0, again.stderr[-3000:]
    log = again.stdout + again.stderr
    submitted = re.search(r"submitting (\d) of 3 jobs", log)
    assert submitted and int(submitted.group(1)) >= 1 and "#2 : method=baseline_matched" in log
    # nothing duplicated or damaged: identical to an uninterrupted basic-launcher sweep
    assert sweep(tmp_path / "basic", args).returncode == 0
    assert_identical(tmp_path / "slurm", tmp_path / "basic")


def test_multiverse_on_slurm_equals_the_local_one(tmp_path):
    command = [sys.executable, "-m", "pipeline.multiverse", "--space", "quick"]
    local = subprocess.run(command + ["--out", str(tmp_path / "local")], cwd=ROOT,
                           capture_output=True, text=True, timeout=240)
    assert local.returncode == 0, local.stderr[-2000:]
    remote = subprocess.run(command + ["--out", str(tmp_path / "slurm"), *SLURM], cwd=ROOT,
                            capture_output=True, text=True, timeout=240)
    assert remote.returncode == 0, remote.stderr[-2000:]
    assert "submitted" in remote.stderr and "to SLURM" in remote.stderr
    for name in ("specifications.csv", "robustness.csv", "dimensions.csv"):
        assert filecmp.cmp(tmp_path / "local" / name, tmp_path / "slurm" / name, shallow=False)


def test_tune_on_slurm_array_workers_equals_the_local_one(tmp_path):
    """A tune whose families run as SLURM arrays (two array tasks per batch, sharing one study
    through its one coordinator): no trial lost or run twice, and the same trials, fronts and
    verdicts as the local tune with the same seeds."""
    from test_tune_pruning import no_trial_lost_or_run_twice

    # one batch of two trials per method: each rung one array of two tasks
    command = [sys.executable, "-m", "pipeline.tune", "--space", "quick", "--set",
               "replicates=1", "--set", "heldout_size=8", "--set", "min_trials=2", "--set",
               "max_trials=2", "--set", "convergence_window=1"]
    local = subprocess.run(command + ["--out", str(tmp_path / "local")], cwd=ROOT,
                           capture_output=True, text=True, timeout=600)
    assert local.returncode == 0, local.stderr[-2000:]
    remote = subprocess.run(command + ["--out", str(tmp_path / "slurm"), *SLURM,
                                       "hydra.launcher.array_parallelism=2"], cwd=ROOT,
                            capture_output=True, text=True, timeout=900)
    assert remote.returncode == 0, remote.stderr[-2000:]
    assert re.search(r"submitted 2 family runs to SLURM", remote.stderr)
    for name in ("trials.csv", "ledger_tuned.csv", "settings_outcomes.csv"):
        assert filecmp.cmp(tmp_path / "local" / name, tmp_path / "slurm" / name, shallow=False)
    for folder in ("local", "slurm"):
        no_trial_lost_or_run_twice(tmp_path / folder)
