"""The report's figures: each a :class:`Figure` (where its files are, what it shows), drawn by
the report's :class:`~pipeline.reporting.figures.FigureWriter` or copied from a study's folder
(the study's command drew it)."""

from __future__ import annotations

import base64
import os
import shutil
from dataclasses import dataclass
from pathlib import Path

from pipeline.reporting.figures import FigureWriter


@dataclass(frozen=True)
class Figure:
    """One figure of the page: its files (``png``, ``svg``), id, group, caption and alt text;
    ``member`` and ``why`` for a gallery member. ``src`` inlines the PNG (read when the page
    is rendered, after every figure is on disk); ``svg`` is the vector file's link."""

    id: str
    group: str
    png: Path
    svg: str
    caption: str
    alt: str
    member: int | None = None
    why: str = ""

    @property
    def src(self) -> str:
        return "data:image/png;base64," + base64.b64encode(Path(self.png).read_bytes()).decode()


@dataclass(frozen=True)
class Figures:
    """Where the page's figures go (``out_dir/figures``) and who draws them."""

    out_dir: Path
    writer: FigureWriter

    @property
    def folder(self) -> Path:
        return self.out_dir / "figures"

    def _figure(self, paths: dict[str, Path], figure_id: str, group: str, caption: str,
                alt: str, **extra) -> Figure:
        return Figure(figure_id, group, Path(paths["png"]),
                      os.path.relpath(paths["svg"], self.out_dir), caption, alt, **extra)

    def draw(self, figure, stem: str, group: str, caption: str, alt: str,
             figure_id: str | None = None, **extra) -> Figure:
        """Draw ``figure`` (a matplotlib Figure, or a function building one) as ``stem``."""
        paths = self.writer.save(figure, self.folder, stem)
        return self._figure(paths, figure_id or stem, group, caption, alt, **extra)

    def copy(self, files: dict[str, Path] | None, stem: str, group: str, caption: str,
             alt: str, figure_id: str | None = None) -> Figure | None:
        """A figure a study's command drew (``files``: its ``png`` and ``svg``), copied in as
        ``stem``; None when it is not there."""
        if files is None:
            return None
        self.folder.mkdir(parents=True, exist_ok=True)
        target = {"png": self.folder / f"{stem}.png", "svg": self.folder / f"{stem}.svg"}
        shutil.copyfile(files["png"], target["png"])
        if Path(files["svg"]).is_file():
            shutil.copyfile(files["svg"], target["svg"])
        return self._figure(target, figure_id or stem, group, caption, alt)
