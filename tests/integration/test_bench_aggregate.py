"""``make bench``'s aggregate step (benchmarks/bench_aggregate.py) runs to its one line: it
once ended ``make bench`` in a traceback (a keyword ``aggregate()`` no longer takes)."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_the_aggregate_benchmark_ends_in_one_line_with_every_job_as_a_row():
    proc = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "bench_aggregate.py"), "12"],
                          capture_output=True, text=True, timeout=300, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr[-2000:]
    lines = proc.stdout.strip().splitlines()
    assert len(lines) == 1 and proc.stderr.strip() == ""
    assert re.fullmatch(r"created 12 job folders in [\d.]+ s; aggregate: [\d.]+ s "
                        r"\(12 rows, \d+ columns\)", lines[0]), lines
