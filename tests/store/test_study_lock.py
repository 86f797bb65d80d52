"""A study's hold on its folder (the one folder lock, ``pipeline.store.lock.folder_lock`` with
the study's name; ``filelock``'s descriptor lock): a second holder is refused with the first
one named, even in the same process, and a killed holder leaves nothing behind that blocks the
next study."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import pytest

from pipeline.errors import FolderBusyError
from pipeline.store.lock import LOCK, folder_lock


def test_a_second_holder_is_refused_naming_the_first_and_the_lock_is_released(tmp_path):
    with folder_lock(tmp_path, "tune quick"):
        assert (tmp_path / LOCK).read_text().split()[2:] == ["tune", "quick"]
        with pytest.raises(FolderBusyError, match=r"in use by another study \(tune quick, pid "
                           rf"{os.getpid()}\)"), folder_lock(tmp_path, "multiverse quick"):
            pass
        with folder_lock(tmp_path):  # a run of the same process nests (a study's families)
            pass
    assert not (tmp_path / LOCK).exists()
    with folder_lock(tmp_path, "multiverse quick"):  # released: the next study takes it
        pass


def test_a_holder_killed_with_sigkill_never_blocks_the_next_study(tmp_path):
    code = ("import sys, time; from pipeline.store.lock import folder_lock\n"
            f"with folder_lock({str(tmp_path)!r}, 'tune default'):\n"
            "    print('held', flush=True); time.sleep(60)\n")
    proc = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout is not None and proc.stdout.readline().strip() == "held"
        with pytest.raises(FolderBusyError, match=rf"\(tune default, pid {proc.pid}\)"), \
                folder_lock(tmp_path, "tune quick"):
            pass
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=30)
    deadline = time.monotonic() + 5
    with folder_lock(tmp_path, "tune quick"):  # the kernel released the dead holder's lock
        assert time.monotonic() < deadline
