"""select.top_k (the selection among more competing lights than K: marks, keys, the bound
from last frame's selection, ranking by counts or, past RANK_COUNT_MAX kept lights, by
insertion) == the rule of DESIGN section 2, "Selection", written here as a sort: the K of
highest key, ties to the lower id, key = P or P + h|P| + h_abs for last frame's selected
lights. Pools with and without the bound (all of last frame's selection competing or not),
few and many lights, and many ties. select.gather_few (an object's few pairs gathered and
its old slots matched in one pass) == gather_live then match_old_slots."""

from __future__ import annotations

import numba as nb
import numpy as np
from helpers import examples
from hypothesis import given
from hypothesis import strategies as st

from lightsched.select import (
    CF_P,
    CF_ROWS,
    CI_ID,
    CI_ROW,
    CI_ROWS,
    F_OLD_P,
    F_P,
    F_ROWS,
    I_ID,
    I_OLD_ID,
    I_OLD_ROW,
    I_ROW,
    I_ROWS,
    RANK_COUNT_MAX,
    gather_few,
    gather_live,
    match_old_slots,
    top_k,
)

# Few distinct values, so ties (and -0.0 against 0.0) are common.
priority = st.one_of(st.sampled_from([0.0, -0.0, 1.0, 2.5, 3.0]),
                     st.floats(0.0, 1e6, allow_nan=False))


# Not cached: numba keys a cache on this file only, and top_k is inlined from select.py.
@nb.njit
def _top_k(p, ids, rows, selected, h, h_abs):
    k = selected.shape[1]
    n = p.size
    cf = np.full((CF_ROWS, n), np.nan)
    ci = np.full((CI_ROWS, n), -9, np.int64)
    cf[CF_P, :] = p
    ci[CI_ID, :] = ids
    ci[CI_ROW, :] = rows
    sf = np.full((F_ROWS, k), np.nan)
    si = np.full((I_ROWS, k), -9, np.int64)
    got = top_k(cf, ci, n, selected, 0, sf, si, h, h_abs)
    return got, sf[F_P].copy(), si[I_ID].copy(), si[I_ROW].copy()


@st.composite
def pools(draw):
    k = draw(st.sampled_from([1, 2, 4, 8]))
    n = draw(st.one_of(st.integers(k + 1, 3 * k + 2),
                       st.integers(RANK_COUNT_MAX - 2, RANK_COUNT_MAX + 40)))
    ids = draw(st.lists(st.integers(0, 10 * n), min_size=n, max_size=n, unique=True))
    p = draw(st.lists(priority, min_size=n, max_size=n))
    # Last frame's selection: K of the pool (the bound holds), fewer, or lights gone.
    kind = draw(st.sampled_from(["all", "fewer", "gone"]))
    chosen = draw(st.permutations(ids))[:k]
    if kind == "fewer":
        chosen = chosen[:draw(st.integers(0, k - 1))]
    elif kind == "gone":
        chosen = chosen[:-1] + [10 * n + 1]
    selected = np.full((1, k), -1, np.int32)
    selected[0, :len(chosen)] = chosen
    h = draw(st.sampled_from([0.0, 0.1, 0.5]))
    h_abs = draw(st.sampled_from([0.0, 0.5, 1.0]))
    return np.array(p), np.array(ids, np.int64), np.arange(n, dtype=np.int64) * 3 + 1, \
        selected, h, h_abs


@examples(4.0)
@given(case=pools())
def test_top_k_is_the_selection_rule(case) -> None:
    p, ids, rows, selected, h, h_abs = case
    k = selected.shape[1]
    was = set(selected[0].tolist())
    key = [x + h * abs(x) + h_abs if i in was else x for x, i in zip(p.tolist(), ids.tolist(),
                                                                      strict=True)]
    order = sorted(range(p.size), key=lambda t: (-key[t], ids[t]))[:k]
    got, got_p, got_ids, got_rows = _top_k(p, ids, rows, selected, h, h_abs)
    assert got == k
    np.testing.assert_array_equal(got_ids, ids[order])
    np.testing.assert_array_equal(got_p, p[order])
    np.testing.assert_array_equal(got_rows, rows[order])


@nb.njit
def _gathered(heap_p, heap_j, live_id, old_ids, few):
    k = old_ids.size
    sf = np.full((F_ROWS, k), np.nan)
    si = np.full((I_ROWS, k), -9, np.int64)
    si[I_OLD_ID, :] = old_ids
    si[I_OLD_ROW, :] = -1
    if few:
        n = gather_few(heap_p, heap_j, live_id, 0, heap_p.size, sf, si)
    else:
        cf = np.full((CF_ROWS, heap_p.size), np.nan)
        ci = np.full((CI_ROWS, heap_p.size), -9, np.int64)
        n = gather_live(heap_p, heap_j, live_id, 0, heap_p.size, cf, ci)
        match_old_slots(cf, ci, n, sf, si)
        sf[F_P, :n] = cf[CF_P, :n]
        si[I_ID, :n] = ci[CI_ID, :n]
        si[I_ROW, :n] = ci[CI_ROW, :n]
    return n, sf, si


@examples(1.0)
@given(k=st.sampled_from([1, 2, 4, 8]), data=st.data())
def test_gather_few_is_gather_live_and_match_old_slots(k, data) -> None:
    n_l = data.draw(st.integers(1, 3 * k))
    live_id = np.array(data.draw(st.lists(st.sampled_from([-2, 0]), min_size=n_l,
                                          max_size=n_l)), np.int32)
    live_id[live_id == 0] = np.flatnonzero(live_id == 0) * 5 + 7
    rows = data.draw(st.lists(st.integers(0, n_l - 1), min_size=0, max_size=k, unique=True))
    heap_j = np.array(rows, np.int32)
    heap_p = np.array(data.draw(st.lists(priority, min_size=len(rows), max_size=len(rows))))
    # Last frame's slots: lights of the pool or gone (999...), filled ones first.
    held = data.draw(st.lists(st.sampled_from(live_id[live_id >= 0].tolist() + [999, 1000]),
                              max_size=k, unique=True))
    old_ids = np.array(held + [-1] * (k - len(held)), np.int64)
    n, sf, si = _gathered(heap_p, heap_j, live_id, old_ids, True)
    n_ref, sf_ref, si_ref = _gathered(heap_p, heap_j, live_id, old_ids, False)
    assert n == n_ref == np.count_nonzero(live_id[heap_j] >= 0)
    # The gathered lights, then each old slot's match (NaN P where none: unwritten).
    np.testing.assert_array_equal(sf[F_P, :n], sf_ref[F_P, :n])
    np.testing.assert_array_equal(si[[I_ID, I_ROW], :n], si_ref[[I_ID, I_ROW], :n])
    np.testing.assert_array_equal(sf[F_OLD_P], sf_ref[F_OLD_P])
    np.testing.assert_array_equal(si[I_OLD_ROW], si_ref[I_OLD_ROW])
