"""Figures of the claims ledger: paired differences, distributions per method."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")  # files only, no display

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
from matplotlib.figure import Figure

from pipeline.reporting.figures.colors import method_color


def claim_differences_figure(differences: dict[tuple[str, str], np.ndarray | None],
                             metric_names: dict[str, str],
                             intervals: dict[tuple[str, str], tuple[float, float, float]]
                             ) -> Figure:
    """Per-scenario paired differences (improved - comparison, < 0 is better): one row per
    comparison, one panel per claim, with the estimate and its interval.

    Keys of ``differences`` and ``intervals`` are ``(claim_id, comparison)``; intervals are
    ``(low, high, estimate)``.
    """
    keys = list(differences)
    claims = list(dict.fromkeys(claim for claim, _ in keys))
    comparisons = list(dict.fromkeys(comparison for _, comparison in keys))
    fig, axes = plt.subplots(len(comparisons), len(claims),
                             figsize=(1.9 * len(claims) + 0.8, 2.9 * len(comparisons)),
                             layout="constrained", squeeze=False)
    rng = np.random.default_rng(0)  # jitter only
    for r, comparison in enumerate(comparisons):
        for c, claim in enumerate(claims):
            ax = axes[r][c]
            key = (claim, comparison)
            if key not in differences:
                ax.set_visible(False)
                continue
            d = np.asarray(differences[key], dtype=float)
            span = max(np.max(np.abs(d)) if d.size else 1.0, 1e-9) * 1.15
            ax.scatter(rng.uniform(-0.25, 0.25, d.size), d, s=7, alpha=0.4, color="#1f77b4")
            ax.axhline(0.0, color="k", lw=0.8)
            low, high, estimate = intervals[key]
            if np.isfinite(estimate):
                ax.errorbar([0.45], [estimate],
                            yerr=[[max(estimate - low, 0.0)], [max(high - estimate, 0.0)]],
                            fmt="D", color="#d62728", capsize=4, label="estimate, CI (1 - alpha/7)")
            ax.set_ylim(-span, span)
            ax.set_title(f"{claim} vs {comparison}", fontsize=8)
            if r == len(comparisons) - 1:
                ax.set_xlabel(metric_names.get(claim, claim), fontsize=7)
            ax.set_xticks([])
            ax.set_xlim(-0.6, 0.7)
            ax.tick_params(axis="y", labelsize=7)
            ax.grid(True, axis="y", alpha=0.3)
        axes[r][0].set_ylabel(f"improved - {comparison}\n(< 0: improved better)", fontsize=8)
    axes[0][0].legend(fontsize=7, loc="lower left")
    return fig


def family_distribution_figure(tables: dict[str, pd.DataFrame], metrics: list[str]) -> Figure:
    """Box plots of metrics per method over the scenario family."""
    fig, axes = plt.subplots(1, len(metrics), figsize=(2.6 * len(metrics), 3.8),
                             layout="constrained", squeeze=False)
    methods = list(tables)
    for ax, metric in zip(axes[0], metrics, strict=True):
        data = [tables[m][metric].astype(float).dropna().to_numpy() for m in methods]
        parts = ax.boxplot(data, tick_labels=methods, showfliers=True, patch_artist=True,
                           flierprops={"markersize": 2})
        for patch, method in zip(parts["boxes"], methods, strict=True):
            patch.set_facecolor(method_color(method))
            patch.set_alpha(0.5)
        ax.set_title(metric, fontsize=8)
        ax.tick_params(axis="x", labelrotation=60, labelsize=7)
        ax.tick_params(axis="y", labelsize=7)
        ax.grid(True, axis="y", alpha=0.3)
    return fig


SWEEP_METRICS = ("reaction_delay_s", "lateral_jerk_rms_mps3", "repulsion_unneeded_share",
                 "recovery_time_s", "oscillation_count", "min_clearance_m")
