"""Build the HTML report from run folders: ``python -m pipeline.report RUNS [--out DIR]``.

A thin entry: the work is in :mod:`pipeline.reporting.page`.
"""

from __future__ import annotations

import sys

from pipeline.reporting.page import build_report, main

__all__ = ['build_report', 'main']

if __name__ == "__main__":
    sys.exit(main())
