"""The Python API: the example of docs/own_method.md runs as written, and its results equal the
commands' (oracle: run_experiment's run folder and the report's family ledger on the same members)."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from pipeline import api

ROOT = Path(__file__).resolve().parents[2]


def test_the_documented_api_example_runs(capsys):
    text = (ROOT / "docs" / "own_method.md").read_text()
    block = re.search(r"<!-- api-example -->\s*```python\n(.*?)```", text, re.S).group(1)
    exec(compile(block, "docs/own_method.md (api example)", "exec"), {})
    out = capsys.readouterr().out
    assert "goal_line" in out and "C1" in out and "baseline" in out


def test_api_results_equal_the_run_folders(tmp_path):
    from pipeline.store.runs import read_run
    from pipeline.studies.experiment import run_experiment

    cfg = api.compose(["method=baseline"])
    run = api.simulate(config=cfg)
    run_experiment(cfg, tmp_path / "run")
    record = read_run(tmp_path / "run")
    assert run.metrics.to_json() == record.metrics.to_json()
    assert np.allclose(run.trajectory["Y_m"].to_numpy(), record.trajectory["Y_m"].to_numpy(),
                       atol=1e-9)
    written = api.simulate(config=cfg, out_dir=tmp_path / "again")
    assert (tmp_path / "again" / "manifest.json").is_file()
    assert written.metrics.to_json() == record.metrics.to_json()


def test_api_refuses_what_it_cannot_do():
    from pipeline.errors import ConfigError

    with pytest.raises(ConfigError, match="planner.beta"):
        api.compose(["planner.beta=-1"])
    with pytest.raises(ValueError, match="scenario family"):
        api.simulate(["scenario=family"])
    with pytest.raises(ValueError, match="not both"):
        api.simulate(["method=improved"], config=api.compose([]))


def test_a_checked_configuration_is_read_only_and_replace_checks_again():
    """Frozen after validation: every part refuses assignment (also after pickling, as a
    worker receives it); dataclasses.replace builds a new object and runs the checks again."""
    import dataclasses
    import pickle

    import pytest

    from pipeline import api
    from pipeline.errors import ConfigError

    cfg = api.compose(["method=improved"])
    for target, name, value in ((cfg, "run", None), (cfg.planner, "beta", 0.5),
                                (cfg.scenario, "n_steps", 3),
                                (cfg.scenario.obstacles[0], "radius_m", 2.0),
                                (cfg.claims, "treatment", "x"), (cfg.metrics, "near_field_m", 1.0)):
        with pytest.raises(dataclasses.FrozenInstanceError, match="read-only"):
            setattr(target, name, value)
    copy = pickle.loads(pickle.dumps(cfg))
    assert copy.config_hash() == cfg.config_hash()
    with pytest.raises(dataclasses.FrozenInstanceError):
        copy.planner.beta = 0.5
    changed = dataclasses.replace(cfg, planner=dataclasses.replace(cfg.planner, beta=0.5))
    assert changed.planner.beta == 0.5 and cfg.planner.beta != 0.5
    assert changed.config_hash() == api.compose(["method=improved",
                                                 "planner.beta=0.5"]).config_hash()
    with pytest.raises(ConfigError, match="scenario.n_steps"):
        dataclasses.replace(cfg.scenario, n_steps=0)
