"""``apf-mpc euro-ncap [--family-size 110] [--tracks lateral,kinematic] [--out DIR]
[overrides...]`` (``make euro-ncap``): the methods on the Euro NCAP crossings
(:mod:`pipeline.studies.euro_ncap`), through the command layer
(:func:`pipeline.commands.run_command`)."""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

from pipeline.commands import checked_family_size, comma_choices, output_folder, run_command
from pipeline.studies.euro_ncap import TRACKS

__all__ = ["main"]

log = logging.getLogger("pipeline.euro_ncap")


def main(argv: list[str] | None = None) -> int:
    """``python -m pipeline.euro_ncap``: ``apf-mpc euro-ncap``."""
    from pipeline.cli import alias

    return alias("euro-ncap", argv)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """``apf-mpc euro-ncap``'s arguments."""
    parser.add_argument("--family-size", dest="family_size", type=int, default=110,
                        help="tests per method (1-10000, default 110: the protocol's grid of "
                             "5 cases x 11 speeds twice)")
    parser.add_argument("--tracks", default=",".join(TRACKS),
                        help="comma-separated subset of: " + ", ".join(TRACKS))
    parser.add_argument("--out", type=output_folder, default=Path("outputs/euro_ncap"))
    parser.add_argument("overrides", nargs="*",
                        help="Hydra overrides for every run, e.g. "
                             "'scenario.source.params.cases=[CPNC-50]'")


def run(args: argparse.Namespace) -> int:
    """The study as ``args`` say, through the command layer."""
    return run_command(lambda: _study(args), kept="completed family runs")


def _study(args: argparse.Namespace) -> int:
    from pipeline.studies.compose import composer
    from pipeline.studies.euro_ncap import euro_ncap

    checked_family_size(args.family_size)
    tracks = comma_choices("--tracks", args.tracks, tuple(TRACKS))
    result = euro_ncap(composer([])[0], args.out, args.family_size,
                       tracks, log=log.info, extra=tuple(args.overrides))
    for track in result.tracks:
        for row in result.summary_rows(track):
            print(f"{track} {row['method']}: {row['avoided']} of {row['tests']} tests avoided")
    print(f"Euro NCAP study written to {args.out.resolve()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
