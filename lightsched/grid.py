"""The grid of objects (DESIGN section 6: a grid instead of brute force once there are
enough pairs): cells, the objects sorted by the cell of their centre, and their records.

``visible_order`` + ``visible_objects``: the objects of the grid (the visible ones, or
every object with the invisible ones' masks hidden, ``simd.SHOWN``) sorted by the grid cell
of their centre (a counting sort), one record each (lo, hi, mask, e2: 64 bytes in float64,
32 in the "fast" precision's float32 relative to the first camera); objects larger than a
cell go past the last cell, to a short list every light tests. ``move_records`` rewrites the
records of objects that moved a little in place. ``light_order`` sorts lights by the cell
of their position so that neighbouring lights walk the same objects while they are cached.
The walks themselves are in walk.py.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, NamedTuple

import numba as nb
import numpy as np

from .buffers import Buffers
from .jit import GROUP_PARTS, OBJECT_CHUNK, PRANGE_ONLY
from .tuning import Tuning

if TYPE_CHECKING:
    from .plan import FramePlan
    from .priority import Packed
    from .scene import ObjectStore
    from .scheduler import FrameState
    from .visibility import Visibility

MAX_CELLS = 1 << 21          # bounds grid memory whatever the scene's extent


RUN_SPLIT = 4                # grid cells are this much finer along z (the run axis)


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
    "fast" precision (origin the first camera), x itself in exact precision (origin 0).
    x, origin: float64; single: bool, "fast" precision. DESIGN section 4 ("fast":
    float32, relative to the first camera)."""
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
    but speed. hot: light_hot [L, 8] float64; rows: int32 light rows; g_f float64 [6],
    dims int64 [3]: the grid's (GridIndex.frame, dims). DESIGN section 6 (the grid);
    section 5 (results do not depend on input order)."""
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
    """Per grid position v (parallel), written into recs (Records: their box and bits):
    (lo - origin, hi - origin, mask (as bits), e2 = |hi - lo|^2) of object row
    vis_rows[v], one cache line per object for the tests (float64, origin 0: exact
    precision; float32 relative to the first camera: "fast", half a line). Returns the
    largest half-extent per axis of the objects at positions below n_small (those in
    cells), which widens every light's cell range. Positions are written in order and rows
    read where they are: measured ~35% faster than the other way round at 100k objects.
    Per-chunk maxima keep the reduction parallel. lo, hi: float64 [N, 3] bounds; omask:
    [N] mask words (the objects' masks, or shown_mask's); vis_rows: int64 [V], the object
    row of each position; n_small: int; origin: float64 [3]. DESIGN section 2, "Affects"
    (the box, mask and e2 the tests read); section 6 (the grid)."""
    vis_box, vis_bits = recs.box, recs.bits
    nv = vis_rows.shape[0]
    n_chunks = (nv + OBJECT_CHUNK - 1) // OBJECT_CHUNK
    chunk_ext = np.zeros((n_chunks, 3))
    for ch in nb.prange(n_chunks):
        for v in range(ch * OBJECT_CHUNK, min(nv, (ch + 1) * OBJECT_CHUNK)):
            o = vis_rows[v]
            write_record(lo, hi, o, omask[o], vis_box, vis_bits, v, origin)
            if v < n_small:
                for a in range(3):
                    # From the record as stored (float32 in "fast" precision), as the walk
                    # sees it.
                    half = (np.float64(vis_box[v, 3 + a]) - np.float64(vis_box[v, a])) / 2
                    chunk_ext[ch, a] = max(chunk_ext[ch, a], half)
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
    g_f, dims, cell_start, ext = grid.frame, grid.dims, grid.cell_start, grid.ext
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
    object moving a little each frame keeps its record for many frames: a record
    rewritten costs a few cache misses, the grid made again a pass over every object.
    grid: GridIndex; recs: its Records; frame = (origin, single) as record_coord. lo, hi:
    float64 [N, 3] bounds; rows: int64 object rows; pos_of: int64 [N], each row's grid
    position (-1: none, which does not fit). DESIGN section 6 (only the objects that moved
    are recomputed)."""
    vis_box, vis_bits = recs.box, recs.bits
    origin = frame[0]
    n_small = grid.cell_start[grid.dims[0] * grid.dims[1] * grid.dims[2]]
    m = rows.shape[0]
    fits = np.empty(m, np.bool_)
    for r in nb.prange(m):
        v = pos_of[rows[r]]
        fits[r] = v >= n_small or (v >= 0 and _record_fits(rows[r], lo, hi, grid, v, frame))
    if not fits.all():
        return False
    for r in nb.prange(m):
        o = rows[r]
        write_record(lo, hi, o, shown_mask[r], vis_box, vis_bits, pos_of[o], origin)
    return True


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def write_record(lo, hi, o, word, vis_box, vis_bits, v, origin):
    """Record v (of Records' box and bits) = object row o of the bounds lo, hi [N, 3]:
    (lo - origin, hi - origin, the mask word ``word``, e2 = |hi - lo|^2), float64 or
    float32 as vis_box is ("fast": relative to the first camera). The one definition
    visible_objects, move_records and records_of write."""
    for a in range(3):
        vis_box[v, a] = lo[o, a] - origin[a]
        vis_box[v, 3 + a] = hi[o, a] - origin[a]
    ex = hi[o, 0] - lo[o, 0]
    ey = hi[o, 1] - lo[o, 1]
    ez = hi[o, 2] - lo[o, 2]
    vis_bits[v, 6] = word
    vis_box[v, 7] = ex * ex + ey * ey + ez * ez  # read back by float64 records only


