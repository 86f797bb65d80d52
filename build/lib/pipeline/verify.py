"""Compare fresh results with ``reports/reference/``: ``python -m pipeline.verify RUNS REF``.

A thin entry: the work is in :mod:`pipeline.studies.verify`.
"""

from __future__ import annotations

import sys

from pipeline.studies.verify import main, verify

__all__ = ['main', 'verify']

if __name__ == "__main__":
    sys.exit(main())
