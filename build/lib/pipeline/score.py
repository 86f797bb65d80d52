"""Score any trajectory CSV with the Table 1 metrics: ``python -m pipeline.score FILE.csv``.

A thin entry: the work is in :mod:`pipeline.studies.score`.
"""

from __future__ import annotations

import sys

from pipeline.studies.score import main

__all__ = ['main']

if __name__ == "__main__":
    sys.exit(main())