@nb.njit(cache=True, nogil=True, error_model="numpy")
def _write_records(lo, hi, omask, recs, origin):
    """recs.box / bits row v = object row recs.rows[v] of the bounds lo, hi [N, 3] and masks
    omask [N] (write_record: the records DESIGN section 2's tests read), relative to
    ``origin`` [3]; recs: Records. On the calling thread: for a few objects, where waking
    a second one costs more than the work."""
    for v in range(recs.rows.shape[0]):
        o = recs.rows[v]
        write_record(lo, hi, o, omask[o], recs.box, recs.bits, v, origin)


def records_of(lo: np.ndarray, hi: np.ndarray, omask: np.ndarray, rows: np.ndarray,
               frame: tuple[np.ndarray, bool]) -> Records:
    """The records of object ``rows`` (int64) in the frame (origin, single) as a grid's
    (visible_objects), in the order given, outside any grid."""
    box = np.empty((rows.size, 8), np.float32 if frame[1] else np.float64)
    recs = Records(box, box.view(np.uint32 if frame[1] else np.uint64), rows)
    _write_records(lo, hi, omask, recs, frame[0])
    return recs


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _axis_cells(p, reach, origin, inv_h, dim):
    slack = reach * 1e-9 + abs(p) * 1e-15
    lo = p - reach - slack
    hi = p + reach + slack
    miss = hi < origin or lo > origin + dim / inv_h
    return _cell(lo, origin, inv_h, dim), _cell(hi, origin, inv_h, dim), miss


# Grid positions per group box of the sweep over a grid of every object (sweep_groups): a
# group is a run of neighbouring cells' objects, and a box round them that a volume's
# plane rejects rejects each of them.
SWEEP_GROUP = 64


class BoxSource(NamedTuple):
    """Where a sweep over a grid of every object reads its positions' world boxes
    (float64): position v's box is row rows[v] of lo and hi if by_row (the stores' boxes,
    under "fast" records), else row v (columns of the grid's float64 records, which hold
    the world boxes exactly, in grid order)."""

    lo: np.ndarray      # float64 [*, 3]
    hi: np.ndarray      # float64 [*, 3]
    rows: np.ndarray    # int64 [V]: each grid position's object row
    by_row: bool


class GroupBoxes(NamedTuple):
    """The groups of a grid of every object (Grid's pos_of and group_box): group g holds
    grid positions g*size..(g+1)*size-1."""

    pos_of: np.ndarray  # int64 [N]: each object row's grid position
    box: np.ndarray     # float64 [G, 6]: lo, hi round the boxes of the group's objects
    size: int           # positions per group (SWEEP_GROUP)


