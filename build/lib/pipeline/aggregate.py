"""Aggregate a Hydra sweep folder: ``python -m pipeline.aggregate SWEEP_DIR``; also the sweep's
``on_multirun_end`` callback (``AggregateCallback``, named by ``_target_`` in ``conf/config.yaml``).

A thin entry: the work is in :mod:`pipeline.studies.aggregate`.
"""

from __future__ import annotations

import sys

from pipeline.studies.aggregate import AggregateCallback, aggregate, main

__all__ = ['AggregateCallback', 'aggregate', 'main']

if __name__ == "__main__":
    sys.exit(main())
