"""The report's explorer runs beside the page in a forked child (pipeline.reporting.page's
_beside): its answer reaches the caller, and when the caller stops (an error, Ctrl-C, SIGTERM)
the child and everything it forked stop with it, so nothing is written after the report
returns."""

from __future__ import annotations

import os
import signal
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import pytest

import pipeline.reporting.page as page
from pipeline.errors import Interrupted, stop_on_signals
from pipeline.reporting.explorer import DATA_FOLDER, PAGE, remove_explorer_temporaries

#: how long the slow writers below wait before they write (s)
WRITE_AFTER_S = 1.5


def _write_later(path: Path) -> str:
    time.sleep(WRITE_AFTER_S)
    path.write_text("written")
    return path.name


def _slow_writer_with_a_worker(folder: Path) -> str:
    """Writes one file itself and one from a forked worker, each after WRITE_AFTER_S."""
    import multiprocessing

    with ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("fork")) as pool:
        from_worker = pool.submit(_write_later, folder / "from_worker.txt")
        _write_later(folder / "from_child.txt")
        return from_worker.result()


def _answer(value: int) -> int:
    return value * 2


def _raise_config_error() -> None:
    from pipeline.errors import ConfigError

    raise ConfigError("report.figure_jobs", 0, "an integer >= 1")


def test_the_child_s_answer_and_its_error_reach_the_caller():
    with page._beside(_answer, 21) as child:
        assert child.result() == 42
    from pipeline.errors import ConfigError

    with page._beside(_raise_config_error) as child, pytest.raises(ConfigError) as raised:
        child.result()
    assert raised.value.key == "report.figure_jobs"


def test_a_child_that_dies_is_reported_not_waited_for():
    def die():
        os.kill(os.getpid(), signal.SIGKILL)

    with page._beside(die) as child, \
            pytest.raises(RuntimeError, match="ended without an answer .exit code -9"):
        child.result()


def test_sigterm_stops_the_child_and_its_workers_at_once(tmp_path):
    """SIGTERM while the block runs: the caller is back in well under the writers' delay, and
    neither the child nor the worker it forked writes anything afterwards (before the fix the
    caller waited for the child, which wrote both files)."""
    stopped: list[bool] = []
    restore = stop_on_signals()
    started = time.perf_counter()
    try:
        with pytest.raises(Interrupted) as raised, \
                page._beside(_slow_writer_with_a_worker, tmp_path,
                             on_stop=lambda: stopped.append(True)):
            time.sleep(0.3)  # the child and its worker are writing (sleeping, here)
            os.kill(os.getpid(), signal.SIGTERM)
            time.sleep(5)  # not reached: the handler raises
    finally:
        restore()
    returned_after_s = time.perf_counter() - started
    assert raised.value.exit_code == 143
    assert returned_after_s < 0.3 + 0.8 * WRITE_AFTER_S
    assert stopped == [True]
    time.sleep(WRITE_AFTER_S + 0.5)
    assert sorted(p.name for p in tmp_path.iterdir()) == []


def test_a_taken_answer_is_not_stopped(tmp_path):
    stopped: list[bool] = []
    with page._beside(_write_later, tmp_path / "done.txt",
                      on_stop=lambda: stopped.append(True)) as child:
        assert child.result() == "done.txt"
    assert stopped == []
    assert (tmp_path / "done.txt").read_text() == "written"


def test_remove_explorer_temporaries_removes_only_temporaries(tmp_path):
    data = tmp_path / DATA_FOLDER / "family"
    data.mkdir(parents=True)
    temporaries = [tmp_path / f".{PAGE}.a1b2.tmp", data / ".s0_i3.js.x9.tmp"]
    kept = [tmp_path / PAGE, data / "s0_i3.js", tmp_path / ".index.html.c3.tmp"]
    for path in temporaries + kept:
        path.write_text("x")
    assert sorted(remove_explorer_temporaries(tmp_path)) == sorted(temporaries)
    assert [p.exists() for p in temporaries] == [False, False]
    assert [p.exists() for p in kept] == [True, True, True]


