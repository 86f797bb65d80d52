"""Report from real run folders: the HTML holds every section, inlined figures, the register."""

from __future__ import annotations

import re

from pipeline.config import INTERPRETATION_REGISTER
from pipeline.reporting.page import build_report, main as report_main
from pipeline.studies.experiment import run_experiment


def test_report_from_runs(tmp_path, make_config):
    runs = tmp_path / "runs"
    for method in ("baseline", "improved"):
        run_experiment(make_config([f"planner={method}"]), runs / method)
    page = build_report(runs, tmp_path / "report", "pytest").read_text()
    for anchor in ("claims", "paths", "series", "metrics", "definitions", "register",
                   "provenance"):
        assert f'id="{anchor}"' in page
    images = re.findall(r'<img src="([^"]+)" alt="([^"]+)"', page)
    assert len(images) >= 5 and all(src.startswith("data:image/png;base64,") for src, _ in images)
    for entry in INTERPRETATION_REGISTER:
        assert entry.config_key in page
    claims_part = page[page.index('id="claims"'):page.index('id="table2"')]
    assert sorted(re.findall(r'<th scope="row">(C[0-5][ab]?)</th>', claims_part)) == [
        "C0", "C1", "C2", "C3a", "C3b", "C4", "C5"]
    assert 'id="table2"' in page and "Slow and aggressive curved avoidance" in page
    assert (tmp_path / "report" / "tables" / "metrics_paper_scenario.csv").is_file()
    assert (tmp_path / "report" / "figures" / "trajectory_baseline.svg").is_file()


def test_report_without_runs_is_a_clear_error(tmp_path, capsys):
    assert report_main([str(tmp_path / "nothing")]) == 2
    assert "no complete run folders" in capsys.readouterr().err
