"""Report from real run folders: the HTML holds every section, inlined figures, the register."""

from __future__ import annotations

import re

import pytest

from pipeline.config import INTERPRETATION_REGISTER
from pipeline.report import main as report_main
from pipeline.reporting.page import build_report
from pipeline.studies.experiment import run_experiment


def test_report_from_runs(tmp_path, make_config):
    runs = tmp_path / "runs"
    for method in ("baseline", "improved"):
        run_experiment(make_config([f"planner={method}"]), runs / method)
    page = build_report(runs, tmp_path / "report", "pytest").read_text()
    # the reference material stands on the appendix page beside the report (issue 61)
    appendix = (tmp_path / "report" / "appendix.html").read_text()
    for anchor in ("claims", "paths", "series"):
        assert f'id="{anchor}"' in page and f'id="{anchor}"' not in appendix
    for anchor in ("metrics", "definitions", "register", "provenance"):
        assert f'id="{anchor}"' in appendix and f'id="{anchor}"' not in page
    images = re.findall(r'<img src="([^"]+)" alt="([^"]+)"', page)
    # the Figure 2/3 analogue pair, the overlay, the time series and the APF forces
    assert len(images) >= 4 and all(src.startswith("data:image/png;base64,") for src, _ in images)
    for entry in INTERPRETATION_REGISTER:
        assert entry.config_key in appendix
    claims_part = page[page.index('id="claims"'):page.index('id="table2"')]
    assert sorted(re.findall(r'<th scope="row">(C[0-5][ab]?)</th>', claims_part)) == [
        "C0", "C1", "C2", "C3a", "C3b", "C4", "C5"]
    assert 'id="table2"' in page and "Slow and aggressive curved avoidance" in page
    assert (tmp_path / "report" / "tables" / "metrics_paper_scenario.csv").is_file()
    assert (tmp_path / "report" / "figures" / "trajectory_pair.svg").is_file()
    # no docstring markup on either page (issue 61, item 7: ':class:' and ':func:' were shown)
    assert not re.findall(r":(?:class|func|mod|meth|data|attr):`", page + appendix)


def test_report_without_runs_is_a_clear_error(tmp_path, capsys):
    assert report_main([str(tmp_path / "nothing")]) == 2
    assert "no complete run folders" in capsys.readouterr().err


def test_extra_runs_never_replace_the_default_ones(tmp_path, make_config):
    """A run folder holding make reproduce's runs plus extra runs of one method (as the README's
    example commands leave them): the claims judge the run make reproduce wrote, whatever the
    sort order, and the opening box says which run was judged and which were left out."""
    import json

    from pipeline.studies.experiment import run_family

    runs = tmp_path / "outputs"
    for method in ("baseline", "improved"):
        run_experiment(make_config([f"method={method}"]), runs / "paper" / method)
        run_family(make_config([f"method={method}", "scenario=family",
                                "scenario.family.size=12", "scenario.family.n_jobs=1"]),
                   runs / "family" / method, progress=False)
    # sorts before paper/: an extra baseline run with another repulsion range
    run_experiment(make_config(["method=baseline", "planner.rho0_m=3"]),
                   runs / "aaa_runs" / "baseline_rho3")
    page = build_report(runs, tmp_path / "report", "pytest").read_text()
    default = json.loads((runs / "paper" / "baseline" / "metrics.json").read_text())
    extra = json.loads((runs / "aaa_runs" / "baseline_rho3" / "metrics.json").read_text())
    assert default["min_clearance_m"] != extra["min_clearance_m"]
    import pandas as pd

    claims = pd.read_csv(tmp_path / "report" / "tables" / "claims_paper_scenario.csv")
    c0 = claims[claims["claim"] == "C1"].iloc[0]
    assert float(c0["baseline"]) == default["reaction_delay_s"]
    box = page[page.index('id="answer"'):]
    box = box[:box.index("</div>")]
    assert "Runs judged:" in box and "the run make reproduce wrote" in box
    assert "planner.rho0_m=3" in box


