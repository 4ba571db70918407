"""simd.point_run then simd.point_priority (a point light's run of records in vector code)
== the scalar rule they replace (priority.box_d2, the mask, priority.falloff + p_user: the
point light's branch of walk._exact_pair), bit for bit, on generated records and runs;
point_run alone == the range test and the mask (the hits' positions and d2, which the
light pass finishes for other lights); simd.spot_priority == the spot branch;
simd.candidate_run (one object against its candidate point and spot lights) == the scalar
loop of candidates.candidate_pairs, and so does candidate_pairs' stream of every object's
candidates (simd.stream_fill, stream_run, stream_spots, stream_pack). With every way of
packing the lanes the target can run (simd.PACKINGS: AVX-512's compress, AVX2's
table and vpermps, the portable branch-free stores), and without a store past the pairs
they append."""

from __future__ import annotations

import copy
import platform

import numba as nb
import numpy as np
import pytest
from helpers import examples
from hypothesis import given
from hypothesis import strategies as st

import lightsched.simd as simd
from lightsched.candidates import RowRecords, candidate_pairs
from lightsched.candidates import scalar_candidates as pairs_scalar
from lightsched.fresh_pairs import FoundLists
from lightsched.grid import Records, visible_objects
from lightsched.group import PairHeap
from lightsched.jit import OBJECT_CHUNK, PRANGE_ONLY
from lightsched.objects import (
    FadeParams,
    ObjectOutputs,
    Residual,
    SlotShadows,
    SlotState,
    live_ids,
    object_pass,
)
from lightsched.priority import MODEL_CONTRIBUTION, PackedLights, PairParams, box_d2, falloff
from lightsched.scene import FADING_IN, FADING_OUT, ON, POINT, SPOT
from lightsched.walk import _finish_hits

finite = {"allow_nan": False, "allow_infinity": False}
SENTINEL_ROW = -7
SENTINEL_P = -123.0


def same_pairs(got: tuple, want: tuple, n: int, room: int) -> bool:
    """The arrays of ``got`` hold ``want``'s first n entries bit for bit (those before the
    pairs, too) and nothing written from ``room`` on: a kernel may store whole vectors
    into the room its caller gives it (simd._store_lanes), never past it."""
    return all(np.array_equal(g[:n].view(np.uint8), w[:n].view(np.uint8))
               and np.array_equal(g[room:].view(np.uint8), w[room:].view(np.uint8))
               for g, w in zip(got, want, strict=True))


@nb.njit(nogil=True, error_model="numpy")
def scalar_run(box, bits, rows, v0, v1, light, out_obj, out_p, n):
    """The scalar rule, record by record, as walk._exact_pair applies it to a point light
    under the contribution model."""
    x, y, z, r, mask, intensity, p_user = light
    lm = np.int64(mask)
    for v in range(v0, v1):
        d2 = box_d2(box, v, x, y, z)
        if d2 <= r * r and np.int64(bits[v, 6]) & lm != 0:
            out_obj[n] = rows[v]
            out_p[n] = falloff(intensity, r, d2, box[v, 7]) + p_user
            n += 1
    return n


@nb.njit(nogil=True, error_model="numpy")
def scalar_hits(box, bits, v0, v1, light, out_obj, out_p, n):
    """(position, d2) of the records in range and mask, as point_run leaves them."""
    x, y, z, r, mask, _, _ = light
    for v in range(v0, v1):
        d2 = box_d2(box, v, x, y, z)
        if d2 <= r * r and np.int64(bits[v, 6]) & np.int64(mask) != 0:
            out_obj[n] = v
            out_p[n] = d2
            n += 1
    return n


def _compiled(packing: str):
    """Fresh kernels around point_run (then point_priority: ``run``; alone: ``hits``),
    lowered with the given packing (simd.PACKING is read when the intrinsic is lowered)."""
    before = simd.PACKING
    simd.PACKING = packing
    try:
        @nb.njit(nogil=True, error_model="numpy")
        def run(box, rows, v0, v1, light, out_obj, out_p, n, room):
            end = simd.point_run(box, rows, v0, v1, light, out_obj, out_p, n, room)
            if end >= 0:
                simd.point_priority(box, rows, light, out_obj, out_p, n, end, room)
            return end

        @nb.njit(nogil=True, error_model="numpy")
        def hits(box, rows, v0, v1, light, out_obj, out_p, n, room):
            return simd.point_run(box, rows, v0, v1, light, out_obj, out_p, n, room)

        @nb.njit(nogil=True, error_model="numpy")
        def spot(box, rows, light, axis, out_obj, out_p, n0, n1, room):
            return simd.spot_priority(box, rows, light, axis, out_obj, out_p, n0, n1, room)

        @nb.njit(nogil=True, error_model="numpy")
        def candidates(box, o, hot, lf, compete, c_j, a, b, out_p, out_j, m, room):
            return simd.candidate_run(box, o, hot, lf, compete, c_j, a, b, out_p, out_j, m,
                                      room)

        @nb.njit(nogil=True, error_model="numpy")
        def held(o, a, n, heap, lights, state, out, shadow):
            return simd.held_row(o, a, n, heap, lights, state, out, shadow)

        box = np.zeros((1, 8))
        candidates(box, 0, box, box, np.ones(1, np.bool_), np.zeros(1, np.int32), 0, 1,
                   np.zeros(1), np.zeros(1, np.int32), 0, 1)
        for kernel in (run, hits):
            kernel(box, np.zeros(1, np.int64), 0, 1, (0.0,) * 7, np.zeros(1, np.int32),
                   np.zeros(1), 0, 1)
        spot(box, np.zeros(1, np.int64), (0.0,) * 7, (0.0,) * 6, np.zeros(1, np.int32),
             np.zeros(1), 0, 0, 1)
        case = held_case(np.random.default_rng(0), ["held"], 1, 0, False)
        held(0, 0, 1, tuple(case[3]), (case[4],), case[5], case[6], held_rules(case))
        return run, hits, spot, candidates, held
    finally:
        simd.PACKING = before


HELD_KINDS = ("held", "reordered", "outranked", "fading", "other", "reset", "hidden")


