"""The report for a first-time reader (issue 61, items 2, 3 and 5): the answer says when an
interval reaches into its claim's margin; every method and term the answer names is defined
on hover and in a glossary on the first screen; the scenario explorer is in the contents and on
the first screen, and every paper-scenario figure has a "watch it" link to a member the
explorer holds."""

from __future__ import annotations

import html
import json
import re

import pytest

from pipeline.methods import method_registry
from pipeline.reporting.sections.answer import TERMS, margin_reach, resolution_words

SIX = ["scenario.family.size=6", "scenario.family.n_jobs=1"]


@pytest.mark.parametrize("outcome, low, high, margin, reaches", [
    ("contradicted", 0.046, 0.069, 0.05, "worse"),     # C3a of make reproduce: 0.046 < 0.05
    ("supported", -0.111, -0.044, 0.05, "better"),     # the near end -0.044 is inside +-0.05
    ("contradicted", 0.20, 0.51, 0.1, ""),             # wholly beyond the margin
    ("supported", -0.562, -0.502, 0.1, ""),
    ("inconclusive", -0.02, 0.12, 0.02, ""),           # no direction to qualify
    ("equivalent", -0.01, 0.01, 0.5, ""),
    ("contradicted", 0.01, 0.2, 0.0, ""),              # no margin: nothing to reach into
])
def test_an_interval_reaching_into_the_margin_is_said(outcome, low, high, margin, reaches):
    row = {"outcome": outcome, "ci_low": low, "ci_high": high, "margin": margin}
    said = margin_reach(row)
    if not reaches:
        assert said == ""
        return
    nearer = low if abs(low) < abs(high) else high
    assert f"{reaches} than the control" in said and f"{nearer:.2g}" in said
    full = resolution_words({**row, "resolvable_effect": 0.015, "metric": "x", "n_pairs": 163})
    assert full.endswith(said)


def test_every_method_the_paper_or_we_add_says_what_it_is():
    """A method with a role (treatment, control, peer, reference) has its one sentence."""
    missing = [name for name, info in method_registry().items()
               if info.role and not info.description.strip()]
    assert missing == []


@pytest.fixture(scope="module")
def report(small_report):
    """The report of improved and the baseline on the paper scenario and a 6-member family
    (the session's :func:`small_report`)."""
    return small_report, (small_report / "index.html").read_text()


def test_every_name_of_the_answer_is_defined_on_hover_and_in_the_glossary(report):
    _, page = report
    answer = page[page.index('id="answer"'):page.index('<nav aria-label="Contents">')]
    glossary = answer[answer.index('id="glossary"'):]
    defined = {html.unescape(m) for m in re.findall(r"<dt>([^<]+)</dt>", glossary)}
    compared = set(re.findall(r'</span> vs (?:<abbr class="term" title="[^"]*">)?([a-z_]+)',
                              answer))
    assert compared and compared <= defined
    assert {"improved", "baseline"} <= defined
    assert {term for term, _ in TERMS} <= defined
    # hover: each comparison of a row carries its sentence
    for name in compared:
        title = re.search(rf'<abbr class="term" title="([^"]+)">{name}</abbr>', answer)
        assert title and method_registry()[name].description[:40] in html.unescape(title[1])


def test_the_explorer_is_in_the_contents_and_on_the_first_screen(report):
    out, page = report
    nav = page[page.index('<nav aria-label="Contents">'):page.index("</nav>")]
    assert '<a href="explorer.html">Scenario explorer' in nav
    answer = page[page.index('id="answer"'):page.index('<nav aria-label="Contents">')]
    assert re.search(r'id="explorer-link".*?href="explorer.html"', answer, re.S)
    assert (out / "explorer.html").is_file()


def test_every_paper_scenario_figure_links_to_a_member_the_explorer_holds(report):
    out, page = report
    explorer = (out / "explorer.html").read_text()
    index = json.loads(re.search(r"window.__explorerIndex = (\{.*?\});", explorer)[1])
    for anchor in ("paths", "series"):
        part = page[page.index(f'id="{anchor}"'):]
        part = part[:part.index("</details>")] if "</details>" in part else part
        captions = re.findall(r"<figcaption>(.*?)</figcaption>", part, re.S)
        assert captions
        for caption in captions:
            link = re.search(r'href="explorer.html#([a-z_]+)/(\d+)">watch it', caption)
            assert link, caption[-200:]
            assert int(link[2]) in index["experiments"][link[1]]["members"]


