"""The plant's braking limit apart from its acceleration limit (``vehicle.brake_max_mps2``, a
choice we add: a passenger car brakes at 8-9 m/s^2 and accelerates at about 3; Appendix A bounds
both at 3): the plant's speed loop and the path frame's speed profile against their closed
forms, and nothing changed without it."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.errors import ConfigError
from pipeline.loop.model import single_track_constants, step_plant


@pytest.mark.parametrize("overrides, decel", [([], 3.0), (["vehicle.brake_max_mps2=8"], 8.0)])
def test_the_plant_brakes_at_its_braking_limit_and_accelerates_at_its_acceleration_limit(
        make_config, overrides, decel):
    """Straight ahead (no steering, no slip) with a target far below the speed: ``vx``
    falls at the braking limit, ``v(t) = v0 - decel t``; far above it rises at 3 m/s^2."""
    vehicle = make_config(overrides).vehicle
    state = np.array([0.0, 0.0, 0.0, 20.0, 0.0, 0.0, 0.0])
    for _ in range(10):  # 1 s
        state = step_plant(state, 0.0, 0.0, vehicle, 0.1, 4)
    assert state[3] == pytest.approx(20.0 - decel, abs=1e-9)
    assert state[0] == pytest.approx(20.0 - decel / 2.0, abs=1e-9)
    state = np.array([0.0, 0.0, 0.0, 5.0, 0.0, 0.0, 0.0])
    for _ in range(10):
        state = step_plant(state, 0.0, 30.0, vehicle, 0.1, 4)
    assert state[3] == pytest.approx(8.0, abs=1e-9)


def test_the_path_frame_predicts_the_speed_falling_at_the_braking_limit():
    """The path frame's stations follow the plant's speed loop: a speed reference of 0 from
    20 m/s on a straight path, each predicted step's speed ``brake ts`` lower."""
    from pipeline.loop.controller.path import frame_step_arrays

    n = 200
    points = [[0.5 * k, 0.0] for k in range(n + 1)]
    headings, curvature = [0.0] * (n + 1), [0.0] * n
    for brake in (3.0, 8.0):
        out = frame_step_arrays(points, headings, curvature, 0.5, n, 0.0, 0.0, 20.0, 0.0,
                                1.0, 0.1, 10, 0.5, 3.0, brake, 5.0, [], [], [])
        vx = np.asarray(out[5])
        assert np.allclose(vx, 20.0 - brake * 0.1 * np.arange(11), atol=1e-12)


def test_without_it_the_constants_and_the_hash_are_as_before(make_config):
    """None brakes at ``accel_max_mps2`` (the same constants, so the same plant bits) and
    hashes as before the key; a value out of range is one line naming the key."""
    cfg = make_config()
    constants = single_track_constants(cfg.vehicle)
    assert constants[12] == constants[9] == cfg.vehicle.accel_max_mps2
    assert make_config(["vehicle.brake_max_mps2=null"]).config_hash() == cfg.config_hash()
    assert make_config(["vehicle.brake_max_mps2=8"]).config_hash() != cfg.config_hash()
    with pytest.raises(ConfigError) as refusal:
        make_config(["vehicle.brake_max_mps2=0"])
    assert "vehicle.brake_max_mps2" in str(refusal.value)