def held_case(rng, kinds, n_l, max_shadowed, ties, fade_in=0.2):
    """objects.object_pass's arguments (K = 8) for one object of each kind: "held" (last
    frame's slots all on, holding its competing lights in output order under this frame's
    P), "reordered" (the same with two neighbouring slots swapped), "outranked" (held, but
    by the last K of its lights by P: others may rank first even against their
    hysteresis), "fading" (held, some slots fading in), "other" (random slots and states),
    "reset" (step 3), "hidden" (not visible); each with 0-18 pairs of n_l lights (some
    not live), P from a few values (``ties``) or continuous, maps on some lights."""
    k = simd.LANES
    ids = rng.permutation(n_l * 3)[:n_l].astype(np.int32)
    live = rng.uniform(size=n_l) < 0.85
    objects = []
    for kind in kinds:
        rows = rng.permutation(n_l)[:int(rng.integers(0, 19))].astype(np.int32)
        p = rng.choice([-1.0, 0.0, 2.0, 2.5], rows.size) if ties else rng.uniform(-1, 9, rows.size)
        lit = sorted((-p[t], int(ids[rows[t]])) for t in range(rows.size) if live[rows[t]])
        if kind == "other":
            old = rng.permutation(ids)[:int(rng.integers(0, k + 1))]
            states = rng.choice([ON, ON, FADING_IN, FADING_OUT], old.size)
            sel = rng.permutation(ids)[:int(rng.integers(0, k + 1))]
        else:
            old = np.array([lid for _, lid in (lit[-k:] if kind == "outranked" else lit[:k])],
                           np.int32)
            if kind == "reordered" and old.size >= 2:
                t = int(rng.integers(0, old.size - 1))
                old[[t, t + 1]] = old[[t + 1, t]]
            states = np.full(old.size, ON)
            if kind == "fading" and old.size:
                states[rng.permutation(old.size)[:int(rng.integers(1, 4))]] = FADING_IN
            sel = rng.permutation(old)
        objects.append((kind, p, rows, old, states, sel))
    shadow_of_row = rng.choice(np.array([-1, -1, 0, 1, 2, 3], np.int8), n_l)
    return pass_arguments(rng, objects, live_ids(ids, live), shadow_of_row, max_shadowed,
                          fade_in)


def pass_arguments(rng, objects, live_id, shadow_of_row, max_shadowed, fade_in=0.2):
    """objects.object_pass's arguments (K = 8) for objects = [(kind, P and light rows of
    its pairs, last frame's slot ids and states, last frame's selection)] (kinds "reset"
    and "hidden" as held_case's), with a few pairs of no object between them; slots not
    on have weights of a few values (ties, one a step short of 1 within 1e-6) or any."""
    k = simd.LANES
    n = len(objects)
    n_l = live_id.size
    seg = np.zeros((n, 2), np.int64)
    heap_p, heap_j = [rng.uniform(-5, 5, 3)], [rng.integers(0, n_l, 3)]
    s_id = np.full((n, k), -1, np.int32)
    s_w = np.zeros((n, k))
    s_st = np.zeros((n, k), np.uint8)
    s_sel = np.full((n, k), -1, np.int32)
    for o, (_, p, rows, old, states, sel) in enumerate(objects):
        seg[o] = (sum(x.size for x in heap_p), rows.size)
        gap = int(rng.integers(0, 3))
        heap_p += [p, rng.uniform(-5, 5, gap)]
        heap_j += [rows, rng.integers(0, n_l, gap)]
        s_id[o, :old.size] = old
        s_st[o, :old.size] = states
        weights = rng.choice([0.25, 0.5, 0.5, 0.7499995, rng.uniform(0.1, 0.9)], old.size)
        s_w[o, :old.size] = np.where(states == ON, 1.0, weights)
        s_sel[o, :sel.size] = sel
    kinds = [obj[0] for obj in objects]
    visible = np.array([kind != "hidden" for kind in kinds])
    reset = np.array([kind == "reset" for kind in kinds])
    out = ObjectOutputs(np.full((n, k), -9, np.int32), np.full((n, k), -9, np.int32),
                        np.full((n, k), -9.0, np.float32), np.full((n, k), -9.0, np.float32),
                        np.full((n, k), 9, np.uint8), np.full(n, -9, np.int32),
                        np.full(n, -9, np.int32), np.full((n, k), -9, np.int8),
                        np.ones(n, np.bool_))
    params = FadeParams(0.1, 0.05, 0.25 if fade_in else 1.0, 0.25, float(fade_in), 0.2)
    heap = PairHeap(np.concatenate(heap_p), np.concatenate(heap_j).astype(np.int32))
    return (np.arange(n, dtype=np.int64), (visible, reset), seg, heap, live_id,
            SlotState(s_id, s_w, s_st, s_sel), out, params,
            SlotShadows(shadow_of_row, int(max_shadowed)), residual_arguments(rng, n, live_id),
            (0,) * k)


def residual_arguments(rng, n, live_id):
    """object_pass's Residual for n objects of boxes round the origin and point lights
    (intensity 1-10, radius 2-20) near them: most centres in range, some not; the lights
    of even rows count, the others do not (as a light with shadows under "skip")."""
    n_l = live_id.size
    hot = np.zeros((n_l, 8))
    hot[:, :3] = rng.uniform(-6, 6, (n_l, 3))
    hot[:, 3] = rng.uniform(2, 20, n_l)
    hot[:, 5] = POINT << 3
    hot[:, 6] = rng.uniform(1, 10, n_l)
    lo = rng.uniform(-4, 4, (n, 3))
    res_id = np.where(np.arange(n_l) % 2 == 0, live_id, -2).astype(np.int32)
    return Residual(res_id, hot, np.zeros((n_l, 8)), lo, lo + rng.uniform(0, 2, (n, 3)),
                    np.zeros(3), np.full((n, 4), -9.0, np.float32))


def held_rules(case):
    """held_row's rules for a case of pass_arguments, as object_pass makes them."""
    _, _, _, _, _, _, _, params, (shadow_of_row, max_shadowed), _, _ = case
    q = max_shadowed if (shadow_of_row >= 0).any() and max_shadowed > 0 else 0
    return (shadow_of_row, np.int64(q), params[0], params[1], params[2], params[4])


