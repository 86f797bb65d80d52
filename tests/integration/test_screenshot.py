"""The README's screenshots (``make screenshot``): the first screen from the page's top at the
viewport asked for, and one-line refusals of what cannot be shot."""

from __future__ import annotations

import os
import shutil

import matplotlib.image as mpimg
import numpy as np
import pytest

from pipeline.screenshot import main

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")


def test_a_missing_report_or_a_bad_member_is_one_line(tmp_path, capsys):
    assert main([str(tmp_path / "none.html"), str(tmp_path / "out.png")]) != 0
    assert "no report at" in capsys.readouterr().err
    report = tmp_path / "index.html"
    report.write_text("<!doctype html><p>x</p>")
    assert main([str(report), str(tmp_path / "out.png"), "--member", "family"]) != 0
    err = capsys.readouterr().err
    assert "--member must be <experiment>/<index>" in err and "Traceback" not in err
    # an explorer screenshot of a report written without the explorer
    assert main([str(report), str(tmp_path / "out.png"), "--explorer",
                 str(tmp_path / "e.png")]) != 0
    assert "no scenario explorer" in capsys.readouterr().err
    assert not (tmp_path / "out.png").exists()
    # a member the explorer lacks: one line at once, naming what it has (no browser started)
    (tmp_path / "explorer.html").write_text("<!doctype html><p>explorer</p>")
    (tmp_path / "explorer_data" / "family").mkdir(parents=True)
    for i in range(3):
        (tmp_path / "explorer_data" / "family" / f"{i}.js").write_text("")
    for member, says in (("family/7", "family has members 0-2"),
                         ("peers/0", "experiments: family")):
        assert main([str(report), str(tmp_path / "out.png"), "--explorer",
                     str(tmp_path / "e.png"), "--member", member]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and f"--member {member}" in err[0] and says in err[0], err
    assert not (tmp_path / "out.png").exists()


@pytest.mark.skipif(CHROMIUM is None and os.environ.get("CI") != "true",
                    reason="no chromium on this machine")
def test_the_first_screen_is_the_pages_top_at_each_width(tmp_path):
    # red on top, an anchor named claims far below it in blue: the shot is the top
    report = tmp_path / "index.html"
    report.write_text('<!doctype html><body style="margin:0">'
                      '<div style="height:1200px;background:#ff0000"></div>'
                      '<div id="claims" style="height:3000px;background:#0000ff"></div>')
    wide, narrow = tmp_path / "wide.png", tmp_path / "narrow.png"
    assert main([str(report), str(wide), "--narrow", str(narrow)]) == 0
    for path, shape in ((wide, (800, 1280)), (narrow, (844, 390))):
        image = mpimg.imread(path)
        assert image.shape[:2] == shape
        np.testing.assert_allclose(image[shape[0] // 2, shape[1] // 2, :3], [1.0, 0.0, 0.0])
