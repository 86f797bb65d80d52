"""The scenario explorer's data: what each step planned (recorded by the loop, kept by the
store and the member cache) and the member data files the report writes beside
``explorer.html`` (the page itself is driven in Chromium in ``test_explorer_browser.py``)."""

from __future__ import annotations

import base64
import gzip
import json
import re
import shutil

import numpy as np
import pytest

from pipeline.loop.scenario import build_scenario
from pipeline.loop.simulate import simulate
from pipeline.reporting.explorer import explorer_href, write_explorer
from pipeline.store.files import npz_bytes
from pipeline.store.manifest import HORIZON_FILE, MANIFEST
from pipeline.store.runs import read_horizon, read_run
from pipeline.studies.experiment import run_experiment, run_family


@pytest.fixture(scope="module")
def paper_runs(make_config):
    """The paper scenario on the lateral track (path frame about the rollout and about its
    pursuit, fixed frame) and on the kinematic track."""
    out = {}
    for name, overrides in (("lateral", ["method=improved"]),
                            ("pursuit", ["method=improved", "controller.path_reference=pursuit"]),
                            ("fixed", ["method=improved", "controller.frame=fixed"]),
                            ("kinematic", ["experiment=kinematic", "method=improved"])):
        cfg = make_config(overrides)
        out[name] = (cfg, simulate(cfg, build_scenario(cfg.scenario)))
    return out


@pytest.mark.parametrize("track", ["lateral", "pursuit", "fixed", "kinematic"])
def test_each_plan_starts_at_the_vehicle_and_its_half_planes_exclude_the_obstacle(
        paper_runs, track):
    """Two facts any plan and any collision constraint must satisfy, checked on the recorded
    global-frame arrays: the plan's step 0 is where the vehicle is (the log's X, Y), and the
    obstacle's predicted centre at each constrained horizon step lies on the half-plane's
    forbidden side (``cos a x + sin a y < c``). A path-frame half-plane (``e_y >= b`` at a
    station) is drawn as the line across the path's normal at the station: exact on a path that
    does not bend between the station and the obstacle (the pursuit path, curvature-limited,
    and the fixed frame's line: every one); about the rollout itself, which may turn by a right
    angle within a metre, at least 90 % of them."""
    cfg, result = paper_runs[track]
    horizon, trajectory = result.horizon, result.trajectory
    rows = len(trajectory)
    assert {"apf_path_m", "plan_xy_m", "constraint_normal_rad", "constraint_offset_m",
            "prediction_step_s", "obstacle_velocity_mps"} <= set(horizon)
    assert all(v.shape[0] == rows for v in horizon.values())
    plan = horizon["plan_xy_m"]
    solved = np.isfinite(plan[:, 0, 0])
    assert solved.sum() >= rows - 2  # every step but the last row (and none fell back here)
    xy = trajectory[["X_m", "Y_m"]].to_numpy()
    np.testing.assert_allclose(plan[solved, 0], xy[solved], atol=1e-9)
    # the APF's path starts at the vehicle too
    np.testing.assert_allclose(horizon["apf_path_m"][solved, 0], xy[solved], atol=1e-9)
    normal, offset = horizon["constraint_normal_rad"], horizon["constraint_offset_m"]
    active = np.argwhere(np.isfinite(normal))
    assert len(active) >= 10, "the paper scenario's obstacle is constrained at some steps"
    velocity = horizon["obstacle_velocity_mps"]
    excluded = 0
    for k, i, j in active:
        centre = trajectory[[f"obs{j}_x_m", f"obs{j}_y_m"]].to_numpy()[k] \
            + velocity[k, j] * horizon["prediction_step_s"][k] * (i + 1)
        side = np.cos(normal[k, i, j]) * centre[0] + np.sin(normal[k, i, j]) * centre[1]
        excluded += side < offset[k, i, j]
    if track == "lateral":
        assert excluded >= 0.9 * len(active)
    else:
        assert excluded == len(active)
    # the obstacle's recorded velocity is the scenario's (0, -0.4) m/s once it is there
    obstacle = cfg.scenario.obstacles[0]
    np.testing.assert_allclose(velocity[-2, 0], [obstacle.vx_mps, obstacle.vy_mps])


