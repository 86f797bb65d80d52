"""Bootstrap results remembered by their inputs: what a report built again finds already done.

A claim's interval is a pure function of the paired differences, the confidence level, the
number of resamples and the claims settings (the bootstrap draws from ``claims.seed``), and of
the code that computes it. :class:`IntervalMemo` keys each result by a digest of exactly that
(the differences' bytes, the level, the resamples, every scalar of the claims settings and a
salt, the code version) and hands back the numbers it was given for the same key: the same
numbers bit for bit, never another sample's. The memo lives in memory; the report keeps it on
disk between builds (:mod:`pipeline.store.interval_memo`), so that a report rebuilt after one
more study (``make pedestrians`` after ``make reproduce``) bootstraps only what is new.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
from dataclasses import dataclass, field

import numpy as np

from pipeline.analysis.settings import ClaimsConfig

#: One result's values: numbers and strings (what JSON keeps exactly).
Values = list[float | int | str]

#: The types of each kind's remembered values, in order (what a recalled entry must have).
VALUE_TYPES: dict[str, tuple[type, ...]] = {
    # BootstrapInterval: low, high, method, n_resamples, low_mc, high_mc
    "bootstrap_interval": (float, float, str, int, float, float),
    # probability of improvement and its interval
    "probability_of_improvement": (float, float, float),
}


@dataclass
class IntervalMemo:
    """Results by the digest of their inputs (:meth:`key`); ``known``: what an earlier build
    left, ``used``: what this one recalled or computed (what is kept for the next build).

    Parameters
    ----------
    salt : str
        Part of every key: the code version, so that changed code never reads another
        version's numbers.
    known : dict of str -> list of values
        Earlier results by key.
    """

    salt: str = ""
    known: dict[str, Values] = field(default_factory=dict)
    used: dict[str, Values] = field(default_factory=dict)
    hits: int = 0
    misses: int = 0

    def key(self, kind: str, sample: np.ndarray, cfg: ClaimsConfig, *args: float | int) -> str:
        """The digest of one computation's inputs: ``kind``, the salt, every scalar setting of
        ``cfg``, ``args`` and the bytes of ``sample`` (as float64)."""
        scalars = [(f.name, getattr(cfg, f.name)) for f in dataclasses.fields(cfg)
                   if isinstance(getattr(cfg, f.name), (bool, int, float, str))]
        head = json.dumps([kind, self.salt, scalars, [repr(a) for a in args]],
                          separators=(",", ":"))
        digest = hashlib.sha256(head.encode())
        digest.update(np.ascontiguousarray(sample, dtype=np.float64).tobytes())
        return f"{kind}:{digest.hexdigest()[:40]}"

    def recall(self, key: str) -> Values | None:
        """The values kept under ``key`` (None: never computed, or not of its kind's types:
        a damaged entry is computed again). ``hits`` counts the distinct keys an earlier
        build's results served, ``misses`` those computed here."""
        if key in self.used:
            return self.used[key]
        values = self.known.get(key)
        if values is None or not _well_typed(key.split(":", 1)[0], values):
            self.misses += 1
            return None
        self.hits += 1
        self.used[key] = values
        return values

    def keep(self, key: str, values: Values) -> None:
        """Remember ``values`` (numbers and strings) under ``key``."""
        self.used[key] = list(values)


def _well_typed(kind: str, values: object) -> bool:
    # strict: an int where a float was kept would print differently ("2" against "2.0")
    types = VALUE_TYPES.get(kind)
    return types is not None and isinstance(values, list) and len(values) == len(types) \
        and all(type(value) is expected for value, expected in zip(values, types, strict=True))
