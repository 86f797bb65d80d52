"""The scenario explorer in a real browser: headless Chromium (Debian's) driven by Playwright,
the page opened from ``file://`` with every other request refused.

CI installs Chromium (`.ci/run`); elsewhere the test is skipped when no Chromium is found,
except under CI=true, where a missing browser is a failure.
"""

from __future__ import annotations

import os
import shutil

import pytest

from pipeline.reporting.explorer import explorer_href, write_explorer
from pipeline.studies.experiment import run_experiment, run_family

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
CHROMIUM_ARGS = ["--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                 "--disable-background-networking", "--disable-component-update",
                 "--disable-sync"]

if CHROMIUM is None:
    if os.environ.get("CI") == "true":
        raise RuntimeError("CI needs Debian's chromium for the browser test (.ci/run installs it)")
    pytest.skip("no chromium on this machine", allow_module_level=True)

STEP = "Number(document.querySelector('#panels').dataset.step)"


@pytest.fixture(scope="module")
def outputs(tmp_path_factory, make_config):
    """A family of four members (two methods) and the paper scenario."""
    root = tmp_path_factory.mktemp("outputs")
    for method in ("baseline", "improved"):
        run_family(make_config([f"method={method}", "scenario=family", "scenario.family.size=4",
                                "scenario.family.n_jobs=1"]), root / "family" / method,
                   progress=False)
    run_experiment(make_config(["method=improved"]), root / "paper" / "improved")
    return root


@pytest.fixture(scope="module")
def report(tmp_path_factory, outputs):
    """A small report folder: ``outputs``' explorer, an ``index.html`` that links member 3,
    and member 2's data file removed."""
    root = outputs
    out = tmp_path_factory.mktemp("report")
    write_explorer(root, out)
    (out / "index.html").write_text(
        f'<!doctype html><a id="watch" href="{explorer_href("family", 3)}">member 3</a>')
    (out / "explorer_data" / "family" / "2.js").unlink()
    return out


@pytest.fixture(scope="module")
def browser():
    from playwright.sync_api import sync_playwright

    with sync_playwright() as pw:
        chromium = pw.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        yield chromium
        chromium.close()


@pytest.fixture
def page(browser):
    """A page whose every request but ``file:`` and ``data:`` is refused (and recorded), its
    errors recorded."""
    context = browser.new_context(viewport={"width": 1280, "height": 900})
    page = context.new_page()
    page.refused, page.errors = [], []

    def refuse(route):
        if route.request.url.startswith(("file:", "data:", "blob:")):
            route.continue_()
        else:
            page.refused.append(route.request.url)
            route.abort()

    context.route("**/*", refuse)
    page.on("console", lambda m: page.errors.append(m.text) if m.type == "error" else None)
    page.on("pageerror", lambda e: page.errors.append(str(e)))
    yield page
    context.close()


def _open(page, report, key):
    page.goto((report / "explorer.html").as_uri() + "#" + key)
    page.wait_for_function("window.explorer && window.explorer.data !== null && "
                           f"window.explorer.key === '{key}'")


def test_play_advances_the_animation_and_pause_stops_it(page, report):
    _open(page, report, "paper/0")
    assert page.evaluate(STEP) == 0
    page.click("#play")
    page.wait_for_function(f"{STEP} >= 3")
    page.click("#play")  # the same button pauses
    paused = page.evaluate(STEP)
    assert page.evaluate("window.explorer.playing") is False
    page.wait_for_timeout(600)  # six steps' worth at 1x: nothing moves while paused
    assert page.evaluate(STEP) == paused
    # every method's scene shows the same step, and step buttons move it by one
    page.click("#forward")
    assert page.evaluate(STEP) == paused + 1
    assert page.evaluate("Array.from(document.querySelectorAll('canvas.scene'))"
                         ".map(c => Number(c.dataset.step))") == [paused + 1]
    assert page.errors == [] and page.refused == []


def test_scrubbing_moves_the_cursor_on_every_signal_plot(page, report):
    _open(page, report, "family/1")
    cursors = "Array.from(document.querySelectorAll('#signals canvas')).map(c => " \
              "Number(c.dataset.cursorX))"
    start = page.evaluate(cursors)
    assert len(start) == 3
    page.evaluate("s => { const r = document.getElementById('scrub'); r.value = s; "
                  "r.dispatchEvent(new Event('input')); }", "40")
    moved = page.evaluate(cursors)
    assert page.evaluate(STEP) == 40
    assert all(b > a + 50 for a, b in zip(start, moved, strict=True)), (start, moved)
    # a click on a plot puts the cursor (and the scenes) where it was clicked
    plot = page.locator("#signals canvas").first
    box = plot.bounding_box()
    left, right = (float(page.evaluate(f"document.querySelector('#signals canvas')"
                                       f".dataset.{side}")) for side in ("left", "right"))
    plot.click(position={"x": left + 0.25 * (right - left), "y": box["height"] / 2})
    steps = page.evaluate("window.explorer.steps")
    assert abs(page.evaluate(STEP) - 0.25 * (steps - 1)) <= 1  # a pixel of border
    assert page.evaluate(cursors)[0] == pytest.approx(left + 0.25 * (right - left), abs=3)
    assert page.errors == [] and page.refused == []