def test_a_config_is_shown_as_its_difference_from_the_reference():
    from pipeline.reporting.sections.paper import config_diff, flat_config

    reference = {"planner": {"name": "improved", "beta": 0.25, "step_max_m": 0.5},
                 "controller": {"horizon": 10, "weights": [1, 2]}, "run": {"seed": 0}}
    mine = {"planner": {"name": "baseline", "beta": 0.25},
            "controller": {"horizon": 10, "weights": [1, 3]}, "run": {"seed": 0},
            "extra": {"k": 1}}
    assert flat_config(reference)["planner.step_max_m"] == 0.5
    assert config_diff(mine, reference) == (
        ("planner.name", "baseline", "improved"), ("controller.weights", "[1, 3]", "[1, 2]"),
        ("extra.k", "1", "(none)"), ("planner.step_max_m", "(none)", "0.5"))
    assert config_diff(reference, reference) == ()


def test_the_register_shows_a_catalogue_by_its_margins_and_a_section_by_its_name():
    from pipeline.reporting.sections.methods import register_value

    catalogue = {"C0": {"margin": 0.02, "text": "long"}, "C1": {"margin": 0.05, "text": "x"}}
    assert register_value(catalogue) == "C0 0.02, C1 0.05"
    assert register_value({"name": "sidewalk_robot", "footprint_radius_m": 0.35}) == \
        "sidewalk_robot"
    assert register_value(0.5) == "0.5" and register_value(None) == "null (not set)"


def test_the_provenance_shows_diffs_and_links_every_whole_config(report):
    out, _ = report
    page = (out / "appendix.html").read_text()
    part = page[page.index('id="configs"'):]
    links = re.findall(r'<a href="(configs/[a-z_]+\.yaml)">', part[:part.index("</p>")])
    assert sorted(links) == ["configs/baseline.yaml", "configs/improved.yaml"]
    assert all((out / link).is_file() for link in links)
    assert "Resolved config" not in page and "<pre>" not in part
    diff = part[part.index("<table class=\"config-diff\">"):]
    diff = diff[:diff.index("</table>")]
    # one table: the reference's column, then each other method's; a method's name and
    # presentation (label, colour, ...) are no difference of what it ran
    assert re.findall(r'<th scope="col">([a-z_]+)</th>', diff) == ["key", "improved", "baseline"]
    assert "<code>planner.name</code>" in diff and "<code>planner.beta</code>" in diff
    assert "run.label" not in diff and "run.color" not in diff and "run.method" not in diff


def test_reference_material_stands_on_the_appendix_page_and_every_link_lands(report):
    """The definitions, compute, register, provenance and all-metrics table stand on
    appendix.html beside the report (issue 61: the open page's height), listed in the report's
    contents as places there; every in-page link of either page lands on an id of its page, and
    every link across lands on an id of the other."""
    from pipeline.reporting.contents import APPENDIX_PAGE

    out, page = report
    appendix = (out / APPENDIX_PAGE).read_text()

    def ids(text: str) -> set[str]:
        return set(re.findall(r'\bid="([^"]+)"', text))

    main_ids, appendix_ids = ids(page), ids(appendix)
    for anchor in ("definitions", "rules", "register", "provenance", "configs", "metrics"):
        assert anchor in appendix_ids and anchor not in main_ids, anchor
    for anchor in ("answer", "claims", "paths", "series", "family"):
        assert anchor in main_ids and anchor not in appendix_ids, anchor
    contents = page[page.index('<nav aria-label="Contents">'):page.index("</nav>")]
    assert 'href="appendix.html#register"' in contents and 'href="#claims"' in contents
    assert 'href="index.html"' in appendix
    for text, own in ((page, main_ids), (appendix, appendix_ids)):
        assert set(re.findall(r'href="#([^"]+)"', text)) <= own
        assert set(re.findall(r'href="appendix\.html#([^"]+)"', text)) <= appendix_ids
        assert set(re.findall(r'href="index\.html#([^"]+)"', text)) <= main_ids


@pytest.mark.parametrize("args, text", [
    ((0.0, -3e-7, 4e-7, "s", 163, 160), "0 s in every resample (no spread, 160 of 163 pairs tied)"),
    ((-0.074, -0.111, -0.044, "s", 159, 0), "-0.074 [-0.111, -0.044] s"),
])
def test_an_interval_narrower_than_the_page_can_print_is_said_in_words(args, text):
    from pipeline.reporting.format import effect

    assert effect(*args) == text


def test_one_number_rule_for_p_values_overrides_and_units():
    from pipeline.reporting.format import override_value, p_value, unit

    assert p_value(6.33e-8) == "< 0.001" and p_value(0.0123) == "0.0123"
    assert p_value(None) == p_value(float("nan")) == "—"
    assert override_value(None) == "null" and override_value(True) == "true"
    assert override_value(0.5) == "0.5"
    assert unit("lateral_jerk_rms_mps3") == "m/s³"


def test_the_page_prints_no_python_none_no_six_zero_interval_and_no_caret_unit(report):
    _, page = report
    text = html.unescape(re.sub(r"<[^>]+>", " ", re.sub(
        r"<(script|svg)\b.*?</\1>", "", page[page.index("<body"):], flags=re.S)))
    assert not re.search(r"\bNone\b", text)
    assert "0.000000 [" not in text and "m/s^3" not in text
