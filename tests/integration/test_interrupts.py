"""Hostile interrupts: SIGINT (Ctrl-C) and SIGTERM stop every command with 130 or 143, one
line and nothing half-written, wherever they land: inside IPOPT (CasADi swallows Ctrl-C and
reports a failed solve, which the NMPC took for a fallback step and the check then exited 0
with wrong numbers), in a finalizer or a weakref callback (matplotlib's callback registry
drops what is raised there), or in a worker process.

The command and the line the user sees::

    $ python -m pipeline.nmpc_check --family-size 1 --track kinematic --jobs 1   # then Ctrl-C
    stopped (interrupted): completed runs are kept; the same command resumes

(exit 130; 143 and ``stopped (SIGTERM): ...`` for SIGTERM).
"""

from __future__ import annotations

import gc
import os
import random
import signal
import subprocess
import sys
import threading
import time
import weakref
from pathlib import Path

import numpy as np
import pytest

from pipeline.commands import run_command
from pipeline.errors import Interrupted, stop_on_signals

ROOT = Path(__file__).resolve().parents[2]
STOPPED = "stopped (interrupted): completed runs are kept; the same command resumes"


def _slow_nlp(n: int = 1500):
    """A CasADi/IPOPT problem that takes about a tenth of a second to solve."""
    import casadi as ca

    x = ca.SX.sym("x", n)
    nlp = {"x": x, "f": ca.sumsqr(x - 1) + ca.sum1(ca.sin(x) ** 4),
           "g": ca.vertcat(*[x[i] * x[i + 1] for i in range(n - 1)])}
    return ca.nlpsol("slow", "ipopt", nlp, {"print_time": False, "ipopt.print_level": 0,
                                            "ipopt.sb": "yes", "ipopt.tol": 1e-14}), n


@pytest.mark.parametrize("under_command", [False, True], ids=["api", "command"])
def test_ctrl_c_inside_ipopt_is_an_interrupt_never_a_failed_solve(under_command):
    """SIGINT while IPOPT iterates: ``ipopt_solve`` raises KeyboardInterrupt (Interrupted
    under a command) instead of returning CasADi's ``NonIpopt_Exception_Thrown`` as a failed
    solve, which the controllers turned into a fallback step. Before: 12 of 12 such solves
    came back as ``solver_error``."""
    from pipeline.loop.controller.nmpc import ipopt_solve

    solver, n = _slow_nlp()
    assert ipopt_solve(solver, x0=np.zeros(n), lbg=-1, ubg=1)[0] == "optimal"
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)  # Python's own
    restore = stop_on_signals() if under_command else (lambda: None)
    outcomes = []
    try:
        for delay in (0.01, 0.02, 0.03, 0.04):
            if under_command:  # a fresh handler per try: each remembers its own signal
                restore()
                restore = stop_on_signals()
            timer = threading.Timer(delay, os.kill, (os.getpid(), signal.SIGINT))
            try:
                timer.start()
                status = ipopt_solve(solver, x0=np.zeros(n), lbg=-1, ubg=1)[0]
                outcomes.append(status)
                time.sleep(2)  # the signal came after the solve: it lands here
            except KeyboardInterrupt as exc:
                outcomes.append(type(exc).__name__)
            finally:
                timer.join()
    finally:
        restore()
        signal.signal(signal.SIGINT, previous)
    expected = "Interrupted" if under_command else "KeyboardInterrupt"
    assert "solver_error" not in outcomes
    assert set(outcomes) <= {expected, "optimal"} and expected in outcomes


@pytest.mark.filterwarnings("ignore::pytest.PytestUnraisableExceptionWarning")
def test_an_interrupt_swallowed_in_a_finalizer_still_stops_the_command(capsys):
    """A KeyboardInterrupt raised inside a weakref callback (what matplotlib's callback
    registry runs when a figure goes) or a ``__del__`` is printed and dropped by Python: the
    command used to finish and exit 0. Now the handler remembers the signal and the command
    exits 130 with its one line."""

    class Figure:
        pass

    def work():
        figure = Figure()
        # the signal arrives while the callback runs: its handler runs there too
        ref = weakref.ref(figure, lambda ref: os.kill(os.getpid(), signal.SIGINT) or
                          [None for _ in range(1000)])
        del figure  # the callback runs; the KeyboardInterrupt it raised is dropped
        gc.collect()
        assert ref() is None
        return 0

    assert run_command(work) == 130
    err = capsys.readouterr().err
    last = err.strip().splitlines()[-1]
    assert last.startswith("stopped (interrupted)") and "kept" in last and "resumes" in last


