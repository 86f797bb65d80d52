"""``apf-mpc speed-check [--family-size 200] [--out DIR]`` (``make speed-check``): is slower ever less safe? (:mod:`pipeline.studies.speed`), through the command
layer (:func:`pipeline.commands.run_command`)."""

from __future__ import annotations

import argparse
import json
import logging
import sys
from pathlib import Path

from pipeline.commands import checked_family_size, comma_choices, output_folder, run_command
from pipeline.studies.speed import VARIANTS, speed_check

__all__ = ["main", "speed_check"]

log = logging.getLogger("pipeline.speed_check")


def main(argv: list[str] | None = None) -> int:
    """``python -m pipeline.speed_check``: ``apf-mpc speed-check``."""
    from pipeline.cli import alias

    return alias("speed-check", argv)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """``apf-mpc speed-check``'s arguments."""
    # --family-size, as `apf-mpc bench` and the config's scenario.family.size name it; --members
    # stays as its alias
    parser.add_argument("--family-size", "--members", dest="family_size", type=int,
                        default=200,
                        help="family members per variant and method (1-10000, default 200)")
    parser.add_argument("--out", type=output_folder, default=Path("outputs/speed"))
    parser.add_argument("--variants", default=",".join(VARIANTS),
                        help="comma-separated subset of: " + ", ".join(VARIANTS))


def run(args: argparse.Namespace) -> int:
    """The check as ``args`` say, through the command layer."""
    return run_command(lambda: _check(args), kept="completed family runs")


def _check(args) -> int:
    from pipeline.studies.compose import composer

    checked_family_size(args.family_size)
    variants = comma_choices("--variants", args.variants, tuple(VARIANTS))
    result = speed_check(composer([])[0], args.out, args.family_size, log=log.info,
                         variants=variants)
    print(json.dumps(result.to_json()["checks"], indent=1))
    print(f"speed check written to {args.out.resolve()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