def check_held(case, kinds, packings):
    """object_pass (held objects through held_row) == object_pass on its scalar path (the
    heap's P as a strided view, which held_row does not take) in every output and state,
    bit for bit; and held_row alone, for each packing, gives each object's row of them
    or -1 with nothing written, and takes every "held" and "fading" object of 1-8 pairs,
    or of 9-16 pairs with more than 8 competing."""
    run, objs, seg, heap, live_id, state, out, params, shadow, residual, k_static = case
    strided = np.zeros(2 * heap.p.size)[::2]
    strided[:] = heap.p
    longest = int(seg[:, 1].max(initial=0))
    before = np.full((2, run.size, simd.LANES), -9, np.int32)
    want = copy.deepcopy((state, out, residual))
    object_pass(run, objs, seg, longest, PairHeap(strided, heap.light_row), live_id, want[0],
                before[0], want[1], params, shadow, want[2], k_static, (0,))
    got = copy.deepcopy((state, out, residual))
    object_pass(run, objs, seg, longest, heap, live_id, got[0], before[1], got[1], params,
                shadow, got[2], k_static, (0,))
    # Each path keeps every row's selection as it was before the pass.
    assert np.array_equal(before[0], state.selected[run])
    assert np.array_equal(before[1], state.selected[run])
    for w, g in zip(want[0] + want[1] + (want[2].residual,),
                    got[0] + got[1] + (got[2].residual,), strict=True):
        assert np.array_equal(w.view(np.uint8), g.view(np.uint8))
    assert not (got[2].residual == -9).any()
    rules = held_rules(case)
    for packing in packings:
        for o, kind in enumerate(kinds):
            n = seg[o, 1]
            if not objs[0][o] or objs[1][o] or not 1 <= n <= 2 * simd.LANES:
                continue
            mine = copy.deepcopy((state, out))
            cand = HELD[packing](o, seg[o, 0], n, tuple(heap), (live_id,), *mine, rules)
            wide = want[1][6][o] > simd.LANES
            taken = kind in ("held", "fading") and (n > simd.LANES) == wide
            assert cand >= 0 or not taken, (o, kind)
            rows = [x[o] for x in mine[0] + mine[1][:5] + mine[1][7:8]]
            if cand < 0:
                before = [x[o] for x in state + out[:5] + out[7:8]]
                assert all(np.array_equal(a, b) for a, b in zip(rows, before, strict=True))
                continue
            assert cand == want[1][6][o] and min(cand, simd.LANES) == want[1][5][o]
            assert mine[1][8][o] == want[1][8][o], (o, packing)
            wanted = [x[o] for x in want[0] + want[1][:5] + want[1][7:8]]
            for a, b in zip(rows, wanted, strict=True):
                assert np.array_equal(a.view(np.uint8), b.view(np.uint8)), (o, kind, packing)


# Every packing the target numba compiles for can run: the portable one everywhere, AVX2's
# on AVX2 and AVX-512 targets, AVX-512's on those alone.
PACKINGS = simd.PACKINGS[simd.PACKINGS.index(simd.PACKING):]
COMPILED = {packing: _compiled(packing) for packing in PACKINGS}
KERNELS = {packing: kernels[0] for packing, kernels in COMPILED.items()}
HITS = {packing: kernels[1] for packing, kernels in COMPILED.items()}
SPOTS = {packing: kernels[2] for packing, kernels in COMPILED.items()}
CANDIDATES = {packing: kernels[3] for packing, kernels in COMPILED.items()}
HELD = {packing: kernels[4] for packing, kernels in COMPILED.items()}


@st.composite
def records_and_run(draw):
    n = draw(st.integers(1, 40))
    origin = draw(st.sampled_from([0.0, 0.0, 1e7, -3e5]))
    coord = st.one_of(st.integers(-6, 6).map(float), st.floats(-30.0, 30.0, **finite))
    extent = st.one_of(st.just(0.0), st.integers(0, 4).map(float), st.floats(0.0, 20.0, **finite),
                       st.just(200.0))
    lo = np.array([[draw(coord) + origin for _ in range(3)] for _ in range(n)])
    hi = lo + np.array([[draw(extent) for _ in range(3)] for _ in range(n)])
    # Mask words as records hold them: an object's mask, or, out of view in a grid of
    # every object, its mask in the upper half (simd.SHOWN).
    masks = np.array([draw(st.sampled_from([0xFFFFFFFF, 1, 2, 6, 0, 0x80000001]))
                      << draw(st.sampled_from([0, 0, 32])) for _ in range(n)], np.uint64)
    rows = np.array(draw(st.permutations(range(n))), np.int64) * 3 + 1
    v0 = draw(st.integers(0, n))
    v1 = draw(st.integers(v0, n))
    light = (draw(coord) + origin, draw(coord) + origin, draw(coord) + origin,
             draw(st.one_of(st.floats(1e-3, 60.0, **finite), st.sampled_from([1.0, 5.0, 25.0]))),
             # -1.0: the walk of candidate lists that hold the objects out of view.
             float(draw(st.sampled_from([0xFFFFFFFF, 1, 2, 0x80000000, 0, -1]))),
             draw(st.one_of(st.just(0.0), st.floats(0.0, 100.0, **finite))),
             draw(st.one_of(st.just(0.0), st.floats(-3.0, 3.0, **finite))))
    return lo, hi, masks, rows, v0, v1, light


@examples(3.0)
@given(case=records_and_run(), start=st.integers(0, 5), slack=st.integers(0, 16))
def test_point_run_equals_the_scalar_rule(case, start, slack):
    """point_run (then point_priority) == the scalar rule: the same pairs in the same
    order, P bit for bit, nothing written before them nor past the room it is given."""
    lo, hi, masks, rows, v0, v1, light = case
    n = lo.shape[0]
    recs = np.zeros((n, 8))
    visible_objects(lo, hi, masks, np.arange(n), n, Records(recs, recs.view(np.int64), np.arange(n)),
                    np.zeros(3))
    bits = recs.view(np.int64)
    size = start + (v1 - v0) + 16
    room = start + (v1 - v0) + slack

    def sentinels():
        return np.full(size, SENTINEL_ROW, np.int32), np.full(size, SENTINEL_P)

    for scalar, kernels in ((scalar_run, KERNELS), (scalar_hits, HITS)):
        want_out = sentinels()
        if scalar is scalar_run:
            want = scalar_run(recs, bits, rows, v0, v1, light, *want_out, start)
        else:
            want = scalar_hits(recs, bits, v0, v1, light, *want_out, start)
        for packing, kernel in kernels.items():
            got_out = sentinels()
            assert kernel(recs, rows, v0, v1, light, *got_out, start, room) == want, packing
            assert same_pairs(got_out, want_out, want, room), packing


