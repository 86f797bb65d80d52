"""The tuning's switch to recorded pedestrians (issue 43, part 4): ``tune.scenario=pedestrians``
trains every replicate on ``training_scenes`` and judges on ``heldout_scenes`` only, the two
disjoint; the scripted family's tuning is unchanged."""

from __future__ import annotations

import pytest

from pipeline.config import CONF_DIR
from pipeline.errors import ConfigError
from pipeline.loop.scenario import family_members
from pipeline.studies.tune.search import Runner
from pipeline.studies.tune.space import load_tune_space

PRESET = CONF_DIR / "tune" / "pedestrians.yaml"


def test_training_and_heldout_families_are_drawn_from_their_own_scenes(tmp_path):
    space = load_tune_space(PRESET, ["training_size=6", "heldout_size=6", "rungs=[3]"])
    assert space.scenario == "pedestrians"
    runner = Runner(space, tmp_path, [], log=lambda *a: None)
    for part, scenes in (("training", space.training_scenes),
                         ("heldout", space.heldout_scenes)):
        cfg = runner.job("improved", "default", {}, part, replicate=0).cfg
        assert cfg.scenario.pedestrians is not None
        assert list(cfg.scenario.pedestrians.scenes) == list(scenes)
        drawn = {m.pedestrians.scene for m in family_members(cfg.scenario)}
        assert drawn and drawn <= set(scenes)
    training = runner.job("improved", "default", {}, "training", replicate=0).cfg.scenario
    heldout = runner.job("improved", "default", {}, "heldout").cfg.scenario
    assert training.family.seed == space.training_seed and heldout.family.seed == \
        space.heldout_seed


def test_the_scripted_tuning_is_unchanged(tmp_path):
    space = load_tune_space(CONF_DIR / "tune" / "quick.yaml")
    assert space.scenario == "family" and space.scenario_overrides("training") == \
        ["scenario=family"]
    cfg = Runner(space, tmp_path, [], log=lambda *a: None).job(
        "improved", "default", {}, "training", replicate=0).cfg
    assert cfg.scenario.pedestrians is None and cfg.scenario.name == "family"


@pytest.mark.parametrize("change, key", [
    ("heldout_scenes=[crowds_zara01]", "tune.heldout_scenes"),
    ("training_scenes=[]", "tune.training_scenes"),
    ("scenario=crowds", "tune.scenario"),
])
def test_bad_scene_settings_name_the_key(change, key):
    with pytest.raises(ConfigError) as caught:
        load_tune_space(PRESET, [change])
    assert key in str(caught.value)
    with pytest.raises(ConfigError, match="tune.training_scenes"):
        load_tune_space(CONF_DIR / "tune" / "quick.yaml", ["training_scenes=[biwi_hotel]"])
