"""The last step of ``make install``: bytecode for the modules the commands import, and the
closed loop's numba kernels in numba's on-disk cache.

``python -m pipeline.warm`` (both), ``--no-kernels`` (the bytecode only: after an extra is
added), ``--kernels-only`` (the kernels, writing the bytecode of what they import). ``make
install`` runs the two halves side by side on the two cores (measured: 6.4 s against 8.4 s one
after the other); two processes writing the same ``.pyc`` is safe, Python writes each to a
temporary file and renames it.

Why: where ``PYTHONDONTWRITEBYTECODE`` is set (this machine and its CI), Python never writes a
``.pyc``, so every process (each family worker, each test worker) would compile every module it
imports again (measured: 5 s of optuna alone). pip compiles the whole of site-packages at install
time; ``uv pip install --compile-bytecode`` did the same, about 8 s of the 17 s set-up on 2 cores,
most of it for modules no command imports. Here the process turns bytecode writing back on for
itself alone (``sys.dont_write_bytecode``) and imports what the commands import: every module of
the project, the libraries they load lazily and the test tools, so exactly those are compiled,
once. The first five steps of four runs then put the loop's kernels in numba's cache, so that a
first ``make reproduce``'s eight experiments and their workers load them instead of compiling them
all at once.
"""

from __future__ import annotations

import compileall
import importlib
import importlib.util
import pkgutil
import sys
import sysconfig
from pathlib import Path

#: libraries imported inside functions (not at a module's top), so not reached by importing the
#: project's modules: the report's figure backends, Optuna's storages, the statistics, the test
#: tools of the ``[test]`` extra (skipped where they are not installed)
LAZY_IMPORTS: tuple[str, ...] = (
    "matplotlib.pyplot", "matplotlib.backends.backend_agg", "matplotlib.backends.backend_svg",
    "PIL.Image", "PIL.PngImagePlugin", "scipy.stats", "scipy.optimize", "scipy.linalg",
    "optuna", "optuna.storages.journal", "cvxpy", "clarabel", "daqp",
    "casadi", "joblib", "submitit", "hydra._internal.core_plugins.basic_launcher",
    "hydra._internal.core_plugins.basic_sweeper",
    "hydra_plugins.hydra_joblib_launcher", "hydra_plugins.hydra_submitit_launcher",
    "pytest", "_pytest.python", "_pytest.fixtures", "xdist", "xdist.remote", "hypothesis",
    "playwright.sync_api", "mypy.api", "pandas.io.formats.style",
)

#: the project's packages: each of their modules is imported
PROJECT_PACKAGES: tuple[str, ...] = ("pipeline", "hydra_plugins.pipeline_launchers")


def _installed(name: str) -> bool:
    """True when ``name``'s top-level package is installed (an optional extra may not be)."""
    return importlib.util.find_spec(name.split(".")[0]) is not None


def project_modules() -> list[str]:
    """Every module of :data:`PROJECT_PACKAGES`, dotted names, sorted."""
    names: list[str] = []
    for package_name in PROJECT_PACKAGES:
        package = importlib.import_module(package_name)
        names.append(package_name)
        for info in pkgutil.walk_packages(package.__path__, prefix=package_name + "."):
            names.append(info.name)
    return sorted(set(names))


def compile_imported_modules() -> int:
    """Import the project's modules and :data:`LAZY_IMPORTS` with bytecode writing on, and
    compile the ``.py`` files at site-packages' top (started by ``.pth`` files at every
    interpreter start); returns how many modules were imported."""
    sys.dont_write_bytecode = False  # this process alone; the environment variable stays
    for site_dir in {sysconfig.get_paths()["purelib"], sysconfig.get_paths()["platlib"]}:
        if Path(site_dir).is_dir():
            compileall.compile_dir(site_dir, maxlevels=0, quiet=1)
    names = [name for name in project_modules()
             # the CommonRoad modules import the optional extra at their top
             if "commonroad" not in name or _installed("commonroad")]
    names += [name for name in LAZY_IMPORTS if _installed(name)]
    for name in names:
        importlib.import_module(name)
    return len(names)


def main(argv: list[str] | None = None) -> int:
    """Compile what the commands import, then warm numba's cache (``make install``); returns the
    exit status (2 with one line for an unknown argument)."""
    args = sys.argv[1:] if argv is None else argv
    unknown = [arg for arg in args if arg not in ("--no-kernels", "--kernels-only")]
    if unknown or len(args) > 1:
        shown = unknown[0] if unknown else " ".join(args)
        print(f"error: pipeline.warm: argument {shown!r} refused; allowed: nothing, "
              "--no-kernels or --kernels-only (one of them)", file=sys.stderr)
        return 2
    done = []
    if "--kernels-only" not in args:
        done.append(f"compiled the bytecode of {compile_imported_modules()} modules and "
                    "their imports")
    if "--no-kernels" not in args:
        sys.dont_write_bytecode = False  # what the kernels' runs import is compiled too
        from pipeline import api

        api.warm_compiled_kernels()
        done.append("put the numba kernels in numba's cache")
    print("pipeline.warm: " + "; ".join(done))
    return 0


if __name__ == "__main__":
    sys.exit(main())
