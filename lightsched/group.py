"""Light-major pairs (a walk's, walk.LightPairs) grouped by object row: the pair cache's
layout (pair_cache.py) and the candidate lists' (candidates.py).

``group_pairs`` is a counting sort (a histogram of every object); ``group_few`` sorts a
few pairs instead, and ``start_at`` gives their segments at the rows that need them.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, NamedTuple

import numba as nb
import numpy as np

from .jit import GROUP_PARTS, PRANGE_ONLY

if TYPE_CHECKING:
    from .buffers import Buffers
    from .walk import LightPairs


class PairHeap(NamedTuple):
    """Pairs record by record, as the pair cache and the candidate lists' grouping hold
    them: two arrays, so that a scan of the light rows reads a quarter of the bytes."""

    p: np.ndarray          # float64 [H]: the pair's P (DESIGN section 2, "Priority")
    light_row: np.ndarray  # int32 [H]

    @staticmethod
    def empty(n: int) -> PairHeap:
        return PairHeap(np.empty(n), np.empty(n, np.int32))


def group_by_object(pairs: LightPairs, n: int, buffers: Buffers, cached: bool = False
                    ) -> tuple[np.ndarray, PairHeap]:
    """Light-major pairs grouped by object row (group_pairs): (start [N+1], their
    PairHeap), object o's pairs at start[o]..start[o+1]-1. ``cached``: the pairs are the
    new pair cache, in a heap from buffers.new_heap (H may be larger than the pairs)."""
    n_pairs = int(pairs.count.sum())
    start = np.empty(n + 1, np.int64)
    heap = buffers.new_heap(n_pairs) if cached else PairHeap.empty(n_pairs)
    # Positions fit int32 below 2^31 pairs: half the bytes keeps each thread's histogram
    # in its core's L2.
    wide = n_pairs >= 2**31
    hist = buffers.scratch("hist64" if wide else "hist", GROUP_PARTS * (n + 1),
                           np.int64 if wide else np.int32)
    parts = group_parts(n_pairs)
    group_pairs(pairs, hist[:parts * (n + 1)].reshape(parts, n + 1), start, heap)
    return start, heap


SERIAL_PAIRS = 1 << 15       # fewer pairs are grouped on one thread (group_parts)


@nb.njit(cache=True, nogil=True, parallel=PRANGE_ONLY, error_model="numpy")
def group_pairs(pairs, hist, start, heap):
    """Counting sort of the pairs by object row, so the object pass reads its lists in
    the order it writes its outputs (DESIGN section 6: the pair cache). The lights are
    split into one run per row of the histogram, each counted and placed with its own row
    (in parallel when there are several); within an object the runs follow each other, so
    the order of its lights is the order of pairs.rows whatever the runs and threads.

    pairs: walk.LightPairs, light-major; hist [Q, N+1] int32 (int64 from 2^31 pairs):
    scratch; start [N+1] and heap (PairHeap), reused buffers, filled: object o's pairs at
    heap[start[o]:start[o+1]], one position, two stores per scattered pair.

    Q = 1 runs on the calling thread: with two runs both threads store into every
    object's segment, the lines of the small segments go back and forth between the
    cores, and below ~2^15 pairs one thread is faster (``group_parts``)."""
    rows, offsets, count, pair_obj, pair_p = (pairs.rows, pairs.offsets, pairs.count,
                                              pairs.obj, pairs.p)
    pair_p_out, pair_j_out = heap.p, heap.light_row
    n_obj = start.shape[0] - 1
    parts = hist.shape[0]
    if parts == 1:
        # A loop: hist[0, :] = 0 would be a parallel region of its own in this kernel.
        for o in range(n_obj + 1):
            hist[0, o] = 0
        _count_run(0, 1, rows, offsets, count, pair_obj, hist)
    else:
        for q in nb.prange(parts):
            hist[q, :] = 0
            _count_run(q, parts, rows, offsets, count, pair_obj, hist)
    run = 0
    for o in range(n_obj):
        start[o] = run
        for q in range(parts):
            c = hist[q, o]
            hist[q, o] = run
            run += c
    start[n_obj] = run
    if parts == 1:
        _place_run(0, 1, rows, offsets, count, pair_obj, pair_p, hist, pair_p_out, pair_j_out)
    else:
        for q in nb.prange(parts):
            _place_run(q, parts, rows, offsets, count, pair_obj, pair_p, hist, pair_p_out,
                       pair_j_out)


def group_parts(n_pairs: int) -> int:
    """The histogram rows (runs) group_pairs takes for n_pairs pairs: one below
    SERIAL_PAIRS, else GROUP_PARTS: a few thousand pairs are grouped faster on one
    thread, tens of thousands on two (bench/RESULTS.md, "Measurements behind the code")."""
    return 1 if n_pairs < SERIAL_PAIRS else GROUP_PARTS


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _count_run(q, parts, rows, offsets, count, pair_obj, hist):
    """group_pairs' count of run q of ``parts`` (of the lights ``rows``): its lights' pairs
    per object row, added to hist[q] (zeros)."""
    n_l = rows.shape[0]
    for t in range(n_l * q // parts, n_l * (q + 1) // parts):
        for e in range(offsets[t], offsets[t] + count[t]):
            hist[q, pair_obj[e]] += 1


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _place_run(q, parts, rows, offsets, count, pair_obj, pair_p, hist, pair_p_out,
               pair_j_out):
    """group_pairs' scatter of run q of ``parts`` from its positions in hist[q]."""
    n_l = rows.shape[0]
    for t in range(n_l * q // parts, n_l * (q + 1) // parts):
        j = rows[t]
        for e in range(offsets[t], offsets[t] + count[t]):
            o = pair_obj[e]
            d = hist[q, o]
            pair_p_out[d] = pair_p[e]
            pair_j_out[d] = j
            hist[q, o] = d + 1


@nb.njit(cache=True, nogil=True, error_model="numpy")
def group_few(pairs):
    """group_pairs for a few pairs (walk.LightPairs): a stable sort by object row instead
    of a histogram of every object, whose O(N) clearing and prefix sum cost as much for no
    pair at all. Returns (object row per pair, ascending; PairHeap), each object's lights
    in the order of pairs.rows; ``start_at`` gives the segments. DESIGN section 6 (the
    pair cache's layout, for an incremental frame's few pairs)."""
    rows, offsets, count, pair_obj, pair_p = (pairs.rows, pairs.offsets, pairs.count,
                                              pairs.obj, pairs.p)
    n_pairs = 0
    for t in range(rows.shape[0]):
        n_pairs += count[t]
    obj = np.empty(n_pairs, np.int64)
    p = np.empty(n_pairs)
    j = np.empty(n_pairs, np.int32)
    e = 0
    for t in range(rows.shape[0]):
        for s in range(offsets[t], offsets[t] + count[t]):
            obj[e] = pair_obj[s]
            p[e] = pair_p[s]
            j[e] = rows[t]
            e += 1
    order = np.argsort(obj, kind="mergesort")
    return obj[order], PairHeap(p[order], j[order])


@nb.njit(cache=True, nogil=True, error_model="numpy")
def start_at(rows, obj, n):
    """start [n + 1] of pairs grouped by object row (``obj``: each pair's row, ascending)
    at the object ``rows`` (ascending) and the row after each, the only entries written:
    start[o] = the number of pairs of rows below o. rows, obj: int64; n: the object
    count. DESIGN section 6 (the pair cache's layout)."""
    start = np.empty(n + 1, np.int64)
    k = 0
    for r in range(rows.shape[0]):
        o = rows[r]
        while k < obj.shape[0] and obj[k] < o:
            k += 1
        start[o] = k
        while k < obj.shape[0] and obj[k] == o:
            k += 1
        start[o + 1] = k
    return start
