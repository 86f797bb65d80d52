"""A planner of your own, outside the package: the "side-step" reference.

It aims at the goal, but when a visible obstacle lies within ``params.reach_m`` ahead of the
vehicle it aims at a point ``params.offset_m`` beside that obstacle (on the side the vehicle is
already on), so the MPC gets a reference that swings out and back. It follows the planner
protocol of ``pipeline.loop.planner``: built from its settings, the horizon and the sample
time; ``rollout(...)`` returns the path the MPC tracks (an ``ApfRollout``).

Run it (from the repository root):

    PYTHONPATH=examples/my_planner .venv/bin/python -m pipeline.run \\
        'hydra.searchpath=[file://examples/my_planner/conf]' method=side_step \\
        scenario=family scenario.family.size=10
"""

from __future__ import annotations

import numpy as np

from pipeline.loop.planner import ApfPlanner, ApfRollout


class SideStepPlanner(ApfPlanner):
    """Straight to the goal, or to a point beside the nearest obstacle ahead."""

    def rollout(self, position_m, goal_m, obstacles, vehicle_velocity_mps=None) -> ApfRollout:
        reach = float(self.settings.params.get("reach_m", 8.0))
        offset = float(self.settings.params.get("offset_m", 2.0))
        step = float(self.settings.step_size)
        target = np.asarray(goal_m, float)
        heading = (target - position_m) / max(np.linalg.norm(target - position_m), 1e-9)
        ahead = [(float((o - position_m) @ heading), o, r) for o, r in
                 zip(obstacles.positions_m, obstacles.radii_m, strict=True)]
        ahead = [a for a in ahead if 0.0 < a[0] < reach]
        if ahead:
            _, centre, radius = min(ahead, key=lambda a: a[0])
            side = np.array([-heading[1], heading[0]])
            sign = 1.0 if (position_m - centre) @ side >= 0 else -1.0
            target = centre + sign * (radius + offset) * side
        path = [np.asarray(position_m, float)]
        for _ in range(self.horizon - 1):
            direction = target - path[-1]
            length = np.linalg.norm(direction)
            path.append(path[-1] + (step * direction / length if length > 1e-9 else 0.0))
        steps = self.horizon - 1
        zeros = np.zeros((steps, 2))
        return ApfRollout(np.array(path), zeros, zeros.copy(), np.zeros(steps, bool),
                          np.zeros(steps, bool))
