"""``python -m pipeline.warm`` (make install's last step): the bytecode of exactly what the
commands import, written even where PYTHONDONTWRITEBYTECODE is set, and the numba kernels in
numba's cache; a wrong argument is one line and exit 2."""

from __future__ import annotations

import importlib.util
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


def test_kernels_only_puts_every_kernel_in_numbas_cache(tmp_path):
    """``--kernels-only`` (the other core's half of make install: ``api.warm_compiled_kernels``)
    leaves each of the twelve loop kernels the runs call (a lone member's and the lockstep
    engine's batched ones: the plants' rows, the path frames' and plans' rows, DAQP's batched
    caller) and the
    ledgers' bootstrap kernels compiled in an empty numba cache (NUMBA_CACHE_DIR), and compiles
    no project module list of its own. (One warm run for both checks: each compiles every
    kernel, about 20 s.)"""
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path)}
    proc = subprocess.run([sys.executable, "-m", "pipeline.warm", "--kernels-only"], env=env,
                          capture_output=True, text=True, check=False)
    assert proc.returncode == 0, proc.stderr
    assert "numba kernels" in proc.stdout and "compiled the bytecode" not in proc.stdout
    indexed = {p.name.split("-")[0] for p in tmp_path.rglob("*.nbi")}
    assert indexed == {"model.single_track_rk4_rows", "planner.apf_rollout_arrays",
                       "references.lateral_side_halfplane_arrays",
                       "references.reference_arrays", "path.chase_path_arrays",
                       "path.rollout_path_arrays", "path.frame_step_arrays",
                       "compiled.walsh_medians", "compiled._count_at_most",
                       "compiled._order_statistic", "path.plan_poses_arrays",
                       "prediction_check.check_record_arrays", "path_rows.path_frame_rows",
                       "path_rows.plan_poses_rows", "daqp_rows.daqp_condensed_rows"}, indexed
    assert len(list(tmp_path.rglob("*.nbc"))) >= 15  # the compiled code beside each index
