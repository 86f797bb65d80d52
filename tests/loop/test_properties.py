"""Property-based tests (hypothesis) of the APF and the metrics."""

from __future__ import annotations

import dataclasses

import numpy as np
import pandas as pd
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from pipeline.analysis.metrics.criteria import compute_metrics
from pipeline.analysis.metrics.geometry import clearance_series
from pipeline.analysis.metrics.signals import TrajectoryContext
from pipeline.config import MetricsConfig, PlannerConfig
from pipeline.loop.planner import apf_step, repulsive_force


def metrics_json(*args):
    """The flat ``metrics.json`` mapping of :func:`compute_metrics`."""
    return compute_metrics(*args).to_json()

coordinate = st.floats(min_value=-1e3, max_value=1e3, allow_nan=False, allow_infinity=False)
point = st.tuples(coordinate, coordinate).map(np.array)
BASELINE = PlannerConfig(name="baseline")
IMPROVED = dataclasses.replace(BASELINE, name="improved", step_size=0.2, normalize_step=False,
                               beta=0.25, repulsion_law="exponential", step_min_m=0.05,
                               step_max_m=0.5)
SETTINGS = settings(max_examples=200, deadline=None,
                    suppress_health_check=[HealthCheck.function_scoped_fixture])


@SETTINGS
@given(p=point, goal=point, obstacles=st.lists(point, min_size=0, max_size=4),
       improved=st.booleans())


def test_apf_step_is_finite_for_any_finite_positions(p, goal, obstacles, improved):
    params = IMPROVED if improved else BASELINE
    nxt, att, rep, *_ = apf_step(p, goal, np.array(obstacles).reshape(-1, 2), params)
    assert np.all(np.isfinite(nxt)) and np.all(np.isfinite(rep))
    if improved:
        assert np.linalg.norm(nxt - p) <= params.step_max_m + 1e-9
    elif np.linalg.norm(att + rep) > 1e-9:
        assert np.isclose(np.linalg.norm(nxt - p), params.step_size)


@SETTINGS
@given(p=point, o=point, improved=st.booleans())
def test_repulsion_points_away_and_vanishes_beyond_range(p, o, improved):
    params = IMPROVED if improved else BASELINE
    force = repulsive_force(p, np.array([30.0, 0.0]), o[None, :], params)
    distance = np.linalg.norm(p - o)
    if distance >= params.rho0_m:
        assert np.all(force == 0.0)
    elif distance > 1e-9:
        assert force @ (p - o) >= 0.0
        # parallel to p - o: the cross product vanishes (relative to the magnitudes)
        cross = force[0] * (p - o)[1] - force[1] * (p - o)[0]
        assert abs(cross) <= 1e-9 * max(1.0, np.linalg.norm(force) * distance)


def scripted(offset_y: float, bump: float, obstacle_y: float, start: float) -> pd.DataFrame:
    t = np.round(start + np.arange(0.0, 11.0, 0.1), 10)
    x = 2.9 * (t - start)  # 2.9 m/s: no sample lands exactly on a threshold
    y = offset_y + bump * np.exp(-((x - 15.0) / 3.0) ** 2)
    psi = np.arctan(np.gradient(y, x))
    return pd.DataFrame({
        "time_s": t, "X_m": x, "Y_m": y, "psi_rad": psi, "vx_mps": 2.9, "vy_mps": 0.0,
        "r_rad_s": np.gradient(psi, t), "delta_rad": np.gradient(psi, t) * 2.5 / 2.9,
        "obs0_x_m": 15.0, "obs0_y_m": obstacle_y, "obs0_radius_m": 0.5,
        "obs0_visible": t >= start + 3.0 - 1e-9, "apf_rep_norm": np.maximum(0, 3 - np.abs(x - 13)),
    })


CTX = TrajectoryContext((0.0, 0.0), (30.0, 0.0), 1.0)
TIME_KEYS = {"obstacle_appear_time_s", "obstacle_passed_time_s", "threat_appear_time_s",
             "smoothness_window_start_s", "smoothness_window_end_s"}


@SETTINGS
@given(bump=st.floats(-3.0, 3.0), obstacle_y=st.floats(-3.0, 3.0),
       shift=st.floats(-100.0, 100.0))
def test_metrics_invariant_to_time_origin_and_mirroring(bump, obstacle_y, shift):
    # an obstacle exactly tangent to the straight path's threat corridor (|y| = both radii +
    # threat margin = 2 m) sits on a knife edge that rounding may tip either way
    assume(abs(abs(obstacle_y) - 2.0) > 1e-6)
    base = metrics_json(scripted(0.0, bump, obstacle_y, 0.0), CTX, MetricsConfig())
    shifted = metrics_json(scripted(0.0, bump, obstacle_y, round(shift, 1)), CTX,
                              MetricsConfig())
    mirrored_frame = scripted(0.0, bump, obstacle_y, 0.0)
    for column in ("Y_m", "psi_rad", "r_rad_s", "delta_rad", "obs0_y_m"):
        mirrored_frame[column] = -mirrored_frame[column]
    mirrored = metrics_json(mirrored_frame, CTX, MetricsConfig())
    for key, value in base.items():
        other = shifted[key]
        if key in TIME_KEYS and value is not None:
            assert np.isclose(other, value + round(shift, 1), atol=1e-6), key
        elif isinstance(value, float):
            assert np.isclose(other, value, rtol=1e-6, atol=1e-6), key
            assert np.isclose(mirrored[key], value, rtol=1e-6, atol=1e-6), key
        else:
            assert other == value and mirrored[key] == value, key


@SETTINGS
@given(points=st.lists(point, min_size=2, max_size=30), o=point,
       radius=st.floats(0.0, 5.0), vehicle=st.floats(0.0, 3.0))
def test_clearance_never_exceeds_true_distance(points, o, radius, vehicle):
    xy = np.array(points)
    frame = pd.DataFrame({"X_m": xy[:, 0], "Y_m": xy[:, 1], "obs0_x_m": o[0], "obs0_y_m": o[1],
                          "obs0_radius_m": radius, "obs0_visible": True})
    clearance = clearance_series(frame, vehicle)
    assert np.all(clearance <= np.linalg.norm(xy - o, axis=1) + 1e-9)
    assert np.allclose(clearance, np.linalg.norm(xy - o, axis=1) - radius - vehicle)
