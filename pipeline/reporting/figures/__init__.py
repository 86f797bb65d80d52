"""Figures stage: matplotlib figures from logged runs and study results (never shown on
screen), a drawing library that imports nothing of the pipeline.

Each ``*_figure`` function takes data and returns a ``matplotlib.figure.Figure``;
:func:`save_figure` writes it as SVG and PNG, :class:`FigureWriter` in forked children.
Nothing here simulates. Modules: :mod:`.runs`, :mod:`.claims`, :mod:`.studies`,
:mod:`.writer`, :mod:`.colors`.
"""

from pipeline.reporting.figures.claims import claim_differences_figure, family_distribution_figure
from pipeline.reporting.figures.colors import EXTRA_COLORS, method_color
from pipeline.reporting.figures.runs import (
                                               apf_force_figure,
                                               avoidance_window,
                                               closest_approach,
                                               overlay_figure,
                                               paths_figure,
                                               snapshot_times,
                                               timeseries_figure,
)
from pipeline.reporting.figures.studies import (
                                               SWEEP_METRICS,
                                               ablation_forest_figure,
                                               bench_scaling_figure,
                                               hypervolume_history_figure,
                                               pareto_front_figure,
                                               specification_curve_figure,
                                               sweep_figure,
)
from pipeline.reporting.figures.writer import FigureWriter, figure_paths, save_figure

__all__ = ["EXTRA_COLORS", "SWEEP_METRICS", "FigureWriter",
           "ablation_forest_figure", "apf_force_figure", "avoidance_window",
           "bench_scaling_figure", "claim_differences_figure", "closest_approach",
           "family_distribution_figure", "figure_paths", "method_color", "overlay_figure",
           "hypervolume_history_figure", "pareto_front_figure", "paths_figure", "save_figure", "snapshot_times",
           "sweep_figure", "specification_curve_figure", "timeseries_figure"]
