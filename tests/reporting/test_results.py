"""Each study's typed result: what it writes it reads back the same, and a folder changed after
writing (or written without its manifest) is refused with the reason, never read."""

from __future__ import annotations

import pandas as pd
import pytest

from pipeline.studies.results import BenchResult, NmpcCheckResult, ResultError, SpeedCheckResult


def test_a_result_reads_back_what_it_wrote_and_refuses_a_changed_folder(tmp_path):
    speed = SpeedCheckResult(3, ({"variant": "nominal", "method": "improved", "collisions": 1},),
                             ({"method": "improved", "check": "on <= off", "holds": True},))
    written = speed.write(tmp_path / "speed")
    again = SpeedCheckResult.load(tmp_path / "speed")
    assert (again.n_members, again.rows, again.checks) == (3, speed.rows, speed.checks)
    assert written.folder == again.folder == tmp_path / "speed"
    nmpc = NmpcCheckResult({"lateral": {"runs": 2, "verdicts": []}}, pd.DataFrame({"a": [1.5]}))
    nmpc.write(tmp_path / "nmpc")
    assert NmpcCheckResult.load(tmp_path / "nmpc").track("lateral") == {"runs": 2,
                                                                        "verdicts": []}
    assert NmpcCheckResult.load(tmp_path / "nmpc").track("kinematic") is None
    bench = BenchResult({"step_over_sparse_floor": 0.43, "lateral": []},
                        pd.DataFrame({"N": [10], "floor_s": [1e-4]}))
    bench.write(tmp_path / "bench")
    loaded = BenchResult.load(tmp_path / "bench")
    assert loaded["step_over_sparse_floor"] == 0.43
    pd.testing.assert_frame_equal(loaded.table, bench.table)
    # a table edited after writing: refused with the file named, never shown
    (tmp_path / "bench" / "bench.csv").write_text("N,floor_s\n10,9\n")
    with pytest.raises(ResultError, match="bench.csv differs"):
        BenchResult.load(tmp_path / "bench")
    # a folder without its manifest (killed, or an older version): refused
    (tmp_path / "speed" / "manifest.json").unlink()
    with pytest.raises(ResultError, match="no manifest.json"):
        SpeedCheckResult.load(tmp_path / "speed")
    # a summary of another shape: one line, not a KeyError
    (tmp_path / "odd").mkdir()
    odd = SpeedCheckResult(1, (), ())
    odd.write(tmp_path / "odd")
    assert SpeedCheckResult.load(tmp_path / "odd").rows == ()
