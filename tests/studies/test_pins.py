"""Behaviour pinned before the analysis half was reorganised (issue 20): the default config
hash, the paper-scenario ``metrics.json`` values, a small family's member metrics and its claims
ledger.

The values are kept in ``tests/data/pins/`` and compared as ``make verify`` compares (numbers
within rel 1e-6 or abs 1e-6, labels and verdicts exactly): bytes were pinned until they were
seen to differ between two CPUs (an Intel and an AMD machine, last bits of BLAS products), while
every value agreed to 1e-9. ``PIPELINE_UPDATE_PINS=1 pytest tests/studies/test_pins.py`` rewrites them.

A change to any of these numbers is a change of behaviour, never of layout: it must come with a
reason in its commit (and, where ``make verify`` checks it, an updated ``reports/reference/``).
Moved once since: verdicts v3 (issue 21: new metric defaults change the config hash, C3 split
into C3a/C3b, the rate interval, the "mixed" outcome); the condensed lateral QP (issue 22: a
new config key changes the hash; numbers agree with the sparse QP to ~1e-7); the condensed
cost stated through its Cholesky factor (issue 22: the same QP, Clarabel's iterates differ, the
numbers move at the 1e-6 level); the condensed statement in ``W = R U`` coordinates (issue 22:
the same QP without auxiliary variables, Clarabel's iterates differ); the lateral MPC in path
coordinates (issue 38: ``controller.frame=path`` is the new default, new keys change the hash,
every lateral number moves, and the runs carry the model-validity metrics); intervals at
1 - alpha/7 (issue 40: the interval is the test; every interval widens, a row with too few
pairs reports none, no outcome moves); the collision oracle's two-phase manoeuvres (issue 56:
the new key metrics.attribution_switch_samples changes the hash; no pinned number moves); the
APF rollout itself as the lateral MPC's reference (issue 56: controller.path_reference=rollout,
new keys change the hash, every lateral number moves) with the answer's statistics (issue 56:
9,999 resamples and their Monte-Carlo resolution, the worst-rank sensitivity, the answer-wide
Holm gate: new ledger columns); one schema per controller kind (issue 57: a run's controller
section holds its kind's keys only, so every hash changes; no pinned number moves); each step of
the lateral MPC solves the statement of the obstacle slots it uses (issue 58: the same QP
without the empty rows' slacks, Clarabel's iterates differ, fewer of them; the numbers move at
the solver's tolerance).
"""

from __future__ import annotations

import os
from io import StringIO
from pathlib import Path

import pandas as pd
import pytest

from pipeline.report import main as report_main
from pipeline.run import run_experiment, run_family
from pipeline.store.runs import read_run
from pipeline.studies.verify import compare_tables

DEFAULT_CONFIG_HASH = "c3169d33ead55c88"
PINS = Path(__file__).resolve().parents[1] / "data" / "pins"
METHODS = ("improved", "baseline", "baseline_matched")
UPDATE = os.environ.get("PIPELINE_UPDATE_PINS") == "1"


def _check(fresh: pd.DataFrame, name: str, key: tuple[str, ...]) -> None:
    """``fresh`` against the pinned table ``name`` (or written as the new pin when updating)."""
    # through CSV, as the pinned side is read, so both have the same types
    fresh = pd.read_csv(StringIO(fresh.to_csv(index=False, float_format="%.10g")))
    if UPDATE:
        PINS.mkdir(parents=True, exist_ok=True)
        fresh.to_csv(PINS / name, index=False)
    assert compare_tables(fresh, pd.read_csv(PINS / name), name, key) == []


def test_default_config_hash_is_pinned(make_config):
    assert make_config([]).config_hash() == DEFAULT_CONFIG_HASH


def test_a_kept_config_hash_is_the_hash_of_the_settings(make_config):
    """The hash a frozen config keeps (asked many times per tune rung) equals the hash of its
    settings computed again, and a changed config (a new object) has its own."""
    import dataclasses

    from pipeline.config import _hash_of

    cfg = make_config(["scenario=family", "scenario.family.size=7"])
    assert cfg.config_hash() == cfg.config_hash() == _hash_of(cfg.to_dict())
    assert cfg.__dict__.get("_config_hash_memo") == cfg.config_hash()
    changed = dataclasses.replace(cfg, scenario=dataclasses.replace(
        cfg.scenario, family=dataclasses.replace(cfg.scenario.family, size=8)))
    assert changed.config_hash() == _hash_of(changed.to_dict()) != cfg.config_hash()
    assert changed.config_hash() == make_config(["scenario=family",
                                                 "scenario.family.size=8"]).config_hash()


@pytest.fixture(scope="module")
def pinned_runs(tmp_path_factory, make_config):
    root = tmp_path_factory.mktemp("pins")
    for method in METHODS:
        run_experiment(make_config([f"method={method}"]), root / "paper" / method)
        run_family(make_config([f"method={method}", "scenario=family",
                                "scenario.family.size=12", "scenario.family.n_jobs=1"]),
                   root / "family" / method, progress=False)
    return root


@pytest.mark.parametrize("method", ["improved", "baseline"])
def test_paper_metrics_are_pinned(pinned_runs, method):
    metrics = read_run(pinned_runs / "paper" / method, trajectory=False).flat_metrics()
    _check(pd.DataFrame([metrics]), f"paper_metrics_{method}.csv", ("method", "scenario"))


def test_family_metrics_and_ledger_are_pinned(pinned_runs, tmp_path):
    _check(pd.read_csv(pinned_runs / "family" / "improved" / "family_metrics.csv"),
           "family_metrics_improved.csv", ("member", "method"))
    assert report_main([str(pinned_runs), "--out", str(tmp_path / "report"),
                        "--bench", str(tmp_path / "no_bench")]) == 0
    _check(pd.read_csv(tmp_path / "report" / "tables" / "claims_ledger.csv"),
           "claims_ledger.csv", ("claim", "comparison"))
