"""The README's screenshots: ``apf-mpc screenshot REPORT.html OUT.png`` (or
``python -m pipeline.screenshot``).

Opens the report in headless Chromium at 1280 x 800 and saves its first screen (the answer in
words beside its figure) through :func:`pipeline.reporting.screenshot.take_screenshot`; with
``--narrow OUT390.png`` also the first screen at 390 x 844 (a phone), with ``--explorer
OUT.png`` the scenario explorer beside the report at ``--member`` (default ``family/0``).
It needs Playwright (the test extras) and a Chromium (Debian's ``chromium``, or Playwright's).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from pipeline.commands import CommandError, run_command
from pipeline.reporting.screenshot import take_explorer_screenshot, take_screenshot


def main(argv: list[str] | None = None) -> int:
    """``python -m pipeline.screenshot``: ``apf-mpc screenshot``."""
    from pipeline.cli import alias

    return alias("screenshot", argv)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """``apf-mpc screenshot``'s arguments."""
    parser.add_argument("report", type=Path, help="the report's index.html")
    parser.add_argument("out", type=Path, help="the PNG to write (first screen at 1280 px)")
    parser.add_argument("--narrow", type=Path, default=None,
                        help="also the first screen at 390 px, to this PNG")
    parser.add_argument("--explorer", type=Path, default=None,
                        help="also the scenario explorer at --member, to this PNG")
    parser.add_argument("--member", default="family/0",
                        help="the explorer's member, <experiment>/<index> (default family/0)")


def run(args: argparse.Namespace) -> int:
    """The screenshots ``args`` ask for, through the command layer."""
    return run_command(lambda: _screenshot(args.report, args.out, args.narrow, args.explorer,
                                           args.member))


def _screenshot(report: Path, out: Path, narrow: Path | None = None,
                explorer: Path | None = None, member: str = "family/0") -> int:
    if not report.is_file():
        raise CommandError(f"error: no report at {report} (run make reproduce first)")
    explorer_page = report.parent / "explorer.html"
    if explorer is not None and not explorer_page.is_file():
        raise CommandError(f"error: no scenario explorer at {explorer_page} (the report was "
                           "written without one)")
    experiment, _, index = member.partition("/")
    if not experiment or not (index.isascii() and index.isdigit()):
        raise CommandError(f"error: --member must be <experiment>/<index>, e.g. family/0; "
                           f"got {member!r}")
    if explorer is not None:
        _require_member(report.parent, experiment, int(index))
    try:
        take_screenshot(report, out)
        if narrow is not None:
            take_screenshot(report, narrow, width=390, height=844)
        if explorer is not None:
            take_explorer_screenshot(explorer_page, explorer, key=member)
    except ImportError:
        raise CommandError("error: the screenshot needs Playwright (pip install -e '.[test]')"
                           ) from None
    except Exception as exc:  # a browser that cannot start: one line
        raise CommandError(f"error: no screenshot ({type(exc).__name__}: "
                           f"{str(exc).splitlines()[0]})") from None
    for path in (out, narrow, explorer):
        if path is not None:
            print(f"screenshot written to {path}")
    return 0


def _require_member(report_dir: Path, experiment: str, index: int) -> None:
    """One line at once when the report's explorer has no data for the member (the browser
    once waited 30 s for it and ended in a Playwright TimeoutError)."""
    from pipeline.reporting.explorer import DATA_FOLDER

    data = report_dir / DATA_FOLDER
    if (data / experiment / f"{index}.js").is_file():
        return
    have = sorted(p.name for p in data.iterdir() if p.is_dir()) if data.is_dir() else []
    if experiment in have:
        members = sorted(int(p.stem) for p in (data / experiment).glob("*.js")
                         if p.stem.isdigit())
        shown = f"{experiment} has members {members[0]}-{members[-1]}" if members \
            else f"{experiment} has no members"
    else:
        shown = "experiments: " + (", ".join(have) or "none")
    raise CommandError(f"error: --member {experiment}/{index}: the report's explorer has no "
                       f"such member ({shown})")


if __name__ == "__main__":
    sys.exit(main())
