"""``python -m pipeline.bench``: an alias of ``make bench``'s command (``apf-mpc bench`` with the
repository's ``benchmarks/`` folder registered), run from a checkout's root.

The benchmark harness lives in the repository (``benchmarks/``), not in the installed package;
from anywhere else this alias says so in one line (exit 2).
"""

from __future__ import annotations

import sys

__all__ = ["main"]


def main(argv: list[str] | None = None) -> int:
    """``python -m pipeline.bench [arguments]``: ``apf-mpc bench [arguments]`` (exit 2 with one
    line outside a checkout)."""
    try:
        from benchmarks.command import main as bench
    except ImportError:
        print("error: the benchmark harness (benchmarks/) is not in the installed package; "
              "run `make bench` or `python -m pipeline.bench` from the repository's root",
              file=sys.stderr)
        return 2
    return bench(argv)


if __name__ == "__main__":
    sys.exit(main())
