"""One command (issue 57, item 3): ``apf-mpc <study> ...`` runs every study of the pipeline,
its subcommands read from the studies' registry; ``apf-mpc --help`` lists them, an unknown one is
one line naming the allowed ones, and each study's ``--help`` and exit codes are its module's
own (``python -m pipeline.<name>`` stays as its alias)."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

from pipeline.cli import main
from pipeline.store.study_registry import load_studies

PACKAGE = Path(__file__).resolve().parents[2] / "pipeline"
#: modules with a main that are not studies of the package: the install step's warm-up, the
#: command itself, and the alias of the benchmark registered from the repository's benchmarks/
INTERNAL = {"pipeline.warm", "pipeline.cli", "pipeline.bench"}
STUDIES = load_studies()


def test_help_lists_every_study_and_no_arguments_is_a_usage_error(capsys):
    assert main(["--help"]) == 0
    out = capsys.readouterr().out
    assert all(f"  {s.name} " in out and s.help[:30] in out for s in STUDIES)
    assert main([]) == 2


def test_an_unknown_study_is_one_line_naming_the_allowed_ones(capsys):
    assert main(["reproduce"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "'reproduce'" in err[0] and "run, " in err[0]


def test_every_entry_module_of_the_package_is_a_registered_study():
    """The oracle is the package itself: every top-level module with a ``main`` is the command
    of a registered study (a new command cannot be left out of ``apf-mpc``), and every
    study's command module exists."""
    found = set()
    for path in PACKAGE.glob("*.py"):
        tree = ast.parse(path.read_text())
        if any(isinstance(n, ast.FunctionDef) and n.name == "main" for n in tree.body):
            found.add(f"pipeline.{path.stem}")
    commands = {s.command for s in STUDIES if s.command}
    assert found - INTERNAL <= commands
    assert all((PACKAGE.parent / (c.replace(".", "/") + ".py")).is_file() for c in commands)
    assert len({s.name for s in STUDIES}) == len(STUDIES)


@pytest.mark.parametrize("study", [s for s in STUDIES if s.name != "run"], ids=lambda s: s.name)
def test_each_study_answers_help_under_its_apf_mpc_name(study, capsys):
    with pytest.raises(SystemExit) as info:
        main([study.name, "--help"])
    assert info.value.code == 0
    assert capsys.readouterr().out.startswith(f"usage: apf-mpc {study.name}")


def test_run_is_hydras_application_with_its_exit_codes(tmp_path, capsys):
    """``apf-mpc run`` takes Hydra overrides: a run writes its folder (exit 0); a value out of
    range is one line naming the key and exit 2."""
    assert main(["run", "planner=baseline", "scenario.n_steps=20",
                 f"hydra.run.dir={tmp_path / 'one'}"]) == 0
    assert (tmp_path / "one" / "manifest.json").is_file()
    assert main(["run", "scenario.n_steps=-1", f"hydra.run.dir={tmp_path / 'bad'}"]) == 2
    err = capsys.readouterr().err
    assert "scenario.n_steps=-1" in err and "an integer >= 1" in err


def test_ctrl_c_while_a_study_imports_is_exit_130_without_a_traceback(monkeypatch, capsys):
    """Ctrl-C during a study's start-up (its imports) ended in a KeyboardInterrupt traceback
    per process (nine under make reproduce's -j9); now exit 130, nothing printed."""
    import importlib

    def interrupted(name, *args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(importlib, "import_module", interrupted)
    assert main(["report", "outputs"]) == 130
    assert main(["pedestrians", "--out", "nowhere"]) == 130
    captured = capsys.readouterr()
    assert captured.err == "" and captured.out == ""


def test_the_bench_alias_outside_a_checkout_is_one_line(tmp_path, monkeypatch, capsys):
    """``python -m pipeline.bench`` where benchmarks/ cannot be imported: exit 2, one line."""
    import builtins

    real_import = builtins.__import__

    def no_benchmarks(name, *args, **kwargs):
        if name.startswith("benchmarks"):
            raise ImportError(name)
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_benchmarks)
    from pipeline.bench import main as bench

    assert bench(["--quick"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "make bench" in err[0]
