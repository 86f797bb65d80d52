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
SCREENSHOT = Path(__file__).resolve().parent.parent / "reports" / "screenshots"

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
        run_family(make_config([f"method={method}", "scenario=family", "scenario.family.size=6"]),
                   root / "family" / method, progress=False)
    from pipeline.studies.multiverse import main as multiverse_main

    assert multiverse_main(["--space", "quick", "--out", str(root / "multiverse")]) == 0
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
        claims_top = page.locator("#claims").bounding_box()["y"]
        verdict_cell = page.locator("#claims ~ div table td strong").first.bounding_box()
        SCREENSHOT.mkdir(parents=True, exist_ok=True)
        page.screenshot(path=str(SCREENSHOT / "report_full.png"), full_page=True)
        page.screenshot(path=str(SCREENSHOT / "report_top.png"))
        wide_tables = page.evaluate(TABLE_FIT)
        robustness_box = page.locator("#robustness-summary").bounding_box()
        trajectory_width = page.locator("#fig-trajectory_baseline img").bounding_box()["width"]
        narrow = browser.new_page(viewport={"width": 420, "height": 900})
        narrow.goto(report.as_uri())
        overflow = narrow.evaluate("document.documentElement.scrollWidth")
        narrow_tables = narrow.evaluate(TABLE_FIT)
        browser.close()
    assert len(images) >= 10
    assert all(complete and width > 0 and alt for complete, width, alt in images), images
    assert console_errors == []
    assert all(url.startswith(("file:", "data:")) for url in requests), requests
    # the claims section and its first verdict are on screen without scrolling
    assert claims_top < 900 and verdict_cell is not None and verdict_cell["y"] < 900
    # a narrow window does not scroll sideways (wide tables scroll inside their box)
    assert overflow <= 430
    # at 1280 px no table hides a column; narrow, every table's last column is reachable in
    # its own scrolling box
    assert [t["head"] for t in wide_tables if not t["fits"]] == []
    assert [t["head"] for t in narrow_tables
            if not (t["fits"] or (t["scrolls"] and t["last_visible"]))] == []
    # the first screen holds the robustness summary; the Figure 2/3 analogues are large
    assert robustness_box is not None and robustness_box["y"] < 900
    assert trajectory_width >= 540
