"""A member as an animated GIF for slides (``make clip MEMBER=family/113``): every method of
the member drives at once, each in its report colour, with the obstacles (dark once seen) and
the time; drawn with matplotlib's animation writer (Pillow, which matplotlib already needs).

The data are the scenario explorer's (:func:`pipeline.reporting.explorer.member_data`: the
same runs, the same rounding), so the clip and the explorer show the same thing.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["CLIPS_FOLDER", "Clip", "clip_frames", "clip_name", "write_clip"]

#: The clips' folder, beside the report's page (the explorer links there).
CLIPS_FOLDER = "clips"

#: The clip's size in inches and its resolution (640 x 360 px).
SIZE_IN = (8.0, 4.5)
DPI = 80


@dataclass(frozen=True)
class Clip:
    """A clip written: its file, its frames and how long it plays (seconds)."""

    path: Path
    frames: int
    duration_s: float


def clip_name(experiment: str, member: int) -> str:
    """The clip's file name for ``<experiment>/<member>`` (the explorer links to it)."""
    return f"{experiment}_{int(member)}.gif"


def clip_frames(steps: int, stride: int) -> list[int]:
    """The steps drawn: every ``stride``-th of ``steps``, and the last one always."""
    frames = list(range(0, max(int(steps), 1), int(stride)))
    if frames[-1] != steps - 1 and steps > 0:
        frames.append(steps - 1)
    return frames


def _series(method: dict, key: str, scale: float) -> np.ndarray:
    return np.array([np.nan if v is None else v / scale for v in method[key]], float)


def write_clip(payload: dict, out: Path, fps: int = 10, stride: int = 1) -> Clip:
    """Draw the member ``payload`` (the explorer's data of one member) into the GIF ``out``
    at ``fps`` frames per second, one frame every ``stride`` steps."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib import pyplot as plt
    from matplotlib.animation import FuncAnimation, PillowWriter
    from matplotlib.patches import Circle

    methods = payload["methods"]
    paths = [(_series(m, "x", 100.0), _series(m, "y", 100.0)) for m in methods]
    steps = max(len(x) for x, _ in paths)
    frames = clip_frames(steps, stride)
    footprint = float(payload.get("footprint", 1.0))
    obstacles = [(_series(o, "x", 100.0), _series(o, "y", 100.0), o["r"] / 100.0,
                  np.array(o["vis"], bool)) for o in methods[0].get("obs", [])]
    times = _series(max(methods, key=lambda m: m["n"]), "t", 1000.0)

    xs = np.concatenate([x for x, _ in paths] + [o[0] for o in obstacles]
                        + [np.array([payload["start"][0], payload["goal"][0]])])
    ys = np.concatenate([y for _, y in paths] + [o[1] for o in obstacles]
                        + [np.array([payload["start"][1], payload["goal"][1]])])
    pad = 2.0 + footprint
    fig, ax = plt.subplots(figsize=SIZE_IN, dpi=DPI)
    ax.set_xlim(np.nanmin(xs) - pad, np.nanmax(xs) + pad)
    ax.set_ylim(np.nanmin(ys) - pad, np.nanmax(ys) + pad)
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.plot(*payload["goal"], marker="*", color="#333", markersize=10, linestyle="none")
    lines: list = []
    discs: list[Circle] = []
    for method, (x, y) in zip(methods, paths, strict=True):
        color = method.get("color") or "#333"
        lines.append(ax.plot([], [], color=color, linewidth=1.6, label=method["name"])[0])
        disc = Circle((x[0], y[0]), footprint, facecolor=color, alpha=0.35, edgecolor=color)
        ax.add_patch(disc)
        discs.append(disc)
    rings = [Circle((ox[0], oy[0]), radius, facecolor="#c0392b", alpha=0.6,
                    edgecolor="#c0392b") for ox, oy, radius, _ in obstacles]
    for ring in rings:
        ax.add_patch(ring)
    legend = ax.legend(loc="upper left", fontsize=8, framealpha=0.8)
    for handle in legend.get_lines():
        handle.set_linewidth(4.0)  # a clear swatch of each method's colour
    title = ax.set_title("")

    def draw(step: int):
        for (x, y), line, disc in zip(paths, lines, discs, strict=True):
            last = min(step, len(x) - 1)
            line.set_data(x[:last + 1], y[:last + 1])
            disc.center = (x[last], y[last])
        for (ox, oy, _, seen), ring in zip(obstacles, rings, strict=True):
            k = min(step, len(ox) - 1)
            ring.center = (ox[k], oy[k])
            ring.set_alpha(0.7 if seen[k] else 0.15)  # faint until the vehicle sees it
        t = times[min(step, len(times) - 1)]
        title.set_text(f"{payload.get('scenario', '')}  {payload['key']}  t = {t:.1f} s")
        return [*lines, *discs, *rings, title]

    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    animation = FuncAnimation(fig, draw, frames=frames, blit=False)
    partial = out.with_name(out.name + ".partial.gif")
    try:
        animation.save(partial, writer=PillowWriter(fps=int(fps)))
        partial.replace(out)  # never a half-written clip under the name asked for
    finally:
        plt.close(fig)
        partial.unlink(missing_ok=True)
    return Clip(out, len(frames), len(frames) / float(fps))
