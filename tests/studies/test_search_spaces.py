"""The search spaces in the project's own schema (``conf/hparams_search/<method>.yaml``, read by
:func:`pipeline.studies.tune.space.search_space`), no longer Hydra's Optuna sweeper's syntax.

Oracle: the distributions hydra-optuna-sweeper's parser made of the old files under Optuna 2.10
(pinned in ``tests/data/pins/search_spaces_optuna2.json`` before the change): every method's
keys, in order, with the same bounds, log scale, step and choices."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from optuna.distributions import CategoricalDistribution, FloatDistribution, IntDistribution

from pipeline.config import CONF_DIR
from pipeline.errors import ConfigError
from pipeline.studies.tune.space import SearchRange, search_ranges, search_space

PINNED = json.loads((Path(__file__).parents[1] / "data" / "pins"
                     / "search_spaces_optuna2.json").read_text())


@pytest.mark.parametrize("method", sorted(PINNED))
def test_each_space_is_the_one_the_sweepers_parser_made(method):
    distributions, texts = search_space(method)
    assert list(distributions) == list(PINNED[method])
    for key, old in PINNED[method].items():
        new = distributions[key]
        if old["type"] == "CategoricalDistribution":
            assert isinstance(new, CategoricalDistribution)
            assert list(new.choices) == old["choices"]
        elif old["type"] == "IntUniformDistribution":
            assert isinstance(new, IntDistribution) and not new.log
            assert (new.low, new.high, new.step) == (old["low"], old["high"], old["step"])
        else:
            assert isinstance(new, FloatDistribution) and new.step is None
            assert (new.low, new.high) == (old["low"], old["high"])
            assert new.log == (old["type"] == "LogUniformDistribution")
        assert texts[key]  # the range in words, with its reason
    # every range of the shipped spaces says why
    assert all(r.why for r in search_ranges(method))


def test_every_space_file_is_pinned():
    assert sorted(p.stem for p in (CONF_DIR / "hparams_search").glob("*.yaml")) \
        == sorted(PINNED)


def test_a_range_in_words():
    assert SearchRange.of("a.b", {"float": [0.05, 2.0], "log": True}, "s").text() \
        == "0.05 to 2, log-uniform"
    assert SearchRange.of("a.n", {"int": [11, 81], "step": 2}, "s").text() \
        == "integers 11 to 81 in steps of 2"
    assert SearchRange.of("a.c", {"choice": ["x", "y"]}, "s").text() == "one of x, y"


@pytest.mark.parametrize("entry, key", [
    ({"float": [1.0, 0.5]}, "s.a.b.float"),          # low above high
    ({"float": [0.0, 1.0], "log": True}, "s.a.b.log"),  # log from 0
    ({"int": [1.5, 3]}, "s.a.b.int"),                # not integers
    ({"int": [1, 10], "step": 4}, "s.a.b.step"),      # 4 does not divide 9
    ({"float": [0.0, 1.0], "step": 2}, "s.a.b.step"),  # a step for floats
    ({"choice": ["x"]}, "s.a.b.choice"),             # one choice
    ({"choice": ["x", "x"]}, "s.a.b.choice"),        # the same twice
    ({"float": [0, 1], "int": [0, 1]}, "s.a.b"),     # two kinds
    ({"why": "no range"}, "s.a.b"),                  # no kind
    ({"float": [0, 1], "prior": "log"}, "s.a.b.prior"),  # unknown key
    ("interval(0.1, 1.0)", "s.a.b"),                 # the sweeper's old syntax
    ({"float": [0, 1], "why": 3}, "s.a.b.why"),
])
def test_a_bad_range_names_its_key(entry, key):
    with pytest.raises(ConfigError) as info:
        SearchRange.of("a.b", entry, "s")
    assert info.value.key == key and len(str(info.value).splitlines()) == 1
