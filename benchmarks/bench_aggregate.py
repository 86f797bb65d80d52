"""Benchmark: aggregate N synthetic job folders (default 10,000); prints one line (seconds).

    .venv/bin/python -m benchmarks.bench_aggregate [N]      (make bench runs it)
"""

from __future__ import annotations

import json
import sys
import tempfile
import time
from pathlib import Path

from pipeline.analysis.metrics.results import RunMetrics
from pipeline.store.runs import RunInfo, write_run
from pipeline.studies.aggregate import aggregate
from pipeline.studies.experiment import config_yaml


def default_config_text() -> str:
    """The default configuration's ``config.yaml`` (every job carries readable settings)."""
    from hydra import compose, initialize_config_dir

    from pipeline.config import CONF_DIR, register_configs, to_experiment_config

    register_configs()
    with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
        return config_yaml(to_experiment_config(compose(config_name="config")))


def make_jobs(root: Path, n: int) -> None:
    """Complete run records (manifest included) with a two-row trajectory each."""
    import pandas as pd  # after the package, which pins numpy's kernels before numpy loads

    metrics = json.loads((Path(__file__).parent / "sample_metrics.json").read_text())
    trajectory = pd.DataFrame({"time_s": [0.0, 0.1], "X_m": [0.0, 0.3], "Y_m": [0.0, 0.0]})
    config_text = default_config_text()
    for i in range(n):
        job = root / f"method={'baseline' if i % 2 else 'improved'},controller.horizon={i // 2}"
        (job / ".hydra").mkdir(parents=True)
        (job / ".hydra" / "overrides.yaml").write_text(
            f"- method={'baseline' if i % 2 else 'improved'}\n- controller.horizon={i // 2}\n")
        flat = {**metrics, "min_clearance_m": i * 1e-4,
                "method": "baseline" if i % 2 else "improved", "config_hash": str(i)}
        write_run(job, config_text=config_text, model={}, trajectory=trajectory, timing={},
                  metrics=RunMetrics.from_json(flat), info=RunInfo.from_json(flat))


def main() -> None:
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 10_000
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        start = time.perf_counter()
        make_jobs(root, n)
        made = time.perf_counter() - start
        start = time.perf_counter()
        # the typed result (pipeline.studies.results.sweep.SweepSummary); its figures are the
        # command's (apf-mpc aggregate), not timed here
        result = aggregate(root, progress=False)
        elapsed = time.perf_counter() - start
    table = result.summary
    print(f"created {n} job folders in {made:.1f} s; aggregate: {elapsed:.2f} s "
          f"({len(table)} rows, {len(table.columns)} columns)")


if __name__ == "__main__":
    main()
