"""Recorded pedestrians (issue 43): the vendored ETH/UCY tracks are replayed exactly at their
sample times (oracle: the file's own numbers), a pedestrian outside the sensor range is
invisible to the planner, the family is reproducible by seed, the constant-velocity prediction
is the closed form, collisions are counted on the true tracks (planted geometry), and bad input
is one line with exit code 2."""

from __future__ import annotations

import gzip
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from pipeline.commands import error_line
from pipeline.errors import ConfigError, TrackFileError
from pipeline.loop.pedestrians import DATA_DIR, load_scene, read_track_rows, scene_of
from pipeline.loop.scenario import ObstacleSnapshot, build_scenario, family_members

ROOT = Path(__file__).resolve().parents[2]
SMALL = ["scenario=pedestrians", "scenario.family.size=3", "scenario.family.n_jobs=1"]


def _file_rows(scene: str) -> np.ndarray:
    """The vendored file read independently of the loader (gzip + numpy)."""
    with gzip.open(DATA_DIR / "eth_ucy" / f"{scene}.txt.gz", "rt") as handle:
        return np.loadtxt(handle)


def test_the_tracks_ship_with_the_project_and_their_citations():
    folder = ROOT / "data" / "eth_ucy"
    assert DATA_DIR == ROOT / "data"
    for scene in ("biwi_eth", "biwi_hotel", "crowds_zara01", "crowds_zara02", "students001",
                  "uni_examples"):
        assert (folder / f"{scene}.txt.gz").is_file()
    readme = (folder / "README.md").read_text()
    assert "Pellegrini" in readme and "Crowds by example" in readme