def test_nothing_is_committed_after_a_swallowed_interrupt(tmp_path):
    """Once a signal was received, an atomic write removes its temporary and raises instead
    of renaming it into place, even when the exception the handler raised was lost."""
    from pipeline.store.files import write_text_atomic

    restore = stop_on_signals()
    try:
        try:
            os.kill(os.getpid(), signal.SIGTERM)
            time.sleep(1)
        except Interrupted:
            pass  # swallowed, as a C extension or a finalizer would
        with pytest.raises(Interrupted) as info:
            write_text_atomic(tmp_path / "summary.json", "{}\n")
        assert info.value.exit_code == 143
    finally:
        restore()
    assert list(tmp_path.iterdir()) == []


def _nmpc_check(out: Path, jobs: int) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "pipeline.nmpc_check", "--family-size", "4", "--track", "kinematic",
         "--jobs", str(jobs), "--out", str(out)],
        cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        start_new_session=True,  # its own process group: Ctrl-C reaches its workers too
        env={**os.environ, "PYTHONPATH": str(ROOT)})


@pytest.mark.parametrize(("signum", "jobs", "seed"),
                         [(signal.SIGINT, 1, 1), (signal.SIGINT, 1, 2),
                          (signal.SIGTERM, 1, 3), (signal.SIGINT, 2, 4)],
                         ids=["sigint-a", "sigint-b", "sigterm", "sigint-workers"])
def test_nmpc_check_interrupted_at_a_random_moment_never_exits_0(tmp_path, signum, jobs,
                                                                 seed):
    """``python -m pipeline.nmpc_check`` stopped at a random moment of its solves (the
    NMPCs' IPOPT runs most of the time): exit 130 or 143 with the one line, no table, no
    temporary. Ctrl-C goes to the whole process group, as a terminal sends it (the workers
    too); SIGTERM to the command alone, as ``kill`` does. Before: Ctrl-C inside IPOPT was
    swallowed in 3 of 7 tries and the check exited 0 with fallback steps in its numbers."""
    out = tmp_path / "nmpc"
    proc = _nmpc_check(out, jobs)
    try:
        deadline = time.monotonic() + 120
        while not out.exists() and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.05)  # the study has begun: its runs come next
        assert proc.poll() is None, proc.stderr.read() if proc.stderr else ""
        time.sleep(random.Random(seed).uniform(0.5, 6.0))
        if signum == signal.SIGINT:
            os.killpg(proc.pid, signum)
        else:
            proc.send_signal(signum)
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    assert proc.returncode == 128 + signum, err[-2000:]
    how = "interrupted" if signum == signal.SIGINT else "SIGTERM"
    # (the whole stderr's tail on failure: once, under make test, its last line began with a
    # traceback's carets)
    assert err.strip().splitlines()[-1] == STOPPED.replace("interrupted", how), err[-3000:]
    # no table, no temporary: only the study lock's (empty) file, which the kernel released
    assert sorted(p.name for p in out.rglob("*")) == []  # the lock removed on the way out


def test_joblibs_workers_are_stopped_through_psutil():
    """Stopping the workers on a signal goes through psutil: without it joblib's loky backend
    kills their tree with pgrep, and a pgrep stopped by the same signal printed a traceback
    (``AttributeError: 'Popen' object has no attribute 'kill'``) after a SIGTERM to a tune."""
    from joblib.externals.loky.backend import utils

    assert utils.psutil is not None


