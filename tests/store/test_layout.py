"""The package reads in data-flow order: no module imports from a stage after it, there is no
import circle, the analysis half has short functions, and only the store opens run folders."""

from __future__ import annotations

import ast
import functools
import subprocess
import sys
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[2] / "pipeline"

#: Stage order (lower first). Studies compute and return typed results; the commands (the
#: last layer) draw their figures; the report reads the results (``pipeline.studies.results``).
LAYERS = (
    ("pipeline", "pipeline.errors", "pipeline.validation", "pipeline.numerics",
     "pipeline.conf_dir"),
    ("pipeline.loop",),
    ("pipeline.peers",),
    ("pipeline.analysis",),
    ("pipeline.config", "pipeline.register", "pipeline.methods"),
    ("pipeline.store",),
    ("pipeline.studies",),
    ("pipeline.reporting",),
    ("pipeline.run", "pipeline.report", "pipeline.aggregate", "pipeline.multiverse",
     "pipeline.tune", "pipeline.api", "pipeline.nmpc_check", "pipeline.speed_check",
     "pipeline.commands", "pipeline.screenshot", "pipeline.verify", "pipeline.cli",
     "pipeline.score", "pipeline.cache", "pipeline.commonroad", "pipeline.clip",
     "pipeline.euro_ncap"),
)
#: Files a run or family folder holds (its layout belongs to the store).
RUN_FOLDER_FILES = ("config.yaml", "model.json", "trajectory.csv", "timing.json", "horizon.npz",
                    "metrics.json", "family_metrics.csv", "family.json", "manifest.json")
#: Each study's files and the module that owns them (its typed result): nobody else names them.
STUDY_FILES = {
    "pipeline.studies.results.multiverse": ("design.csv", "specifications.csv",
                                            "robustness.csv", "dimensions.csv", "space.json"),
    "pipeline.studies.results.tune": ("trials.csv", "heldout.csv", "ledger_default.csv",
                                      "ledger_tuned.csv", "settings_outcomes.csv"),
    "pipeline.studies.results.bench": ("bench.csv", "bench_summary.json"),
    "pipeline.studies.results.speed": ("speed.csv",),
    "pipeline.studies.results.nmpc_check": ("agreement.csv",),
    "pipeline.studies.results.sweep": ("summary.csv", "swept_keys.json", "verdicts.csv",
                                       "skipped.csv"),
    "pipeline.studies.results.commonroad": ("commonroad.json", "solution.xml"),
    "pipeline.studies.results.euro_ncap": ("euro_ncap.csv",),
}
#: The outputs root's sections: only the layout (``pipeline.store.layout``) joins them to a
#: path.
SECTIONS = ("paper", "kinematic", "kinematic_readings", "family", "kinematic_family", "frames",
            "apf_alone", "peers", "kinematic_peers", "pedestrians", "ablation", "interpretations", "multiverse",
            "tune", "tune_peers", "nmpc_check", "speed", "sweeps")


def module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def layer(name: str) -> int:
    best, rank = -1, -1
    for i, group in enumerate(LAYERS):
        for prefix in group:
            if (name == prefix or name.startswith(prefix + ".")) and len(prefix) > best:
                best, rank = len(prefix), i
    return rank


def modules() -> dict[str, ast.Module]:
    """Every module of the package, parsed (once per test process: about 0.9 s each time, and
    some thirty tests ask; the trees are only read)."""
    return dict(_parsed_modules())


@functools.lru_cache(maxsize=1)
def _parsed_modules() -> dict[str, ast.Module]:
    return {module_name(p): ast.parse(p.read_text(), str(p)) for p in PACKAGE.rglob("*.py")}


def imports(tree: ast.AST, known: set[str] | frozenset[str] = frozenset()) -> set[str]:
    """Every pipeline module ``tree`` imports, lazy (function-local) imports included; with
    ``known``, ``from pipeline.loop import model`` names the module ``pipeline.loop.model``
    too."""
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("pipeline"):
            found.add(node.module)
            found.update(f"{node.module}.{a.name}" for a in node.names
                         if f"{node.module}.{a.name}" in known)
        elif isinstance(node, ast.Import):
            found.update(a.name for a in node.names if a.name.startswith("pipeline"))
    return found


def test_every_module_has_a_stage():
    assert [name for name in modules() if layer(name) < 0] == []


def test_no_module_imports_from_a_stage_after_it():
    backwards = [f"{name} -> {target}" for name, tree in modules().items()
                 for target in imports(tree) if layer(target) > layer(name)]
    assert backwards == []


#: What the drawing library may read of the pipeline: the method registry (each method's
#: colour is its preset's, a config-stage table; the figures read nothing else).
DRAWING_READS = ("pipeline.methods",)


def test_the_drawing_library_imports_nothing_of_the_pipeline():
    found = {name: tree for name, tree in modules().items()
             if name.startswith("pipeline.reporting.figures")}
    assert len(found) > 1
    outside = {f"{name} -> {target}" for name, tree in found.items() for target in imports(tree)
               if not target.startswith("pipeline.reporting.figures")
               and target not in DRAWING_READS}
    assert outside == set()


