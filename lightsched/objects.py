"""The object pass (DESIGN section 2, "Selection", "Fade", slot_shadow): per object, its
cached pairs in, top-K with hysteresis (select.py), the fade machine (fade.py) and the
shadowed slots (shadows.pick_slot_shadows), outputs out.
"""

from __future__ import annotations

import math
import operator
from dataclasses import dataclass
from typing import TYPE_CHECKING, NamedTuple

import numba as nb
import numpy as np

from .buffers import Buffers, SpareOutputs, read_only_view
from .fade import fade_object, held_slots, steady_slots
from .frame import (
    PER_OBJECT,
    copy_rows,
    copy_rows_parallel,
    field_shape,
    held_elsewhere,
    rows_not_in,
)
from .jit import OBJECT_CHUNK, PRANGE_ONLY
from .priority import residual_term
from .scene import ON
from .select import (
    CF_P,
    CF_ROWS,
    CI_ID,
    CI_ROW,
    CI_ROWS,
    F_NEW_P,
    F_NEW_W,
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
    I_ROW,
    I_ROWS,
    gather_few,
    gather_live,
    match_old_slots,
    top_k,
)
from .shadows import pick_slot_shadows
from .simd import LANES, held_row

if TYPE_CHECKING:
    from .pair_cache import PairCache
    from .plan import FramePlan
    from .priority import Packed
    from .scene import Config, LightStore, ObjectStore
    from .scheduler import FrameState
    from .shadows import ShadowSet
    from .tuning import Tuning

STATIC_K = (4, 8)            # K values the object pass is compiled for (8 is the default)
SORT_FEW = 16                # residual_gather sorts more lights than this with numpy's sort
RESIDUAL_TERMS = 4096        # a ResidualBatch's terms (more when one object has more pairs)
# Residual.residual with the residual off: the pass writes none (of the type it has on).
_NO_RESIDUAL = np.zeros((0, 4), np.float32)

# Per-object outputs the objects stage writes ("visible" is the visibility array itself).
WRITTEN = tuple(name for name in PER_OBJECT if name != "visible")
# Those of ObjectOutputs: all but the residual, which the pass writes through Residual
# (simd.held_row takes ObjectOutputs as they are).
PASS_WRITTEN = tuple(name for name in WRITTEN if name != "residual")
_pass_outputs = operator.itemgetter(*PASS_WRITTEN)
# The object pass's output arrays: PASS_WRITTEN (DESIGN section 3), each [N, K] or [N],
# and ``fading`` bool [N], whether a slot of the object is fading in or out.
ObjectOutputs = NamedTuple("ObjectOutputs", [(name, np.ndarray) for name in PASS_WRITTEN]
                           + [("fading", np.ndarray)])


class SlotState(NamedTuple):
    """The per-object state the object pass reads, each [N, K] (the object store's)."""

    light_ids: np.ndarray  # int32: last frame's light_ids (read-only)
    weight: np.ndarray     # float64: the slots' weights, updated in place
    state: np.ndarray      # uint8: last frame's fade_state (read-only)
    selected: np.ndarray   # int32: last frame's selected lights, updated in place


class FadeParams(NamedTuple):
    """The rules of DESIGN section 2, "Selection" (hysteresis) and "Fade", for one dt."""

    hysteresis: float
    hysteresis_abs: float
    fade_in_step: float   # dt / fade_in, a weight's step up a frame (1 when fade_in is 0)
    fade_out_step: float  # dt / fade_out
    fade_in: float
    fade_out: float


class SlotShadows(NamedTuple):
    """What slot_shadow reads (DESIGN section 2, "slot_shadow[o, k]")."""

    shadow_of_row: np.ndarray  # int: per light row its shadow map index, or -1
    max_shadowed: int          # Config.max_shadowed_per_object


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


