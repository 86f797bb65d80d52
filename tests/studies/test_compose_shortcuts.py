"""The composer's two shortcuts for a tuning's many compositions (pipeline.studies.compose):
plain value overrides read without Hydra's parser, and a section's plain values set with
``dataclasses.replace`` instead of OmegaConf's typing. Oracles: Hydra's own parser on the same
texts, and the composer with the shortcut switched off on the same runs (the same typed config
and config hash)."""

from __future__ import annotations

import random

import pytest
from hydra.core.override_parser.overrides_parser import OverridesParser

import pipeline.studies.compose as compose
from pipeline.studies.compose import OverrideReader, composer
from pipeline.studies.tune.space import search_ranges

EDGES = ["a.b=1", "a.b=-3", "a.b=+4", "a.b=0", "a.b=-0", "a.b=0.5", "a.b=.5", "a.b=5.",
         "a.b=1e-05", "a.b=1E5", "a.b=0e0", "a.b=-.5e-2", "a.b=-0.25e+3", "a.b=10.25",
         "a.b=1.5e007", "a.b=007", "a.b=00.5", "a.b=05e3", "a.b=1_000", "a.b=constant",
         "a.b=True", "a.b=FALSE", "a.b=null", "a.b=inf", "a.b=NaN", "a.b=_x", "x.y_z=every_step",
         "a.b='quoted'", "a.b=[1,2]", "a.b=1,2", "a.b=${x}", "+a.b=1", "~a.b", "a=1",
         "hydra.job.name=x", "a/b=c", "a.b=", "a.b=x y"]


def test_plain_overrides_read_as_hydras_parser_reads_them():
    rng = random.Random(0)
    texts = EDGES + [f"planner.beta={rng.uniform(-10, 10)!r}" for _ in range(300)] \
        + [f"planner.x={rng.lognormvariate(0, 8)!r}" for _ in range(300)] \
        + [f"k.n={rng.randint(-10**6, 10**6)}" for _ in range(100)]
    hydra = OverridesParser.create()
    read = 0
    for text in texts:
        plain = OverrideReader.plain(text)
        if plain is None:
            continue
        read += 1
        want = hydra.parse_overrides([text])[0]
        assert plain.key_or_group == want.key_or_group, text
        assert plain.value() == want.value() and type(plain.value()) is type(want.value()), text
    # the shortcut reads the numbers and words (what a tuning sets), not the special forms
    assert read >= 700
    assert all(OverrideReader.plain(t) is None for t in
               ("a.b=007", "a.b=00.5", "a.b=True", "a.b=null", "a.b=inf", "a.b=[1,2]",
                "+a.b=1", "a=1", "a.b=1,2", "a.b='quoted'"))
    # and a reader gives the parser's results for everything else (read twice: the second
    # time from what it kept)
    valid = [t for t in EDGES if not t.startswith(("+", "~", "hydra")) and "=" in t
             and t not in ("a.b=1,2", "a.b=${x}", "a.b=NaN")]
    reader = OverrideReader()
    for _ in range(2):
        assert [(p.key_or_group, p.value()) for p in reader.parse(valid)] \
            == [(o.key_or_group, o.value()) for o in hydra.parse_overrides(valid)]


def _setting(ranges, rng: random.Random) -> list[str]:
    out = []
    for r in ranges:
        if r.kind == "choice":
            value = rng.choice(r.choices)
        elif r.kind == "int":
            value = rng.randrange(r.low, r.high + 1, r.step)
        else:
            value = rng.uniform(r.low, r.high)
        out.append(f"{r.key}={value!r}" if isinstance(value, float) else f"{r.key}={value}")
    return out


@pytest.mark.parametrize("method", ["improved", "baseline", "vo", "cbf_filter"])
def test_a_section_set_directly_is_the_section_omegaconf_types(method, monkeypatch):
    """Random settings of the method's search space, composed with the shortcut and without
    it (each by a composer of its own: a composer keeps the sections it typed): the same
    typed config, the same hash; and the shortcut was taken (the planner's values are plain)."""
    rng = random.Random(method)
    fast, _ = composer([])
    taken = []
    real = compose._replaced_section

    def counting(section, items):
        out = real(section, items)
        taken.append(out is not None)
        return out

    settings = [[f"method={method}", "scenario=family", "scenario.family.seed=3",
                 "scenario.family.size=5", *_setting(search_ranges(method), rng)]
                for _ in range(8)]
    monkeypatch.setattr(compose, "_replaced_section", counting)
    with_shortcut = [fast(s) for s in settings]
    monkeypatch.setattr(compose, "_replaced_section", lambda *_: None)
    slow, _ = composer([])
    for cfg, overrides in zip(with_shortcut, settings, strict=True):
        want = slow(overrides)
        assert cfg == want and cfg.config_hash() == want.config_hash()
    assert any(taken) and not fast.fallbacks and not slow.fallbacks
