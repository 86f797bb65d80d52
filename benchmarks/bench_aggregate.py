"""Benchmark: aggregate N synthetic job folders (default 10,000); prints seconds.

    .venv/bin/python benchmarks/bench_aggregate.py [N]
"""

from __future__ import annotations

import json
import sys
import tempfile
import time
from pathlib import Path

import pandas as pd

from pipeline.studies.aggregate import aggregate
from pipeline.store.runs import write_run


def make_jobs(root: Path, n: int) -> None:
    """Complete run records (manifest included) with a two-row trajectory each."""
    metrics = json.loads((Path(__file__).parent / "sample_metrics.json").read_text())
    trajectory = pd.DataFrame({"time_s": [0.0, 0.1], "X_m": [0.0, 0.3], "Y_m": [0.0, 0.0]})
    for i in range(n):
        job = root / f"method={'baseline' if i % 2 else 'improved'},controller.horizon={i // 2}"
        (job / ".hydra").mkdir(parents=True)
        (job / ".hydra" / "overrides.yaml").write_text(
            f"- method={'baseline' if i % 2 else 'improved'}\n- controller.horizon={i // 2}\n")
        write_run(job, config_text="{}\n", model={}, trajectory=trajectory, timing={},
                  metrics={**metrics, "min_clearance_m": i * 1e-4,
                           "method": "baseline" if i % 2 else "improved"}, config_hash=str(i))


def main() -> None:
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 10_000
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        start = time.perf_counter()
        make_jobs(root, n)
        made = time.perf_counter() - start
        start = time.perf_counter()
        summary = aggregate(root, progress=False, figures=False)
        elapsed = time.perf_counter() - start
    print(f"created {n} job folders in {made:.1f} s; aggregate: {elapsed:.2f} s "
          f"({len(summary)} rows, {len(summary.columns)} columns)")


if __name__ == "__main__":
    main()