@nb.njit(nogil=True, error_model="numpy")
def scalar_spot(box, rows, hot, lf, out_obj, out_p, n0, n1):
    """The scalar rule on point_run's hits of spot row 0: walk._finish_hits (the cone,
    then P) under the contribution model."""
    return _finish_hits(hot, lf, 0, SPOT, n0, n1, box, rows, out_obj, out_p,
                        MODEL_CONTRIBUTION, 0.0, 0.0)


@st.composite
def spot_cones(draw):
    """(axis, cos o, sin o, cos inner or NaN) as pack_lights leaves light_f columns 0-5."""
    axis = np.array([draw(st.one_of(st.integers(-1, 1).map(float),
                                    st.floats(-1.0, 1.0, **finite))) for _ in range(3)])
    if not np.linalg.norm(axis) > 1e-3:
        axis = np.array([0.0, -1.0, 0.0])
    axis = axis / np.linalg.norm(axis)
    outer = draw(st.one_of(st.floats(0.01, 1.5, **finite), st.sampled_from([0.3, 0.785, 1.2])))
    inner = draw(st.one_of(st.just(outer), st.just(0.0), st.floats(0.0, outer, **finite)))
    cos_i = np.cos(inner)
    step = inner == outer or cos_i == np.cos(outer)
    return (*axis, np.cos(outer), np.sin(outer), np.nan if step else cos_i)


@examples(3.0)
@given(case=records_and_run(), cone=spot_cones(), start=st.integers(0, 5))
def test_spot_priority_equals_the_scalar_rule(case, cone, start):
    """spot_priority on point_run's hits == _finish_hits' spot branch: the same pairs kept
    (bounding sphere meets the cone), in the same order, P bit for bit; nothing written
    past the room it is given (here: the hits)."""
    lo, hi, masks, rows, v0, v1, light = case
    n = lo.shape[0]
    recs = np.zeros((n, 8))
    visible_objects(lo, hi, masks, np.arange(n), n, Records(recs, recs.view(np.int64), np.arange(n)),
                    np.zeros(3))
    hot = np.array([[*light[:5], SPOT * 8, *light[5:]]])
    lf = np.zeros((1, 8))
    lf[0, :6] = cone
    size = start + (v1 - v0) + 16
    for packing in PACKINGS:
        hits = (np.full(size, SENTINEL_ROW, np.int32), np.full(size, SENTINEL_P))
        end = HITS[packing](recs, rows, v0, v1, light, *hits, start, size)
        want = tuple(a.copy() for a in hits)
        want_end = scalar_spot(recs, rows, hot, lf, *want, start, end)
        got = tuple(a.copy() for a in hits)
        got_end = SPOTS[packing](recs, rows, light, cone, *got, start, end, end)
        assert got_end == want_end, packing
        assert same_pairs(got, want, want_end, end), packing


@pytest.mark.parametrize("packing", PACKINGS)
def test_spot_priority_on_a_cloud_around_the_cone(packing):
    """Small and large boxes all around a spot (inside, in the penumbra, outside, behind,
    on the apex), smooth and step profiles: the scalar rule's pairs and P."""
    rng = np.random.default_rng(11)
    n = 3000
    centre = rng.normal(size=(n, 3)) * 12.0
    half = rng.choice([0.0, 0.3, 2.0, 9.0], size=(n, 1)) * rng.uniform(0, 1, (n, 3))
    lo, hi = centre - half, centre + half
    recs = np.zeros((n, 8))
    visible_objects(lo, hi, np.full(n, 0xFFFFFFFF, np.uint32), np.arange(n), n,
                    Records(recs, recs.view(np.int64), np.arange(n)), np.zeros(3))
    rows = rng.permutation(n).astype(np.int64)
    light = (0.5, 0.25, -0.5, 25.0, float(0xFFFFFFFF), 40.0, 0.5)
    hot = np.array([[*light[:5], SPOT * 8, *light[5:]]])
    kept = set()
    for axis, outer, inner in [((0.0, -1.0, 0.0), 0.6, 0.3), ((0.6, 0.0, 0.8), 1.2, 1.2),
                               ((0.0, 0.0, 1.0), 0.05, 0.0), ((0.36, 0.48, 0.8), 1.5, 1.0)]:
        cos_i = np.cos(inner)
        cone = (*axis, np.cos(outer), np.sin(outer), np.nan if inner == outer else cos_i)
        lf = np.zeros((1, 8))
        lf[0, :6] = cone
        hits = (np.zeros(n, np.int32), np.zeros(n))
        end = HITS[packing](recs, rows, 0, n, light, *hits, 0, n)
        want, got = tuple(a.copy() for a in hits), tuple(a.copy() for a in hits)
        want_end = scalar_spot(recs, rows, hot, lf, *want, 0, end)
        assert SPOTS[packing](recs, rows, light, cone, *got, 0, end, n) == want_end
        assert np.array_equal(got[0][:want_end], want[0][:want_end])
        assert np.array_equal(got[1][:want_end].view(np.int64),
                              want[1][:want_end].view(np.int64))
        p_spot = (want[1][:want_end] - light[6]) / light[5]
        kept.add((want_end > 0, bool((p_spot > 0).any())))
    # Each cone kept pairs, some of them lit (s > 0).
    assert kept == {(True, True)}


@pytest.mark.parametrize("packing", PACKINGS)
def test_point_run_reads_to_the_last_record_and_no_further(packing):
    """A run ending at the last record of the array (its final step reads fewer than eight
    records) and runs of every length from 0 to 17 give the scalar rule's pairs; with a
    light that reaches every record and a room of exactly one pair per record, nothing is
    written past the room."""
    rng = np.random.default_rng(3)
    n = 37
    lo = rng.uniform(-10, 10, (n, 3))
    hi = lo + rng.uniform(0, 3, (n, 3))
    recs = np.zeros((n, 8))
    visible_objects(lo, hi, np.full(n, 0xFFFFFFFF, np.uint32), np.arange(n), n,
                    Records(recs, recs.view(np.int64), np.arange(n)), np.zeros(3))
    rows = np.arange(n, dtype=np.int64)
    light = (0.0, 0.0, 0.0, 1e4, float(0xFFFFFFFF), 1.0, 0.0)
    for v0, v1 in [(0, n), (n - 3, n), (n - 9, n)] + [(5, 5 + k) for k in range(18)]:
        for start in (0, 3):
            room = start + v1 - v0

            def sentinels():
                return np.full(n + 16, SENTINEL_ROW, np.int32), np.full(n + 16, SENTINEL_P)

            want_out, got_out = sentinels(), sentinels()
            want = scalar_run(recs, recs.view(np.int64), rows, v0, v1, light, *want_out, start)
            assert want == room  # a light reaching every record
            assert KERNELS[packing](recs, rows, v0, v1, light, *got_out, start, room) == want
            assert same_pairs(got_out, want_out, want, room)


