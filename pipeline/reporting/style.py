"""How the report writes its figures: a checked style read from
``conf/report/figure_style/<name>.yaml`` (``pipeline.report --figure-style``)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

from pipeline.errors import ConfigError


@dataclass(frozen=True)
class FigureStyle:
    """How figures are written (``conf/report/figure_style/<name>.yaml``, chosen with
    ``pipeline.report --figure-style``): the report inlines the PNG and links the vector file.

    Attributes
    ----------
    width_in : float or None
        Every figure scaled to this width (inches, aspect kept); None: as designed (7 in).
    dpi : int
        PNG resolution.
    vector_format : str
        ``"svg"`` or ``"pdf"`` (fonts embedded as TrueType, editable in a paper's figure).
    font_family : str
        Matplotlib's ``font.family`` (e.g. ``"serif"`` for a paper).
    """

    width_in: Optional[float] = None
    dpi: int = 130
    vector_format: str = "svg"
    font_family: str = "sans-serif"

    def __post_init__(self) -> None:
        if self.width_in is not None and not (isinstance(self.width_in, (int, float))
                                              and 1.0 <= self.width_in <= 20.0):
            raise ConfigError("figure_style.width_in", self.width_in,
                              "null or a width in inches in [1, 20]")
        if isinstance(self.dpi, bool) or not isinstance(self.dpi, int) \
                or not 50 <= self.dpi <= 600:
            raise ConfigError("figure_style.dpi", self.dpi, "an integer in [50, 600]")
        if self.vector_format not in ("svg", "pdf"):
            raise ConfigError("figure_style.vector_format", self.vector_format,
                              "one of 'svg', 'pdf'")
        if not isinstance(self.font_family, str) or not self.font_family:
            raise ConfigError("figure_style.font_family", self.font_family,
                              "a matplotlib font family, e.g. 'serif'")

    def rc(self) -> dict:
        """The matplotlib settings this style implies (for ``plt.rc_context``)."""
        return {"font.family": self.font_family, "svg.fonttype": "none",
                "pdf.fonttype": 42}


def load_figure_style(name: str) -> FigureStyle:
    """The figure style ``conf/report/figure_style/<name>.yaml`` (or a YAML file's path),
    checked: an unknown key, a wrong type or a value out of range raises
    :class:`pipeline.errors.ConfigError` naming the key and what is allowed."""
    import dataclasses
    from pathlib import Path

    from pipeline.config import CONF_DIR
    from pipeline.store.safe_load import load_yaml

    folder = Path(CONF_DIR) / "report" / "figure_style"
    path = Path(name) if name.endswith((".yaml", ".yml")) else folder / f"{name}.yaml"
    if not path.exists():
        known = sorted(p.stem for p in folder.glob("*.yaml"))
        raise ConfigError("--figure-style", name, f"one of {known} or a YAML file's path")
    # size, UTF-8 and alias limits: one line naming the file (pipeline.store.safe_load)
    data = load_yaml(path, "a figure style (conf/report/figure_style/<name>.yaml)") or {}
    if not isinstance(data, dict):
        raise ConfigError("figure_style", type(data).__name__, "a mapping of settings")
    allowed = [f.name for f in dataclasses.fields(FigureStyle)]
    for key in data:
        if key not in allowed:
            raise ConfigError(f"figure_style.{key}", data[key], f"one of the keys {allowed}")
    return FigureStyle(**data)
