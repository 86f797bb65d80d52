"""One table of refusals per command (issue 57, item 4): each row is the arguments after
``apf-mpc``, the exit code, the key the last line names and a fragment of what it says is
allowed or wrong; never the whole sentence, so a new option or a new peer changes no row. Every
row runs in this process through ``apf-mpc``'s own entry (:func:`pipeline.cli.main`) and
writes nothing."""

from __future__ import annotations

import pytest

from pipeline.cli import main

NOWHERE = "/nonexistent_apf_mpc_folder"

#: command -> rows of (arguments after the command, exit code, key, fragment)
REFUSALS: dict[str, list[tuple[list[str], int, str, str]]] = {
    "run": [(["scenario.n_steps=-1"], 2, "scenario.n_steps=-1", "an integer >= 1"),
            (["controller.horizon=0"], 2, "controller.horizon=0", "an integer in [1, "),
            # removed (issue 58: no experiment used them): the refusal says so
            (["controller.backend=clarabel_dense"], 2, "controller.backend='clarabel_dense'",
             "clarabel_direct, daqp, nmpc (clarabel_dense was removed"),
            (["controller.formulation=sparse"], 2, "controller.formulation='sparse'",
             "one of condensed (sparse was removed")],
    "clip": [(["paper/0", "--fps", "0"], 2, "--fps", "[1, 60]"),
             (["paper/0", "--stride", "0"], 2, "--stride", "[1, 100]"),
             (["paper"], 2, "member", "<experiment>/<index>")],
    "nmpc-check": [(["--family-size", "0"], 2, "--family-size", "[1, 10000]"),
                   (["--jobs", "0"], 2, "--jobs", "[1, 64]")],
    "speed-check": [(["--family-size", "0"], 2, "--family-size", "[1, 10000]"),
                    (["--variants", "nope"], 2, "--variants", "nominal")],
    "euro-ncap": [(["--family-size", "0"], 2, "--family-size", "[1, 10000]"),
                  (["--tracks", "nope"], 2, "--tracks", "lateral, lateral_braking, kinematic"),
                  (["scenario.source.params.cases=[CPXX-50]"], 2,
                   "scenario.source.params.cases", "distinct cases from CPNC-50"),
                  (["scenario.source.params.lead_time_s=-1"], 2,
                   "scenario.source.params.lead_time_s", "a number in [0, 10]")],
    "tune": [(["--space", "nope"], 2, "--space", "a file in conf/tune/"),
             (["--set", "nope=1"], 2, "--set", "key=value with key one of"),
             (["--workers", "ray://x:1"], 2, "--workers", "dask-local:N"),
             (["--workers", "dask-local:2", "hydra/launcher=slurm"], 2, "--workers",
              "local with hydra/launcher=slurm")],
    "multiverse": [(["--space", "nope"], 2, "multiverse space", "a file in conf/multiverse/"),
                   (["--jobs", "0"], 2, "--jobs", "[1, 256]")],
    "report": [([NOWHERE], 2, NOWHERE, "no such folder")],
    "verify": [([NOWHERE, NOWHERE], 2, NOWHERE, "no paper-scenario runs")],
    "score": [([NOWHERE + ".csv"], 2, NOWHERE + ".csv", "no such file")],
    "aggregate": [([NOWHERE], 2, NOWHERE, "no complete job folders")],
    "screenshot": [([NOWHERE + ".html", NOWHERE + ".png"], 2, NOWHERE + ".html", "no report")],
}


@pytest.mark.parametrize("command, argv, code, key, fragment", [
    (command, argv, code, key, fragment)
    for command, rows in REFUSALS.items() for argv, code, key, fragment in rows],
    ids=lambda v: v if isinstance(v, str) else None)
def test_a_refusal_is_its_exit_code_and_one_line_naming_the_key(capsys, monkeypatch, tmp_path,
                                                               command, argv, code, key,
                                                               fragment):
    monkeypatch.chdir(tmp_path)  # nothing is written here either
    assert main([command, *argv]) == code
    last = capsys.readouterr().err.strip().splitlines()[-1]
    assert key in last and fragment in last, last
    assert "Traceback" not in last
    assert list(tmp_path.iterdir()) == []


def test_every_registered_study_with_options_has_a_row():
    """A study whose command takes options is in the table (a new one must add its rows)."""
    from pipeline.store.study_registry import load_studies

    without = {"cache", "pedestrians", "ablation", "nmpc-family", "commonroad"}
    missing = {s.name for s in load_studies()} - set(REFUSALS) - without
    assert missing == set()


def test_a_refused_run_leaves_a_users_folder_with_its_results(capsys, monkeypatch, tmp_path):
    """The folder Hydra made for a refused job goes; a folder that holds anything else stays
    with everything in it (only Hydra's own files are added to it)."""
    monkeypatch.chdir(tmp_path)
    keep = tmp_path / "keep"
    keep.mkdir()
    (keep / "result.txt").write_text("x")
    assert main(["run", "scenario.n_steps=-1", f"hydra.run.dir={keep}"]) == 2
    assert (keep / "result.txt").read_text() == "x"
    assert main(["run", "scenario.n_steps=-1"]) == 2
    assert sorted(p.name for p in tmp_path.iterdir()) == ["keep"]
