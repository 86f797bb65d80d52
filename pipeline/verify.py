"""Compare fresh results with ``reports/reference/``: ``apf-mpc-verify RUNS REF`` (or
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
    parser = argparse.ArgumentParser(prog="apf-mpc-verify", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("runs", type=Path, help="runs folder (make reproduce's outputs)")
    parser.add_argument("reference", type=Path, nargs="?", default=Path("reports/reference"))
    parser.add_argument("--update", action="store_true", help="rewrite the reference")
    args = parser.parse_args(argv)
    return run_command(lambda: _verify(args), os_error=cannot(
        "write" if args.update else "read", args.reference))


def _verify(args) -> int:
    if args.reference.exists() and not args.reference.is_dir():
        raise CommandError(f"error: reference {args.reference}: a file, not a folder")
    try:
        problems = verify(args.runs, args.reference, args.update)
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


if __name__ == "__main__":
    sys.exit(main())
