"""Values checked where they enter (issue 62, item 3): a physical input is bounded by the
schema with its reason, and an angle is wrapped once, in closed form, where it enters the
scenario (a start heading of 1e16 rad once hung every lateral run: the pursuit chase wrapped it
by steps of 2 pi, which never changes such a number)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pipeline.errors import ConfigError


@pytest.mark.parametrize("heading", ["1e16", "-7.0", "inf", "nan"])
def test_a_start_heading_beyond_one_turn_is_refused_naming_the_key_and_range(make_config,
                                                                            heading):
    with pytest.raises(ConfigError) as info:
        make_config([f"scenario.start_heading_rad={heading}"])
    assert info.value.key == "scenario.start_heading_rad"
    if heading in ("1e16", "-7.0"):
        assert "[-6.2832, 6.2832]" in str(info.value) and "rad" in str(info.value)


def test_a_start_heading_one_turn_away_drives_the_same_run(make_config):
    """The oracle is geometry: 2 pi - 0.3 rad and -0.3 rad are one heading, so the runs agree
    to rounding (the scenario holds the wrapped value; without the wrap the path frame would
    see a heading error of a whole turn)."""
    from pipeline.loop.scenario import build_scenario
    from pipeline.loop.simulate import simulate

    paths = {}
    for heading in (-0.3, 2.0 * math.pi - 0.3):
        cfg = make_config(["method=improved", f"scenario.start_heading_rad={heading!r}",
                           "scenario.n_steps=40"])
        scenario = build_scenario(cfg.scenario)
        assert -math.pi <= scenario.start_heading_rad <= math.pi
        paths[heading] = simulate(cfg, scenario).trajectory[["X_m", "Y_m"]].to_numpy()
    first, second = paths.values()
    assert np.abs(first - second).max() < 1e-6
    assert np.abs(np.diff(first[:, 1])).max() > 1e-3  # it turned: not a trivial run
