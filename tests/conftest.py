"""Shared fixtures: compose configs with Hydra's compose API, as the entry point does."""

from __future__ import annotations

from pathlib import Path

import pytest
from hydra import compose, initialize_config_dir

from pipeline.config import ExperimentConfig, register_configs, to_experiment_config

CONF_DIR = Path(__file__).resolve().parent.parent / "conf"


@pytest.fixture(scope="session")
def make_config():
    """Factory: ``make_config(["planner=baseline", ...]) -> ExperimentConfig``."""
    register_configs()

    def _make(overrides: list[str] | None = None) -> ExperimentConfig:
        with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
            cfg = compose(config_name="config", overrides=list(overrides or []))
        return to_experiment_config(cfg)

    return _make
