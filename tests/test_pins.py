"""Behaviour pinned before the analysis half was reorganised (issue 20): the default config
hash, the bytes of paper-scenario ``metrics.json`` files and of a small family's claims ledger.

A change to any of these numbers is a change of behaviour, never of layout: it must come with a
reason in its commit (and, where ``make verify`` checks it, an updated ``reports/reference/``).
Moved once since: verdicts v3 (issue 21: new metric defaults change the config hash, C3 split
into C3a/C3b, the rate interval, the "mixed" outcome).
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import pytest

from pipeline.report import main as report_main
from pipeline.run import run_experiment, run_family

DEFAULT_CONFIG_HASH = "1c93200c3a4abe3f"
PAPER_METRICS_SHA256 = {
    "improved": "01f27b3f87e3ba4d5dd82e1f7d963d8e0903c6deeec08202e5de7c0460d15260",
    "baseline": "5a794dfcf6fba7251e4130ebbb9e6841ab89a41de6b3216b7c105653bf20d45d",
}
FAMILY_METRICS_SHA256 = "2771267415cb721850c542f8dc5b3643d3a087890b0f3fb6253563bc00fe8719"
LEDGER_SHA256 = "ef2a66a294987fcdc652177e4c75406ddfb4208e49f7a3f843003389d4babe0f"
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
