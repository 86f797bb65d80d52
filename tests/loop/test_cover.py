"""True shapes as discs (issue 60, item 1): a rectangle covered by n equal discs contains it and
has the smallest radius such a cover can have (closed form); the ego as several discs reaches the
lateral MPC's half-planes (against a brute force over the ego's discs) and the metrics'
distances (against the distance from each disc); a car parked in the next lane does not touch a
car in its own lane (the drivability checker on the true rectangles as oracle), where the
earlier one-disc reading said it did."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from pipeline.analysis.metrics.geometry import clearance_series, ego_disc_view
from pipeline.loop.controller.references import collision_halfplanes
from pipeline.loop.cover import cover_centres, footprint_offsets_m, rectangle_cover

CAR = (4.5, 1.8)


def _boundary_and_interior(length: float, width: float, n: int = 400) -> np.ndarray:
    """Points on the rectangle's edges and a grid inside it (centred, long side along x)."""
    t = np.linspace(-0.5, 0.5, n)
    edges = np.concatenate([np.stack([t * length, np.full(n, width / 2)], 1),
                            np.stack([t * length, np.full(n, -width / 2)], 1),
                            np.stack([np.full(n, length / 2), t * width], 1),
                            np.stack([np.full(n, -length / 2), t * width], 1)])
    gx, gy = np.meshgrid(np.linspace(-0.5, 0.5, 41) * length, np.linspace(-0.5, 0.5, 21) * width)
    return np.concatenate([edges, np.stack([gx.ravel(), gy.ravel()], 1)])


@pytest.mark.parametrize("length, width", [CAR, (0.6, 0.5), (12.0, 2.5), (1.0, 1.0),
                                           (1.8, 4.5)])
@pytest.mark.parametrize("n", [1, 2, 3, 5])
def test_the_cover_contains_the_rectangle_with_the_least_radius_on_its_axis(length, width, n):
    """Contains: every point of the rectangle lies in some disc. Least: a cover by n equal
    discs centred on the long axis covers at most 2 sqrt(r^2 - (w/2)^2) of each long edge per
    disc, so r >= sqrt((l / 2n)^2 + (w / 2)^2) (l, w the long and short sides); the cover's
    radius is that bound (for n = 1 the half-diagonal, the smallest disc holding it)."""
    centres, radius = cover_centres(length, width, n)
    points = _boundary_and_interior(length, width)
    distance = np.min(np.linalg.norm(points[:, None, :] - centres[None], axis=2), axis=1)
    assert distance.max() <= radius + 1e-12
    long_side, short_side = max(length, width), min(length, width)
    assert radius == pytest.approx(math.sqrt((long_side / (2 * n)) ** 2 + (short_side / 2) ** 2),
                                   rel=1e-12)
    if n == 1:
        assert radius == pytest.approx(math.hypot(length, width) / 2, rel=1e-12)
    # any smaller radius leaves a slice's corner out (the corner at the first disc's edge)
    smaller = radius * (1 - 1e-6)
    assert distance.max() > smaller


def test_the_ego_offsets_span_the_cover_of_its_rectangle():
    offsets, radius = rectangle_cover(*CAR, 3)
    assert offsets.tolist() == pytest.approx([-1.5, 0.0, 1.5])
    assert footprint_offsets_m(3, 3.0).tolist() == pytest.approx(offsets.tolist())
    assert footprint_offsets_m(1, 0.0).tolist() == [0.0]
    assert radius == pytest.approx(math.hypot(0.75, 0.9))


