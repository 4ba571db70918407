"""Probe: a frame's pairs from per-object candidate lists kept with a skin, against the light
pass and the grouping that make them now (RESULTS "Next", candidate lists).

    python bench/candidates_probe.py --size 100k:10k --skins 0,1,2 --reps 15

A light's candidates are the objects within its radius plus a skin; while the light stays
within the skin of where the lists were made, they hold every object it can affect, so a
frame needs no grid walk and no grouping, only the exact test (DESIGN "Affects") and P of
each candidate (as molecular dynamics keeps Verlet neighbour lists, and Box2D's broad
phase its fat AABBs). This measures that per-frame part, and of the lists' upkeep the
walk of the lights that leave their skin in a frame (not the edits of the object lists).
On the captured inputs of a full frame of city(N, N/10) (every light moving), caches
flushed before each call, variants interleaved call by call:

- ``light pass + grouping``: walk.light_bounds, light_pass, group_pairs, as a frame runs
  them;
- ``candidates by object row``: the lists per object row, objects walked in row order
  (each object's record is then read at a random grid position); ``records by row``: the
  same with the records copied into row order (the grid is no longer needed to find
  pairs, only to make the lists);
- ``candidates by position``: the lists laid out by grid position and walked in that
  order (every stream sequential but the lights); its pairs come out in position order,
  which the object pass would have to read or write at random rows;
- ``... range test only``: the same without P, the share P takes.

Every variant's pairs are checked equal, bit for bit, to the light pass's (as sets per
object: the order within an object does not matter). Prints medians (ms) and each
variant's median ratio to the light pass + grouping in the same round.
"""

from __future__ import annotations

import argparse
import sys
import time
from functools import partial

import numba as nb
import numpy as np
from common import parse_sizes, say
from kernel_profile import capture, fresh

from lightsched.group import PairHeap, group_pairs
from lightsched.jit import GROUP_PARTS
from lightsched.priority import box_d2, record_pair_p
from lightsched.scene import DIRECTIONAL
from lightsched.walk import LightPairs, light_bounds, light_pass


@nb.njit(nogil=True, inline="always", error_model="numpy")
def _candidate_pairs(v, a, b, cand, lights, recs, out, m, params):
    """The pairs of the object at grid position v among its candidate lights cand[a:b]:
    the exact Affects test and P (priority.record_pair_p), appended to out = (P, light row) at m
    (range test only when params[3] is 0). Returns the new m."""
    hot, lf = lights
    vis_box, vis_bits = recs
    out_p, out_j = out
    model, w_obj, w_int, with_p = int(params[0]), params[1], params[2], params[3] != 0
    bits = np.int64(vis_bits[v, 6])
    for t in range(a, b):
        j = np.int64(cand[t])
        if bits & np.int64(hot[j, 4]) == 0:
            continue
        typ = (np.int64(hot[j, 5]) >> 3) & 3
        if typ == DIRECTIONAL:
            out_p[m] = hot[j, 6] + hot[j, 7]
            out_j[m] = j
            m += 1
            continue
        d2 = box_d2(vis_box, v, hot[j, 0], hot[j, 1], hot[j, 2])
        if d2 <= hot[j, 3] * hot[j, 3]:
            hit, p = record_pair_p(hot, lf, j, typ, v, d2, vis_box, model, w_obj, w_int) \
                if with_p else (True, d2)
            if hit:
                out_p[m] = p
                out_j[m] = j
                m += 1
    return m