@nb.njit(cache=True, nogil=True, parallel=PRANGE_ONLY, error_model="numpy")
def group_boxes(at):
    """Per group of SWEEP_GROUP consecutive grid positions (parallel): the box round every
    box of the group, [G, 6] (min lo, max hi), from the boxes themselves (float64), so it
    holds each of them exactly. at: BoxSource. DESIGN section 2, "Casters" and
    "Visibility" (a box a plane rejects rejects each object in it); section 6 (kept with
    the grid)."""
    lo, hi, rows, by_row = at.lo, at.hi, at.rows, at.by_row
    n = rows.shape[0]
    n_g = (n + SWEEP_GROUP - 1) // SWEEP_GROUP
    out = np.empty((n_g, 6))
    for g in nb.prange(n_g):
        for a in range(3):
            out[g, a] = np.inf
            out[g, 3 + a] = -np.inf
        for v in range(g * SWEEP_GROUP, min(n, (g + 1) * SWEEP_GROUP)):
            p = rows[v] if by_row else v
            for a in range(3):
                if lo[p, a] < out[g, a]:
                    out[g, a] = lo[p, a]
                if hi[p, a] > out[g, 3 + a]:
                    out[g, 3 + a] = hi[p, a]
    return out


@nb.njit(cache=True, nogil=True, error_model="numpy")
def widen_group_boxes(boxes, lo, hi, rows, pos_of):
    """The group boxes of the objects ``rows``, which moved within a kept grid, widened
    to hold their new boxes too (the old ones stay inside: a group box only has to hold
    its objects, and it is made tight again with the grid). boxes: float64 [G, 6]
    (group_boxes), in place; lo, hi: float64 [N, 3] bounds; rows: int64 object rows;
    pos_of: int64 [N], each row's grid position. DESIGN section 6 (a kept grid's upkeep)."""
    for i in range(rows.shape[0]):
        o = rows[i]
        g = pos_of[o] // SWEEP_GROUP
        for a in range(3):
            if lo[o, a] < boxes[g, a]:
                boxes[g, a] = lo[o, a]
            if hi[o, a] > boxes[g, 3 + a]:
                boxes[g, 3 + a] = hi[o, a]


# --------------------------------------------------------------------------- the grid stage


class GridIndex(NamedTuple):
    """Where a grid's objects are (records_grid): the kernels' view of its cells."""

    frame: np.ndarray       # float64 [6]: the origin of cell (0, 0, 0) and 1/h per axis
    dims: np.ndarray        # int64 [3]: cells per axis (z RUN_SPLIT x finer)
    cell_start: np.ndarray  # int64 [cells + 1]: cell c's records are at [start[c], start[c+1])
    ext: np.ndarray         # float64 [3]: the largest half-extent of an object in a cell
    big_pos: np.ndarray     # int32: positions of the objects larger than a cell (past them)


class Records(NamedTuple):
    """A grid's object records in grid order (grid.visible_objects writes them)."""

    box: np.ndarray   # [V, 8] float64 (float32 in "fast"): lo [3], hi [3], mask, e2
    bits: np.ndarray  # the same memory as unsigned integers (the mask word, column 6)
    rows: np.ndarray  # int64 [V]: each position's object row


@dataclass
class Grid:
    """The grid of objects a frame walks: its ``index`` and ``records``. Either a grid of
    the visible objects (``shown`` None), or of every object (``shown`` the visibility its
    records hold: an invisible object's record has no SHOWN bit in its mask word, so it
    pairs with no light (shown_mask); ``pos_of`` each row's position, ``box`` every
    object's bounding box, which set the grid's extent). ``how``: how it was made, for the
    plan; ``kept``: it is last frame's."""

    index: GridIndex
    records: Records
    how: str
    shown: np.ndarray | None = None
    pos_of: np.ndarray | None = None
    box: np.ndarray | None = None
    # (competing lights, the bytes of their radii, how many compete) when the cell edge of
    # a grid of every object was last checked against the lights' (_every_grid).
    edge_of: tuple[np.ndarray, bytes, int] | None = None
    # A grid of every object: the boxes round each SWEEP_GROUP of its positions' objects
    # (grid.group_boxes), made at the first sweep of a directional light's casters and
    # kept with the grid, widened in place for the objects that move within it.
    group_box: np.ndarray | None = None
    kept: bool = False
    # This frame's entry of the plan for it (``how``, and whether it was kept).
    text: str = ""


