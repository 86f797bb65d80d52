"""The README's screenshot, taken from a report in headless Chromium (``make screenshot``,
``python -m pipeline.screenshot``).

:func:`take_screenshot` opens the page at 1280 x 800
and saves the top of it: the answer in words and the start of the ledger. It needs Playwright
(the test extras) and a Chromium (Debian's ``chromium``, or Playwright's own).
"""

from __future__ import annotations

import shutil
from pathlib import Path


def take_screenshot(report: Path, out: Path, width: int = 1280, height: int = 800) -> Path:
    """Save the top ``width`` x ``height`` pixels of ``report`` as ``out`` (PNG)."""
    from playwright.sync_api import sync_playwright

    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    out.parent.mkdir(parents=True, exist_ok=True)
    with sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=chromium,
                                     args=["--no-sandbox", "--disable-gpu"])
        page = browser.new_page(viewport={"width": width, "height": height})
        page.goto(Path(report).resolve().as_uri())
        page.wait_for_load_state("load")
        page.locator("#claims").scroll_into_view_if_needed()
        page.evaluate("window.scrollTo(0, document.querySelector('#claims').offsetTop - 10)")
        page.screenshot(path=str(out))
        browser.close()
    return out
