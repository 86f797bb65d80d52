"""Compare fresh results with ``reports/reference/``: ``apf-mpc verify RUNS REF`` (or
``python -m pipeline.verify``).

The command: its options, then :func:`pipeline.studies.verify.verify` through the command
layer (:func:`pipeline.commands.run_command`). Numbers must agree within ``rel 1e-6 or abs
1e-6``, labels and verdicts exactly; ``--update`` rewrites the reference (say why in the
commit).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from pipeline.commands import CommandError, cannot, run_command
from pipeline.studies.verify import verify

__all__ = ["main", "verify"]


def main(argv: list[str] | None = None) -> int:
    """``python -m pipeline.verify``: ``apf-mpc verify``."""
    from pipeline.cli import alias

    return alias("verify", argv)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """``apf-mpc verify``'s arguments."""
    parser.add_argument("runs", type=Path, help="runs folder (make reproduce's outputs)")
    parser.add_argument("reference", type=Path, nargs="?", default=Path("reports/reference"))
    parser.add_argument("--update", action="store_true", help="rewrite the reference")
    parser.add_argument("--seeds", type=int, default=5,
                        help="bootstrap seeds the answer's outcomes must agree under "
                             "(claims.seed 0..N-1; 0 or 1: not checked; default 5)")


def run(args: argparse.Namespace) -> int:
    """Verify as ``args`` say, through the command layer."""
    return run_command(lambda: _verify(args), os_error=cannot(
        "write" if args.update else "read", args.reference))


def _verify(args) -> int:
    if args.reference.exists() and not args.reference.is_dir():
        raise CommandError(f"error: reference {args.reference}: a file, not a folder")
    if not 0 <= args.seeds <= 50:
        raise CommandError(f"error: --seeds {args.seeds}: an integer in [0, 50]")
    try:
        problems = verify(args.runs, args.reference, args.update, report_ledgers(args.runs),
                          0 if args.update else args.seeds)
    except FileNotFoundError as exc:
        raise CommandError(f"error: {exc}") from None
    if args.update:
        print(f"reference written to {args.reference}")
        return 0
    for line in problems:
        print(line)
    print("verify: " + ("OK, matches the reference" if not problems
                        else f"{len(problems)} difference(s)"))
    return 1 if problems else 0


def report_ledgers(runs: Path):
    """The report's ledgers over ``runs`` under a bootstrap seed (see
    :data:`pipeline.studies.verify.Ledgers`): the runs are read at the first call, once;
    without a family to judge there are none."""
    import dataclasses
    import logging

    import pandas as pd

    from pipeline.reporting.inputs import ReportInputs
    from pipeline.reporting.tables import answer_outcomes, published_ledgers
    from pipeline.reporting.verdicts import Verdicts

    read: list[ReportInputs] = []

    def ledgers(seed):
        if not read:
            # the report's progress lines are not verify's (a skipped folder still warns)
            logging.getLogger("pipeline.reporting").setLevel(logging.WARNING)
            read.append(ReportInputs.load(runs))
        inputs = read[0]
        if inputs.family is None or not inputs.family.judgeable(inputs.claims):
            return {}, pd.DataFrame(columns=["ledger", "claim", "comparison", "outcome"])
        claims = inputs.claims if seed is None else dataclasses.replace(inputs.claims,
                                                                        seed=seed)
        verdicts = Verdicts.compute(inputs, claims)
        return published_ledgers(verdicts), answer_outcomes(verdicts)

    return ledgers


if __name__ == "__main__":
    sys.exit(main())
