"""Progress of long steps: a tqdm bar on a terminal, plain lines with the time left otherwise
(a log file or CI gets a readable line every few seconds, never carriage returns)."""

from __future__ import annotations

import sys
import time
from typing import Any, Protocol


class TextStream(Protocol):
    """Where progress lines go: anything with ``write`` and ``flush`` (a file, stderr, a
    stream that hands each line to a logger)."""

    def write(self, text: str, /) -> Any: ...

    def flush(self) -> Any: ...


class Progress:
    """Counts done items of ``total``; use as a context manager, call :meth:`update`.

    Parameters
    ----------
    total : int
    desc : str
        What is counted ("improved family", "multiverse: family runs").
    unit : str
    initial : int
        Items already done (a resumed run).
    disable : bool
        Print nothing.
    stream : file, optional
        Where to write (default: stderr). On a terminal a tqdm bar, else plain lines.
    every_s : float
        Plain mode: at most one line per ``every_s`` seconds (and the last one always).
    """

    def __init__(self, total: int, desc: str, unit: str = "item", initial: int = 0,
                 disable: bool = False, stream: TextStream | None = None,
                 every_s: float = 10.0) -> None:
        self.total, self.desc, self.unit = int(total), desc, unit
        self.done = self.start_done = int(initial)
        self.disable, self.every_s = disable, every_s
        self.stream = stream if stream is not None else sys.stderr
        self.started = self.last_line = time.perf_counter()
        self.bar: Any = None  # a tqdm bar on a terminal
        if not disable and getattr(self.stream, "isatty", lambda: False)():
            from tqdm import tqdm

            self.bar = tqdm(total=self.total, initial=self.done, desc=desc, unit=unit,
                            file=self.stream)

    def __enter__(self) -> Progress:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def time_left_s(self, now: float | None = None) -> float | None:
        """Seconds left at the rate of the items done in this process (None before any)."""
        fresh = self.done - self.start_done
        if fresh <= 0:
            return None
        now = time.perf_counter() if now is None else now
        return (now - self.started) / fresh * max(self.total - self.done, 0)

    def line(self, now: float | None = None) -> str:
        now = time.perf_counter() if now is None else now
        left = self.time_left_s(now)
        tail = f", about {left:.0f} s left" if left is not None and self.done < self.total \
            else ""
        plural = self.unit[:-1] + "ies" if self.unit.endswith("y") else self.unit + "s"
        return (f"{self.desc}: {self.done}/{self.total} {plural} "
                f"({now - self.started:.0f} s{tail})")

    def update(self, n: int = 1) -> None:
        self.done += n
        if self.disable:
            return
        if self.bar is not None:
            self.bar.update(n)
            return
        now = time.perf_counter()
        if self.done >= self.total or now - self.last_line >= self.every_s:
            self.last_line = now
            self.stream.write(self.line(now) + "\n")
            self.stream.flush()

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
            self.bar = None
