"""Entry point: ``python -m pipeline.nmpc_check [--members 50] [--track both] [--out DIR]``
(``make nmpc-check``): each track's linear MPC against the same problem on the nonlinear model
(:mod:`pipeline.studies.nmpc_check`)."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from pipeline.errors import run_study
from pipeline.studies.nmpc_check import nmpc_agreement

__all__ = ["main", "nmpc_agreement"]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m pipeline.nmpc_check",
                                     description=__doc__.split("\n\n")[0])
    parser.add_argument("--members", type=int, default=50,
                        help="family members per method (1-10000, default 50)")
    parser.add_argument("--out", type=Path, default=Path("outputs/nmpc_check"))
    parser.add_argument("--track", choices=("both", "lateral", "kinematic"), default="both",
                        help="which track's linear MPC to check (default both)")
    parser.add_argument("--jobs", type=int, default=2,
                        help="worker processes (1-64, default 2)")
    args = parser.parse_args(argv)
    if not 1 <= args.jobs <= 64:
        print(f"--jobs: {args.jobs} is not allowed; allowed: an integer in [1, 64]",
              file=sys.stderr)
        return 2
    tracks = ("lateral", "kinematic") if args.track == "both" else (args.track,)
    if not 1 <= args.members <= 10_000:
        print(f"--members: {args.members} is not allowed; allowed: an integer in [1, 10000]",
              file=sys.stderr)
        return 2
    from pipeline.studies.multiverse import composer

    code, summary = run_study(lambda: nmpc_agreement(
        composer([])[0], args.out, args.members,
        log=lambda m: print(m, file=sys.stderr, flush=True), tracks=tracks, n_jobs=args.jobs))
    if code:
        return code
    print(json.dumps({track: {k: v for k, v in part.items() if k != "verdicts"}
                      for track, part in summary["tracks"].items()}, indent=1))
    print(f"agreement written to {args.out.resolve()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
