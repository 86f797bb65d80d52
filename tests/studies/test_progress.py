"""Progress of long steps: plain lines with the time left when not on a terminal, a tqdm bar
on one."""

from __future__ import annotations

import io

from pipeline.studies.progress import Progress


class _Tty(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_plain_lines_count_and_estimate_the_time_left(monkeypatch):
    clock = iter([0.0, 2.0, 4.0, 6.0, 8.0])
    monkeypatch.setattr("pipeline.studies.progress.time.perf_counter", lambda: next(clock))
    out = io.StringIO()
    with Progress(4, "improved family", "scenario", stream=out, every_s=0.0) as bar:
        for _ in range(4):
            bar.update()
    lines = out.getvalue().splitlines()
    # 2 s per item: after the first of four, 6 s left; no carriage returns, the last has none
    assert lines[0] == "improved family: 1/4 scenarios (2 s, about 6 s left)"
    assert lines[-1] == "improved family: 4/4 scenarios (8 s)"
    assert "\r" not in out.getvalue() and len(lines) == 4


def test_plain_lines_are_rate_limited_and_a_resume_counts_only_new_work(monkeypatch):
    clock = iter([0.0, 1.0, 2.0, 30.0, 31.0])
    monkeypatch.setattr("pipeline.studies.progress.time.perf_counter", lambda: next(clock))
    out = io.StringIO()
    bar = Progress(6, "x", stream=out, initial=2, every_s=10.0)
    for _ in range(4):
        bar.update()
    lines = out.getvalue().splitlines()
    assert lines == ["x: 5/6 items (30 s, about 10 s left)", "x: 6/6 items (31 s)"]


def test_a_terminal_gets_a_tqdm_bar_and_disable_prints_nothing():
    tty = _Tty()
    with Progress(3, "bar", stream=tty) as bar:
        assert bar.bar is not None
        bar.update(3)
    assert "3/3" in tty.getvalue()
    quiet = io.StringIO()
    with Progress(3, "quiet", stream=quiet, disable=True) as bar:
        bar.update(3)
    assert quiet.getvalue() == ""
