"""The MPC's obstacle slots filled nearest first (issue 43: CommonRoad scenarios have more
obstacles than slots; ``Scenario.nearest_first``). Needs no optional extra."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from pipeline.loop.scenario import ObstacleSnapshot, build_scenario
from pipeline.loop.settings import ObstacleConfig
from pipeline.loop.simulate import simulate


def test_nearest_first_orders_every_array_by_distance():
    snap = ObstacleSnapshot(np.array([[10.0, 0.0], [1.0, 1.0], [-3.0, 0.0]]),
                            np.array([[1.0, 0.0], [2.0, 0.0], [3.0, 0.0]]),
                            np.array([0.1, 0.2, 0.3]), np.array([True, False, True]))
    ranked = snap.nearest_first(np.array([0.0, 0.0]))
    assert ranked.positions_m.tolist() == [[1.0, 1.0], [-3.0, 0.0], [10.0, 0.0]]
    assert ranked.velocities_mps[:, 0].tolist() == [2.0, 3.0, 1.0]
    assert ranked.radii_m.tolist() == [0.2, 0.3, 0.1]
    assert ranked.visible.tolist() == [False, True, True]


def test_one_slot_goes_to_the_near_obstacle_only_when_filled_nearest_first(make_config):
    """The MPC with a straight-to-goal reference (its half-planes are what avoids), one slot;
    obstacle 0 is 30 m off the route (never within
    ``controller.constraint_activation_m``), obstacle 1 the paper's crossing one. Filled in
    index order the slot holds the far obstacle: the MPC has no active half-plane, exactly as
    with ``controller.collision_constraints=false``. Filled nearest first it holds the crossing
    obstacle, and the run swerves (by more than 0.5 m) around it."""
    cfg = make_config(["method=mpc_no_apf", "controller.max_obstacles=1"])
    far = ObstacleConfig(x_m=15.0, y_m=30.0, radius_m=0.5, appear_time_s=0.0)
    two = replace(cfg.scenario, obstacles=[far, *cfg.scenario.obstacles])
    by_index = build_scenario(two)
    assert not by_index.nearest_first  # the default, as before
    unconstrained = make_config(["method=mpc_no_apf", "controller.max_obstacles=1",
                                 "controller.collision_constraints=false"])

    def path(config, scenario):
        trajectory = simulate(config, scenario).trajectory
        return trajectory[["X_m", "Y_m"]].to_numpy()

    index_path = path(cfg, by_index)
    assert np.array_equal(index_path, path(unconstrained, by_index))
    nearest_path = path(cfg, replace(by_index, nearest_first=True))
    assert np.max(np.abs(index_path[:, 1])) < 0.1  # straight on, through the obstacle
    assert np.max(np.abs(nearest_path[:, 1])) > 0.5
