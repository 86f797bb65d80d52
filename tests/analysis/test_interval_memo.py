"""The interval memo: a ledger with remembered bootstrap results is the ledger computed afresh,
bit for bit; what the memo holds is what comes back (a planted entry shows it is read); any
change of the differences, the level, the resamples, a setting or the code is another key; a
damaged, unreadable or other version's memo is computed again; a report built twice into one
folder recalls every interval and writes the same tables."""

from __future__ import annotations

import dataclasses
import json
import logging
import math
import shutil

import numpy as np
import pandas as pd
import pytest

from pipeline.analysis.claims.catalogue import CLAIMS, claims_of
from pipeline.analysis.claims.ledger import family_ledger
from pipeline.analysis.claims.memo import IntervalMemo
from pipeline.analysis.claims.statistics import (
    _estimator,
    bootstrap_interval,
    compare,
    probability_of_improvement,
)
from pipeline.config import ClaimsConfig
from pipeline.store.interval_memo import INTERVAL_MEMO, load_interval_memo, save_interval_memo

CFG = ClaimsConfig(n_resamples=999, n_resamples_refine=1999)
C1 = CLAIMS[0]


def planted_tables(n: int = 60, seed: int = 3) -> dict[str, pd.DataFrame]:
    """Three methods' tables with every claim's metric (noise about planted shifts) and a few
    collisions."""
    rng = np.random.default_rng(seed)
    metrics = {c.primary_metric for c in claims_of(CFG)} - {"collision"}

    def table(shift: float) -> pd.DataFrame:
        data = {"scenario": [f"s{i}" for i in range(n)], "collision": rng.random(n) < 0.1}
        data.update({m: 1.0 + shift + rng.normal(0.0, 0.2, n) for m in sorted(metrics)})
        return pd.DataFrame(data)

    return {"improved": table(-0.05), "baseline": table(0.0), "baseline_matched": table(0.02)}


def same_row(a: dict, b: dict) -> bool:
    """Every value equal, NaN to NaN, and the same type (a recalled int where a float was
    computed would print differently)."""
    return a.keys() == b.keys() and all(
        type(x) is type(y) and (x == y or (isinstance(x, float) and math.isnan(x)
                                           and math.isnan(y)))
        for x, y in zip(a.values(), b.values(), strict=True))


def test_a_ledger_with_the_memo_is_the_ledger_computed_afresh_bit_for_bit():
    tables = planted_tables()
    fresh = family_ledger(tables, CFG)
    memo = IntervalMemo(salt="v1")
    first = family_ledger(tables, CFG, memo=memo)
    assert memo.hits == 0 and memo.misses == len(memo.used) > 20
    again = IntervalMemo(salt="v1", known=json.loads(json.dumps(memo.used)))
    second = family_ledger(tables, CFG, memo=again)
    assert again.misses == 0 and again.hits == len(memo.used)
    assert len(fresh) == len(first) == len(second) == 14
    for a, b, c in zip(fresh, first, second, strict=True):
        assert same_row(a.to_dict(), b.to_dict()) and same_row(a.to_dict(), c.to_dict())


def test_what_the_memo_holds_is_what_comes_back():
    # a planted entry under the key of this very computation is read back: the memo is used
    rng = np.random.default_rng(1)
    improved = pd.DataFrame({"scenario": [f"s{i}" for i in range(40)],
                             C1.primary_metric: rng.normal(0.0, 0.1, 40), "collision": False})
    baseline = improved.assign(**{C1.primary_metric: 0.0})
    d = improved[C1.primary_metric].to_numpy(float)
    memo = IntervalMemo(salt="v1")
    level = 0.95
    memo.known[memo.key("bootstrap_interval", d, CFG, level, CFG.n_resamples)] = \
        [-7.0, 7.0, "planted", 5, 0.0, 0.0]
    memo.known[memo.key("probability_of_improvement", d, CFG, level)] = [0.25, 0.125, 0.375]
    result = compare(improved, baseline, C1, CFG, level=level, memo=memo)
    assert (result.ci_low, result.ci_high, result.interval_method) == (-7.0, 7.0, "planted")
    assert (result.prob_improvement, result.pi_low, result.pi_high) == (0.25, 0.125, 0.375)
    # without the memo the same call computes the bootstrap: another interval
    plain = compare(improved, baseline, C1, CFG, level=level)
    assert plain.interval_method == "BCa" and -1.0 < plain.ci_low < plain.ci_high < 1.0
    interval = bootstrap_interval(d, _estimator(CFG.estimator, d), CFG, level)
    assert (plain.ci_low, plain.ci_high) == (interval.low, interval.high)
    assert (plain.prob_improvement, plain.pi_low, plain.pi_high) == \
        probability_of_improvement(d, CFG, level)


@pytest.mark.parametrize("change", ["sample", "level", "resamples", "seed", "estimator",
                                    "salt", "kind"])