def test_the_half_planes_keep_every_ego_disc_out(make_config):
    """lateral_side half-planes about an ego of three discs: at every station the keep-out
    width is that of the ego disc nearest to the obstacle along the path,
    sqrt(R^2 - min_i (x_k + c_i - o_x)^2) (brute force over the discs), and one disc gives
    the one-disc planes."""
    from dataclasses import replace

    cfg = make_config(["controller.max_obstacles=2"])
    one = cfg.vehicle
    three = replace(one, footprint_radius_m=1.17, footprint_discs=3, footprint_span_m=3.0)
    stations = np.linspace(0.0, 18.0, 10)
    obstacle = np.stack([np.full(10, 9.0), np.full(10, 1.0)], 1)[:, None, :]   # (N, 1, 2)
    y_ref = np.full(10, -2.0)   # the APF passes below: sigma = -1
    G, h = collision_halfplanes(stations, y_ref, np.array([0.0, -2.0]), obstacle,
                                np.array([1.0]), three, cfg.controller)
    reach = 1.0 + 1.17 + cfg.controller.safety_margin_m
    offsets = np.array([-1.5, 0.0, 1.5])
    for k, x in enumerate(stations):
        dx = np.min(np.abs(x + offsets - 9.0))
        if dx < reach:
            assert G[k, 0] == -1.0
            assert h[k, 0] == pytest.approx(-1.0 + math.sqrt(reach ** 2 - dx ** 2), abs=1e-12)
        else:
            assert G[k, 0] == 0.0 and h[k, 0] == 0.0
    # the stations where only an end disc is within reach have planes the one disc lacks
    G1, h1 = collision_halfplanes(stations, y_ref, np.array([0.0, -2.0]), obstacle,
                                  np.array([1.0]), replace(one, footprint_radius_m=1.17),
                                  cfg.controller)
    assert np.count_nonzero(G[:, 0]) > np.count_nonzero(G1[:, 0])
    assert np.all(h[:, 0] >= h1[:, 0] - 1e-12)


def _table(poses: list[tuple[float, float, float]], obstacles: list[tuple[float, float, float]]
           ) -> pd.DataFrame:
    """A logged table: the ego's poses and fixed obstacle discs (x, y, radius), all visible."""
    data: dict[str, list] = {"time_s": [0.1 * k for k in range(len(poses))],
                             "X_m": [p[0] for p in poses], "Y_m": [p[1] for p in poses],
                             "psi_rad": [p[2] for p in poses]}
    for j, (x, y, r) in enumerate(obstacles):
        data[f"obs{j}_x_m"], data[f"obs{j}_y_m"] = [x] * len(poses), [y] * len(poses)
        data[f"obs{j}_radius_m"], data[f"obs{j}_visible"] = [r] * len(poses), [True] * len(poses)
    return pd.DataFrame(data)


def test_the_metrics_measure_from_the_nearest_ego_disc():
    """Clearance of an ego of three discs: min over discs and obstacles of
    |p + c h - o| - r_o - r_e (brute force), headings included; one disc: the table itself."""
    rng = np.random.default_rng(3)
    poses = [(float(x), float(y), float(a)) for x, y, a in
             zip(rng.uniform(-5, 5, 30), rng.uniform(-3, 3, 30), rng.uniform(-3, 3, 30),
                 strict=True)]
    obstacles = [(1.0, 2.0, 0.5), (-2.0, -1.0, 1.2)]
    table = _table(poses, obstacles)
    offsets = (-1.5, 0.0, 1.5)
    got = clearance_series(ego_disc_view(table, offsets), 1.17)
    for k, (x, y, a) in enumerate(poses):
        discs = [(x + c * math.cos(a), y + c * math.sin(a)) for c in offsets]
        want = min(math.hypot(dx - ox, dy - oy) - r - 1.17 for dx, dy in discs
                   for ox, oy, r in obstacles)
        assert got[k] == pytest.approx(want, abs=1e-12)
    assert ego_disc_view(table, (0.0,)) is table
    # the positions stay as logged: a static obstacle passed by the ego keeps zero velocity
    view = ego_disc_view(table, offsets)
    for column in ("obs0_x_m", "obs0_y_m", "obs1_x_m", "obs1_y_m"):
        assert view[column].tolist() == table[column].tolist()


def test_an_obstacle_passed_by_a_long_ego_keeps_its_velocity():
    """The ego at 10 m/s along y = 2 past a static disc at the origin: the obstacle tracks the
    metrics difference from the view have zero velocity at every step (moving the obstacle by
    the nearest disc's offset gave 15 m/s on the steps the nearest disc changed)."""
    from pipeline.analysis.metrics.geometry import obstacle_tracks

    poses = [(-5.0 + 1.0 * k, 2.0, 0.0) for k in range(11)]
    view = ego_disc_view(_table(poses, [(0.0, 0.0, 0.5)]), (-1.5, 0.0, 1.5))
    track, = obstacle_tracks(view)
    assert np.allclose(track.velocity, 0.0)


