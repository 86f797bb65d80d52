"""Model stage against independent oracles: scipy's expm and the plant's own Jacobian."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.linalg import expm

from pipeline.loop.model import build_lateral_model, lateral_matrices, plant_derivative


@pytest.mark.parametrize("speed_mps", [1.5, 3.0, 12.0])
@pytest.mark.parametrize("sample_time_s", [0.05, 0.1])
def test_zoh_discretization_equals_expm_of_augmented_matrix(make_config, speed_mps, sample_time_s):
    vehicle = make_config().vehicle
    model = build_lateral_model(vehicle, speed_mps, sample_time_s)
    B = np.hstack([model.B1, model.B2])
    augmented = np.zeros((7, 7))
    augmented[:5, :5] = model.A
    augmented[:5, 5:] = B
    phi = expm(augmented * sample_time_s)
    np.testing.assert_allclose(model.Ad, phi[:5, :5], rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(model.Bd, phi[:5, 5:6], rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(model.Ed, phi[:5, 6:7], rtol=1e-10, atol=1e-12)


def test_lateral_matrix_entries_follow_design(make_config):
    v = make_config().vehicle
    A, B1, B2 = lateral_matrices(v, 3.0)
    m, iz, a, b = v.mass_kg, v.yaw_inertia_kg_m2, v.cg_to_front_m, v.cg_to_rear_m
    caf, car = v.cornering_stiffness_front_n_per_rad, v.cornering_stiffness_rear_n_per_rad
    assert A[0, 2] == pytest.approx(3.0)
    assert A[1, 1] == pytest.approx(-(caf + car) / (m * 3.0))
    assert A[1, 3] == pytest.approx((b * car - a * caf) / (m * 3.0) - 3.0)
    assert A[3, 3] == pytest.approx(-(a**2 * caf + b**2 * car) / (iz * 3.0))
    assert A[3, 4] == pytest.approx(a * caf / iz)
    assert B1.ravel().tolist() == [0, 0, 0, 0, 1]
    assert B2.ravel().tolist() == [0, 0, -1, 0, 0]
    assert v.cg_to_front_m + v.cg_to_rear_m == pytest.approx(2.5)


def test_plant_linearizes_to_the_lateral_model(make_config):
    """Finite-difference Jacobian of the nonlinear plant about straight driving equals A, B1.

    Plant state [X, Y, psi, vx, vy, r, delta]; lateral state [y, vy, epsi, r, delta] maps to
    plant indices [1, 4, 2, 5, 6] when the reference line is the X axis.
    """
    vehicle = make_config().vehicle
    speed = 3.0
    A, B1, _ = lateral_matrices(vehicle, speed)
    idx = [1, 4, 2, 5, 6]
    base = np.array([0.0, 0.0, 0.0, speed, 0.0, 0.0, 0.0])
    eps = 1e-6
    jac = np.zeros((5, 5))
    for col, i in enumerate(idx):
        up, down = base.copy(), base.copy()
        up[i] += eps
        down[i] -= eps
        jac[:, col] = (plant_derivative(up, 0.0, speed, vehicle)[idx]
                       - plant_derivative(down, 0.0, speed, vehicle)[idx]) / (2 * eps)
    np.testing.assert_allclose(jac, A, rtol=1e-5, atol=1e-6)
    rate = (plant_derivative(base, 1e-3, speed, vehicle) - plant_derivative(base, 0.0, speed,
                                                                            vehicle))[idx] / 1e-3
    np.testing.assert_allclose(rate, B1.ravel(), atol=1e-9)


def test_model_speed_is_floored_not_infinite(make_config):
    vehicle = make_config().vehicle
    model = build_lateral_model(vehicle, 1e-6, 0.1)
    assert model.speed_mps == vehicle.min_model_speed_mps
    assert np.all(np.isfinite(model.Ad))