def test_an_interrupt_raised_inside_a_finalizer_prints_no_traceback():
    """A signal handled while Python runs a ``__del__`` cannot raise there: Python printed
    ``Exception ignored in ...`` and the interrupt's traceback (once, after a tune's SIGTERM:
    ``pipeline.errors.Interrupted: 15``). Under a command it is not printed (the command stops
    with its one line); any other exception in a finalizer still is. (A subprocess: pytest
    takes the unraisable hook over in its own process.)"""
    code = (
        "import gc, signal, sys\n"
        "from pipeline.commands import run_command\n"
        "from pipeline.errors import Interrupted\n"
        "class Finalized:\n"
        "    def __init__(self, error): self.error = error\n"
        "    def __del__(self): raise self.error\n"
        "def work():\n"
        "    quiet = Finalized(Interrupted(signal.SIGTERM)); del quiet\n"
        "    loud = Finalized(ValueError(\"a finalizer's own bug\")); del loud\n"
        "    gc.collect(); return 0\n"
        "sys.exit(run_command(work))\n")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=120, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr
    assert "Interrupted" not in proc.stderr and "a finalizer's own bug" in proc.stderr


def test_a_stopped_pool_prints_nothing_from_loky_s_thread(make_config, tmp_path):
    """A tune stopped mid-rung stops its family pool with tasks queued: every task settled by
    the executor's shutdown before ``stop()`` returns, none cancelled (a future cancelled
    before the shutdown made loky's manager thread raise ``InvalidStateError: CANCELLED``
    after the command's stop line); loky's own threads, racing the killed workers (a
    ``KeyError`` on a work item under load), print nothing; any other thread still does."""
    import threading

    from pipeline.loop.controller import QpCache
    from pipeline.store.member_cache import MemberCounts
    from pipeline.studies.family_pool import FamilyPool

    raised: list[BaseException] = []
    previous = threading.excepthook
    threading.excepthook = lambda args: raised.append(args.exc_value)
    try:
        cfg = make_config(["method=improved", "scenario=family", "scenario.family.size=24",
                           "controller.backend=daqp"])
        pool = FamilyPool(2, QpCache(), None, MemberCounts())
        pool.submit(cfg, tmp_path / "family", lambda: None)
        futures = list(pool._futures)
        assert len(futures) >= 2
        pool.stop()
        # settled by the shutdown before stop() returned, none cancelled: loky's thread has
        # nothing left to set on a cancelled future later
        assert all(f.done() and not f.cancelled() for f in futures)
        time.sleep(0.5)
        # another thread's exception is still reported (only loky's own threads are quiet)
        other = threading.Thread(target=lambda: (_ for _ in ()).throw(ValueError("mine")))
        other.start()
        other.join()
    finally:
        threading.excepthook = previous
    assert [type(e).__name__ for e in raised] == ["ValueError"]
    assert not pool._futures


class _PlantedSolver:
    """A CasADi solver whose result's conversion to numpy fails as CasADi's did when SIGINT
    arrived there: a SystemError caused by the interrupt (or by something else)."""

    def __init__(self, cause: BaseException) -> None:
        self.cause = cause

    def __call__(self, **arguments):
        cause = self.cause

        class Result:
            def __array__(self, dtype=None, copy=None):
                try:
                    raise cause
                except BaseException as exc:
                    raise SystemError("returned a result with an exception set") from exc

        return {"x": Result()}

    @staticmethod
    def stats():
        return {"return_status": "Solve_Succeeded", "iter_count": 3}


def test_an_interrupt_inside_the_results_conversion_is_an_interrupt():
    """SIGINT just after IPOPT returned, while numpy converts CasADi's result: numpy wraps the
    interrupt in a SystemError; ipopt_solve raises the interrupt itself (seen on a loaded
    machine in test_ctrl_c_inside_ipopt_is_an_interrupt_never_a_failed_solve), and any other
    SystemError stays what it is."""
    from pipeline.loop.controller.nmpc import ipopt_solve

    with pytest.raises(KeyboardInterrupt):
        ipopt_solve(_PlantedSolver(KeyboardInterrupt()))
    with pytest.raises(SystemError):
        ipopt_solve(_PlantedSolver(ValueError("not an interrupt")))


