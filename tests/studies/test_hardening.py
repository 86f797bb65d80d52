"""Hostile but fair inputs to the tools around the run and the report (issue 27): one probe
per class, each exiting 2 with one line, destroying nothing."""

from __future__ import annotations

import os

import numpy as np
import pytest

from pipeline.errors import ConfigError


@pytest.fixture(scope="module")
def trajectory(tmp_path_factory, make_config):
    from pipeline.studies.experiment import run_experiment

    folder = tmp_path_factory.mktemp("run") / "improved"
    run_experiment(make_config(["method=improved"]), folder)
    return folder / "trajectory.csv"


def _one_line(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    return err[0]


def test_score_never_writes_over_its_input_a_folder_or_a_pipe(trajectory, tmp_path, capsys):
    from pipeline.score import main

    copy = tmp_path / "t.csv"
    copy.write_bytes(trajectory.read_bytes())
    before = copy.read_bytes()
    assert main([str(copy), "--out", str(copy)]) == 2
    assert "is an input of this command" in _one_line(capsys)
    assert copy.read_bytes() == before
    (tmp_path / "folder").mkdir()
    assert main([str(copy), "--out", str(tmp_path / "folder")]) == 2
    assert "a folder, not a file" in _one_line(capsys)
    os.mkfifo(tmp_path / "pipe")
    assert main([str(copy), "--out", str(tmp_path / "pipe")]) == 2
    assert "not a regular file" in _one_line(capsys)
    # a symbolic link is written through: the link stays, its target gets the JSON
    (tmp_path / "link.json").symlink_to(tmp_path / "real.json")
    assert main([str(copy), "--out", str(tmp_path / "link.json")]) == 0
    assert (tmp_path / "link.json").is_symlink()
    assert (tmp_path / "real.json").read_text().lstrip().startswith("{")
    # a link to the input is the input
    (tmp_path / "sneaky.json").symlink_to(copy)
    assert main([str(copy), "--out", str(tmp_path / "sneaky.json")]) == 2
    assert copy.read_bytes() == before


def test_report_and_verify_refuse_their_inputs_and_files_as_folders(trajectory, tmp_path,
                                                                     capsys):
    from pipeline.report import main as report_main
    from pipeline.verify import main as verify_main

    runs = trajectory.parent.parent
    assert report_main([str(runs), "--out", str(runs)]) == 2
    assert "is an input of this command" in _one_line(capsys)
    blocked = tmp_path / "blocked"
    blocked.write_text("mine")
    assert report_main([str(runs), "--out", str(blocked)]) == 2
    assert "a file, not a folder" in _one_line(capsys)
    assert verify_main([str(runs), str(blocked)]) == 2
    assert "a file, not a folder" in _one_line(capsys)
    assert blocked.read_text() == "mine"


@pytest.mark.parametrize("text, key", [
    ("famly_size: 10\ndimensions: [{key: planner.beta, stage: simulation, values: [0.25, 1]}]",
     "famly_size"),
    ("family_size: ten\ndimensions: [{key: planner.beta, stage: simulation, values: [0.25, 1]}]",
     "family_size"),
    ("- a\n- b\n", "multiverse space"),
    ("dimensions: planner.beta\n", "dimensions"),
    ("dimensions: [planner.beta]\n", "dimensions[0]"),
    ("dimensions: [{key: planner.beta, stage: simulation, valus: [1, 2]}]", "dimensions[0].valus"),
    ("dimensions: [{key: planner.beta, stage: simulation, values: 0.5}]", "dimensions[0].values"),
])
def test_a_bad_space_file_stops_before_any_work(tmp_path, capsys, text, key):
    from pipeline.multiverse import main

    space = tmp_path / "space.yaml"
    space.write_text(text)
    out = tmp_path / "mv"
    assert main(["--space", str(space), "--out", str(out)]) == 2
    line = _one_line(capsys)
    assert key in line and "allowed" in line
    assert not (out / "runs").exists()


def test_multiverse_jobs_and_a_blocked_output_folder(tmp_path, capsys):
    from pipeline.multiverse import main

    assert main(["--space", "quick", "--jobs", "0", "--out", str(tmp_path / "mv")]) == 2
    assert "--jobs=0" in _one_line(capsys)
    assert not (tmp_path / "mv").exists()
    blocked = tmp_path / "file"
    blocked.write_text("mine")
    assert main(["--space", "quick", "--out", str(blocked)]) == 2
    assert str(blocked) in _one_line(capsys)
    assert blocked.read_text() == "mine"


def test_messages_show_plain_values():
    assert "planner.beta=-0.5 is invalid" in str(ConfigError("planner.beta", np.float64(-0.5),
                                                             ">= 0"))
    long = str(ConfigError("scenario.n_steps", 10 ** 400, "an integer"))
    assert "(401 characters)" in long and len(long) < 160
    assert "[1.5, 2]" in str(ConfigError("x", [np.float64(1.5), np.int64(2)], "y"))


def test_score_ignores_trailing_separators_and_counts_empty_cells(trajectory, tmp_path,
                                                                  capsys):
    """A spreadsheet's trailing commas are no columns; an empty cell in an optional column is
    said with its count (the last row, which logs the end without an input, excepted)."""
    import json

    import pandas as pd

    from pipeline.score import main

    table = pd.read_csv(trajectory)
    keep = ["time_s", "X_m", "Y_m", "psi_rad", "delta_rad"] + [
        c for c in table.columns if c.startswith("obs0_")]
    plain = tmp_path / "plain.csv"
    table[keep].to_csv(plain, index=False)
    trailing = tmp_path / "trailing.csv"
    trailing.write_text("\n".join(line + ",," for line in plain.read_text().splitlines()) + "\n")
    assert main([str(plain)]) == 0
    expected = json.loads(capsys.readouterr().out)
    assert main([str(trailing)]) == 0
    assert json.loads(capsys.readouterr().out) == expected
    holes = table[keep].copy()
    holes.loc[5:9, "delta_rad"] = float("nan")
    holed = tmp_path / "holes.csv"
    holes.to_csv(holed, index=False)
    assert main([str(holed)]) == 0
    out = capsys.readouterr()
    assert "column delta_rad: 5 empty cell(s) (data rows 6-10)" in out.err
    assert json.loads(out.out)["score_quality"]["empty_cells"] == {"delta_rad": 5}
    assert "empty cell" not in (main([str(plain)]) == 0 and capsys.readouterr().err)


def test_aggregate_refuses_a_baseline_that_is_not_a_run(tmp_path, capsys):
    from pipeline.aggregate import main

    sweep = tmp_path / "sweep"
    sweep.mkdir()
    assert main([str(sweep), "--baseline", str(tmp_path / "missing")]) == 2
    assert "--baseline" in _one_line(capsys)


def test_an_unknown_key_inside_a_list_is_named_by_its_full_path(make_config):
    with pytest.raises(ConfigError) as info:
        make_config(["+scenario.obstacles.0.foo=1"])
    assert info.value.key == "scenario.obstacles[0].foo"
    assert "ObstacleConfig" in str(info.value)


def test_a_study_stopped_by_a_signal_exits_130_or_143_with_one_line(capsys):
    import signal

    from pipeline.commands import run_command
    from pipeline.errors import Interrupted

    def stopped(exc):
        def call():
            raise exc
        return call

    assert run_command(stopped(KeyboardInterrupt())) == 130
    assert "stopped (interrupted)" in _one_line(capsys)
    assert run_command(stopped(Interrupted(signal.SIGTERM))) == 143
    assert "stopped (SIGTERM)" in _one_line(capsys)
    # run_command turned SIGTERM into Interrupted: a real signal to this process is caught too
    import os

    def terminate():
        os.kill(os.getpid(), signal.SIGTERM)
        import time
        time.sleep(5)  # interrupted long before this ends

    try:
        assert run_command(terminate) == 143
    finally:
        signal.signal(signal.SIGTERM, signal.SIG_DFL)
    assert "SIGTERM" in _one_line(capsys)
