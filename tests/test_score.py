"""The scoring command: bad files give one clear error; our own log scores to metrics.json."""

from __future__ import annotations

import json

import pytest

from pipeline.run import run_experiment
from pipeline.score import main as score_main


@pytest.mark.parametrize("content, message", [
    ("", "empty"),
    ("time_s,X_m,Y_m\n", "no rows"),
    ("time_s,X_m,Y_m\n0,0,0\n", "single row"),
    ("time_s,X_m\n0,0\n0.1,0.3\n", "missing required column(s) ['Y_m']"),
    ("time_s,X_m,Y_m\n0,0,0\n0.1,abc,0\n", "non-numeric"),
    ("time_s,X_m,Y_m\n0,0,0\n0.1,0.3,0\n0.1,0.6,0\n", "increase strictly"),
    ("time_s,X_m,Y_m\n0.2,0,0\n0.1,0.3,0\n", "increase strictly"),
    ("time_s,X_m,Y_m\n0,0,0\n0.1,,0\n", "non-numeric or non-finite"),
])
def test_bad_trajectory_files_give_a_clear_error(tmp_path, capsys, content, message):
    path = tmp_path / "bad.csv"
    path.write_text(content)
    assert score_main([str(path)]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err


def test_missing_file_and_bad_mapping(tmp_path, capsys):
    assert score_main([str(tmp_path / "none.csv")]) == 2
    path = tmp_path / "t.csv"
    path.write_text("t,x,y\n0,0,0\n0.1,0.3,0\n")
    assert score_main([str(path), "--columns", "time_s=t,X_m=x,Y_m=q"]) == 2
    assert "mapped column" in capsys.readouterr().err
    assert score_main([str(path), "--columns", "time_s=t,X_m=x,Y_m=y",
                       "--obstacle", "5,0"]) == 2


def test_scoring_our_own_trajectory_reproduces_its_metrics(tmp_path, make_config, capsys):
    run_experiment(make_config(["planner=baseline"]), tmp_path / "run")
    expected = json.loads((tmp_path / "run" / "metrics.json").read_text())
    out = tmp_path / "scored.json"
    assert score_main([str(tmp_path / "run" / "trajectory.csv"), "--out", str(out)]) == 0
    scored = json.loads(out.read_text())
    for key, value in scored.items():
        if isinstance(value, float):
            assert value == pytest.approx(expected[key], rel=1e-6, abs=1e-6), key
        else:
            assert value == expected[key], key


def test_external_trajectory_with_mapping_and_obstacle(tmp_path):
    path = tmp_path / "matlab.csv"
    rows = ["t,x,y,theta"] + [f"{0.1 * k:.1f},{0.3 * k:.1f},0,0" for k in range(101)]
    path.write_text("\n".join(rows) + "\n")
    out = tmp_path / "m.json"
    assert score_main([str(path), "--columns", "time_s=t,X_m=x,Y_m=y,psi_rad=theta",
                       "--obstacle", "15,2,0.5,3.0", "--out", str(out)]) == 0
    m = json.loads(out.read_text())
    assert m["min_clearance_m"] == pytest.approx(2.0 - 1.5)
    assert m["goal_reached"] and m["time_to_goal_s"] == pytest.approx(9.9)
    assert m["reaction_delay_s"] is None  # no steering column
