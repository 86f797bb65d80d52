"""Entry points as a user runs them: invalid configs exit 2 with one line; the report builds."""

from __future__ import annotations

import subprocess
import sys

import pytest


def run_cli(*args: str, cwd=None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "pipeline.run", *args], capture_output=True,
                          text=True, cwd=cwd, timeout=300)


@pytest.mark.parametrize("override, key", [
    ("controller.horizon=-1", "controller.horizon"),
    ("controller.control_horizon=11", "controller.control_horizon"),
    ("scenario.sample_time_s=0", "scenario.sample_time_s"),
    ("scenario=unknown_scenario", "scenario"),
    ("scenario.obstacles.0.radius_m=nan", "scenario.obstacles[0].radius_m"),
    ("controller.horizon=ten", "controller.horizon"),
])
def test_invalid_config_exits_2_with_one_line(tmp_path, override, key):
    result = run_cli(override, f"hydra.run.dir={tmp_path}")
    assert result.returncode == 2, result.stderr
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1, result.stderr
    assert key in lines[0] and "Traceback" not in result.stderr
    assert not (tmp_path / "metrics.json").exists()