@pytest.mark.parametrize("scene", ["biwi_hotel", "crowds_zara01"])
def test_a_recorded_track_is_replayed_exactly_at_its_sample_times(make_config, scene):
    cfg = make_config(SMALL).scenario.pedestrians
    tracks = load_scene(cfg, scene)
    rows = _file_rows(scene)
    window = 3.7  # an arbitrary recording time as the scenario's t = 0
    for j in (0, 7, len(tracks.ids) // 2, len(tracks.ids) - 1):
        mine = rows[rows[:, 1] == tracks.ids[j]]
        motion = tracks.motion(np.array([j]), window)
        for frame, _, x, y in mine:
            positions, _, present = motion.states_at(frame * 0.04 - window)
            assert present[0]
            assert positions[0, 0] == x and positions[0, 1] == y  # bit for bit
        if len(mine) >= 2:  # halfway between two samples: their mean (linear interpolation)
            (f0, _, x0, y0), (f1, _, x1, y1) = mine[0], mine[1]
            positions, velocities, _ = motion.states_at(0.5 * (f0 + f1) * 0.04 - window)
            np.testing.assert_allclose(positions[0], [(x0 + x1) / 2, (y0 + y1) / 2],
                                       rtol=0, atol=1e-12)
            np.testing.assert_allclose(velocities[0], [(x1 - x0) / 0.4, (y1 - y0) / 0.4],
                                       rtol=1e-12)
        # absent before its first and after its last sample
        _, _, before = motion.states_at(mine[0, 0] * 0.04 - window - 0.2)
        _, _, after = motion.states_at(mine[-1, 0] * 0.04 - window + 0.2)
        assert not before[0] and not after[0]


def test_an_extended_track_walks_in_and_out_at_its_end_segments_velocity():
    """scenario.pedestrians.track_extension_s: a track sampled at 1.0, 1.4 and 1.8 s at
    x = 0, 0.4, 1.0 m (1 m/s, then 1.5 m/s) extended by 1 s is present from 0.0 to 2.8 s,
    at x = 0 - 1 m/s (1.0 - t) before its first sample and at 1.0 + 1.5 m/s (t - 1.8) after
    its last, with those velocities; on its samples the samples themselves; without the
    extension (the recording) it is absent outside [1.0, 1.8] s. A one-sample track at 1.0 s
    stands exactly at its sample from 0.0 to 2.0 s."""
    from pipeline.loop.pedestrians import RecordedTrackMotion

    positions = np.array([[[0.0, 2.0], [0.4, 2.0], [1.0, 2.0]],
                          [[5.0, 5.0], [5.0, 5.0], [5.0, 5.0]]])
    def motion(extension_s: float) -> RecordedTrackMotion:
        return RecordedTrackMotion(np.array([1.0, 1.0]), 0.4, np.array([3, 1]), positions,
                                   extension_s)

    extended, recorded = motion(1.0), motion(0.0)
    for t, x, v in [(0.0, -1.0, 1.0), (0.55, -0.45, 1.0), (2.3, 1.75, 1.5), (2.8, 2.5, 1.5)]:
        where, velocity, present = extended.states_at(t)
        assert present[0] and present[1] == (t <= 2.0), t
        np.testing.assert_allclose(where[0], [x, 2.0], rtol=0, atol=1e-12)
        np.testing.assert_allclose(velocity[0], [v, 0.0], rtol=0, atol=1e-12)
        np.testing.assert_array_equal(where[1], [5.0, 5.0])
        np.testing.assert_array_equal(velocity[1], [0.0, 0.0])
        assert not recorded.states_at(t)[2].any(), t
    for t in (-0.05, 2.85):
        assert not extended.states_at(t)[2].any(), t
    assert not extended.states_at(2.05)[2][1]
    for k, t in enumerate((1.0, 1.4, 1.8)):  # the samples, bit for bit, either way
        for m in (extended, recorded):
            assert m.states_at(t)[0][0, 0] == positions[0, k, 0]
    # every step at once is each step alone (crossing_difficulty's path)
    times = np.arange(-2, 40) * 0.1
    at_once, present_at_once = extended.positions_over(times)
    for k, t in enumerate(times):
        np.testing.assert_array_equal(at_once[k], extended.states_at(float(t))[0])
        np.testing.assert_array_equal(present_at_once[k], extended.states_at(float(t))[2])


def test_constant_velocity_prediction_is_the_closed_form(make_config):
    cfg = make_config(SMALL).scenario.pedestrians
    tracks = load_scene(cfg, "crowds_zara02")
    rows = _file_rows("crowds_zara02")
    j = 11
    mine = rows[rows[:, 1] == tracks.ids[j]]
    (f0, _, x0, y0), (_, _, x1, y1) = mine[3], mine[4]
    t = f0 * 0.04 + 0.1  # a quarter into the segment
    positions, velocities, present = tracks.motion(np.array([j]), 0.0).states_at(t)
    snapshot = ObstacleSnapshot(positions, velocities, np.array([0.3]), present)
    ahead = np.array([0.0, 0.3, 1.0, 2.5])
    v = np.array([x1 - x0, y1 - y0]) / 0.4
    expected = np.array([x0, y0]) + (0.1 + ahead)[:, None] * v  # p(t) + tau v on the segment
    np.testing.assert_allclose(snapshot.predicted_positions(ahead)[:, 0, :], expected,
                               rtol=0, atol=1e-9)


def test_the_same_seed_gives_the_same_family_and_another_seed_another(make_config):
    base = make_config(SMALL).scenario
    first, again = family_members(base), family_members(base)
    assert first == again
    other = family_members(replace(base, family=replace(base.family, seed=1)))
    assert [m.start_xy_m for m in other] != [m.start_xy_m for m in first]
    for member in first:
        ped = member.pedestrians
        assert ped.scene in ped.scenes and scene_of(member.name, ped.scenes) == ped.scene
        assert member.family is None and ped.window_start_s is not None
        assert 1.0 <= member.speed_mps <= 2.0
        length = np.hypot(*np.subtract(member.goal_xy_m, member.start_xy_m))
        assert length == pytest.approx(ped.crossing_length_m)
        # member i does not depend on the family's size
    assert family_members(replace(base, family=replace(base.family, size=1)))[0] == first[0]


def _plant(tmp_path: Path, tracks: dict[int, list[tuple[float, float]]]) -> Path:
    """A track file: pedestrian id -> positions at frames 0, 10, 20, ..."""
    lines = [f"{10 * k}\t{pid}\t{x}\t{y}" for pid, points in tracks.items()
             for k, (x, y) in enumerate(points)]
    path = tmp_path / "plant.txt"
    path.write_text("\n".join(lines) + "\n")
    return path


def _planted_config(make_config, tmp_path: Path, extra: list[str] | None = None):
    """A member on the planted scene: from (0, 0) to (12, 0) at 1.5 m/s, the vehicle
    driving straight (no APF, no collision half-planes), the sensor range 6 m."""
    cfg = make_config(SMALL + ["method=mpc_no_apf", "controller.collision_constraints=false",
                               f"scenario.pedestrians.data_dir={tmp_path}",
                               "scenario.pedestrians.scenes=[plant]"] + (extra or []))
    member = replace(cfg.scenario, name="planted", start_xy_m=[0.0, 0.0],
                     goal_xy_m=[12.0, 0.0], start_heading_rad=0.0, speed_mps=1.5,
                     family=None, pedestrians=replace(cfg.scenario.pedestrians, scene="plant",
                                                      window_start_s=0.0, corridor_m=20.0))
    return replace(cfg, scenario=member)


def test_a_pedestrian_outside_the_sensor_range_is_invisible_to_the_planner(make_config,
                                                                          tmp_path):
    from pipeline.loop.simulate import simulate

    # one pedestrian standing 3 m off the line at x = 10 for the whole run
    _plant(tmp_path, {1: [(10.0, 3.0)] * 60})
    cfg = _planted_config(make_config, tmp_path, ["method=improved"])
    tr = simulate(cfg, build_scenario(cfg.scenario)).trajectory
    gap = np.hypot(tr["X_m"] - 10.0, tr["Y_m"] - 3.0).to_numpy()
    seen = tr["obs0_visible"].to_numpy(bool)
    assert (seen == (gap <= 6.0)).all()
    assert not seen[0] and seen.any()  # out of range at the start, in range later
    # while unseen the APF feels no repulsion (a pedestrian 3 m off would push otherwise)
    unseen = ~seen[:-1]
    assert np.all(tr["apf_rep_norm"].to_numpy()[:-1][unseen] == 0.0)
    assert np.any(tr["apf_rep_norm"].to_numpy()[:-1][~unseen] > 0.0)
    # the logged position is the true one, seen or not
    assert np.all(tr["obs0_x_m"] == 10.0) and np.all(tr["obs0_y_m"] == 3.0)


def test_collisions_are_counted_on_the_true_tracks(make_config, tmp_path):
    """Planted: the vehicle drives straight along y = 0; pedestrian 1 walks down onto the line
    and stops there (a collision whatever is seen), pedestrian 2 stands 4 m off it (the closest
    clearance is 4 - 1.0 - 0.3 = 2.7 m)."""
    from pipeline.analysis.metrics import compute_metrics
    from pipeline.analysis.metrics.context import trajectory_context
    from pipeline.loop.simulate import simulate

    walker = [(8.0, 4.0 - 0.4 * k) for k in range(10)] + [(8.0, 0.0)] * 50
    _plant(tmp_path, {1: walker})
    cfg = _planted_config(make_config, tmp_path)
    tr = simulate(cfg, build_scenario(cfg.scenario)).trajectory
    metrics = compute_metrics(tr, trajectory_context(cfg), cfg.metrics)
    assert metrics.to_json()["collision"] is True

    _plant(tmp_path, {2: [(6.0, 4.0)] * 60})
    tr = simulate(cfg, build_scenario(cfg.scenario)).trajectory
    flat = compute_metrics(tr, trajectory_context(cfg), cfg.metrics).to_json()
    assert flat["collision"] is False
    assert abs(tr["e_y_m"]).max() < 0.05  # it did drive straight
    assert flat["min_clearance_m"] == pytest.approx(2.7, abs=0.05)


def test_the_mpc_slots_are_filled_nearest_first():
    snapshot = ObstacleSnapshot(np.array([[9.0, 0.0], [2.0, 0.0], [5.0, 1.0]]),
                                np.zeros((3, 2)), np.array([0.3, 0.4, 0.5]),
                                np.array([True, True, True]))
    ordered = snapshot.nearest_first(np.array([0.0, 0.0]))
    assert ordered.radii_m.tolist() == [0.4, 0.5, 0.3]


# ---- bad input: one line, exit code 2 -------------------------------------------------------

def _line(exc: BaseException) -> tuple[str, int]:
    found = error_line(exc)
    assert found is not None
    return found


@pytest.mark.parametrize("text, says", [
    ("0\t1\t1.0\t2.0\n10\t1\t1.5\n", "line 2"),
    ("0\t1\t1.0\tabc\n", "line 1"),
    ("0\t1\t1.0\tnan\n", "line 1"),
    ("", "no tracks"),
])
def test_a_malformed_track_file_is_one_line_naming_it(tmp_path, text, says):
    path = tmp_path / "bad.txt"
    path.write_text(text)
    with pytest.raises(TrackFileError) as caught:
        read_track_rows(path)
    line, code = _line(caught.value)
    assert code == 2 and "\n" not in line
    assert str(path) in line and says in line and "frame, pedestrian_id, x_m, y_m" in line


def test_two_rows_for_one_pedestrian_and_frame_are_one_line(make_config, tmp_path):
    (tmp_path / "twice.txt").write_text("0\t1\t1.0\t2.0\n0\t1\t1.5\t2.0\n")
    cfg = make_config(SMALL + [f"scenario.pedestrians.data_dir={tmp_path}"]).scenario
    with pytest.raises(TrackFileError) as caught:
        load_scene(cfg.pedestrians, "twice")
    line, code = _line(caught.value)
    assert code == 2 and str(tmp_path / "twice.txt") in line and "two rows for one frame" \
        in line


def test_a_missing_track_file_names_the_file_and_the_scenes_found(make_config, tmp_path):
    (tmp_path / "here.txt").write_text("0\t1\t1.0\t2.0\n")
    cfg = make_config(SMALL + [f"scenario.pedestrians.data_dir={tmp_path}",
                               "scenario.pedestrians.scenes=[nowhere]"])
    with pytest.raises(TrackFileError) as caught:
        family_members(cfg.scenario)
    line, code = _line(caught.value)
    assert code == 2 and str(tmp_path / "nowhere.txt.gz") in line and "found: here" in line


def test_a_scene_too_small_for_the_crossing_names_the_key_and_range(make_config, tmp_path):
    _plant(tmp_path, {1: [(0.0, 0.0), (1.0, 1.0)] * 300, 2: [(3.0, 2.0)] * 600})
    cfg = make_config(SMALL + [f"scenario.pedestrians.data_dir={tmp_path}",
                               "scenario.pedestrians.scenes=[plant]"])
    with pytest.raises(ConfigError) as caught:
        family_members(cfg.scenario)
    line, code = _line(caught.value)
    # extent 3 m x 2 m: diagonal 3.61 m less 2 x 0.5 m margin = 2.6 m
    assert code == 2 and "scenario.pedestrians.crossing_length_m=10.0" in line \
        and "<= 2.6 m for scene 'plant'" in line


@pytest.mark.parametrize("override, key, allowed", [
    ("scenario.pedestrians.sensor_range_m=0", "scenario.pedestrians.sensor_range_m",
     "(0, 100]"),
    ("scenario.pedestrians.sensor_range_m=-3", "scenario.pedestrians.sensor_range_m",
     "(0, 100]"),
    ("scenario.pedestrians.sensor_range_m=1.2", "scenario.pedestrians.sensor_range_m",
     "(1.3, 100]"),
    ("scenario.pedestrians.radius_m=0", "scenario.pedestrians.radius_m", "[0.01, 5.0]"),
    ("scenario.pedestrians.platform_speed_mps=[2.0,1.0]",
     "scenario.pedestrians.platform_speed_mps", "low <= high"),
    ("scenario.pedestrians.scenes=[]", "scenario.pedestrians.scenes", "non-empty"),
    ("scenario.pedestrians.track_extension_s=-1", "scenario.pedestrians.track_extension_s",
     "[0.0, 10.0]"),
    ("controller.solver_refinement=maybe", "controller.solver_refinement", "bool"),
])
def test_bad_pedestrian_settings_name_the_key_and_range(make_config, override, key, allowed):
    with pytest.raises(Exception) as caught:
        make_config(SMALL + [override])
    line, code = _line(caught.value)
    assert code == 2 and key in line and allowed in line, line


def test_clarabels_refinement_cannot_be_switched_off_for_daqp(make_config):
    with pytest.raises(ConfigError) as caught:
        make_config(SMALL + ["controller.backend=daqp", "controller.solver_refinement=false"])
    line, code = _line(caught.value)
    assert code == 2 and "controller.solver_refinement=False" in line \
        and "only with clarabel_direct or cvxpy" in line, line


def test_the_command_exits_2_with_one_line_for_a_malformed_file(tmp_path):
    (tmp_path / "broken.txt").write_text("0\t1\t1.0\t2.0\n10\t1\n")
    done = subprocess.run(
        [sys.executable, "-m", "pipeline.run", "scenario=pedestrians",
         f"scenario.pedestrians.data_dir={tmp_path}", "scenario.pedestrians.scenes=[broken]",
         "scenario.family.size=1", f"hydra.run.dir={tmp_path / 'run'}"],
        capture_output=True, text=True, cwd=ROOT, timeout=300)
    assert done.returncode == 2, done.stderr[-2000:]
    lines = [x for x in done.stderr.splitlines() if x.strip()]
    assert len(lines) == 1 and str(tmp_path / "broken.txt") in lines[0] \
        and "line 2" in lines[0], done.stderr[-2000:]


@pytest.mark.parametrize("extension_s", [0.0, 1.0])
def test_every_steps_walkers_read_at_once_are_each_steps_bit_for_bit(make_config, extension_s):
    """SteppedTrackMotion (the loop's walkers, every step time read at once) gives, bit for
    bit, the positions, velocities and presence that RecordedTrackMotion.states_at gives at
    each step time, with and without the track extension; a time between steps (the social
    force's look-ahead) is the tracks' own answer."""
    from pipeline.loop.pedestrians import SteppedTrackMotion, pedestrians_near

    ped = make_config(["experiment=pedestrians"]).scenario.pedestrians
    tracks = load_scene(ped, ped.scenes[0])
    which = pedestrians_near(tracks, np.array([0.0, 0.0]), np.array([10.0, 0.0]), 30.0,
                             22.0, 1e6)[:40]
    recorded = tracks.motion(which, 30.0, extension_s)
    stepped = SteppedTrackMotion.of(recorded, 0.1, 220)
    assert stepped.present.any() and not stepped.present.all()
    for k in range(221):
        for got, want in zip(stepped.states_at(k * 0.1), recorded.states_at(k * 0.1),
                             strict=True):
            np.testing.assert_array_equal(got, want)
    for t in (0.05, 3.333, 22.5, -1.0):
        for got, want in zip(stepped.states_at(t), recorded.states_at(t), strict=True):
            np.testing.assert_array_equal(got, want)
    # a row handed out is a copy: the caller's edits do not reach the next step
    stepped.states_at(1.0)[0][:] = np.nan
    assert np.isfinite(stepped.states_at(1.0)[0]).all()
