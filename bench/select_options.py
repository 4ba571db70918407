"""The ways to choose K among many competing lights (issue 49, item 2), measured on the same
pools: the time per object of top-K with hysteresis for 16 to 400 lights an object.

    python bench/select_options.py                    # K = 8, every method and size
    python bench/select_options.py --sizes 33 --objects 50000

The pools are synthetic and steady, as in a scene whose lights move a little a frame:
P = intensity x falloff (uniform intensity, squared uniform falloff); last frame's
selection is the top K of P perturbed by 1%, so most of it is still selected and a few
lights swap. Every method gets the same keys (P, raised for last frame's selection) except
``bound + rank`` (select.top_k, what the object pass runs), which keys its pool itself.
The methods:

- insertion: select.topk_insert a light (K compares, a branch that mispredicts);
- heap: a bounded min-heap of the K best (a compare a light, a sift when it enters);
- network: blocks of 8 sorted by a sorting network of branch-free compare-exchanges
  (unrolled) and merged into the best 8 by a bitonic merge (K = 8 only);
- rank all: every light's place counted against every other (n^2 compares, vector code);
- bound + rank: select.top_k: last frame's selection bounds the K-th key; only the lights
  at or above it are ranked by counting.

Every method's choice is checked equal to a sort's. One process, methods interleaved per
round; the median of the rounds. Prints a table of ns per object and ns per light.
"""

from __future__ import annotations

import argparse
import sys
import time

import numba as nb
import numpy as np
from common import machine, say

from lightsched.select import (
    CF_P,
    CF_ROWS,
    CI_ID,
    CI_ROW,
    CI_ROWS,
    F_ROWS,
    I_ID,
    I_ROWS,
    raised_key,
    ranks_before,
    top_k,
    topk_insert,
)

H, H_ABS = 0.1, 0.0  # Config's default hysteresis


def make_pools(n: int, k: int, count: int, seed: int) -> tuple[np.ndarray, ...]:
    """count pools of n lights: P [count, n], ids [count, n] (unique in a pool), last
    frame's selection [count, k], and the keys (P raised for that selection)."""
    rng = np.random.default_rng(seed)
    p = rng.uniform(1.0, 100.0, (count, n)) * rng.uniform(0.0, 1.0, (count, n)) ** 2
    ids = np.argsort(rng.random((count, n)), axis=1).astype(np.int64) * 7 + 3
    noisy = p * (1.0 + 0.01 * rng.standard_normal((count, n)))
    best = np.argsort(-noisy, axis=1, kind="stable")[:, :k]
    selected = np.take_along_axis(ids, best, axis=1).astype(np.int32)
    was = np.zeros((count, n), np.bool_)
    np.put_along_axis(was, best, True, axis=1)
    keys = np.where(was, p + H * np.abs(p) + H_ABS, p)
    return p, ids, selected, keys


@nb.njit(cache=True)
def by_insertion(keys, ids, p, k, out):
    sf = np.empty((F_ROWS, k))
    si = np.empty((I_ROWS, k), np.int64)
    for o in range(keys.shape[0]):
        nbest = 0
        for t in range(keys.shape[1]):
            nbest = topk_insert(sf, si, nbest, keys[o, t], ids[o, t], p[o, t], t)
        out[o, :] = si[I_ID, :]


