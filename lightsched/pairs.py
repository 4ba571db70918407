"""Light-object pairs (DESIGN section 2, "Affects") and the object pass that consumes them.

Takes the packed lights (priority.py), the rows of the lights that compete for slots and
the object store; returns per visible object its affecting lights with their P, grouped by
object, then runs top-K with hysteresis (select.py) and the fade machine (fade.py) per
object. Pairs are plain arrays (row, P), never Python objects.

The work is light-major, in four kernels:
1. ``visible_order`` + ``visible_objects``: the objects of the grid (the visible ones, or
   every object with the invisible ones' masks hidden, ``SHOWN``) sorted by the grid cell of
   their centre (a counting sort), one record each (lo, hi, mask: 64 bytes in float64, 32
   in the "fast" precision's float32 relative to the first camera); objects larger than a
   cell go past the last cell, to a short list every light tests.
2. ``light_pass`` (parallel over lights): a light walks the columns of cells that can hold
   the centre of an object it reaches (its sphere widened by the largest object
   half-extent, cut column by column), each column one contiguous run of objects; the
   exact range test (d2 <= r*r) filters, then the rest of Affects and P (priority.py); a
   point light under the contribution model takes its run eight records a step in
   vector code (simd.py), the same arithmetic lane by lane. Each
   light writes its own segment of the pair buffers, sized beforehand by ``light_bounds``,
   so the result does not depend on the thread count. The light is fixed in the inner
   loop: its type and data stay in registers, and the objects it meets are neighbours in
   memory.
   Lights are walked in grid-cell order (``light_order``) so neighbouring lights share
   the objects in cache.
3. ``group_pairs``: a counting sort of the pairs by object row, into the pair cache (per
   object a segment of (P, light row)), which the next frame keeps: ``scan_pairs`` finds
   the objects holding pairs of lights that changed, ``replace_lists`` rewrites their
   segments, ``compact_heap`` packs the cache when it is mostly garbage.
4. ``object_pass`` (parallel over objects in row order, all of them or those an
   incremental frame recomputes): state in, selection, fade, outputs out.
A full frame whose objects and grid of every object are the last frame's (lights drifting,
the camera still or moving) takes steps 2 and 3 from candidate lists instead
(scheduler._candidates): ``left_spheres`` finds the lights that left the sphere their lists
were made with, ``spread_lists`` lays out per object the lights whose widened sphere
reached it, ``edit_candidates`` and ``light_lists`` (``compact_light_lists``) follow the
lights that walk the grid again, and ``candidate_pairs`` makes the exact test and P of
each object's candidates, in row order: chunks of objects whose candidates are laid end to
end and taken eight a step whatever object each belongs to (simd.stream_run). An
incremental frame whose lights change runs it on the objects in those lights' lists
(``list_objects``).
A scene small enough for brute force is the same pipeline with a single cell.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from .fade import fade_object, held_slots, steady_slots
from .frustum import SERIAL_LIGHTS
from .jit import PRANGE_ONLY
from .priority import MODEL_CONTRIBUTION, box_d2, falloff, spot_cone, thesis
from .scene import DIRECTIONAL, ON, POINT, SPOT
from .select import (
    F_NEW_P,
    F_NEW_W,
    F_OLD_P,
    F_OLD_W,
    F_P,
    F_ROWS,
    I_ID,
    I_NEW_ID,
    I_NEW_ROW,
    I_NEW_ST,
    I_OLD_ID,
    I_OLD_ROW,
    I_OLD_ST,
    I_PREV_SEL,
    I_ROW,
    I_ROWS,
    hysteresis_key,
    topk_insert,
)
from .shadows import caster_bits, pick_slot_shadows
from .simd import (
    LANES,
    SHOWN,
    candidate_run,
    held_row,
    point_priority,
    point_run,
    prefetch_row,
    spot_priority,
    stream_fill,
    stream_pack,
    stream_run,
    stream_spots,
)

MAX_CELLS = 1 << 21          # bounds grid memory whatever the scene's extent
GROUP_PARTS = 2              # independent histograms when grouping pairs by object
SERIAL_PAIRS = 1 << 15       # fewer pairs are grouped on one thread (group_parts)
OBJECT_CHUNK = 256           # objects per parallel work item of the object pass
LIGHT_CHUNK = 64             # lights per parallel work item of the light pass
SCAN_LANES = 8               # pairs scan_pairs reads per object in a loop of fixed length
# The grid of the lights (light_grid, grid_pairs) for the objects an incremental frame
# moves or brings into view.
LIGHT_GRID_CELLS = 4         # cells per light, at most
LIGHT_GRID_BIG = 64          # a light over more cells is tested by every object
FRESH_CHUNK = 512            # objects per parallel work item of grid_pairs
# candidate_pairs asks for the light rows of the object this many rows ahead, once
# light_hot is over PREFETCH_BYTES: an object's candidates are rows of it at random, which
# the records streaming through L2 push out (on captured inputs, 2 threads: (100k, 10k)
# 4.32 -> 3.93 ms, (1M, 100k) 60.8 -> 46.6; two objects ahead 4.07 and 51.1, four 4.19;
# light_f's rows too, 5.61 against 4.87). The 64 KB of 1k lights stay cached: there the
# prefetches cost +0.04 ms of a full (10k, 1k) frame (paired; bench/RESULTS.md).
PREFETCH_OBJECTS = 1
PREFETCH_BYTES = 1 << 18
# list_objects asks for the seg rows and lists of the lights this far ahead: on a captured
# lights10 (100k, 10k) input (1000 lights, 61k list entries, caches flushed between
# calls) ~115 -> ~90 us; 4 and 16-32 lights ahead gave about the same.
LIST_AHEAD = 8
RUN_SPLIT = 4                # grid cells are this much finer along z (the run axis)
STATIC_K = (4, 8)            # K values the object pass is compiled for (8 is the default)


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _cell(x, origin, inv_h, dim):
    v = (x - origin) * inv_h
    if not v > 0.0:
        return 0
    if v >= dim - 1:
        return dim - 1
    return int(v)


def grid_shape(lo: np.ndarray, hi: np.ndarray, cell: float) -> tuple[np.ndarray, np.ndarray]:
    """(origin and 1/cell edge per axis as float64[6], dims int64[3]) covering the box with
    cells of edge ``cell`` (grown until there are at most MAX_CELLS), cut RUN_SPLIT times
    finer along z: a column of cells is one run of objects whatever its cell count, so a
    finer z trims each run to the light's chord at no cost per column."""
    extent = [max(float(hi[a]) - float(lo[a]), 0.0) for a in range(3)]
    # From the edge asked for, grown only while the cells of this box's actual shape are too
    # many (a flat city is not a cube: growing from a cubic estimate made cells twice too
    # coarse at 1M objects).
    h = max(cell, 1e-300)
    while True:
        edge = (h, h, h / RUN_SPLIT)
        dims = [max(math.ceil(extent[a] / edge[a]), 1) for a in range(3)]
        cells = dims[0] * dims[1] * dims[2]
        if cells <= MAX_CELLS:
            break
        h *= max(1.01, min((cells / MAX_CELLS) ** (1 / 3), 1e3))
    g_f = np.array([float(lo[0]), float(lo[1]), float(lo[2]),
                    1.0 / edge[0], 1.0 / edge[1], 1.0 / edge[2]])
    return g_f, np.array(dims, np.int64)


@nb.njit(cache=True, nogil=True, parallel=PRANGE_ONLY, error_model="numpy")
def _centre_cells(lo, hi, visible, g_f, dims, frame):
    """Per object: its centre's cell, ncell for an object with a half-extent over one cell
    edge (it goes past the last cell, to the big objects every light tests directly), or
    -1 if invisible. frame = (origin [3], single): the box as its record will hold it
    (``record_coord``), so cells and records agree."""
    origin, single = frame
    n = lo.shape[0]
    ncell = dims[0] * dims[1] * dims[2]
    cell_edge = 1.0 / g_f[3]
    key = np.empty(n, np.int64)
    for o in nb.prange(n):
        if not visible[o]:
            key[o] = -1
            continue
        lx = record_coord(lo[o, 0], origin[0], single)
        ly = record_coord(lo[o, 1], origin[1], single)
        lz = record_coord(lo[o, 2], origin[2], single)
        hx = record_coord(hi[o, 0], origin[0], single)
        hy = record_coord(hi[o, 1], origin[1], single)
        hz = record_coord(hi[o, 2], origin[2], single)
        if (hx - lx) / 2 > cell_edge or (hy - ly) / 2 > cell_edge or (hz - lz) / 2 > cell_edge:
            key[o] = ncell
            continue
        x = _cell((lx + hx) / 2, g_f[0], g_f[3], dims[0])
        y = _cell((ly + hy) / 2, g_f[1], g_f[4], dims[1])
        z = _cell((lz + hz) / 2, g_f[2], g_f[5], dims[2])
        key[o] = (x * dims[1] + y) * dims[2] + z
    return key


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def record_coord(x, origin, single):
    """A coordinate as an object record holds it: x - origin, rounded to float32 in
    "fast" precision (origin the first camera), x itself in exact precision (origin 0)."""
    d = x - origin
    return np.float64(np.float32(d)) if single else d


