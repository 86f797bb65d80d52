"""A tune's families on a Dask cluster's persistent workers (``--workers``,
pipeline.studies.workers) give the tune of this machine's loky pool: the same trials, values,
held-out tables and verdicts. Locally on a Dask cluster of two processes; on SLURM through
dask-jobqueue (``make test-slurm``, the cluster of .ci/slurm-cluster)."""

from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path

import pytest

from pipeline.config import CONF_DIR
from pipeline.errors import ConfigError
from pipeline.studies.tune import load_tune_space, run_tuning
from pipeline.studies.workers import Workers

SPACE = ["replicates=1", "max_trials=6", "min_trials=6", "heldout_size=6"]
SAME = ("trials.csv", "heldout.csv", "ledger_tuned.csv", "settings_outcomes.csv")


def _tune(folder: Path, workers: Workers) -> list[str]:
    said: list[str] = []
    space = load_tune_space(CONF_DIR / "tune" / "quick.yaml", SPACE)
    run_tuning(space, folder, ["scenario.family.n_jobs=2"], log=said.append, workers=workers)
    return said


def _same_as_loky(tmp_path: Path, workers: Workers) -> list[str]:
    _tune(tmp_path / "loky", Workers())
    said = _tune(tmp_path / "cluster", workers)
    for name in SAME:
        assert (tmp_path / "cluster" / name).read_text() == \
            (tmp_path / "loky" / name).read_text(), name
    return said


@pytest.mark.machine
def test_a_local_dask_cluster_tunes_as_the_loky_pool(tmp_path):
    said = _same_as_loky(tmp_path, Workers.parse("dask-local:2"))
    # the switch is real: the families went to the cluster (the held-out ones too)
    assert said[0] == "families run on a Dask cluster of 2 worker processes here"
    assert any("families on the cluster's workers" in line for line in said)


def test_a_cluster_with_slurm_arrays_is_refused_in_one_line(tmp_path):
    space = load_tune_space(CONF_DIR / "tune" / "quick.yaml", SPACE)
    with pytest.raises(ConfigError, match="--workers"):
        run_tuning(space, tmp_path / "t", ["hydra/launcher=slurm"],
                   workers=Workers.parse("dask-local:2"))
    assert not (tmp_path / "t").exists()


def _slurm_up() -> bool:
    if not os.environ.get("SLURM_CONF") or shutil.which("sinfo") is None:
        return False
    out = subprocess.run(["sinfo", "-h", "-o", "%T"], capture_output=True, text=True)
    return out.returncode == 0 and bool(out.stdout.strip())


@pytest.mark.slurm
def test_dask_workers_submitted_to_slurm_tune_as_the_loky_pool(tmp_path):
    if not _slurm_up():
        if os.environ.get("CI") == "true":
            raise RuntimeError("CI runs the SLURM tests on the cluster of .ci/slurm-cluster")
        pytest.skip("no SLURM cluster (run `make test-slurm`)")
    before = set(Path.cwd().glob("slurm-*.out"))
    said = _same_as_loky(tmp_path, Workers.parse("dask-slurm:2"))
    assert said[0] == "families run on 2 SLURM jobs of one Dask worker each"
    # the jobs' logs are the study's, not the current folder's (two were once committed)
    assert len(list((tmp_path / "cluster" / "slurm_logs").glob("dask-worker-*.out"))) >= 2
    assert set(Path.cwd().glob("slurm-*.out")) == before