def test_a_car_in_the_next_lane_does_not_collide_with_one_in_its_own():
    """Two 4.5 x 1.8 cars side by side on lanes 3.2 m apart, the ego passing the parked one:
    the true rectangles never touch (the drivability checker), nor do their covers; the
    earlier reading (the parked car's circumscribed 2.46 m disc against a 1 m ego disc) saw a
    collision on every step beside it."""
    pytest.importorskip("commonroad_dc", reason="the CommonRoad extra")
    from commonroad.geometry.shape import Rectangle
    from commonroad_dc import pycrcc

    from pipeline.analysis.commonroad_check import ours_colliding
    from pipeline.loop.commonroad_scenario import discs_of_shape

    parked = (20.0, 3.2)
    poses = [(float(x), 0.0, 0.0) for x in np.linspace(10.0, 30.0, 21)]
    rectangle = Rectangle(*CAR)
    cover = [(parked[0] + c[0], parked[1] + c[1], r)
             for c, r in discs_of_shape(rectangle, "cover", 3)]
    offsets, ego_radius = rectangle_cover(*CAR, 3)
    ours = ours_colliding(_table(poses, cover), ego_radius, tuple(offsets))
    truth = [pycrcc.RectOBB(CAR[0] / 2, CAR[1] / 2, 0.0, x, y).collide(
        pycrcc.RectOBB(CAR[0] / 2, CAR[1] / 2, 0.0, *parked)) for x, y, _ in poses]
    assert not any(truth) and not ours.any()
    (centre, radius), = discs_of_shape(rectangle, "circumscribed")
    earlier = ours_colliding(_table(poses, [(parked[0], parked[1], radius)]), 1.0)
    assert radius == pytest.approx(math.hypot(*CAR) / 2)
    # closed form: the discs overlap where |x - 20| < sqrt((2.42 + 1)^2 - 3.2^2) = 1.21 m
    reach = math.sqrt((radius + 1.0) ** 2 - parked[1] ** 2)
    assert earlier.tolist() == [abs(x - parked[0]) < reach for x, _, _ in poses]
    assert earlier.sum() == 3


def test_a_rotated_rectangle_is_covered_along_its_long_side():
    """A car across the road (orientation pi/2 in its shape): its discs stand along y."""
    pytest.importorskip("commonroad", reason="the CommonRoad extra")
    from commonroad.geometry.shape import Rectangle

    from pipeline.loop.commonroad_scenario import discs_of_shape

    discs = discs_of_shape(Rectangle(*CAR, center=np.array([1.0, 2.0]),
                                     orientation=math.pi / 2), "cover", 3)
    centres = np.array([c for c, _ in discs])
    assert np.allclose(np.sort(centres[:, 1]), [0.5, 2.0, 3.5], atol=1e-9)
    assert np.allclose(centres[:, 0], 1.0, atol=1e-9)


def test_the_kinematic_half_planes_keep_the_nearest_ego_disc_out(make_config):
    """Appendix-A track, heading 0, an obstacle straight ahead of every predicted pose: the
    front disc (1.5 m ahead) is the nearest, so the three-disc planes are the one-disc planes
    of the obstacle moved back by 1.5 m (translation: the same normals, bounds 1.5 n_x lower);
    one disc gives the one-disc planes themselves."""
    from dataclasses import replace

    from pipeline.loop.controller.references import kinematic_halfplanes

    cfg = make_config(["experiment=kinematic", "controller.max_obstacles=1"])
    N = cfg.controller.horizon
    xs = np.linspace(0.0, 0.3 * N, N + 1)
    states = np.stack([xs, np.zeros(N + 1), np.zeros(N + 1), np.full(N + 1, 3.0)])
    reference = np.stack([xs[1:], np.full(N, 0.2)])
    obstacle = np.stack([xs[1:] + 6.0, np.full(N, 0.5)], axis=1)[:, None, :]
    vehicle = replace(cfg.vehicle, footprint_radius_m=1.17, footprint_discs=3,
                      footprint_span_m=3.0)
    one = replace(cfg.vehicle, footprint_radius_m=1.17)
    Gx, Gy, h = kinematic_halfplanes(states, reference, obstacle, np.array([0.5]), vehicle,
                                     cfg.controller)
    moved = obstacle - np.array([1.5, 0.0])
    Gx1, Gy1, h1 = kinematic_halfplanes(states, reference, moved, np.array([0.5]), one,
                                        cfg.controller)
    assert np.count_nonzero(Gx) == N
    assert np.allclose(Gx, Gx1) and np.allclose(Gy, Gy1) and np.allclose(h, h1)
    Gx0, _, h0 = kinematic_halfplanes(states, reference, obstacle, np.array([0.5]), one,
                                      cfg.controller)
    assert not np.allclose(h0, h)