@nb.njit(nogil=True, parallel=True, error_model="numpy")
def by_row(cand_start, cand, pos_of, lights, recs, out, out_n, params):
    """Candidates per object row, objects in row order (parallel in chunks of 256)."""
    n = pos_of.shape[0]
    for ch in nb.prange((n + 255) // 256):
        for o in range(ch * 256, min(n, ch * 256 + 256)):
            m = cand_start[o]
            if pos_of[o] >= 0:
                m = _candidate_pairs(pos_of[o], cand_start[o], cand_start[o + 1], cand,
                                     lights, recs, out, m, params)
            out_n[o] = m - cand_start[o]


@nb.njit(nogil=True, parallel=True, error_model="numpy")
def by_position(cand_start, cand, lights, recs, out, out_n, params):
    """Candidates per grid position, positions in order (parallel in chunks of 256)."""
    n = cand_start.shape[0] - 1
    for ch in nb.prange((n + 255) // 256):
        for v in range(ch * 256, min(n, ch * 256 + 256)):
            m = _candidate_pairs(v, cand_start[v], cand_start[v + 1], cand, lights, recs, out,
                                 cand_start[v], params)
            out_n[v] = m - cand_start[v]


def light_major(lights, rows, grid, vis, params, n_obj):
    """The frame's way: (start [N+1], P, light row) grouped by object row."""
    off = light_bounds(lights[0], rows, grid, vis[0].shape[0])
    pair_obj = np.empty(int(off[-1]), np.int32)
    pair_p = np.empty(int(off[-1]))
    count = light_pass(lights, rows, grid, vis, off, pair_obj, pair_p, params)
    h = int(count.sum())
    start = np.empty(n_obj + 1, np.int64)
    heap = PairHeap.empty(h)
    hist = np.empty((GROUP_PARTS, n_obj + 1), np.int32)
    group_pairs(LightPairs(rows, off, count, pair_obj, pair_p), hist, start, heap)
    return start, heap.p, heap.light_row


def triples(obj_of_slot, p, j):
    """(object, light row, P) sorted: a set of pairs to compare bit for bit."""
    order = np.lexsort((p, j, obj_of_slot))
    return obj_of_slot[order], j[order], p[order].view(np.int64)


def same_pairs(start, n, row_of, out, want, what):
    """Asserts that the pairs a variant left in ``out`` (the first n[i] of each segment
    start[i]; segment i is object row_of[i], or i) are ``want`` bit for bit."""
    idx, seg = segments(start, n)
    got = triples(seg if row_of is None else row_of[seg], out[0][idx], out[1][idx])
    assert all(np.array_equal(a, b) for a, b in zip(got, want, strict=True)), \
        f"{what}: other pairs than the light pass"


def segments(start, n):
    """Indices of the first n[i] entries of each segment start[i].. and their segment."""
    seg = np.repeat(np.arange(n.size), n)
    first = np.repeat(start[:-1] if start.size > n.size else start, n)
    return first + (np.arange(seg.size) - np.repeat(np.cumsum(n) - n, n)), seg


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--size", default="100k:10k", help="N:L of the city")
    ap.add_argument("--skins", default="0,1,2", help="skins in metres, comma-separated")
    ap.add_argument("--reps", type=int, default=15, help="rounds of calls")
    args = ap.parse_args(argv)
    (n, n_l), = parse_sizes(args.size)
    _, (lights, rows, grid, vis, _, _, _, params) = capture("light_pass", n, n_l, 6)
    _, gp = capture("group_pairs", n, n_l, 6)
    n_obj = gp[5][1].shape[0] - 1
    hot, lf = lights
    vis_box, vis_bits, vis_rows = vis
    pos_of = np.full(n_obj, -1, np.int64)
    pos_of[vis_rows] = np.arange(vis_rows.size)
    recs = (vis_box, vis_bits)
    # The same records by object row (an object outside the grid: mask 0, no pair).
    row_box = vis_box[np.maximum(pos_of, 0)]
    row_box.view(vis_bits.dtype)[pos_of < 0, 6] = 0
    row_recs = (row_box, row_box.view(vis_bits.dtype))
    row_of = np.where(pos_of >= 0, np.arange(n_obj), -1)
    start, heap_p, heap_j = light_major(lights, rows, grid, vis, params, n_obj)
    want = triples(np.repeat(np.arange(n_obj), np.diff(start)), heap_p, heap_j)
    say(f"city({n}, {n_l}): {heap_p.size} pairs, {vis_rows.size} objects in the grid")

    variants = {"light pass + grouping": lambda: light_major(lights, rows, grid, vis, params,
                                                              n_obj)}
    for skin in (float(s) for s in args.skins.split(",")):
        # The candidate lists: the light pass with every radius widened by the skin (the
        # cone of a spot is kept as is: a probe of the per-frame cost, not of the upkeep).
        wide = hot.copy()
        wide[:, 3] += skin
        c_start, _, cand = light_major((wide, lf), rows, grid, vis, params, n_obj)
        lens = np.diff(c_start)[vis_rows]
        p_start = np.concatenate([[0], np.cumsum(lens)])
        p_cand = cand[segments(c_start[vis_rows], lens)[0]]
        say(f"skin {skin:g} m: {cand.size} candidates ({cand.size / heap_p.size:.2f} per pair)")
        out = (np.empty(cand.size), np.empty(cand.size, np.int32))
        out_row, out_pos = np.empty(n_obj, np.int64), np.empty(vis_rows.size, np.int64)
        for with_p in (1.0, 0.0):
            prm = np.array([params[0], params[1], params[2], with_p])
            by_row(c_start, cand, pos_of, lights, recs, out, out_row, prm)
            if with_p:
                same_pairs(c_start, out_row, None, out, want, "by object row")
            by_position(p_start, p_cand, lights, recs, out, out_pos, prm)
            if with_p:
                same_pairs(p_start, out_pos, vis_rows, out, want, "by position")
            tag = f"skin {skin:g} m" + ("" if with_p else ", range test only")
            by_row(c_start, cand, row_of, lights, row_recs, out, out_row, prm)
            if with_p:
                same_pairs(c_start, out_row, None, out, want, "by object row, records by row")
                variants[f"candidates by object row, {tag}"] = (
                    lambda c_start=c_start, cand=cand, out=out, o=out_row, prm=prm:
                    by_row(c_start, cand, pos_of, lights, recs, out, o, prm))
            variants[f"candidates by object row, records by row, {tag}"] = (
                lambda c_start=c_start, cand=cand, out=out, o=out_row, prm=prm:
                by_row(c_start, cand, row_of, lights, row_recs, out, o, prm))
            variants[f"candidates by position, {tag}"] = (
                lambda p_start=p_start, p_cand=p_cand, out=out, o=out_pos, prm=prm:
                by_position(p_start, p_cand, lights, recs, out, o, prm))
        if skin > 0:
            # The lists' upkeep, in part: the lights that leave their skin in a frame walk
            # the grid again (at 3 m/s and 60 Hz, 0.05 m / skin of them; the edits of the
            # object lists they enter and leave are not measured).
            leaving = np.sort(np.random.default_rng(0).choice(
                rows.size, max(1, round(rows.size * 0.05 / skin)), replace=False))
            variants[f"walk of the {leaving.size} lights leaving a {skin:g} m skin"] = (
                lambda w=wide, r=rows[leaving]: light_major((w, lf), r, grid, vis, params,
                                                            n_obj))
    say("every variant's pairs equal the light pass's, bit for bit")

    report(variants, args.reps, "light pass + grouping")

    # The consumer: pairs made by position come out in position order. The object pass as
    # a frame runs it (rows in row order, lists by row), against rows walked in position
    # order with their lists laid out in that order (the heap then streams, and the
    # per-row state and outputs are read and written at random rows).
    kern, op = capture("object_pass", n, n_l, 6)
    run, objs, (seg, (hp, hj)), *rest = op
    order = vis_rows.astype(run.dtype)
    lens = seg[order, 1]
    idx = segments(seg[order, 0], lens)[0]
    seg_pos = seg.copy()
    seg_pos[order, 0] = np.cumsum(lens) - lens
    by_pos = (order, objs, (seg_pos, (hp[idx], hj[idx])), *rest)
    report({"object pass, rows and lists in row order": lambda: partial(kern, *fresh(op)),
            "object pass, rows and lists in position order":
                lambda: partial(kern, *fresh(by_pos))},
           args.reps, "object pass, rows and lists in row order", prepare=True)
    return 0


def report(variants: dict, reps: int, base_name: str, prepare: bool = False) -> None:
    """Medians of the variants called in turn ``reps`` times, caches flushed before each
    call, and each one's median ratio to ``base_name``. With ``prepare``, a variant returns
    its call (its inputs copied first, outside the time)."""
    times: dict[str, list[float]] = {name: [] for name in variants}
    flush = np.ones(8_000_000)
    for _ in range(reps):
        for name, call in variants.items():
            if prepare:
                call = call()
            flush += 1.0  # 64 MB written: the inputs leave the caches, as in a frame
            t = time.perf_counter()
            call()
            times[name].append((time.perf_counter() - t) * 1e3)
    base = np.array(times[base_name])
    say(f"{'variant':<68} {'ms':>7} {'ratio':>6}")
    for name, ts in times.items():
        say(f"{name:<68} {np.median(ts):7.2f} {np.median(np.array(ts) / base):6.2f}")


if __name__ == "__main__":
    sys.exit(main())
