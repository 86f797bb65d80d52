"""Walkers that react: each recorded pedestrian follows its own recorded route under Helbing
and Molnar's social force model (Phys. Rev. E 51, 4282, 1995; the exponential repulsion of
Helbing, Farkas and Vicsek, Nature 407, 2000), and avoids the other walkers and the platform.

Per walker ``i`` (unit mass), with position ``x_i`` and velocity ``v_i``::

    dv_i/dt = (v_i^0 - v_i) / tau  +  sum_j A exp((r_ij - d_ij) / B) n_ij

- ``v_i^0``: the velocity that brings the walker to its *recorded* position ``lookahead_s``
  ahead within that time, at most ``max_speed_factor`` times the recorded speed there (at
  least 0.5 m/s, so a walker pushed off a standing track steps back): the walker keeps its
  route and its timing;
- the sum runs over the other present walkers and the platform; ``d_ij`` is the centre
  distance, ``r_ij`` the sum of the two radii, ``n_ij`` the unit vector from ``j`` to ``i``;
  ``A`` (m/s^2) the strength and ``B`` (m) the range.

Integrated with semi-implicit Euler at the scenario's sample time (velocity first, then the
position with the new velocity). A walker exists from its first to its last recorded sample
(:class:`~pipeline.loop.pedestrians.RecordedTrackMotion`'s presence): it enters at its
recorded position and velocity and leaves at its end.

Why not ``pysocialforce``: its simulator gives every agent one fixed goal (ours move with the
recording), steps every agent itself (the platform is driven by the closed loop), and its
import sets the root logger to DEBUG (every run's log then carries numba's compiler trace).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

#: the slowest desired speed (m/s) a displaced walker on a standing track returns with
MIN_RETURN_SPEED_MPS = 0.5


@dataclass(frozen=True)
class SocialForceSettings:
    """The model's parameters (``scenario.pedestrians.social_*``; SI units)."""

    tau_s: float = 0.5
    lookahead_s: float = 2.0
    strength_mps2: float = 2.1
    range_m: float = 0.3
    max_speed_factor: float = 1.3
    walker_radius_m: float = 0.3


def social_accelerations(positions_m: np.ndarray, velocities_mps: np.ndarray,
                         present: np.ndarray, desired_mps: np.ndarray,
                         platform_m: np.ndarray | None, platform_radius_m: float,
                         settings: SocialForceSettings) -> np.ndarray:
    """Every walker's acceleration (n, 2): relaxation to its desired velocity plus the
    exponential repulsion of the other present walkers and of the platform (absent walkers
    get 0 and push no one)."""
    s = settings
    acc = (desired_mps - velocities_mps) / s.tau_s
    idx = np.flatnonzero(present)
    if idx.size > 1:
        rel = positions_m[idx, None, :] - positions_m[None, idx, :]   # i minus j
        dist = np.hypot(rel[..., 0], rel[..., 1])
        np.fill_diagonal(dist, np.inf)
        push = s.strength_mps2 * np.exp((2.0 * s.walker_radius_m - dist) / s.range_m)
        unit = rel / np.where(np.isfinite(dist), np.maximum(dist, 1e-9), 1.0)[..., None]
        acc[idx] += np.sum(np.where(np.isfinite(dist), push, 0.0)[..., None] * unit, axis=1)
    if platform_m is not None and idx.size:
        rel = positions_m[idx] - np.asarray(platform_m, float)[None, :]
        dist = np.maximum(np.hypot(rel[:, 0], rel[:, 1]), 1e-9)
        push = s.strength_mps2 * np.exp(
            (s.walker_radius_m + platform_radius_m - dist) / s.range_m)
        acc[idx] += push[:, None] * rel / dist[:, None]
    acc[~present] = 0.0
    return acc


@dataclass
class SocialForceMotion:
    """Recorded walkers that react (the module docstring), as the scenario's obstacle motion.

    The closed loop tells it where the platform is (:meth:`react`) before it asks where the
    walkers are (:meth:`states_at`) on the same step; times are the scenario's, asked in
    order from 0 (asking for time 0 again starts over, so a scenario can be simulated twice).
    """

    recorded: object  # RecordedTrackMotion (the route each walker follows)
    sample_time_s: float
    settings: SocialForceSettings
    _time_s: float = field(default=0.0, init=False)
    _positions: np.ndarray | None = field(default=None, init=False)
    _velocities: np.ndarray | None = field(default=None, init=False)
    _present: np.ndarray | None = field(default=None, init=False)
    _platform: np.ndarray | None = field(default=None, init=False)
    _platform_radius_m: float = field(default=0.0, init=False)

    def react(self, time_s: float, platform_m: np.ndarray, platform_radius_m: float) -> None:
        """The platform's position (m) and footprint radius (m) at ``time_s``: the walkers
        avoid it from now on."""
        self._platform = np.asarray(platform_m, float).copy()
        self._platform_radius_m = float(platform_radius_m)

    def _start(self) -> None:
        positions, velocities, present = self.recorded.states_at(0.0)  # type: ignore[attr-defined]
        self._time_s = 0.0
        self._positions, self._velocities = positions.copy(), velocities.copy()
        self._present = present.copy()

    def _desired(self, time_s: float) -> np.ndarray:
        """Each walker's desired velocity at ``time_s`` (towards its recorded position
        ``lookahead_s`` ahead, capped)."""
        s = self.settings
        ahead, recorded_v, _ = self.recorded.states_at(  # type: ignore[attr-defined]
            time_s + s.lookahead_s)
        assert self._positions is not None
        want = (ahead - self._positions) / s.lookahead_s
        cap = s.max_speed_factor * np.maximum(np.hypot(recorded_v[:, 0], recorded_v[:, 1]),
                                              MIN_RETURN_SPEED_MPS)
        speed = np.hypot(want[:, 0], want[:, 1])
        scale = np.where(speed > cap, cap / np.maximum(speed, 1e-12), 1.0)
        return want * scale[:, None]

    def _advance(self) -> None:
        """One step of ``sample_time_s`` (semi-implicit Euler)."""
        assert self._positions is not None and self._velocities is not None \
            and self._present is not None
        dt = self.sample_time_s
        acc = social_accelerations(self._positions, self._velocities, self._present,
                                   self._desired(self._time_s), self._platform,
                                   self._platform_radius_m, self.settings)
        self._velocities = self._velocities + dt * acc
        self._positions = self._positions + dt * self._velocities
        self._time_s += dt
        # who is there now: a walker entering starts at its recorded state, one leaving is gone
        positions, velocities, present = self.recorded.states_at(  # type: ignore[attr-defined]
            self._time_s)
        entering = present & ~self._present
        self._positions[entering] = positions[entering]
        self._velocities[entering] = velocities[entering]
        self._present = present
        self._velocities[~present] = 0.0

    def states_at(self, time_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Positions (n, 2), velocities (n, 2) and presence (n,) at ``time_s`` (advanced in
        steps of the sample time from the last time asked; 0 starts over)."""
        if self._positions is None or time_s <= 0.5 * self.sample_time_s \
                or time_s < self._time_s - 1e-9:
            self._start()
        while self._time_s < time_s - 0.5 * self.sample_time_s:
            self._advance()
        assert self._positions is not None and self._velocities is not None \
            and self._present is not None
        return self._positions.copy(), self._velocities.copy(), self._present.copy()
