"""The report in a real browser: headless Chromium (Debian's) driven by Playwright.

CI installs Chromium (`.ci/run`); elsewhere the test is skipped when no Chromium is found,
except under CI=true, where a missing browser is a failure.
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import pytest

from pipeline.report import build_report
from pipeline.run import run_experiment, run_family

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
    return build_report(root, tmp_path_factory.mktemp("report"), "pytest")


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
        narrow = browser.new_page(viewport={"width": 420, "height": 900})
        narrow.goto(report.as_uri())
        overflow = narrow.evaluate("document.documentElement.scrollWidth")
        browser.close()
    assert len(images) >= 10
    assert all(complete and width > 0 and alt for complete, width, alt in images), images
    assert console_errors == []
    assert all(url.startswith(("file:", "data:")) for url in requests), requests
    # the claims section and its first verdict are on screen without scrolling
    assert claims_top < 900 and verdict_cell is not None and verdict_cell["y"] < 900
    # a narrow window does not scroll sideways (wide tables scroll inside their box)
    assert overflow <= 430
