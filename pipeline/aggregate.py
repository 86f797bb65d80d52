"""Aggregate a Hydra sweep folder: ``apf-mpc aggregate SWEEP_DIR``; also the sweep's
``on_multirun_end`` callback (``AggregateCallback``, named by ``_target_`` in ``conf/config.yaml``).

The command: its options, then :func:`pipeline.studies.aggregate.aggregate` through the command
layer (:func:`pipeline.commands.run_command`).
"""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

from hydra.experimental.callback import Callback

from pipeline.commands import CommandError, cannot, run_command
from pipeline.studies.aggregate import aggregate
from pipeline.studies.results.sweep import SUMMARY, SweepSummary

__all__ = ["AggregateCallback", "aggregate", "draw_sweep_figures", "main"]

log = logging.getLogger("pipeline.aggregate")


def draw_sweep_figures(result: SweepSummary) -> None:
    """The figures of metric versus parameter of an aggregated sweep, into its folder."""
    from pipeline.reporting.figures import save_figure, sweep_figure

    good = result.summary[result.summary["status"] == "ok"]
    for fig, stem in sweep_figure(good, list(result.swept_keys)):
        save_figure(fig, result.figure_folder(), stem)


class AggregateCallback(Callback):
    """Hydra callback: aggregate the sweep folder when a multirun ends (and draw its figures).

    Configured in ``conf/config.yaml`` under ``hydra.callbacks.aggregate``.
    """

    def __init__(self, baseline_dir: str | None = None, figures: bool = True) -> None:
        self.baseline_dir = baseline_dir
        self.figures = figures

    def on_multirun_end(self, config, **kwargs) -> None:
        sweep_dir = Path(config.hydra.sweep.dir)
        try:
            result = aggregate(sweep_dir, Path(self.baseline_dir) if self.baseline_dir
                               else None, progress=False)
            if self.figures:
                draw_sweep_figures(result)
            log.info("aggregated %s -> %s", sweep_dir, sweep_dir / SUMMARY)
        except FileNotFoundError as exc:
            log.warning("aggregate skipped: %s", exc)


def main(argv: list[str] | None = None) -> int:
    """``python -m pipeline.aggregate``: ``apf-mpc aggregate``."""
    from pipeline.cli import alias

    return alias("aggregate", argv)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """``apf-mpc aggregate``'s arguments."""
    parser.add_argument("sweep_dir", type=Path)
    parser.add_argument("--baseline", type=Path, default=None,
                        help="baseline job folder for improved jobs without a partner")
    parser.add_argument("--no-figures", action="store_true", help="skip the figures")


def run(args: argparse.Namespace) -> int:
    """Aggregate as ``args`` say, through the command layer."""
    return run_command(lambda: _aggregate(args),
                       os_error=cannot("write the summary", args.sweep_dir))


def _aggregate(args) -> int:
    from pipeline.store.runs import folder_kind

    if args.baseline is not None and folder_kind(args.baseline) is None:
        # named on purpose, so never ignored: a folder that is not a trusted run or family
        raise CommandError(f"error: --baseline {args.baseline}: not a run or family folder "
                           "(no manifest)")
    if args.sweep_dir.exists() and not args.sweep_dir.is_dir():
        raise CommandError(f"error: {args.sweep_dir}: a file, not a sweep folder")
    try:
        result = aggregate(args.sweep_dir, args.baseline)
    except FileNotFoundError as exc:
        raise CommandError(f"error: {exc}") from None
    if not args.no_figures:
        draw_sweep_figures(result)
    print(f"{len(result.summary)} jobs -> {args.sweep_dir / SUMMARY}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