@nb.njit(cache=True)
def by_heap(keys, ids, p, k, out):
    hk = np.empty(k)
    hi = np.empty(k, np.int64)
    for o in range(keys.shape[0]):
        size = 0
        for t in range(keys.shape[1]):
            key, lid = keys[o, t], ids[o, t]
            if size < k:
                # Sift up: the root is the lowest-ranked of the heap.
                c = size
                size += 1
                while c > 0 and ranks_before(hk[(c - 1) // 2], hi[(c - 1) // 2], key, lid):
                    hk[c], hi[c] = hk[(c - 1) // 2], hi[(c - 1) // 2]
                    c = (c - 1) // 2
                hk[c], hi[c] = key, lid
            elif ranks_before(key, lid, hk[0], hi[0]):
                c = 0
                while True:
                    child = 2 * c + 1
                    if child >= k:
                        break
                    if child + 1 < k and ranks_before(hk[child], hi[child], hk[child + 1],
                                                      hi[child + 1]):
                        child += 1
                    if not ranks_before(key, lid, hk[child], hi[child]):
                        break
                    hk[c], hi[c] = hk[child], hi[child]
                    c = child
                hk[c], hi[c] = key, lid
        # The heap's K in key order (an insertion sort of K).
        for a in range(1, k):
            key, lid = hk[a], hi[a]
            b = a
            while b > 0 and ranks_before(key, lid, hk[b - 1], hi[b - 1]):
                hk[b], hi[b] = hk[b - 1], hi[b - 1]
                b -= 1
            hk[b], hi[b] = key, lid
        out[o, :] = hi


# Batcher's odd-even merge sort of 8, and the bitonic sort of a bitonic 8.
SORT8 = ((0, 1), (2, 3), (4, 5), (6, 7), (0, 2), (1, 3), (4, 6), (5, 7), (1, 2), (5, 6),
         (0, 4), (1, 5), (2, 6), (3, 7), (2, 4), (3, 5), (1, 2), (3, 4), (5, 6))
BITONIC8 = ((0, 4), (1, 5), (2, 6), (3, 7), (0, 2), (1, 3), (4, 6), (5, 7), (0, 1), (2, 3),
            (4, 5), (6, 7))


@nb.njit(cache=True, inline="always")
def _exchange(vk, vi, a, b):
    """Puts the higher-ranked of places a, b first, with selects, not a branch."""
    ka, ia, kb, ib = vk[a], vi[a], vk[b], vi[b]
    first = ranks_before(ka, ia, kb, ib)
    vk[a], vi[a] = (ka if first else kb), (ia if first else ib)
    vk[b], vi[b] = (kb if first else ka), (ib if first else ia)


@nb.njit(cache=True)
def by_network(keys, ids, p, k, out):
    tk = np.empty(8)
    ti = np.empty(8, np.int64)
    bk = np.empty(8)
    bi = np.empty(8, np.int64)
    for o in range(keys.shape[0]):
        n = keys.shape[1]
        tk[:] = -np.inf
        ti[:] = np.iinfo(np.int64).max
        for start in range(0, n, 8):
            for m in range(8):
                t = start + m
                bk[m] = keys[o, t] if t < n else -np.inf
                bi[m] = ids[o, t] if t < n else np.iinfo(np.int64).max
            for pair in nb.literal_unroll(SORT8):
                _exchange(bk, bi, pair[0], pair[1])
            # The best 8 of two sorted 8: pairwise the better of top[m] and block[7 - m]
            # (a bitonic sequence), sorted by the bitonic network.
            for m in range(8):
                first = ranks_before(tk[m], ti[m], bk[7 - m], bi[7 - m])
                tk[m], ti[m] = ((tk[m] if first else bk[7 - m]),
                                (ti[m] if first else bi[7 - m]))
            for pair in nb.literal_unroll(BITONIC8):
                _exchange(tk, ti, pair[0], pair[1])
        out[o, :] = ti


@nb.njit(cache=True)
def by_rank_all(keys, ids, p, k, out):
    for o in range(keys.shape[0]):
        n = keys.shape[1]
        for u in range(n):
            place = 0
            for v in range(n):
                place += ranks_before(keys[o, v], ids[o, v], keys[o, u], ids[o, u])
            if place < k:
                out[o, place] = ids[o, u]


@nb.njit(cache=True)
def by_bound_and_rank(p, ids, selected, out):
    n, k = p.shape[1], selected.shape[1]
    cf = np.empty((CF_ROWS, n))
    ci = np.empty((CI_ROWS, n), np.int64)
    sf = np.empty((F_ROWS, k))
    si = np.empty((I_ROWS, k), np.int64)
    for o in range(p.shape[0]):
        for t in range(n):
            cf[CF_P, t] = p[o, t]
            ci[CI_ID, t] = ids[o, t]
            ci[CI_ROW, t] = t
        top_k(cf, ci, n, selected, o, sf, si, H, H_ABS)
        out[o, :] = si[I_ID, :]


METHODS = ("insertion", "heap", "network", "rank all", "bound + rank")


def run(method: str, pools: tuple[np.ndarray, ...], out: np.ndarray) -> float:
    p, ids, selected, keys = pools
    k = selected.shape[1]
    t0 = time.perf_counter()
    if method == "insertion":
        by_insertion(keys, ids, p, k, out)
    elif method == "heap":
        by_heap(keys, ids, p, k, out)
    elif method == "network":
        by_network(keys, ids, p, k, out)
    elif method == "rank all":
        by_rank_all(keys, ids, p, k, out)
    else:
        by_bound_and_rank(p, ids, selected, out)
    return time.perf_counter() - t0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sizes", type=lambda t: [int(x) for x in t.split(",")],
                    default=[16, 33, 64, 100, 400], help="competing lights an object")
    ap.add_argument("--k", type=int, default=8)
    ap.add_argument("--objects", type=int, default=20000, help="pools a size")
    ap.add_argument("--rounds", type=int, default=7)
    a = ap.parse_args(argv)
    assert raised_key(1.0, H, H_ABS) == 1.0 + H * 1.0 + H_ABS
    methods = [m for m in METHODS if m != "network" or a.k == 8]
    m_info = machine()
    say(f"{m_info['cpu']}, one thread; K = {a.k}, {a.objects} pools a size, median of "
        f"{a.rounds} rounds (ns per object, and per light)")
    say("| lights an object | " + " | ".join(methods) + " |")
    say("|---" * (len(methods) + 1) + "|")
    for n in a.sizes:
        pools = make_pools(n, a.k, a.objects, seed=n)
        p, ids, selected, keys = pools
        want = np.take_along_axis(ids, np.lexsort((ids, -keys), axis=1)[:, :a.k], axis=1)
        times: dict[str, list[float]] = {m: [] for m in methods}
        for r in range(a.rounds + 1):  # round 0 compiles
            for m in methods:
                out = np.full((a.objects, a.k), -1, np.int64)
                t = run(m, pools, out)
                if r == 0 and not np.array_equal(out, want):
                    raise SystemExit(f"{m} chose other lights than the rule at n = {n}")
                if r:
                    times[m].append(t)
        cells = []
        for m in methods:
            ns = float(np.median(times[m])) / a.objects * 1e9
            cells.append(f"{ns:.0f} ({ns / n:.1f})")
        say(f"| {n} | " + " | ".join(cells) + " |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
