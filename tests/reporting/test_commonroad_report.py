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
    assert "agreed on every" in html and "(80/80)" in html


def test_the_verdict_is_ours_on_the_true_shapes_and_the_discs_stand_beside_it(tmp_path):
    """A run whose covers touched for 5 steps while the true shapes stayed apart: its verdict
    is no collision, the discs' 5 steps shown beside it and counted among the runs whose disc
    steps differ; a result written before the true-shape check keeps the disc verdict."""
    verdicts = {"steps": 80, "ours_collision": True, "ours_collision_steps": 5,
                "ours_true_shapes_collision": False, "ours_true_shapes_collision_steps": 0,
                "agreement_ours_true_shapes_steps": 80,
                "checker_same_geometry_collision": True,
                "checker_true_shapes_collision": False,
                "agreement_same_geometry_steps": 80, "agreement_true_shapes_steps": 75,
                "off_road_steps": 0, "goal_reached_commonroad": True, "success": True}
    touching = {**verdicts, "ours_true_shapes_collision": True,
                "ours_true_shapes_collision_steps": 5, "checker_true_shapes_collision": True,
                "success": False}
    for method, v in (("improved", verdicts), ("baseline", touching)):
        summary = {"file": {"benchmark_id": "ZAM_Planted-1", "obstacles": 1},
                   "run": {"method": method, "speed_mps": 10.0, "goal_reached_ours": True},
                   "verdicts": v}
        CommonRoadResult(summary).write(tmp_path / "ZAM_Planted-1" / method,
                                        lambda path: path.write_text("<x/>"))
    section = commonroad_section(SimpleNamespace(
        commonroad=tuple(CommonRoadResult.load_all(tmp_path))))
    assert [(r.method, r.collision, r.collision_ours, r.contact_steps_true_shapes,
             r.contact_steps_discs) for r in section.rows] == \
        [("baseline", True, True, 5, 5), ("improved", False, True, 0, 5)]
    assert section.disc_steps_differ == (1, 2) and section.true_shapes_agree_everywhere
    html = environment().get_template("sections/commonroad.html.j2").render(
        commonroad=section)
    assert "<td>no (0; 80/80)</td><td>no</td><td>yes (5)</td>" in html
    assert "other steps in contact than the true shapes in 1 of 2 runs" in html
    earlier = {**verdicts}
    for key in ("ours_true_shapes_collision", "ours_true_shapes_collision_steps",
                "agreement_ours_true_shapes_steps", "ours_collision_steps"):
        earlier.pop(key)
    old, = commonroad_section(SimpleNamespace(commonroad=(SimpleNamespace(
        summary={"file": {"benchmark_id": "x", "obstacles": 1},
                 "run": {"method": "improved", "goal_reached_ours": True},
                 "verdicts": earlier}, folder=None),))).rows
    assert (old.collision, old.contact_steps_discs) == (True, None)


def test_the_files_criterion_the_shapes_and_why_the_goals_differ_are_shown(tmp_path):
    """A result of the cover reading: named by its file's stem with its benchmark id beside,
    the shapes read, success by the file's criterion (its goal, no contact on the true
    shapes), the least true gap and the reason the goals differ."""
    summary = {
        "file": {"path": "scenes/DEU_Crit-1_1_T-1.xml", "benchmark_id": "DEU_Test-1_1_T-1",
                 "obstacles": 2, "obstacle_discs": 6, "obstacle_disc": "cover",
                 "cover_discs": 3},
        "run": {"method": "improved", "speed_mps": 10.0, "goal_reached_ours": True},
        "verdicts": {"steps": 80, "ours_collision": False,
                     "checker_same_geometry_collision": False,
                     "checker_true_shapes_collision": False,
                     "agreement_same_geometry_steps": 80, "agreement_true_shapes_steps": 80,
                     "off_road_steps": 7, "off_road_steps_before_contact": 2,
                     "goal_reached_commonroad": False, "success": False,
                     "min_clearance_true_shapes_m": 1.25,
                     "goal_disagreement": "inside the goal area on time steps 40-44, never "
                                          "within its time_step interval"}}
    CommonRoadResult(summary).write(tmp_path / "DEU_Crit-1_1_T-1" / "improved",
                                    lambda path: path.write_text("<x/>"))
    section = commonroad_section(SimpleNamespace(
        commonroad=tuple(CommonRoadResult.load_all(tmp_path))))
    row, = section.rows
    assert row.scenario == "DEU_Crit-1_1_T-1 (id DEU_Test-1_1_T-1)"
    assert (row.shapes, row.success, row.min_clearance_true_shapes_m) == \
        ("cover (3 discs)", False, 1.25)
    assert (row.off_road_steps_before_contact, row.off_road_steps) == (2, 7)
    html = environment().get_template("sections/commonroad.html.j2").render(
        commonroad=section)
    assert "never within its time_step interval" in html and ">1.25<" in html
    assert '<td class="num">2</td><td class="num">7</td>' in html
    # a result written before the count: shown as not known, the whole run's count beside
    earlier = {**summary, "verdicts": {k: v for k, v in summary["verdicts"].items()
                                       if k != "off_road_steps_before_contact"}}
    old, = commonroad_section(SimpleNamespace(
        commonroad=(SimpleNamespace(summary=earlier, folder=None),))).rows
    assert (old.off_road_steps_before_contact, old.off_road_steps) == (None, 7)


def test_a_disagreement_on_the_same_discs_is_said_and_no_runs_no_section(tmp_path):
    _result(tmp_path / "ZAM_Planted-1" / "improved", "improved", 79, False)
    section = commonroad_section(SimpleNamespace(
        commonroad=tuple(CommonRoadResult.load_all(tmp_path))))
    assert section is not None and not section.discs_agree_everywhere
    html = environment().get_template("sections/commonroad.html.j2").render(
        commonroad=section)
    assert "disagreed on some" in html and "79/80" in html
    assert commonroad_section(SimpleNamespace(commonroad=())) is None


def test_success_is_the_files_goal_without_contact_by_our_true_shape_verdict():
    """A run whose covers touched for 3 steps while the true shapes stayed apart reached the
    file's goal: success; a contact on the true shapes, or no goal, is none."""
    from pipeline.analysis.commonroad_check import CommonRoadVerdicts

    def verdicts(true_steps: int, goal: bool) -> CommonRoadVerdicts:
        return CommonRoadVerdicts(
            steps=40, ours_collision_steps=3, checker_same_geometry_collision_steps=3,
            checker_true_shapes_collision_steps=true_steps, agreement_same_geometry_steps=40,
            agreement_true_shapes_steps=37, min_clearance_ours_m=-0.1,
            min_clearance_true_shapes_m=0.2 if not true_steps else 0.0, off_road_steps=0,
            goal_reached_commonroad=goal, goal_time_step=30, goal_note="",
            ours_true_shapes_collision_steps=true_steps,
            agreement_ours_true_shapes_steps=40)

    assert verdicts(0, True).success and verdicts(0, True).ours_collision
    assert not verdicts(2, True).success and not verdicts(0, False).success
    assert verdicts(0, True).to_json()["success"] is True
