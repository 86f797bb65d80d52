"""The package as a user installs it: a wheel with the configs inside, console commands that
take the same arguments as ``python -m pipeline.<name>``, run from an empty folder."""

from __future__ import annotations

import glob
import shutil
import subprocess
import sys
import sysconfig
import zipfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def test_wheel_installs_and_runs_from_an_empty_folder(tmp_path):
    """Build the wheel, install it (alone) into a fresh virtual environment whose dependencies
    come from this one, and run ``apf-mpc run planner=baseline`` from an empty folder: exit 0
    and a run folder with its manifest, the package and its configs read from the install."""
    # build from a copy: setuptools writes build/ beside the sources, never into the checkout
    source = tmp_path / "source"
    ignore = shutil.ignore_patterns("__pycache__", "*.pyc")
    for folder in ("pipeline", "conf", "hydra_plugins", "data"):
        shutil.copytree(ROOT / folder, source / folder, ignore=ignore)
    for name in ("pyproject.toml", "README.md", "LICENSE"):
        shutil.copy(ROOT / name, source / name)
    wheels = tmp_path / "wheels"
    subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation",
                    "-q", "-w", str(wheels), str(source)], check=True, capture_output=True,
                   timeout=300)
    wheel = glob.glob(str(wheels / "*.whl"))[0]
    names = zipfile.ZipFile(wheel).namelist()
    assert "pipeline/conf/config.yaml" in names and "pipeline/py.typed" in names
    assert any(n.startswith("pipeline/conf/hparams_search/") for n in names)
    assert any(n.startswith("pipeline/data/eth_ucy/") and n.endswith(".txt.gz") for n in names)
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True,
                   timeout=120)
    python = venv / "bin" / "python"
    site = Path(subprocess.run([str(python), "-c", "import sysconfig; print(sysconfig."
                                "get_paths()['purelib'])"], check=True, capture_output=True,
                               text=True).stdout.strip())
    (site / "project_deps.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    subprocess.run([sys.executable, "-m", "pip", "--python", str(python), "install", "-q",
                    "--no-deps", wheel], check=True, capture_output=True, timeout=300)
    empty = tmp_path / "empty"
    empty.mkdir()
    proc = subprocess.run([str(venv / "bin" / "apf-mpc"), "run", "planner=baseline"], cwd=empty,
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert list(empty.glob("outputs/runs/*/baseline/*/manifest.json"))
    where = subprocess.run([str(python), "-c", "import pipeline.config as c; "
                            "print(c.__file__); print(c.CONF_DIR)"], cwd=empty,
                           capture_output=True, text=True, check=True).stdout.split()
    assert all(str(venv) in line for line in where)
    for study in ("report", "score", "tune"):
        assert subprocess.run([str(venv / "bin" / "apf-mpc"), study, "--help"], cwd=empty,
                              capture_output=True, timeout=120).returncode == 0
    # the one command lists every study of the wheel; the benchmark harness is not in it
    listed = subprocess.run([str(venv / "bin" / "apf-mpc"), "--help"], cwd=empty,
                            capture_output=True, text=True, timeout=120).stdout
    assert "  tune " in listed and "  bench " not in listed
    assert not list(site.glob("benchmarks"))


def _freeze(python: Path) -> set[str]:
    """The installed distributions, normalised (pip's bookkeeping packages left out)."""
    out = subprocess.run([str(python), "-m", "pip", "list", "--format=freeze"],
                         capture_output=True, text=True, check=True).stdout
    names = {line.lower().replace("_", "-") for line in out.splitlines() if "==" in line}
    return {n for n in names if n.split("==")[0] not in ("pip", "setuptools", "wheel", "uv",
                                                          "apf-mpc-repro")}


def test_make_install_uses_uv_and_falls_back_to_pip_with_the_same_pins(tmp_path):
    """``make install`` (INSTALLER=uv, the default) installs with uv; ``INSTALLER=pip`` with pip
    alone; both give the same distributions at the same pinned versions."""
    envs = {}
    for installer in ("uv", "pip"):
        venv = tmp_path / f"venv_{installer}"
        proc = subprocess.run(["make", "install", f"VENV={venv}", f"INSTALLER={installer}"],
                              cwd=ROOT, capture_output=True, text=True, timeout=900)
        assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
        said = "installed with uv" if installer == "uv" else "installing with pip"
        assert said in proc.stdout
        assert (venv / "bin" / "uv").exists() == (installer == "uv")
        envs[installer] = _freeze(venv / "bin" / "python")
    assert envs["uv"] == envs["pip"] and len(envs["uv"]) > 50
    pins = {line.strip().lower().replace("_", "-")
            for line in (ROOT / "constraints.txt").read_text().splitlines() if "==" in line}
    assert envs["uv"] <= pins
