"""Hostile environments: what the machine lacks is one line and exit 2, never a traceback: no
SLURM for ``hydra/launcher=slurm``, a full disk (the file being written is named, also when a
worker process hit it), a read-only output folder.

The commands and the lines the user sees::

    $ python -m pipeline.run -m hydra/launcher=slurm method=baseline     # no SLURM here
    error: hydra/launcher=slurm needs SLURM, but sbatch, srun, squeue are not on PATH; run on
    a cluster's login node, or leave out hydra/launcher=slurm to run here; nothing was submitted

    $ python -m pipeline.nmpc_check --out D                              # the disk is full
    error: D/agreement.csv: cannot write its results (No space left on device)
"""

from __future__ import annotations

import errno
import io
import os
import subprocess
import sys
from pathlib import Path

import pytest

from pipeline.commands import run_command

ROOT = Path(__file__).resolve().parents[2]


def _sweep(tmp_path: Path, path: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "pipeline.run", "-m", "hydra/launcher=slurm",
                           "method=baseline", f"hydra.sweep.dir={tmp_path / 'sweep'}"],
                          cwd=ROOT, capture_output=True, text=True, timeout=300,
                          env={**os.environ, "PYTHONPATH": str(ROOT), "PATH": path})


def _error_lines(stderr: str) -> list[str]:
    """stderr without Hydra's own log lines (``[date][HYDRA] ...``)."""
    return [line for line in stderr.strip().splitlines() if not line.startswith("[")]


def test_slurm_launcher_without_slurm_is_one_line(tmp_path):
    """No sbatch, srun or squeue on PATH (a laptop): exit 2, one line, nothing submitted.
    Before: a 37-line traceback from submitit ("Could not detect srun")."""
    empty = tmp_path / "bin"
    empty.mkdir()
    proc = _sweep(tmp_path, str(empty))
    assert proc.returncode == 2, proc.stderr[-2000:]
    assert _error_lines(proc.stderr) == [
        "error: hydra/launcher=slurm needs SLURM, but sbatch, srun, squeue are not on PATH; "
        "run on a cluster's login node, or leave out hydra/launcher=slurm to run here; "
        "nothing was submitted"]
    assert not (tmp_path / "sweep" / ".submitit").exists()


def test_slurm_launcher_whose_controller_does_not_answer_is_one_line(tmp_path):
    """SLURM's commands installed but no controller (a container, a node outside the
    cluster): squeue's fatal line, in one line of ours, exit 2 (before: sbatch's four
    lines, then a code error with exit 1)."""
    fake = tmp_path / "bin"
    fake.mkdir()
    for name in ("sbatch", "srun", "squeue"):
        script = fake / name
        script.write_text("#!/bin/sh\necho \"$0: error: fetch_config: DNS SRV lookup failed\" >&2\n"
                          "echo \"$0: fatal: Could not establish a configuration source\" >&2\n"
                          "exit 1\n")
        script.chmod(0o755)
    proc = _sweep(tmp_path, f"{fake}{os.pathsep}/usr/bin{os.pathsep}/bin")
    assert proc.returncode == 2, proc.stderr[-2000:]
    assert _error_lines(proc.stderr) == [
        f"error: hydra/launcher=slurm: SLURM does not answer here ({fake / 'squeue'}: fatal: "
        "Could not establish a configuration source); run on a cluster's login node, or "
        "leave out hydra/launcher=slurm; nothing was submitted"]


class _FullDisk(io.StringIO):
    """A file on a full disk: every write fails as the kernel says it (no file name)."""

    def write(self, text):
        raise OSError(errno.ENOSPC, "No space left on device")


def _full_disk(monkeypatch):
    import pipeline.store.files as files

    real = os.fdopen
    monkeypatch.setattr(files.os, "fdopen", lambda fd, *a, **k: (real(fd).close(),
                                                                  _FullDisk())[1])


def test_nmpc_check_on_a_full_disk_names_the_file(tmp_path, monkeypatch, capsys):
    """``python -m pipeline.nmpc_check --out D`` when the disk fills as it writes its table:
    exit 2, one line naming the file, no temporary left (before: a traceback ending in
    ``OSError: [Errno 28] No space left on device`` and no file named)."""
    import pandas as pd

    import pipeline.nmpc_check as command
    from pipeline.studies.results.nmpc_check import NmpcCheckResult

    def study(compose, out_dir, *args, **kwargs):  # the check's own writer, on a tiny table
        table = pd.DataFrame({"track": ["kinematic"], "max_path_difference_m": [0.1]})
        return NmpcCheckResult({"kinematic": {"runs": 1}}, table).write(out_dir)

    monkeypatch.setattr(command, "nmpc_agreement", study)
    _full_disk(monkeypatch)
    out = tmp_path / "nmpc"
    assert command.main(["--family-size", "1", "--out", str(out)]) == 2
    captured = capsys.readouterr()
    assert captured.err.strip().splitlines() == [
        f"error: {out / 'agreement.csv'}: cannot write its results (No space left on device)"]
    assert not list(out.glob("*.tmp")) and not (out / "agreement.csv").exists()


