"""A composed config becomes :class:`ExperimentConfig` by the direct builder when every value
already has its declared type (about 1 ms), else by OmegaConf's structured merge (about 60 ms),
which converts or refuses it: the two give the same object on every method preset, and what the
direct build does not take as it stands still goes OmegaConf's way."""

from __future__ import annotations

import json

import pytest
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf
from omegaconf.errors import MissingMandatoryValue

import pipeline.config as config
from pipeline.config import CONF_DIR, register_configs, to_experiment_config, typed_config
from pipeline.errors import ConfigError

METHODS = sorted(path.stem for path in (CONF_DIR / "method").glob("*.yaml"))
EXTRAS = [["scenario=family"], ["controller=kinematic"], ["scenario=pedestrians"],
          ["scenario=euro_ncap", "controller.backend=daqp"], ["controller=pure_pursuit"]]


def _composed(overrides: list[str]):
    register_configs()
    with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
        return compose(config_name="config", overrides=overrides)


def _through_omegaconf(cfg):
    return OmegaConf.to_object(typed_config(cfg))


def _same(a, b) -> bool:
    # repr shows each value's type (1 against 1.0, "3" against 3); the dump and the hash too
    return repr(a) == repr(b) and a.config_hash() == b.config_hash() \
        and json.dumps(a.to_dict(), sort_keys=True) == json.dumps(b.to_dict(), sort_keys=True)


@pytest.mark.parametrize("overrides", [[f"method={m}"] for m in METHODS]
                         + [["method=improved", *extra] for extra in EXTRAS],
                         ids=lambda o: " ".join(o))
def test_the_direct_build_is_omegaconfs_object(overrides):
    cfg = _composed(overrides)
    data, composed = config._composed_data(cfg)
    direct = config._built_exactly(data, composed)
    assert direct is not None  # every preset as composed takes the direct way
    assert _same(direct, _through_omegaconf(cfg))
    assert _same(to_experiment_config(cfg), direct)


def test_a_value_of_another_type_is_converted_as_omegaconf_converts_it():
    # a plain mapping (no schema composed with it) with an int where a string is declared and
    # an int where a float is: the direct build takes the int as a float (as OmegaConf does), not the
    # string, so the whole config goes OmegaConf's way and the name comes back as text
    plain = OmegaConf.create(OmegaConf.to_container(_composed(["method=improved"])))
    plain.vehicle.name = 3
    plain.planner.beta = 2
    data, composed = config._composed_data(plain)
    assert config._built_exactly(data, composed) is None
    typed = to_experiment_config(plain)
    assert typed.vehicle.name == "3" and typed.planner.beta == 2.0
    assert _same(typed, _through_omegaconf(plain))


def test_a_missing_value_and_another_kinds_schema_are_refused_as_before():
    plain = OmegaConf.create(OmegaConf.to_container(_composed(["method=improved"])))
    plain.vehicle.source = "???"
    with pytest.raises(MissingMandatoryValue):
        to_experiment_config(plain)
    # the lateral MPC's composed schema refuses the kinematic kind, naming its keys
    cfg = _composed(["method=improved", "controller.kind=kinematic_mpc"])
    with pytest.raises(ConfigError) as direct:
        to_experiment_config(cfg)
    with pytest.raises(ConfigError) as before:
        _through_omegaconf(cfg)
    assert str(direct.value) == str(before.value)


def _outcome(route, cfg):
    try:
        typed = route(cfg)
    except Exception as exc:  # the exception is the outcome compared
        return type(exc).__name__, str(exc).splitlines()[0]
    return "ok", repr(typed), typed.config_hash()


@pytest.mark.parametrize("overrides", [
    # the first refusal named is the first bad value, whatever the controller's kind
    ["method=improved", "vehicle.mass_kg=-1", "controller.kind=foo"],
    ["method=improved", "controller.kind=foo"],
    # an interpolation escaped in the composition: OmegaConf's merge resolves it once more
    ["method=improved", "+planner.params.x='\\${planner.name}'"],
    ["method=improved", "run.label='costs \\${nothing}'"],
], ids=["bad value and bad kind", "bad kind", "escaped interpolation", "escaped unknown"])
def test_what_the_direct_build_cannot_say_goes_omegaconfs_way(overrides):
    cfg = _composed(overrides)
    assert _outcome(to_experiment_config, cfg) == _outcome(_through_omegaconf, cfg)


@pytest.mark.parametrize("removed", ["vehicle.source", "scenario.name", "vehicle"])
def test_a_key_or_section_left_out_is_refused_as_before(removed):
    # a config from a plain mapping (a run folder's, say) without a key whose default is
    # OmegaConf's missing value, or without a whole section
    data = OmegaConf.to_container(_composed(["method=improved"]))
    section, _, key = removed.partition(".")
    del_from = data[section] if key else data
    del del_from[key or section]
    plain = OmegaConf.create(data)
    outcome = _outcome(to_experiment_config, plain)
    assert outcome[0] != "ok" and outcome == _outcome(_through_omegaconf, plain)
