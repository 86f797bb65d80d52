"""Shared fixtures: compose configs with Hydra's compose API, as the entry point does.

The tests stand in folders by the package's stages (``loop/``, ``analysis/``, ``store/``,
``studies/``, ``reporting/``, ``commands/``) and one tier folder, ``integration/``."""

from __future__ import annotations

import logging
import os
from pathlib import Path

import pytest
from hydra import compose, initialize_config_dir

from pipeline.config import ExperimentConfig, register_configs, to_experiment_config

CONF_DIR = Path(__file__).resolve().parents[1] / "conf"

# tests never share members through a cache of the user's (`make test` sets this too); a test of
# the member cache hands its own MemberCache to the code under test
os.environ["PIPELINE_MEMBER_CACHE"] = "off"

#: Test files with whole runs in them, longest first (their tests' summed times in a `make test`
#: run's junit report on a 2-core machine, 2026-12-06). `make test` hands whole files to its
#: workers (``--dist loadfile``) in collection order (``--no-loadscope-reorder``: xdist's default
#: reorders the files by their number of tests); starting the longest first keeps one worker
#: from running a long file alone at the end. ``make lint`` (test_lint.py) goes first: the
#: other worker starts the longest file meanwhile.
LONGEST_FILES_FIRST = ("test_lint.py", "test_install.py", "test_apf_alone.py",
                       "test_bench_quick.py", "test_tune.py", "test_processes.py", "test_multiverse.py",
                       "test_extensions.py", "test_scenario_sources.py", "test_run_records.py",
                       "test_report_browser.py", "test_tune_pruning.py", "test_sweeps.py",
                       "test_tune_workers.py", "test_peers_report.py", "test_report.py",
                       "test_report_damaged_member.py", "test_tune_peers.py",
                       "test_multiverse_worlds.py", "test_features.py", "test_interrupts.py",
                       "test_settings_travel.py", "test_warm.py", "test_compose_sections.py",
                       "test_engine.py", "test_bad_config.py", "test_tune_store_sources.py")


#: The integration tier (marker ``integration``): the files of ``tests/integration/``, whole
#: studies and the machine around the package (the wheel and make install, the tune, the
#: multiverse, the browser, SLURM, make targets, processes signalled and plug-ins from outside
#: the package). ``make test`` leaves it out, ``make test-integration`` runs it; CI runs both.
#: The folder is the tier: a file moved there is marked, nothing else is.
INTEGRATION_FOLDER = Path(__file__).resolve().parent / "integration"


def pytest_collection_modifyitems(config, items):
    """Longest files first (:data:`LONGEST_FILES_FIRST`); the order within a file is kept.
    The tests under :data:`INTEGRATION_FOLDER` carry the ``integration`` marker."""
    rank = {name: i for i, name in enumerate(LONGEST_FILES_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))
    for item in items:
        if INTEGRATION_FOLDER in Path(item.path).resolve().parents:
            item.add_marker(pytest.mark.integration)


@pytest.fixture(autouse=True)
def _root_log_handlers_restored():
    """The root logger's handlers as they were before each test. A Hydra entry point run in a
    test installs its job logging's stream handlers on the root logger, bound to that test's
    captured stderr; a later test's log record then reached a closed stream and printed
    "--- Logging error ---" with the record's text into that test's stderr."""
    root = logging.getLogger()
    before, level = list(root.handlers), root.level
    yield
    for handler in list(root.handlers):
        # pytest's own capture handlers come and go with its phases: left to pytest
        if handler not in before and not type(handler).__module__.startswith("_pytest"):
            root.removeHandler(handler)
    root.setLevel(level)


@pytest.fixture(scope="session")
def make_config():
    """Factory: ``make_config(["planner=baseline", ...]) -> ExperimentConfig``.

    Hydra's compose costs about 0.15 s, more than a paper-scenario run; the suite asks for the
    same few override lists hundreds of times. Each list is composed once per worker and every
    call gets its own deep copy (a validated config is read-only, and a copy keeps one test's
    list edits, should one make them, away from the next)."""
    import copy

    register_configs()
    composed: dict[tuple[str, ...], ExperimentConfig] = {}

    def _make(overrides: list[str] | None = None) -> ExperimentConfig:
        key = tuple(overrides or ())
        if key not in composed:
            with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
                cfg = compose(config_name="config", overrides=list(key))
            composed[key] = to_experiment_config(cfg)
        return copy.deepcopy(composed[key])

    return _make


def _file_states(root: Path) -> dict[str, tuple[int, int]]:
    """Every file under ``root`` with its size and modification time (ns)."""
    return {str(path.relative_to(root)): (path.stat().st_size, path.stat().st_mtime_ns)
            for path in sorted(root.rglob("*")) if path.is_file()}


@pytest.fixture(scope="session")
def small_reproduce(tmp_path_factory, make_config) -> Path:
    """``make reproduce`` in small, made once per worker: the paper scenario and a 6-member
    family (``scenario=family``) of baseline and improved, in ``<root>/paper/<method>`` and
    ``<root>/family/<method>``; returns ``<root>``.

    Read-only: a test that changes, adds or damages files copies the folder first
    (``shutil.copytree``). The teardown fails the session, naming the files, when any file in it
    changed, so a test cannot hand the next one a changed folder. The report, the tables'
    and the record tests read it (tests/reporting/test_report_reader.py, test_report_methods.py,
    test_report_folders.py, tests/studies/test_run_records.py); a test that needs other
    members (peers, pedestrians, a 30-step run for a clip, a three-member explorer) makes its
    own."""
    from pipeline.studies.experiment import run_experiment, run_family

    root = tmp_path_factory.mktemp("small_reproduce") / "outputs"
    for method in ("baseline", "improved"):
        run_experiment(make_config([f"method={method}"]), root / "paper" / method)
        run_family(make_config([f"method={method}", "scenario=family",
                                "scenario.family.size=6", "scenario.family.n_jobs=1"]),
                   root / "family" / method, progress=False, member_cache=None)
    before = _file_states(root)
    yield root
    after = _file_states(root)
    changed = sorted(name for name in set(before) | set(after)
                     if before.get(name) != after.get(name))
    assert not changed, f"a test changed the shared small_reproduce folder: {changed[:10]}"


@pytest.fixture(scope="session")
def small_report(small_reproduce, tmp_path_factory) -> Path:
    """The report of :func:`small_reproduce` (its folder, with ``index.html``), made once per
    worker; read-only like the runs."""
    from pipeline.reporting.page import build_report

    return build_report(small_reproduce, tmp_path_factory.mktemp("small_report"), "pytest",
                        figure_jobs=1).parent