@nb.njit(cache=True, nogil=True, parallel=PRANGE_ONLY, error_model="numpy")
def object_pass(run, objs, seg, longest, heap, live_id, state, selected_before, out, params,
                shadow, residual, k_static, residual_static):
    """For the object rows ``run`` (ascending, parallel in chunks): top-K with hysteresis,
    fade, outputs; rows not in ``run`` are left as they are (an incremental frame has
    copied them from the last frame).

    objs = (visible, reset): reset marks objects that start with their selected lights on
    (step 3 of Fade); seg [N, 2] (start, length) of each object's pairs in ``heap``
    (group.PairHeap): the pair cache; longest: at least the longest segment
    (PairCache.longest: each chunk's pools take that many lights); live_id = per light
    row its id if it is live (visible, and not removed by unshadowed = "skip"), else -2
    (``live_ids``; pairs of other lights are kept in the cache but do not compete); state:
    SlotState; selected_before: int32 [run.size, K], where the pass keeps each row's
    state.selected as it was before the pass (for explain; kept as the row is read, where
    a copy apart cost a pass over memory); out: ObjectOutputs; params: FadeParams;
    shadow: SlotShadows; residual: Residual (residual_gather once a row's slots are
    written, residual_flush by batches); k_static = a tuple of K zeros if K is in
    STATIC_K, else (); residual_static = (0,) with the residual on (Config.residual), else
    () (no residual is written). run: int64 object rows; visible, reset: bool [N];
    live_id: int32 [L].

    DESIGN section 2, "Slots" (candidates), "Selection", "Fade", "slot_shadow[o, k]" and
    "Residual"; section 3 (the per-object outputs and their empty slots); section 6 (only
    ``run``).

    Most objects of a scene in motion are steady: last frame's slots are all on and hold
    exactly this frame's selection, so only P changes. They skip the fade machine (its
    result is fade.held_slots: last frame's order, sorted again by this frame's P) and
    read only last frame's ids and states. With K = 8 those still in last frame's order
    (83% of a full (100k, 10k) frame's rows), and those whose slots only fade in, go
    through simd.held_row, one vector store an output row; the rest run the code below.
    """
    shadow_of_row, max_shadowed = shadow.shadow_of_row, shadow.max_shadowed
    any_shadow = max_shadowed > 0 and shadow_of_row.max() >= 0 if shadow_of_row.size else False
    n_run = run.shape[0]
    n_chunks = (n_run + OBJECT_CHUNK - 1) // OBJECT_CHUNK
    held_rules = (shadow_of_row, np.int64(max_shadowed) if any_shadow else np.int64(0),
                  params.hysteresis, params.hysteresis_abs, params.fade_in_step, params.fade_in)
    # (As a tuple: a NamedTuple cannot cross into the prange by itself.)
    empty = residual_batch(0, False)
    idle = (empty.objects, empty.start, empty.keys, empty.rho)
    for ch in nb.prange(n_chunks):
        # A call a chunk: the rows' code is inlined in it, where numba's parallel analysis
        # of a prange body cannot follow it, and a call a row would count the references
        # of its arrays atomically, on lines both threads write.
        _object_chunk(run, ch * OBJECT_CHUNK, min(n_run, (ch + 1) * OBJECT_CHUNK), objs, seg,
                      longest, heap, live_id, state, selected_before, out, params, held_rules,
                      residual, k_static, residual_static, idle)


