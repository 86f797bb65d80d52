"""The wheel's packages, found rather than listed (a package added under ``pipeline/`` or
``hydra_plugins/`` ships without an edit here); the Hydra configs (``conf/``) and the recorded
tracks (``data/``) ship inside the package as ``pipeline.conf`` and ``pipeline.data`` (their
folders found as namespace packages, mapped in pyproject.toml's ``package-dir``). Everything
else about the package is in pyproject.toml."""

from setuptools import find_namespace_packages, setup

# namespace discovery: hydra_plugins has no __init__.py (Hydra finds its plugins that way)
code = find_namespace_packages(include=["pipeline", "pipeline.*", "hydra_plugins", "hydra_plugins.*"],
                               exclude=["*__pycache__*"])
shipped = [f"pipeline.{top}" + (f".{sub}" if sub else "")
           for top in ("conf", "data")
           for sub in ["", *find_namespace_packages(where=top, exclude=["*__pycache__*"])]]
setup(packages=code + shipped)
