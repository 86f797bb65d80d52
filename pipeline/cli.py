"""The one command: ``apf-mpc <study> [arguments]``, its subcommands built from the studies'
registry (:mod:`pipeline.store.study_registry`).

``apf-mpc --help`` lists every registered study from the registry alone (nothing is imported);
``apf-mpc <study> --help`` imports that study's module and shows its arguments. A study runs
through the command layer (:func:`pipeline.commands.run_command`): its module gives
``add_arguments(parser)`` and ``run(args) -> int``; a study that is a Hydra experiment
(``experiment:`` in its entry) runs ``apf-mpc run experiment=<it> hydra.sweep.dir=<--out>`` with
the overrides given. ``python -m pipeline.<name>`` stays as an alias of ``apf-mpc <name>``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from pipeline.commands import output_folder

PROG = "apf-mpc"
DESCRIPTION = ("The reproduction of Yoo & Choi (2025), Improved MPC for dynamical obstacle "
               "avoidance: one subcommand per study (make's targets call them).")


def main(argv: list[str] | None = None, extra_studies: tuple[Path, ...] = ()) -> int:
    """``apf-mpc <study> ...``: the study's exit code (2 with one line for an unknown study or
    a registry entry that cannot be read); ``extra_studies``: further folders of study YAMLs
    (as ``$PIPELINE_STUDIES``)."""
    from pipeline.errors import ConfigError
    from pipeline.store.study_registry import load_studies

    argv = list(sys.argv[1:] if argv is None else argv)
    try:
        studies = {s.name: s for s in load_studies(extra_studies)}
    except ConfigError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    if not argv or argv[0] in ("-h", "--help"):
        print(usage(studies.values()))
        return 0 if argv else 2
    name, rest = argv[0], argv[1:]
    if name not in studies:
        print(f"{PROG}: error: unknown study {name!r}; allowed: {', '.join(studies)}",
              file=sys.stderr)
        return 2
    return run_study(studies[name], rest)


def usage(studies) -> str:
    """``apf-mpc --help``: every study with its line, in the registry's order."""
    studies = list(studies)
    width = max((len(s.name) for s in studies), default=0) + 2
    lines = [f"usage: {PROG} <study> [arguments]  ({PROG} <study> --help: its arguments)", "",
             DESCRIPTION, "", "studies:"]
    lines += [f"  {s.name.ljust(width)}{s.help}" for s in studies]
    return "\n".join(lines)


def run_study(study, argv: list[str]) -> int:
    """Run the registered ``study`` with its arguments ``argv`` (see the module docstring)."""
    from pipeline.store.study_registry import resolve

    prog = f"{PROG} {study.name}"
    if study.experiment is not None:
        return _experiment(study, prog, argv)
    from pipeline.errors import ConfigError

    try:
        module: Any = resolve(study.command, f"{study.source}: command")
    except KeyboardInterrupt:
        # Ctrl-C while the study's imports load (numpy, Hydra, the solvers: about a second):
        # nothing has run, nothing is written; no traceback (make -j9 printed nine)
        return 130
    except ConfigError as exc:  # a registry entry naming a module that does not import
        print(f"error: {exc}", file=sys.stderr)
        return 2
    if not hasattr(module, "add_arguments"):  # a Hydra command: Hydra reads its arguments
        return int(module.command(argv, prog))
    parser = argparse.ArgumentParser(prog=prog, description=study_description(study, module),
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    module.add_arguments(parser)
    return int(module.run(parser.parse_args(argv)))


def study_description(study, module) -> str:
    """A study's ``--help`` text: its registry line, then its module's first paragraph."""
    doc = (module.__doc__ or "").strip().split("\n\n")[0]
    return f"{study.help[:1].upper()}{study.help[1:]}." + (f"\n\n{doc}" if doc else "")


def _experiment(study, prog: str, argv: list[str]) -> int:
    """A study that is a Hydra experiment: ``apf-mpc run experiment=<it>`` into ``--out``
    (the ``run`` study's command, found as any study's: by its name in the registry)."""
    from pipeline.store.study_registry import resolve, study_named

    runner = study_named("run")
    try:
        run: Any = resolve(str(runner.command), f"{runner.source}: command")
    except KeyboardInterrupt:  # as in run_study
        return 130
    folder = study.folder or study.name
    parser = argparse.ArgumentParser(
        prog=prog, description=f"{study.help[:1].upper()}{study.help[1:]}: apf-mpc run "
                               f"experiment={study.experiment} into --out.")
    parser.add_argument("--out", type=output_folder, default=Path("outputs") / folder,
                        help=f"the sweep folder (default: outputs/{folder})")
    parser.add_argument("overrides", nargs="*",
                        help="Hydra overrides for every run (e.g. scenario.family.size=50)")
    args = parser.parse_args(argv)
    return run.command([f"experiment={study.experiment}", f"hydra.sweep.dir={args.out}",
                        *args.overrides], prog)


def alias(name: str, argv: list[str] | None = None) -> int:
    """``python -m pipeline.<module>``: ``apf-mpc <name>`` with the same arguments."""
    return main([name, *(sys.argv[1:] if argv is None else argv)])


if __name__ == "__main__":
    sys.exit(main())
