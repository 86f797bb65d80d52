"""Memory model of compiling the lateral QP, for the horizon's range check."""

from __future__ import annotations

#: Largest MPC horizon the controller settings accept.
MAX_HORIZON = 200


def qp_memory_gib(horizon: float, obstacles: float) -> float:
    """Rough memory of compiling the lateral QP: CVXPY's canonicalization grows with N^2, about
    1.4 kB N^2 (12 GiB at N = 3000, measured order of magnitude)."""
    n = float(horizon)
    return 1440.0 * n * n * (1.0 + float(obstacles) / 30.0) / 2**30