def test_the_horizon_record_is_stored_listed_and_read_back(make_config, tmp_path):
    """``horizon.npz`` is in the run folder and its manifest; reading it gives the arrays
    (float32); a changed file is not trusted; the same arrays give the same bytes."""
    folder = tmp_path / "run"
    run_experiment(make_config(["method=baseline"]), folder)
    manifest = json.loads((folder / MANIFEST).read_text())
    assert HORIZON_FILE in manifest["files"]
    read = read_horizon(folder)
    assert read is not None and read["plan_xy_m"].shape[1:] == (11, 2)
    trajectory = read_run(folder).trajectory
    np.testing.assert_allclose(read["plan_xy_m"][:-1, 0], trajectory[["X_m", "Y_m"]]
                               .to_numpy()[:-1], atol=1e-4)
    arrays = {"a": np.arange(6.0).reshape(3, 2), "b": np.array([np.nan, 1.5])}
    assert npz_bytes(arrays) == npz_bytes(dict(reversed(arrays.items())))
    (folder / HORIZON_FILE).write_bytes(npz_bytes(arrays))
    assert read_horizon(folder) is None


def test_the_member_cache_restores_the_horizon_record(make_config, tmp_path):
    from pipeline.store.member_cache import MemberCache

    cache = MemberCache(tmp_path / "cache")
    cfg = make_config(["method=improved", "scenario=family", "scenario.family.size=1",
                       "scenario.family.n_jobs=1"])
    run_family(cfg, tmp_path / "first", progress=False, member_cache=cache)
    run_family(cfg, tmp_path / "second", progress=False, member_cache=cache)
    first, second = tmp_path / "first" / "member_0000", tmp_path / "second" / "member_0000"
    assert json.loads((second / MANIFEST).read_text()).get("member_cache")
    assert (second / HORIZON_FILE).read_bytes() == (first / HORIZON_FILE).read_bytes()
    assert read_horizon(second) is not None


def _decode(path):
    text = path.read_text()
    key, packed = re.fullmatch(r'\(window\.__explorerData = window\.__explorerData \|\| \{\}\)'
                               r'\[("[^"]+")\] = "([A-Za-z0-9+/=]+)";\n', text).groups()
    return json.loads(key), json.loads(gzip.decompress(base64.b64decode(packed)))


@pytest.fixture(scope="module")
def small_outputs(tmp_path_factory, small_reproduce):
    """The session's :func:`small_reproduce` (a family of six members and the paper scenario,
    baseline and improved), copied with a study's folder and a peer on the family's scenarios
    (a copy of the baseline's family) added."""
    root = tmp_path_factory.mktemp("explorer") / "outputs"
    shutil.copytree(small_reproduce, root)
    (root / "multiverse").mkdir()  # a study's section: never in the explorer
    shutil.copytree(root / "family" / "baseline", root / "peers" / "a_peer")
    return root


def test_every_member_gets_a_data_file_and_the_page_lists_it(small_outputs, tmp_path):
    root, out = small_outputs, tmp_path / "report"
    index = write_explorer(root, out)
    assert list(index.experiments) == ["paper", "family", "peers"]
    assert index.experiments["peers"]["methods"] == ["improved (family)", "baseline (family)",
                                                     "a_peer"]
    _, peers = _decode(out / "explorer_data" / "peers" / "1.js")
    assert [m["name"] for m in peers["methods"]] == ["improved (family)", "baseline (family)",
                                                     "a_peer"]
    assert peers["methods"][1]["x"] == peers["methods"][2]["x"]  # the same run, twice
    # one colour per method in every experiment, the report's (issue 61, item 1)
    from pipeline.reporting.figures.colors import method_color

    _, family_one = _decode(out / "explorer_data" / "family" / "1.js")
    colours = {m["name"]: m["color"] for m in family_one["methods"] + peers["methods"]}
    assert colours["improved"] == colours["improved (family)"] == method_color("improved")
    assert colours["baseline"] == colours["baseline (family)"] == method_color("baseline")
    assert colours["a_peer"] == method_color("a_peer")
    assert index.experiments["family"]["members"] == [0, 1, 2, 3, 4, 5]
    assert explorer_href("family", 2) == "explorer.html#family/2"
    key, data = _decode(out / "explorer_data" / "family" / "2.js")
    assert key == data["key"] == "family/2"
    assert [m["name"] for m in data["methods"]] == ["baseline", "improved"]
    assert index.experiments["paper"]["members"] == [0] and index.experiments["paper"]["single"]
    improved = data["methods"][1]
    run = read_run(root / "family" / "improved" / "member_0002")
    # positions in centimetres, the plan relative to the vehicle (its step 0 is 0, 0)
    assert improved["x"] == [round(v * 100) for v in run.trajectory["X_m"]]
    assert improved["plan"][5][:2] == [0, 0] and len(improved["plan"][5]) == 22
    assert all(len(row) == 5 for row in improved["cons"])
    assert data["steer_max"] == pytest.approx(run.config.vehicle.steering_max_rad)
    # the member's own scenario, not member 0's (issue 61: every status line named i0000)
    assert data["scenario"] == run.config.scenario.name and data["scenario"].endswith("i0002")
    assert data["start"] == list(run.config.scenario.start_xy_m)
    assert data["goal"] == list(run.config.scenario.goal_xy_m)
    page = (out / "explorer.html").read_text()
    assert '"family":{"methods":["baseline","improved"],"members":[0,1,2,3,4,5]' in page
    assert "http://" not in page and "https://" not in page
    # written again with nothing changed: the data files are kept as they were
    before = (out / "explorer_data" / "family" / "1.js").stat().st_mtime_ns
    write_explorer(root, out)
    assert (out / "explorer_data" / "family" / "1.js").stat().st_mtime_ns == before