def test_point_run_leaves_float32_records_to_the_scalar_loop():
    """"fast" precision's float32 records are not handled (-1, nothing written): the light
    pass then runs its scalar loop on them."""
    recs = np.zeros((4, 8), np.float32)
    out_obj, out_p = np.full(4, SENTINEL_ROW, np.int32), np.full(4, SENTINEL_P)
    light = (0.0, 0.0, 0.0, 10.0, float(0xFFFFFFFF), 1.0, 0.0)
    for kernel in KERNELS.values():
        assert kernel(recs, np.arange(4), 0, 4, light, out_obj, out_p, 0, 4) == -1
    assert (out_obj == SENTINEL_ROW).all() and (out_p == SENTINEL_P).all()


@nb.njit(nogil=True, error_model="numpy")
def scalar_candidates(box, o, hot, lf, compete, c_j, a, b, out_p, out_j, m):
    """candidates.scalar_candidates (candidate_pairs' scalar loop) for one object under the
    contribution model, with candidate_run's arguments."""
    return pairs_scalar(box, np.int64(box.view(np.int64)[o, 6]), o, PackedLights(hot, lf),
                        compete, c_j, a, b, PairHeap(out_p, out_j), m,
                        PairParams(MODEL_CONTRIBUTION, 0.0, 0.0))


@st.composite
def object_and_candidates(draw):
    """One object's record among a few, and point and spot lights around it (some not
    competing, some of other mask bits, some out of range), as candidate_pairs gets them."""
    origin = draw(st.sampled_from([0.0, 1e7, -3e5]))
    coord = st.one_of(st.integers(-6, 6).map(float), st.floats(-30.0, 30.0, **finite))
    extent = st.one_of(st.just(0.0), st.integers(0, 4).map(float),
                       st.floats(0.0, 20.0, **finite), st.just(200.0))
    n = draw(st.integers(1, 3))
    lo = np.array([[draw(coord) + origin for _ in range(3)] for _ in range(n)])
    hi = lo + np.array([[draw(extent) for _ in range(3)] for _ in range(n)])
    masks = np.array([draw(st.sampled_from([0xFFFFFFFF, 1, 6, 0x80000001]))
                      for _ in range(n)], np.uint32)
    n_l = draw(st.integers(1, 20))
    hot = np.zeros((n_l, 8))
    lf = np.zeros((n_l, 8))
    for j in range(n_l):
        typ = draw(st.sampled_from([POINT, POINT, SPOT]))
        hot[j] = (draw(coord) + origin, draw(coord) + origin, draw(coord) + origin,
                  draw(st.one_of(st.floats(1e-3, 60.0, **finite),
                                 st.sampled_from([1.0, 5.0, 25.0]))),
                  float(draw(st.sampled_from([0xFFFFFFFF, 1, 2, 0x80000000]))),
                  j * 32 + typ * 8, draw(st.one_of(st.just(0.0), st.floats(0.0, 100.0, **finite))),
                  draw(st.one_of(st.just(0.0), st.floats(-3.0, 3.0, **finite))))
        lf[j, :6] = draw(spot_cones())
    compete = np.array(draw(st.lists(st.booleans(), min_size=n_l, max_size=n_l)), np.bool_)
    compete |= np.array([draw(st.integers(0, 3)) > 0 for _ in range(n_l)])
    c_j = np.array(draw(st.lists(st.integers(0, n_l - 1), max_size=30)), np.int32)
    a = draw(st.integers(0, c_j.size))
    b = draw(st.integers(a, c_j.size))
    return lo, hi, masks, draw(st.integers(0, n - 1)), hot, lf, compete, c_j, a, b


@examples(3.0)
@given(case=object_and_candidates(), start=st.integers(0, 5), slack=st.integers(0, 16))
def test_candidate_run_equals_the_scalar_loop(case, start, slack):
    """candidate_run == candidate_pairs' scalar loop: the same pairs (the mask, the range
    test, the cone of a spot) in candidate order, P bit for bit, nothing written before
    them nor past the room it is given."""
    lo, hi, masks, o, hot, lf, compete, c_j, a, b = case
    n = lo.shape[0]
    recs = np.zeros((n, 8))
    visible_objects(lo, hi, masks, np.arange(n), n, Records(recs, recs.view(np.int64), np.arange(n)),
                    np.zeros(3))
    size = start + (b - a) + 16
    room = start + (b - a) + slack
    want = (np.full(size, SENTINEL_P), np.full(size, SENTINEL_ROW, np.int32))
    want_end = scalar_candidates(recs, o, hot, lf, compete, c_j, a, b, *want, start)
    for packing, kernel in CANDIDATES.items():
        got = (np.full(size, SENTINEL_P), np.full(size, SENTINEL_ROW, np.int32))
        assert kernel(recs, o, hot, lf, compete, c_j, a, b, *got, start, room) == want_end
        assert same_pairs(got, want, want_end, room), packing


