"""The Hodges-Lehmann estimate of many bootstrap resamples of one sample, compiled (numba).

A resample holds the sample's distinct values ``u`` (sorted) with counts ``c``; its Walsh
averages ``(u_a + u_b) / 2, a <= b`` carry the weights ``c_a c_b`` (``c_a (c_a + 1) / 2`` on
the diagonal), and its estimate is their weighted median. :func:`walsh_medians` finds the two
middle order statistics by a binary search over the sample's sorted Walsh averages; each probe
counts the weighted averages at most a value with two pointers over the values the resample
holds (``O(u)``), so one resample costs ``O(u log u)`` (fewer probes where the search
interpolates) instead of the ``O(u^2)`` of a cumulative sum over every average (measured on
the lateral family, 168 distinct differences: about 4 us per resample against 50 us). The
comparisons are the same floating-point expressions as the averages' own (``(u_a + u_b) /
2.0``), so the estimates are the same numbers bit for bit (tested against the direct median).

Importing this module imports numba and loads the kernel from numba's on-disk cache (compiled
once, about 1 s, the first time).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from numba import njit


def _jit(function: Callable[..., Any]) -> Callable[..., Any]:
    """``numba.njit`` with numba's on-disk cache, or without it where no cache folder is
    writable (the kernel is then compiled once per process)."""
    try:
        return njit(cache=True, nogil=True)(function)
    except RuntimeError:
        return njit(nogil=True)(function)


@_jit
def _count_at_most(value: float, counts: np.ndarray, prefix: np.ndarray,
                   u: np.ndarray, size: int) -> int:  # pragma: no cover (run compiled)
    """The weighted number of Walsh averages ``(u_a + u_b) / 2 <= value``, ``a <= b``, over
    the first ``size`` entries of ``u`` and ``counts`` (``prefix``: their cumulative sum)."""
    b = size - 1
    total = 0
    for a in range(size):
        while b >= a and (u[a] + u[b]) / 2.0 > value:
            b -= 1
        if b < a:
            break
        c = counts[a]
        total += c * (prefix[b + 1] - prefix[a + 1]) + c * (c + 1) // 2
    return total


@_jit
def _order_statistic(rank: int, counts: np.ndarray, prefix: np.ndarray, u: np.ndarray,
                     size: int, walsh: np.ndarray) -> int:  # pragma: no cover (run compiled)
    """The index in ``walsh`` (sorted) of the weighted Walsh average of 0-based ``rank``: the
    first index whose value has more than ``rank`` weighted averages at or below it.

    A search between ``low`` (at most ``rank`` at or below it; -1 to start) and ``high`` (more
    than ``rank``): each probe interpolates the rank between the two ends' counts (the count
    grows about evenly with the index: about 7 probes on 170 values, where bisection takes
    14); after as many probes as bisection would need it bisects, so it never takes more than
    twice bisection's probes."""
    low, high = -1, walsh.size - 1
    count_low, count_high = 0, prefix[size] * (prefix[size] + 1) // 2
    probes, patience = 0, int(np.log2(walsh.size)) + 1
    while high - low > 1:
        width = high - low
        if probes >= patience:
            middle = low + width // 2
        else:
            share = (rank + 0.5 - count_low) / max(count_high - count_low, 1)
            middle = low + min(max(int(share * width), 1), width - 1)
        count = _count_at_most(walsh[middle], counts, prefix, u, size)
        probes += 1
        if count > rank:
            high, count_high = middle, count
        else:
            low, count_low = middle, count
    return high


@_jit
def walsh_medians(codes: np.ndarray, u: np.ndarray, walsh: np.ndarray, first: np.ndarray,
                  second: np.ndarray) -> np.ndarray:  # pragma: no cover (run compiled)
    """The Hodges-Lehmann estimate of each row of ``codes``.

    Parameters
    ----------
    codes : int64 array (rows, n)
        Each row a resample, as indices into ``u``.
    u : float array
        The sample's distinct values, sorted.
    walsh, first, second : arrays
        Every ``(u[a] + u[b]) / 2.0, a <= b``, sorted, and its ``a`` and ``b``.
    """
    rows, n = codes.shape
    out = np.empty(rows)
    counts = np.zeros(u.size, np.int64)
    # the values present in a resample, their counts and the counts' cumulative sum
    present = np.empty(u.size)
    present_counts = np.empty(u.size, np.int64)
    prefix = np.zeros(u.size + 1, np.int64)
    total = n * (n + 1) // 2
    rank_low, rank_high = (total - 1) // 2, total // 2
    for row in range(rows):
        counts[:] = 0
        for k in range(n):
            counts[codes[row, k]] += 1
        size = 0
        for a in range(u.size):
            if counts[a]:
                present[size] = u[a]
                present_counts[size] = counts[a]
                prefix[size + 1] = prefix[size] + counts[a]
                size += 1
        low = _order_statistic(rank_low, present_counts, prefix, present, size, walsh)
        high = low
        if rank_high != rank_low and \
                _count_at_most(walsh[low], present_counts, prefix, present, size) <= rank_high:
            # the next larger average this resample holds (both its values present)
            high = low + 1
            while walsh[high] == walsh[low] or counts[first[high]] == 0 \
                    or counts[second[high]] == 0:
                high += 1
        out[row] = (walsh[low] + walsh[high]) / 2.0
    return out


def warm_kernel() -> None:
    """Compile :func:`walsh_medians` (and what it calls) into numba's on-disk cache, on a
    tiny sample (``make install`` calls it through :mod:`pipeline.warm`: the first report then
    loads the kernel instead of compiling it, about 1 s)."""
    values = np.arange(5.0)
    first, second = np.triu_indices(values.size)
    walsh = (values[first] + values[second]) / 2.0
    order = np.argsort(walsh, kind="stable")
    walsh_medians(np.array([[0, 1, 2, 3, 4], [4, 4, 1, 0, 2]], dtype=np.int64), values,
                  walsh[order], first[order], second[order])