@nb.njit(cache=True, nogil=True, error_model="numpy")
def _object_chunk(run, first, end, objs, seg, longest, heap, live_id, state, selected_before,
                  out, params, held_rules, residual, k_static, residual_static, idle):
    """object_pass on run[first:end]; held_rules: simd.held_row's rules (shadow_of_row,
    how many slots may take a map: 0 when no light has one, h, hysteresis_abs,
    dt/fade_in, fade_in); idle: the arrays of the ResidualBatch a chunk takes with the
    residual off (one for the pass: four allocations a chunk add up over a frame's
    chunks); the others as object_pass's."""
    visible, reset = objs
    heap_p, heap_j = heap.p, heap.light_row
    s_id, s_w, s_st, s_sel = state.light_ids, state.weight, state.state, state.selected
    o_ids, o_index, o_prio, o_w = out.light_ids, out.light_index, out.priority, out.fade_weight
    o_st, o_count, o_cand, o_shadow = out.fade_state, out.count, out.candidates, out.slot_shadow
    o_fading = out.fading
    shadow_of_row, max_shadowed = held_rules[0], held_rules[1]
    any_shadow = max_shadowed > 0
    h = params.hysteresis
    h_abs = params.hysteresis_abs
    inc = params.fade_in_step
    dec = params.fade_out_step
    fade_in = params.fade_in
    fade_out = params.fade_out
    # A common K is a compile-time constant, the length of a tuple (its type holds it):
    # every per-slot loop then has a known trip count, which LLVM unrolls and vectorises
    # whole (bench/RESULTS.md, "Measurements behind the code"). Each such K costs a
    # compilation of this kernel (slow, then cached), so only STATIC_K are; any other K
    # is read from the arrays. (numba.literally would type the kernel again every call.)
    k = len(k_static) if len(k_static) else s_id.shape[1]
    sf = np.empty((F_ROWS, k))
    si = np.empty((I_ROWS, k), np.int64)
    pool_size = max(k + 1, longest)
    cf = np.empty((CF_ROWS, pool_size))
    ci = np.empty((CI_ROWS, pool_size), np.int64)
    # Off, the residual's code is dead at compile time (the length of the tuple
    # ``residual_static`` is in its type), so a frame without it runs the pass it had
    # before the residual. (An empty tuple inside the Residual NamedTuple cannot cross into
    # the prange.)
    on = len(residual_static) > 0
    batch = residual_batch(pool_size, on) if on else ResidualBatch(*idle)
    in_batch = 0
    for r in range(first, end):
        o = run[r]
        for m in range(k):
            selected_before[r, m] = s_sel[o, m]
        cand = -1
        if k == LANES and visible[o] and not reset[o] and 0 < seg[o, 1] <= 2 * LANES:
            # The common case in vector code: slots held in last frame's order.
            cand = held_row(o, seg[o, 0], seg[o, 1], (heap_p, heap_j), (live_id,), state,
                            out, held_rules)
            if cand >= 0:
                o_count[o] = min(cand, k)
                o_cand[o] = cand
                summed = cand > k or o_fading[o]
        if cand < 0:
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
                if b - a <= k:
                    # Every competing light is selected: gathered straight into the
                    # selection's rows, no keys, no ranking.
                    cand = gather_few(heap_p, heap_j, live_id, a, b, sf, si)
                    nbest = cand
                else:
                    cand = gather_live(heap_p, heap_j, live_id, a, b, cf, ci)
                    match_old_slots(cf, ci, cand, sf, si)
                    if cand <= k:
                        for t in range(cand):
                            sf[F_P, t] = cf[CF_P, t]
                            si[I_ID, t] = ci[CI_ID, t]
                            si[I_ROW, t] = ci[CI_ROW, t]
                        nbest = cand
                    else:
                        nbest = top_k(cf, ci, cand, s_sel, o, sf, si, h, h_abs)
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
            summed = visible[o] and (cand > cnt or fading)
        # (Off, no row is written: the frame's residual is Buffers' array of zeros.)
        if on and summed:
            if batch.start[in_batch] + seg[o, 1] > batch.keys.shape[0]:
                in_batch = residual_flush(batch, in_batch, residual)
            in_batch = residual_gather(o, (heap_j, seg[o, 0], seg[o, 0] + seg[o, 1]), k,
                                       (o_index, s_w), residual, batch, in_batch)
            if in_batch == OBJECT_CHUNK:
                in_batch = residual_flush(batch, in_batch, residual)
        elif on:
            for c in range(4):
                residual.residual[o, c] = 0.0
    if on:
        residual_flush(batch, in_batch, residual)


class Residual(NamedTuple):
    """What the object pass reads for the residual, and where it writes it (DESIGN section
    2, "Residual")."""

    res_id: np.ndarray       # int32 [L]: per light row its id if it counts, else -2
    hot: np.ndarray          # float64 [L, 8]: priority.PackedLights.hot
    lf: np.ndarray           # float64 [L, 8]: priority.PackedLights.f
    bounds_min: np.ndarray   # float64 [N, 3]: the object store's
    bounds_max: np.ndarray   # float64 [N, 3]
    origin: np.ndarray       # float64 [3]: the packed rows' origin (0 in exact precision)
    residual: np.ndarray     # float32 [N, 4]: the output


class ResidualBatch(NamedTuple):
    """A chunk's residual work in flight: the objects whose lights are gathered and not yet
    summed (residual_gather, residual_flush). Summing them together, in a loop of their
    own, keeps the terms' divisions and cache misses in flight across objects, where in
    each object's turn they waited on one another and on the selection's branches."""

    objects: np.ndarray  # int64 [OBJECT_CHUNK]: the objects' rows, in turn
    start: np.ndarray    # int64 [OBJECT_CHUNK + 1]: each one's first term in keys, then the end
    keys: np.ndarray     # int64 [capacity]: per term (light row << 32) | its index in rho
    rho: np.ndarray      # float64 [capacity]: per term 1 - w_l, by the object's first term