@pytest.mark.parametrize("packing", PACKINGS)
def test_candidate_run_on_objects_around_spots_and_points(packing):
    """Many objects, each against every light of a mixed set of point and spot lights
    (smooth and step profiles, some not competing, some of other mask bits): the scalar
    loop's pairs and P, with pairs kept by both kinds and some spot pairs lit."""
    rng = np.random.default_rng(17)
    n, n_l = 400, 37
    centre = rng.normal(size=(n, 3)) * 12.0
    half = rng.choice([0.0, 0.3, 2.0, 9.0], size=(n, 1)) * rng.uniform(0, 1, (n, 3))
    recs = np.zeros((n, 8))
    masks = rng.choice(np.array([0xFFFFFFFF, 1, 2], np.uint32), n)
    visible_objects(centre - half, centre + half, masks, np.arange(n), n,
                    Records(recs, recs.view(np.int64), np.arange(n)), np.zeros(3))
    hot = np.zeros((n_l, 8))
    lf = np.zeros((n_l, 8))
    typ = np.where(np.arange(n_l) % 3 == 0, SPOT, POINT)
    hot[:, :3] = rng.normal(size=(n_l, 3)) * 10.0
    hot[:, 3] = rng.uniform(2.0, 30.0, n_l)
    hot[:, 4] = rng.choice([float(0xFFFFFFFF), 1.0, 2.0], n_l)
    hot[:, 5] = np.arange(n_l) * 32 + typ * 8
    hot[:, 6] = rng.uniform(1.0, 50.0, n_l)
    hot[:, 7] = rng.uniform(-1.0, 1.0, n_l)
    axis = rng.normal(size=(n_l, 3))
    lf[:, :3] = axis / np.linalg.norm(axis, axis=1, keepdims=True)
    outer = rng.uniform(0.2, 1.4, n_l)
    inner = np.where(np.arange(n_l) % 2 == 0, outer, outer * 0.5)
    lf[:, 3], lf[:, 4] = np.cos(outer), np.sin(outer)
    lf[:, 5] = np.where(inner == outer, np.nan, np.cos(inner))
    compete = rng.uniform(size=n_l) < 0.9
    c_j = rng.permutation(n_l).astype(np.int32)
    kinds = set()
    for o in range(n):
        want = (np.zeros(n_l), np.zeros(n_l, np.int32))
        got = (np.zeros(n_l), np.zeros(n_l, np.int32))
        end = scalar_candidates(recs, o, hot, lf, compete, c_j, 0, n_l, *want, 0)
        assert CANDIDATES[packing](recs, o, hot, lf, compete, c_j, 0, n_l, *got, 0, n_l) == end
        assert np.array_equal(got[0][:end].view(np.int64), want[0][:end].view(np.int64))
        assert np.array_equal(got[1][:end], want[1][:end])
        lit = set(want[1][:end][want[0][:end] - hot[want[1][:end], 7] > 0].tolist())
        reach = [j for j in range(n_l) if compete[j] and int(hot[j, 4]) & int(masks[o])
                 and box_d2(recs, o, *hot[j, :3]) <= hot[j, 3] ** 2]
        kinds |= {(int(typ[j]), j in want[1][:end], j in lit) for j in reach}
    # Lit pairs of both kinds, and spots in range whose cone misses the object.
    assert {(POINT, True, True), (SPOT, True, True), (SPOT, False, False)} <= kinds


class _Packing:
    """Kernels compiled inside take the given packing (read when an intrinsic is lowered,
    i.e. at a fresh dispatcher's first call)."""

    def __init__(self, packing: str):
        self.packing = packing

    def __enter__(self):
        self.before = simd.PACKING
        simd.PACKING = self.packing

    def __exit__(self, *exc):
        simd.PACKING = self.before


# candidate_pairs compiled afresh per packing (and record dtype), on first use.
STREAMS = {packing: nb.njit(parallel=PRANGE_ONLY, nogil=True, error_model="numpy")(
    candidate_pairs.py_func) for packing in PACKINGS}


def candidate_scene(rng, n, n_l, dtype=np.float64):
    """candidate_pairs' arguments for n objects (some out of view: no SHOWN bit in the
    record, its mask 0 or, in float64 records, in the upper half; some of zero extent, some
    large) and n_l point and spot lights round them, each object
    with a list of 0..24 distinct lights in a room with garbage after it, as
    candidates.Candidates keeps them."""
    centre = rng.normal(size=(n, 3)) * 15.0
    half = rng.choice([0.0, 0.5, 2.0, 12.0], size=(n, 1)) * rng.uniform(0, 1, (n, 3))
    masks = rng.choice(np.array([0xFFFFFFFF, 1, 2, 0], np.uint32), n, p=[0.6, 0.15, 0.15, 0.1])
    recs = np.zeros((n, 8), dtype)
    bits = recs.view(np.int32 if dtype == np.float32 else np.int64)
    visible_objects(centre - half, centre + half, masks, np.arange(n), n,
                    Records(recs, bits, np.arange(n)), np.zeros(3))
    if dtype == np.float64:
        hide = rng.uniform(size=n) < 0.15
        bits[hide, 6] = (masks[hide].astype(np.uint64) << np.uint64(32)).view(np.int64)
    hot = np.zeros((n_l, 8))
    lf = np.zeros((n_l, 8))
    typ = np.where(rng.uniform(size=n_l) < 0.3, SPOT, POINT)
    hot[:, :3] = rng.normal(size=(n_l, 3)) * 12.0
    hot[:, 3] = rng.uniform(1.0, 30.0, n_l)
    hot[:, 4] = rng.choice([float(0xFFFFFFFF), 1.0, 2.0], n_l)
    hot[:, 5] = np.arange(n_l) * 32 + typ * 8
    hot[:, 6] = rng.uniform(0.0, 50.0, n_l)
    hot[:, 7] = rng.choice([0.0, 0.5, -1.0], n_l)
    axis = rng.normal(size=(n_l, 3))
    lf[:, :3] = axis / np.linalg.norm(axis, axis=1, keepdims=True)
    outer = rng.uniform(0.2, 1.4, n_l)
    inner = np.where(rng.uniform(size=n_l) < 0.5, outer, outer * 0.5)
    lf[:, 3], lf[:, 4] = np.cos(outer), np.sin(outer)
    lf[:, 5] = np.where(inner == outer, np.nan, np.cos(inner))
    compete = rng.uniform(size=n_l) < 0.85
    lengths = np.minimum(rng.choice([0, 3, 6, 9, 17, 24], n) + rng.integers(0, 3, n), n_l)
    seg = np.zeros((n, 2), np.int64)
    c_j = []
    for o in range(n):
        seg[o] = len(c_j), lengths[o]
        c_j += rng.permutation(n_l)[:lengths[o]].tolist()
        c_j += rng.integers(0, n_l, rng.integers(0, 4)).tolist()  # the room's spare end
    c_j = np.array(c_j + [0], np.int32)
    return FoundLists(seg, c_j), RowRecords(recs, bits), PackedLights(hot, lf), compete


