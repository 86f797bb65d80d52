"""One command (issue 57, item 3): ``apf-mpc <command> ...`` runs every command of the
pipeline; ``apf-mpc --help`` lists them, an unknown one is one line naming the allowed ones,
and each command's ``--help`` and exit codes are the module's own (``python -m
pipeline.<name>`` stays as its alias)."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

from pipeline.cli import COMMANDS, main

PACKAGE = Path(__file__).resolve().parent.parent / "pipeline"
#: modules with a main that are not user commands (the install step's warm-up)
INTERNAL = {"pipeline.warm", "pipeline.cli"}


def test_help_lists_every_command_and_no_arguments_is_a_usage_error(capsys):
    assert main(["--help"]) == 0
    out = capsys.readouterr().out
    assert all(f"  {c.name}" in out and c.summary[:30] in out for c in COMMANDS)
    assert main([]) == 2


def test_an_unknown_command_is_one_line_naming_the_allowed_ones(capsys):
    assert main(["reproduce"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "'reproduce'" in err[0] and "allowed: run, report" in err[0]


def test_every_entry_module_of_the_package_is_a_command():
    """The oracle is the package itself: every top-level module with a ``main`` is a row of
    COMMANDS (a new command cannot be left out of ``apf-mpc``), and every row's module has
    one."""
    found = set()
    for path in PACKAGE.glob("*.py"):
        tree = ast.parse(path.read_text())
        if any(isinstance(n, ast.FunctionDef) and n.name == "main" for n in tree.body):
            found.add(f"pipeline.{path.stem}")
    assert found - INTERNAL == {c.module for c in COMMANDS}
    assert len({c.name for c in COMMANDS}) == len(COMMANDS)


@pytest.mark.parametrize("command", [c for c in COMMANDS if not c.hydra], ids=lambda c: c.name)
def test_each_command_answers_help_under_its_apf_mpc_name(command, capsys):
    with pytest.raises(SystemExit) as info:
        main([command.name, "--help"])
    assert info.value.code == 0
    assert capsys.readouterr().out.startswith(f"usage: apf-mpc {command.name}")


def test_run_is_hydras_application_with_its_exit_codes(tmp_path, capsys):
    """``apf-mpc run`` takes Hydra overrides: a run writes its folder (exit 0); a value out of
    range is one line naming the key and exit 2."""
    assert main(["run", "planner=baseline", "scenario.n_steps=20",
                 f"hydra.run.dir={tmp_path / 'one'}"]) == 0
    assert (tmp_path / "one" / "manifest.json").is_file()
    assert main(["run", "scenario.n_steps=-1", f"hydra.run.dir={tmp_path / 'bad'}"]) == 2
    err = capsys.readouterr().err
    assert "scenario.n_steps=-1" in err and "allowed: an integer >= 1" in err


def test_ctrl_c_while_a_command_imports_is_exit_130_without_a_traceback(monkeypatch, capsys):
    """Ctrl-C during a command's start-up (its imports) ended in a KeyboardInterrupt
    traceback per process (nine under make reproduce's -j9); now exit 130, nothing printed."""
    import importlib

    def interrupted(name, *args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(importlib, "import_module", interrupted)
    assert main(["report", "outputs"]) == 130
    captured = capsys.readouterr()
    assert captured.err == "" and captured.out == ""
