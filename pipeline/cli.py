"""``apf-mpc <command> [arguments]``: every command of the pipeline behind one entry point.

Each command is one row of :data:`COMMANDS` (its name, its module and what it does); the
module's ``main`` runs it through the command layer (:func:`pipeline.commands.run_command`:
one line and exit code 2 for a usage or configuration error, 130/143 for Ctrl-C/SIGTERM).
``apf-mpc --help`` lists the commands, ``apf-mpc <command> --help`` gives one command's
arguments. ``python -m pipeline.<module>`` stays as an alias of each (the Makefile's form).
A command of one's own is a row added here and a module with ``main(argv) -> int``.
"""

from __future__ import annotations

import importlib
import sys
from dataclasses import dataclass

__all__ = ["COMMANDS", "Command", "main"]


@dataclass(frozen=True)
class Command:
    """One command: its name after ``apf-mpc``, the module whose ``main`` runs it, what it
    does (one line), and whether it is a Hydra application (``run``: it reads ``sys.argv``
    itself, Hydra overrides as its arguments)."""

    name: str
    module: str
    summary: str
    hydra: bool = False


#: Every command, in the order ``apf-mpc --help`` lists them (the Makefile's targets in
#: brackets run them).
COMMANDS: tuple[Command, ...] = (
    Command("run", "pipeline.run", "one run, a family or a Hydra sweep: Hydra overrides "
            "(make reproduce, make pedestrians, make sweep)", hydra=True),
    Command("report", "pipeline.report", "the HTML report from the run folders (make report)"),
    Command("verify", "pipeline.verify", "compare the runs with reports/reference (make verify)"),
    Command("multiverse", "pipeline.multiverse", "how robust each verdict is "
            "(make multiverse)"),
    Command("tune", "pipeline.tune", "both methods tuned with one budget, judged on held-out "
            "scenarios (make tune)"),
    Command("nmpc-check", "pipeline.nmpc_check", "each track's linear MPC against the "
            "nonlinear MPC (make nmpc-check)"),
    Command("speed-check", "pipeline.speed_check", "is slower ever less safe? "
            "(make speed-check)"),
    Command("score", "pipeline.score", "the metrics of a trajectory of your own"),
    Command("aggregate", "pipeline.aggregate", "gather a sweep folder into summary.csv"),
    Command("bench", "pipeline.bench", "benchmark the controller step against the solver's "
            "floor (make bench)"),
    Command("screenshot", "pipeline.screenshot", "the README's screenshots (make screenshot)"),
    Command("cache", "pipeline.cache", "what the member cache holds, or empty it "
            "(make cache-size, make clean-cache)"),
)


def usage() -> str:
    """``apf-mpc --help``: the commands and what each does."""
    width = max(len(c.name) for c in COMMANDS)
    lines = ["usage: apf-mpc <command> [arguments]   (apf-mpc <command> --help: its arguments)",
             "", "commands:"]
    lines += [f"  {c.name:<{width}}  {c.summary}" for c in COMMANDS]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """Run ``apf-mpc <command> [arguments]`` (``argv``: the arguments after ``apf-mpc``;
    default ``sys.argv[1:]``); its exit code."""
    args = list(sys.argv[1:] if argv is None else argv)
    if not args or args[0] in ("-h", "--help", "help"):
        print(usage())
        return 0 if args else 2
    by_name = {c.name: c for c in COMMANDS}
    command = by_name.get(args[0])
    if command is None:
        print(f"error: apf-mpc has no command {args[0]!r}; allowed: "
              f"{', '.join(by_name)} (apf-mpc --help)", file=sys.stderr)
        return 2
    try:
        module = importlib.import_module(command.module)
    except KeyboardInterrupt:
        # Ctrl-C while the command's imports load (numpy, Hydra, the solvers: about a
        # second): nothing has run, nothing is written; no traceback (make -j9 printed nine)
        return 130
    if command.hydra:
        # Hydra reads sys.argv: the module's own path first, as `python -m` sets it
        sys.argv = [str(module.__file__), *args[1:]]
        try:
            module.main()
        except SystemExit as done:
            return int(done.code or 0) if not isinstance(done.code, str) else 2
        return 0
    return int(module.main(args[1:]) or 0)


if __name__ == "__main__":
    sys.exit(main())
