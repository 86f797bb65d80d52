"""The scoring command: bad files give one clear error; our own log scores to metrics.json."""

from __future__ import annotations

import json

import pytest

from pipeline.score import main as score_main
from pipeline.studies.experiment import run_experiment


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
    # a coordinate whose square overflows: one line, never a null clearance read as missing
    assert score_main([str(path), "--obstacle", "1e200,2,1"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].endswith("--obstacle: '1e200,2,1' is out of range; allowed: numbers within "
                            "+-1e+07 (m, m/s)")


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
    # every column is there: nothing missing, nothing derived from the path
    assert scored.pop("score_quality") == {"missing": {}, "derived": {}, "empty_cells": {}}
    assert "score:" not in capsys.readouterr().err
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


def test_partial_trajectories_say_what_they_cannot_give(tmp_path, make_config, capsys):
    """The README's case (t, x, y, theta, as the paper's MATLAB code would export): C1 and C3
    are missing (null, never 'false'), C2 is derived from the path, one stderr line each and
    marked in the JSON; adding the steering and APF columns makes them exact (equal to the
    run's own metrics.json)."""
    import pandas as pd

    run_experiment(make_config(["method=improved"]), tmp_path / "run")
    expected = json.loads((tmp_path / "run" / "metrics.json").read_text())
    full = pd.read_csv(tmp_path / "run" / "trajectory.csv")
    obstacles = [c for c in full.columns if c.startswith("obs")]
    part = full[["time_s", "X_m", "Y_m", "psi_rad"] + obstacles].rename(
        columns={"time_s": "t", "X_m": "x", "Y_m": "y", "psi_rad": "theta"})
    part.to_csv(tmp_path / "part.csv", index=False)
    capsys.readouterr()
    assert score_main([str(tmp_path / "part.csv"), "--columns",
                       "time_s=t,X_m=x,Y_m=y,psi_rad=theta", "--out",
                       str(tmp_path / "p.json")]) == 0
    err = capsys.readouterr().err
    assert "score: C1 reaction_delay_s missing: no steering-angle column" in err
    assert "score: C3a repulsion_unneeded_share missing" in err
    assert "score: C2 lateral_jerk_rms_mps3 derived" in err
    scored = json.loads((tmp_path / "p.json").read_text())
    assert scored["reacted"] is None and scored["reaction_delay_s"] is None
    assert "lateral_jerk_rms_mps3" in scored["score_quality"]["derived"]
    assert scored["lateral_jerk_rms_mps3"] != pytest.approx(expected["lateral_jerk_rms_mps3"])
    exact = full[["time_s", "X_m", "Y_m", "psi_rad", "vx_mps", "vy_mps", "r_rad_s",
                  "delta_rad", "steering_rate_rad_s", "apf_rep_norm"] + obstacles]
    exact.to_csv(tmp_path / "exact.csv", index=False)
    assert score_main([str(tmp_path / "exact.csv"), "--out", str(tmp_path / "e.json")]) == 0
    scored = json.loads((tmp_path / "e.json").read_text())
    for key in ("reaction_delay_s", "lateral_jerk_rms_mps3", "repulsion_unneeded_share",
                "repulsion_onset_ttc_s", "recovery_time_s", "oscillation_count"):
        assert scored[key] == pytest.approx(expected[key], rel=1e-6, abs=1e-6), key


def c3_known_answer_csv(path, onset_x_m: float = 6.0) -> None:
    """3 m/s along y = -3 past a static obstacle at (15, 0), then a second run on its line:
    here one file, beside the obstacle, repulsion 2.0 from x = onset_x_m on (0.5 before)."""
    import numpy as np
    import pandas as pd

    t = np.round(np.arange(0.0, 10.0, 0.1), 10)
    x = 3.0 * t
    frame = pd.DataFrame({"time_s": t, "X_m": x, "Y_m": np.full(t.size, -3.0),
                          "psi_rad": 0.0, "vx_mps": 3.0, "vy_mps": 0.0, "r_rad_s": 0.0,
                          "delta_rad": 0.0, "steering_rate_rad_s": 0.0,
                          "apf_rep_norm": np.where(x >= onset_x_m - 1e-9, 2.0, 0.5),
                          "obs0_x_m": 15.0, "obs0_y_m": 0.0, "obs0_radius_m": 0.5,
                          "obs0_visible": True})
    frame.to_csv(path, index=False)


def test_score_gives_the_known_answers_of_c3a_and_c3b(tmp_path, capsys):
    """C3a through pipeline.score: beside the obstacle (clearance 1.5 m, inside the 2 m near
    field while |x - 15| < sqrt(3.5^2 - 9)) the force is needed; the unneeded share is the
    impulse outside the near field over all of it. C3b: on the obstacle's line the onset of
    repulsion above 1.0 at x = 6 m comes (15 - 6 - 2) / 3 s before contact."""
    import numpy as np

    beside = tmp_path / "beside.csv"
    c3_known_answer_csv(beside)
    assert score_main([str(beside), "--vehicle-radius", "1.0"]) == 0
    m = json.loads(capsys.readouterr().out)
    t = np.round(np.arange(0.0, 10.0, 0.1), 10)
    x = 3.0 * t
    rep = np.where(x >= 6.0 - 1e-9, 2.0, 0.5)
    far = np.hypot(x - 15.0, 3.0) - 1.5 > 2.0
    assert m["repulsion_unneeded_share"] == pytest.approx(rep[far].sum() / rep.sum())
    on_line = tmp_path / "on_line.csv"
    c3_known_answer_csv(on_line)
    text = on_line.read_text().replace(",-3.0,", ",0.0,")
    on_line.write_text(text)
    assert score_main([str(on_line), "--vehicle-radius", "1.0"]) == 0
    m = json.loads(capsys.readouterr().out)
    assert m["repulsion_onset_ttc_s"] == pytest.approx((15.0 - 6.0 - 2.0) / 3.0)