def _slow_explorer(run_root, out_dir, experiments, jobs):
    """A stand-in for write_explorer that leaves a temporary, then writes its page late."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / f".{PAGE}.slow.tmp").write_text("half")
    time.sleep(WRITE_AFTER_S)
    (out_dir / PAGE).write_text("late")


def test_an_interrupted_report_stops_its_explorer(small_reproduce, tmp_path, monkeypatch):
    """The reviewer's case: the report interrupted while its page is built returns at once;
    the explorer writes nothing after, and its temporary is removed."""
    raised_at: list[float] = []

    def interrupted_page(*args, **kwargs):
        time.sleep(0.3)
        raised_at.append(time.perf_counter())
        raise Interrupted(signal.SIGTERM)

    monkeypatch.setattr(page, "write_explorer", _slow_explorer)
    monkeypatch.setattr(page, "_report_page", interrupted_page)
    out = tmp_path / "report"
    with pytest.raises(Interrupted):
        page.build_report(small_reproduce, out, "pytest")
    assert time.perf_counter() - raised_at[0] < 0.8 * WRITE_AFTER_S
    time.sleep(WRITE_AFTER_S + 0.5)
    assert not (out / PAGE).exists()
    assert not list(out.glob(".*.tmp"))


def _unpicklable():
    return lambda: None


def test_an_answer_that_does_not_pickle_is_an_error_that_names_it():
    with page._beside(_unpicklable) as child, \
            pytest.raises(RuntimeError, match="function: .* .could not be handed over"):
        child.result()


def _worker_then_die(pid_file: Path) -> None:
    """Forks a worker that sleeps (holding the child's end of the pipe), then dies."""
    import multiprocessing

    pool = ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("fork"))
    worker_pid = pool.submit(os.getpid).result()
    pool.submit(time.sleep, 30)
    pid_file.write_text(str(worker_pid))
    os.kill(os.getpid(), signal.SIGKILL)


def test_a_child_that_dies_while_its_worker_lives_is_an_error_at_once(tmp_path):
    """The worker inherits the child's end of the pipe, so the pipe never ends: the child's
    own exit is what result() sees; its group (the worker) is then killed and on_stop runs
    (before the fix result() waited for as long as the worker lived)."""
    stopped: list[bool] = []

    def too_long(signum, frame):
        raise TimeoutError("result() still waiting after 20 s")

    previous = signal.signal(signal.SIGALRM, too_long)
    signal.alarm(20)  # a waiting result() fails the test instead of hanging it
    try:
        with page._beside(_worker_then_die, tmp_path / "worker.pid",
                          on_stop=lambda: stopped.append(True)) as child, \
                pytest.raises(RuntimeError, match="ended without an answer .exit code -9"):
            child.result()
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)
    assert stopped == [True]
    worker = int((tmp_path / "worker.pid").read_text())
    time.sleep(0.2)
    assert _state(worker) in ("gone", "Z")  # killed (a zombie until its new parent reaps it)


def _state(pid: int) -> str:
    try:
        status = Path(f"/proc/{pid}/status").read_text()
    except FileNotFoundError:
        return "gone"
    return next(line.split()[1] for line in status.splitlines() if line.startswith("State:"))


def _refuse_to_load():
    raise TypeError("cannot be rebuilt here")


class _Unloadable:
    """Pickles (by a module-level function), but loading it raises: as an exception class
    whose __init__ takes other arguments than its args does, unless tblib (which dask's
    distributed installs) rebuilds exceptions without __init__."""

    def __reduce__(self):
        return (_refuse_to_load, ())


def _return_unloadable() -> _Unloadable:
    return _Unloadable()


def test_an_answer_that_cannot_be_rebuilt_is_an_error_that_says_so():
    """It pickles in the child but cannot be rebuilt in the parent."""
    with page._beside(_return_unloadable) as child, \
            pytest.raises(RuntimeError, match="answered what cannot be read here: TypeError: "
                                              "cannot be rebuilt here"):
        child.result()
