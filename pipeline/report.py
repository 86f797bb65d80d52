"""Build the HTML report from run folders: ``apf-mpc report RUNS [--out DIR]``.

The command: its options, then :func:`pipeline.reporting.page.build_report` through the
command layer (:func:`pipeline.commands.run_command`). The report only reads: it never
simulates.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from pipeline.commands import CommandError, output_folder, run_command
from pipeline.reporting.page import build_report

__all__ = ["build_report", "main"]


def main(argv: list[str] | None = None) -> int:
    """``python -m pipeline.report``: ``apf-mpc report``."""
    from pipeline.cli import alias

    return alias("report", argv)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """``apf-mpc report``'s arguments."""
    parser.add_argument("runs", type=Path, help="folder holding run folders (e.g. outputs/paper)")
    parser.add_argument("--out", type=output_folder, default=Path("reports/latest"),
                        help="output folder (default: reports/latest)")
    parser.add_argument("--sweep", type=Path, action="append", default=[],
                        help="aggregated sweep folder to add as a Sweep section (repeatable)")
    parser.add_argument("--bench", type=Path, default=Path("reports/bench"),
                        help="benchmark folder to add as the Performance section, if present")
    parser.add_argument("--multiverse", type=Path, default=None,
                        help="multiverse folder (default: RUNS/multiverse, if present)")
    parser.add_argument("--treatment", default=None,
                        help="the method whose claims are judged (default: claims.treatment of "
                             "the runs' settings, improved)")
    parser.add_argument("--controls", default=None,
                        help="comma-separated methods it is compared with (default: "
                             "claims.controls, baseline,baseline_matched)")
    parser.add_argument("--tune", type=Path, default=None,
                        help="fair-fight folder of make tune (default: RUNS/tune, if present)")
    parser.add_argument("--figure-style", default="default",
                        help="how figures are written: a name under conf/report/figure_style/ "
                             "(default, paper) or a YAML file's path")
    parser.add_argument("--figure-jobs", type=int, default=None,
                        help="figures drawn at the same time, in child processes (default: the "
                             "machine's cores; 1: one after the other here, and the scenario "
                             "explorer written here too)")
    parser.add_argument("--strict", action="store_true",
                        help="exit 1 when any folder was skipped (after writing the report)")
    parser.add_argument("--command", default=None,
                        help="command to show under provenance (default: this command line; "
                             "make passes the make command that ran, e.g. make tune "
                             "TUNE=quick)")


def run(args: argparse.Namespace) -> int:
    """The report as ``args`` say, through the command layer."""
    command = args.command or _command_line()

    def cannot_write(exc: OSError) -> str:
        return (f"error: --out {args.out}: cannot write the report ({exc.strerror or exc}: "
                f"{exc.filename or args.out})")

    return run_command(lambda: _report(args, command), os_error=cannot_write)


def _command_line() -> str:
    """The command that ran, with its arguments: ``apf-mpc report ...`` when the installed
    command ran, ``python -m pipeline.report ...`` otherwise."""
    import shlex

    ran = Path(sys.argv[0]).name if sys.argv and sys.argv[0] else ""
    words = sys.argv[1:]
    if ran == "apf-mpc" and words[:1] == ["report"]:
        name, words = "apf-mpc report", words[1:]
    else:
        name = "python -m pipeline.report"
    return " ".join([name, *(shlex.quote(a) for a in words)])


def _report(args, command: str) -> int:
    from pipeline.errors import ConfigError
    from pipeline.reporting.style import load_figure_style
    from pipeline.store.files import refuse_input_as_output
    from pipeline.store.runs import Skipped

    try:
        # the report is a folder of its own: never one of its inputs, never a file
        refuse_input_as_output(args.out, [args.runs, *args.sweep, args.multiverse, args.tune])
        if args.out.exists() and not args.out.is_dir():
            raise OSError(20, "a file, not a folder", str(args.out))
    except OSError as exc:
        raise CommandError(f"error: --out {args.out}: cannot write the report "
                           f"({exc.strerror})") from None
    if args.figure_jobs is not None and not 1 <= args.figure_jobs <= 256:
        raise CommandError(f"error: --figure-jobs={args.figure_jobs} is invalid; allowed: an "
                           "integer in [1, 256]")
    try:
        style = load_figure_style(args.figure_style)
    except ConfigError as exc:
        raise CommandError(f"error: {exc}") from None
    skipped: list[Skipped] = []
    controls = _compared_methods(args)
    try:
        path = build_report(args.runs, args.out, command, tuple(args.sweep), args.bench,
                            args.multiverse, skipped, args.tune, args.treatment, controls,
                            style=style, figure_jobs=args.figure_jobs)
    except FileNotFoundError as exc:
        raise CommandError(f"error: {exc}") from None
    print(f"report written to {path.resolve()}"
          + (f" ({len(skipped)} folder(s) skipped, listed in the report)" if skipped else ""))
    answer = path.parent / "answer.txt"
    if answer.is_file() and answer.read_text().strip():
        # the answer in words, last, so that a command's final lines are the verdicts
        print("The answer over the scenario family (per claim: the outcome against the declared "
              "primary comparison, estimate [interval] unit, its pairs, then the judge of "
              "record, the readings it hangs on and the secondary comparisons; d = treatment - "
              "comparison, below 0 is better):")
        print(answer.read_text().rstrip())
    if args.strict and skipped:
        print(f"error: --strict: {len(skipped)} folder(s) skipped", file=sys.stderr)
        return 1
    return 0


def methods_in(runs: Path) -> set[str]:
    """The method names the runs under ``runs`` were made with
    (:func:`pipeline.store.runs.method_names`)."""
    from pipeline.store.runs import method_names

    return method_names(runs)


def _compared_methods(args) -> tuple[str, ...]:
    """The controls of ``--controls`` (comma-separated); :class:`CommandError` (one line, the
    names allowed) for an empty list, a treatment among its controls, a name given twice, or
    a treatment or control with no runs under RUNS (it would judge nothing, silently)."""
    controls = tuple(c.strip() for c in (args.controls or "").split(",") if c.strip())
    if args.controls is not None and not controls:
        raise CommandError(f"error: --controls {args.controls!r} is invalid; allowed: "
                           "comma-separated method names, e.g. baseline,baseline_matched")
    if args.treatment is not None and not args.treatment.strip():
        raise CommandError("error: --treatment '' is invalid; allowed: a method name")
    if len(set(controls)) != len(controls):
        raise CommandError(f"error: --controls {args.controls} names a method twice; "
                           "allowed: each method once")
    if args.treatment is not None and args.treatment in controls:
        raise CommandError(f"error: --treatment {args.treatment} is also in --controls "
                           f"{args.controls}; allowed: controls other than the treatment")
    if (args.treatment is None and not controls) or not Path(args.runs).is_dir():
        return controls
    known = methods_in(Path(args.runs))
    for option, name in [("--treatment", args.treatment)] + [("--controls", c)
                                                             for c in controls]:
        if name is not None and name not in known:
            raise CommandError(f"error: {option} {name}: no runs of that method under "
                               f"{args.runs}; allowed: "
                               + (", ".join(sorted(known)) or "none (no runs found)"))
    return controls


if __name__ == "__main__":
    sys.exit(main())
