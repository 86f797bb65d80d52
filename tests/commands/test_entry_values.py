"""Values checked where they enter (issue 62, item 3): a physical input is bounded by the
schema with its reason, and an angle is wrapped once, in closed form, where it enters the
scenario (a start heading of 1e16 rad once hung every lateral run: the pursuit chase wrapped it
by steps of 2 pi, which never changes such a number)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pipeline.errors import ConfigError


@pytest.mark.parametrize("heading", ["1e16", "-7.0", "inf", "nan"])
def test_a_start_heading_beyond_one_turn_is_refused_naming_the_key_and_range(make_config,
                                                                            heading):
    with pytest.raises(ConfigError) as info:
        make_config([f"scenario.start_heading_rad={heading}"])
    assert info.value.key == "scenario.start_heading_rad"
    if heading in ("1e16", "-7.0"):
        assert "[-6.2832, 6.2832]" in str(info.value) and "rad" in str(info.value)


def test_a_start_heading_one_turn_away_drives_the_same_run(make_config):
    """The oracle is geometry: 2 pi - 0.3 rad and -0.3 rad are one heading, so the runs agree
    to rounding (the scenario holds the wrapped value; without the wrap the path frame would
    see a heading error of a whole turn)."""
    from pipeline.loop.scenario import build_scenario
    from pipeline.loop.simulate import simulate

    paths = {}
    for heading in (-0.3, 2.0 * math.pi - 0.3):
        cfg = make_config(["method=improved", f"scenario.start_heading_rad={heading!r}",
                           "scenario.n_steps=40"])
        scenario = build_scenario(cfg.scenario)
        assert -math.pi <= scenario.start_heading_rad <= math.pi
        paths[heading] = simulate(cfg, scenario).trajectory[["X_m", "Y_m"]].to_numpy()
    first, second = paths.values()
    assert np.abs(first - second).max() < 1e-6
    assert np.abs(np.diff(first[:, 1])).max() > 1e-3  # it turned: not a trivial run


def _track_lines() -> list[str]:
    import gzip

    from pipeline.loop.pedestrians import DATA_DIR

    with gzip.open(DATA_DIR / "eth_ucy" / "biwi_eth.txt.gz", "rt") as handle:
        return handle.read().splitlines()


def _load_planted(tmp_path, lines: list[str]):
    from types import SimpleNamespace

    from pipeline.loop.pedestrians import load_scene

    (tmp_path / "planted.txt").write_text("\n".join(lines) + "\n")
    cfg = SimpleNamespace(data_dir=str(tmp_path), seconds_per_frame=0.04)
    return load_scene(cfg, "planted")  # type: ignore[arg-type]


@pytest.mark.parametrize("frame, says", [("78000000", "frame steps after the pedestrian's "
                                                       "previous row; allowed: at most 25"),
                                         ("7805", "not on the file's frame lattice"),
                                         ("7800.5", "a whole frame number")])
def test_a_mistyped_frame_number_is_named_by_line_before_any_array_is_made(tmp_path, frame,
                                                                          says):
    """One mistyped frame number in a real recording (ETH) once made the loader allocate
    58 GiB; now the file's line is named and the peak allocation stays small (tracemalloc)."""
    import tracemalloc

    from pipeline.errors import TrackFileError

    lines = _track_lines()
    # a row in the middle of a pedestrian's track: its own id has rows before and after
    ids = [line.split()[1] for line in lines]
    row = next(i for i in range(1, len(lines) - 1)
               if ids[i - 1] == ids[i] == ids[i + 1] and float(lines[i].split()[0]) > 7000)
    parts = lines[row].split()
    lines[row] = "\t".join([frame, *parts[1:]])
    tracemalloc.start()
    try:
        with pytest.raises(TrackFileError) as info:
            _load_planted(tmp_path, lines)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    message = str(info.value)
    assert f"planted.txt: line {row + 1} (frame {float(frame):g}" in message and says in message
    assert "\n" not in message and peak < 200e6


def test_the_recordings_pass_the_frame_checks_unchanged(tmp_path):
    """The same file planted unchanged loads: 10-frame steps at 0.4 s, its pedestrians."""
    tracks = _load_planted(tmp_path, _track_lines())
    ids = {line.split()[1] for line in _track_lines()}
    assert tracks.step_s == pytest.approx(0.4) and len(tracks.ids) == len(ids)


def test_a_folder_or_a_pipe_given_as_a_track_file_is_named_so(tmp_path):
    import os

    from pipeline.errors import TrackFileError

    (tmp_path / "planted.txt.gz").mkdir()
    from types import SimpleNamespace

    from pipeline.loop.pedestrians import scene_path

    cfg = SimpleNamespace(data_dir=str(tmp_path), seconds_per_frame=0.04)
    with pytest.raises(TrackFileError, match=r"planted\.txt\.gz: a folder"):
        scene_path(cfg, "planted")  # type: ignore[arg-type]
    os.rmdir(tmp_path / "planted.txt.gz")
    os.mkfifo(tmp_path / "planted.txt")
    with pytest.raises(TrackFileError, match=r"planted\.txt: not a regular file"):
        scene_path(cfg, "planted")  # type: ignore[arg-type]