@nb.njit(cache=True, nogil=True)
def residual_batch(pool_size, on):
    """An empty ResidualBatch that holds at least one object of ``pool_size`` pairs, or
    with the residual off (``on`` False) one of empty arrays."""
    cap = max(pool_size, RESIDUAL_TERMS) if on else 0
    n = OBJECT_CHUNK if on else 0
    return ResidualBatch(np.empty(n, np.int64), np.zeros(n + 1, np.int64),
                         np.empty(cap, np.int64), np.empty(cap))


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def residual_gather(o, pairs, k, slots, res, batch, n):
    """Adds object row o to the batch (its n-th object): over o's cached pairs whose light
    counts (res_id >= 0: live, and with unshadowed = "skip" not a light with shadows), those
    not wholly in a slot, with rho = 1 - w_l, w_l the float64 weight of l's slot (0
    without one), in ascending light row (= ascending id). o: the object row; pairs =
    (the pair heap's light rows, int32 [H]; o's first pair; its end); k: K; slots =
    (this frame's light_index, int32 [N, K]; the slots' float64 weights [N, K]); res:
    Residual; batch: ResidualBatch with room for o's pairs. Returns n + 1. DESIGN
    section 2, "Residual"."""
    res_id = res.res_id
    heap_j, first, end = pairs
    slot_rows, slot_w = slots
    keys, rho = batch.keys, batch.rho
    base = batch.start[n]
    m = 0
    for t in range(first, end):
        j = np.int64(heap_j[t])
        # The slot's weight by a pass over the K slots without a branch (light rows are
        # unique).
        w = 0.0
        for s in range(k):
            ws = slot_w[o, s]
            w = ws if slot_rows[o, s] == j else w
        # Sorted by this key, the lights are in ascending row, and each keeps its rho.
        keys[base + m] = (j << 32) | m
        rho[base + m] = 1.0 - w
        # Only the lights not wholly in a slot: t = 0 would add nothing.
        m += (res_id[j] >= 0) & (w < 1.0)
    if m > SORT_FEW:
        keys[base:base + m].sort()
    else:
        for i in range(base + 1, base + m):
            x = keys[i]
            at = i
            while at > base and keys[at - 1] > x:
                keys[at] = keys[at - 1]
                at -= 1
            keys[at] = x
    batch.objects[n] = o
    batch.start[n + 1] = base + m
    return n + 1


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def residual_flush(batch, n, res):
    """residual[o] of the batch's n objects: t = rho_l * E_l over each one's terms in
    turn, (E_l, u_l) priority.residual_term's; a += t, b += t u in float64, stored
    float32. batch: ResidualBatch; res: Residual. Returns 0 (the batch is empty). DESIGN
    section 2, "Residual"; section 3 (residual [N, 4])."""
    lo, hi, origin, out = res.bounds_min, res.bounds_max, res.origin, res.residual
    keys, rho, start = batch.keys, batch.rho, batch.start
    for b in range(n):
        o = batch.objects[b]
        ex = hi[o, 0] - lo[o, 0]
        ey = hi[o, 1] - lo[o, 1]
        ez = hi[o, 2] - lo[o, 2]
        e2 = ex * ex + ey * ey + ez * ez
        geo = ((lo[o, 0] + hi[o, 0]) / 2 - origin[0],
               (lo[o, 1] + hi[o, 1]) / 2 - origin[1],
               (lo[o, 2] + hi[o, 2]) / 2 - origin[2], math.sqrt(e2) / 2, e2)
        a = 0.0
        b0 = 0.0
        b1 = 0.0
        b2 = 0.0
        for i in range(start[b], start[b + 1]):
            e, u0, u1, u2 = residual_term(res.hot, res.lf, keys[i] >> 32, geo)
            t = rho[start[b] + (keys[i] & 0xFFFFFFFF)] * e
            a += t
            b0 += t * u0
            b1 += t * u1
            b2 += t * u2
        out[o, 0] = np.float32(a)
        out[o, 1] = np.float32(b0)
        out[o, 2] = np.float32(b1)
        out[o, 3] = np.float32(b2)
    return 0