def check_stream(rng, n, n_l):
    """candidate_pairs (each packing) on candidate_scene(rng, n, n_l) in float64 and
    float32 records, for every row and for some rows after a used part of the heap, ==
    the scalar loop, object by object; it returns the end of the room, the pairs it wrote
    and the pairs the rows' old segments held (none when no record was in use), and given
    a heap one record short of that room, writes nothing."""
    for dtype in (np.float64, np.float32):
        cands, recs, lights, compete = candidate_scene(rng, n, n_l, dtype)
        seg, c_j = cands
        params = PairParams(MODEL_CONTRIBUTION, 0.0, 0.0)
        some = np.flatnonzero(rng.uniform(size=n) < 0.4)
        for which, used in ((np.arange(n), 0), (some, 5), (some[:0], 3)):
            room = used + int(seg[which, 1].sum())
            for packing, kernel in STREAMS.items():
                old_seg = np.stack([np.full(n, -1), rng.integers(0, 9, n)], axis=1)
                dropped = int(old_seg[which, 1].sum()) if used else 0
                out = (old_seg.copy(), np.full(room + 1, SENTINEL_P),
                       np.full(room + 1, SENTINEL_ROW, np.int32))
                args = (which, cands, recs, lights, compete, np.zeros(0, np.int64), params)
                with _Packing(packing):
                    if room > used:
                        # A heap one record short of the room: nothing written.
                        short = PairHeap(out[1][:room - 1], out[2][:room - 1])
                        assert kernel(*args, out[0], short, used) == (room, -1, dropped)
                        assert (out[0] == old_seg).all() and (out[2] == SENTINEL_ROW).all()
                    end, wrote, gone = kernel(*args, out[0], PairHeap(out[1], out[2]), used)
                assert end == room and gone == dropped
                o_seg, o_p, o_j = out
                assert wrote == o_seg[which, 1].sum()
                rest = np.setdiff1d(np.arange(n), which)
                assert (o_seg[rest] == old_seg[rest]).all()
                assert (o_j[:used] == SENTINEL_ROW).all() and o_j[room] == SENTINEL_ROW
                for r, o in enumerate(which):
                    want = (np.zeros(n_l), np.zeros(n_l, np.int32))
                    ob = np.int64(recs.bits[o, 6]) & simd.SHOWN
                    end = pairs_scalar(recs.box, ob, o, lights, compete, c_j, seg[o, 0],
                                       seg[o, 0] + (seg[o, 1] if ob else 0), PairHeap(*want), 0,
                                       params)
                    a, m = o_seg[o]
                    assert m == end, (packing, dtype, o)
                    assert np.array_equal(o_p[a:a + m].view(np.int64),
                                          want[0][:m].view(np.int64))
                    assert np.array_equal(o_j[a:a + m], want[1][:m])
                    # Within the room of its chunk of rows: the chunks run in parallel.
                    c0 = r // OBJECT_CHUNK * OBJECT_CHUNK
                    c1 = min(which.size, c0 + OBJECT_CHUNK)
                    assert (used + seg[which[:c0], 1].sum() <= a
                            and a + m <= used + seg[which[:c1], 1].sum())


@examples(1.0)
@given(seed=st.integers(0, 2**32 - 1), n=st.sampled_from([1, 7, OBJECT_CHUNK, 600]),
       n_l=st.integers(1, 40))
def test_candidate_pairs_stream_equals_the_scalar_loop(seed, n, n_l):
    """candidate_pairs' stream (whole chunks of objects, eight candidates of any objects a
    step, the spots' cones after them, the pairs packed per chunk) gives each object the
    scalar loop's pairs in candidate order, P bit for bit, within its chunk's room; and
    with float32 records ("fast") the per-object loop gives them too."""
    check_stream(np.random.default_rng(seed), n, n_l)


def test_candidate_run_leaves_float32_records_to_the_scalar_loop():
    """"fast" precision's float32 records: -1 and nothing written."""
    out_p, out_j = np.full(4, SENTINEL_P), np.full(4, SENTINEL_ROW, np.int32)
    hot = np.zeros((1, 8))

    @nb.njit(nogil=True, error_model="numpy")
    def run(box):
        return simd.candidate_run(box, 0, hot, hot, np.ones(1, np.bool_),
                                  np.zeros(4, np.int32), 0, 4, out_p, out_j, 0, 4)

    assert run(np.zeros((1, 8), np.float32)) == -1
    assert (out_j == SENTINEL_ROW).all() and (out_p == SENTINEL_P).all()


@examples(3.0)
@given(kinds=st.lists(st.sampled_from(HELD_KINDS), min_size=1, max_size=12),
       n_l=st.integers(1, 24), max_shadowed=st.integers(0, 3), ties=st.booleans(),
       fade_in=st.sampled_from([0.2, 0.0]), seed=st.integers(0, 2**32 - 1))
def test_held_row_equals_the_scalar_path(kinds, n_l, max_shadowed, ties, fade_in, seed):
    """held_row inside object_pass and alone: the scalar path's outputs and state bit for
    bit (check_held), on objects held in order, reordered, outranked, fading in, of other
    slots, reset and hidden, with ties of P, maps on some lights, fades at once or not."""
    case = held_case(np.random.default_rng(seed), kinds, n_l, max_shadowed, ties, fade_in)
    check_held(case, kinds, PACKINGS)


def test_held_row_takes_the_held_objects_of_a_crowd():
    """A few hundred objects of every kind around 40 lights: held_row takes every held
    object (check_held), and the others go to the scalar path with the same result."""
    rng = np.random.default_rng(23)
    kinds = list(rng.choice(HELD_KINDS, 300))
    case = held_case(rng, kinds, 40, 2, False)
    check_held(case, kinds, PACKINGS)
    # The residual of held objects (their rows written after held_row) is among what
    # check_held compared: some have lights past K or fading slots, and so a residual.
    args = copy.deepcopy(case)
    object_pass(*args[:3], int(args[2][:, 1].max()), *args[3:6],
                np.empty((args[0].size, simd.LANES), np.int32), *args[6:], (0,))
    held = np.array([kind in ("held", "fading") for kind in kinds]) & (case[2][:, 1] <= 16)
    assert (args[9].residual[held, 0] > 0).sum() >= 10
    seg = case[2]
    taken = [HELD[PACKINGS[-1]](o, seg[o, 0], seg[o, 1], tuple(case[3]), (case[4],),
                                *copy.deepcopy((case[5], case[6])), held_rules(case))
             for o in range(len(kinds)) if 1 <= seg[o, 1] <= 2 * simd.LANES]
    held = [cand for cand in taken if cand >= 0]
    assert 70 < len(held) < len(taken)
    assert sum(cand > simd.LANES for cand in held) > 20


