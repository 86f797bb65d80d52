"""The numerical kernels are pinned on x86-64 (pipeline.numerics): importing the package sets
OpenBLAS's core type and numpy's SIMD levels before numpy loads, keeps a user's own setting,
and says so when numpy was loaded first."""

from __future__ import annotations

import json
import os
import platform
import subprocess
import sys

import pytest

from pipeline.numerics import PINNED_KERNELS

pytestmark = pytest.mark.skipif(platform.machine().lower() not in ("x86_64", "amd64"),
                                reason="the kernels are pinned on x86-64 only")

SHOW = ("import json, warnings; warnings.simplefilter('always'); {first}; "
        "from pipeline.numerics import numerical_kernels; "
        "print(json.dumps(numerical_kernels()))")


def _run(first: str, **env: str) -> subprocess.CompletedProcess:
    clean = {k: v for k, v in os.environ.items() if k not in PINNED_KERNELS}
    return subprocess.run([sys.executable, "-c", SHOW.format(first=first)], capture_output=True,
                          text=True, env={**clean, **env}, check=True)


def test_importing_pipeline_first_pins_the_kernels():
    done = _run("import pipeline; import numpy")
    # OpenBLAS's own answer and numpy's: the processor's choice would be Haswell (AVX2) or
    # SkylakeX (AVX-512) and X86_V3/X86_V4 on the machines this project runs on
    assert json.loads(done.stdout) == {"numpy_simd": "X86_V2", "openblas": "Nehalem"}
    assert "RuntimeWarning" not in done.stderr


def test_a_users_own_setting_is_kept():
    done = _run("import pipeline; import numpy", OPENBLAS_CORETYPE="Sandybridge")
    assert json.loads(done.stdout)["openblas"] == "Sandybridge"


def test_numpy_loaded_first_is_said():
    done = _run("import numpy; import pipeline")
    assert "numpy was imported before pipeline" in done.stderr
    assert json.loads(done.stdout)["openblas"] != "unknown"