@nb.njit(cache=True, nogil=True, parallel=PRANGE_ONLY, error_model="numpy")
def _counting_sort(key, ncell):
    """Rows with key >= 0 sorted by key (stable): (rows by position, position of each row or
    -1, start of each key's positions [ncell + 2]). GROUP_PARTS runs of rows count and place
    their own rows in parallel; the runs follow each other within a key, so the order is
    the sequential one."""
    n = key.shape[0]
    hist = np.zeros((GROUP_PARTS, ncell + 1), np.int64)
    for q in nb.prange(GROUP_PARTS):
        for o in range(n * q // GROUP_PARTS, n * (q + 1) // GROUP_PARTS):
            if key[o] >= 0:
                hist[q, key[o]] += 1
    cell_start = np.empty(ncell + 2, np.int64)
    run = 0
    for c in range(ncell + 1):
        cell_start[c] = run
        for q in range(GROUP_PARTS):
            cnt = hist[q, c]
            hist[q, c] = run
            run += cnt
    cell_start[ncell + 1] = run
    vis_rows = np.empty(run, np.int64)
    pos_of = np.empty(n, np.int64)
    for q in nb.prange(GROUP_PARTS):
        for o in range(n * q // GROUP_PARTS, n * (q + 1) // GROUP_PARTS):
            c = key[o]
            if c < 0:
                pos_of[o] = -1
                continue
            d = hist[q, c]
            vis_rows[d] = o
            pos_of[o] = d
            hist[q, c] = d + 1
    return vis_rows, pos_of, cell_start


@nb.njit(cache=True, nogil=True, error_model="numpy")
def light_order(hot, rows, g_f, dims):
    """``rows`` sorted by the grid cell of the light's position (a stable counting sort;
    lights beyond the grid count in its border cells): consecutive lights then walk the
    same columns of objects while they are in cache. The order of lights within an
    object's list does not matter (selection breaks ties by id), so this changes nothing
    but speed."""
    ncell = dims[0] * dims[1] * dims[2]
    key = np.empty(rows.shape[0], np.int64)
    counts = np.zeros(ncell + 2, np.int64)
    for t in range(rows.shape[0]):
        j = rows[t]
        x = _cell(hot[j, 0], g_f[0], g_f[3], dims[0])
        y = _cell(hot[j, 1], g_f[1], g_f[4], dims[1])
        z = _cell(hot[j, 2], g_f[2], g_f[5], dims[2])
        key[t] = (x * dims[1] + y) * dims[2] + z
        counts[key[t] + 1] += 1
    for c in range(ncell):
        counts[c + 1] += counts[c]
    out = np.empty_like(rows)
    for t in range(rows.shape[0]):
        out[counts[key[t]]] = rows[t]
        counts[key[t]] += 1
    return out


def visible_order(lo: np.ndarray, hi: np.ndarray, visible: np.ndarray, g_f: np.ndarray,
                  dims: np.ndarray, frame: tuple[np.ndarray, bool]
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Visible object rows sorted by the cell of their centre (a counting sort: neighbours
    in space become neighbours in memory). Returns (vis_rows int64[V], pos_of int64[N]
    (-1 if invisible), cell_start int64[ncell+2]): the objects centred in cell c are
    positions cell_start[c] .. cell_start[c+1]-1, so a column of cells is one run; the
    objects larger than a cell come last, from cell_start[ncell] to V. The caster grid
    passes its own selection as ``visible``; frame = (origin, single) of the records."""
    key = _centre_cells(lo, hi, visible, g_f, dims, frame)
    return _counting_sort(key, int(dims[0] * dims[1] * dims[2]))


@nb.njit(cache=True, nogil=True, parallel=PRANGE_ONLY, error_model="numpy")
def visible_objects(lo, hi, omask, vis_rows, n_small, recs, origin):
    """Per grid position v (parallel), written into recs = (vis_box [V, 8], its integer view
    vis_bits): (lo - origin, hi - origin, mask (as bits), e2 = |hi - lo|^2) of object row
    vis_rows[v], one cache line per object for the tests (float64, origin 0: exact
    precision; float32 relative to the first camera: "fast", half a line). Returns the
    largest half-extent per axis of the objects at positions below n_small (those in
    cells), which widens every light's cell range. Positions are written in order and rows
    read where they are: measured ~35% faster than the other way round at 100k objects.
    Per-chunk maxima keep the reduction parallel."""
    vis_box, vis_bits = recs
    nv = vis_rows.shape[0]
    n_chunks = (nv + OBJECT_CHUNK - 1) // OBJECT_CHUNK
    chunk_ext = np.zeros((n_chunks, 3))
    for ch in nb.prange(n_chunks):
        for v in range(ch * OBJECT_CHUNK, min(nv, (ch + 1) * OBJECT_CHUNK)):
            o = vis_rows[v]
            for a in range(3):
                vis_box[v, a] = lo[o, a] - origin[a]
                vis_box[v, 3 + a] = hi[o, a] - origin[a]
                if v < n_small:
                    # From the record as stored (float32 in "fast" precision), as the walk
                    # sees it.
                    half = (np.float64(vis_box[v, 3 + a]) - np.float64(vis_box[v, a])) / 2
                    chunk_ext[ch, a] = max(chunk_ext[ch, a], half)
            ex = hi[o, 0] - lo[o, 0]
            ey = hi[o, 1] - lo[o, 1]
            ez = hi[o, 2] - lo[o, 2]
            vis_bits[v, 6] = omask[o]
            vis_box[v, 7] = ex * ex + ey * ey + ez * ez  # read back by float64 records only
    ext = np.zeros(3)
    for ch in range(n_chunks):
        for a in range(3):
            ext[a] = max(ext[a], chunk_ext[ch, a])
    return ext


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _record_fits(o, lo, hi, grid, v, frame):
    """Whether object row o's box, its record at grid position v (below the big objects),
    lies inside the slab of that position's cell widened by the grid's ext on every
    axis (move_records)."""
    g_f, dims, cell_start, ext, _ = grid
    origin, single = frame
    key = np.searchsorted(cell_start, v, side="right") - 1
    cell = (key // (dims[1] * dims[2]), (key // dims[2]) % dims[1], key % dims[2])
    for a in range(3):
        h = 1.0 / g_f[3 + a]
        if not (record_coord(lo[o, a], origin[a], single) >= g_f[a] + cell[a] * h - ext[a]
                and record_coord(hi[o, a], origin[a], single)
                <= g_f[a] + (cell[a] + 1) * h + ext[a]):
            return False
    return True


@nb.njit(cache=True, nogil=True, parallel=PRANGE_ONLY, error_model="numpy")
def move_records(lo, hi, rows, shown_mask, grid, recs, pos_of, frame):
    """The records of the moved object ``rows`` rewritten in place in a kept grid of every
    object, as visible_objects writes them (shown_mask: per row of ``rows``, its record's
    mask word, SHOWN). Every walk of the grid (_light_cells, _slab_d2, _column_run) finds an
    object by the cell its record sits in: the slab of that cell's centres widened by the
    largest half-extent ``ext`` on each axis. So a record may stay where it is while the
    object's new box lies inside that widened slab, whatever cell its centre is now in;
    the big objects after the cells, which every light tests, take any box. Returns False,
    having written nothing, when a box leaves its slab: the grid is then made again. An
    object moving a little each frame keeps its record for many frames, where making the
    grid of 100k objects took ~5 ms (1000 records rewritten: ~0.3 ms on one thread, each
    a few cache misses). frame = (origin, single) as record_coord."""
    vis_box, vis_bits = recs
    origin = frame[0]
    n_small = grid[2][grid[1][0] * grid[1][1] * grid[1][2]]
    m = rows.shape[0]
    fits = np.empty(m, np.bool_)
    for r in nb.prange(m):
        v = pos_of[rows[r]]
        fits[r] = v >= n_small or (v >= 0 and _record_fits(rows[r], lo, hi, grid, v, frame))
    if not fits.all():
        return False
    for r in nb.prange(m):
        o = rows[r]
        v = pos_of[o]
        for a in range(3):
            vis_box[v, a] = lo[o, a] - origin[a]
            vis_box[v, 3 + a] = hi[o, a] - origin[a]
        ex = hi[o, 0] - lo[o, 0]
        ey = hi[o, 1] - lo[o, 1]
        ez = hi[o, 2] - lo[o, 2]
        vis_bits[v, 6] = shown_mask[r]
        vis_box[v, 7] = ex * ex + ey * ey + ez * ez
    return True


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _axis_cells(p, reach, origin, inv_h, dim):
    slack = reach * 1e-9 + abs(p) * 1e-15
    lo = p - reach - slack
    hi = p + reach + slack
    miss = hi < origin or lo > origin + dim / inv_h
    return _cell(lo, origin, inv_h, dim), _cell(hi, origin, inv_h, dim), miss


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _light_cells(hot, j, g_f, dims, ext):
    """The clamped range of the cells that can hold the centre of an object light j
    reaches: its bounding cube widened by the largest object half-extent (and a relative
    1e-9 so rounding never drops a pair); empty (x1 < x0) if that misses the grid."""
    x0, x1, mx = _axis_cells(hot[j, 0], hot[j, 3] + ext[0], g_f[0], g_f[3], dims[0])
    y0, y1, my = _axis_cells(hot[j, 1], hot[j, 3] + ext[1], g_f[1], g_f[4], dims[1])
    z0, z1, mz = _axis_cells(hot[j, 2], hot[j, 3] + ext[2], g_f[2], g_f[5], dims[2])
    if mx or my or mz:
        return (1, 0, 0, 0, 0, 0)
    return (x0, y0, z0, x1, y1, z1)


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _slab_d2(p, cell, origin, h, dim, ext_a):
    """Squared distance along one axis from p to the centres' slab of a cell row, widened
    by the largest object half-extent; the clamped border cells reach to infinity and a
    relative 1e-9 margin absorbs rounding."""
    eps = h * 1e-9 + abs(origin) * 1e-15
    lo = -np.inf if cell == 0 else origin + cell * h - eps - ext_a
    hi = np.inf if cell == dim - 1 else origin + (cell + 1) * h + eps + ext_a
    d = max(lo - p, 0.0, p - hi)
    return d * d


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _reach2(hot, j):
    """Squared radius of light j's sphere widened by a relative 1e-9 (and 1e-15 of its
    coordinates), so the cell walk's rounding never drops an object the exact test keeps."""
    r = hot[j, 3]
    big_r = r + r * 1e-9 + (abs(hot[j, 0]) + abs(hot[j, 1]) + abs(hot[j, 2])) * 1e-15
    return big_r * big_r


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _column_run(hot, j, c, x, y, dxx, rr, g_f, dims, cell_start, ext):
    """Positions [v0, v1) of the objects centred in the column (x, y) of light j's cell
    range c that its widened sphere (squared radius rr; dxx its x slab distance) can reach:
    the cube is cut to the sphere column by column, empty when the sphere misses the
    column's slab, else trimmed to its chord along z."""
    dd = dxx + _slab_d2(hot[j, 1], y, g_f[1], 1.0 / g_f[4], dims[1], ext[1])
    if dd > rr:
        return 0, 0
    zr = math.sqrt(rr - dd) * (1.0 + 1e-9) + ext[2]
    z0 = max(c[2], _cell(hot[j, 2] - zr, g_f[2], g_f[5], dims[2]))
    z1 = min(c[5], _cell(hot[j, 2] + zr, g_f[2], g_f[5], dims[2]))
    if z1 < z0:
        return 0, 0
    base = (x * dims[1] + y) * dims[2]
    return cell_start[base + z0], cell_start[base + z1 + 1]


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _light_bound(hot, j, g_f, dims, cell_start, ext, n_big, n_vis):
    if (np.int64(hot[j, 5]) >> 3) & 3 == DIRECTIONAL:
        return n_vis
    c = _light_cells(hot, j, g_f, dims, ext)
    total = n_big
    # The whole cube, not the sphere cut: a looser bound is cheaper to count.
    for x in range(c[0], c[3] + 1):
        for y in range(c[1], c[4] + 1):
            base = (x * dims[1] + y) * dims[2]
            total += cell_start[base + c[5] + 1] - cell_start[base + c[2]]
    return total


@nb.njit(cache=True, nogil=True, parallel=PRANGE_ONLY, error_model="numpy")
def light_bounds(hot, rows, grid, n_vis):
    """Offsets [len(rows) + 1] of each light's segment in the pair buffers: the prefix sum
    of an upper bound of the pairs it can emit (objects centred in the cells of its
    widened cube plus the big objects; every visible object for a directional light).
    Parallel from SERIAL_LIGHTS lights."""
    g_f, dims, cell_start, ext, big_pos = grid
    n_big = big_pos.shape[0]
    out = np.zeros(rows.shape[0], np.int64)
    if rows.shape[0] < SERIAL_LIGHTS:
        for t in range(rows.shape[0]):
            out[t] = _light_bound(hot, rows[t], g_f, dims, cell_start, ext, n_big, n_vis)
    else:
        # (The grid unpacked out of the loop, as in light_pass.)
        for t in nb.prange(rows.shape[0]):
            out[t] = _light_bound(hot, rows[t], g_f, dims, cell_start, ext, n_big, n_vis)
    offsets = np.zeros(rows.shape[0] + 1, np.int64)
    for t in range(rows.shape[0]):
        offsets[t + 1] = offsets[t] + out[t]
    return offsets


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _pair_p(hot, lf, j, typ, v, d2, vis_box, model, w_obj, w_int):
    """(affects, P) of light j and visible object v once d2 <= r*r holds: the spot cone and
    the model's P (priority.py holds the rules). The bounding sphere (centre (lo + hi)/2,
    R = |hi - lo|/2) is only built when a rule needs it."""
    e2 = _record_e2(vis_box, v)
    if typ == SPOT or model != MODEL_CONTRIBUTION:
        geo = _geometry(vis_box, v)
        s = 1.0
        if typ == SPOT:
            meets, s = spot_cone(hot, lf, j, geo, model == MODEL_CONTRIBUTION)
            if not meets:
                return False, 0.0
        if model != MODEL_CONTRIBUTION:
            return True, thesis(hot, lf, j, geo, w_obj, w_int)
        return True, falloff(hot[j, 6], hot[j, 3], d2, e2) * s + hot[j, 7]
    return True, falloff(hot[j, 6], hot[j, 3], d2, e2) + hot[j, 7]


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _exact_pair(hot, lf, j, lm, typ, v, d2, vis_box, vis_bits, vis_rows, pair_obj, pair_p, n,
                model, w_obj, w_int):
    """The rest of the exact float64 Affects test of light j (mask lm) and visible object
    v once d2 <= r*r holds (the mask, then _pair_p); on a hit appends (object row, P) at n.
    Returns the new n. The record arrays come one by one, not as the ``vis`` tuple: a tuple
    of arrays unpacked once per pair kept their reference counting in the loop (measured
    +27% on the light pass)."""
    if np.int64(vis_bits[v, 6]) & lm == 0:
        return n
    hit, p = _pair_p(hot, lf, j, typ, v, d2, vis_box, model, w_obj, w_int)
    if hit:
        pair_obj[n] = vis_rows[v]
        pair_p[n] = p
        n += 1
    return n


@nb.njit(cache=True, nogil=True, parallel=PRANGE_ONLY, error_model="numpy")
def light_pass(lights, rows, grid, vis, offsets, pair_obj, pair_p, params):
    """For each light in ``rows`` (parallel), its affecting pairs with visible objects:
    pair_obj / pair_p [offsets[t] : offsets[t] + count[t]] = (object row, P).

    lights = (light_hot, light_f); grid = (origin and 1/h, dims, cell_start, ext,
    big_pos); vis = (vis_box, vis_bits, vis_rows); params = (model, w_obj,
    w_int). Returns count per light."""
    model = int(params[0])
    w_obj = params[1]
    w_int = params[2]
    # Unpacked once: a tuple of arrays unpacked in the loop (once a light, in a helper)
    # keeps its reference counting there, atomic operations on counts both threads share.
    hot, lf = lights
    g_f, dims, cell_start, ext, big_pos = grid
    vis_box, vis_bits, vis_rows = vis
    n_vis = vis_box.shape[0]
    count = np.zeros(rows.shape[0], np.int64)
    n_chunks = (rows.shape[0] + LIGHT_CHUNK - 1) // LIGHT_CHUNK
    for ch in nb.prange(n_chunks):
        keep = (np.empty(256, np.int32), np.empty(256))
        for t in range(ch * LIGHT_CHUNK, min(rows.shape[0], (ch + 1) * LIGHT_CHUNK)):
            if t + 1 < rows.shape[0]:
                prefetch_row(hot, rows[t + 1])
            # Light rows[t]'s pairs into its segment of pair_obj / pair_p; ``keep`` is the
            # filter scratch of _run_pairs (regrown there when short).
            j = rows[t]
            lm = np.int64(hot[j, 4])
            typ = (np.int64(hot[j, 5]) >> 3) & 3
            n = offsets[t]
            if typ == DIRECTIONAL:
                p = hot[j, 6] + hot[j, 7]
                for v in range(n_vis):
                    if np.int64(vis_bits[v, 6]) & lm != 0:
                        pair_obj[n] = vis_rows[v]
                        pair_p[n] = p
                        n += 1
                count[t] = n - offsets[t]
                continue
            c = _light_cells(hot, j, g_f, dims, ext)
            rr = _reach2(hot, j)
            for x in range(c[0], c[3] + 1):
                dxx = _slab_d2(hot[j, 0], x, g_f[0], 1.0 / g_f[3], dims[0], ext[0])
                if dxx > rr:
                    continue
                for y in range(c[1], c[4] + 1):
                    # The objects centred in a column of cells are one run of positions.
                    v0, v1 = _column_run(hot, j, c, x, y, dxx, rr, g_f, dims, cell_start, ext)
                    if v1 > v0:
                        n, keep = _run_pairs(v0, v1, hot, lf, j, lm, typ, vis_box, vis_bits,
                                             vis_rows, pair_obj, pair_p, n, keep, model, w_obj,
                                             w_int)
            if vis_box.itemsize == 8:
                # Float64 records: the walk left (position, d2) of the hits (simd.point_run).
                if typ == POINT and model == MODEL_CONTRIBUTION:
                    point_priority(vis_box, vis_rows, _point_light(hot, j), pair_obj, pair_p,
                                   offsets[t], n)
                elif typ == SPOT and model == MODEL_CONTRIBUTION:
                    spot = (lf[j, 0], lf[j, 1], lf[j, 2], lf[j, 3], lf[j, 4], lf[j, 5])
                    n = spot_priority(vis_box, vis_rows, _point_light(hot, j), spot, pair_obj,
                                      pair_p, offsets[t], n)
                else:
                    n = _finish_hits(hot, lf, j, typ, offsets[t], n, vis_box, vis_rows,
                                     pair_obj, pair_p, model, w_obj, w_int)
            r = hot[j, 3]
            rr_exact = r * r
            for b in range(big_pos.shape[0]):
                v = big_pos[b]
                d2 = box_d2(vis_box, v, hot[j, 0], hot[j, 1], hot[j, 2])
                if d2 <= rr_exact:
                    n = _exact_pair(hot, lf, j, lm, typ, v, d2, vis_box, vis_bits, vis_rows,
                                    pair_obj, pair_p, n, model, w_obj, w_int)
            count[t] = n - offsets[t]
    return count


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _point_light(hot, j):
    """Light j as simd.point_run, point_priority and spot_priority take it."""
    return hot[j, 0], hot[j, 1], hot[j, 2], hot[j, 3], hot[j, 4], hot[j, 6], hot[j, 7]


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _finish_hits(hot, lf, j, typ, n0, n1, vis_box, vis_rows, pair_obj, pair_p, model, w_obj,
                 w_int):
    """The hits simd.point_run left at n0..n1-1, (position, d2), through the rest of
    Affects and P (_pair_p: the spot cone, the thesis model), kept ones compacted in place
    as (object row, P). Returns the new end."""
    m = n0
    for i in range(n0, n1):
        v = pair_obj[i]
        hit, p = _pair_p(hot, lf, j, typ, v, pair_p[i], vis_box, model, w_obj, w_int)
        if hit:
            pair_obj[m] = vis_rows[v]
            pair_p[m] = p
            m += 1
    return m


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _run_pairs(v0, v1, hot, lf, j, lm, typ, vis_box, vis_bits, vis_rows, pair_obj, pair_p, n,
               keep, model, w_obj, w_int):
    """The pairs of light j with the objects at positions v0..v1-1, appended at n. Float64
    records go eight at a time through simd.point_run (the range test and the mask), which
    appends (position, d2) of the hits; light_pass finishes them after the walk. Float32
    records ("fast") take the scalar loop: the range test (exact, DESIGN's d2 <= r*r)
    compacts the survivors and their d2 into ``keep`` without branching (a test that fails
    at random would mispredict); the rest of Affects and P run on survivors only. Returns
    (new n, keep, regrown when short)."""
    end = point_run(vis_box, vis_rows, v0, v1, _point_light(hot, j), pair_obj, pair_p, n)
    if end >= 0:
        return end, keep
    p0 = hot[j, 0]
    p1 = hot[j, 1]
    p2 = hot[j, 2]
    r = hot[j, 3]
    rr_exact = r * r
    if v1 - v0 > keep[0].shape[0]:
        keep = (np.empty(2 * (v1 - v0), np.int32), np.empty(2 * (v1 - v0)))
    kept, kept_d2 = keep
    m = 0
    for v in range(v0, v1):
        d2 = box_d2(vis_box, v, p0, p1, p2)
        kept[m] = v
        kept_d2[m] = d2
        m += d2 <= rr_exact
    for i in range(m):
        n = _exact_pair(hot, lf, j, lm, typ, kept[i], kept_d2[i], vis_box, vis_bits, vis_rows,
                        pair_obj, pair_p, n, model, w_obj, w_int)
    return n, keep


@nb.njit(cache=True, nogil=True, parallel=PRANGE_ONLY, error_model="numpy")
def affects_any(lights, rows, grid, vis):
    """Per light of ``rows`` (parallel): whether it affects at least one object of the grid
    (DESIGN "Affects": mask, range, cone), stopping at the first hit. An incremental frame
    asks this of its shadowed lights, the shadow ranking's candidates, instead of walking
    every light."""
    hot, lf = lights
    g_f, dims, cell_start, ext, big_pos = grid
    vis_box, vis_bits = vis[0], vis[1]
    out = np.zeros(rows.shape[0], np.bool_)
    for t in nb.prange(rows.shape[0]):
        j = rows[t]
        lm = np.int64(hot[j, 4])
        typ = (np.int64(hot[j, 5]) >> 3) & 3
        hit = False
        if typ == DIRECTIONAL:
            for v in range(vis_box.shape[0]):
                if np.int64(vis_bits[v, 6]) & lm != 0:
                    hit = True
                    break
            out[t] = hit
            continue
        c = _light_cells(hot, j, g_f, dims, ext)
        rr = _reach2(hot, j)
        for x in range(c[0], c[3] + 1):
            dxx = _slab_d2(hot[j, 0], x, g_f[0], 1.0 / g_f[3], dims[0], ext[0])
            if hit or dxx > rr:
                continue
            for y in range(c[1], c[4] + 1):
                if hit:
                    break
                v0, v1 = _column_run(hot, j, c, x, y, dxx, rr, g_f, dims, cell_start, ext)
                for v in range(v0, v1):
                    if _affects(hot, lf, j, lm, typ, v, vis_box, vis_bits):
                        hit = True
                        break
        for b in range(big_pos.shape[0]):
            if hit:
                break
            hit = _affects(hot, lf, j, lm, typ, big_pos[b], vis_box, vis_bits)
        out[t] = hit
    return out


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _affects(hot, lf, j, lm, typ, v, vis_box, vis_bits):
    """DESIGN "Affects" of point or spot light j (mask lm) and visible object v."""
    if np.int64(vis_bits[v, 6]) & lm == 0:
        return False
    r = hot[j, 3]
    d2 = box_d2(vis_box, v, hot[j, 0], hot[j, 1], hot[j, 2])
    if not d2 <= r * r:
        return False
    if typ != SPOT:
        return True
    return spot_cone(hot, lf, j, _geometry(vis_box, v), False)[0]


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _geometry(box, v):
    """(centre x, y, z, R, e2) of record v: centre (lo + hi)/2, e2 = |hi - lo|^2, R =
    sqrt(e2)/2 (DESIGN "Affects"), in float64 whatever the records' precision (float32 +
    float32 would round in float32). A float64 record holds e2 (loading it was measured
    ~12% of a full frame faster than computing it on every pair); a float32 one cannot
    hold it exactly, so it is computed from the record's coordinates."""
    e2 = _record_e2(box, v)
    return ((np.float64(box[v, 0]) + np.float64(box[v, 3])) / 2,
            (np.float64(box[v, 1]) + np.float64(box[v, 4])) / 2,
            (np.float64(box[v, 2]) + np.float64(box[v, 5])) / 2, math.sqrt(e2) / 2, e2)


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _record_e2(box, v):
    """e2 = |hi - lo|^2 of record v (see _geometry)."""
    if box.itemsize == 8:
        return np.float64(box[v, 7])
    ex = np.float64(box[v, 3]) - np.float64(box[v, 0])
    ey = np.float64(box[v, 4]) - np.float64(box[v, 1])
    ez = np.float64(box[v, 5]) - np.float64(box[v, 2])
    return ex * ex + ey * ey + ez * ez


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _caster(hot, lf, light, v, box, box_rows, casts, omask, lo, hi, w_lo, w_hi, vn, vq, vm,
            out_rows, out_mask, n):
    """Appends (object row, caster mask) of grid position v for shadowed light ``light`` =
    (row j, type, index t of its culling volumes) at n when it is a caster: casts_shadows,
    mask, d2 <= r*r, then shadows.caster_bits. Returns the new n. box, box_rows, lo, hi:
    the grid's records, their object rows and lo / hi views; casts, omask, w_lo, w_hi: the
    store's casts_shadows, mask, bounds_min, bounds_max (in a grid of every object the
    records of the invisible ones hold no SHOWN bit, so they pair with no light, but
    invisible objects cast); vn, vq, vm: the culling volumes. The arrays come one by one: a tuple of
    them unpacked once an object kept its reference counting in the walk."""
    j, typ, t = light
    o = box_rows[v]
    if not casts[o] or np.int64(omask[o]) & np.int64(hot[j, 4]) == 0:
        return n
    r = hot[j, 3]
    if not box_d2(box, v, hot[j, 0], hot[j, 1], hot[j, 2]) <= r * r:
        return n
    bits = caster_bits(hot, lf, j, typ, t, vn, vq, vm, lo, hi, v, w_lo, w_hi, o)
    if bits != 0:
        out_rows[n] = o
        out_mask[n] = bits
        n += 1
    return n


@nb.njit(cache=True, nogil=True, parallel=PRANGE_ONLY, error_model="numpy")
def grid_casters(lights, rows, grid, recs, objects, vols, offsets, out):
    """Casters (DESIGN "Casters") of the shadowed point and spot lights ``rows`` (parallel)
    among the objects of a grid built like the light pass's (visible_order /
    visible_objects): each light walks the same column runs as ``light_pass`` and keeps
    the objects that pass ``_caster``. vols = culling volumes indexed like rows; recs =
    (records [V, 8], their integer view, object row per position); objects = (casts_shadows,
    mask, bounds_min, bounds_max) of the store, whose world boxes meet the culling volumes (the
    records may be relative to the first camera); out = (object rows, caster masks), light t
    writing from offsets[t] (``light_bounds`` on this grid). Returns the count per light;
    a light's rows come ascending (sorted here, per light: the frame keeps them as they
    are)."""
    # Every tuple unpacked here: arrays taken out of a tuple inside the parallel loop were
    # written to copies (numba 0.68 parfors), and the stores were lost.
    hot, lf = lights
    g_f, dims, cell_start, ext, big_pos = grid
    box, box_rows = recs[0], recs[2]
    lo, hi = box[:, 0:3], box[:, 3:6]
    casts, omask, w_lo, w_hi = objects
    vn, vq, vm = vols[0], vols[1], vols[2]
    out_rows, out_mask = out
    count = np.zeros(rows.shape[0], np.int64)
    for t in nb.prange(rows.shape[0]):
        j = rows[t]
        light = (j, (np.int64(hot[j, 5]) >> 3) & 3, np.int64(t))
        n = offsets[t]
        c = _light_cells(hot, j, g_f, dims, ext)
        rr = _reach2(hot, j)
        for x in range(c[0], c[3] + 1):
            dxx = _slab_d2(hot[j, 0], x, g_f[0], 1.0 / g_f[3], dims[0], ext[0])
            if dxx > rr:
                continue
            for y in range(c[1], c[4] + 1):
                v0, v1 = _column_run(hot, j, c, x, y, dxx, rr, g_f, dims, cell_start, ext)
                for v in range(v0, v1):
                    n = _caster(hot, lf, light, v, box, box_rows, casts, omask, lo, hi, w_lo,
                                w_hi, vn, vq, vm, out_rows, out_mask, n)
        for b in range(big_pos.shape[0]):
            n = _caster(hot, lf, light, big_pos[b], box, box_rows, casts, omask, lo, hi, w_lo,
                        w_hi, vn, vq, vm, out_rows, out_mask, n)
        a = offsets[t]
        order = np.argsort(out_rows[a:n])
        sorted_rows, sorted_mask = out_rows[a:n][order], out_mask[a:n][order]
        out_rows[a:n] = sorted_rows
        out_mask[a:n] = sorted_mask
        count[t] = n - a
    return count


@nb.njit(cache=True, nogil=True, parallel=PRANGE_ONLY, error_model="numpy")
def group_pairs(rows, offsets, count, pair_obj, pair_p, out):
    """Counting sort of the pairs by object row, so the object pass reads its lists in
    the order it writes its outputs. The lights are split into one run per row of the
    histogram, each counted and placed with its own row (in parallel when there are
    several); within an object the runs follow each other, so the order of its lights is
    the order of ``rows`` whatever the runs and threads. out = (hist [Q, N+1] int32 (int64
    from 2^31 pairs) scratch, start [N+1], (P float64 [H], light row int32 [H])), reused
    buffers; fills start and the pairs (P, light row): one position, two stores per
    scattered pair.

    Q = 1 runs on the calling thread: with two runs both threads store into every
    object's segment, the lines of the small segments go back and forth between the
    cores, and below ~2^15 pairs one thread is faster (``group_parts``)."""
    hist, start, (pair_p_out, pair_j_out) = out
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
    SERIAL_PAIRS, else GROUP_PARTS. On a frame's captured inputs (caches flushed, paired
    medians), one run against two: (1k, 100) full, 3.7k pairs, -25 us of ~77; (10k, 1k)
    lights10, 3.7k pairs, -29 of ~125; (100k, 10k) lights10, 44k pairs, 841 against 791
    us; (1M, 100k) lights10, 360k pairs, 7.55 against 6.58 ms (bench/RESULTS.md)."""
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
def group_few(rows, offsets, count, pair_obj, pair_p):
    """group_pairs for a few pairs: a stable sort by object row instead of a histogram of
    every object, whose O(N) clearing and prefix sum took ~0.4 ms at 100k objects for no
    pair at all. Returns (object row per pair, ascending; (P, light row)), each object's
    lights in the order of ``rows``; ``start_at`` gives the segments."""
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
    return obj[order], (p[order], j[order])


@nb.njit(cache=True, nogil=True, error_model="numpy")
def start_at(rows, obj, n):
    """start [n + 1] of pairs grouped by object row (``obj``: each pair's row, ascending)
    at the object ``rows`` (ascending) and the row after each, the only entries written:
    start[o] = the number of pairs of rows below o."""
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


@nb.njit(cache=True, nogil=True, parallel=PRANGE_ONLY, error_model="numpy")
def candidate_pairs(rows, cands, recs, lights, compete, dir_rows, params, out, used):
    """The pairs of the object ``rows`` (int64, ascending) from their candidate lights
    (scheduler._Candidates: the point and spot lights whose sphere, widened by a skin,
    reached the object when its list was made, and which still lies inside that widened
    sphere): per candidate that competes, the exact Affects test and P (_pair_p, as the
    light pass), then the competing directional lights ``dir_rows``. So a frame whose
    lights moved within their skins walks no grid and groups nothing, and finds the same
    pairs (bench/RESULTS.md, Next 10 and ebb5ec0: the pairs and lists
    stages of a full (100k, 10k) frame 8.3 -> 6.6 ms, the lists' upkeep included); an
    incremental frame, those of the objects a changed light may reach.

    Under the contribution model with float64 records and no directional light in the
    slots, each chunk of rows runs as a stream (_stream_chunk): their candidates laid end
    to end and taken eight a step in vector code whatever object each belongs to, the spot
    lights' cones eight at a time after them, then the pairs packed into the chunk's room.
    Object by object (candidate_run, eight candidates of one object a step), a step held
    6.2 candidates on average and a branch on its spots' cones failed unpredictably (40%
    of the steps hold a spot): on captured inputs of a full (100k, 10k) frame, 2.81 ->
    2.07 ms (bench/RESULTS.md). Otherwise object by object: candidate_run, or the scalar
    loop below (other models, "fast" float32 records); where the lights' rows do not stay
    cached, those of the next object's candidates are prefetched while this one's are
    tested (PREFETCH_OBJECTS).

    cands = (seg [N, 2] (start, length), light row int32 [C]); recs = (boxes [N, 8], their
    integer view): the grid's records in object row order; lights = (light_hot, light_f);
    params = (model, w_obj, w_int); out = (seg [N, 2], P [H], light row int32 [H]), the
    heap's records from ``used`` on free for the rows' candidates plus len(dir_rows) per
    row. Writes the rows' segments (the others' are left as they are), each object's pairs
    in candidate order within the room of its chunk of rows, and returns (the end of those
    rooms, the number of pairs written, the number of pairs the rows' old segments held);
    (that end, -1, that number) with nothing written when the heap is shorter than it, so
    that a caller may size the heap from an estimate or pack it. ``used`` = 0 means no
    segment holds a record (a full frame's seg is new, and not read): an incremental frame
    learns its room and the pairs it drops in the one parallel pass over its rows that
    sizes the chunks (a serial pass over 44k of 100k rows took ~0.2 ms: those rows' seg
    entries are cache misses)."""
    c_seg, c_j = cands
    box, bits = recs
    hot, lf = lights
    o_seg, o_p, o_j = out
    model = int(params[0])
    n_rows = rows.shape[0]
    n_dir = dir_rows.shape[0]
    # candidate_run and the stream read whole 8-word rows.
    vector = (model == MODEL_CONTRIBUTION and box.shape[1] == 8 and hot.shape[1] == 8
              and lf.shape[1] == 8)
    stream = vector and n_dir == 0
    far = hot.nbytes > PREFETCH_BYTES
    n_chunks = (n_rows + OBJECT_CHUNK - 1) // OBJECT_CHUNK
    # The chunks' rooms summed in parallel: at (1M, 100k) a serial pass over the rows'
    # lengths (16 MB of segments, read with a stride) took ~0.5 ms.
    room = np.empty(n_chunks + 1, np.int64)
    room[0] = used
    dropped = np.zeros(n_chunks, np.int64)
    for ch in nb.prange(n_chunks):
        size = 0
        old = 0
        for r in range(ch * OBJECT_CHUNK, min(n_rows, (ch + 1) * OBJECT_CHUNK)):
            o = rows[r]
            size += c_seg[o, 1] + n_dir
            if used:
                old += o_seg[o, 1]
        room[ch + 1] = size
        dropped[ch] = old
    for ch in range(n_chunks):
        room[ch + 1] += room[ch]
    at = room[n_chunks]
    if at > o_p.shape[0]:
        return at, -1, dropped.sum()
    wrote = np.empty(n_chunks, np.int64)
    for ch in nb.prange(n_chunks):
        r0 = ch * OBJECT_CHUNK
        r1 = min(n_rows, r0 + OBJECT_CHUNK)
        if stream:
            k = _stream_chunk(cands, recs, lights, compete, (rows, r0, r1), room[ch:ch + 2],
                              out)
            if k >= 0:
                wrote[ch] = k
                continue
        m = room[ch]
        for r in range(r0, r1):
            o = rows[r]
            o_seg[o, 0] = m
            ahead = r + PREFETCH_OBJECTS
            if far and ahead < n_rows:
                oa = rows[ahead]
                if np.int64(bits[oa, 6]) & SHOWN != 0:
                    for t in range(c_seg[oa, 0], c_seg[oa, 0] + c_seg[oa, 1]):
                        prefetch_row(hot, c_j[t])
            ob = np.int64(bits[o, 6]) & SHOWN
            # An object out of view (no SHOWN bit in its record) keeps its list but pairs
            # with none.
            a = c_seg[o, 0]
            b = a + (c_seg[o, 1] if ob != 0 else 0)
            if vector and b > a:
                # Float64 records: eight candidates a step in vector code (-1: float32).
                end = candidate_run(box, o, hot, lf, compete, c_j, a, b, o_p, o_j, m)
                if end >= 0:
                    a = b
                    m = end
            m = scalar_candidates(box, ob, o, lights, compete, c_j, a, b, (o_p, o_j), m,
                                  params)
            for d in range(n_dir):
                j = dir_rows[d]
                if ob & np.int64(hot[j, 4]) != 0:
                    o_p[m] = hot[j, 6] + hot[j, 7]
                    o_j[m] = j
                    m += 1
            o_seg[o, 1] = m - o_seg[o, 0]
        wrote[ch] = m - room[ch]
    return at, wrote.sum(), dropped.sum()


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _stream_chunk(cands, recs, lights, compete, span, room, out):
    """candidate_pairs' vector path for the object rows of span = (rows, r0, r1), i.e.
    rows[r0:r1] (no directional light in the slots): their
    candidates laid end to end (simd.stream_fill), the exact test and P eight entries a
    step (stream_run), the spots in range eight a step (stream_spots), the pairs packed
    from room[0] on (stream_pack; room[1]: the end of the chunk's room), each object's
    segment from the pairs before its first entry. The same pairs, in the same order and
    bits, as candidate_run object by object. Returns the number of pairs written, or -1,
    having written nothing, for float32 records. out as candidate_pairs'."""
    rows, r0, r1 = span
    o_seg, o_p, o_j = out
    base = room[0]
    # Each step stores eight entries whole: room for one more step.
    ints = np.empty((3, room[1] - base + LANES), np.int32)
    stream = (ints[0], ints[1])
    spots = ints[2]
    starts = np.empty(r1 - r0 + 1, np.int64)
    n_s = stream_fill(cands, recs, rows, r0, r1, stream, starts)
    if n_s < 0:
        return -1
    box = recs[0]
    results = (np.empty(n_s + LANES), np.empty(n_s + LANES, np.uint8))
    n_spots = stream_run(box, lights[0], compete, stream, n_s, results, spots)
    if n_spots:
        stream_spots(box, lights, stream, spots, n_spots, results)
    before = np.empty(n_s + LANES + 1, np.int64)
    stream_pack(stream, results, n_s, (o_p, o_j), base, before)
    for r in range(r0, r1):
        o = rows[r]
        a = before[starts[r - r0]]
        o_seg[o, 0] = base + a
        o_seg[o, 1] = before[starts[r - r0 + 1]] - a
    return before[n_s]


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _vector_rows(params, box, lights):
    """Whether simd.candidate_run takes these pairs: the contribution model and whole
    8-word rows of records and lights, which it reads."""
    return (int(params[0]) == MODEL_CONTRIBUTION and box.shape[1] == 8
            and lights[0].shape[1] == 8 and lights[1].shape[1] == 8)


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _record_pairs(o, recs, lights, compete, cands, dir_rows, o_p, o_j, m, params, vector):
    """The pairs of record o of recs = (boxes, integer view) with the candidate light rows
    c_j[a:b] (cands = (c_j, a, b)) and the directional ``dir_rows``, appended from m to
    (o_p, o_j); returns the new end. ``vector``: the records and light rows are 8-word
    float64 rows under the contribution model, which simd.candidate_run takes eight
    candidates at a time. candidate_pairs keeps its own copy of these lines: calling this
    from its parallel loop, a full (100k, 10k) frame's candidates' pass took ~1.3 ms more
    (paired, twice), though not on captured inputs."""
    box, bits = recs
    hot, lf = lights
    c_j, a, b = cands
    ob = np.int64(bits[o, 6]) & SHOWN
    # An object out of view (no SHOWN bit in its record) keeps its list but pairs with none.
    if ob == 0:
        b = a
    if vector and b > a:
        # Float64 records: eight candidates a step in vector code (-1: float32).
        end = candidate_run(box, o, hot, lf, compete, c_j, a, b, o_p, o_j, m)
        if end >= 0:
            a = b
            m = end
    m = scalar_candidates(box, ob, o, lights, compete, c_j, a, b, (o_p, o_j), m, params)
    for d in range(dir_rows.shape[0]):
        j = dir_rows[d]
        if ob & np.int64(hot[j, 4]) != 0:
            o_p[m] = hot[j, 6] + hot[j, 7]
            o_j[m] = j
            m += 1
    return m


@nb.njit(cache=True, nogil=True, error_model="numpy")
def direct_pairs(rows, recs, lights, compete, point_rows, dir_rows, params, n):
    """The pairs of a few objects that came into view, each tested against every competing
    light (candidate_pairs' rule with every point and spot light ``point_rows`` a
    candidate): one object a step on the calling thread, no grid. An incremental frame with
    a camera move brings a handful of objects into view; a grid of them walked by every
    light took ~1.1 ms at (100k, 10k) for one object (the grid's O(N) pass over the rows,
    10k lights' cell ranges and runs). rows = object rows ascending, recs = their records
    in that order; lights, compete, params as candidate_pairs. Returns (start [n + 1],
    (P, light row)): object rows[r]'s pairs at start[rows[r]]..start[rows[r] + 1], the
    only entries of start written."""
    vector = _vector_rows(params, recs[0], lights)
    room = rows.shape[0] * (point_rows.shape[0] + dir_rows.shape[0])
    o_p = np.empty(room)
    o_j = np.empty(room, np.int32)
    start = np.empty(n + 1, np.int64)
    m = 0
    for r in range(rows.shape[0]):
        start[rows[r]] = m
        m = _record_pairs(r, recs, lights, compete, (point_rows, 0, point_rows.shape[0]),
                          dir_rows, o_p, o_j, m, params, vector)
        start[rows[r] + 1] = m
    return start, (o_p[:m], o_j[:m])


@nb.njit(cache=True, nogil=True, error_model="numpy")
def light_grid(hot, rows):
    """The spheres of the point and spot light ``rows`` of light_hot sorted into a grid of
    cubic cells: (g_f [6] (origin, 1/edge per axis as grid_shape), dims [3], cell_start
    [C + 1], the light rows of each cell int32, the rows over LIGHT_GRID_BIG cells int32,
    which every object tests). The edge is twice the median radius (of at most 1024 of
    them, evenly spaced), so a light spans ~2 cells an axis, made larger until there are
    at most LIGHT_GRID_CELLS cells per light. A sphere's cell range is widened as
    _axis_cells widens it, so rounding never drops a light the exact test keeps.

    At (100k, 10k) the grid takes ~0.9 ms to make (31 x 5 x 31 cells of 35 m, ~19 lights
    a cell) and grid_pairs ~0.4 ms for 981 moved objects; with an edge of 1.5, 1 and 0.5
    median radii 0.34, 2.4 and 8.1 ms (the city's larger objects then span many cells),
    with 3 radii 0.52 ms (measured on captured inputs, 2 threads)."""
    n = rows.shape[0]
    g_f = np.zeros(6)
    dims = np.ones(3, np.int64)
    if n == 0:
        return g_f, dims, np.zeros(2, np.int64), np.zeros(0, np.int32), np.zeros(0, np.int32)
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
    return g_f, dims, count, cell_rows, big


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
    record that took each light row), written from m into ``out``; returns the new end."""
    g_f, dims, cell_start, cell_rows, big = lgrid
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
    g_f, dims, cell_start, _, big = lgrid
    x0, y0, z0, x1, y1, z1 = _box_cells(box, r, g_f, dims)
    m = big.shape[0]
    for x in range(x0, x1 + 1):
        for y in range(y0, y1 + 1):
            base = (x * dims[1] + y) * dims[2]
            m += cell_start[base + z1 + 1] - cell_start[base + z0]
    return m


@nb.njit(cache=True, nogil=True, parallel=PRANGE_ONLY, error_model="numpy")
def grid_pairs(rows, recs, lights, compete, lgrid, dir_rows, params, n):
    """direct_pairs with each object's candidates from a grid of the point and spot lights
    (light_grid): the lights of the cells its box overlaps, and the big ones. The same
    pairs, in another order within an object. The candidates are listed in parallel over
    blocks of FRESH_CHUNK objects, each into a room sized from the cells' starts
    (_grid_bound), tested by candidate_pairs (its stream: a moved object has ~40
    candidates here, and one object at a time took ~330 ns an object at (100k, 10k) with
    10% of the objects moving), and the pairs packed in object order."""
    n_l = lights[0].shape[0]
    f = rows.shape[0]
    n_chunks = (f + FRESH_CHUNK - 1) // FRESH_CHUNK
    c_seg = np.zeros((f, 2), np.int64)
    box = recs[0]
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
    o_p = np.empty(room)
    o_j = np.empty(room, np.int32)
    candidate_pairs(np.arange(f), (c_seg, c_j), recs, lights, compete, dir_rows, params,
                    (seg, o_p, o_j), 0)
    start = np.empty(n + 1, np.int64)
    m = 0
    for r in range(f):
        start[rows[r]] = m
        for t in range(seg[r, 0], seg[r, 0] + seg[r, 1]):
            o_p[m] = o_p[t]
            o_j[m] = o_j[t]
            m += 1
        start[rows[r] + 1] = m
    return start, (o_p[:m], o_j[:m])


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def scalar_candidates(box, ob, o, lights, compete, c_j, a, b, out, m, params):
    """candidate_pairs' rule, one candidate at a time: of object row o (record o of box,
    mask bits ob) and the candidate light rows c_j[a:b], the pairs of lights that compete with
    a mask bit of the object's, in range, then _pair_p (cone, P of the model), appended
    from m to out = (P, light row); returns the new end. simd.candidate_run does the same
    eight at a time (tests/test_simd.py holds one against the other)."""
    hot, lf = lights
    o_p, o_j = out
    model = int(params[0])
    for t in range(a, b):
        j = np.int64(c_j[t])
        if not compete[j] or ob & np.int64(hot[j, 4]) == 0:
            continue
        d2 = box_d2(box, o, hot[j, 0], hot[j, 1], hot[j, 2])
        if d2 <= hot[j, 3] * hot[j, 3]:
            typ = (np.int64(hot[j, 5]) >> 3) & 3
            hit, p = _pair_p(hot, lf, j, typ, o, d2, box, model, params[1], params[2])
            if hit:
                o_p[m] = p
                o_j[m] = j
                m += 1
    return m


@nb.njit(cache=True, nogil=True, error_model="numpy")
def widen_walkers(hot, walk, positions, wide, widen):
    """The rows of the lights that walk for the candidate lists (``walk`` True per light
    row), int32 ascending, with their rows of ``wide`` written from light_hot's: the radius
    widened by skin, the mask ``every`` (every mask bit: float(SHOWN), or -1.0 to meet the
    hidden masks of the objects out of view too), the point type (whatever the light's
    type: the lists hold the range test only), and the centre ahead along the light's last
    step by lead x skin x its radius (positions = (world positions now, last frame's); a
    light that did not move keeps its centre). widen = (scheduler.SKIN, scheduler.LEAD,
    every). One loop over the lights, where numpy took a dozen calls of ~1-3 us each on
    the walkers' rows.
    """
    skin, lead, every = widen
    now, last = positions
    n = 0
    for j in range(walk.shape[0]):
        n += walk[j]
    sel = np.empty(n, np.int32)
    k = 0
    for j in range(walk.shape[0]):
        if not walk[j]:
            continue
        sel[k] = j
        k += 1
        for c in range(8):
            wide[j, c] = hot[j, c]
        wide[j, 3] = hot[j, 3] * (1.0 + skin)
        wide[j, 4] = every
        wide[j, 5] = j * 32.0
        dx = now[j, 0] - last[j, 0]
        dy = now[j, 1] - last[j, 1]
        dz = now[j, 2] - last[j, 2]
        length = math.sqrt(dx * dx + dy * dy + dz * dz)
        if length > 0.0:
            ahead = lead * skin * hot[j, 3] / length
            wide[j, 0] = hot[j, 0] + ahead * dx
            wide[j, 1] = hot[j, 1] + ahead * dy
            wide[j, 2] = hot[j, 2] + ahead * dz
    return sel


# left_spheres loops on the calling thread below this many lights: ~2 ns a light, so
# below a few thousand waking the second thread costs what it would save (1k: 2.6 us on
# one thread, 2.8 on two).
SERIAL_SPHERES = 4096


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _left_sphere(hot, anchor, j):
    """left_spheres' test of light row j."""
    dx = hot[j, 0] - anchor[j, 0]
    dy = hot[j, 1] - anchor[j, 1]
    dz = hot[j, 2] - anchor[j, 2]
    reach = anchor[j, 3]
    room = 1e-9 * reach + 1e-12 * (abs(anchor[j, 0]) + abs(anchor[j, 1]) + abs(anchor[j, 2]))
    return not (reach > 0 and math.sqrt(dx * dx + dy * dy + dz * dz) + hot[j, 3] + room
                <= reach)


@nb.njit(cache=True, nogil=True, parallel=PRANGE_ONLY, error_model="numpy")
def left_spheres(hot, anchor, own):
    """Per light row: an ``own`` light whose sphere no longer lies inside the one its
    candidate lists were found with (anchor [L, 4]: centre and widened radius, 0 for none),
    i.e. |p - anchor| + r > reach, with room for rounding (while it stays inside, every
    object it reaches is within reach of the anchor). One loop, not numpy on the [L, 8]
    records' strided columns: 0.02 against ~0.55 ms at 10k lights; parallel from
    SERIAL_SPHERES lights (10k: 20 -> 11 us)."""
    out = np.zeros(hot.shape[0], np.bool_)
    if hot.shape[0] < SERIAL_SPHERES:
        for j in range(hot.shape[0]):
            if own[j]:
                out[j] = _left_sphere(hot, anchor, j)
    else:
        for j in nb.prange(hot.shape[0]):
            if own[j]:
                out[j] = _left_sphere(hot, anchor, j)
    return out


@nb.njit(cache=True, nogil=True, parallel=PRANGE_ONLY, error_model="numpy")
def spread_lists(start, light_j, lists):
    """Candidate lists grouped by object (object o's at start[o]..start[o+1]-1 of
    ``light_j``) copied into rooms with space to grow (len + 2 + len // 2 each), so that
    ``edit_candidates`` changes them in place and they stay in row order. lists = (seg
    [N, 2] (start, length), cap [N] (room), light row int32 [C], fill [GROUP_PARTS, 2]):
    cand must hold the rooms' total (``list_room``); the rest is spare room, shared out
    to the GROUP_PARTS row ranges of edit_candidates: fill[q] = (where part q's next moved
    list goes, the end of its share)."""
    seg, cap, cand, fill = lists
    n = seg.shape[0]
    at = 0
    for o in range(n):
        m = start[o + 1] - start[o]
        seg[o, 0] = at
        seg[o, 1] = m
        cap[o] = _room_for(m)
        at += cap[o]
    spare = (cand.shape[0] - at) // GROUP_PARTS
    for q in range(GROUP_PARTS):
        fill[q, 0] = at + q * spare
        fill[q, 1] = at + (q + 1) * spare
    for ch in nb.prange((n + OBJECT_CHUNK - 1) // OBJECT_CHUNK):
        for o in range(ch * OBJECT_CHUNK, min(n, (ch + 1) * OBJECT_CHUNK)):
            for t in range(seg[o, 1]):
                cand[seg[o, 0] + t] = light_j[start[o] + t]


@nb.njit(cache=True, nogil=True, parallel=PRANGE_ONLY, error_model="numpy")
def compact_light_lists(by_light, spare):
    """The lists by light row packed into a new array with ``spare`` free records after
    them (the segments light_lists left behind are garbage); returns (seg, object rows,
    records used). The lists, appended frame after frame, lie scattered over the old
    array: copied one light a time in parallel, each a slice (one element at a time on
    one thread, ~2.5 ms at (100k, 10k) once every ~40-80 frames; bench/RESULTS.md)."""
    l_seg, l_obj = by_light
    new_seg = np.empty_like(l_seg)
    at = 0
    for j in range(l_seg.shape[0]):
        new_seg[j, 0] = at
        new_seg[j, 1] = l_seg[j, 1]
        at += l_seg[j, 1]
    new_obj = np.empty(at + spare, np.int32)
    for j in nb.prange(l_seg.shape[0]):
        a, m, b = l_seg[j, 0], l_seg[j, 1], new_seg[j, 0]
        new_obj[b:b + m] = l_obj[a:a + m]
    return new_seg, new_obj, at


@nb.njit(cache=True, nogil=True, error_model="numpy")
def list_room(start):
    """The total room spread_lists gives lists grouped at ``start``."""
    at = 0
    for o in range(start.shape[0] - 1):
        at += _room_for(start[o + 1] - start[o])
    return at


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _room_for(m):
    """The room of a candidate list of m lights: space for half as many again, and two."""
    return m + 2 + m // 2


@nb.njit(cache=True, nogil=True, error_model="numpy")
def list_objects(by_light, lights, mark):
    """Marks (True in ``mark``) the objects in the candidate lists of the light rows
    ``lights`` (by_light = (seg [L, 2], object rows), as light_lists keeps them).

    Each light's seg row and the start of its list are misses (lights at random, lists
    scattered over the heap): both are prefetched LIST_AHEAD lights ahead, the seg row
    twice as far so that its list's start can be read. One thread: two would write the
    same lines of ``mark``."""
    l_seg, l_obj = by_light
    n = lights.shape[0]
    for t in range(n):
        if t + 2 * LIST_AHEAD < n:
            prefetch_row(l_seg, lights[t + 2 * LIST_AHEAD])
        if t + LIST_AHEAD < n:
            prefetch_row(l_obj, l_seg[lights[t + LIST_AHEAD], 0])
        j = lights[t]
        for i in range(l_seg[j, 0], l_seg[j, 0] + l_seg[j, 1]):
            mark[l_obj[i]] = True


@nb.njit(cache=True, nogil=True, error_model="numpy")
def reached_rows(reach, visible, more):
    """The rows of the objects an incremental frame reaches through the candidate lists
    (``reach``, list_objects' marks) that are in view, whose pairs it makes again, and the
    rows it runs the object pass on: those, and the rows ``more`` marks (fading ones).
    Both ascending, int64, in one pass without branches: with ~45% of the rows reached
    (lights10 at (100k, 10k)), np.flatnonzero of a mask mispredicts on nearly every other
    row, and the two took ~0.23 ms of the frame (line profile)."""
    n = reach.shape[0]
    rows = np.empty(n, np.int64)
    run = np.empty(n, np.int64)
    a = 0
    b = 0
    for o in range(n):
        hit = reach[o] & visible[o]
        rows[a] = o
        a += hit
        run[b] = o
        b += hit | more[o]
    return rows[:a], run[:b]


@nb.njit(cache=True, nogil=True, error_model="numpy")
def light_lists(walked, by_light, used):
    """Each walked light's objects (walked = light_pass's rows, offsets, count, object
    rows) appended to the lists by light row (by_light = (seg [L, 2], object rows [H]))
    from record ``used``; returns the records used after them, or -1 when they do not
    fit (nothing is written then)."""
    rows, offsets, count, pair_obj = walked
    l_seg, l_obj = by_light
    total = 0
    for t in range(rows.shape[0]):
        total += count[t]
    if used + total > l_obj.shape[0]:
        return -1
    for t in range(rows.shape[0]):
        j = rows[t]
        l_seg[j, 0] = used
        l_seg[j, 1] = count[t]
        for e in range(offsets[t], offsets[t] + count[t]):
            l_obj[used] = pair_obj[e]
            used += 1
    return used


@nb.njit(cache=True, nogil=True, parallel=PRANGE_ONLY, error_model="numpy")
def edit_candidates(walked, lists, by_light):
    """The object lists of the walked lights made again in place: each walked light is
    dropped from the lists of the objects it had (``by_light``, before ``light_lists``
    records its new ones) and has no longer, and added to those it has now and had not.
    A light that moved a little keeps most of its objects, so only the difference touches
    the object lists: its new objects are stamped with its place in the walk, then its
    old ones found by their stamp. The objects are split into GROUP_PARTS row ranges,
    each edited by one thread in the walk's light order (so each list sees the same edits
    in the same order whatever the threads), with its own stamps; a list that outgrows
    its room moves to its part's spare space with twice the room. lists as spread_lists
    made them. Returns False when a part's spare space ran out (the caller makes every
    list again: they are half edited)."""
    rows, offsets, count, pair_obj = walked
    seg, cap, cand, fill = lists
    l_seg, l_obj = by_light
    n = seg.shape[0]
    ok = np.ones(GROUP_PARTS, np.bool_)
    for q in nb.prange(GROUP_PARTS):
        lo = n * q // GROUP_PARTS
        hi = n * (q + 1) // GROUP_PARTS
        # stamp[o - lo]: 2t + 1 when object o is in walked light t's new list, 2t + 2 once
        # it was found in its old one too (kept as it is).
        stamp = np.zeros(hi - lo, np.int32)
        for t in range(rows.shape[0]):
            j = rows[t]
            new = 2 * t + 1
            for e in range(offsets[t], offsets[t] + count[t]):
                o = pair_obj[e]
                if lo <= o < hi:
                    stamp[o - lo] = new
            for e in range(l_seg[j, 0], l_seg[j, 0] + l_seg[j, 1]):
                o = l_obj[e]
                if o < lo or o >= hi:
                    continue
                if stamp[o - lo] == new:
                    stamp[o - lo] = new + 1
                    continue
                a = seg[o, 0]
                m = seg[o, 1]
                for i in range(a, a + m):
                    if cand[i] == j:
                        cand[i] = cand[a + m - 1]
                        seg[o, 1] = m - 1
                        break
            for e in range(offsets[t], offsets[t] + count[t]):
                o = pair_obj[e]
                if o < lo or o >= hi or stamp[o - lo] != new or not ok[q]:
                    continue
                m = seg[o, 1]
                if m == cap[o]:
                    room = 2 * m + 2
                    if fill[q, 0] + room > fill[q, 1]:
                        ok[q] = False
                        continue
                    for i in range(m):
                        cand[fill[q, 0] + i] = cand[seg[o, 0] + i]
                    seg[o, 0] = fill[q, 0]
                    cap[o] = room
                    fill[q, 0] += room
                cand[seg[o, 0] + m] = j
                seg[o, 1] = m + 1
    return ok.all()


def live_ids(ids: np.ndarray, live: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """object_pass's live_id: per light row its id (int32) where ``live``, else -2 (not
    -1, the id of an empty slot). One table, so the object pass reads one entry a pair
    where it read the id and the live flag: held_row gathers eight lanes of it, and the
    gather of the flags was ~5% of the pass (bench/RESULTS.md)."""
    if out is None or out.shape != ids.shape:
        out = np.empty(ids.shape, np.int32)
    np.copyto(out, ids)
    out[~live] = -2
    return out


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _match_old_slot(p, j, lid, sf, si):
    """Records this frame's P and row for the object's old slot of light lid, if any.
    Compares only inside the loop (it vectorises); the one store happens after it."""
    slot = -1
    for m in range(sf.shape[1]):
        slot = m if si[I_OLD_ID, m] == lid else slot
    if slot >= 0:
        sf[F_OLD_P, slot] = p
        si[I_OLD_ROW, slot] = j


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _select(p, j, lid, sf, si, nbest, h, h_abs):
    """Offers light row j (id lid) with priority p to the object's top K (select.py):
    hysteresis key, insert, and this frame's P / row for the object's old slot of that
    light. Returns nbest."""
    _match_old_slot(p, j, lid, sf, si)
    return topk_insert(sf, si, nbest, hysteresis_key(p, lid, si, h, h_abs), lid, p, j)


@nb.njit(cache=True, nogil=True, parallel=PRANGE_ONLY, error_model="numpy")
def object_pass(run, objs, lists, live_id, state, out, params, shadow, k_static):
    """For the object rows ``run`` (ascending, parallel in chunks): top-K with hysteresis,
    fade, outputs; rows not in ``run`` are left as they are (an incremental frame has
    copied them from the last frame).

    objs = (visible, reset): reset marks objects that start with their selected lights on
    (step 3 of Fade); lists = (seg [N, 2] (start, length) of each object's pairs in the
    heap, heap = (P float64 [H], light row int32 [H])): the pair cache; live_id = per light
    row its id if it is live (visible, and not removed by unshadowed = "skip"), else -2
    (``live_ids``; pairs of other lights are kept in the cache but do not compete); state =
    (slot ids, slot weights f64, slot states, selected ids), each [N, K]: the ids and states
    are last frame's light_ids and fade_state outputs, the weights and selection are updated
    in place; out = (light_ids, light_index, priority f32, fade_weight f32, fade_state,
    count, candidates, slot_shadow int8, fading bool [N]: a slot is fading in or out);
    params = (h, h_abs, dt/fade_in, dt/fade_out, fade_in, fade_out); shadow = (shadow map
    index per light row or -1, max_shadowed_per_object); k_static = a tuple of K zeros if K
    is in STATIC_K, else ().

    Most objects of a scene in motion are steady: last frame's slots are all on and hold
    exactly this frame's selection, so only P changes. They skip the fade machine (its
    result is fade.held_slots: last frame's order, sorted again by this frame's P) and
    read only last frame's ids and states. With K = 8 those still in last frame's order
    (83% of a full (100k, 10k) frame's rows), and those whose slots only fade in, go
    through simd.held_row, one vector store an output row; the rest run the code below.
    """
    visible, reset = objs
    seg, (heap_p, heap_j) = lists
    s_id, s_w, s_st, s_sel = state
    o_ids, o_index, o_prio, o_w, o_st, o_count, o_cand, o_shadow, o_fading = out
    shadow_of_row, max_shadowed = shadow
    any_shadow = max_shadowed > 0 and shadow_of_row.max() >= 0 if shadow_of_row.size else False
    h = params[0]
    h_abs = params[1]
    inc = params[2]
    dec = params[3]
    fade_in = params[4]
    fade_out = params[5]
    n_run = run.shape[0]
    # A common K is a compile-time constant, the length of a tuple (its type holds it):
    # every per-slot loop then has a known trip count, which LLVM unrolls and vectorises
    # whole (-0.4 ms of ~6.7 at (100k, 10k), bench/RESULTS.md). Each such K costs a
    # compilation of this kernel (~13 s, then cached), so only STATIC_K are; any other K
    # is read from the arrays. (numba.literally would re-type every call: ~1.5 s each.)
    k = len(k_static) if len(k_static) else s_id.shape[1]
    n_chunks = (n_run + OBJECT_CHUNK - 1) // OBJECT_CHUNK
    held_rules = (shadow_of_row, np.int64(max_shadowed) if any_shadow else np.int64(0), h,
                  h_abs, inc, fade_in)
    for ch in nb.prange(n_chunks):
        sf = np.empty((F_ROWS, k))
        si = np.empty((I_ROWS, k), np.int64)
        for r in range(ch * OBJECT_CHUNK, min(n_run, (ch + 1) * OBJECT_CHUNK)):
            o = run[r]
            if k == LANES and visible[o] and not reset[o] and 0 < seg[o, 1] <= 2 * LANES:
                # The common case in vector code: slots held in last frame's order.
                cand = held_row(o, seg[o, 0], seg[o, 1], (heap_p, heap_j), (live_id,), state,
                                out, held_rules)
                if cand >= 0:
                    o_count[o] = min(cand, k)
                    o_cand[o] = cand
                    continue
            cnt = 0
            nbest = 0
            cand = 0
            if visible[o]:
                a = seg[o, 0]
                b = a + seg[o, 1]
                n_old = 0
                all_on = True
                for m in range(k):
                    lid = s_id[o, m]
                    si[I_OLD_ID, m] = lid
                    si[I_OLD_ROW, m] = -1
                    n_old += lid >= 0
                    all_on &= (lid < 0) | (s_st[o, m] == ON)
                # One pass counts the competing lights and keeps them while they fit in K,
                # the common case: then every one is selected, no keys, no ranking.
                for t in range(a, b):
                    j = np.int64(heap_j[t])
                    lid = np.int64(live_id[j])
                    if lid >= 0:
                        if cand < k:
                            p = heap_p[t]
                            _match_old_slot(p, j, lid, sf, si)
                            sf[F_P, cand] = p
                            si[I_ID, cand] = lid
                            si[I_ROW, cand] = j
                        cand += 1
                if cand <= k:
                    nbest = cand
                else:
                    # (The first K old-slot matches are made again, to the same values.)
                    for m in range(k):
                        si[I_PREV_SEL, m] = s_sel[o, m]
                    for t in range(a, b):
                        j = np.int64(heap_j[t])
                        lid = np.int64(live_id[j])
                        if lid >= 0:
                            nbest = _select(heap_p[t], j, lid, sf, si, nbest, h, h_abs)
                held = False
                if not reset[o] and all_on and n_old == nbest:
                    # Held when every old slot holds a selected light (filled slots come
                    # first; ids are unique, so counting them is a set comparison).
                    matched = 0
                    for m in range(n_old):
                        hit = False
                        for t in range(nbest):
                            hit |= si[I_ID, t] == si[I_OLD_ID, m]
                        matched += hit
                    held = matched == nbest
                if reset[o]:
                    steady_slots(sf, si, nbest)
                    cnt = nbest
                elif held:
                    held_slots(sf, si, nbest)
                    cnt = nbest
                else:
                    for m in range(k):
                        sf[F_OLD_W, m] = s_w[o, m]
                        si[I_OLD_ST, m] = s_st[o, m]
                    cnt = fade_object(sf, si, nbest, False, inc, dec, fade_in, fade_out)
            fading = False
            for m in range(k):
                if m < cnt:
                    st = si[I_NEW_ST, m]
                    fading |= st != ON
                    s_w[o, m] = sf[F_NEW_W, m]
                    o_ids[o, m] = si[I_NEW_ID, m]
                    o_index[o, m] = si[I_NEW_ROW, m]
                    o_prio[o, m] = np.float32(sf[F_NEW_P, m])
                    o_w[o, m] = np.float32(sf[F_NEW_W, m])
                    o_st[o, m] = st
                else:
                    s_w[o, m] = 0.0
                    o_ids[o, m] = -1
                    o_index[o, m] = -1
                    o_prio[o, m] = 0.0
                    o_w[o, m] = 0.0
                    o_st[o, m] = 0
                o_shadow[o, m] = -1
                s_sel[o, m] = si[I_ID, m] if m < nbest else -1
            o_count[o] = cnt
            o_cand[o] = cand
            o_fading[o] = fading
            if any_shadow and cnt:
                pick_slot_shadows(sf, si, cnt, shadow_of_row, max_shadowed, o_shadow, o)


# --------------------------------------------------------------------------- pair cache
#
# The pairs of a frame are kept for the next one (DESIGN section 6): per object row a
# segment (start, length) of a heap of (P, light row) pairs, kept as two arrays (P float64,
# light row int32) so a scan of the light rows reads a quarter of it. An incremental frame
# rewrites only the segments of objects whose pairs changed, appending them to the heap;
# the segments it no longer points to are garbage until the heap is compacted.


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _scan_object(o, seg, heap_j, light_flag, drop):
    """(the OR of light_flag over object o's cached pairs, how many have no ``drop`` bit).

    Objects hold a few pairs each (4.4 on average in the city, 0 to 16), so a loop over
    each list's length mispredicts its exit about once an object. The first SCAN_LANES
    pairs are read in a loop of fixed length instead, the lanes past the end reading the
    last pair again and counting nothing: on a lights10 frame's captured inputs at (100k,
    10k), 1.03 -> 0.81 ms (4 lanes 0.93, 12 lanes 1.08)."""
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
    over the rewritten lists cost 0.34 of replace_lists' 0.82 ms at 100k objects)."""
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
    flagged lights reach): the flags' OR is 0 and ``kept`` undefined at every other row."""
    n = seg.shape[0]
    out = np.zeros(n, np.uint8)
    kept = np.empty(n, np.int64)
    for r in range(rows.shape[0]):
        o = rows[r]
        out[o], kept[o] = _scan_object(o, seg, heap_j, light_flag, drop)
    return out, kept


@nb.njit(cache=True, nogil=True, parallel=PRANGE_ONLY, error_model="numpy")
def compact_heap(seg, heap, out):
    """The live segments of the heap (P, light row) packed from the start of ``out`` (P,
    light row), another heap with room for them (the records after them are free); returns
    (new seg, out, records used). Segment order is row order."""
    n = seg.shape[0]
    start = np.zeros(n + 1, np.int64)
    for o in range(n):
        start[o + 1] = start[o] + seg[o, 1]
    used = start[n]
    heap_p, heap_j = heap
    new_p, new_j = out
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
def replace_lists(rows, mode, cache, walked, kept, fresh, used):
    """New pair lists of the object ``rows`` (ascending), appended to the heap from record
    ``used`` (the caller made room). mode per row: 0 empty (the object left the view), 1
    only its ``fresh`` pairs (its lists were rebuilt against every light: it moved or came
    into view), 2 its cached pairs of lights not flagged in ``walked`` (kept[o] of them,
    from ``scan_pairs``; all of them if kept is empty) followed by its fresh pairs (lights
    that changed were walked again). cache = (seg, (P, light row)), updated in place;
    fresh = (start [N+1], (P, light row)) grouped by object row."""
    seg, (heap_p, heap_j) = cache
    f_start, (f_p, f_j) = fresh
    at = np.empty(rows.shape[0] + 1, np.int64)
    at[0] = used
    for r in range(rows.shape[0]):
        o = rows[r]
        size = 0
        if mode[r] == 2:
            size = kept[o] if kept.size else seg[o, 1]
        if mode[r] != 0:
            size += f_start[o + 1] - f_start[o]
        at[r + 1] = at[r] + size
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
    return at[rows.shape[0]]
