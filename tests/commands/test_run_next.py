"""``apf-mpc run A... --next B...`` (make pedestrians' family and variants in one process):
each run is the run its overrides give alone, byte for byte; the first run that does not exit
0 ends the command with its code and the runs after it never start; ``--next`` with no run on
either side is refused in one line."""

from __future__ import annotations

import pytest

from pipeline.run import NEXT_RUN, command

CHEAP = ["scenario.n_steps=50"]


def _files(folder):
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir())
            if p.name in ("trajectory.csv", "metrics.json", "config.yaml")}


def test_runs_joined_by_next_are_the_runs_alone(tmp_path, monkeypatch):
    monkeypatch.delenv("HYDRA_FULL_ERROR", raising=False)
    first = ["method=improved", *CHEAP]
    second = ["method=baseline", "scenario.obstacles.0.vy_mps=-0.5", *CHEAP]
    assert command([*first, f"hydra.run.dir={tmp_path / 'alone_a'}"]) == 0
    assert command([*second, f"hydra.run.dir={tmp_path / 'alone_b'}"]) == 0
    assert command([*first, f"hydra.run.dir={tmp_path / 'joined_a'}", NEXT_RUN,
                    *second, f"hydra.run.dir={tmp_path / 'joined_b'}"]) == 0
    for name in ("a", "b"):
        alone, joined = _files(tmp_path / f"alone_{name}"), _files(tmp_path / f"joined_{name}")
        assert set(alone) == {"trajectory.csv", "metrics.json", "config.yaml"}
        assert joined == alone, name
    # the two runs are not one run twice
    assert _files(tmp_path / "joined_a") != _files(tmp_path / "joined_b")


def test_a_failing_run_ends_the_command_and_the_next_never_starts(tmp_path, monkeypatch,
                                                                  capsys):
    monkeypatch.delenv("HYDRA_FULL_ERROR", raising=False)
    code = command(["controller.horizon=-1", f"hydra.run.dir={tmp_path / 'bad'}", NEXT_RUN,
                    "method=improved", *CHEAP, f"hydra.run.dir={tmp_path / 'never'}"])
    assert code == 2
    assert "controller.horizon" in capsys.readouterr().err
    assert not (tmp_path / "never").exists()


@pytest.mark.parametrize("argv", [[NEXT_RUN, "method=improved"], ["method=improved", NEXT_RUN],
                                  ["method=improved", NEXT_RUN, NEXT_RUN, "method=baseline"]])
def test_next_without_a_run_on_each_side_is_one_line(tmp_path, capsys, argv):
    assert command(argv) == 2
    lines = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert lines == [f"error: {NEXT_RUN} is invalid here; allowed: between two runs' overrides "
                     f"(apf-mpc run A=1 {NEXT_RUN} B=2), each run with at least one"]


def test_joined_runs_each_name_their_folder(tmp_path, capsys, monkeypatch):
    """Hydra's default folder is named by the second the run starts: two runs of one process
    started within a second would share it (a reviewer's five joined runs left three folders,
    exit 0). A run without hydra.run.dir or hydra.sweep.dir is refused before any runs."""
    monkeypatch.chdir(tmp_path)
    assert command(["method=improved", *CHEAP, f"hydra.run.dir={tmp_path / 'a'}", NEXT_RUN,
                    "method=baseline", *CHEAP]) == 2
    lines = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert lines == [f"error: {NEXT_RUN} is invalid without each run's own folder (run 2 has "
                     "none); allowed: hydra.run.dir=<folder> (hydra.sweep.dir=<folder> for a "
                     "sweep) in every run"]
    assert not any(tmp_path.iterdir())  # nothing ran
