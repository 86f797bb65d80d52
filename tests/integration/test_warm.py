"""``python -m pipeline.warm`` (make install's last step): the bytecode of exactly what the
commands import, written even where PYTHONDONTWRITEBYTECODE is set, and the numba kernels in
numba's cache; a wrong argument is one line and exit 2."""

from __future__ import annotations

import importlib.util
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest


def _cached(prefix: Path, module: str) -> bool:
    """True when ``module``'s ``.pyc`` lies under the pycache ``prefix``."""
    spec = importlib.util.find_spec(module)
    assert spec is not None and spec.origin is not None, module
    # with PYTHONPYCACHEPREFIX, a.py's bytecode lies at <prefix>/<a's folder>/a.cpython-311.pyc
    source = Path(spec.origin).resolve()
    tag = sys.implementation.cache_tag
    return (prefix / source.parent.relative_to("/") / f"{source.stem}.{tag}.pyc").is_file()


@pytest.mark.machine
def test_bytecode_is_written_for_what_the_commands_import_and_nothing_else(tmp_path):
    """With bytecode writing off in the environment (as on this machine), ``--no-kernels``
    leaves the ``.pyc`` of the project's modules and of the libraries they import lazily
    (optuna, scipy.stats, the report's figure backend) in a fresh pycache, and none for a
    module nothing imports (scipy.io's MATLAB reader)."""
    prefix = tmp_path / "pycache"
    env = {**os.environ, "PYTHONDONTWRITEBYTECODE": "1", "PYTHONPYCACHEPREFIX": str(prefix)}
    proc = subprocess.run([sys.executable, "-m", "pipeline.warm", "--no-kernels"], env=env,
                          capture_output=True, text=True, check=False)
    assert proc.returncode == 0, proc.stderr
    assert "compiled the bytecode of" in proc.stdout
    for module in ("pipeline.studies.tune.search", "pipeline.reporting.page", "optuna.study",
                   "scipy.stats._stats_py", "matplotlib.backends.backend_agg"):
        assert _cached(prefix, module), module
    assert not _cached(prefix, "scipy.io.matlab._mio5")


def test_without_the_warm_step_nothing_is_written(tmp_path):
    """The oracle for the test above: the same environment and an ordinary import of optuna
    leaves no ``.pyc`` (so the warm step's bytecode is its own doing)."""
    prefix = tmp_path / "pycache"
    env = {**os.environ, "PYTHONDONTWRITEBYTECODE": "1", "PYTHONPYCACHEPREFIX": str(prefix)}
    subprocess.run([sys.executable, "-c", "import optuna.study"], env=env, check=True)
    assert not _cached(prefix, "optuna.study")


@pytest.mark.parametrize("args", [["--fast"], ["--no-kernels", "--kernels-only"]])
def test_a_wrong_argument_is_one_line(args):
    proc = subprocess.run([sys.executable, "-m", "pipeline.warm", *args],
                          capture_output=True, text=True, check=False)
    assert proc.returncode == 2
    assert proc.stderr.count("\n") == 1 and "allowed" in proc.stderr
    assert "Traceback" not in proc.stderr


#: Run in a fresh process: ``pipeline.warm --kernels-only`` (its ``main``), then every kernel of
#: the two kernel modules as numba holds it: its cache's class and index file, its signatures
#: (what this process compiled or loaded from the cache).
_INSPECT_WARM = """
import json
from pathlib import Path
from numba.core.dispatcher import Dispatcher
from pipeline.warm import main
status = main(["--kernels-only"])
import pipeline.analysis.claims.compiled as claims_kernels
import pipeline.analysis.metrics.compiled as metrics_kernels
import pipeline.loop.compiled as loop_kernels
kernels = {}
for module in (loop_kernels, claims_kernels, metrics_kernels):
    for value in vars(module).values():
        if isinstance(value, Dispatcher):
            index = Path(str(value._cache._cache_file._index_path))
            kernels[index.name.split("-")[0]] = {
                "cache": type(value._cache).__name__, "index": index.is_file(),
                "signatures": len(value.signatures)}
print(json.dumps({"status": status, "kernels": kernels}))
"""

#: The kernels the runs call (a lone member's and the lockstep engine's batched ones: the
#: plants' rows, the path frames' and plans' rows, DAQP's batched caller, the Clarabel
#: members' data and read-out; the calls of the engine's groups, pipeline/loop/group_rows.py;
#: the ledgers' bootstrap; the collision oracle's search), and the two the bootstrap's kernel
#: compiles into itself.
RUN_KERNELS = {"model.single_track_rk4_rows", "planner.apf_rollout_arrays",
               "references.lateral_side_halfplane_arrays", "references.reference_arrays",
               "path.chase_path_arrays", "path.rollout_path_arrays", "path.frame_step_arrays",
               "compiled.walsh_medians", "path.plan_poses_arrays",
               "prediction_check.check_record_arrays", "path_rows.path_frame_rows",
               "path_rows.plan_poses_rows", "daqp_rows.daqp_condensed_rows",
               "direct_rows.direct_theta_rows", "direct_rows.direct_readout_rows",
               "geometry.manoeuvre_survives", "group_rows.observe_plan_rows",
               "group_rows.frame_rows", "group_rows.solve_rows", "group_rows.apply_rows",
               "group_rows.theta_rows", "group_rows.readout_rows", "group_rows.check_rows"}
CALLEES = {"compiled._count_at_most", "compiled._order_statistic"}


@pytest.mark.machine
def test_kernels_only_puts_every_kernel_in_numbas_cache():
    """``--kernels-only`` (the other core's half of make install: ``api.warm_compiled_kernels``)
    compiles or loads each kernel the runs call, every one with numba's on-disk cache and its
    index file there, and compiles no project module list of its own. Run on the checkout's own
    cache (warm after make install: about 4 s, where an empty cache compiles every kernel in
    about 25 s, as make install does): a kernel the warm step stops calling has no signature in
    the warm process, and one numba cannot cache has no cache or no index file."""
    proc = subprocess.run([sys.executable, "-c", _INSPECT_WARM], capture_output=True,
                          text=True, check=False, cwd=Path(__file__).resolve().parents[2])
    assert proc.returncode == 0, proc.stderr
    said, inspected = proc.stdout.strip().splitlines()[-2:]
    assert said == "pipeline.warm: put the numba kernels in numba's cache"
    report = json.loads(inspected)
    kernels = report["kernels"]
    assert report["status"] == 0
    warmed = {name for name, k in kernels.items() if k["signatures"]}
    assert warmed == RUN_KERNELS, warmed ^ RUN_KERNELS
    # the plant's lone step compiled is kept (its rows call it); no run calls it alone
    assert set(kernels) == RUN_KERNELS | CALLEES | {"model.single_track_rk4"}
    assert {name for name, k in kernels.items() if k["cache"] != "FunctionCache"} == set()
    assert {name for name in RUN_KERNELS | CALLEES if not kernels[name]["index"]} == set()