def test_the_report_writes_the_explorer_and_every_link_has_its_member(small_outputs, tmp_path):
    """``build_report`` writes ``explorer.html`` beside the page; every link of the page into
    it (the gallery's, the peers section's) names a member whose data file is there."""
    from pipeline.reporting.page import build_report

    out = tmp_path / "report"
    page = build_report(small_outputs, out, "pytest", figure_jobs=1).read_text()
    links = set(re.findall(r'href="explorer\.html#([a-z_]+/[0-9]+)"', page))
    assert (out / "explorer.html").is_file()
    assert "peers/0" in links, links
    assert any(link.startswith("family/") for link in links), "the gallery links its members"
    for link in links:
        assert (out / "explorer_data" / f"{link}.js").is_file(), link


def test_a_study_of_tracks_shows_each_track_as_an_experiment(small_reproduce, tmp_path):
    """``make euro-ncap``'s folder (``euro_ncap/<track>/<method>``: a study, not an
    experiment) is shown track by track as ``euro_ncap-<track>``: its members get data files
    under that name, its address opens them, its table numbers come from its own families; a
    track folder without families is not listed."""
    from pipeline.reporting.explorer import experiment_entries, experiment_members, member_data

    root = tmp_path / "outputs"
    shutil.copytree(small_reproduce / "family", root / "family")
    for method in ("baseline", "improved"):
        shutil.copytree(small_reproduce / "family" / method,
                        root / "euro_ncap" / "lateral" / method)
    (root / "euro_ncap" / "kinematic").mkdir()  # no families yet
    entries = experiment_entries(root)
    assert [name for name, _ in entries] == ["family", "euro_ncap-lateral"]
    assert entries[1][1] == root / "euro_ncap" / "lateral"
    assert experiment_members(root)["euro_ncap-lateral"] == [0, 1, 2, 3, 4, 5]
    out = tmp_path / "report"
    index = write_explorer(root, out)
    assert list(index.experiments) == ["family", "euro_ncap-lateral"]
    assert index.experiments["euro_ncap-lateral"]["methods"] == ["baseline", "improved"]
    assert index.experiments["euro_ncap-lateral"]["numbers"]["improved"]
    key, data = _decode(out / "explorer_data" / "euro_ncap-lateral" / "3.js")
    assert key == data["key"] == "euro_ncap-lateral/3"
    _, family = _decode(out / "explorer_data" / "family" / "3.js")
    assert data["methods"][1]["x"] == family["methods"][1]["x"]  # the same runs
    direct = member_data(root, "euro_ncap-lateral", 3)
    assert direct is not None and direct["key"] == "euro_ncap-lateral/3"
    assert member_data(root, "euro_ncap-kinematic", 0) is None
    assert '"euro_ncap-lateral":{"methods":["baseline","improved"]' in \
        (out / "explorer.html").read_text()


def test_a_flag_column_reads_the_same_as_booleans_and_as_text():
    """read_csv's boolean column (the fast path) and the same flags as text, with a missing
    cell and the spellings a CSV writer may use, give the same flags."""
    import pandas as pd

    from pipeline.reporting.explorer import _flag

    flags = [True, False, True, True, False]
    as_bool = pd.DataFrame({"obs0_visible": flags})
    as_text = pd.DataFrame({"obs0_visible": ["True", "false", " 1", "1.0", np.nan]})
    assert as_bool["obs0_visible"].dtype == bool and as_text["obs0_visible"].dtype != bool
    assert _flag(as_bool, "obs0_visible").tolist() == flags
    assert _flag(as_text, "obs0_visible").tolist() == flags
    assert _flag(as_bool, "obs1_visible").tolist() == [False] * 5