def test_figure_2_3_analogue_labels_never_overlap(make_config):
    """The Figure 2/3 analogue on a three-obstacle family member and on the paper scenario:
    the labels (where the obstacle appears, the closest approach) of one panel never overlap,
    by their bounding boxes from matplotlib's renderer; the panels share equal-scale axes."""
    import dataclasses

    from pipeline.loop.scenario import build_scenario, family_members
    from pipeline.loop.simulate import simulate
    from pipeline.reporting.figures import closest_approach, paths_figure

    family = make_config(["scenario=family", "scenario.family.size=12"])
    members = family_members(family.scenario, family.vehicle.footprint_radius_m)
    busy = next(m for m in members if len(m.obstacles) == 3)
    for scenario_cfg in (make_config().scenario, busy):
        runs = {}
        for method in ("baseline", "improved"):
            cfg = dataclasses.replace(make_config([f"method={method}"]), scenario=scenario_cfg)
            runs[method] = simulate(cfg, build_scenario(scenario_cfg)).trajectory
        appear = scenario_cfg.obstacles[0].appear_time_s
        fig = paths_figure(runs, tuple(scenario_cfg.goal_xy_m), 1.0, appear)
        fig.canvas.draw()
        renderer = fig.canvas.get_renderer()
        axes = [ax for ax in fig.axes if ax.get_title(loc="left")]
        assert len(axes) == 2
        assert axes[0].get_xlim() == axes[1].get_xlim()
        assert axes[0].get_aspect() == 1.0
        for ax in axes:
            labels = [t for t in ax.texts if (t.get_gid() or "").startswith("label-")]
            assert {t.get_gid() for t in labels} == {"label-appear", "label-closest"}
            boxes = [t.get_window_extent(renderer) for t in labels]
            for i in range(len(boxes)):
                for j in range(i + 1, len(boxes)):
                    assert not boxes[i].overlaps(boxes[j]), [t.get_text() for t in labels]
        # the closest-approach label quotes the clearance computed from the log
        near = closest_approach(runs["improved"], 1.0)
        text = next(t.get_text() for t in axes[1].texts if t.get_gid() == "label-closest")
        assert f"{near['clearance_m']:.2f} m" in text


