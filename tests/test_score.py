"""The scoring command: bad files give one clear error; our own log scores to metrics.json."""

from __future__ import annotations

import json

import pytest

from pipeline.studies.experiment import run_experiment
from pipeline.studies.score import main as score_main


@pytest.mark.parametrize("content, message", [
    ("", "empty"),
    ("time_s,X_m,Y_m\n", "no rows"),
    ("time_s,X_m,Y_m\n0,0,0\n", "single row"),
    ("time_s,X_m\n0,0\n0.1,0.3\n", "missing required column(s) ['Y_m']"),
    ("time_s,X_m,Y_m\n0,0,0\n0.1,abc,0\n", "column 'X_m', data row 2: 'abc' is not a finite"),
    ("time_s,X_m,Y_m\n0,0,0\n0.1,0.3,0\n0.1,0.6,0\n", "increase strictly"),
    ("time_s,X_m,Y_m\n0.2,0,0\n0.1,0.3,0\n", "increase strictly"),
    ("time_s,X_m,Y_m\n0,0,0\n0.1,,0\n", "column 'X_m', data row 2: '' is not a finite"),
    ("time_s,X_m,Y_m,obs0_x_m,obs0_y_m,obs0_radius_m,obs0_visible\n0,0,0,5,0,0.5,yes\n"
     "0.1,0.3,0,5,0,0.5,no\n", "'yes' is not a boolean"),
    ("time_s,X_m,Y_m,obs0_x_m,obs0_y_m,obs0_radius_m\n0,0,0,5,0,-0.5\n0.1,0.3,0,5,0,-0.5\n",
     "is not a positive radius"),
    ("time_s,X_m,Y_m,obs0_x_m,obs0_y_m\n0,0,0,5,0\n0.1,0.3,0,5,0\n", "has no obs0_radius_m"),
    ("time_s,X_m,Y_m,obs0_x_m,obs0_y_m,obs0_radius_m\n0,0,0,five,0,0.5\n0.1,0.3,0,5,0,0.5\n",
     "column 'obs0_x_m', data row 1: 'five'"),
    ("time_s X_m Y_m\n0 0 0\n0.1 0.3 0\n", "no comma, semicolon or tab"),
])
def test_bad_trajectory_files_give_a_clear_error(tmp_path, capsys, content, message):
    path = tmp_path / "bad.csv"
    path.write_text(content)
    assert score_main([str(path)]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err


def test_other_peoples_files_encodings_separators_comments_and_stdin(tmp_path, capsys,
                                                                    monkeypatch):
    import io

    body = "time_s;X_m;Y_m\n# a comment line\n0;0;0\n0.1;0.3;0\n0.2;0.6;0\n"
    path = tmp_path / "semicolon_bom.csv"
    path.write_bytes(b"\xef\xbb\xbf" + body.encode())
    assert score_main([str(path)]) == 0
    latin = tmp_path / "latin.csv"
    latin.write_bytes("time_s\tX_m\tY_m\tnotiz_\xe4\n0\t0\t0\ta\n0.1\t0.3\t0\tb\n"
                      .encode("latin-1"))
    assert score_main([str(latin)]) == 0
    monkeypatch.setattr("sys.stdin", io.StringIO("time_s,X_m,Y_m\n0,0,0\n0.1,0.3,0\n"))
    assert score_main(["-"]) == 0
    capsys.readouterr()
    assert score_main([str(path), "--columns", "psi=theta"]) == 2
    assert "unknown name(s) ['psi']" in capsys.readouterr().err
    assert score_main([str(path), "--columns", "X_m=Y_m"]) == 2
    assert "already in the file" in capsys.readouterr().err
    assert score_main([str(path), "--obstacle", "5,0,-1"]) == 2
    assert "not positive" in capsys.readouterr().err


def test_out_is_atomic(tmp_path, capsys):
    path = tmp_path / "t.csv"
    path.write_text("time_s,X_m,Y_m\n0,0,0\n0.1,0.3,0\n")
    out = tmp_path / "m.json"
    out.write_text("{\"good\": 1}\n")
    # a folder in the way of the temporary file: the write fails, the old file stays whole
    blocked = tmp_path / "sub"
    blocked.mkdir()
    assert score_main([str(path), "--out", str(blocked)]) == 2
    assert "cannot write" in capsys.readouterr().err
    assert out.read_text() == "{\"good\": 1}\n"
    assert score_main([str(path), "--out", str(out)]) == 0
    assert json.loads(out.read_text())["n_steps_logged"] == 2


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
