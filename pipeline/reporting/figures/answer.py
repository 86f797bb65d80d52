"""The answer as a picture: each claim's effect with its interval and its margin, one panel
per claim (each on its own scale and unit), one row per reading (our settings against each
control, both methods tuned over replicates, the APF by itself), in the style of rliable's
interval plots. Written as SVG by hand so that every interval is a link (``<a href>``) to
the scenarios behind it; no matplotlib, nothing of the pipeline."""

from __future__ import annotations

import math
from dataclasses import dataclass
from html import escape

#: fill of each outcome's interval and point
OUTCOME_COLORS = {"supported": "#2a9d3c", "contradicted": "#c0392b", "equivalent": "#4a5a8c",
                  "inconclusive": "#b8860b", "mixed": "#8e44ad"}
NEUTRAL = "#777777"


@dataclass(frozen=True)
class Interval:
    """One estimate with its interval; ``outcome`` colours it; ``href`` is where a click goes,
    ``title`` its tooltip."""

    estimate: float
    low: float
    high: float
    outcome: str
    href: str = ""
    title: str = ""


@dataclass(frozen=True)
class AnswerRow:
    """One reading of a claim: its label, its intervals (one, or one per replicate) and a
    note written at the right (an outcome, or counts over replicates)."""

    label: str
    intervals: tuple[Interval, ...]
    note: str = ""


@dataclass(frozen=True)
class AnswerPanel:
    """One claim: id, words, unit, margin (the band drawn around zero), rows, and the link of
    its title (its ledger row)."""

    claim: str
    words: str
    unit: str
    margin: float
    rows: tuple[AnswerRow, ...]
    href: str = ""


def _finite(*values: float) -> list[float]:
    return [v for v in values if v is not None and math.isfinite(v)]


def _scale(panel: AnswerPanel) -> tuple[float, float]:
    """The panel's x range: every interval, the margin band and zero, padded by 6 %."""
    values = _finite(0.0, panel.margin, -panel.margin,
                     *(v for row in panel.rows for i in row.intervals
                       for v in (i.low, i.high, i.estimate)))
    low, high = min(values), max(values)
    if high - low <= 0:
        low, high = low - 1.0, high + 1.0
    pad = 0.06 * (high - low)
    return low - pad, high + pad


def _tick(value: float) -> str:
    return f"{value:.2g}" if value != 0 else "0"


def answer_svg(panels: tuple[AnswerPanel, ...], width_px: int = 500, label_px: int = 150,
               note_px: int = 96, row_px: int = 13, title_px: int = 17) -> str:
    """The figure as an SVG document (``<svg>``, inlined by the page and written beside it).

    Each panel: the claim's title with its scale's ends and unit, a grey band from -margin to
    +margin (inside it the effect is negligible: "equivalent" when the whole interval is in
    it), a dashed line at zero, and per row its intervals (a line from low to high, a dot at
    the estimate) coloured by outcome, each a link. Below zero is the paper's claimed
    direction throughout."""
    x0, x1 = label_px, width_px - note_px
    parts: list[str] = []
    y = 2
    for panel in panels:
        low, high = _scale(panel)

        def x(value: float, low: float = low, high: float = high) -> float:
            return x0 + (x1 - x0) * (value - low) / (high - low)

        title = escape(f"{panel.claim} {panel.words}")
        head = f'<text x="0" y="{y + 12}" class="t">{title}</text>'
        if panel.href:
            head = f'<a href="{escape(panel.href)}">{head}</a>'
        parts.append(head)
        parts.append(f'<text x="{width_px}" y="{y + 12}" class="s" text-anchor="end">'
                     f'{escape(_tick(low))} … {escape(_tick(high))} {escape(panel.unit)}</text>')
        y += title_px
        top, bottom = y, y + row_px * len(panel.rows)
        if panel.margin > 0:
            left, right = x(max(-panel.margin, low)), x(min(panel.margin, high))
            parts.append(f'<rect x="{left:.1f}" y="{top}" width="{right - left:.1f}" '
                         f'height="{bottom - top}" fill="#e6e6e6"><title>margin ±'
                         f'{escape(_tick(panel.margin))} {escape(panel.unit)}</title></rect>')
        parts.append(f'<line x1="{x(0):.1f}" x2="{x(0):.1f}" y1="{top}" y2="{bottom}" '
                     'stroke="#555" stroke-dasharray="2,2"/>')
        for row in panel.rows:
            mid = y + row_px / 2
            parts.append(f'<text x="0" y="{mid + 4:.1f}" class="s">{escape(row.label)}</text>')
            for item in row.intervals:
                color = OUTCOME_COLORS.get(item.outcome, NEUTRAL)
                shapes = []
                ends = _finite(item.low, item.high)
                if len(ends) == 2:
                    shapes.append(f'<line x1="{x(ends[0]):.1f}" x2="{x(ends[1]):.1f}" '
                                  f'y1="{mid:.1f}" y2="{mid:.1f}" stroke="{color}" '
                                  'stroke-width="3"/>')
                if _finite(item.estimate):
                    shapes.append(f'<circle cx="{x(item.estimate):.1f}" cy="{mid:.1f}" r="3.5" '
                                  f'fill="{color}" stroke="#fff" stroke-width="0.8"/>')
                if not shapes:
                    continue
                body = f'<title>{escape(item.title)}</title>' + "".join(shapes)
                parts.append(f'<a href="{escape(item.href)}">{body}</a>' if item.href
                             else f"<g>{body}</g>")
            if row.note:
                color = OUTCOME_COLORS.get(row.note.split()[0], "#333")
                parts.append(f'<text x="{width_px}" y="{mid + 4:.1f}" class="s" '
                             f'text-anchor="end" fill="{color}">{escape(row.note)}</text>')
            y += row_px
        y += 7
    height = y + 2
    return (f'<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 {width_px} {height}" '
            f'width="{width_px}" height="{height}" role="img" font-family="system-ui, '
            'sans-serif"><style>.t{font-size:11.5px;font-weight:600}.s{font-size:11px}'
            'a:hover line,a:hover circle{stroke:#000}</style>'
            + "".join(parts) + "</svg>")