def test_held_row_keeps_the_selection_by_key():
    """Two old slots whose P differ by an ulp and whose hysteresis keys round to one
    value, the lower P on the lower id: output order (by P) keeps them as they were, the
    selection (by key, ties to the lower id) swaps them, so the selection row is not last
    frame's slots and held_row leaves the object to the scalar path."""
    h, h_abs = 0.1, 0.05
    p1 = 1.9
    while True:
        p2 = np.nextafter(p1, 0.0)
        if p1 + h * abs(p1) + h_abs == p2 + h * abs(p2) + h_abs:
            break
        p1 = np.nextafter(p1, 2.0)
    ids = np.array([10, 11, 12, 13, 14, 15, 21, 20, 30], np.int32)
    p = np.array([6.0, 5.5, 5.0, 4.5, 4.0, 3.5, p1, p2, 0.5])
    rows = np.arange(9, dtype=np.int32)
    old = ids[:8].copy()
    objects = [("held", p, rows, old, np.full(8, ON), old[::-1].copy())]
    rng = np.random.default_rng(3)
    case = pass_arguments(rng, objects, live_ids(ids, np.ones(9, np.bool_)),
                          np.full(9, -1, np.int8), 0)
    check_held(case, ["keys tie"], PACKINGS)
    assert HELD[PACKINGS[-1]](0, case[2][0, 0], 9, tuple(case[3]), (case[4],),
                              *copy.deepcopy((case[5], case[6])), held_rules(case)) == -1


WITHOUT_AVX512 = """
import numpy as np
import lightsched.simd as simd
from lightsched.grid import Records, visible_objects
from test_simd import CANDIDATES, KERNELS, scalar_candidates, scalar_run
import sys
packing = sys.argv[1]
assert simd.PACKING == packing and list(KERNELS) == list(simd.PACKINGS[simd.PACKINGS.index(packing):])
for kernels in (KERNELS, CANDIDATES):
    asm = "".join(kernels[packing].inspect_asm().values())
    assert "zmm" not in asm
    assert ("vpermps" in asm) == (packing == "avx2"), packing
    assert ("ymm" in asm) == (packing == "avx2"), packing
rng = np.random.default_rng(5)
n = 200
lo = rng.uniform(-20, 20, (n, 3))
hi = lo + rng.uniform(0, 6, (n, 3))
recs = np.zeros((n, 8))
visible_objects(lo, hi, rng.integers(0, 4, n).astype(np.uint32), np.arange(n), n,
                Records(recs, recs.view(np.int64), np.arange(n)), np.zeros(3))
rows = rng.permutation(n).astype(np.int64)
for _ in range(300):
    v0 = int(rng.integers(0, n)); v1 = int(rng.integers(v0, n + 1))
    light = (*rng.uniform(-20, 20, 3), float(rng.uniform(0.5, 15)), float(rng.integers(1, 4)),
             float(rng.uniform(0, 10)), 0.0)
    want = (np.full(n + 8, -7, np.int32), np.full(n + 8, -1.0))
    k = scalar_run(recs, recs.view(np.int64), rows, v0, v1, light, *want, 3)
    for kernel in KERNELS.values():
        got = (np.full(n + 8, -7, np.int32), np.full(n + 8, -1.0))
        assert kernel(recs, rows, v0, v1, light, *got, 3, n + 8) == k
        assert np.array_equal(got[0][:k], want[0][:k]) and np.array_equal(got[1][:k], want[1][:k])
n_l = 40
hot = np.zeros((n_l, 8))
hot[:, :3] = rng.uniform(-20, 20, (n_l, 3))
hot[:, 3] = rng.uniform(1, 15, n_l)
hot[:, 4] = rng.integers(1, 4, n_l)
hot[:, 5] = np.arange(n_l) * 32 + (np.arange(n_l) % 3 == 0) * 8
hot[:, 6] = rng.uniform(0, 10, n_l)
lf = np.zeros((n_l, 8))
lf[:, 1], lf[:, 3], lf[:, 4], lf[:, 5] = -1.0, np.cos(0.8), np.sin(0.8), np.cos(0.4)
compete = rng.uniform(size=n_l) < 0.9
c_j = rng.permutation(n_l).astype(np.int32)
for o in range(n):
    want = (np.zeros(n_l), np.zeros(n_l, np.int32))
    k = scalar_candidates(recs, o, hot, lf, compete, c_j, 0, n_l, *want, 0)
    for kernel in CANDIDATES.values():
        got = (np.zeros(n_l), np.zeros(n_l, np.int32))
        assert kernel(recs, o, hot, lf, compete, c_j, 0, n_l, *got, 0, n_l) == k
        assert np.array_equal(got[0][:k], want[0][:k]) and np.array_equal(got[1][:k], want[1][:k])
from test_simd import check_stream
check_stream(np.random.default_rng(11), 600, 40)
from test_simd import HELD, HELD_KINDS, check_held, held_case
assert "zmm" not in "".join(HELD[packing].inspect_asm().values())
rng = np.random.default_rng(7)
kinds = list(rng.choice(HELD_KINDS, 200))
check_held(held_case(rng, kinds, 30, 2, False), kinds, list(HELD))
print("ok")
"""


@pytest.mark.slow  # compiles the kernels again, into an empty cache
@pytest.mark.skipif(platform.machine() not in ("x86_64", "AMD64"),
                    reason="numba forces x86 targets on x86 hosts only")
@pytest.mark.parametrize("target,packing", [("avx2", "avx2"), ("x86-64", "portable")])
def test_the_kernels_compile_and_agree_on_a_target_without_avx512(tmp_path, target, packing):
    """Numba compiling for a CPU without AVX-512 (an AVX2 Haswell; x86-64 without AVX)
    takes that target's packing, emits no 512-bit code (nor 256-bit without AVX), and
    with every packing it can run gives the scalar rule's pairs (point_run, candidate_run
    and candidate_pairs' stream) and the scalar path's slots (held_row, inside object_pass
    and alone)."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    cpu, features = simd.FORCED_TARGETS[target]
    env = dict(os.environ, NUMBA_CPU_NAME=cpu, NUMBA_CPU_FEATURES=features,
               NUMBA_CACHE_DIR=str(tmp_path), PYTHONPATH=str(Path(__file__).parent))
    done = subprocess.run([sys.executable, "-c", WITHOUT_AVX512, packing], env=env,
                          capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, done.stderr[-3000:]
    assert done.stdout.strip().endswith("ok")