def _worker_on_a_full_disk(path: str) -> None:
    """A worker process (loky) writing a member file when the disk is full."""
    import errno as errno_
    import io as io_

    import pipeline.store.files as files

    class Full(io_.StringIO):
        def write(self, text):
            raise OSError(errno_.ENOSPC, "No space left on device")

    real = files.os.fdopen
    files.os.fdopen = lambda fd, *a, **k: (real(fd).close(), Full())[1]
    files.write_text_atomic(Path(path), "member\n")


def test_a_full_disk_in_a_worker_process_is_one_line_naming_the_file(tmp_path, capsys):
    """The multiverse and the families write their members in loky worker processes: the
    error crosses back to the command with its file name (before: a traceback from the
    worker, no file named)."""
    from joblib import Parallel, delayed

    target = tmp_path / "member_000" / "metrics.json"
    target.parent.mkdir()

    def work():
        Parallel(n_jobs=2)(delayed(_worker_on_a_full_disk)(str(target)) for _ in range(2))

    assert run_command(work) == 2
    assert capsys.readouterr().err.strip().splitlines() == [
        f"error: {target}: No space left on device"]
    assert list(target.parent.iterdir()) == []


def test_a_disk_fault_without_a_file_name_is_still_one_line(capsys):
    """A full disk that reaches the command with no file name (a library's own write): one
    line saying what the machine lacks, exit 2."""

    def work():
        try:
            raise OSError(errno.ENOSPC, "No space left on device")
        except OSError as exc:
            raise RuntimeError("a library failed") from exc

    assert run_command(work) == 2
    assert capsys.readouterr().err.strip().splitlines() == [
        "error: cannot write: No space left on device (ENOSPC); free some space or choose "
        "another output folder"]


def test_an_output_that_is_a_file_is_one_line(tmp_path, capsys):
    """``python -m pipeline.nmpc_check --out FILE``: before, ``error: FILE: File exists``."""
    import pipeline.nmpc_check as command

    afile = tmp_path / "afile"
    afile.write_text("mine\n")
    assert command.main(["--family-size", "1", "--out", str(afile)]) == 2
    assert capsys.readouterr().err.strip().splitlines() == [
        f"--out: {afile} is not a folder; allowed: a folder (new, or one this check wrote "
        "before)"]
    assert afile.read_text() == "mine\n"


def test_a_read_only_output_folder_is_one_line_naming_it(tmp_path, monkeypatch, capsys):
    """``python -m pipeline.nmpc_check --out D`` with D on a read-only file system (simulated:
    the tests may run as root, whom permissions do not stop): exit 2, one line naming D."""
    import pipeline.nmpc_check as command
    import pipeline.store.files as files
    from pipeline.studies.results.nmpc_check import NmpcCheckResult

    def read_only(*args, dir=None, **kwargs):
        raise OSError(errno.EROFS, "Read-only file system", os.path.join(dir, ".x.tmp"))

    monkeypatch.setattr(files.tempfile, "mkstemp", read_only)
    monkeypatch.setattr(command, "nmpc_agreement", lambda compose, out_dir, *a, **k:
                        NmpcCheckResult({"kinematic": {}}, None).write(out_dir))
    out = tmp_path / "ro"
    assert command.main(["--family-size", "1", "--out", str(out)]) == 2
    assert capsys.readouterr().err.strip().splitlines() == [
        f"error: {out / '.x.tmp'}: cannot write its results (Read-only file system)"]


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into read-only folders")
def test_a_read_only_folder_for_real(tmp_path, capsys):
    out = tmp_path / "ro"
    out.mkdir()
    out.chmod(0o555)
    try:
        from pipeline.store.files import write_text_atomic

        assert run_command(lambda: write_text_atomic(out / "summary.json", "{}")) == 2
        line = capsys.readouterr().err.strip()
        assert line.startswith(f"error: {out}") and "Permission denied" in line
    finally:
        out.chmod(0o755)


def test_the_multiverse_on_slurm_without_slurm_is_one_line(tmp_path):
    """The multiverse and the tuning submit through the same executor: ``python -m
    pipeline.multiverse --space quick hydra/launcher=slurm`` without SLURM is the same line,
    exit 2, before any family is submitted."""
    empty = tmp_path / "bin"
    empty.mkdir()
    proc = subprocess.run([sys.executable, "-m", "pipeline.multiverse", "--space", "quick",
                           "--out", str(tmp_path / "mv"), "hydra/launcher=slurm"],
                          cwd=ROOT, capture_output=True, text=True, timeout=600,
                          env={**os.environ, "PYTHONPATH": str(ROOT), "PATH": str(empty)})
    assert proc.returncode == 2, proc.stderr[-2000:]
    last = _error_lines(proc.stderr)[-1]  # the key, what is missing, that nothing ran
    assert last.startswith("error: hydra/launcher=slurm") and "not on PATH" in last
    assert all(name in last for name in ("sbatch", "srun", "squeue"))
    assert "nothing was submitted" in last