def test_studies_never_import_the_report_and_the_report_reads_only_their_results():
    """Studies compute; they never draw (the commands do) nor import the report; the report
    reads a study only through its typed result (``pipeline.studies.results``)."""
    found = modules()
    into_reporting = [f"{name} -> {target}" for name, tree in found.items()
                      if name.startswith("pipeline.studies")
                      for target in imports(tree) if target.startswith("pipeline.reporting")]
    into_studies = [f"{name} -> {target}" for name, tree in found.items()
                    if name.startswith("pipeline.reporting")
                    for target in imports(tree, set(found))
                    if target.startswith("pipeline.studies")
                    and not target.startswith("pipeline.studies.results")]
    assert into_reporting == [] and into_studies == []


def test_only_a_studys_result_names_its_files_and_only_the_layout_its_sections():
    offenders = []
    owner_of = {f: owner for owner, files in STUDY_FILES.items() for f in files}
    for name, tree in modules().items():
        for node in ast.walk(tree):
            if isinstance(node, ast.Constant) and node.value in owner_of \
                    and name != owner_of[node.value]:
                offenders.append(f"{name}:{node.lineno}: {node.value}")
            # ``root / "multiverse"``: a section's folder joined by anyone but the layout (the
            # config folder's own groups, ``CONF_DIR / "multiverse"``, are not outputs)
            if isinstance(node, ast.BinOp) and isinstance(node.op, ast.Div) \
                    and isinstance(node.right, ast.Constant) and node.right.value in SECTIONS \
                    and not (isinstance(node.left, ast.Name) and node.left.id == "CONF_DIR") \
                    and name != "pipeline.store.layout":
                offenders.append(f"{name}:{node.lineno}: / {node.right.value!r}")
    assert offenders == []


def test_no_import_circle_between_modules():
    """No circle, lazy imports included (a function-local import only hides one)."""
    found = modules()
    graph = {name: {t for t in imports(tree, set(found)) if t != name}
             for name, tree in found.items()}
    state: dict[str, int] = {}
    cycles = []

    def visit(node, path):
        state[node] = 1
        for nxt in graph.get(node, ()):
            if nxt not in graph:
                continue
            if state.get(nxt) == 1:
                cycles.append(path[path.index(nxt):] + [nxt] if nxt in path else [node, nxt])
            elif state.get(nxt) is None:
                visit(nxt, path + [nxt])
        state[node] = 2

    for name in graph:
        if state.get(name) is None:
            visit(name, [name])
    # a package's __init__ re-exporting its own modules is not a circle
    cycles = [c for c in cycles if not all(n.startswith(c[0].rsplit(".", 1)[0]) for n in c)
              or len({n.split(".")[1] if "." in n else n for n in c}) > 1]
    assert cycles == []


@pytest.mark.parametrize("name", sorted(n for n in modules() if n.startswith("pipeline.analysis")))
def test_analysis_functions_are_short(name):
    tree = modules()[name]
    long = [f"{node.name}: {node.end_lineno - node.lineno + 1} lines"
            for node in ast.walk(tree) if isinstance(node, (ast.FunctionDef,
                                                            ast.AsyncFunctionDef))
            and node.end_lineno - node.lineno + 1 > 80]
    assert long == []


def test_only_the_store_names_run_folder_files():
    offenders = []
    for name, tree in modules().items():
        if layer(name) == layer("pipeline.store"):
            continue
        for node in ast.walk(tree):
            if isinstance(node, ast.Constant) and node.value in RUN_FOLDER_FILES:
                offenders.append(f"{name}:{node.lineno}: {node.value}")
    assert offenders == []


def test_the_package_is_a_regular_package():
    out = subprocess.run([sys.executable, "-c", "import pipeline; print(pipeline.__file__)"],
                         capture_output=True, text=True, check=True).stdout.strip()
    assert out.endswith(str(Path("pipeline") / "__init__.py"))


def test_the_makefile_writes_where_the_layout_reads(tmp_path):
    """Every ``$(RUNS)/<section>`` the Makefile writes is a section of ``conf/paths`` (the one
    layout the report and the checks read), ``make reproduce``'s included; a renamed section in
    ``conf/paths`` is what the readers then look for, and a bad one is a one-line error."""
    import re

    from pipeline.errors import ConfigError
    from pipeline.store.layout import OutputsLayout

    layout = OutputsLayout.load(tmp_path)
    names = {getattr(layout, s) for s in layout.sections}
    makefile = (PACKAGE.parent / "Makefile").read_text()
    written = set(re.findall(r"\$\(RUNS\)/([a-z_]+)", makefile))
    assert written <= names, written - names
    assert {"paper", "kinematic", "kinematic_readings", "family", "kinematic_family",
            "frames", "apf_alone", "peers", "kinematic_peers", "ablation", "interpretations",
            "multiverse", "tune", "tune_peers", "nmpc_check", "speed", "sweeps"} <= written
    renamed = tmp_path / "paths.yaml"
    renamed.write_text("multiverse: robustness_study\n")
    moved = OutputsLayout.load(tmp_path, renamed)
    assert moved.folder("multiverse") == tmp_path / "robustness_study"
    assert moved.folder("tune") == tmp_path / "tune"
    assert "robustness_study" in moved.not_main_runs
    for bad in ("multiverse: ../x\n", "multiverse: a/b\n", "nonsense: x\n"):
        renamed.write_text(bad)
        with pytest.raises(ConfigError):
            OutputsLayout.load(tmp_path, renamed)
