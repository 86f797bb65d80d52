"""The README's screenshot: ``apf-mpc-screenshot REPORT.html OUT.png`` (or
``python -m pipeline.screenshot``).

Opens the report in headless Chromium at 1280 x 800 and saves the top of it (the answer in
words and the start of the ledger) through :func:`pipeline.reporting.screenshot.take_screenshot`.
It needs Playwright (the test extras) and a Chromium (Debian's ``chromium``, or Playwright's).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from pipeline.commands import CommandError, run_command
from pipeline.reporting.screenshot import take_screenshot


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="apf-mpc-screenshot", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("report", type=Path, help="the report's index.html")
    parser.add_argument("out", type=Path, help="the PNG to write")
    args = parser.parse_args(argv)
    return run_command(lambda: _screenshot(args.report, args.out))


def _screenshot(report: Path, out: Path) -> int:
    if not report.is_file():
        raise CommandError(f"error: no report at {report} (run make reproduce first)")
    try:
        take_screenshot(report, out)
    except ImportError:
        raise CommandError("error: the screenshot needs Playwright (pip install -e '.[test]')"
                           ) from None
    except Exception as exc:  # noqa: BLE001 - a browser that cannot start: one line
        raise CommandError(f"error: no screenshot ({type(exc).__name__}: "
                           f"{str(exc).splitlines()[0]})") from None
    print(f"screenshot written to {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
