"""``python -m pipeline.bench --quick --smoke`` (issue 58, item 7): the reduced benchmark, each
measurement at its smallest size, runs to its end from the checkout's root and writes
``bench_summary.json`` into ``--out`` with every figure a quick run measures a finite number (the
ratios over a floor positive), the two it leaves out None with the reason. It once ended ``make bench`` in a
traceback after 26 minutes; no timing is asserted."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

from benchmarks.harness import NOT_QUICK, QUICK_KEYS

ROOT = Path(__file__).resolve().parents[2]


def test_the_quick_bench_writes_every_figure_it_measures(tmp_path):
    out = tmp_path / "bench"
    proc = subprocess.run([sys.executable, "-m", "pipeline.bench", "--quick", "--smoke", "--out",
                           str(out)], capture_output=True, text=True, timeout=900, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert "Traceback" not in proc.stderr
    summary = json.loads((out / "bench_summary.json").read_text())
    assert summary["quick"] is True and summary["smoke"] is True
    missing = [key for key in QUICK_KEYS if key not in summary]
    assert missing == []
    not_finite = {key: summary[key] for key in QUICK_KEYS
                  if not isinstance(summary[key], (int, float)) or isinstance(summary[key], bool)
                  or not math.isfinite(summary[key])}
    assert not_finite == {}
    ratios = [key for key in QUICK_KEYS if "_over_" in key]
    assert {"family_member_over_sparse_floor_daqp", "outside_qp_over_qp_daqp"} <= set(ratios)
    assert {key: summary[key] for key in ratios if summary[key] <= 0} == {}
    # the QPs were solved on every backend and agreed with the sparse floor's first move
    lateral = summary["lateral"][0]
    assert (lateral["N"], lateral["obstacles"]) == (10, 1)
    assert lateral["max_u0_diff_floor_vs_cvxpy"] < 1e-4
    assert lateral["max_u0_diff_daqp_vs_direct"] < 1e-4
    assert {key: summary[key] for key in NOT_QUICK} == NOT_QUICK
    assert (out / "bench.csv").is_file() and (out / "scaling.png").is_file()
