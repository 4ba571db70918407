"""Candidate lists (Verlet lists): per object the point and spot lights whose sphere,
widened by a skin (Tuning.skin), reached it when its list was made (DESIGN section 6:
lights that moved a little find their pairs without walking the grid).

``left_spheres`` finds the lights that left the sphere their lists were made with,
``widen_walkers`` gives those their widened sphere for a walk of the grid (walk.py),
``spread_lists`` lays out per object the lights whose widened sphere reached it,
``edit_candidates`` and ``light_lists`` (``compact_light_lists``) follow the lights that
walk again, and ``candidate_pairs`` makes the exact Affects test and P of each object's
candidates, in row order: chunks of objects whose candidates are laid end to end and taken
eight a step whatever object each belongs to (simd.stream_run). An incremental frame whose
lights change runs it on the objects in those lights' lists (``list_objects``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, NamedTuple

import numba as nb
import numpy as np

from .grid import light_order
from .group import group_by_object
from .jit import GROUP_PARTS, OBJECT_CHUNK, PRANGE_ONLY
from .priority import (
    MODEL_CONTRIBUTION,
    PackedLights,
    PairParams,
    aligned_empty,
    box_d2,
    record_pair_p,
)
from .simd import (
    LANES,
    SHOWN,
    candidate_run,
    prefetch_row,
    stream_fill,
    stream_pack,
    stream_run,
    stream_spots,
)
from .walk import LightPairs, walk_lights

if TYPE_CHECKING:
    from .buffers import Buffers
    from .grid import Grid
    from .priority import Packed
    from .scene import LightStore, ObjectStore
    from .tuning import Tuning


class CandidateLists(NamedTuple):
    """The candidate lists by object row, each in a room with space to grow
    (spread_lists), so that edit_candidates changes them in place."""

    seg: np.ndarray        # int64 [N, 2]: the list's start in light_row, its length
    cap: np.ndarray        # int64 [N]: the room the list has
    light_row: np.ndarray  # int32 [C]: the lists, then spare room
    fill: np.ndarray       # int64 [GROUP_PARTS, 2]: per row range, where its next moved
    #                        list goes and the end of its share of the spare room


class LightLists(NamedTuple):
    """The candidate lists by light row: light j's objects at object_row[seg[j, 0]:][:seg[j, 1]],
    appended frame after frame (light_lists), packed when full (compact_light_lists)."""

    seg: np.ndarray         # int64 [L, 2]: start, length
    object_row: np.ndarray  # int32 [H]


class RowRecords(NamedTuple):
    """The grid's object records copied into object row order (grid.Records' box and
    bits, row o at o), as candidate_pairs reads them."""

    box: np.ndarray   # [N, 8] float64 (float32 in "fast")
    bits: np.ndarray  # the same memory as unsigned integers (the mask word, column 6)


@dataclass
class Candidates:
    """Per object row, the point and spot lights that may affect it while each stays
    inside its anchored sphere (candidate_pairs): ``anchor`` [L, 4] is per light row the
    centre (records' frame) and radius of the sphere its candidates were found with,
    radius 0 for none; ``lists`` the lists by object row, ``by_light`` the same by light
    row, from record ``used`` on free; ``records`` the grid's records in object row
    order; ``hidden`` whether the lists hold the objects out of view too. Valid while the
    objects, the records' origin and the grid are the ones they were made with and,
    unless ``hidden``, no object came into view (pairs.find_pairs)."""

    anchor: np.ndarray
    lists: CandidateLists
    by_light: LightLists
    used: int
    records: RowRecords
    hidden: bool


def update_candidates(old: Candidates | None, *, lights: LightStore, objects: ObjectStore,
                      packed: Packed, grid: Grid, tuning: Tuning, buffers: Buffers,
                      hidden: bool, last_position: np.ndarray | None
                      ) -> tuple[Candidates, np.ndarray, bool]:
    """The candidate lists for this frame's lights (``old`` valid or None): a competing
    point or spot light keeps its candidates while its sphere lies inside the one they
    were found with (left_spheres); the others walk the grid again with their sphere
    widened by tuning.skin and centred ahead along their last step (tuning.lead, given
    ``last_position``, each light's position last frame), range test only (every light
    mask bit: the lists must not depend on the lights' masks, which may change while they
    are kept), a light that turned directional is dropped from them, and the lists of the
    objects they leave or enter are edited in place (edit_candidates; a list that outgrows
    its room moves to the spare room). All are made again when there are none, more than
    tuning.rebuild_share of the lights left theirs, or the spare room ran out; made with
    ``hidden`` (the camera moves) they hold the objects out of view too, by their own mask,
    so that they serve the objects a moving camera brings into view; else only the
    objects in view, which keeps the walks and lists of a still camera smaller. Returns
    (lists, the rows of the lights whose lists changed: those walked and those dropped,
    made from scratch)."""
    hot = packed.rows.hot
    n_l = hot.shape[0]
    own = packed.compete.copy()
    own[packed.dir_all] = False
    walk_mask = own
    hold = hidden if old is None else old.hidden
    gone = np.zeros(0, np.int64)
    if old is not None:
        walk_mask = left_spheres(hot, old.anchor, own)
        if np.count_nonzero(walk_mask) > tuning.rebuild_share * np.count_nonzero(own):
            old, walk_mask, hold = None, own, hidden
        else:
            # A point or spot light that turned directional still has its objects in the
            # lists (it has an anchor), where candidate_pairs would pair it again beside
            # its directional pair: it is dropped from them, as a walk that found nothing.
            gone = packed.dir_all[old.anchor[packed.dir_all, 3] > 0]
    # The walk as the light pass's with every light a point light of the widened radius
    # and every mask bit (its P are not used). It reads the rows of the lights it walks
    # only: those are written, into a kept buffer.
    wide = buffers.scratch("wide", n_l * 8, np.float64)[:n_l * 8].reshape(n_l, 8)
    now = lights.position
    # Centred ahead of a moving light, along its last step: it crosses the widened sphere
    # before it leaves it, ~(1 + lead) x as many frames.
    last = now if last_position is None else last_position
    exact = grid.records.box.dtype == np.float64

    def walk_of(mask: np.ndarray) -> LightPairs:
        # Lists that hold the objects out of view: in float64 records those keep their
        # masks in the upper half of the word, which a walker's mask of every bit of the
        # word meets (SHOWN).
        every = -1.0 if hold and exact else float(SHOWN)
        sel = widen_walkers(hot, mask, now, last, wide, tuning.skin, tuning.lead, every)
        rows = light_order(hot, sel, grid.index.frame, grid.index.dims)
        params = PairParams(MODEL_CONTRIBUTION, 0.0, 0.0)
        if not hold or exact:
            return walk_lights(PackedLights(wide, packed.rows.f), rows, grid, params, buffers,
                               "cand")
        # Float32 records, whose out-of-view objects' masks are 0: those carry their own
        # mask during the walk, kept with the visibility and grid they come from.
        if (buffers.hidden is None or buffers.hidden[0] is not grid.shown
                or buffers.hidden[1] is not grid.pos_of):
            out_of_view = np.flatnonzero(~grid.shown)
            buffers.hidden = (grid.shown, grid.pos_of, grid.pos_of[out_of_view],
                              objects.mask[out_of_view])
        pos, mask_of = buffers.hidden[2:]
        grid.records.bits[pos, 6] = mask_of
        try:
            return walk_lights(PackedLights(wide, packed.rows.f), rows, grid, params, buffers,
                               "cand")
        finally:
            grid.records.bits[pos, 6] = 0

    walked = walk_of(walk_mask)
    if gone.size:
        rows, offsets, count = walked.rows, walked.offsets, walked.count
        walked = LightPairs(np.concatenate([rows, gone.astype(rows.dtype)]),
                            np.concatenate([offsets, np.full(gone.size, offsets[-1])]),
                            np.concatenate([count, np.zeros(gone.size, count.dtype)]),
                            walked.obj, walked.p)
    if old is not None:
        if edit_candidates(walked, old.lists, old.by_light):
            by_light, used = old.by_light, old.used
            n_new = int(walked.count.sum())
            if used + n_new > by_light.object_row.size:
                # Packed, with room for the live lists again (a few dozen frames).
                l_seg, l_obj, used = compact_light_lists(
                    by_light, int(by_light.seg[:, 1].sum()) + n_new + 1024)
                by_light = LightLists(l_seg, l_obj)
            used = light_lists(walked, by_light, used)
            out = Candidates(old.anchor, old.lists, by_light, used, old.records, hold)
        else:
            old, walk_mask, hold, gone = None, own, hidden, gone[:0]
            walked = walk_of(own)
    if old is None:
        out = _new_lists(walked, grid, n_l, hold, buffers)
    walk = walked.rows[:walked.rows.size - gone.size]
    out.anchor[walk] = wide[walk, :4]
    out.anchor[gone, 3] = 0.0
    return out, walked.rows, old is None


def _new_lists(walked: LightPairs, grid: Grid, n_l: int, hold: bool,
               buffers: Buffers) -> Candidates:
    """Candidate lists made from scratch from a walk of every light (``walked``)."""
    n = grid.pos_of.size
    start, grouped = group_by_object(walked, n, buffers)
    light_j = grouped.light_row
    room = int(list_room(start))
    lists = CandidateLists(np.empty((n, 2), np.int64), np.empty(n, np.int64),
                           np.empty(room + max(4096, room // 4), np.int32),
                           np.empty((GROUP_PARTS, 2), np.int64))
    spread_lists(start, light_j, lists)
    by_light = LightLists(np.zeros((n_l, 2), np.int64),
                          np.empty(2 * light_j.size + 1024, np.int32))
    used = light_lists(walked, by_light, 0)
    box = np.take(grid.records.box, grid.pos_of, axis=0, mode="wrap",
                  out=aligned_empty((n, 8), grid.records.box.dtype))
    return Candidates(np.zeros((n_l, 4)), lists, by_light, used,
                      RowRecords(box, box.view(grid.records.bits.dtype)), hold)

# candidate_pairs asks for the light rows of the object this many rows ahead, once
# light_hot is over PREFETCH_BYTES: an object's candidates are rows of it at random, which
# the records streaming through L2 push out. One object ahead did best, and prefetching
# light_f's rows too cost more than it saved. The 64 KB of 1k lights stay cached: there the
# prefetches only cost (bench/RESULTS.md, "Measurements behind the code").
PREFETCH_OBJECTS = 1


PREFETCH_BYTES = 1 << 18


# list_objects asks for the seg rows and lists of the lights this far ahead, cache misses
# otherwise; the distance matters little (bench/RESULTS.md, "Measurements behind the code").
LIST_AHEAD = 8


@nb.njit(cache=True, nogil=True, parallel=PRANGE_ONLY, error_model="numpy")
def candidate_pairs(rows, lists, recs, lights, compete, dir_rows, params, seg, heap, used):
    """The pairs of the object ``rows`` (int64, ascending) from their candidate lights
    (scheduler._Candidates: the point and spot lights whose sphere, widened by a skin,
    reached the object when its list was made, and which still lies inside that widened
    sphere): per candidate that competes, the exact Affects test and P (record_pair_p, as the
    light pass), then the competing directional lights ``dir_rows``. So a frame whose
    lights moved within their skins walks no grid and groups nothing, and finds the same
    pairs; an incremental frame, those of the objects a changed light may reach. The
    lists' upkeep costs less than the walk and grouping they save (bench/RESULTS.md,
    Next 10 and ebb5ec0).

    Under the contribution model with float64 records and no directional light in the
    slots, each chunk of rows runs as a stream (_stream_chunk): their candidates laid end
    to end and taken eight a step in vector code whatever object each belongs to, the spot
    lights' cones eight at a time after them, then the pairs packed into the chunk's room.
    Object by object (candidate_run, eight candidates of one object a step), a step was
    often part empty and a branch on its spots' cones failed unpredictably (bench/RESULTS.md,
    "Measurements behind the code"). Otherwise object by object: candidate_run, or the scalar
    loop below (other models, "fast" float32 records); where the lights' rows do not stay
    cached, those of the next object's candidates are prefetched while this one's are
    tested (PREFETCH_OBJECTS).

    DESIGN section 2 ("Affects", "Priority") on the pairs of DESIGN section 6's candidate
    lists. lists: CandidateLists; recs: RowRecords; lights: priority.PackedLights;
    compete: bool [L], the lights that compete for slots; params: priority.PairParams;
    seg [N, 2] (start, length) and heap (group.PairHeap): the pair cache, the heap's
    records from ``used`` on free for the rows' candidates plus len(dir_rows) per row.
    Writes the rows' segments (the others' are left as they are), each object's pairs
    in candidate order within the room of its chunk of rows, and returns (the end of those
    rooms, the number of pairs written, the number of pairs the rows' old segments held);
    (that end, -1, that number) with nothing written when the heap is shorter than it, so
    that a caller may size the heap from an estimate or pack it. ``used`` = 0 means no
    segment holds a record (a full frame's seg is new, and not read): an incremental frame
    learns its room and the pairs it drops in the one parallel pass over its rows that
    sizes the chunks (a separate serial pass would cost more: those rows' seg entries are
    cache misses)."""
    c_seg, c_j = lists.seg, lists.light_row
    box, bits = recs.box, recs.bits
    hot, lf = lights.hot, lights.f
    o_seg, o_p, o_j = seg, heap.p, heap.light_row
    model = params.model
    n_rows = rows.shape[0]
    n_dir = dir_rows.shape[0]
    # candidate_run and the stream read whole 8-word rows.
    vector = (model == MODEL_CONTRIBUTION and box.shape[1] == 8 and hot.shape[1] == 8
              and lf.shape[1] == 8)
    stream = vector and n_dir == 0
    far = hot.nbytes > PREFETCH_BYTES
    n_chunks = (n_rows + OBJECT_CHUNK - 1) // OBJECT_CHUNK
    # The chunks' rooms summed in parallel: at (1M, 100k) the rows' lengths are 16 MB of
    # segments, read with a stride.
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
            k = _stream_chunk(lists, recs, lights, compete, rows, r0, r1, room[ch:ch + 2],
                              seg, heap)
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
                end = candidate_run(box, o, hot, lf, compete, c_j, a, b, o_p, o_j, m,
                                    room[ch + 1])
                if end >= 0:
                    a = b
                    m = end
            m = scalar_candidates(box, ob, o, lights, compete, c_j, a, b, heap, m, params)
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
def _stream_chunk(lists, recs, lights, compete, rows, r0, r1, room, seg, heap):
    """candidate_pairs' vector path for the object rows rows[r0:r1] (no directional light
    in the slots): their
    candidates laid end to end (simd.stream_fill), the exact test and P eight entries a
    step (stream_run), the spots in range eight a step (stream_spots), the pairs packed
    from room[0] on (stream_pack; room[1]: the end of the chunk's room), each object's
    segment from the pairs before its first entry. The same pairs, in the same order and
    bits, as candidate_run object by object. Returns the number of pairs written, or -1,
    having written nothing, for float32 records. The other parameters as
    candidate_pairs'."""
    base = room[0]
    # Each step stores eight entries whole: room for one more step.
    ints = np.empty((3, room[1] - base + LANES), np.int32)
    stream = (ints[0], ints[1])
    spots = ints[2]
    starts = np.empty(r1 - r0 + 1, np.int64)
    # simd's primitives take plain tuples (their IR checks the types).
    n_s = stream_fill((lists.seg, lists.light_row), (recs.box, recs.bits), rows, r0, r1,
                      stream, starts)
    if n_s < 0:
        return -1
    box = recs.box
    results = (np.empty(n_s + LANES), np.empty(n_s + LANES, np.uint8))
    n_spots = stream_run(box, lights.hot, compete, stream, n_s, results, spots)
    if n_spots:
        stream_spots(box, (lights.hot, lights.f), stream, spots, n_spots, results)
    before = np.empty(n_s + LANES + 1, np.int64)
    stream_pack(stream, results, n_s, (heap.p, heap.light_row), base, room[1], before)
    for r in range(r0, r1):
        o = rows[r]
        a = before[starts[r - r0]]
        seg[o, 0] = base + a
        seg[o, 1] = before[starts[r - r0 + 1]] - a
    return before[n_s]


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def scalar_candidates(box, ob, o, lights, compete, c_j, a, b, out, m, params):
    """candidate_pairs' rule, one candidate at a time (DESIGN section 2, "Affects" and
    "Priority"): of object row o (record o of box, mask bits ob) and the candidate light
    rows c_j[a:b], the pairs of lights (priority.PackedLights) that compete with a mask
    bit of the object's, in range, then record_pair_p (cone, P of the model
    priority.PairParams), appended from m to ``out`` (group.PairHeap); returns the new
    end. simd.candidate_run does the same eight at a time (tests/test_simd.py holds one
    against the other)."""
    hot, lf = lights.hot, lights.f
    o_p, o_j = out.p, out.light_row
    model = params.model
    for t in range(a, b):
        j = np.int64(c_j[t])
        if not compete[j] or ob & np.int64(hot[j, 4]) == 0:
            continue
        d2 = box_d2(box, o, hot[j, 0], hot[j, 1], hot[j, 2])
        if d2 <= hot[j, 3] * hot[j, 3]:
            typ = (np.int64(hot[j, 5]) >> 3) & 3
            hit, p = record_pair_p(hot, lf, j, typ, o, d2, box, model, params.w_obj, params.w_int)
            if hit:
                o_p[m] = p
                o_j[m] = j
                m += 1
    return m


@nb.njit(cache=True, nogil=True, error_model="numpy")
def widen_walkers(hot, walk, now, last, wide, skin, lead, every):
    """The rows of the lights that walk for the candidate lists (``walk`` True per light
    row), int32 ascending, with their rows of ``wide`` written from light_hot's: the radius
    widened by skin, the mask ``every`` (every mask bit: float(SHOWN), or -1.0 to meet the
    hidden masks of the objects out of view too), the point type (whatever the light's
    type: the lists hold the range test only), and the centre ahead along the light's last
    step by lead x skin x its radius (now, last: the lights' world positions [L, 3] now
    and last frame; a light that did not move keeps its centre); skin, lead: Tuning's.
    DESIGN section 6 (candidate lists). One loop over the lights, where numpy took a dozen
    calls on the walkers' rows, each paying numpy's per-call overhead.
    """
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


# left_spheres loops on the calling thread below this many lights: the test is cheap, so
# below a few thousand waking the second thread costs what it would save.
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
    records' strided columns, whose temporaries cost many times the loop; parallel from
    SERIAL_SPHERES lights. hot: light_hot [L, 8] float64 (priority.PackedLights.hot);
    own: bool [L], the competing point and spot lights; returns bool [L] (False where not
    ``own``). DESIGN section 6 (candidate lists: lights that moved a little keep theirs)."""
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
    ``edit_candidates`` changes them in place (a list that outgrows its room moves to
    the spare room, out of row order). lists:
    CandidateLists, whose light_row must hold the rooms' total (``list_room``); the rest
    is spare room, shared out to the GROUP_PARTS row ranges of edit_candidates. start:
    int64 [N + 1]; light_j: int32 light rows (group.group_by_object's PairHeap.light_row).
    DESIGN section 6 (the candidate lists' layout)."""
    seg, cap, cand, fill = lists.seg, lists.cap, lists.light_row, lists.fill
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
    """The lists by light row (LightLists) packed into a new array with ``spare`` free records after
    them (the segments light_lists left behind are garbage); returns (seg, object rows,
    records used). The lists, appended frame after frame, lie scattered over the old
    array: copied one light a time in parallel, each a slice (one element at a time on
    one thread, it was a spike in the frames it falls on; bench/RESULTS.md). by_light:
    LightLists; spare: int.
    DESIGN section 6 (the candidate lists' upkeep)."""
    l_seg, l_obj = by_light.seg, by_light.object_row
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
    """The total room spread_lists gives lists grouped at ``start`` (int64 [N + 1], as
    spread_lists'), an int. DESIGN section 6 (the candidate lists' layout)."""
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
    ``lights`` (light rows, int32 or int64; by_light: LightLists, as light_lists keeps
    them); mark: bool [N], by object row. DESIGN section 6 (only the objects changed
    lights can touch are recomputed).

    Each light's seg row and the start of its list are misses (lights at random, lists
    scattered over the heap): both are prefetched LIST_AHEAD lights ahead, the seg row
    twice as far so that its list's start can be read. One thread: two would write the
    same lines of ``mark``."""
    l_seg, l_obj = by_light.seg, by_light.object_row
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
    Both ascending, int64, in one pass without branches: with about half of the rows
    reached (lights10), np.flatnonzero of a mask mispredicts on nearly every other row.
    reach, visible (the objects' visibility), more: [N] bools viewed as uint8. DESIGN
    section 6 (only the objects changed lights can touch are recomputed)."""
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
    """Each walked light's objects (walked: walk.LightPairs) appended to the lists by light
    row (by_light: LightLists) from record ``used`` (int); returns the records used after
    them, or -1 when they do not fit (nothing is written then). DESIGN section 6 (the
    candidate lists' upkeep)."""
    rows, offsets, count, pair_obj = walked.rows, walked.offsets, walked.count, walked.obj
    l_seg, l_obj = by_light.seg, by_light.object_row
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
    made them. walked: walk.LightPairs; lists: CandidateLists; by_light: LightLists.
    Returns False when a part's spare space ran out (the caller makes every list again:
    they are half edited). DESIGN section 6 (the candidate lists' upkeep)."""
    rows, offsets, count, pair_obj = walked.rows, walked.offsets, walked.count, walked.obj
    seg, cap, cand, fill = lists.seg, lists.cap, lists.light_row, lists.fill
    l_seg, l_obj = by_light.seg, by_light.object_row
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
