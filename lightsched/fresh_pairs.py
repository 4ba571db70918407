"""Pairs of the objects an incremental frame moves or brings into view, each against
every competing light (DESIGN section 6: only the objects that moved are recomputed):
tested against all of them (``direct_pairs``) when they are few, else against those of the
cells its box overlaps in a grid of the point and spot lights (``light_grid``,
``grid_pairs``), kept while no light changes.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, NamedTuple

import numba as nb
import numpy as np

from .candidates import candidate_pairs, scalar_candidates
from .grid import Records, _axis_cells, _cell, visible_objects
from .group import PairHeap
from .jit import PRANGE_ONLY
from .priority import MODEL_CONTRIBUTION, PairParams
from .simd import SHOWN, candidate_run

if TYPE_CHECKING:
    from .priority import Packed
    from .scene import ObjectStore

LIGHT_GRID_CELLS = 4         # cells per light in the grid of the lights, at most
LIGHT_GRID_BIG = 64          # a light over more cells is tested by every object
FRESH_CHUNK = 512            # objects per parallel work item of grid_pairs


class LightGrid(NamedTuple):
    """The point and spot lights sorted into a grid of cubic cells (light_grid)."""

    frame: np.ndarray       # float64 [6]: the origin of cell (0, 0, 0), 1/edge per axis
    dims: np.ndarray        # int64 [3]: cells per axis
    cell_start: np.ndarray  # int64 [C + 1]: cell c's lights at light_row[start[c]:start[c+1]]
    light_row: np.ndarray   # int32: the light rows of each cell
    big: np.ndarray         # int32: the rows over LIGHT_GRID_BIG cells, which every object tests


class FoundLists(NamedTuple):
    """Per record r the candidate light rows grid_pairs found for it: light_row[seg[r, 0]:]
    [:seg[r, 1]] (the fields of candidates.CandidateLists that candidate_pairs reads)."""

    seg: np.ndarray        # int64 [F, 2]: start, length
    light_row: np.ndarray  # int32


def fresh_object_pairs(rows: np.ndarray, objects: ObjectStore, packed: Packed,
                       params: PairParams, frame: tuple[np.ndarray, bool],
                       cells: LightGrid | None) -> tuple[np.ndarray, PairHeap]:
    """The pairs of the object ``rows`` (ascending) with every competing light, each object
    tested against all of them (direct_pairs) or, given a grid of the lights ``cells``,
    against those of the cells its box overlaps (grid_pairs), as (start [N + 1], PairHeap)
    grouped by object row: valid at ``rows`` and the row after each, which is all that
    pair_cache.replace_lists reads of them. frame = (origin, single) of the records."""
    box = np.empty((rows.size, 8), np.float32 if frame[1] else np.float64)
    recs = Records(box, box.view(np.uint32 if frame[1] else np.uint64), rows)
    visible_objects(objects.bounds_min, objects.bounds_max, objects.mask, rows, rows.size,
                    recs, frame[0])
    compete, dir_all = packed.compete, packed.dir_all
    dir_rows = dir_all[compete[dir_all]]
    if cells is not None:
        return grid_pairs(recs, packed.rows, compete, cells, dir_rows, params, len(objects))
    point_rows = np.flatnonzero(compete & ~packed.is_dir if dir_all.size else compete
                                ).astype(np.int32)
    return direct_pairs(recs, packed.rows, compete, point_rows, dir_rows, params,
                        len(objects))


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _vector_rows(params, box, lights):
    """Whether simd.candidate_run takes these pairs: the contribution model and whole
    8-word rows of records and lights, which it reads."""
    return (params.model == MODEL_CONTRIBUTION and box.shape[1] == 8
            and lights.hot.shape[1] == 8 and lights.f.shape[1] == 8)


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _record_pairs(o, recs, lights, compete, c_j, a, b, dir_rows, out, m, params, vector):
    """The pairs of record o of recs (grid.Records) with the candidate light rows c_j[a:b]
    and the directional ``dir_rows``, appended from m to ``out`` (PairHeap); returns the
    new end. ``vector``: the records and light rows are 8-word float64 rows under the
    contribution model, which simd.candidate_run takes eight candidates at a time.
    candidate_pairs keeps its own copy of these lines: calling this from its parallel
    loop made a full frame's candidates' pass slower in paired runs, though not on
    captured inputs."""
    box, bits = recs.box, recs.bits
    hot, lf = lights.hot, lights.f
    o_p, o_j = out.p, out.light_row
    ob = np.int64(bits[o, 6]) & SHOWN
    # An object out of view (no SHOWN bit in its record) keeps its list but pairs with none.
    if ob == 0:
        b = a
    if vector and b > a:
        # Float64 records: eight candidates a step in vector code (-1: float32).
        # One object at a time on one thread: the buffer past m is free.
        end = candidate_run(box, o, hot, lf, compete, c_j, a, b, o_p, o_j, m, o_p.shape[0])
        if end >= 0:
            a = b
            m = end
    m = scalar_candidates(box, ob, o, lights, compete, c_j, a, b, out, m, params)
    for d in range(dir_rows.shape[0]):
        j = dir_rows[d]
        if ob & np.int64(hot[j, 4]) != 0:
            o_p[m] = hot[j, 6] + hot[j, 7]
            o_j[m] = j
            m += 1
    return m


@nb.njit(cache=True, nogil=True, error_model="numpy")
def direct_pairs(recs, lights, compete, point_rows, dir_rows, params, n):
    """The pairs of a few objects that came into view, each tested against every competing
    light (candidate_pairs' rule with every point and spot light ``point_rows`` a
    candidate): one object a step on the calling thread, no grid. An incremental frame with
    a camera move brings a handful of objects into view; a grid of them walked by every
    light costs, even for one object, the grid's O(N) pass over the rows and every light's
    cell ranges and runs. recs: grid.Records of the objects, rows ascending; lights,
    compete, params as candidate_pairs. DESIGN section 2 ("Affects", "Priority"). Returns
    (start [n + 1], PairHeap): object rows[r]'s pairs at start[rows[r]]..start[rows[r] +
    1], the only entries of start written."""
    rows = recs.rows
    vector = _vector_rows(params, recs.box, lights)
    room = rows.shape[0] * (point_rows.shape[0] + dir_rows.shape[0])
    out = PairHeap(np.empty(room), np.empty(room, np.int32))
    start = np.empty(n + 1, np.int64)
    m = 0
    for r in range(rows.shape[0]):
        start[rows[r]] = m
        m = _record_pairs(r, recs, lights, compete, point_rows, 0, point_rows.shape[0],
                          dir_rows, out, m, params, vector)
        start[rows[r] + 1] = m
    return start, PairHeap(out.p[:m], out.light_row[:m])


@nb.njit(cache=True, nogil=True, error_model="numpy")
def light_grid(hot, rows):
    """The spheres of the point and spot light ``rows`` of light_hot sorted into a grid of
    cubic cells: a LightGrid. The edge is twice the median radius (of at most 1024 of
    them, evenly spaced), so a light spans ~2 cells an axis, made larger until there are
    at most LIGHT_GRID_CELLS cells per light. A sphere's cell range is widened as
    _axis_cells widens it, so rounding never drops a light the exact test keeps.

    Much finer cells make the city's larger objects span many cells, coarser ones give
    each object more lights to test (bench/RESULTS.md, "Measurements behind the code").

    hot: light_hot [L, 8] float64 (priority.PackedLights.hot); rows: int32 light rows.
    DESIGN section 6 (a grid instead of brute force, for the objects that moved)."""
    n = rows.shape[0]
    g_f = np.zeros(6)
    dims = np.ones(3, np.int64)
    if n == 0:
        return LightGrid(g_f, dims, np.zeros(2, np.int64), np.zeros(0, np.int32),
                         np.zeros(0, np.int32))
    lo = np.full(3, np.inf)
    hi = np.full(3, -np.inf)
    radii = np.empty(n)
    for t in range(n):
        j = rows[t]
        radii[t] = hot[j, 3]
        for a in range(3):
            lo[a] = min(lo[a], hot[j, a] - hot[j, 3])
            hi[a] = max(hi[a], hot[j, a] + hot[j, 3])
    edge = max(2.0 * np.median(radii[::max(1, n // 1024)]), 1e-300)
    for a in range(3):
        edge = max(edge, (hi[a] - lo[a]) / (1 << 20))
    while True:
        cells = 1
        for a in range(3):
            dims[a] = max(1, min(1 << 20, int(math.ceil((hi[a] - lo[a]) / edge))))
            cells *= dims[a]
        if cells <= LIGHT_GRID_CELLS * n + 64:
            break
        edge *= 1.25
    for a in range(3):
        g_f[a] = lo[a]
        g_f[3 + a] = 1.0 / edge
    ranges = np.empty((n, 6), np.int64)
    count = np.zeros(cells + 1, np.int64)
    n_big = 0
    for t in range(n):
        j = rows[t]
        x0, x1, _ = _axis_cells(hot[j, 0], hot[j, 3], g_f[0], g_f[3], dims[0])
        y0, y1, _ = _axis_cells(hot[j, 1], hot[j, 3], g_f[1], g_f[4], dims[1])
        z0, z1, _ = _axis_cells(hot[j, 2], hot[j, 3], g_f[2], g_f[5], dims[2])
        ranges[t] = (x0, y0, z0, x1, y1, z1)
        if (x1 - x0 + 1) * (y1 - y0 + 1) * (z1 - z0 + 1) > LIGHT_GRID_BIG:
            n_big += 1
            continue
        for x in range(x0, x1 + 1):
            for y in range(y0, y1 + 1):
                for z in range(z0, z1 + 1):
                    count[(x * dims[1] + y) * dims[2] + z + 1] += 1
    for c in range(cells):
        count[c + 1] += count[c]
    at = count[:-1].copy()
    cell_rows = np.empty(count[cells], np.int32)
    big = np.empty(n_big, np.int32)
    n_big = 0
    for t in range(n):
        x0, y0, z0, x1, y1, z1 = ranges[t]
        if (x1 - x0 + 1) * (y1 - y0 + 1) * (z1 - z0 + 1) > LIGHT_GRID_BIG:
            big[n_big] = rows[t]
            n_big += 1
            continue
        for x in range(x0, x1 + 1):
            for y in range(y0, y1 + 1):
                for z in range(z0, z1 + 1):
                    c = (x * dims[1] + y) * dims[2] + z
                    cell_rows[at[c]] = rows[t]
                    at[c] += 1
    return LightGrid(g_f, dims, count, cell_rows, big)


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _box_cells(box, r, g_f, dims):
    """The cells (x0, y0, z0, x1, y1, z1) of a grid of lights (light_grid) that record r's
    box overlaps."""
    return (_cell(box[r, 0], g_f[0], g_f[3], dims[0]), _cell(box[r, 1], g_f[1], g_f[4], dims[1]),
            _cell(box[r, 2], g_f[2], g_f[5], dims[2]), _cell(box[r, 3], g_f[0], g_f[3], dims[0]),
            _cell(box[r, 4], g_f[1], g_f[4], dims[1]), _cell(box[r, 5], g_f[2], g_f[5], dims[2]))


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _grid_candidates(r, box, lgrid, seen, out, m):
    """The candidate light rows of record r of ``box`` in a grid of lights (light_grid):
    the big lights, then those of the cells its box overlaps, each once (``seen``: the last
    record that took each light row), written from m into ``out``; returns the new end.
    lgrid: LightGrid."""
    g_f, dims, cell_start, cell_rows, big = (lgrid.frame, lgrid.dims, lgrid.cell_start,
                                             lgrid.light_row, lgrid.big)
    for j in big:
        out[m] = j
        m += 1
    x0, y0, z0, x1, y1, z1 = _box_cells(box, r, g_f, dims)
    for x in range(x0, x1 + 1):
        for y in range(y0, y1 + 1):
            base = (x * dims[1] + y) * dims[2]
            for t in range(cell_start[base + z0], cell_start[base + z1 + 1]):
                j = cell_rows[t]
                if seen[j] != r:
                    seen[j] = r
                    out[m] = j
                    m += 1
    return m


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _grid_bound(r, box, lgrid):
    """At least the number of _grid_candidates of record r: the big lights and every entry
    of the cells its box overlaps (a light in several of them counted each time), from the
    cells' starts alone."""
    g_f, dims, cell_start, big = lgrid.frame, lgrid.dims, lgrid.cell_start, lgrid.big
    x0, y0, z0, x1, y1, z1 = _box_cells(box, r, g_f, dims)
    m = big.shape[0]
    for x in range(x0, x1 + 1):
        for y in range(y0, y1 + 1):
            base = (x * dims[1] + y) * dims[2]
            m += cell_start[base + z1 + 1] - cell_start[base + z0]
    return m