def object_grid(plan: FramePlan, last: FrameState | None, objects: ObjectStore,
                vis: Visibility, packed: Packed, object_rows: np.ndarray | None, tuning: Tuning,
                buffers: Buffers) -> Grid:
    """The grid stage: of every object once at least tuning.every_object_share are
    visible, kept while the objects are (a camera move rewrites the masks of the objects
    that entered or left the view, a small move their records); else of the visible
    objects, kept while the visible set and its boxes are. A new one writes its records
    over the kept one's (nothing reads those once it is made). ``object_rows``: the rows
    of the objects that changed (changes.Changes.object_rows)."""
    n = len(objects)
    frame = (plan.origin, plan.fast)
    n_vis = int(np.count_nonzero(vis.objects))
    note = ""
    if n and n_vis >= tuning.every_object_share * n:
        grid = _every_grid(plan, last, objects, vis, packed, object_rows, tuning, buffers)
    elif plan.full and plan.visibility == "kept" and last.grid.shown is None:
        # The lights set the cell edge: the kept grid serves while it is the same.
        shape = grid_cells(n_vis, vis.box, packed, frame, tuning)
        old = last.grid
        if np.array_equal(shape[0], old.index.frame) and np.array_equal(shape[1],
                                                                        old.index.dims):
            grid = Grid(old.index, old.records, shape[2] or old.how, kept=True)
            note = " (kept: the objects and cameras did not change)"
        else:
            grid = _visible_grid(objects, vis, packed, frame, tuning, buffers, shape)
    elif plan.full or vis.fresh.size or vis.left.size or last.grid.shown is not None:
        grid = _visible_grid(objects, vis, packed, frame, tuning, buffers)
    else:
        grid = dataclasses.replace(last.grid, kept=True)
    grid.text = grid.how + note
    if not packed.compete.any() or not vis.objects.any():
        grid.text = "none: no competing light or no visible object"
    return grid


