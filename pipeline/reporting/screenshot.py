"""The README's screenshots, taken from a report in headless Chromium (``make screenshot``,
``python -m pipeline.screenshot``).

:func:`take_screenshot` opens the page at a given viewport and saves its first screen (the top
of the page as a reader first sees it: the answer in words beside its figure at 1280 px, the
answer in words at 390 px). :func:`take_explorer_screenshot` opens the scenario explorer at one
member, scrubs to a step and saves the scenes and their signal plots. Both need Playwright (the
test extras) and a Chromium (Debian's ``chromium``, or Playwright's own).
"""

from __future__ import annotations

import shutil
from pathlib import Path

#: Chromium's switches for a headless run in a container (no sandbox, no GPU).
CHROMIUM_ARGS = ["--no-sandbox", "--disable-gpu"]


def _launch(pw):
    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    return pw.chromium.launch(executable_path=chromium, args=CHROMIUM_ARGS)


def take_screenshot(report: Path, out: Path, width: int = 1280, height: int = 800) -> Path:
    """Save the first ``width`` x ``height`` pixels of ``report`` (scrolled to its top) as
    ``out`` (PNG)."""
    from playwright.sync_api import sync_playwright

    out.parent.mkdir(parents=True, exist_ok=True)
    with sync_playwright() as pw:
        browser = _launch(pw)
        page = browser.new_page(viewport={"width": width, "height": height})
        page.goto(Path(report).resolve().as_uri())
        page.wait_for_load_state("load")
        page.evaluate("window.scrollTo(0, 0)")
        page.screenshot(path=str(out))
        browser.close()
    return out


def take_explorer_screenshot(explorer: Path, out: Path, key: str = "family/0",
                             step_share: float = 0.4, width: int = 1280,
                             height: int = 900) -> Path:
    """Save the scenario explorer (``explorer.html``) at member ``key``
    (``<experiment>/<member>``), scrubbed to ``step_share`` of the run, as ``out`` (PNG).

    Raises
    ------
    ValueError
        When ``step_share`` is outside [0, 1].
    """
    if not 0.0 <= step_share <= 1.0:
        raise ValueError(f"step_share must be in [0, 1], got {step_share}")
    from playwright.sync_api import sync_playwright

    out.parent.mkdir(parents=True, exist_ok=True)
    with sync_playwright() as pw:
        browser = _launch(pw)
        page = browser.new_page(viewport={"width": width, "height": height})
        page.goto(Path(explorer).resolve().as_uri() + "#" + key)
        page.wait_for_function("window.explorer && window.explorer.data !== null && "
                               f"window.explorer.key === '{key}'", timeout=30_000)
        page.evaluate("share => { const r = document.getElementById('scrub'); "
                      "r.value = Math.round(share * (window.explorer.steps - 1)); "
                      "r.dispatchEvent(new Event('input')); }", step_share)
        page.screenshot(path=str(out))
        browser.close()
    return out