def _method_data_obstacles_one_at_a_time(trajectory, horizon, footprint_m):
    """The obstacles' part of method_data as it was written before every obstacle was read at
    once: one obstacle after the other (the oracle)."""
    import pandas as pd

    from pipeline.loop.trajectory import obstacle_column, obstacle_indices
    from pipeline.reporting.explorer import _flag, _ints

    def column(name):
        if name in trajectory:
            return pd.to_numeric(trajectory[name], errors="coerce").to_numpy(float)
        return np.full(len(trajectory), np.nan)

    n = len(trajectory)
    x, y = column("X_m"), column("Y_m")
    clearance = np.full(n, np.inf)
    obstacles = []
    for j in obstacle_indices(trajectory.columns):
        ox, oy = column(obstacle_column(j, "x_m")), column(obstacle_column(j, "y_m"))
        radius = column(obstacle_column(j, "radius_m"))
        seen = _flag(trajectory, obstacle_column(j, "visible"))
        gap = np.hypot(x - ox, y - oy) - radius - footprint_m
        clearance = np.where(seen & np.isfinite(gap), np.minimum(clearance, gap), clearance)
        entry = {"x": _ints(ox, 100), "y": _ints(oy, 100),
                 "r": _ints([np.nanmax(radius) if np.isfinite(radius).any() else 0.0], 100)[0],
                 "vis": [int(v) for v in seen.tolist()]}
        if horizon is not None and "obstacle_velocity_mps" in horizon \
                and j < horizon["obstacle_velocity_mps"].shape[1]:
            velocity = horizon["obstacle_velocity_mps"][:n, j]
            entry["vx"], entry["vy"] = _ints(velocity[:, 0], 100), _ints(velocity[:, 1], 100)
        obstacles.append(entry)
    return _ints(np.where(np.isfinite(clearance), clearance, np.nan), 100), obstacles


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_every_obstacle_read_at_once_is_each_obstacle_read_alone(seed):
    """method_data's obstacles (all columns at once) against the loop over obstacles it
    replaced: index gaps, NaN and absent cells, a text column, a flag column as text, an
    obstacle never seen, fewer velocity slots in the horizon than obstacles."""
    import pandas as pd

    from pipeline.reporting.explorer import method_data

    rng = np.random.default_rng(seed)
    n = 25
    frame = {"time_s": np.arange(n) * 0.1, "X_m": rng.normal(0, 3, n), "Y_m": rng.normal(0, 3, n)}
    for j in (0, 1, 3, 4, 7):  # gaps: 2, 5 and 6 absent
        frame[f"obs{j}_x_m"] = rng.normal(0, 3, n)
        frame[f"obs{j}_y_m"] = rng.normal(0, 3, n)
        frame[f"obs{j}_radius_m"] = np.full(n, 0.3 + 0.1 * j)
        frame[f"obs{j}_visible"] = rng.random(n) < 0.7
    frame["obs1_x_m"][rng.random(n) < 0.3] = np.nan
    frame["obs3_radius_m"][:] = np.nan
    frame["obs4_visible"][:] = False
    trajectory = pd.DataFrame(frame)
    trajectory["obs7_x_m"] = [f"{v}" if i % 3 else "" for i, v in
                              enumerate(trajectory["obs7_x_m"])]  # text, a missing cell
    trajectory["obs0_visible"] = trajectory["obs0_visible"].map(str)
    # 4 slots: obstacles 4 and 7 get no velocity; 8 slots (more than the 5 obstacles): all
    few, many = rng.normal(0, 1, (n, 4, 2)), rng.normal(0, 1, (n, 8, 2))
    few[3, 1, 0] = np.nan
    for horizon, with_velocity in ((None, [False] * 5),
                                   ({"obstacle_velocity_mps": few}, [True] * 3 + [False] * 2),
                                   ({"obstacle_velocity_mps": many}, [True] * 5)):
        got = method_data(trajectory, horizon, 0.5)
        clear, obstacles = _method_data_obstacles_one_at_a_time(trajectory, horizon, 0.5)
        assert json.dumps(got["obs"]) == json.dumps(obstacles)
        assert json.dumps(got["clear"]) == json.dumps(clear)
        assert [("vx" in o) for o in got["obs"]] == with_velocity
