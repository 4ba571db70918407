"""Top-K selection with hysteresis (DESIGN section 2, "Selection").

Takes the competing lights of one object and keeps the K of highest key, ties to the lower
light id; key = P, or P + h|P| + hysteresis_abs for a light that was in the object's
selected set last frame, so near-equal lights do not flicker in and out of the set. Returns
the selected set in key order. Inlined into the object pass (objects.py), which skips the
ranking when every competing light fits in K.

With many competing lights (30-100 in a dense scene, hundreds under a stadium's
floodlights) an insertion a light mispredicts a branch a light, so the pass is in steps
without per-light branches (``top_k``): the live lights are gathered into a pool and keyed
(last frame's selection raised); that selection, when all of it still competes,
bounds the K-th key from below, so only the lights at or above that bound are kept; those
few are ranked by counting (a light's place is the number of lights ranking before it).
"""

from __future__ import annotations

import numba as nb
import numpy as np


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def ranks_before(key_a, id_a, key_b, id_b):
    """True if (key_a, id_a) ranks before (key_b, id_b): higher key, ties lower id.
    DESIGN section 2, "Selection" (and "Fade"'s output order). Without a branch, so that
    the loops counting it vectorise."""
    return (key_a > key_b) | ((key_a == key_b) & (id_a < id_b))


# Per-object scratch, one row per quantity and K columns: float64 sf[F_ROWS, K] and int64
# si[I_ROWS, K]. Two matrices instead of many small arrays keep the inlined per-object code
# free of array views (their reference counting costs more than the pair tests).
F_KEY, F_P, F_OLD_P, F_OLD_W, F_NEW_W, F_NEW_P = range(6)
F_ROWS = 6
(I_ID, I_ROW, I_OLD_ID, I_OLD_ROW, I_OLD_ST, I_NEW_ID, I_NEW_ROW, I_NEW_ST, I_HAS_SLOT,
 I_TAKEN) = range(10)
I_ROWS = 10


