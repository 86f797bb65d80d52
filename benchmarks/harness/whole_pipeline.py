"""Whole-pipeline figures: import time, one paper-scenario run, a family's throughput and
compilations, peak memory, and the quick multiverse's member reads."""

from __future__ import annotations

import resource
import subprocess
import sys
import time
from pathlib import Path

from benchmarks.harness.inputs import compose_config
from pipeline.store.runs import read_family


def bench_multiverse_reads(smoke: bool = False) -> dict:
    """The quick multiverse (conf/multiverse/quick.yaml) run once into a temporary folder: how
    many member trajectories its re-scoring read per member (goal 1: every metric reading of a
    member computed in one pass). ``smoke``: 4 members and 4 specifications (the same
    dimensions and readings; its wall time is then not the quick space's)."""
    import contextlib
    import dataclasses
    import io
    import tempfile

    from pipeline.config import CONF_DIR
    from pipeline.studies.multiverse import load_space, run_multiverse

    space = load_space(CONF_DIR / "multiverse" / "quick.yaml")
    if smoke:
        space = dataclasses.replace(space, family_size=4, n_specifications=4)
    with tempfile.TemporaryDirectory() as tmp, contextlib.redirect_stdout(io.StringIO()):
        start = time.perf_counter()
        result = run_multiverse(space, Path(tmp), log=lambda message: None)
        wall = time.perf_counter() - start
    return {"multiverse_member_reads_per_member": result.info.member_reads_per_member,
            "quick_multiverse_wall_s": wall}


def bench_pipeline(family_size: int, compile_family_size: int = 40) -> dict:
    """Import time, one paper-scenario run (with its files), compilations over a family, a
    family's throughput on two workers (worker start included), peak memory."""
    import tempfile

    from pipeline.studies.experiment import run_experiment, run_family

    code = ("import sys, time; t = time.perf_counter(); import pipeline.studies.experiment; "
            "sys.stdout.write(str(time.perf_counter() - t))")
    imports = float(subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                                   check=True).stdout.strip())
    with tempfile.TemporaryDirectory() as tmp:
        start = time.perf_counter()
        # composed inside the timers as a command composes (not from the bench's memo)
        run_experiment(compose_config(["method=improved"], cached=False), Path(tmp) / "one",
                       resume=False)
        one_run = time.perf_counter() - start
        run_family(compose_config(["method=improved", "scenario=family",
                                   f"scenario.family.size={compile_family_size}",
                                   "scenario.family.n_jobs=2"]), Path(tmp) / "compiles",
                   progress=False)
        compiles = read_family(Path(tmp) / "compiles", members=False).timing["compiles"]
        start = time.perf_counter()
        run_family(compose_config(["method=improved", "scenario=family",
                                   f"scenario.family.size={family_size}",
                                   "scenario.family.n_jobs=2"], cached=False),
                   Path(tmp) / "timed", progress=False)
        family = time.perf_counter() - start
    return {"import_s": imports, "one_paper_run_s": one_run, "family_size": family_size,
            "family_wall_s": family, "family_scenarios_per_s": family_size / family,
            "compile_family_size": compile_family_size, "compiles_per_family": int(compiles),
            "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0}
