"""The report's 'CommonRoad scenarios' section (issue 43), from results written by hand (needs
no optional extra): one row per run, both verdicts, and the sentence on the discs' agreement."""

from __future__ import annotations

from types import SimpleNamespace

from pipeline.reporting.render import environment
from pipeline.reporting.sections.commonroad import commonroad_section
from pipeline.studies.results.commonroad import CommonRoadResult


def _result(folder, method, agree_discs, true_collision):
    summary = {
        "file": {"benchmark_id": "ZAM_Planted-1", "obstacles": 2},
        "run": {"method": method, "speed_mps": 10.0, "goal_reached_ours": True},
        "verdicts": {"steps": 80, "ours_collision": True,
                     "checker_same_geometry_collision": True,
                     "checker_true_shapes_collision": true_collision,
                     "agreement_same_geometry_steps": agree_discs,
                     "agreement_true_shapes_steps": 77, "off_road_steps": 3,
                     "goal_reached_commonroad": False}}
    return CommonRoadResult(summary).write(folder, lambda path: path.write_text("<x/>"))


def test_the_section_lists_every_run_with_both_verdicts(tmp_path):
    _result(tmp_path / "ZAM_Planted-1" / "improved", "improved", 80, False)
    _result(tmp_path / "ZAM_Planted-1" / "baseline", "baseline", 80, True)
    results = CommonRoadResult.load_all(tmp_path)
    assert [r.summary["run"]["method"] for r in results] == ["baseline", "improved"]
    section = commonroad_section(SimpleNamespace(commonroad=tuple(results)))
    assert section is not None and section.discs_agree_everywhere
    assert [(r.method, r.collision_checker_true_shapes, r.agreement_discs, r.goal_commonroad)
            for r in section.rows] == [("baseline", True, "80/80", False),
                                       ("improved", False, "80/80", False)]
    html = environment().get_template("sections/commonroad.html.j2").render(
        commonroad=section)
    assert html.count("<tr><th scope=\"row\">ZAM_Planted-1</th>") == 2
    assert "agreed on every" in html and "77/80" in html


def test_a_disagreement_on_the_same_discs_is_said_and_no_runs_no_section(tmp_path):
    _result(tmp_path / "ZAM_Planted-1" / "improved", "improved", 79, False)
    section = commonroad_section(SimpleNamespace(
        commonroad=tuple(CommonRoadResult.load_all(tmp_path))))
    assert section is not None and not section.discs_agree_everywhere
    html = environment().get_template("sections/commonroad.html.j2").render(
        commonroad=section)
    assert "disagreed on some" in html and "79/80" in html
    assert commonroad_section(SimpleNamespace(commonroad=())) is None