def test_a_link_opens_its_member_from_file_with_the_network_blocked(page, report):
    page.goto((report / "index.html").as_uri())
    page.click("#watch")
    page.wait_for_function("window.explorer && window.explorer.data !== null")
    assert page.evaluate("window.explorer.key") == "family/3"
    assert page.evaluate("window.explorer.data.member") == 3
    assert page.locator("#member").input_value() == "3"
    assert "member 3" in page.locator("#status").inner_text()
    # the member's clip: the file make clip MEMBER=family/3 writes beside the page
    assert page.locator("#clip").get_attribute("href") == "clips/family_3.gif"
    assert page.locator("canvas.scene").count() == 2  # baseline and improved side by side
    assert page.url.startswith("file://")
    assert page.errors == [] and page.refused == []


def test_a_member_without_its_data_file_says_so_in_one_line(page, report):
    page.goto((report / "explorer.html").as_uri() + "#family/2")
    page.wait_for_selector("#missing")
    text = page.locator("#missing").inner_text()
    assert text.count("\n") == 0
    assert "family/2" in text and "explorer_data/family/2.js" in text and "missing" in text
    # the page is still there: its controls, and another member opens from it
    assert page.locator("#play").is_visible()
    page.evaluate("location.hash = 'family/1'")
    page.wait_for_function("window.explorer.data !== null && window.explorer.key === 'family/1'")
    assert page.locator("#missing").count() == 0
    assert page.refused == []


def test_a_narrow_window_does_not_scroll_sideways(browser, report):
    page = browser.new_page(viewport={"width": 390, "height": 844})
    page.goto((report / "explorer.html").as_uri() + "#family/0")
    page.wait_for_function("window.explorer && window.explorer.data !== null")
    assert page.evaluate("document.documentElement.scrollWidth") <= 390
    assert page.locator("canvas.scene").first.bounding_box()["width"] <= 390
    page.close()


def test_the_finder_lists_the_members_a_method_collided_in_and_opens_one(page, report,
                                                                         outputs):
    """Filter "baseline did not collide", sorted by improved - baseline minimum clearance,
    largest first: the members and their order are those of the families' own tables; a
    row's click opens that member, whose numbers table shows each method's metrics.json."""
    import json

    import pandas as pd

    tables = {m: pd.read_csv(outputs / "family" / m / "family_metrics.csv").set_index("member")
              for m in ("baseline", "improved")}
    clear = [i for i in tables["baseline"].index if not bool(tables["baseline"].at[i, "collision"])]
    d = {i: tables["improved"].at[i, "min_clearance_m"] - tables["baseline"].at[i, "min_clearance_m"]
         for i in clear}
    expected = sorted(clear, key=lambda i: (-d[i], i))
    _open(page, report, "family/0")
    page.click("#finder summary")
    page.select_option("#filter", "baseline:clear")
    page.select_option("#sortby", "d:min_clearance_m")
    shown = [int(v) for v in page.eval_on_selector_all(
        "#members tbody tr", "rows => rows.map(r => r.dataset.member)")]
    assert shown == expected
    assert "improved − baseline" in page.locator("#members thead").inner_text()
    target = next(i for i in expected if i not in (0, 2))  # 2's data file is removed
    page.locator(f'#members tbody tr[data-member="{target}"]').click()
    page.wait_for_function(f"window.explorer.data && window.explorer.data.member === {target}")
    metrics = json.loads((outputs / "family" / "improved" / f"member_{target:04d}" /
                          "metrics.json").read_text())
    row = page.locator("#numbers tbody tr", has_text="improved").inner_text()
    assert f"{float(metrics['min_clearance_m']):.3g}" in row
    # each claim's name leads to its row of the family's ledger against the control
    assert page.locator("#numbers thead a", has_text="C1").get_attribute("href") == \
        "index.html#ledger-C1-baseline"
    legend = page.locator("#signal-legend").inner_text()
    assert "baseline" in legend and "improved" in legend
    assert page.errors == [] and page.refused == []


def test_the_time_step_is_kept_in_the_address(page, report):
    _open(page, report, "family/1")
    page.goto((report / "explorer.html").as_uri() + "#family/1@12")
    page.wait_for_function(f"{STEP} === 12")
    page.click("#forward")
    assert page.evaluate("location.hash") == "#family/1@13"
    page.reload()
    page.wait_for_function(f"window.explorer.data !== null && {STEP} === 13")
    assert page.errors == []
