"""The pair cache (DESIGN section 6: static objects and lights keep their pairs): per
object row a segment (start, length) of a heap of (P, light row) pairs, which the next
frame keeps.

``group_pairs`` is a counting sort of a light pass's light-major pairs by object row, into
the cache; ``group_few`` sorts a few. An incremental frame finds the objects holding pairs
of lights that changed (``scan_pairs``, ``scan_rows``), rewrites their segments
(``replace_lists``, appending to the heap), and packs the heap when it is mostly garbage
(``compact_heap``). The heap is two arrays (P float64, light row int32) so a scan of the
light rows reads a quarter of it.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import reduce
from typing import TYPE_CHECKING

import numba as nb
import numpy as np

from .buffers import Buffers
from .candidates import candidate_pairs, list_objects, reached_rows
from .grid import light_order
from .group import PairHeap, group_by_object, group_few, start_at
from .jit import OBJECT_CHUNK, PRANGE_ONLY
from .pairs import CANDIDATES, LISTS, WALK, Pairs
from .walk import walk_lights

if TYPE_CHECKING:
    from .grid import Grid
    from .plan import FramePlan
    from .priority import Packed, PairParams
    from .scheduler import FrameState
    from .shadows import ShadowSet
    from .tuning import Tuning
    from .visibility import Visibility


SCAN_LANES = 8               # pairs scan_pairs reads per object in a loop of fixed length


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _scan_object(o, seg, heap_j, light_flag, drop):
    """(the OR of light_flag over object o's cached pairs, how many have no ``drop`` bit).

    Objects hold a few pairs each (4.4 on average in the city, 0 to 16), so a loop over
    each list's length mispredicts its exit about once an object. The first SCAN_LANES
    pairs are read in a loop of fixed length instead, the lanes past the end reading the
    last pair again and counting nothing; eight lanes did better than 4 or 12
    (bench/RESULTS.md, "Measurements behind the code")."""
    a = seg[o, 0]
    size = seg[o, 1]
    acc = 0
    keep = 0
    if size > 0:
        last = a + size - 1
        for k in range(SCAN_LANES):
            f = light_flag[heap_j[min(a + k, last)]]
            acc |= f
            keep += ((f & drop) == 0) & (k < size)
        for t in range(a + SCAN_LANES, a + size):
            f = light_flag[heap_j[t]]
            acc |= f
            keep += (f & drop) == 0
    return acc, keep


@nb.njit(cache=True, nogil=True, parallel=PRANGE_ONLY, error_model="numpy")
def scan_pairs(seg, heap_j, light_flag, drop):
    """Per object row (parallel): the OR of light_flag[light row] over its cached pairs,
    so an incremental frame finds the objects that hold a pair of a changed light, and
    the number of its pairs whose light's flag has no ``drop`` bit: the pairs
    ``replace_lists`` keeps, counted here while the flags are read anyway (a second pass
    over the rewritten lists was a large share of replace_lists' time). seg: int64 [N, 2]
    (start, length); heap_j: int32 [H], the heap's light rows (group.PairHeap.light_row);
    light_flag: uint8 [L] (WALKED, RESELECT bits); drop: the bit whose pairs are dropped.
    Returns (uint8 [N], int64 [N]). DESIGN section 6 (the pair cache of an incremental
    frame)."""
    n = seg.shape[0]
    out = np.zeros(n, np.uint8)
    kept = np.empty(n, np.int64)
    n_chunks = (n + OBJECT_CHUNK - 1) // OBJECT_CHUNK
    for ch in nb.prange(n_chunks):
        for o in range(ch * OBJECT_CHUNK, min(n, (ch + 1) * OBJECT_CHUNK)):
            out[o], kept[o] = _scan_object(o, seg, heap_j, light_flag, drop)
    return out, kept


@nb.njit(cache=True, nogil=True, error_model="numpy")
def scan_rows(rows, seg, heap_j, light_flag, drop):
    """scan_pairs at the object ``rows`` only, on the calling thread (the few objects the
    flagged lights reach): the flags' OR is 0 and ``kept`` undefined at every other row.
    rows: int64 object rows; seg, heap_j, light_flag, drop as scan_pairs'. DESIGN section 6
    (the pair cache of an incremental frame)."""
    n = seg.shape[0]
    out = np.zeros(n, np.uint8)
    kept = np.empty(n, np.int64)
    for r in range(rows.shape[0]):
        o = rows[r]
        out[o], kept[o] = _scan_object(o, seg, heap_j, light_flag, drop)
    return out, kept


@nb.njit(cache=True, nogil=True, parallel=PRANGE_ONLY, error_model="numpy")
def compact_heap(seg, heap, out):
    """The live segments (seg [N, 2]: start, length) of ``heap`` (group.PairHeap) packed
    from the start of ``out``, another PairHeap with room for them (the records after
    them are free); returns (new seg, out, records used). Segment order is row order.
    DESIGN section 6 (the pair cache's upkeep)."""
    n = seg.shape[0]
    start = np.zeros(n + 1, np.int64)
    for o in range(n):
        start[o + 1] = start[o] + seg[o, 1]
    used = start[n]
    heap_p, heap_j = heap.p, heap.light_row
    new_p, new_j = out.p, out.light_row
    new_seg = np.empty_like(seg)
    n_chunks = (n + OBJECT_CHUNK - 1) // OBJECT_CHUNK
    for ch in nb.prange(n_chunks):
        for o in range(ch * OBJECT_CHUNK, min(n, (ch + 1) * OBJECT_CHUNK)):
            a = seg[o, 0]
            d = start[o]
            for t in range(seg[o, 1]):
                new_p[d + t] = heap_p[a + t]
                new_j[d + t] = heap_j[a + t]
            new_seg[o, 0] = d
            new_seg[o, 1] = seg[o, 1]
    return new_seg, out, used


@nb.njit(cache=True, nogil=True, parallel=PRANGE_ONLY, error_model="numpy")
def replace_lists(rows, mode, seg, heap, walked, kept, fresh_start, fresh, used):
    """New pair lists of the object ``rows`` (ascending), appended to the heap from record
    ``used`` (the caller made room). mode per row: 0 empty (the object left the view), 1
    only its ``fresh`` pairs (its lists were rebuilt against every light: it moved or came
    into view), 2 its cached pairs of lights not flagged in ``walked`` (kept[o] of them,
    from ``scan_pairs``; all of them if kept is empty) followed by its fresh pairs (lights
    that changed were walked again). The cache, seg [N, 2] (start, length) and heap
    (group.PairHeap), is updated in place; the fresh pairs are grouped by object row:
    object o's at fresh[fresh_start[o]:fresh_start[o+1]] (a PairHeap). Returns (records
    used, the pairs the rows' lists held, the pairs they hold now, the longest new list),
    which the cache's counts follow. DESIGN section 6 (the pair cache of an incremental
    frame)."""
    heap_p, heap_j = heap.p, heap.light_row
    f_start, f_p, f_j = fresh_start, fresh.p, fresh.light_row
    at = np.empty(rows.shape[0] + 1, np.int64)
    at[0] = used
    held = longest = 0
    for r in range(rows.shape[0]):
        o = rows[r]
        held += seg[o, 1]
        size = 0
        if mode[r] == 2:
            size = kept[o] if kept.size else seg[o, 1]
        if mode[r] != 0:
            size += f_start[o + 1] - f_start[o]
        at[r + 1] = at[r] + size
        longest = max(longest, size)
    for r in nb.prange(rows.shape[0]):
        o = rows[r]
        d = at[r]
        if mode[r] == 2:
            for t in range(seg[o, 0], seg[o, 0] + seg[o, 1]):
                if not walked[heap_j[t]]:
                    heap_p[d] = heap_p[t]
                    heap_j[d] = heap_j[t]
                    d += 1
        if mode[r] != 0:
            for t in range(f_start[o], f_start[o + 1]):
                heap_p[d] = f_p[t]
                heap_j[d] = f_j[t]
                d += 1
        seg[o, 0] = at[r]
        seg[o, 1] = d - at[r]
    return at[rows.shape[0]], held, at[rows.shape[0]] - used, longest


# --------------------------------------------------------------------------- the lists stage

# light_flag bits of an incremental frame (scan_pairs): the light's pairs are replaced (it
# changed, or entered or left the view); the objects holding its pairs must select again
# (its shadow map or "skip" status changed).
WALKED, RESELECT = 1, 2
_NO_ROWS = np.zeros(0, np.int64)


@dataclass(slots=True)
class PairCache:
    """The lists stage's output, kept for the next frame: per object row ``seg`` (start,
    length) of its pairs in ``heap`` (group.PairHeap), ``used`` the heap records
    in use (live or garbage), ``pairs`` the live ones (the lengths in seg summed),
    ``longest`` at least the longest segment (the object pass sizes its pools by it). Also
    this frame's ``run``: the object rows the object pass recomputes, and ``how``."""

    seg: np.ndarray
    heap: PairHeap
    used: int
    pairs: int
    longest: int
    run: np.ndarray
    how: str


def update_pair_cache(plan: FramePlan, last: FrameState | None, pairs: Pairs,
                      shadows: ShadowSet, vis: Visibility, packed: Packed, grid: Grid,
                      light_rows: np.ndarray | None, tuning: Tuning, buffers: Buffers
                      ) -> PairCache:
    """The lists stage: the pair cache made from this frame's pairs (a full frame), or last
    frame's with the changed lists rewritten (an incremental one), as the pairs stage's
    path says. ``light_rows``: the lights that changed (changes.Changes)."""
    n = vis.objects.size
    if pairs.path == CANDIDATES:
        cache = _from_candidates(pairs, packed, n, buffers)
    elif pairs.path == WALK:
        start, heap = group_by_object(pairs.lights, n, buffers, cached=True)
        seg = np.empty((n, 2), np.int64)
        seg[:, 0] = start[:-1]
        np.subtract(start[1:], start[:-1], out=seg[:, 1])
        cache = PairCache(seg, heap, int(start[-1]), int(start[-1]), longest(seg),
                          buffers.rows(n, read_only=False), "grouped by object (every pair new)")
    elif pairs.path == LISTS:
        cache = _from_lists(plan, last, pairs, shadows, vis, packed, buffers)
    else:
        cache = _patch(plan, last, pairs, shadows, vis, packed, grid, light_rows, tuning,
                       buffers)
    if last is not None and last.cache.heap.p is not cache.heap.p:
        buffers.spare_heap = last.cache.heap
    return cache


def longest(seg: np.ndarray, rows: np.ndarray | None = None) -> int:
    """The longest of the segments ``seg`` (at ``rows``; None: all), for PairCache.longest.
    An incremental frame bounds its cache by last frame's bound and the lists it rewrote
    (a bound that only shrinks at a full frame), so the object pass need not scan its
    rows' lengths."""
    if rows is None:
        return int(seg[:, 1].max(initial=0))
    return int(_longest_at(seg, rows))


@nb.njit(cache=True, nogil=True, error_model="numpy")
def _longest_at(seg, rows):
    """max(seg[rows, 1], 0) without the gathered copy. DESIGN section 6 (the pair cache)."""
    m = 0
    for o in rows:
        m = max(m, seg[o, 1])
    return m


def _from_candidates(pairs: Pairs, packed: Packed, n: int, buffers: Buffers) -> PairCache:
    """Every object's pairs from its candidate list, by object row (candidate_pairs), into
    a new heap sized from the lists: a pair is a candidate that passes the Affects test, or
    a competing directional light with each object. Should that fall short,
    candidate_pairs writes nothing and reports the exact room, which the heap then takes."""
    cands = pairs.candidates
    dir_rows = packed.dir_all[packed.compete[packed.dir_all]]
    seg = np.empty((n, 2), np.int64)
    # (The lights' list lengths, not the objects': the same candidates, fewer to sum.)
    heap = buffers.new_heap(int(cands.by_light.seg[:, 1].sum()) + n * dir_rows.size)
    args = (buffers.rows(n), cands.lists, cands.records, packed.rows, packed.compete,
            dir_rows, pairs.params)
    used, n_pairs, _ = candidate_pairs(*args, seg, heap, 0)
    if n_pairs < 0:
        buffers.spare_heap = heap
        heap = buffers.new_heap(int(used))
        used, n_pairs, _ = candidate_pairs(*args, seg, heap, 0)
    return PairCache(seg, heap, int(used), int(n_pairs), longest(seg),
                     buffers.rows(n, read_only=False),
                     "every pair from the objects' candidate lists, by object row")


def _from_lists(plan: FramePlan, last: FrameState, pairs: Pairs, shadows: ShadowSet,
                vis: Visibility, packed: Packed, buffers: Buffers) -> PairCache:
    """Last frame's cache with the lists of the objects the changed lights may reach (and
    those of lights whose shadow map or "skip" status changed) made again from their
    candidates."""
    cands, reach = pairs.candidates, pairs.reach
    old = last.shadows
    reselect = np.flatnonzero(shadows.reselect(old))
    list_objects(cands.by_light, reselect, reach)
    # The visibility is last frame's: an object out of view has no pairs. (As bytes: the
    # kernel's loop on bools is slower.)
    fading = last.outputs.fading
    more = (fading | vis.objects | last.visibility.objects) if plan.cut else fading
    rows, run = reached_rows(reach.view(np.uint8), vis.objects.view(np.uint8),
                             more.view(np.uint8))
    c = last.cache
    seg, heap, used, n_pairs = c.seg, c.heap, c.used, c.pairs
    if rows.size:
        args = (rows, cands.lists, cands.records, packed.rows, packed.compete, _NO_ROWS,
                pairs.params)
        at, wrote, dropped = candidate_pairs(*args, seg, heap, used)
        if wrote < 0:
            seg, heap, used = _room(buffers, seg, heap, used, n_pairs, int(at) - used)
            at, wrote, dropped = candidate_pairs(*args, seg, heap, used)
        need = int(at) - used
        used, n_pairs = int(at), n_pairs - int(dropped) + int(wrote)
        # Packed now, not at the start of the next frame like this one (which would not
        # fit, or would leave the heap mostly garbage): that frame then writes into room
        # it knows it has, without a failed try.
        seg, heap, used = _room(buffers, seg, heap, used, n_pairs, need)
    return PairCache(seg, heap, used, n_pairs, max(c.longest, longest(seg, rows)), run,
                     f"cache kept; the lists of {rows.size} objects made again from their "
                     f"candidates; {run.size} of {np.count_nonzero(vis.objects)} visible "
                     "objects recomputed (in reach of changed lights or of lights whose "
                     "shadow map changed, fading slots" + (", a cut" if plan.cut else "") + ")")


def _patch(plan: FramePlan, last: FrameState, pairs: Pairs, shadows: ShadowSet,
           vis: Visibility, packed: Packed, grid: Grid, light_rows: np.ndarray,
           tuning: Tuning, buffers: Buffers) -> PairCache:
    """Last frame's cache brought up to date. Objects holding a pair of a walked light
    (found by scanning the cache: every object's pairs, or those of the objects
    ``_near_rows`` gives for the flagged lights) and objects the walk gave pairs keep
    their other pairs and take the fresh ones; moved or newly visible objects take their
    new lists (``pairs.objects``: grouped by object row, valid at vis.fresh and the row
    after each); objects that left the view lose theirs."""
    c, old = last.cache, last.shadows
    n = vis.objects.size
    flag = np.zeros(shadows.live.size, np.uint8)
    flag[pairs.walked] |= WALKED
    flag[shadows.reselect(old)] |= RESELECT
    flagged = np.flatnonzero(flag)
    near = (_near_rows(plan, c, flagged, light_rows, packed, grid, pairs.params, tuning,
                       buffers) if flagged.size else None)
    if near is not None:
        holds, kept = scan_rows(near, c.seg, c.heap.light_row, flag, WALKED)
        scanned = (f"the pairs of the {near.size} objects the {flagged.size} flagged lights "
                   "reach scanned")
    elif flagged.size:
        holds, kept = scan_pairs(c.seg, c.heap.light_row, flag, WALKED)
        scanned = f"every object's pairs scanned for {flagged.size} flagged lights"
    else:
        holds, kept = np.zeros(n, np.uint8), np.zeros(0, np.int64)
        scanned = "no light flagged"
    fresh = pairs.lights
    few = int(fresh.count.sum()) <= tuning.few_pairs * n
    rows1 = vis.renewed
    if few:
        w_obj, w_pairs = group_few(fresh)
    else:
        w_start, w_pairs = group_by_object(fresh, n, buffers)
    fading = last.outputs.fading
    if few and near is not None and not plan.cut:
        # Only the objects near the flagged lights, the walk's objects and rows1 can
        # change: the same rows as below, without its passes over every row.
        near_holds = holds[near]
        rows2 = np.setdiff1d(np.union1d(near[(near_holds & WALKED) != 0], w_obj), rows1,
                             assume_unique=True)
        run = reduce(np.union1d, (near[near_holds != 0], rows2, rows1, np.flatnonzero(fading)))
    else:
        rewrite = (holds & WALKED) != 0
        if few:
            rewrite[w_obj] = True
        else:
            rewrite |= w_start[1:] > w_start[:-1]
        rewrite[rows1] = False
        rows2 = np.flatnonzero(rewrite)
        run = (holds != 0) | rewrite | fading
        run[rows1] = True
        if plan.cut:
            run |= vis.objects | last.visibility.objects
        run = np.flatnonzero(run)
    if few:
        w_start = start_at(rows2, w_obj, n)
    # replace_lists' modes: 2 (rows2) the kept pairs and the walk's, 1 the new lists of
    # moved or newly visible objects, 0 none for those that left the view.
    mode1 = vis.objects[rows1].view(np.int8)
    o_start, o_pairs = pairs.objects
    # The cache is this frame's to change.
    seg, heap, used = _room(buffers, c.seg, c.heap, c.used, c.pairs,
                            w_pairs.p.size + int(c.seg[rows2, 1].sum()) + o_pairs.p.size)
    walked = (flag & WALKED) != 0
    # The cache's pairs and bound follow from the rewritten lists' lengths.
    used, held2, now2, longest2 = replace_lists(rows2, np.full(rows2.size, 2, np.int8), seg,
                                                heap, walked, kept, w_start, w_pairs, used)
    used, held1, now1, longest1 = replace_lists(rows1, mode1, seg, heap, walked, kept, o_start,
                                                o_pairs, used)
    n_pairs = c.pairs - held1 - held2 + now1 + now2
    return PairCache(seg, heap, used, n_pairs, max(c.longest, longest1, longest2), run,
                     f"cache kept; {scanned}; {run.size} of {np.count_nonzero(vis.objects)} "
                     "visible objects recomputed (pairs of changed lights, moved or newly "
                     "visible objects, shadow-map changes, fading slots"
                     + (", a cut" if plan.cut else "") + ")")


def _near_rows(plan: FramePlan, c: PairCache, flagged: np.ndarray, light_rows: np.ndarray,
               packed: Packed, grid: Grid, params: PairParams, tuning: Tuning,
               buffers: Buffers) -> np.ndarray | None:
    """The objects that can hold a pair of the lights ``flagged``, when none of them
    changed this frame: each such pair was made with the light as it is, so an object
    holding one that is in view now meets the light in the grid (exact records: the same
    test, the same bits); one that moved, came into view or left it takes new lists
    whatever it holds. None: scan every object's pairs (a light changed, a directional
    one, float32 records whose origin may have moved, or more walks than the scan costs)."""
    if (plan.fast or flagged.size * tuning.near_scan_pairs > c.pairs
            or packed.is_dir[flagged].any() or np.isin(flagged, light_rows).any()):
        return None
    order = light_order(packed.rows.hot, flagged.astype(np.int32), grid.index.frame,
                        grid.index.dims)
    walked = walk_lights(packed.rows, order, grid, params, buffers, "near")
    return np.unique(np.concatenate(
        [walked.obj[walked.offsets[t]:walked.offsets[t] + walked.count[t]]
         for t in range(order.size)] + [_NO_ROWS]))


def _room(buffers: Buffers, seg: np.ndarray, heap: PairHeap, used: int, n_live: int,
          need: int) -> tuple[np.ndarray, PairHeap, int]:
    """A pair cache (seg, heap, records used; ``n_live`` of them live) with room for
    ``need`` more records. New lists go after the records in use (those are not written),
    the heap packed first when short of room or mostly garbage, into a heap from
    buffers.new_heap. The room left after packing holds ~4 more frames like this one."""
    if used + need > heap.p.size or used > 2 * (n_live + need) + 4096:
        seg, heap, used = compact_heap(seg, heap,
                                       buffers.new_heap(n_live + 4 * need + n_live // 2 + 1024))
    return seg, heap, used