@nb.njit(cache=True, nogil=True, parallel=PRANGE_ONLY, error_model="numpy")
def grid_pairs(recs, lights, compete, lgrid, dir_rows, params, n):
    """direct_pairs with each object's candidates from a grid of the point and spot lights
    (light_grid): the lights of the cells its box overlaps, and the big ones. The same
    pairs, in another order within an object. The candidates are listed in parallel over
    blocks of FRESH_CHUNK objects, each into a room sized from the cells' starts
    (_grid_bound), tested by candidate_pairs (its stream, eight candidates a step across
    objects: one object at a time was slower), and the pairs packed in object order.
    lgrid: LightGrid; dir_rows: int64, the competing directional light rows; n: the object
    count; recs (grid.Records), compete, params and the result as direct_pairs'. DESIGN
    section 2 ("Affects", "Priority") on the objects of DESIGN section 6 that moved or
    came into view."""
    rows = recs.rows
    n_l = lights.hot.shape[0]
    f = rows.shape[0]
    n_chunks = (f + FRESH_CHUNK - 1) // FRESH_CHUNK
    c_seg = np.zeros((f, 2), np.int64)
    box = recs.box
    for r in nb.prange(f):
        c_seg[r, 1] = _grid_bound(r, box, lgrid)
    total = 0
    for r in range(f):
        c_seg[r, 0] = total
        total += c_seg[r, 1]
    c_j = np.empty(total, np.int32)
    for ch in nb.prange(n_chunks):
        seen = np.full(n_l, -1, np.int32)
        for r in range(ch * FRESH_CHUNK, min(f, (ch + 1) * FRESH_CHUNK)):
            c_seg[r, 1] = _grid_candidates(r, box, lgrid, seen, c_j, c_seg[r, 0]) - c_seg[r, 0]
    room = total + f * dir_rows.shape[0]
    seg = np.empty((f, 2), np.int64)
    heap = PairHeap(np.empty(room), np.empty(room, np.int32))
    o_p, o_j = heap.p, heap.light_row
    candidate_pairs(np.arange(f), FoundLists(c_seg, c_j), recs, lights, compete, dir_rows,
                    params, seg, heap, 0)
    start = np.empty(n + 1, np.int64)
    m = 0
    for r in range(f):
        start[rows[r]] = m
        for t in range(seg[r, 0], seg[r, 0] + seg[r, 1]):
            o_p[m] = o_p[t]
            o_j[m] = o_j[t]
            m += 1
        start[rows[r] + 1] = m
    return start, PairHeap(o_p[:m], o_j[:m])
