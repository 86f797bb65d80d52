"""The report's bootstrap results between builds (:class:`~pipeline.analysis.claims.memo.
IntervalMemo` on disk): one JSON file beside the report, written atomically.

The file holds the code version that computed its entries; another version's file, an unreadable
one or a damaged entry is read as nothing (those results are computed again), so a memo never
hands over a number the current code would not compute. Each build keeps only the entries it
used, so the file does not grow with every report ever built.
"""

from __future__ import annotations

import json
import logging
from pathlib import Path

from pipeline.analysis.claims.memo import IntervalMemo
from pipeline.store.files import write_text_atomic
from pipeline.store.manifest import code_version

log = logging.getLogger("pipeline.store")

#: The memo's file in a report folder.
INTERVAL_MEMO = Path(".cache") / "intervals.json"


def environment_salt() -> str:
    """The code version and the versions of the libraries that compute an interval (SciPy's
    bootstrap, NumPy's generator, numba's Walsh medians): an upgrade computes them again."""
    import numba
    import numpy
    import scipy

    return (f"{code_version()} numpy {numpy.__version__} scipy {scipy.__version__} "
            f"numba {numba.__version__}")


def load_interval_memo(path: Path) -> IntervalMemo:
    """The memo kept at ``path`` (empty when absent, unreadable or of another code version),
    salted with this code's version."""
    memo = IntervalMemo(salt=environment_salt())
    try:
        data = json.loads(Path(path).read_text(encoding="utf-8"))
    except FileNotFoundError:
        return memo
    except (OSError, ValueError) as exc:
        log.warning("interval memo %s unreadable (%s): the intervals are computed again",
                    path, exc)
        return memo
    if isinstance(data, dict) and data.get("code_version") == memo.salt \
            and isinstance(data.get("entries"), dict):
        memo.known = data["entries"]
    return memo


def save_interval_memo(path: Path, memo: IntervalMemo) -> None:
    """Write the entries ``memo`` used in this build to ``path`` (atomically)."""
    text = json.dumps({"code_version": memo.salt, "entries": memo.used}, sort_keys=True,
                      separators=(",", ":"))
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    write_text_atomic(Path(path), text + "\n")