# The object's pool of competing lights, one column a light: float64 cf[CF_ROWS, n] and int64
# ci[CI_ROWS, n], n at most its pair count. CF_P, CI_ID, CI_ROW: the live lights gathered;
# CF_KEY: their keys; CF_S_*, CI_S_*: the lights kept for ranking; CF_T_P, CI_T_*: the
# ranked ones at their places (column K takes every place past K).
CF_KEY, CF_P, CF_S_KEY, CF_S_P, CF_T_P = F_KEY, F_P, 2, 3, 4
CF_ROWS = 5
CI_ID, CI_ROW, CI_S_ID, CI_S_ROW, CI_T_ID, CI_T_ROW = I_ID, I_ROW, 2, 3, 4, 5
CI_ROWS = 6
# Ranking by counting costs n^2 compares for n kept lights, in vector code; an insertion
# K compares and a mispredicted branch a light. Past this many kept lights the insertion.
RANK_COUNT_MAX = 48


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def raised_key(p, h, h_abs):
    """The key of a light selected last frame: P + h|P| + h_abs. p: P; h, h_abs:
    Config.hysteresis, hysteresis_abs. DESIGN section 2, "Selection" (hysteresis)."""
    return p + h * abs(p) + h_abs


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def gather_live(heap_p, heap_j, live_id, a, b, cf, ci):
    """Gathers the pairs a..b of the pair cache whose light is live into the pool's CF_P,
    CI_ID, CI_ROW, in pair order, without a branch (every pair is stored; a dead one is
    overwritten by the next); returns how many. heap_p, heap_j: the pairs' P and light
    rows; live_id: per light row its id, or -2 (objects.live_ids). DESIGN section 2,
    "Slots" (the competing lights)."""
    n = 0
    for t in range(a, b):
        j = np.int64(heap_j[t])
        lid = np.int64(live_id[j])
        cf[CF_P, n] = heap_p[t]
        ci[CI_ID, n] = lid
        ci[CI_ROW, n] = j
        n += lid >= 0
    return n


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def pool_column(ci, n, lid):
    """The column of light id lid among the n lights of the pool, or -1. Light ids are
    unique, so a sum over the pool finds the one that matches: it vectorises, where a
    search would branch a light."""
    at = 0
    for t in range(n):
        at += (t + 1) if ci[CI_ID, t] == lid else 0
    return at - 1


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def match_old_slots(cf, ci, n, sf, si):
    """This frame's P and row (F_OLD_P, I_OLD_ROW) of each old slot's light (I_OLD_ID) that
    is in the pool; I_OLD_ROW stays -1 for the others. cf, ci: the pool, n lights; sf, si:
    the object's scratch."""
    for m in range(sf.shape[1]):
        at = pool_column(ci, n, si[I_OLD_ID, m])
        if at >= 0:
            sf[F_OLD_P, m] = cf[CF_P, at]
            si[I_OLD_ROW, m] = ci[CI_ROW, at]


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def gather_few(heap_p, heap_j, live_id, a, b, sf, si):
    """gather_live and match_old_slots in one pass, for an object whose b - a <= K pairs
    all fit in its selection: the live lights into F_P, I_ID, I_ROW of sf, si in pair
    order, and each old slot's light (I_OLD_ID) found there its P and row (F_OLD_P,
    I_OLD_ROW); returns how many are live. The common case of a sparse scene: with so
    few pairs the branch on a light's liveness predicts well, and K compares a light cost
    less than match_old_slots' K sums over the pool, loops of a few lanes that AVX-512
    code runs masked (bench/RESULTS.md, issue 48). DESIGN section 2, "Slots"."""
    n = 0
    for t in range(a, b):
        j = np.int64(heap_j[t])
        lid = np.int64(live_id[j])
        if lid >= 0:
            p = heap_p[t]
            # Compares only inside the loop (it vectorises); the one store after it.
            slot = -1
            for m in range(sf.shape[1]):
                slot = m if si[I_OLD_ID, m] == lid else slot
            if slot >= 0:
                sf[F_OLD_P, slot] = p
                si[I_OLD_ROW, slot] = j
            sf[F_P, n] = p
            si[I_ID, n] = lid
            si[I_ROW, n] = j
            n += 1
    return n


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def top_k(cf, ci, n, selected, o, sf, si, h, h_abs):
    """The object's selection among the n > K lights of its pool, in key order, into the
    rows F_P, I_ID, I_ROW (and F_KEY) of sf, si; returns K. selected: int32 [N, K] last
    frame's selected ids of each object (padded with -1); o: the object's row; h, h_abs:
    Config.hysteresis, hysteresis_abs. DESIGN section 2, "Selection". The steps are in
    the module's docstring."""
    k = sf.shape[1]
    for t in range(n):
        cf[CF_KEY, t] = cf[CF_P, t]
    # Last frame's selected lights get the raised key. When all K of them still compete,
    # the K-th key ranks at or before the lowest of theirs (low, low_id): the bound.
    n_marked = 0
    low = np.inf
    low_id = np.int64(-1)
    for m in range(k):
        was = np.int64(selected[o, m])
        at = pool_column(ci, n, was)
        if at >= 0:
            key = raised_key(cf[CF_P, at], h, h_abs)
            cf[CF_KEY, at] = key
            n_marked += 1
            if ranks_before(low, low_id, key, was):
                low, low_id = key, was
    if n_marked < k:
        low, low_id = -np.inf, np.int64(-1)
    s = 0
    for t in range(n):
        key = cf[CF_KEY, t]
        lid = ci[CI_ID, t]
        cf[CF_S_KEY, s] = key
        cf[CF_S_P, s] = cf[CF_P, t]
        ci[CI_S_ID, s] = lid
        ci[CI_S_ROW, s] = ci[CI_ROW, t]
        s += (key > low) | ((key == low) & (lid <= low_id))
    if s > RANK_COUNT_MAX:
        nbest = 0
        for t in range(s):
            nbest = topk_insert(sf, si, nbest, cf[CF_S_KEY, t], ci[CI_S_ID, t], cf[CF_S_P, t],
                                ci[CI_S_ROW, t])
        return nbest
    for u in range(s):
        key = cf[CF_S_KEY, u]
        lid = ci[CI_S_ID, u]
        place = 0
        for v in range(s):
            place += ranks_before(cf[CF_S_KEY, v], ci[CI_S_ID, v], key, lid)
        place = min(place, k)
        cf[CF_T_P, place] = cf[CF_S_P, u]
        ci[CI_T_ID, place] = lid
        ci[CI_T_ROW, place] = ci[CI_S_ROW, u]
    for m in range(k):
        sf[F_P, m] = cf[CF_T_P, m]
        si[I_ID, m] = ci[CI_T_ID, m]
        si[I_ROW, m] = ci[CI_T_ROW, m]
    return k


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def topk_insert(sf, si, nbest, key, lid, p, row):
    """Inserts one candidate into the sorted top-K rows (F_KEY, F_P, I_ID, I_ROW); returns
    the new size. sf: float64 [F_ROWS, K], si: int64 [I_ROWS, K]: the object's scratch;
    nbest: the rows filled; key: P or raised_key; lid: light id; p: P; row: light row.
    DESIGN section 2, "Selection"."""
    k = sf.shape[1]
    # Where it goes: a count of compares (no stores, so it vectorises), then the shift.
    pos = 0
    for m in range(nbest):
        pos += ranks_before(sf[F_KEY, m], si[I_ID, m], key, lid)
    if pos >= k:
        return nbest
    for i in range(min(nbest, k - 1), pos, -1):
        sf[F_KEY, i] = sf[F_KEY, i - 1]
        sf[F_P, i] = sf[F_P, i - 1]
        si[I_ID, i] = si[I_ID, i - 1]
        si[I_ROW, i] = si[I_ROW, i - 1]
    i = pos
    sf[F_KEY, i] = key
    sf[F_P, i] = p
    si[I_ID, i] = lid
    si[I_ROW, i] = row
    return nbest + 1 if nbest < k else k
