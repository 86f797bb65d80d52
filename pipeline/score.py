"""Score any trajectory CSV with the Table 1 metrics: ``apf-mpc score FILE.csv``.

The command: its options, then :func:`pipeline.studies.score.load_trajectory` and the metrics
through the command layer (:func:`pipeline.commands.run_command`). What the file cannot give is
said on stderr (one line per metric) and under ``score_quality`` in the JSON (see
:mod:`pipeline.studies.score`).
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
from pathlib import Path

import numpy as np

from pipeline.commands import CommandError, run_command
from pipeline.studies import score as scoring

__all__ = ["main"]

log = logging.getLogger("pipeline.score")


def main(argv: list[str] | None = None) -> int:
    """``python -m pipeline.score``: ``apf-mpc score``."""
    from pipeline.cli import alias

    return alias("score", argv)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """``apf-mpc score``'s arguments (the description: what a file cannot give)."""
    parser.description = f"{parser.description}\n\n{scoring.__doc__}"
    parser.add_argument("trajectory", help="trajectory CSV, or - for standard input")
    parser.add_argument("--columns", default="", help="OUR=THEIRS,... column name mapping")
    parser.add_argument("--start", default="0,0", help="start X,Y in m (default 0,0)")
    parser.add_argument("--goal", default="30,0", help="goal X,Y in m (default 30,0)")
    parser.add_argument("--vehicle-radius", type=float, default=1.0,
                        help="vehicle footprint radius in m (default 1.0)")
    parser.add_argument("--obstacle", action="append", default=[],
                        help="x,y,radius[,appear_s[,vx,vy]] (repeatable)")
    parser.add_argument("--out", type=Path, default=None, help="write metrics JSON here")


def run(args: argparse.Namespace) -> int:
    """Score as ``args`` say, through the command layer."""

    def cannot_write(exc: OSError) -> str:
        return f"error: --out {args.out}: cannot write ({exc.strerror})"

    return run_command(lambda: _score(args), os_error=cannot_write)


def _score(args) -> int:
    from pipeline.analysis.metrics.criteria import compute_metrics
    from pipeline.analysis.metrics.signals import TrajectoryContext
    from pipeline.config import MetricsConfig, ModelConfig
    from pipeline.loop.model import tyre_linear_limit
    from pipeline.store.files import output_target, refuse_input_as_output, write_text_atomic

    if args.out is not None:
        # refused before anything is read: the input must never become the output
        try:
            refuse_input_as_output(args.out, [Path(args.trajectory)]
                                   if args.trajectory != "-" else [])
            output_target(args.out)
        except OSError as exc:
            raise CommandError(f"error: --out {args.out}: cannot write ({exc.strerror})") \
                from None
    try:
        frame = scoring.load_trajectory(
            args.trajectory, scoring.parse_pairs(args.columns, "--columns"),
            [scoring.parse_floats(o, (3, 4, 6), "--obstacle") for o in args.obstacle],
            stdin_text=sys.stdin.read() if args.trajectory == "-" else None)
        start = scoring.parse_floats(args.start, (2,), "--start")
        goal = scoring.parse_floats(args.goal, (2,), "--goal")
        if start == goal:
            raise scoring.TrajectoryFileError("--goal must differ from --start")
        if not np.isfinite(args.vehicle_radius) or args.vehicle_radius < 0:
            raise scoring.TrajectoryFileError("--vehicle-radius must be a finite number >= 0")
    except scoring.TrajectoryFileError as exc:
        raise CommandError(f"error: {exc}") from None
    # the model's bounds a trajectory's logged model columns are judged against: the
    # project's defaults (model.validity_heading_rad, model.tyre_linear_tolerance)
    model = ModelConfig()
    context = TrajectoryContext((start[0], start[1]), (goal[0], goal[1]), args.vehicle_radius,
                                model.validity_heading_rad,
                                tyre_linear_limit(model.tyre_linear_tolerance))
    metrics = compute_metrics(frame, context, MetricsConfig())
    missing, derived = scoring.score_quality(frame.columns)
    values = metrics.to_json()
    blank = frame.attrs.get("blank_cells", {})
    for column, (count, first, last) in blank.items():
        log.warning("score: column %s: %d empty cell(s) (data rows %s-%s); the metrics that use "
                    "it leave those rows out", column, count, first, last)
    for key, reason in missing.items():
        values[key] = None  # not "false" or "0": the file cannot say
        claim = f"{scoring.CLAIM_OF[key]} " if key in scoring.CLAIM_OF else ""
        log.warning("score: %s%s missing: %s", claim, key, reason)
    for key, how in derived.items():
        claim = f"{scoring.CLAIM_OF[key]} " if key in scoring.CLAIM_OF else ""
        log.warning("score: %s%s derived: %s", claim, key, how)
    values["score_quality"] = {"missing": missing, "derived": derived,
                               "empty_cells": {c: v[0] for c, v in blank.items()}}
    text = json.dumps(values, indent=2, sort_keys=True)
    if args.out:
        # atomic: a failed write leaves an existing file as it was (its OSError: one line)
        write_text_atomic(args.out, text + "\n")
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
