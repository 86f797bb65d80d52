"""Writing figures: SVG and PNG with fixed metadata, in forked children beside the caller."""

from __future__ import annotations

import os
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # files only, no display

import matplotlib.pyplot as plt
from matplotlib.figure import Figure


def figure_paths(out_dir: Path, stem: str, style=None) -> dict[str, Path]:
    """Where :func:`save_figure` writes ``stem``: ``"png"`` and ``"svg"`` (the vector file,
    whatever ``style``'s vector format)."""
    vector = getattr(style, "vector_format", "svg")
    return {"svg": Path(out_dir) / f"{stem}.{vector}", "png": Path(out_dir) / f"{stem}.png"}


def save_figure(fig: Figure, out_dir: Path, stem: str, style=None) -> dict[str, Path]:
    """Write ``stem.<vector format>`` and ``stem.png`` into ``out_dir`` and close the figure.

    ``style`` (a :class:`pipeline.reporting.style.FigureStyle`, or anything with its
    ``width_in``, ``dpi`` and ``vector_format``) sets the width, the PNG's resolution and the
    vector format; by default each figure as designed, 130 dpi, SVG. The returned mapping has
    ``"png"`` and ``"svg"`` (the vector file, whatever its format)."""
    width_in = getattr(style, "width_in", None)
    dpi = getattr(style, "dpi", 130)
    vector = getattr(style, "vector_format", "svg")
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = figure_paths(out_dir, stem, style)
    if width_in is not None:
        width, height = fig.get_size_inches()
        fig.set_size_inches(width_in, height * width_in / width)
    engine = fig.get_layout_engine()
    if engine is not None:
        # the layout solved once for both files (each savefig would solve it again: it was
        # 40 % of the report's time), then frozen. No engine at all afterwards: with any engine
        # left (even the "none" placeholder) savefig draws the figure once more, unrendered,
        # before drawing it for the file
        engine.execute(fig)
        with matplotlib.rc_context({"figure.autolayout": False,
                                    "figure.constrained_layout.use": False}):
            fig.set_layout_engine(None)
    # fixed metadata (and the SVG's element ids salted by the file's name, not at random) so
    # that identical data give identical files
    with matplotlib.rc_context({"svg.hashsalt": stem}):
        fig.savefig(paths["svg"], metadata={"CreationDate": None} if vector == "pdf"
                    else {"Date": None})
    fig.savefig(paths["png"], dpi=dpi, metadata={"Software": None})
    plt.close(fig)
    return paths


class FigureWriter:
    """Writes figures like :func:`save_figure`, each in a forked child process when it can, so
    that building and drawing them (most of a report's time) runs beside the caller's work.

    :meth:`save` takes a figure, or a function of no arguments that builds one (then the child
    builds it too), and returns the paths at once; the files exist after :meth:`close` (or the
    end of a ``with`` block). A child inherits the figure, its data and the matplotlib settings
    in force by ``fork`` (nothing is pickled) and exits with the files written. A child that
    fails leaves its figure to be written here, in this process, at :meth:`close`
    (:attr:`written_here` counts them). With ``max_workers=1``, or where ``os.fork`` does not
    exist, every figure is written here at once.

    Parameters
    ----------
    style : FigureStyle or None
        As for :func:`save_figure`.
    max_workers : int or None
        Children at the same time; None: twice the machine's cores (the caller keeps working
        while they run, so a few more than the cores keep every core busy).
    """

    def __init__(self, style=None, max_workers: int | None = None) -> None:
        self.style = style
        self.max_workers = int(max_workers or 2 * (os.cpu_count() or 1))
        self.parallel = self.max_workers > 1 and hasattr(os, "fork")
        self.forked = 0          # children started
        self.written_here = 0    # figures written in this process (serial, or a child failed)
        self._running: list = []  # (pid, figure or builder, out_dir, stem), oldest first

    def save(self, figure, out_dir: Path, stem: str) -> dict[str, Path]:
        """Write ``figure`` (a Figure, or a function returning one) as ``stem.<vector format>``
        and ``stem.png`` under ``out_dir`` (now, or in a child); the paths as
        :func:`save_figure` returns them."""
        out_dir = Path(out_dir)
        if not self.parallel:
            self.written_here += 1
            return self._write(figure, out_dir, stem)
        import sys
        import warnings

        out_dir.mkdir(parents=True, exist_ok=True)
        while len(self._running) >= self.max_workers:
            self._reap_oldest()
        # nothing buffered may be written twice (the child leaves by os._exit, unflushed)
        sys.stdout.flush()
        sys.stderr.flush()
        with warnings.catch_warnings():
            # Python >= 3.12 warns on fork with threads; here the only other threads are the
            # BLAS library's idle workers, and the child draws one figure and exits
            warnings.simplefilter("ignore", DeprecationWarning)
            pid = os.fork()
        if pid == 0:  # the child: write the files, leave without running the parent's exit code
            code = 1
            try:
                self._write(figure, out_dir, stem)
                code = 0
            finally:
                os._exit(code)
        self.forked += 1
        if isinstance(figure, Figure):
            plt.close(figure)  # out of pyplot's registry; the object stays for a fallback
        self._running.append((pid, figure, out_dir, stem))
        return figure_paths(out_dir, stem, self.style)

    def _write(self, figure, out_dir: Path, stem: str) -> dict[str, Path]:
        return save_figure(figure if isinstance(figure, Figure) else figure(), out_dir, stem,
                           self.style)

    def _reap_oldest(self, redraw: bool = True) -> None:
        pid, figure, out_dir, stem = self._running.pop(0)
        _, status = os.waitpid(pid, 0)
        if redraw and not (os.WIFEXITED(status) and os.WEXITSTATUS(status) == 0):
            # the child failed (or was killed): write the figure here instead
            self.written_here += 1
            self._write(figure, out_dir, stem)

    def close(self, redraw: bool = True) -> None:
        """Wait for every child; afterwards every figure saved so far is on disk (with
        ``redraw=False``, what failed in a child is left undrawn)."""
        while self._running:
            self._reap_oldest(redraw)

    def __enter__(self) -> FigureWriter:
        return self

    def __exit__(self, exc_type, *exc) -> None:
        # leaving on an error or a signal (Ctrl-C reaches the children too): wait for the
        # children, never redraw what they left, so that stopping stays prompt
        self.close(redraw=exc_type is None)
