"""The report in a real browser: headless Chromium (Debian's) driven by Playwright.

CI installs Chromium (`.ci/run`); elsewhere the test is skipped when no Chromium is found,
except under CI=true, where a missing browser is a failure.
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import pytest

from pipeline.reporting.page import build_report
from pipeline.studies.experiment import run_experiment, run_family

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
CHROMIUM_ARGS = ["--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                 "--disable-background-networking", "--disable-component-update",
                 "--disable-sync"]
SCREENSHOT = Path(__file__).resolve().parents[2] / "reports" / "screenshots"

if CHROMIUM is None:
    if os.environ.get("CI") == "true":
        raise RuntimeError("CI needs Debian's chromium for the browser test (.ci/run installs it)")
    pytest.skip("no chromium on this machine", allow_module_level=True)


@pytest.fixture(scope="module")
def report(tmp_path_factory, make_config):
    root = tmp_path_factory.mktemp("outputs")
    for method in ("baseline", "baseline_matched", "improved"):
        run_experiment(make_config([f"method={method}"]), root / "paper" / method)
        run_experiment(make_config(["experiment=kinematic", f"planner={method}"]),
                       root / "kinematic" / method)
        run_family(make_config([f"method={method}", "scenario=family", "scenario.family.size=6",
                                "scenario.family.n_jobs=1"]),
                   root / "family" / method, progress=False)
    # extra runs, as the README's examples leave them: one sorts before the default one
    run_experiment(make_config(["method=baseline", "planner.rho0_m=3"]),
                   root / "examples" / "a_baseline_rho3")
    run_experiment(make_config(["method=improved", "planner.beta=1.0"]),
                   root / "examples" / "improved_beta1")
    from pipeline.multiverse import main as multiverse_main

    assert multiverse_main(["--space", "quick", "--out", str(root / "multiverse"),
                            "scenario.family.n_jobs=1"]) == 0
    return build_report(root, tmp_path_factory.mktemp("report"), "pytest")


TABLE_FIT = """() => Array.from(document.querySelectorAll('table')).map(t => {
    const box = t.parentElement;
    const cell = t.querySelector('tr:first-child > :last-child');
    box.scrollLeft = box.scrollWidth;
    const right = cell.getBoundingClientRect().right, edge = box.getBoundingClientRect().right;
    return {head: (t.querySelector('caption, th') || {}).textContent.slice(0, 40),
            fits: t.scrollWidth <= box.clientWidth + 1,
            scrolls: ['auto', 'scroll'].includes(getComputedStyle(box).overflowX),
            last_visible: right <= edge + 1};
})"""


def test_report_in_headless_chromium(report):
    from playwright.sync_api import sync_playwright

    console_errors, requests = [], []
    with sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        page = browser.new_page(viewport={"width": 1280, "height": 900})
        page.on("console", lambda m: console_errors.append(m.text) if m.type == "error" else None)
        page.on("pageerror", lambda e: console_errors.append(str(e)))
        page.on("request", lambda r: requests.append(r.url))
        page.goto(report.as_uri())
        page.wait_for_load_state("load")
        images = page.evaluate(
            "Array.from(document.images).map(i => [i.complete, i.naturalWidth, i.alt])")
        answer_box = page.locator("#answer").bounding_box()
        first_verdict = page.locator("#answer .verdict").first.bounding_box()
        answer_figure = page.locator("#answer-figure svg").bounding_box()
        figure_links = page.evaluate(
            "Array.from(document.querySelectorAll('#answer-figure svg a')).map(a => "
            "a.getAttribute('href'))")
        answer_text = page.locator("#answer").inner_text()
        # every section closed, its verdict line visible in its summary
        summaries = page.evaluate(
            "Array.from(document.querySelectorAll('details.section')).map(d => [d.id, d.open, "
            "(d.querySelector(':scope > summary .verdict-line') || {offsetHeight: 0})"
            ".offsetHeight])")
        toc = page.evaluate("Array.from(document.querySelectorAll('nav a')).map(a => "
                            "a.getAttribute('href').slice(1))")
        order = page.evaluate("Array.from(document.querySelectorAll('#answer, details.section'))"
                              ".map(e => e.id)")
        exploratory = page.evaluate("Array.from(document.querySelectorAll("
                                    "'details.exploratory')).map(d => d.id)")
        height_1280 = page.evaluate("document.documentElement.scrollHeight")
        SCREENSHOT.mkdir(parents=True, exist_ok=True)
        page.screenshot(path=str(SCREENSHOT / "report_top.png"))
        # a link into a closed section opens it
        page.goto(report.as_uri() + "#fig-trajectory_pair")
        page.wait_for_load_state("load")
        opened = page.evaluate("document.getElementById('paths').open")
        page.evaluate("document.querySelectorAll('details').forEach(d => d.open = true)")
        open_height_1280 = page.evaluate("document.documentElement.scrollHeight")
        verdict_cell = page.locator("#claims table.ledger td strong").first.bounding_box()
        rendered = page.evaluate(
            "Array.from(document.querySelectorAll('figure img')).map(i => [i.alt, "
            "i.getBoundingClientRect().width, i.getBoundingClientRect().height])")
        page.screenshot(path=str(SCREENSHOT / "report_full.png"), full_page=True)
        wide_tables = page.evaluate(TABLE_FIT)
        features = page.locator("#figure-features").bounding_box()
        robustness_box = page.locator("#robustness-summary").bounding_box()
        trajectory_box = page.locator("#fig-trajectory_pair img").bounding_box()
        mover_links = page.evaluate(
            "Array.from(document.querySelectorAll('#claims .movers a')).map(a => "
            "a.getAttribute('href'))")
        # the contents' link to the register opens it on the appendix page
        page.goto(report.parent.joinpath("appendix.html").as_uri() + "#register")
        page.wait_for_load_state("load")
        appendix_register_open = page.evaluate("document.getElementById('register').open")
        appendix_back = page.evaluate(
            "document.querySelector('nav a').getAttribute('href')")
        narrow_appendix = browser.new_page(viewport={"width": 390, "height": 844})
        narrow_appendix.goto(report.parent.joinpath("appendix.html").as_uri())
        narrow_appendix.evaluate(
            "document.querySelectorAll('details').forEach(d => d.open = true)")
        appendix_overflow = narrow_appendix.evaluate("document.documentElement.scrollWidth")
        narrow = browser.new_page(viewport={"width": 390, "height": 844})
        narrow.goto(report.as_uri())
        narrow_verdict = narrow.locator("#answer .verdict").first.bounding_box()
        narrow.screenshot(path=str(SCREENSHOT / "report_top_390.png"))
        overflow = narrow.evaluate("document.documentElement.scrollWidth")
        narrow.evaluate("document.querySelectorAll('details').forEach(d => d.open = true)")
        # the family ledger's outcome column, scrolled to without moving sideways
        narrow.evaluate("document.querySelector('#claims table.ledger:not("
                        "#robustness-summary)').scrollIntoView()")
        outcome_box = narrow.locator(
            "#claims table.ledger:not(#robustness-summary) td strong").first.bounding_box()
        narrow_scroll_x = narrow.evaluate(
            "document.querySelector('#claims table.ledger:not(#robustness-summary)')"
            ".parentElement.scrollLeft")
        narrow_tables = narrow.evaluate(TABLE_FIT)
        # with every section open: the page never scrolls sideways, the answer figure's text
        # is drawn at 11 px or more (its size times the figure's scale), and a wide table's
        # first column stays in view when its box scrolls
        open_scroll_x = narrow.evaluate("document.documentElement.scrollWidth")
        answer_text_px = narrow.evaluate(
            "(() => { const svg = document.querySelector('#answer-figure svg');"
            " const scale = svg.getBoundingClientRect().width / svg.viewBox.baseVal.width;"
            " return Math.min(...[...svg.querySelectorAll('text')].map("
            "t => parseFloat(getComputedStyle(t).fontSize) * scale)); })()")
        sticky = narrow.evaluate(
            "[...document.querySelectorAll('.scroll > table')].every(t => { const c ="
            " t.querySelector('tbody tr > :first-child'); return !c ||"
            " getComputedStyle(c).position === 'sticky'; })")
        browser.close()
    assert len(images) >= 10
    assert all(complete and width > 0 and alt for complete, width, alt in images), images
    assert console_errors == []
    assert all(url.startswith(("file:", "data:")) for url in requests), requests
    # the answer in words, its first verdict and its figure are on the first screen at 1280 px
    assert answer_box is not None and first_verdict["y"] < 900
    assert answer_figure is not None and answer_figure["y"] < 900
    assert answer_figure["x"] > first_verdict["x"]  # beside the words, not below them
    # every interval of the figure leads to a scenario or to its ledger row
    assert figure_links and all(h.startswith(("explorer.html#family/", "#ledger-", "#"))
                                for h in figure_links)
    assert any(h.startswith("explorer.html#family/") for h in figure_links)
    assert "faster obstacle-avoidance response" in answer_text and "d = " in answer_text
    assert verdict_cell is not None
    # the extra runs: named in the opening box, never judged; every figure has its size
    assert "Runs judged:" in answer_text and "planner.rho0_m=3" in answer_text
    assert all(w > 200 and h > 100 for _, w, h in rendered), rendered
    # sections closed, each with a visible verdict line; the contents in reading order
    assert summaries and all(not is_open for _, is_open, _ in summaries)
    assert all(h > 0 for sid, _, h in summaries if sid not in ("series", "metrics")), summaries
    assert [t for t in toc if t in order] == order, (toc, order)
    # the quick multiverse is below the default space's budget: exploratory, off the answer
    assert exploratory == ["robustness"] and "multiverse:" not in answer_text
    assert robustness_box is not None  # in the ledger's section, marked exploratory
    assert "Exploratory, not in this answer" in answer_text
    # the page's height at 1280 px with its sections closed: this fixture's page measured
    # 10,103 px before the sections closed; make reproduce's report 9,430 px (2,650 after)
    assert height_1280 <= 8000, height_1280
    # with every section open, at most 25,000 px (issue 61; make reproduce's page: 24,509 px,
    # its reference material on the appendix page); the appendix's contents lead back
    assert open_height_1280 <= 25000, open_height_1280
    assert appendix_register_open and appendix_back == "index.html"
    assert appendix_overflow <= 390, appendix_overflow  # nothing scrolls sideways there either
    # at 390 px the answer's first verdict is on the first screen
    assert narrow_verdict is not None and narrow_verdict["y"] < 844
    # a narrow window does not scroll sideways (wide tables scroll inside their box), and the
    # ledger's outcome column is visible at 390 px without scrolling its table sideways
    assert overflow <= 390 and open_scroll_x <= 390
    assert answer_text_px >= 11, answer_text_px
    assert sticky
    assert narrow_scroll_x == 0 and outcome_box["x"] + outcome_box["width"] <= 390
    # at 1280 px no table hides a column; narrow, every table's last column is reachable in
    # its own scrolling box
    assert [t["head"] for t in wide_tables if not t["fits"]] == []
    assert [t["head"] for t in narrow_tables
            if not (t["fits"] or (t["scrolls"] and t["last_visible"]))] == []
    # the paper's described features beside the Figure 2/3 analogue, which is large
    assert opened and features is not None and trajectory_box["width"] >= 440
    assert features["x"] > trajectory_box["x"] or features["y"] < trajectory_box["y"] + \
        trajectory_box["height"] + 400
    # ledger rows link the members that move them most
    assert mover_links and all(h.startswith("explorer.html#family/") for h in mover_links)
