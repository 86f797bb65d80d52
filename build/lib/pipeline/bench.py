"""Benchmark the controller step against the solver's floor: ``python -m pipeline.bench``.

A thin entry: the work is in :mod:`pipeline.studies.bench`.
"""

from __future__ import annotations

import sys

from pipeline.studies.bench import main

__all__ = ['main']

if __name__ == "__main__":
    sys.exit(main())
