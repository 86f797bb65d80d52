"""The recorded-pedestrian scene figure: the pedestrians' true tracks over a member's run and
each method's path through them."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")  # files only, no display

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
from matplotlib.figure import Figure
from matplotlib.patches import Circle

from pipeline.reporting.figures.colors import method_color


def _tracks(trajectory: pd.DataFrame) -> list[tuple[np.ndarray, np.ndarray]]:
    """Each logged pedestrian's positions and whether the vehicle saw it, row by row."""
    out, j = [], 0
    while f"obs{j}_x_m" in trajectory.columns:
        xy = trajectory[[f"obs{j}_x_m", f"obs{j}_y_m"]].to_numpy(float)
        out.append((xy, trajectory[f"obs{j}_visible"].to_numpy(bool)))
        j += 1
    return out


def pedestrian_scene_figure(runs: dict[str, pd.DataFrame], start_xy_m: tuple[float, float],
                            goal_xy_m: tuple[float, float], sensor_range_m: float,
                            vehicle_radius_m: float, title: str,
                            width_in: float = 7.0) -> Figure:
    """One member of the pedestrian family: every simulated pedestrian's true track over the
    longest run (grey; darker where the vehicle saw it), each method's path with its
    footprint at the end, start, goal and the sensor range around the start.

    Parameters
    ----------
    runs : dict of method -> trajectory
        The member's runs (the same pedestrians in each).
    start_xy_m, goal_xy_m : tuple
    sensor_range_m, vehicle_radius_m : float
    title : str
    """
    fig, ax = plt.subplots(figsize=(width_in, 0.75 * width_in), layout="constrained")
    longest = max(runs.values(), key=len)
    for xy, seen in _tracks(longest):
        moving = np.r_[True, np.any(np.diff(xy, axis=0) != 0.0, axis=1)]
        ax.plot(xy[moving, 0], xy[moving, 1], color="0.75", lw=0.8, zorder=1)
        if seen.any():
            ax.plot(np.where(seen, xy[:, 0], np.nan), np.where(seen, xy[:, 1], np.nan),
                    color="0.35", lw=1.2, zorder=2)
        ax.plot(xy[moving, 0][-1:], xy[moving, 1][-1:], marker=">", color="0.5", ms=3,
                ls="none", zorder=2)
    for method, tr in runs.items():
        color = method_color(method)
        ax.plot(tr["X_m"], tr["Y_m"], color=color, lw=2, zorder=3, label=method)
        ax.add_patch(Circle((float(tr["X_m"].iloc[-1]), float(tr["Y_m"].iloc[-1])),
                            vehicle_radius_m, fill=False, ec=color, lw=1, zorder=3))
    ax.add_patch(Circle(start_xy_m, sensor_range_m, fill=False, ec="k", ls=":", lw=0.8))
    ax.plot(*start_xy_m, "ko", ms=4)
    ax.plot(*goal_xy_m, marker="*", color="gold", mec="k", ms=12, ls="none")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x [m] (dot: start, dotted: sensor range there, star: goal)", fontsize=8)
    ax.set_ylabel("y [m]", fontsize=8)
    ax.set_title(title, fontsize=9, loc="left")
    ax.tick_params(labelsize=7)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8, loc="best")
    return fig
