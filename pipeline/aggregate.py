"""Aggregate a Hydra sweep folder: ``python -m pipeline.aggregate SWEEP_DIR``; also the sweep's
``on_multirun_end`` callback (``AggregateCallback``, named by ``_target_`` in ``conf/config.yaml``).

The command: its options, then :func:`pipeline.studies.aggregate.aggregate` through the command
layer (:func:`pipeline.commands.run_command`).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from pipeline.commands import CommandError, cannot, run_command
from pipeline.studies.aggregate import AggregateCallback, aggregate

__all__ = ["AggregateCallback", "aggregate", "main"]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m pipeline.aggregate",
                                     description="Gather a sweep folder into summary.csv.")
    parser.add_argument("sweep_dir", type=Path)
    parser.add_argument("--baseline", type=Path, default=None,
                        help="baseline job folder for improved jobs without a partner")
    parser.add_argument("--no-figures", action="store_true", help="skip the figures")
    args = parser.parse_args(argv)
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
        summary = aggregate(args.sweep_dir, args.baseline, figures=not args.no_figures)
    except FileNotFoundError as exc:
        raise CommandError(f"error: {exc}") from None
    print(f"{len(summary)} jobs -> {args.sweep_dir / 'summary.csv'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
