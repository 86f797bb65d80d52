"""The default launcher (``hydra/launcher=sequential``): every job of a multirun composed once,
run with its own overrides, against Hydra's basic launcher composing each twice."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest
import yaml
from hydra._internal.config_loader_impl import ConfigLoaderImpl
from hydra.core.global_hydra import GlobalHydra


def _multirun(tmp_path: Path, monkeypatch, launcher: list[str]) -> tuple[int, list[dict]]:
    """Run ``pipeline.run -m`` in this process over two methods; the number of compositions
    and each job's resolved configuration."""
    import pipeline.run as run

    calls = []
    compose = ConfigLoaderImpl.load_sweep_config

    def counting(self, master_config, sweep_overrides):
        calls.append(tuple(sweep_overrides))
        return compose(self, master_config, sweep_overrides)

    monkeypatch.setattr(ConfigLoaderImpl, "load_sweep_config", counting)
    out = tmp_path / "sweep"
    monkeypatch.setattr(sys, "argv", ["pipeline.run", "-m", "method=baseline,improved",
                                      "scenario.n_steps=3", f"hydra.sweep.dir={out}"]
                        + launcher)
    GlobalHydra.instance().clear()
    try:
        run.hydra_main()
    finally:
        GlobalHydra.instance().clear()
    configs = [yaml.safe_load((folder / "config.yaml").read_text())
               for folder in sorted(p for p in out.iterdir() if (p / "config.yaml").exists())]
    return len(calls), configs


@pytest.mark.parametrize("launcher, compositions", [([], 2), (["hydra/launcher=basic"], 4)])
def test_each_job_is_composed_once_and_runs_its_own_overrides(tmp_path, monkeypatch, launcher,
                                                              compositions):
    count, configs = _multirun(tmp_path, monkeypatch, launcher)
    assert count == compositions
    assert sorted(c["run"]["method"] or c["planner"]["name"] for c in configs) \
        == ["baseline", "improved"]
    assert all(c["scenario"]["n_steps"] == 3 for c in configs)