def test_every_input_of_a_result_is_part_of_its_key(change):
    d = np.linspace(-1.0, 1.0, 30)
    memo = IntervalMemo(salt="v1")
    key = memo.key("bootstrap_interval", d, CFG, 0.95, 999)
    other = {
        "sample": lambda: memo.key("bootstrap_interval", d + 1e-15, CFG, 0.95, 999),
        "level": lambda: memo.key("bootstrap_interval", d, CFG, 0.9875, 999),
        "resamples": lambda: memo.key("bootstrap_interval", d, CFG, 0.95, 1999),
        "seed": lambda: memo.key("bootstrap_interval", d, dataclasses.replace(CFG, seed=1),
                                 0.95, 999),
        "estimator": lambda: memo.key("bootstrap_interval", d,
                                      dataclasses.replace(CFG, estimator="median"), 0.95, 999),
        "salt": lambda: IntervalMemo(salt="v2").key("bootstrap_interval", d, CFG, 0.95, 999),
        "kind": lambda: memo.key("probability_of_improvement", d, CFG, 0.95, 999),
    }[change]()
    assert other != key
    assert memo.key("bootstrap_interval", d.copy(), CFG, 0.95, 999) == key


@pytest.mark.parametrize("damaged", [[1.0, 2.0, "BCa", 999, 0.0], [1, 2.0, "BCa", 999, 0.0, 0.0],
                                     [1.0, 2.0, "BCa", 999.0, 0.0, 0.0], "text", None,
                                     [1.0, 2.0, "BCa", True, 0.0, 0.0]])
def test_a_damaged_entry_is_computed_again(damaged):
    tables = planted_tables(n=30)
    pair = tables["improved"].assign(collision=False), tables["baseline"].assign(collision=False)
    d = (pair[0][C1.primary_metric] - pair[1][C1.primary_metric]).to_numpy(float)
    memo = IntervalMemo(salt="v1")
    key = memo.key("bootstrap_interval", d, CFG, 0.95, CFG.n_resamples)
    memo.known[key] = damaged
    result = compare(*pair, C1, CFG, level=0.95, memo=memo)
    plain = compare(*pair, C1, CFG, level=0.95)
    assert (result.ci_low, result.ci_high) == (plain.ci_low, plain.ci_high)
    first = bootstrap_interval(d, _estimator(CFG.estimator, d), CFG, 0.95)
    assert memo.used[key] == [first.low, first.high, first.method, first.n_resamples,
                              first.low_mc, first.high_mc]


def test_the_file_round_trips_every_number_and_refuses_another_code_version(tmp_path, caplog):
    path = tmp_path / INTERVAL_MEMO
    assert load_interval_memo(path).known == {}  # absent: empty
    memo = load_interval_memo(path)
    values = [math.nan, -0.0, "BCa", 9999, 0.1 + 0.2, 1e-300]
    memo.keep("bootstrap_interval:abc", values)
    save_interval_memo(path, memo)
    back = load_interval_memo(path)
    got = back.known["bootstrap_interval:abc"]
    assert math.isnan(got[0]) and math.copysign(1.0, got[1]) == -1.0
    assert got[2:] == values[2:] and [type(v) for v in got] == [type(v) for v in values]
    assert back.salt == memo.salt != ""
    data = json.loads(path.read_text())
    data["code_version"] = "another"
    path.write_text(json.dumps(data))
    assert load_interval_memo(path).known == {}
    path.write_text("{not json")
    with caplog.at_level(logging.WARNING, logger="pipeline.store"):
        assert load_interval_memo(path).known == {}
    assert "unreadable" in caplog.text
    # only what a build used is kept
    used = load_interval_memo(path)
    used.known = {"bootstrap_interval:old": values, "bootstrap_interval:new": values}
    assert used.recall("bootstrap_interval:new") == values
    save_interval_memo(path, used)
    assert set(json.loads(path.read_text())["entries"]) == {"bootstrap_interval:new"}


def test_a_report_built_again_recalls_every_interval_and_writes_the_same_tables(
        small_reproduce, small_report, tmp_path, caplog):
    from pipeline.reporting.page import build_report

    again = tmp_path / "report"
    shutil.copytree(small_report, again)
    kept = json.loads((again / INTERVAL_MEMO).read_text())["entries"]
    assert len(kept) > 10
    with caplog.at_level(logging.INFO, logger="pipeline.reporting"):
        build_report(small_reproduce, again, "pytest", figure_jobs=1)
    assert f"report: {len(kept)} bootstrap results recalled from the last build, 0 computed" \
        in caplog.text
    for table in sorted((small_report / "tables").glob("*.csv")):
        assert (again / "tables" / table.name).read_bytes() == table.read_bytes(), table.name
    assert (again / "answer.txt").read_bytes() == (small_report / "answer.txt").read_bytes()


def test_the_salt_names_the_libraries_that_compute_an_interval_and_a_config_error_pickles():
    """An upgrade of SciPy, NumPy or numba computes the intervals again; a ConfigError raised
    in a forked child (the report's explorer) reaches the parent as itself."""
    import pickle

    import numba
    import scipy

    from pipeline.errors import ConfigError
    from pipeline.store.interval_memo import environment_salt
    from pipeline.store.manifest import code_version

    salt = environment_salt()
    assert salt.startswith(code_version()) and f"scipy {scipy.__version__}" in salt \
        and f"numpy {np.__version__}" in salt and f"numba {numba.__version__}" in salt
    back = pickle.loads(pickle.dumps(ConfigError("claims.seed", -1, "an integer >= 0")))
    assert type(back) is ConfigError and (back.key, back.value) == ("claims.seed", -1)
    assert str(back) == "config error: claims.seed=-1 is invalid; allowed: an integer >= 0"