def _every_grid(plan: FramePlan, last: FrameState | None, objects: ObjectStore,
                vis: Visibility, packed: Packed, orows: np.ndarray | None, tuning: Tuning,
                buffers: Buffers) -> Grid:
    """The grid of every object. Last frame's serves while the records' origin is the
    same, its cell edge is within tuning.cell_slack of the one the lights ask for, and
    every object that changed still lies where the grid's walks look for its record
    (move_records, which rewrites those records in place); then the records of the objects
    whose visibility changed get their mask word again (shown_mask)."""
    n = len(objects)
    frame = (plan.origin, plan.fast)
    kept = (last is not None and last.grid.shown is not None and orows is not None
            and plan.same_origin)
    moved = "the objects did not change"
    if kept and orows.size:
        g = last.grid
        kept = move_records(objects.bounds_min, objects.bounds_max, orows,
                            shown_mask(vis.objects[orows], objects.mask[orows], frame[1]),
                            g.index, g.records, g.pos_of, frame)
        if kept and g.group_box is not None:
            widen_group_boxes(g.group_box, objects.bounds_min, objects.bounds_max, orows,
                              g.pos_of)
        moved = f"{orows.size} changed objects' records rewritten in place"
    box = last.grid.box if kept else _every_box(objects)
    # The competing lights' radii set the cell edge: the same ones ask for the same grid.
    # Lights entering and leaving the view change a few of them every frame; the edge is
    # checked again once tuning.edge_drift of them changed since it last was, or any
    # radius did (radii are > 0, so bitwise equality of their bytes is equality). The edge
    # sets the cost of the walks, never their pairs.
    radii = packed.rows.hot[:, 3]
    compete = packed.compete
    edge_of = last.grid.edge_of if kept else None
    same_radii = (edge_of is not None and radii.tobytes() == edge_of[1]
                  and np.count_nonzero(compete != edge_of[0]) <= tuning.edge_drift * edge_of[2])
    shape = None
    if not same_radii:
        shape = grid_cells(n, box, packed, frame, tuning)
        edge_of = (compete.copy(), radii.tobytes(), int(np.count_nonzero(compete)))
    if kept and shape is not None:
        old = last.grid.index
        if (shape[2] is not None) != last.grid.how.startswith("brute"):
            kept = False
        elif shape[2] is not None:
            kept = np.array_equal(shape[0], old.frame) and np.array_equal(shape[1], old.dims)
        else:
            ratio = shape[0][3] / old.frame[3]  # kept edge over the edge asked for
            kept = 1 / tuning.cell_slack <= ratio <= tuning.cell_slack
        if not kept and orows.size:
            # The kept box missed the objects that moved.
            box = _every_box(objects)
            shape = grid_cells(n, box, packed, frame, tuning)
    if kept:
        g = last.grid
        rows = (np.zeros(0, np.int64) if vis.objects is g.shown
                else vis.flipped if g.shown is last.visibility.objects
                else np.flatnonzero(vis.objects != g.shown))
        if rows.size:
            g.records.bits[g.pos_of[rows], 6] = shown_mask(vis.objects[rows], objects.mask[rows],
                                                         frame[1])
        how = g.how.split(" (kept", 1)[0] + (
            f" (kept: {moved}; {rows.size} records' visibility updated)")
        return Grid(g.index, g.records, how, vis.objects, g.pos_of, box, edge_of, g.group_box,
                    kept=True)
    assert shape is not None
    g_f, dims, how = shape
    out = buffers.scratch("records", 8 * n, np.float32 if frame[1] else np.float64)
    index, recs, pos_of = records_grid(objects.bounds_min, objects.bounds_max,
                                       shown_mask(vis.objects, objects.mask, frame[1]),
                                       np.ones(n, np.bool_), (g_f, dims), frame, out)
    if how is None:
        how = grid_text("every object, the invisible ones masked out", index)
    return Grid(index, recs, how, vis.objects, pos_of, box, edge_of)


def _every_box(objects: ObjectStore) -> np.ndarray:
    """Every object's bounding box (lo, hi), axis by axis (numpy's min over axis 0 of an
    [N, 3] array is slower than three strided columns)."""
    return np.array([objects.bounds_min[:, a].min() for a in range(3)]
                    + [objects.bounds_max[:, a].max() for a in range(3)])


def _visible_grid(objects: ObjectStore, vis: Visibility, packed: Packed,
                  frame: tuple[np.ndarray, bool], tuning: Tuning, buffers: Buffers,
                  shape: tuple[np.ndarray, np.ndarray, str | None] | None = None) -> Grid:
    """The visible objects sorted into a grid of cells (grid_cells, unless the caller has
    the shape), with their records in the frame (origin, single) of the packed lights,
    written into the scratch buffer "records"."""
    n_sel = int(np.count_nonzero(vis.objects))
    g_f, dims, how = shape if shape is not None else grid_cells(
        n_sel, vis.box, packed, frame, tuning)
    out = buffers.scratch("records", 8 * n_sel, np.float32 if frame[1] else np.float64)
    index, recs, _ = records_grid(objects.bounds_min, objects.bounds_max, objects.mask,
                                  vis.objects, (g_f, dims), frame, out)
    if how is None:
        how = grid_text("visible objects", index)
    return Grid(index, recs, how)


def frame_box(box: np.ndarray, frame: tuple[np.ndarray, bool]) -> np.ndarray:
    """A world box (lo, hi) in the records' frame: relative to the origin, and in "fast"
    precision widened by float32's rounding so that it holds every rounded record."""
    origin, single = frame
    rel = box - np.concatenate([origin, origin])
    if single:
        pad = np.abs(rel) * 2.0**-22 + 1e-30
        rel = rel + np.concatenate([-pad[:3], pad[3:]])
    return rel


