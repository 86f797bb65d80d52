"""The package as a user installs it: a wheel with the configs inside, console commands that
take the same arguments as ``python -m pipeline.<name>``, run from an empty folder."""

from __future__ import annotations

import glob
import shutil
import subprocess
import sys
import sysconfig
import tomllib
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def installed(tmp_path_factory) -> tuple[Path, Path, list[str]]:
    """Build the wheel from a copy of the sources and install it (alone) into a fresh virtual
    environment whose dependencies come from this one: (the venv, an empty folder, the wheel's
    file names)."""
    tmp_path = tmp_path_factory.mktemp("wheel")
    # build from a copy: setuptools writes build/ beside the sources, never into the checkout
    source = tmp_path / "source"
    ignore = shutil.ignore_patterns("__pycache__", "*.pyc")
    for folder in ("pipeline", "conf", "hydra_plugins", "data"):
        shutil.copytree(ROOT / folder, source / folder, ignore=ignore)
    for name in ("pyproject.toml", "setup.py", "README.md", "LICENSE"):
        shutil.copy(ROOT / name, source / name)
    wheels = tmp_path / "wheels"
    subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation",
                    "-q", "-w", str(wheels), str(source)], check=True, capture_output=True,
                   timeout=300)
    wheel = glob.glob(str(wheels / "*.whl"))[0]
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
    return venv, empty, zipfile.ZipFile(wheel).namelist()


def test_the_wheel_carries_every_module_config_and_track_of_the_checkout(installed):
    """Packages are found, not listed (setup.py): every Python file under pipeline/ and
    hydra_plugins/, every YAML under conf/ and every track under data/ of the checkout is in the
    wheel (the oracle is the file tree itself; a hand list once left pipeline.peers out)."""
    names = set(installed[2])
    expected = {str(p.relative_to(ROOT)) for folder in ("pipeline", "hydra_plugins")
                for p in (ROOT / folder).rglob("*.py") if "__pycache__" not in p.parts}
    expected |= {"pipeline/conf/" + str(p.relative_to(ROOT / "conf"))
                 for p in (ROOT / "conf").rglob("*.yaml")}
    expected |= {"pipeline/data/" + str(p.relative_to(ROOT / "data"))
                 for p in (ROOT / "data").rglob("*") if p.is_file()}
    assert "pipeline/peers/velocity_obstacles.py" in expected and "pipeline/py.typed" in names
    assert expected - names == set()
    assert not [n for n in names if "__pycache__" in n or n.startswith(("tests/", "build/"))]


def test_wheel_installs_and_runs_from_an_empty_folder(installed):
    """From an empty folder, the installed ``apf-mpc run planner=baseline`` exits 0 and writes a
    run folder with its manifest, the package and its configs read from the install; every
    console script the package declares answers ``--help``, and so does every command of
    ``apf-mpc``."""
    venv, empty, _ = installed
    python = venv / "bin" / "python"
    proc = subprocess.run([str(venv / "bin" / "apf-mpc"), "run", "planner=baseline"], cwd=empty,
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert list(empty.glob("outputs/runs/*/baseline/*/manifest.json"))
    where = subprocess.run([str(python), "-c", "import pipeline.config as c; "
                            "print(c.__file__); print(c.CONF_DIR)"], cwd=empty,
                           capture_output=True, text=True, check=True).stdout.split()
    assert all(str(venv) in line for line in where)
    scripts = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["scripts"]
    assert scripts
    assert list(scripts) == ["apf-mpc"]  # one command (aliases: python -m pipeline.<name>)
    from pipeline.store.study_registry import load_studies

    studies = load_studies()
    listed = subprocess.run([str(venv / "bin" / "apf-mpc"), "--help"], cwd=empty,
                            capture_output=True, text=True, timeout=120)
    assert listed.returncode == 0 and all(f"  {s.name} " in listed.stdout for s in studies)
    # the benchmark harness lives in the repository (benchmarks/), not in the wheel
    assert "  bench " not in listed.stdout
    assert not [n for n in installed[2] if n.startswith("benchmarks/")]
    for study in studies:
        proc = subprocess.run([str(venv / "bin" / "apf-mpc"), study.name, "--help"],
                              cwd=empty, capture_output=True, text=True, timeout=120)
        # argparse's usage line; Hydra's own help for `run` ("... powered by Hydra")
        said = "hydra" if study.name == "run" else "usage"
        assert proc.returncode == 0 and said in proc.stdout.lower(), \
            (study.name, proc.stderr[-1000:])


def test_every_method_preset_runs_from_the_installed_wheel(installed):
    """Every method preset the wheel carries (peers included) runs the paper scenario from the
    installed package in one Hydra multirun: exit 0 and one run folder per method."""
    venv, empty, names = installed
    methods = sorted(Path(n).stem for n in names if n.startswith("pipeline/conf/method/"))
    assert {"vo", "dwa_kinematic", "mpc_dcbf", "cbf_filter", "improved"} <= set(methods)
    sweep = empty / "every_method"
    proc = subprocess.run([str(venv / "bin" / "python"), "-m", "pipeline.run", "-m",
                           "method=" + ",".join(methods), "scenario.n_steps=20",
                           f"hydra.sweep.dir={sweep}"], cwd=empty, capture_output=True,
                          text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert len(list(sweep.glob("*/manifest.json"))) == len(methods), proc.stderr[-2000:]


def _freeze(python: Path) -> set[str]:
    """The installed distributions, normalised (pip's bookkeeping packages left out)."""
    out = subprocess.run([str(python), "-m", "pip", "list", "--format=freeze"],
                         capture_output=True, text=True, check=True).stdout
    names = {line.lower().replace("_", "-") for line in out.splitlines() if "==" in line}
    return {n for n in names if n.split("==")[0] not in ("pip", "setuptools", "wheel", "uv",
                                                          "apf-mpc-repro")}


@pytest.mark.machine
def test_make_install_uses_uv_and_falls_back_to_pip_with_the_same_pins(tmp_path):
    """``make install`` (INSTALLER=uv, the default) installs with uv; ``INSTALLER=pip`` with pip
    alone; both give the same distributions at the same pinned versions (WARM=no: the warm
    step is test_warm's)."""
    envs = {}
    for installer in ("uv", "pip"):
        venv = tmp_path / f"venv_{installer}"
        proc = subprocess.run(["make", "install", f"VENV={venv}", f"INSTALLER={installer}",
                               "WARM=no"],
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
