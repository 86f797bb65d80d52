"""A run's value overrides are set on the sections they touch (issue 41: the tune composes a
config for every trial; a deep copy of the whole typed config was a tenth of its parent's CPU).

Oracle: Hydra's whole path (compose, then the typed schema), for the settings the tune asks of
every method's search space, on both tracks' overrides and the pedestrians' scenes."""

from __future__ import annotations

import types

import numpy as np
import pytest

from pipeline.config import CONF_DIR, to_experiment_config
from pipeline.errors import ConfigError
from pipeline.studies import compose as compose_module
from pipeline.studies.compose import composer
from pipeline.studies.tune.search import _override
from pipeline.studies.tune.space import TRACK_OVERRIDES, search_space


def _hydra_path(overrides: list[str]):
    from hydra import compose, initialize_config_dir

    with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
        return to_experiment_config(compose(config_name="config", overrides=overrides))


def _draw(distributions: dict, rng: np.random.Generator) -> dict:
    """One setting of a search space (Optuna's distributions), as the sampler would give."""
    out = {}
    for name, dist in distributions.items():
        if hasattr(dist, "choices"):
            out[name] = dist.choices[int(rng.integers(len(dist.choices)))]
        else:
            low, high = float(dist.low), float(dist.high)
            value = float(rng.uniform(low, high))
            out[name] = int(round(value)) if type(dist).__name__.startswith("Int") else value
    return out


@pytest.mark.parametrize("method", ["improved", "baseline"])
def test_a_trials_config_is_hydras_whatever_section_its_values_touch(method, monkeypatch):
    make, _ = composer([])
    distributions, _ = search_space(method)
    rng = np.random.default_rng(41)
    cases = []
    for k in range(6):
        params = _draw(distributions, rng)
        base = [f"method={method}", "scenario=family", f"scenario.family.seed={100 + k}",
                "scenario.family.size=40"]
        track = (["controller.backend=daqp", *TRACK_OVERRIDES["lateral"]] if k % 2
                 else list(TRACK_OVERRIDES["kinematic"]))
        cases.append(base + track + [_override(n, v) for n, v in params.items()])
    cases.append([f"method={method}", "scenario=pedestrians",
                  "scenario.pedestrians.scenes=[eth,hotel]", "planner.beta=0.25"])
    for overrides in cases:
        fast = make(overrides)
        reference = _hydra_path(overrides)
        assert fast == reference and fast.config_hash() == reference.config_hash(), overrides
    assert make.fallbacks == []
    # the sections' path itself served them: with the deep copy gone, nothing falls back
    with monkeypatch.context() as patch:
        patch.setattr(compose_module, "copy", types.SimpleNamespace(
            deepcopy=lambda *a, **k: pytest.fail("deep copy of the whole config")))
        for overrides in cases:
            assert make(overrides) == _hydra_path(overrides)
    # a value out of range or a misspelled key: Hydra's whole path, its one line
    with pytest.raises(ConfigError, match="planner.beta"):
        make([f"method={method}", "scenario=family", "planner.beta=-1"])
    with pytest.raises(Exception, match="no_such_key"):
        make([f"method={method}", "scenario=family", "planner.no_such_key=1"])
    assert len(make.fallbacks) == 2


def test_what_a_section_cannot_say_alone_is_still_hydras():
    """Found in review: a value the schema fills from another section when it is null
    (metrics.goal_tolerance_m follows scenario.goal_tolerance_m), a key set both as a section
    and inside it (their order decides), and a value that interpolates (it reads the whole
    config): each gives Hydra's config, or Hydra's error."""
    make, _ = composer([])
    base = ["method=improved", "scenario=family"]
    cases = [["scenario.goal_tolerance_m=0.5000000001"],  # close: the same check passes
             ["scenario.goal_tolerance_m=1.0"],
             ["scenario.goal_tolerance_m=1.0", "metrics.goal_tolerance_m=1.0"],
             ["planner.beta=0.3", "scenario.family.seed=4", "scenario.goal_tolerance_m=0.8"],
             ["scenario.family.seed=5", "scenario.family={seed:7}", "scenario.family.seed=9"],
             ["scenario.family={seed:7}", "scenario.family.seed=9"],
             ["scenario.family.seed=9", "scenario.family={seed:7}"]]
    for extra in cases:
        fast, reference = make(base + extra), _hydra_path(base + extra)
        assert fast == reference and fast.config_hash() == reference.config_hash(), extra
        assert fast.metrics.goal_tolerance_m == fast.scenario.goal_tolerance_m
    assert make.fallbacks == []
    for extra in (["scenario.family.size=${seed}"], ["planner.step_max_m=${step_size}"],
                  ["scenario.goal_tolerance_m=1.0", "metrics.goal_tolerance_m=0.7"]):
        with pytest.raises(Exception) as hydra_error:
            _hydra_path(base + extra)
        with pytest.raises(type(hydra_error.value)):
            make(base + extra)
