"""How robust is each verdict: ``apf-mpc multiverse [--space NAME|PATH] [--out DIR]``.

The command: its options, then :func:`pipeline.studies.multiverse.run_multiverse` through the
command layer (:func:`pipeline.commands.run_command`).
"""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

import pandas as pd

from pipeline.commands import CommandError, output_folder, run_command
from pipeline.studies import multiverse as study
from pipeline.studies.results import MultiverseResult

__all__ = ["main"]

log = logging.getLogger("pipeline.multiverse")


def main(argv: list[str] | None = None) -> int:
    """``python -m pipeline.multiverse``: ``apf-mpc multiverse``."""
    from pipeline.cli import alias

    return alias("multiverse", argv)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """``apf-mpc multiverse``'s arguments."""
    parser.add_argument("--space", default="default",
                        help="conf/multiverse/<name>.yaml or a path (default: default)")
    parser.add_argument("--out", type=output_folder, default=Path("outputs/multiverse"))
    parser.add_argument("--jobs", type=int, default=2, help="analysis workers (default 2)")
    parser.add_argument("overrides", nargs="*", help="Hydra overrides for every run")


def run(args: argparse.Namespace) -> int:
    """The multiverse as ``args`` say, through the command layer."""
    return run_command(lambda: _multiverse(args))


def draw_specification_curves(result: MultiverseResult) -> None:
    """One specification curve per claim, into the result's figure folder (drawn in forked
    children; all on disk when this returns)."""
    from pipeline.analysis.claims import ALL_CLAIMS
    from pipeline.reporting.figures import FigureWriter, specification_curve_figure
    from pipeline.studies.multiverse import matches

    design = result.design.set_index("spec_id")
    default = design[design["kind"] == "default"].iloc[0]
    keys = [d["key"] for d in result.info.dimensions]
    changed = pd.DataFrame({key: ~matches(design[key], default[key]) for key in keys})
    folder = result.figure_folder()
    with FigureWriter() as writer:
        for claim in ALL_CLAIMS:
            writer.save(specification_curve_figure(result.specifications, changed,
                                                   claim.claim_id),
                        folder, MultiverseResult.curve_stem(claim.claim_id))


def _multiverse(args) -> int:
    from pipeline.config import CONF_DIR

    if not 1 <= args.jobs <= 256:
        raise CommandError(f"error: --jobs={args.jobs} is invalid; allowed: an integer in "
                           "[1, 256]")
    path = Path(args.space)
    if not path.suffix:
        path = CONF_DIR / "multiverse" / f"{args.space}.yaml"
    result = study.run_multiverse(study.load_space(path), args.out, args.overrides, args.jobs,
                                  log=log.info)
    draw_specification_curves(result)
    for r in result.robustness.to_dict("records"):
        print(f"{r['claim']} vs {r['comparison']}: default {r['default_outcome']}, {r['label']} "
              f"({100 * r['agree_share']:.0f} % agree); most influential: "
              f"{r['most_influential']}")
    print(f"multiverse written to {args.out.resolve()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