def test_the_figure_style_sets_size_format_and_font(tmp_path, make_config, capsys):
    """--figure-style paper: PDF beside a 300-dpi PNG, every figure 7 in wide (2100 px), serif
    text; the default: SVG and a 130-dpi PNG; a misspelled key or a value out of range exits 2
    with one line naming it."""
    from PIL import Image

    from pipeline.report import main

    runs = tmp_path / "runs"
    for method in ("baseline", "improved"):
        run_experiment(make_config([f"method={method}"]), runs / "paper" / method)
    assert main([str(runs), "--out", str(tmp_path / "plain")]) == 0
    assert main([str(runs), "--out", str(tmp_path / "paper"), "--figure-style", "paper"]) == 0
    plain, paper = tmp_path / "plain" / "figures", tmp_path / "paper" / "figures"
    assert (plain / "overlay.svg").is_file() and not (plain / "overlay.pdf").exists()
    assert (paper / "overlay.pdf").read_bytes().startswith(b"%PDF")
    assert Image.open(paper / "overlay.png").size[0] == 2100
    assert Image.open(paper / "timeseries.png").size[0] == 2100
    assert Image.open(plain / "overlay.png").size[0] == 910
    pdf = (paper / "overlay.pdf").read_bytes()
    assert b"DejaVuSerif" in pdf and b"/FontFile2" in pdf  # serif, embedded as TrueType
    svg = (plain / "overlay.svg").read_text()
    assert "<text" in svg and "DejaVu Sans" in svg  # text stays text in the default SVG
    assert 'href="figures/overlay.pdf"' in (tmp_path / "paper" / "index.html").read_text()
    bad = tmp_path / "bad.yaml"
    bad.write_text("dpi: 300\nfontsize: 9\n")
    capsys.readouterr()
    assert main([str(runs), "--out", str(tmp_path / "bad"), "--figure-style", str(bad)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "figure_style.fontsize" in err[0]
    bad.write_text("vector_format: eps\n")
    assert main([str(runs), "--out", str(tmp_path / "bad"), "--figure-style", str(bad)]) == 2
    assert "figure_style.vector_format" in capsys.readouterr().err


def _two_figures():
    import matplotlib.pyplot as plt

    figures = []
    for k in (1, 2):
        fig, ax = plt.subplots(figsize=(3, 2), layout="constrained")
        ax.plot([0, 1, 2], [0, k, k * k], label=f"k={k}")
        ax.legend()
        figures.append(fig)
    return figures


def test_figure_writer_draws_in_children_the_same_files(tmp_path):
    """Figures written by forked children are byte for byte the ones written in this process
    (PNG), the paths are returned at once and the files exist after close; one writer slot
    draws everything here."""
    from pipeline.reporting.figures import FigureWriter, save_figure

    serial = [save_figure(fig, tmp_path / "serial", f"f{i}")
              for i, fig in enumerate(_two_figures())]
    with FigureWriter(max_workers=2) as writer:
        forked = [writer.save(fig, tmp_path / "forked", f"f{i}")
                  for i, fig in enumerate(_two_figures())]
    assert writer.forked == 2 and writer.written_here == 0
    for a, b in zip(serial, forked, strict=True):
        assert a["png"].read_bytes() == b["png"].read_bytes()
        assert b["svg"].is_file() and b["svg"].stat().st_size > 1000
    one = FigureWriter(max_workers=1)
    one.save(_two_figures()[0], tmp_path / "one", "f0")
    assert one.forked == 0 and one.written_here == 1
    assert (tmp_path / "one" / "f0.png").read_bytes() == serial[0]["png"].read_bytes()
    # a function that builds the figure: built and drawn in the child, the same file
    with FigureWriter(max_workers=2) as built:
        path = built.save(lambda: _two_figures()[1], tmp_path / "built", "f1")["png"]
    assert built.forked == 1 and path.read_bytes() == serial[1]["png"].read_bytes()


def test_figure_writer_redraws_what_a_dead_child_left(tmp_path, monkeypatch):
    """A child that dies (killed here while it hangs) leaves its figure, given as a Figure or as
    a function building one, to the writer's own process: the files are complete after close,
    and the fallbacks are counted."""
    import os
    import signal
    import time

    import pipeline.reporting.figures.writer as figures
    from pipeline.reporting.figures import FigureWriter, save_figure

    expected = save_figure(_two_figures()[0], tmp_path / "serial", "f0")["png"].read_bytes()
    parent = os.getpid()

    def hangs_in_a_child(fig, out_dir, stem, style=None):
        if os.getpid() != parent:
            time.sleep(60)  # killed before it wakes
        return save_figure(fig, out_dir, stem, style)

    monkeypatch.setattr(figures, "save_figure", hangs_in_a_child)
    writer = FigureWriter(max_workers=2)
    paths = writer.save(_two_figures()[0], tmp_path / "killed", "f0")
    os.kill(writer._running[-1][0], signal.SIGKILL)
    built = writer.save(lambda: _two_figures()[0], tmp_path / "killed", "built")
    os.kill(writer._running[-1][0], signal.SIGKILL)
    writer.close()
    assert writer.forked == 2 and writer.written_here == 2
    assert paths["png"].read_bytes() == expected == built["png"].read_bytes()
    # leaving a with block on an error (or Ctrl-C): the children are waited for, nothing redrawn
    with pytest.raises(KeyboardInterrupt), FigureWriter(max_workers=2) as stopped:
        stopped.save(_two_figures()[0], tmp_path / "stopped", "f0")
        os.kill(stopped._running[-1][0], signal.SIGKILL)
        raise KeyboardInterrupt
    assert stopped.forked == 1 and stopped.written_here == 0 and not stopped._running
    assert not (tmp_path / "stopped" / "f0.png").exists()


def test_report_figure_jobs_switch(tmp_path, make_config, monkeypatch):
    """--figure-jobs 1 draws every figure in the report's own process (no fork); by default the
    figures are drawn in children; an out-of-range value is refused in one line."""
    import os

    runs = tmp_path / "runs"
    for method in ("baseline", "improved"):
        run_experiment(make_config([f"planner={method}"]), runs / method)
    forks = []
    real_fork = os.fork

    def counting_fork():
        forks.append(1)
        return real_fork()

    monkeypatch.setattr(os, "fork", counting_fork)
    assert report_main([str(runs), "--out", str(tmp_path / "serial"), "--figure-jobs", "1"]) == 0
    assert forks == []
    assert report_main([str(runs), "--out", str(tmp_path / "forked"), "--figure-jobs", "2"]) == 0
    assert len(forks) >= 4
    for name in ("trajectory_pair.png", "overlay.png"):
        assert (tmp_path / "serial" / "figures" / name).read_bytes() == \
            (tmp_path / "forked" / "figures" / name).read_bytes()
    assert report_main([str(runs), "--out", str(tmp_path / "bad"), "--figure-jobs", "0"]) == 2


def test_the_register_page_is_the_register_itself():
    """docs/register.md is written from pipeline/register.py (``python -m pipeline.register``):
    it once lacked ten entries and stated two older readings."""
    from pathlib import Path

    from pipeline.register import register_markdown

    page = (Path(__file__).resolve().parents[2] / "docs" / "register.md").read_text()
    assert page == register_markdown()
    rows = [line for line in page.splitlines() if line.startswith("| ") and "---" not in line]
    assert len(rows) == len(INTERPRETATION_REGISTER) + 1  # the header
    assert "| `metrics.pass_reading` |" in page and "\\|d\\|" in page  # a cell's | escaped


def _failing_explorer(parent_pid, run_root, out_dir, experiments=None, jobs=None):
    import os

    where = "here" if os.getpid() == parent_pid else "in a child"
    raise ValueError(f"explorer failed {where}, jobs={jobs}")


@pytest.mark.parametrize("figure_jobs", [1, 2])
def test_an_explorer_that_fails_fails_the_report_after_the_page(small_reproduce, tmp_path,
                                                                monkeypatch, figure_jobs):
    """The explorer is written beside the page (a forked child) or here (figure_jobs 1): what
    it raises reaches the caller either way, and the page is written all the same."""
    import functools
    import os

    import pipeline.reporting.page as page

    monkeypatch.setattr(page, "write_explorer", functools.partial(_failing_explorer,
                                                                  os.getpid()))
    with pytest.raises(ValueError, match="explorer failed") as failed:
        build_report(small_reproduce, tmp_path / "report", "pytest", figure_jobs=figure_jobs)
    assert str(failed.value) == ("explorer failed here, jobs=1" if figure_jobs == 1
                                 else "explorer failed in a child, jobs=None")
    assert (tmp_path / "report" / "index.html").is_file()
