"""The fair fight: ``apf-mpc tune [--space default] [--out DIR] [hydra overrides]`` (``make
tune``). The work is :func:`pipeline.studies.tune.run_tuning`."""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

from pipeline.commands import output_folder, run_command
from pipeline.config import CONF_DIR
from pipeline.studies.results.tune import PARTS, TuneResult
from pipeline.studies.tune import TuneSpace, front_points, load_tune_space, run_tuning
from pipeline.studies.workers import Workers

__all__ = ["main", "run_tuning"]

log = logging.getLogger("pipeline.tune")


def main(argv: list[str] | None = None) -> int:
    """``python -m pipeline.tune``: ``apf-mpc tune``."""
    from pipeline.cli import alias

    return alias("tune", argv)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """``apf-mpc tune``'s arguments."""
    parser.add_argument("--space", default="default",
                        help="conf/tune/<name>.yaml or a path (default: default)")
    parser.add_argument("--out", type=output_folder, default=Path("outputs/tune"))
    parser.add_argument("--set", dest="changes", action="append", default=[],
                        metavar="KEY=VALUE",
                        help="change one setting of the space (e.g. --set 'rungs=[]' for the "
                             "unpruned check; --set name=... names the changed space)")
    parser.add_argument("--workers", default="local",
                        help="where the families run: local (this machine's worker "
                             "processes), dask-local:N, dask://HOST:PORT (a running Dask "
                             "scheduler) or dask-slurm:N (N SLURM jobs of one Dask worker); "
                             "the numbers are the same")
    parser.add_argument("overrides", nargs="*",
                        help="Hydra overrides for every run (e.g. hydra/launcher=slurm)")


def run(args: argparse.Namespace) -> int:
    """Tune as ``args`` say, through the command layer."""
    return run_command(lambda: _tune(args), kept="completed family runs and tables")


def draw_figures(result: TuneResult, space: TuneSpace) -> None:
    """The first replicate's Pareto settings of each method on the training and the held-out
    family (every pair of objectives on shared axes) and every replicate's hypervolume
    history, into the result's figure folder."""
    from pipeline.reporting.figures import (
        hypervolume_history_figure,
        pareto_front_figure,
        save_figure,
    )

    for part in PARTS:
        points = front_points(result.trials, result.heldout, space, part, replicate=0)
        save_figure(pareto_front_figure(points, [o.label for o in space.objectives],
                                        f"{part} family, replicate 0"),
                    result.figure_folder(), TuneResult.front_stem(part))
    save_figure(hypervolume_history_figure(list(result.summary.replicates),
                                           space.convergence_window),
                result.figure_folder(), TuneResult.HISTORY_STEM)


def _tune(args) -> int:
    path = Path(args.space)
    if not path.suffix:
        path = CONF_DIR / "tune" / f"{args.space}.yaml"
    space = load_tune_space(path, args.changes)
    workers = Workers.parse(args.workers)
    result = run_tuning(space, args.out, args.overrides, log=log.info, workers=workers)
    draw_figures(result, space)
    if result.summary.settle_note:
        print(result.summary.settle_note)
    for claim in result.summary.claims:
        print(claim.answer)
    if result.summary.label:
        print(f"not for the headline: {result.summary.label}")
    print(f"tuning written to {Path(args.out).resolve()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