def residual_ids(live_id: np.ndarray, shadows: np.ndarray, skip: bool,
                 out: np.ndarray | None = None) -> np.ndarray:
    """The residual's res_id (Residual): live_id, with the lights that have shadows at -2 too under
    unshadowed = "skip" (the residual has no shadow to keep them out of a wall's lee)."""
    if not skip:
        return live_id
    if out is None or out.shape != live_id.shape:
        out = np.empty(live_id.shape, np.int32)
    np.copyto(out, live_id)
    out[shadows] = -2
    return out


# --------------------------------------------------------------------------- the objects stage
# Per-object state kept in the object store: the float64 slot weights and last frame's
# selection (the slot ids and states are the last frame's light_ids and fade_state).
STATE = (("slot_light", np.int32, -1), ("slot_weight", np.float64, 0.0),
         ("slot_state", np.uint8, 0), ("selected", np.int32, -1))


@dataclass(slots=True)
class Outputs:
    """The objects stage's output: the per-object arrays of DESIGN section 3 (``arrays``,
    PER_OBJECT), per object whether a slot is fading in or out (``fading``, which keeps
    the next frame from being "unchanged"), the rows the object pass ran on, and ``how``
    (added to the lists stage's plan entry)."""

    arrays: dict[str, np.ndarray]
    fading: np.ndarray
    run: np.ndarray
    # ``selected`` at the rows ``run`` before the pass overwrote them (for explain).
    selected_before: np.ndarray
    how: str = ""


def select_and_fade(plan: FramePlan, last: FrameState | None, cache: PairCache,
                    packed: Packed, shadows: ShadowSet, visible: np.ndarray,
                    lights: LightStore, objects: ObjectStore, renumbered: bool, config: Config,
                    dt: float, tuning: Tuning, buffers: Buffers) -> Outputs:
    """The objects stage: top-K with hysteresis, fade and slot_shadow (object_pass) on the
    rows the pair cache stage gives (every row in a full frame); the other rows are last
    frame's. A full frame leaves out the objects out of view in it and the two frames
    before: the output arrays it takes back (the frame before the last's) hold their empty
    rows already. ``renumbered``: the object rows are not last frame's."""
    n, k = len(objects), config.max_lights
    run, how = cache.run, ""
    # With the residual off every row of it is 0: the frame gets a read-only array of zeros
    # kept from frame to frame, and the pass writes none. (Buffers holds that array, so a
    # frame's outputs that include it are never taken back to be written.)
    names = WRITTEN if config.residual else PASS_WRITTEN
    if plan.full:
        out, out_vis = _outputs(last, None, n, k, names, tuning, buffers)
        fading = np.empty(n, np.bool_)
        if out_vis is not None and last is not None and not renumbered:
            run = run_rows((visible, last.visibility.objects, out_vis), buffers)
            if run.size < n:
                fading[:] = False
                how = (f"; {n - run.size} objects out of view keep their empty rows (and in "
                       "the two frames before)")
    elif run.size:
        out = _outputs(last, run, n, k, names, tuning, buffers)[0]
        fading = last.outputs.fading.copy()
    else:
        out = {name: getattr(last.frame, name) for name in names}
        fading = last.outputs.fading
    if last is not None and run.size:
        # The last frame's arrays lag this frame's by the rows this frame recomputes.
        buffers.spare_outputs = SpareOutputs(
            {name: getattr(last.frame, name) for name in names},
            None if plan.full else run, last.visibility.objects)
    out["visible"] = visible
    if not config.residual:
        out["residual"] = buffers.zeros("residual zeros", field_shape("residual", n, k),
                                        np.float32)
    # Two buffers in turn: a frame that fails leaves explain the last one's.
    buffers.turn ^= 1
    selected_before = buffers.scratch(f"selected before {buffers.turn}", run.size * k,
                                      np.int32)[:run.size * k].reshape(run.size, k)
    if run.size:
        reset = objects.is_new | ~objects.get("was_visible")
        if plan.reset_all:
            reset = np.ones(n, np.bool_)
        state = SlotState(read_only_view(objects.get("slot_light")), objects.get("slot_weight"),
                          read_only_view(objects.get("slot_state")), objects.get("selected"))
        params = FadeParams(*map(float, (config.hysteresis, config.hysteresis_abs,
                                         _rate(dt, config.fade_in), _rate(dt, config.fade_out),
                                         config.fade_in, config.fade_out)))
        n_l = len(lights)
        live_id = live_ids(lights.id, shadows.live, buffers.scratch("live_id", n_l, np.int32)[:n_l])
        res_id = residual_ids(live_id, lights.shadows, config.unshadowed == "skip",
                              buffers.scratch("res_id", n_l, np.int32)[:n_l])
        object_pass(run, (read_only_view(visible), reset), cache.seg, cache.longest, cache.heap,
                    live_id, state, selected_before,
                    ObjectOutputs(*_pass_outputs(out), fading), params,
                    SlotShadows(shadows.shadow_of_row, int(config.max_shadowed_per_object)),
                    Residual(res_id, packed.rows.hot, packed.rows.f,
                             objects.bounds_min, objects.bounds_max, packed.origin,
                             out["residual"] if config.residual else _NO_RESIDUAL),
                    (0,) * k if k in STATIC_K else (), (0,) if config.residual else ())
    objects.put("slot_light", out["light_ids"])
    objects.put("slot_state", out["fade_state"])
    objects.put("was_visible", visible)
    return Outputs(out, fading, run, selected_before, how)


