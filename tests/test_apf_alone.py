"""What each APF does by itself (issue 40, part 4): ``controller.collision_constraints``, the
``apf_alone`` experiment of ``make reproduce`` and its ledger in the report.

The switch is tested against an independent oracle of "no half-planes":
``controller.constraint_activation_m=0`` (no obstacle is ever near enough to be constrained)
gives the same closed loop, bit for bit, on every backend and both tracks; the default gives
another one, in which the straight-to-goal peer ``mpc_no_apf`` (no APF: only the half-planes
can steer it round the obstacle) keeps clear of the obstacle it drives through without them.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pandas as pd
import pytest

from pipeline import api
from pipeline.errors import ConfigError
from pipeline.loop.controller import collision_halfplanes, kinematic_halfplanes

OFF = "controller.collision_constraints=false"
ORACLE = "controller.constraint_activation_m=0"

#: Every way the MPC's half-planes are stated: the lateral QP's backends and formulations, both
#: frames, the lateral NMPC, and Appendix A's kinematic track (LTV-QP and NMPC).
BACKENDS = {
    "clarabel_direct": ["method=mpc_no_apf"],
    "clarabel_dense": ["method=mpc_no_apf", "controller.backend=clarabel_dense"],
    "daqp": ["method=mpc_no_apf", "controller.backend=daqp"],
    "cvxpy": ["method=mpc_no_apf", "controller.backend=cvxpy"],
    "sparse": ["method=mpc_no_apf", "controller.formulation=sparse"],
    "fixed_frame": ["method=mpc_no_apf", "controller.frame=fixed"],
    "lateral_nmpc": ["method=mpc_no_apf", "controller.backend=nmpc"],
    "kinematic": ["experiment=kinematic", "planner=mpc_no_apf"],
    "kinematic_nmpc": ["experiment=kinematic", "planner=mpc_no_apf", "controller.backend=nmpc"],
}


@pytest.mark.parametrize("backend", list(BACKENDS))
def test_switch_off_is_the_closed_loop_without_half_planes(backend):
    overrides = BACKENDS[backend]
    on = api.simulate(overrides)
    off = api.simulate(overrides + [OFF])
    oracle = api.simulate(overrides + [ORACLE])
    assert on.config.controller.collision_constraints is True
    assert off.config.controller.collision_constraints is False
    # off: exactly the loop in which no obstacle is ever constrained
    pd.testing.assert_frame_equal(off.trajectory, oracle.trajectory, check_exact=True)
    assert off.metrics.value("min_clearance_m") == oracle.metrics.value("min_clearance_m")
    # on: the half-planes push the straight-to-goal reference round the obstacle; without
    # them the vehicle drives into it (the paper scenario's obstacle sits on the line)
    clear_on = on.metrics.value("min_clearance_m")
    clear_off = off.metrics.value("min_clearance_m")
    assert clear_off < 0.0, clear_off
    assert clear_on > clear_off + 0.3, (clear_on, clear_off)
    # no slack is ever spent without half-planes (there is nothing to violate)
    assert float(off.trajectory["max_slack_m"].max()) == 0.0


def test_switch_empties_both_tracks_half_plane_rows(make_config):
    """The rows themselves: an obstacle 3 m ahead binds with the switch on (a nonzero gain at
    the stations it covers, the disk's exact width as bound) and gives only empty rows
    ``0 y + s >= 0`` with it off, on the lateral and the kinematic track."""
    lateral = make_config([])
    vehicle = lateral.vehicle
    stations = np.linspace(0.3, 3.0, 10)
    obstacle = np.tile([3.0, 0.1], (10, 1, 1))
    radii = np.array([0.5])
    off_cfg = dataclasses.replace(lateral.controller, collision_constraints=False)
    G, h = collision_halfplanes(stations, np.zeros(10), np.zeros(2), obstacle, radii, vehicle,
                                lateral.controller)
    reach = 0.5 + vehicle.footprint_radius_m + lateral.controller.safety_margin_m
    covered = np.abs(stations - 3.0) < reach
    assert covered.any() and np.all(G[covered, 0] == -1.0)  # the reference passes below
    np.testing.assert_allclose(h[covered, 0],
                               -0.1 + np.sqrt(reach ** 2 - (stations[covered] - 3.0) ** 2))
    G_off, h_off = collision_halfplanes(stations, np.zeros(10), np.zeros(2), obstacle, radii,
                                        vehicle, off_cfg)
    assert not G_off.any() and not h_off.any()

    kin = make_config(["experiment=kinematic", "planner=improved"])
    states = np.zeros((4, 11))
    states[0] = np.linspace(0.0, 3.0, 11)
    reference = np.stack([np.linspace(0.3, 3.0, 10), np.full(10, 0.8)])
    parts = kinematic_halfplanes(states, reference, obstacle, radii, kin.vehicle, kin.controller)
    assert np.abs(parts[1]).max() > 0.5 and parts[2].max() > 0.0
    parts_off = kinematic_halfplanes(states, reference, obstacle, radii, kin.vehicle,
                                     dataclasses.replace(kin.controller,
                                                         collision_constraints=False))
    assert not any(p.any() for p in parts_off)


def test_switch_is_checked_and_enters_the_run_hash(make_config):
    """A word that is not a boolean names the key; off and on never share a run folder's
    hash (the default's is still the one pinned before the key existed: tests/test_pins.py)."""
    cfg = make_config(["method=improved"])
    with pytest.raises(ConfigError, match="controller.collision_constraints"):
        dataclasses.replace(cfg.controller, collision_constraints="no")
    off = make_config(["method=improved", OFF])
    assert off.config_hash() != cfg.config_hash()
