"""``apf-mpc nmpc-check [--family-size 50] [--track both] [--out DIR]`` (``make nmpc-check``): each track's linear MPC against the same problem on the nonlinear model
(:mod:`pipeline.studies.nmpc_check`), through the command layer
(:func:`pipeline.commands.run_command`)."""

from __future__ import annotations

import argparse
import json
import logging
import sys
from pathlib import Path

from pipeline.commands import CommandError, cannot, checked_family_size, output_folder, run_command
from pipeline.studies.nmpc_check import nmpc_agreement

__all__ = ["main", "nmpc_agreement"]

log = logging.getLogger("pipeline.nmpc_check")


def main(argv: list[str] | None = None) -> int:
    """``python -m pipeline.nmpc_check``: ``apf-mpc nmpc-check``."""
    from pipeline.cli import alias

    return alias("nmpc-check", argv)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """``apf-mpc nmpc-check``'s arguments."""
    # --family-size, as `apf-mpc bench` and the config's scenario.family.size name it; --members
    # stays as its alias
    parser.add_argument("--family-size", "--members", dest="family_size", type=int,
                        default=50,
                        help="family members per method (1-10000, default 50)")
    parser.add_argument("--out", type=output_folder, default=Path("outputs/nmpc_check"))
    parser.add_argument("--track", choices=("both", "lateral", "kinematic"), default="both",
                        help="which track's linear MPC to check (default both)")
    parser.add_argument("--jobs", type=int, default=2,
                        help="worker processes (1-64, default 2)")


def run(args: argparse.Namespace) -> int:
    """The check as ``args`` say, through the command layer."""
    return run_command(lambda: _check(args), kept="completed runs",
                       os_error=cannot("write its results", args.out))


def _check(args) -> int:
    from pipeline.studies.compose import composer

    if not 1 <= args.jobs <= 64:
        raise CommandError(f"--jobs: {args.jobs} is not allowed; allowed: an integer in "
                           "[1, 64]")
    checked_family_size(args.family_size)
    if args.out.exists() and not args.out.is_dir():
        raise CommandError(f"--out: {args.out} is not a folder; allowed: a folder (new, or "
                           "one this check wrote before)")
    tracks = ("lateral", "kinematic") if args.track == "both" else (args.track,)
    result = nmpc_agreement(composer([])[0], args.out, args.family_size, log=log.info,
                            tracks=tracks, n_jobs=args.jobs)
    print(json.dumps({track: {k: v for k, v in part.items() if k != "verdicts"}
                      for track, part in result.to_json()["tracks"].items()}, indent=1))
    print(f"agreement written to {args.out.resolve()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
