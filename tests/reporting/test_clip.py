"""A member as an animated GIF (issue 61, item 6): ``apf-mpc clip <experiment>/<member>``
(``make clip MEMBER=...``) writes the frames asked for at the rate asked for, every method in
its report colour; bad input is one line naming the argument and what is allowed."""

from __future__ import annotations

import numpy as np
import pytest
from PIL import Image

from pipeline.cli import main
from pipeline.methods import method_info
from pipeline.reporting.clip import clip_frames, clip_name

STEPS = 31  # scenario.n_steps=30: 31 rows


@pytest.mark.parametrize("steps, stride, expected", [
    (31, 1, list(range(31))), (31, 2, list(range(0, 31, 2))), (31, 4, [*range(0, 31, 4), 30]),
    (1, 5, [0])])
def test_the_frames_are_every_strideth_step_and_the_last(steps, stride, expected):
    assert clip_frames(steps, stride) == expected


@pytest.fixture(scope="module")
def outputs(tmp_path_factory):
    """improved and the baseline on the paper scenario, 30 steps each."""
    from hydra import compose, initialize_config_dir

    from pipeline.config import CONF_DIR, register_configs, to_experiment_config
    from pipeline.studies.experiment import run_experiment

    register_configs()
    root = tmp_path_factory.mktemp("outputs")
    for method in ("baseline", "improved"):
        with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
            cfg = to_experiment_config(compose(config_name="config", overrides=[
                f"method={method}", "scenario.n_steps=30"]))
        run_experiment(cfg, root / "paper" / method)
    return root


def _closest(frame: Image.Image, hex_color: str) -> float:
    """The distance (0-441) from ``hex_color`` to the nearest colour the frame holds."""
    target = np.array([int(hex_color[i:i + 2], 16) for i in (1, 3, 5)], float)
    pixels = np.asarray(frame.convert("RGB"), float).reshape(-1, 3)
    return float(np.min(np.linalg.norm(pixels - target, axis=1)))


def test_a_clip_has_its_frames_its_rate_and_each_methods_colour(outputs, tmp_path, capsys):
    out = tmp_path / "clips" / clip_name("paper", 0)
    assert main(["clip", "paper/0", "--outputs", str(outputs), "--out", str(out),
                 "--fps", "5", "--stride", "2"]) == 0
    assert "16 frames" in capsys.readouterr().out
    with Image.open(out) as gif:
        assert gif.n_frames == len(clip_frames(STEPS, 2)) == 16
        assert gif.info["duration"] == 200  # ms per frame at 5 fps
        gif.seek(gif.n_frames - 1)
        last = gif.copy()
    for method in ("baseline", "improved"):
        assert _closest(last, method_info(method).color) < 12, method
    assert not list(out.parent.glob("*.partial*"))


@pytest.mark.parametrize("argv, fragment", [
    (["paper/7"], "allowed: 0"),
    (["nowhere/0"], "no experiment 'nowhere'"),
    (["paper"], "<experiment>/<index>"),
    (["paper/0", "--fps", "0"], "--fps: 0"),
    (["paper/0", "--stride", "101"], "[1, 100]"),
    (["paper/0", "--out", "x.png"], "ending in .gif"),
])
def test_bad_input_is_one_line_naming_what_is_allowed(outputs, tmp_path, capsys, argv, fragment):
    argv = [*argv, "--outputs", str(outputs)]
    if "--out" not in argv:
        argv += ["--out", str(tmp_path / "c.gif")]
    assert main(["clip", *argv]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and fragment in err[0], err
    assert not (tmp_path / "c.gif").exists()


def test_the_explorer_links_each_member_to_its_clip():
    """The explorer's link is the file ``make clip`` writes (the page builds it per member)."""
    from pipeline.reporting.explorer import ExplorerIndex, explorer_page

    page = explorer_page(ExplorerIndex())
    assert 'id="clip"' in page and '"clips/" + key.replace("/", "_") + ".gif"' in page
    assert clip_name("family", 113) == "family_113.gif"


def test_the_member_list_sorts_by_treatment_minus_first_control():
    """The explorer's difference column: the registry's treatment and first control (by
    run.order), whatever order the experiment lists its methods in."""
    from pipeline.reporting.explorer import difference_pair

    assert difference_pair(["apf_pursuit", "baseline", "baseline_matched", "improved"]) == \
        ["improved", "baseline"]
    assert difference_pair(["x_own", "y_own"]) == ["x_own", "y_own"]
