"""Whole processes stopped, locked out and resumed (the integration tier: each starts
``python -m pipeline.run`` and signals it): SIGTERM to a family, a second run into a busy folder,
SIGKILL in the middle of a sweep. Moved here from the stage folders (issue 57, item 4: the tiers
before it run in under four minutes); the guarantees are the same tests."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import pandas as pd

SWEEP = ["-m", "method=baseline,improved", "scenario=family", "scenario.family.size=2",
         "scenario.family.n_jobs=1", "scenario.family.seed=0,1"]


def test_sigterm_stops_a_family_keeps_its_members_and_a_resume_gives_the_same_bytes(tmp_path):
    """SIGTERM to ``pipeline.run`` on a 40-member family: it exits 143 within seconds with one
    line, its workers stop with it (no member appears afterwards), no temporary is left; rerunning
    the same command completes it with family.json and family_metrics.csv byte-identical to an
    uninterrupted run's."""
    import signal
    import subprocess
    import sys
    import time

    def command(folder):
        return [sys.executable, "-m", "pipeline.run", "method=improved", "scenario=family",
                "scenario.family.size=40", f"hydra.run.dir={folder}"]

    folder = tmp_path / "fam"
    proc = subprocess.Popen(command(folder), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and len(list(folder.glob("member_*/manifest.json"))) < 10:
        time.sleep(0.2)
    proc.send_signal(signal.SIGTERM)
    start = time.monotonic()
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 143 and time.monotonic() - start < 10
    assert err.strip().splitlines()[-1].startswith("stopped (SIGTERM)")
    done = len(list(folder.glob("member_*/manifest.json")))
    time.sleep(2)
    assert len(list(folder.glob("member_*/manifest.json"))) == done < 40
    assert list(folder.rglob("*.tmp")) == []
    assert not (folder / "family.json").exists()
    resumed = subprocess.run(command(folder), capture_output=True, text=True)
    assert resumed.returncode == 0, resumed.stderr[-500:]
    fresh = tmp_path / "fresh"
    assert subprocess.run(command(fresh), capture_output=True).returncode == 0
    for name in ("family.json", "family_metrics.csv"):
        assert (folder / name).read_bytes() == (fresh / name).read_bytes(), name


def test_a_second_run_into_a_busy_folder_exits_2_naming_the_first(tmp_path):
    """Two runs into one folder: the second exits 2 with one line naming the first's pid and
    writes nothing; a lock left by a killed run (its process gone) is taken over."""
    import subprocess
    import sys
    import time

    folder = tmp_path / "fam"
    first = subprocess.Popen([sys.executable, "-m", "pipeline.run", "method=improved",
                              "scenario=family", "scenario.family.size=200",
                              f"hydra.run.dir={folder}"], stdout=subprocess.DEVNULL,
                             stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and not (folder / ".lock").exists():
            time.sleep(0.1)
        second = subprocess.run([sys.executable, "-m", "pipeline.run", "method=baseline",
                                 f"hydra.run.dir={folder}"], capture_output=True, text=True)
        assert second.returncode == 2
        line = second.stderr.strip().splitlines()[-1]
        assert f"pid {first.pid}" in line and "another run" in line
        assert not (folder / "metrics.json").exists()
    finally:
        first.terminate()
        first.wait(timeout=60)
    # a stale lock (no such process) does not block the next run
    stale = tmp_path / "stale"
    stale.mkdir()
    (stale / ".lock").write_text("999999999\n")
    rerun = subprocess.run([sys.executable, "-m", "pipeline.run", "method=baseline",
                            f"hydra.run.dir={stale}"], capture_output=True, text=True)
    assert rerun.returncode == 0, rerun.stderr[-300:]
    assert (stale / "metrics.json").is_file() and not (stale / ".lock").exists()


def test_sweep_killed_with_sigkill_then_resumed_equals_an_uninterrupted_one(tmp_path):
    clean, broken = tmp_path / "clean", tmp_path / "broken"
    command = [sys.executable, "-m", "pipeline.run", *SWEEP]
    subprocess.run(command + [f"hydra.sweep.dir={clean}"], check=True, capture_output=True,
                   timeout=600)
    proc = subprocess.Popen(command + [f"hydra.sweep.dir={broken}"], stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL, start_new_session=True)
    deadline = time.time() + 300
    while time.time() < deadline and not list(broken.glob("*/family.json")):
        time.sleep(0.05)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    finished_before = len(list(broken.glob("*/family.json")))
    assert 1 <= finished_before < 4, "the kill did not land half-way"
    subprocess.run(command + [f"hydra.sweep.dir={broken}"], check=True, capture_output=True,
                   timeout=600)
    assert not list(broken.rglob("*.tmp")), "a half-written file survived"
    assert len(list(broken.glob("*/family.json"))) == 4
    for job in sorted(clean.glob("*/family_metrics.csv")):
        twin = broken / job.parent.name / "family_metrics.csv"
        assert twin.read_bytes() == job.read_bytes(), job.parent.name
    a, b = pd.read_csv(clean / "summary.csv"), pd.read_csv(broken / "summary.csv")
    pd.testing.assert_frame_equal(a, b)