def test_workers_leave_ctrl_c_to_the_command():
    """A family's or the NMPC check's worker ignores SIGINT (the command alone stops on a
    Ctrl-C to the process group, and its workers are killed): in a process other than the
    named parent the handler becomes SIG_IGN; in the parent, or with no parent named, it is
    left as it was. Oracle: the handler a forked child reports."""
    from joblib import Parallel, delayed

    from pipeline.errors import leave_interrupts_to

    before = signal.getsignal(signal.SIGINT)
    leave_interrupts_to(os.getpid())
    leave_interrupts_to(None)
    assert signal.getsignal(signal.SIGINT) is before

    # a task in a thread (a Dask worker's) leaves its process's handler alone: no error
    failures: list[BaseException] = []

    def in_a_thread():
        try:
            leave_interrupts_to(os.getpid() + 1)
        except BaseException as exc:  # reported below
            failures.append(exc)

    thread = threading.Thread(target=in_a_thread)
    thread.start()
    thread.join()
    assert not failures and signal.getsignal(signal.SIGINT) is before
    ignored = Parallel(n_jobs=2)(delayed(_sigint_ignored_after)(pid, leave)
                                 for pid, leave in ((os.getpid(), True), (None, False)))
    assert ignored == [True, False]


def _sigint_ignored_after(parent_pid, leave):
    """In a joblib worker: whether SIGINT is ignored after leave_interrupts_to(parent_pid)
    (the handler put back first: a reused worker may have run the other case)."""
    from pipeline.errors import leave_interrupts_to

    signal.signal(signal.SIGINT, signal.default_int_handler)
    if leave:
        leave_interrupts_to(parent_pid)
    else:
        leave_interrupts_to(None)
    return signal.getsignal(signal.SIGINT) == signal.SIG_IGN


#: In a fresh interpreter (joblib's workers are reused within a process): the workers a
#: generator-mode Parallel starts inside workers_start_deaf_to_ctrl_c begin with SIGINT blocked,
#: and the mask is restored after the block
_DEAF_WORKERS = """
import os, signal
from joblib import Parallel, delayed
from pipeline.errors import workers_start_deaf_to_ctrl_c

def blocked(_):
    return signal.SIGINT in signal.pthread_sigmask(signal.SIG_BLOCK, set()), os.getpid()

if __name__ == "__main__":
    with workers_start_deaf_to_ctrl_c():
        results = Parallel(n_jobs=2, return_as="generator_unordered")(
            delayed(blocked)(i) for i in range(8))
    here = signal.SIGINT in signal.pthread_sigmask(signal.SIG_BLOCK, set())
    print(sorted({b for b, _ in results}), here)
"""


def test_workers_start_with_ctrl_c_blocked_and_a_ctrl_c_meanwhile_waits(tmp_path):
    """A worker Ctrl-C reaches in its start-up (before leave_interrupts_to) printed a
    traceback into the command's one line (seen in make test: the NMPC check's last line
    began with a traceback's carets). Started inside workers_start_deaf_to_ctrl_c, every
    worker reports SIGINT blocked (fails without the resource tracker started first: it
    unblocks SIGINT in the thread that starts it); here the mask is as before, and a SIGINT
    received inside the block is raised when it ends."""
    from pipeline.errors import workers_start_deaf_to_ctrl_c

    script = tmp_path / "deaf.py"
    script.write_text(_DEAF_WORKERS)
    done = subprocess.run([sys.executable, str(script)], capture_output=True, text=True,
                          timeout=120, cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.split() == ["[True]", "False"]

    restore = stop_on_signals()
    reached: list[str] = []
    try:
        with pytest.raises(Interrupted) as raised, workers_start_deaf_to_ctrl_c():
            # to this thread (a signal to the process may be taken by another thread,
            # whose handler raises here at once, as without the block)
            signal.pthread_kill(threading.main_thread().ident, signal.SIGINT)
            time.sleep(0.2)  # blocked: nothing is raised here
            reached.append("end of block")
    finally:
        restore()
    assert reached == ["end of block"] and raised.value.exit_code == 130