def _outputs(last: FrameState | None, written: np.ndarray | None, n: int, k: int,
             names: tuple[str, ...], tuning: Tuning, buffers: Buffers
             ) -> tuple[dict[str, np.ndarray], np.ndarray | None]:
    """Arrays for this frame's per-object outputs ``names`` (of WRITTEN): every row is
    written when ``written`` is None (a full frame), else only those rows are, the others
    must be the last frame's. The arrays of the frame before the last are taken back when
    they are the same names and nothing outside holds them any more (a steady scene
    allocates no output memory) and brought up to date with the rows the last frame
    changed and this one does not write; else new arrays (copies of the last frame's for
    an incremental frame). Also, for a full frame that takes them back, the visibility of
    the frame they held (its invisible objects' rows are empty), else None."""
    spare, buffers.spare_outputs = buffers.spare_outputs, None
    if (spare is not None and spare.arrays["light_ids"].shape == (n, k)
            and tuple(spare.arrays) == names and not held_elsewhere(spare.arrays)):
        for arr in spare.arrays.values():
            arr.setflags(write=True)
        if written is not None:
            lag = spare.lag
            if lag is not None:
                # Rows this frame writes need no copy: with the same lights moving frame
                # after frame, that is nearly all of the lag.
                lag = rows_not_in(lag, written)
            if lag is None:
                for name, arr in spare.arrays.items():
                    np.copyto(arr, getattr(last.frame, name))
            elif lag.size:
                pairs = tuple((getattr(last.frame, name), arr)
                              for name, arr in spare.arrays.items())
                row_bytes = sum(arr.strides[0] for arr in spare.arrays.values())
                copy = (copy_rows_parallel if lag.size * row_bytes > tuning.parallel_copy_bytes
                        else copy_rows)
                copy(pairs, lag)
            return spare.arrays, None
        return spare.arrays, spare.visible if spare.visible.shape == (n,) else None
    if written is None:
        return {name: np.empty(field_shape(name, n, k), PER_OBJECT[name][0])
                for name in names}, None
    return {name: getattr(last.frame, name).copy() for name in names}, None


def run_rows(vis: tuple[np.ndarray, np.ndarray, np.ndarray], buffers: Buffers) -> np.ndarray:
    """The rows in view in any of ``vis`` (read-only visibilities: this frame's, the last
    frame's, that of the frame whose arrays are taken back), kept while they are the same
    arrays: under a still camera they are, frame after frame."""
    kept = buffers.kept_run
    if kept is not None and all(a is b for a, b in zip(kept[0], vis, strict=True)):
        return kept[1]
    run = np.flatnonzero(vis[0] | vis[1] | vis[2])
    # (A visibility made in this frame is frozen with it: kept from the next frame on.)
    buffers.kept_run = None if any(v.flags.writeable for v in vis) else (vis, run)
    return run


def _rate(dt: float, fade_time: float) -> float:
    return dt / fade_time if fade_time > 0.0 else 1.0
