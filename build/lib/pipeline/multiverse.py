"""How robust is each verdict: ``python -m pipeline.multiverse [--space NAME|PATH] [--out DIR]``.

A thin entry: the work is in :mod:`pipeline.studies.multiverse`.
"""

from __future__ import annotations

import sys

from pipeline.studies.multiverse import main

__all__ = ['main']

if __name__ == "__main__":
    sys.exit(main())
