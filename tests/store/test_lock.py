"""Hostile concurrency on one output folder: the folder lock is a kernel lock (``flock``,
released by the kernel when its process ends, however it ends) and host-aware: a lock file
written on another host is never taken over.

The command and the line the user sees, e.g. a second run into a folder locked on another
node::

    $ python -m pipeline.run hydra.run.dir=runs/a
    error: runs/a is locked by another run (pid 4242 on host node17); wait for it to finish,
    or if it has ended remove runs/a/.lock, or choose another output folder

(one line; exit code 2). The old lock tested the pid with ``os.kill(pid, 0)``, which on this
host says nothing about a process on another one: it broke a live lock of another node.
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from pipeline.errors import FolderBusyError
from pipeline.store.lock import LOCK, folder_lock

ROOT = Path(__file__).resolve().parents[2]
HOST = socket.gethostname()

HOLDER = """
import sys, time
from pipeline.store.lock import folder_lock
with folder_lock(sys.argv[1]):
    print("held", flush=True)
    time.sleep(120)
"""


def _holder(folder: Path) -> subprocess.Popen:
    """Another process holding ``folder``'s lock (until killed)."""
    proc = subprocess.Popen([sys.executable, "-c", HOLDER, str(folder)],
                            stdout=subprocess.PIPE, text=True,
                            env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert proc.stdout is not None and proc.stdout.readline().strip() == "held"
    return proc


def test_a_live_lock_of_this_host_is_refused_naming_its_pid(tmp_path):
    folder = tmp_path / "runs"
    holder = _holder(folder)
    try:
        with pytest.raises(FolderBusyError) as info, folder_lock(folder):
            pass
        message = str(info.value)
        assert message.startswith(f"{folder} is in use by another run (pid {holder.pid})")
        assert "choose another output folder" in message
        assert (folder / LOCK).read_text() == f"{holder.pid} {HOST}\n"
    finally:
        holder.kill()
        holder.wait()


def test_a_killed_holder_releases_its_lock_at_once(tmp_path):
    """SIGKILL leaves the file, but the kernel released the lock: the next writer takes it
    (even if the dead holder's pid were reused by another process meanwhile)."""
    folder = tmp_path / "runs"
    holder = _holder(folder)
    holder.send_signal(signal.SIGKILL)
    holder.wait()
    assert (folder / LOCK).exists()
    with folder_lock(folder):
        assert (folder / LOCK).read_text() == f"{os.getpid()} {HOST}\n"
    assert not (folder / LOCK).exists()
    # a file naming a live process of this host but locked by nobody: that process is not a
    # writer (its pid was reused), so the lock is free
    (folder / LOCK).write_text(f"{os.getppid()} {HOST}\n")
    with folder_lock(folder):
        pass


def test_another_hosts_lock_is_never_broken(tmp_path):
    """A lock file written on another node (whose pid means nothing here, and whose ``flock``
    this host's kernel may not see on a cluster file system) is refused, never taken."""
    folder = tmp_path / "runs"
    folder.mkdir()
    (folder / LOCK).write_text("999999999 node17.cluster\n")
    with pytest.raises(FolderBusyError) as info, folder_lock(folder):
        pass
    message = str(info.value)
    assert message.startswith(f"{folder} is locked by another run (pid 999999999 on host "
                              "node17.cluster)")
    assert f"remove {folder / LOCK}" in message
    assert (folder / LOCK).read_text() == "999999999 node17.cluster\n"  # untouched


def test_the_command_line_for_another_hosts_lock(tmp_path):
    """``python -m pipeline.run hydra.run.dir=D`` with D locked on another host: exit 2, the
    one line above, nothing written."""
    folder = tmp_path / "runs"
    folder.mkdir()
    (folder / LOCK).write_text("4242 node17\n")
    proc = subprocess.run([sys.executable, "-m", "pipeline.run", f"hydra.run.dir={folder}"],
                          cwd=ROOT, capture_output=True, text=True, timeout=300,
                          env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert proc.returncode == 2
    line = proc.stderr.strip().splitlines()[-1]
    assert line.startswith(f"error: {folder} is locked by another run (pid 4242 on host "
                           "node17)") and f"remove {folder / LOCK}" in line
    assert not (folder / "metrics.json").exists()


def test_a_lock_of_the_earlier_format_still_works(tmp_path):
    """``.lock`` holding a pid only (written before this change): a dead pid is taken over,
    a live one refused (the earlier rule, on this host)."""
    folder = tmp_path / "runs"
    folder.mkdir()
    (folder / LOCK).write_text("999999999\n")
    with folder_lock(folder):
        pass
    sleeper = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        (folder / LOCK).write_text(f"{sleeper.pid}\n")
        with pytest.raises(FolderBusyError, match=f"pid {sleeper.pid}"), folder_lock(folder):
            pass
    finally:
        sleeper.kill()
        sleeper.wait()


def test_the_same_process_may_nest_the_lock(tmp_path):
    folder = tmp_path / "runs"
    with folder_lock(folder), folder_lock(folder):
        assert (folder / LOCK).exists()
    assert not (folder / LOCK).exists()


def test_two_writers_racing_for_a_new_folder_never_both_hold_it(tmp_path):
    """Eight processes start at once on one folder: each either holds the lock alone or is
    refused with one line; no two ever hold it together (each holder checks that it is the
    only one inside)."""
    folder = tmp_path / "runs"
    racer = """
import os, sys, time
from pipeline.errors import FolderBusyError
from pipeline.store.lock import folder_lock
folder = sys.argv[1]
time.sleep(max(0.0, float(sys.argv[2]) - time.time()))
try:
    with folder_lock(folder):
        marker = os.path.join(folder, "inside")
        fd = os.open(marker, os.O_CREAT | os.O_EXCL | os.O_WRONLY)  # fails if another is in
        time.sleep(0.2)
        os.close(fd)
        os.unlink(marker)
    print("held")
except FolderBusyError as exc:
    print("busy", str(exc).count(chr(10)))
"""
    start = time.time() + 3.0
    procs = [subprocess.Popen([sys.executable, "-c", racer, str(folder), str(start)],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                              env={**os.environ, "PYTHONPATH": str(ROOT)}) for _ in range(8)]
    outcomes = [p.communicate(timeout=120) for p in procs]
    assert all(p.returncode == 0 for p in procs), [o[1][-500:] for o in outcomes]
    words = [o[0].strip() for o in outcomes]
    assert "held" in words and all(w in ("held", "busy 0") for w in words)
    assert not (folder / LOCK).exists()


@settings(max_examples=40, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(content=st.one_of(st.binary(max_size=64),
                         st.text(max_size=40).map(str.encode),
                         st.builds(lambda pid, host: f"{pid} {host}\n".encode(),
                                   st.integers(0, 2**40), st.sampled_from([HOST, "other-node"]))))
@example(content="\u00b9".encode())  # a digit to str.isdigit, not to int()
@example(content="\u0663 other-node\n".encode())  # an Arabic-Indic three
def test_any_lock_file_content_is_taken_or_refused_in_one_line(tmp_path, content):
    """Property: whatever a (damaged, foreign, empty) lock file holds, folder_lock either
    takes it (and then writes this process and host) or refuses in one line; it never takes
    a lock that names another host."""
    folder = tmp_path / "prop"
    folder.mkdir(exist_ok=True)
    (folder / LOCK).write_bytes(content)
    words = content.decode("utf-8", "replace").split()
    # a pid is ASCII digits (what a lock writes); anything else is a damaged file, not a holder
    foreign = (len(words) > 1 and words[0].isascii() and words[0].isdigit()
               and len(words[0]) < 12 and words[1] != HOST)
    try:
        with folder_lock(folder):
            assert (folder / LOCK).read_text() == f"{os.getpid()} {HOST}\n"
        taken = True
    except FolderBusyError as exc:
        assert "\n" not in str(exc)
        taken = False
    assert not (taken and foreign)
    (folder / LOCK).unlink(missing_ok=True)


def test_two_nmpc_checks_into_one_folder_the_second_is_refused(tmp_path, capsys):
    """``python -m pipeline.nmpc_check --out D`` while another check writes D: exit 2, one
    line naming the first (before: both ran and their table and summary could mix)."""
    import pipeline.nmpc_check as command

    folder = tmp_path / "nmpc"
    holder = _holder(folder)
    try:
        assert command.main(["--family-size", "1", "--track", "kinematic", "--out",
                             str(folder)]) == 2
    finally:
        holder.kill()
        holder.wait()
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(
        f"error: {folder} is in use by another run (pid {holder.pid})")
    assert sorted(p.name for p in folder.iterdir()) == [LOCK]  # the killed holder's file
