"""Behaviour pinned before the analysis half was reorganised (issue 20): the default config
hash, the bytes of paper-scenario ``metrics.json`` files and of a small family's claims ledger.

A change to any of these numbers is a change of behaviour, never of layout: it must come with a
reason in its commit (and, where ``make verify`` checks it, an updated ``reports/reference/``).
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import pytest

from pipeline.report import main as report_main
from pipeline.run import run_experiment, run_family

DEFAULT_CONFIG_HASH = "34dd7bbfed3003fc"
PAPER_METRICS_SHA256 = {
    "improved": "b065a1f95199740f68553be24516c01d26bb18d1b81554db0b51d44ca4447896",
    "baseline": "e4291ddc98266ed261defc8ce4d41bf555272f9b09f61651f7eb44b0f8af34d4",
}
FAMILY_METRICS_SHA256 = "9f31f57c475baf9d23c8e7766b16d941eb502d0e68c874e08c5d05c35811a2f6"
LEDGER_SHA256 = "bb1d4d777b5b2c4178aa127304fc23662c7faa5866227316f8a406963d2da46e"
METHODS = ("improved", "baseline", "baseline_matched")


def _sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def test_default_config_hash_is_pinned(make_config):
    assert make_config([]).config_hash() == DEFAULT_CONFIG_HASH


@pytest.fixture(scope="module")
def pinned_runs(tmp_path_factory, make_config):
    root = tmp_path_factory.mktemp("pins")
    for method in METHODS:
        run_experiment(make_config([f"method={method}"]), root / "paper" / method)
        run_family(make_config([f"method={method}", "scenario=family",
                                "scenario.family.size=12", "scenario.family.n_jobs=1"]),
                   root / "family" / method, progress=False)
    return root


@pytest.mark.parametrize("method", sorted(PAPER_METRICS_SHA256))
def test_paper_metrics_bytes_are_pinned(pinned_runs, method):
    assert _sha(pinned_runs / "paper" / method / "metrics.json") == PAPER_METRICS_SHA256[method]


def test_family_metrics_and_ledger_bytes_are_pinned(pinned_runs, tmp_path):
    assert _sha(pinned_runs / "family" / "improved" / "family_metrics.csv") \
        == FAMILY_METRICS_SHA256
    assert report_main([str(pinned_runs), "--out", str(tmp_path / "report"),
                        "--bench", str(tmp_path / "no_bench")]) == 0
    assert _sha(tmp_path / "report" / "tables" / "claims_ledger.csv") == LEDGER_SHA256