def grid_cells(n_sel: int, box: np.ndarray, packed: Packed, frame: tuple[np.ndarray, bool],
               tuning: Tuning) -> tuple[np.ndarray, np.ndarray, str | None]:
    """(g_f, dims, how or None) of the grid of n_sel objects in the world box ``box``: cells
    of edge tuning.cell_per_radius x the median radius of the competing point and spot
    lights, or a single cell when there are few enough pairs for brute force (its how)."""
    compete = packed.compete
    point_rows = np.flatnonzero(compete & ~packed.is_dir)
    box = np.zeros(6) if n_sel == 0 else frame_box(box, frame)
    if point_rows.size * n_sel <= tuning.brute_force_pairs:
        # One cell holding every selected object: each light tests them all.
        g_f, dims = grid_shape(box[:3], box[3:], 2.0 * max(float(np.max(box[3:] - box[:3])), 1.0))
        return g_f, dims, f"brute force ({np.count_nonzero(compete)} lights x {n_sel} objects)"
    radii = packed.rows.hot[point_rows, 3]
    median = float(np.partition(radii, radii.size // 2)[radii.size // 2])
    g_f, dims = grid_shape(box[:3], box[3:], tuning.cell_per_radius * median)
    return g_f, dims, None


def grid_text(what: str, index: GridIndex) -> str:
    """How a grid of ``what`` was made: its cells and how many objects it tests directly."""
    g_f, dims, big_pos = index.frame, index.dims, index.big_pos
    return (f"grid of {what} ({dims[0]}x{dims[1]}x{dims[2]} cells of {1 / g_f[3]:.3g} m, "
            f"z {RUN_SPLIT}x finer, {big_pos.size} objects larger than a cell tested directly)")


def group_boxes_of(grid: Grid, lo: np.ndarray, hi: np.ndarray, single: bool) -> BoxSource:
    """The boxes of a grid of every object as grid.group_boxes reads them, its group
    boxes made from them if it has none yet. Its records hold the world boxes in exact
    precision (origin 0, float64), in grid order; "fast" ones (``single``) are rounded, so
    the stores' boxes (lo, hi) are read by row."""
    box = grid.records.box
    boxes = (BoxSource(lo, hi, grid.records.rows, True) if single else
             BoxSource(box[:, :3], box[:, 3:6], grid.records.rows, False))
    if grid.group_box is None:
        grid.group_box = group_boxes(boxes)
    return boxes


def shown_mask(shown: np.ndarray, mask: np.ndarray, single: bool) -> np.ndarray:
    """The mask words of the records of a grid of every object (visible_objects,
    move_records), per object: its mask when ``shown``; else, so that it pairs with no
    light, 0 in float32 records (``single``) and in float64 records its mask in the upper
    half of the word, where the candidate lists' walk of a moving camera finds it without
    writing it (simd.SHOWN)."""
    if single:
        return np.where(shown, mask, 0).astype(mask.dtype, copy=False)
    wide = mask.astype(np.uint64)
    return np.where(shown, wide, wide << np.uint64(32))


def records_grid(lo: np.ndarray, hi: np.ndarray, mask: np.ndarray, select: np.ndarray,
                 shape: tuple[np.ndarray, np.ndarray], frame: tuple[np.ndarray, bool],
                 out: np.ndarray | None = None) -> tuple[GridIndex, Records, np.ndarray]:
    """The selected rows of (lo, hi, mask) sorted into the grid shape = (g_f, dims), and
    their records: (GridIndex, Records, position per row or -1). Records are float64, or
    float32 in "fast" precision, written into the front of ``out`` (1-d, of that dtype)
    if given."""
    g_f, dims = shape
    vis_rows, pos_of, cell_start = visible_order(lo, hi, select, g_f, dims, frame)
    nv = vis_rows.size
    n_small = int(cell_start[int(dims[0] * dims[1] * dims[2])])
    vis_box = (np.empty((nv, 8), np.float32 if frame[1] else np.float64) if out is None
               else out[:8 * nv].reshape(nv, 8))
    vis_bits = vis_box.view(np.uint32 if frame[1] else np.uint64)
    recs = Records(vis_box, vis_bits, vis_rows)
    ext = visible_objects(lo, hi, mask, vis_rows, n_small, recs, frame[0])
    big_pos = np.arange(n_small, nv, dtype=np.int32)
    return GridIndex(g_f, dims, cell_start, ext, big_pos), recs, pos_of
