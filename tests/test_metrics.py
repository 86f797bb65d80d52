"""Metrics against closed forms on synthetic trajectories."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from pipeline.config import MetricsConfig
from pipeline.metrics import (TrajectoryContext, compute_metrics, settling_time, sign_changes)

CTX = TrajectoryContext(start_m=(0.0, 0.0), goal_m=(30.0, 0.0), vehicle_radius_m=1.0)


def synthetic(t, x, y, psi=None, r=None, delta=None, v=3.0, obstacle=None, appear=0.0):
    """A trajectory table with the simulator's columns."""
    n = len(t)
    psi = np.zeros(n) if psi is None else psi
    frame = pd.DataFrame({"time_s": t, "X_m": x, "Y_m": y, "psi_rad": psi,
                          "vx_mps": np.full(n, v), "vy_mps": np.zeros(n),
                          "r_rad_s": np.zeros(n) if r is None else r,
                          "delta_rad": np.zeros(n) if delta is None else delta})
    if obstacle is not None:
        frame["obs0_x_m"], frame["obs0_y_m"] = obstacle[0], obstacle[1]
        frame["obs0_radius_m"] = obstacle[2]
        frame["obs0_visible"] = t >= appear - 1e-9
    return frame


def test_settling_time_of_exponential_decay_matches_closed_form():
    t = np.arange(0.0, 10.0, 0.01)
    tau, e0, band = 0.8, -1.5, 0.1
    expected = tau * math.log(abs(e0) / band)
    assert settling_time(t, e0 * np.exp(-t / tau), band) == pytest.approx(expected, abs=0.011)


def test_settling_time_is_nan_when_never_recovering():
    t = np.arange(0.0, 5.0, 0.1)
    assert math.isnan(settling_time(t, np.full(t.size, 1.0), 0.25))
    assert math.isnan(settling_time(t, np.linspace(0.0, 2.0, t.size), 0.25))
    assert settling_time(t, np.full(t.size, 0.1), 0.25) == 0.0


def test_sign_changes_of_sinusoid():
    t = np.arange(0.0, 10.0, 0.01)
    # sin(pi t) crosses zero at t = 1, ..., 9 inside (0, 10): nine sign changes
    assert sign_changes(np.sin(np.pi * t), 0.05) == 9
    assert sign_changes(0.01 * np.sin(np.pi * t), 0.05) == 0  # all inside the band


def test_constant_curvature_arc_has_zero_jerk_and_curvature_rate():
    v, radius = 3.0, 10.0
    t = np.arange(0.0, 5.0, 0.1)
    theta = v * t / radius
    frame = synthetic(t, radius * np.sin(theta), radius * (1 - np.cos(theta)), psi=theta,
                      r=np.full(t.size, v / radius), v=v)
    m = compute_metrics(frame, CTX, MetricsConfig())
    assert m["lateral_jerk_rms_mps3"] == pytest.approx(0.0, abs=1e-12)
    assert m["curvature_rate_rms_1_per_ms"] == pytest.approx(0.0, abs=1e-12)
    assert m["lateral_accel_max_mps2"] == pytest.approx(v**2 / radius)
    assert m["path_length_m"] == pytest.approx(v * t[-1], rel=1e-3)


def test_reaction_delay_clearance_and_recovery_on_a_scripted_avoidance():
    dt = 0.1
    t = np.arange(0.0, 12.0 + dt / 2, dt)
    x = 3.0 * t
    # steer from t = 3.4 s; lateral detour to -2 m between x = 9 and 21, back by x = 24
    y = -2.0 * np.clip(np.minimum((x - 6.0) / 3.0, (24.0 - x) / 3.0), 0.0, 1.0)
    delta = np.where(t >= 3.4 - 1e-9, 0.05, 0.0)
    psi = np.arctan(np.gradient(y, x))
    frame = synthetic(t, x, y, psi=psi, delta=delta, obstacle=(15.0, 0.0, 0.5), appear=3.0)
    m = compute_metrics(frame, CTX, MetricsConfig())
    assert m["reaction_delay_s"] == pytest.approx(0.4, abs=1e-9)
    # closest approach at y = -2 right beside the obstacle: 2 - 0.5 - 1.0
    assert m["min_clearance_m"] == pytest.approx(0.5, abs=1e-9)
    assert not m["collision"]
    # the obstacle is passed when x - 15 > 1.5, i.e. x = 16.8 at t = 5.6 s
    assert m["obstacle_passed_time_s"] == pytest.approx(5.6, abs=1e-9)
    # lateral error inside 0.25 m once y > -0.25, i.e. x > 23.625 -> t = 7.9 s
    assert m["recovery_lateral_s"] == pytest.approx(7.9 - 5.6, abs=1e-9)
    assert m["max_lateral_deviation_m"] == pytest.approx(2.0)
    assert m["goal_reached"] and m["time_to_goal_s"] == pytest.approx(9.9, abs=1e-9)


def test_collision_flag_and_no_reaction():
    t = np.arange(0.0, 8.0, 0.1)
    frame = synthetic(t, 3.0 * t, np.zeros(t.size), obstacle=(15.0, 0.3, 0.5), appear=2.0)
    m = compute_metrics(frame, CTX, MetricsConfig())
    assert m["collision"] and m["min_clearance_m"] == pytest.approx(0.3 - 1.5, abs=1e-9)
    assert m["reaction_delay_s"] is None and m["reacted"] is False


def test_repulsion_share_closed_form_and_zero_when_never_repelled():
    t = np.arange(0.0, 10.0, 0.1)
    frame = synthetic(t, 3.0 * t, np.full(t.size, -2.0), obstacle=(15.0, 0.0, 0.5), appear=0.0)
    # clearance = hypot(x - 15, 2) - 1.5 > 2 m (far) until |x - 15| < sqrt(3.5^2 - 4)
    frame["apf_rep_norm"] = 1.0
    m = compute_metrics(frame, CTX, MetricsConfig())
    far = np.hypot(3.0 * t - 15.0, 2.0) - 1.5 > 2.0
    assert m["repulsive_impulse_far_share"] == pytest.approx(far.mean())
    assert m["repulsive_impulse"] == pytest.approx(t.size * 0.1)
    frame["apf_rep_norm"] = 0.0
    assert compute_metrics(frame, CTX, MetricsConfig())["repulsive_impulse_far_share"] == 0.0
