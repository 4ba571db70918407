"""fade.held_slots (held slots put in output order by an insertion sort from last frame's
order) == fade.steady_slots (the same slots placed by rank counts) on every order of the
old slots, with tied and signed-zero priorities: the object pass takes the first for an
object whose slots were all on and hold exactly its selection, so the two must agree
whatever order last frame left (DESIGN section 2, "Fade": output order is P descending,
ties to the lower light id)."""

from __future__ import annotations

import numpy as np
from helpers import examples
from hypothesis import given
from hypothesis import strategies as st

from lightsched.fade import held_slots, steady_slots
from lightsched.scene import ON
from lightsched.select import (
    F_NEW_P,
    F_NEW_W,
    F_OLD_P,
    F_P,
    F_ROWS,
    I_ID,
    I_NEW_ID,
    I_NEW_ROW,
    I_NEW_ST,
    I_OLD_ID,
    I_OLD_ROW,
    I_ROW,
    I_ROWS,
)

K = 8
# Few distinct values, so ties (and -0.0 against 0.0) are common.
priority = st.one_of(st.sampled_from([0.0, -0.0, 1.0, 2.5, -3.0]),
                     st.floats(-1e6, 1e6, allow_nan=False))


@st.composite
def held_selection(draw):
    n = draw(st.integers(0, K))
    ids = draw(st.lists(st.integers(0, 40), min_size=n, max_size=n, unique=True))
    p = draw(st.lists(priority, min_size=n, max_size=n))
    rows = draw(st.lists(st.integers(0, 1000), min_size=n, max_size=n))
    old_order = draw(st.permutations(range(n)))
    return ids, p, rows, old_order


def _new_slots(sf: np.ndarray, si: np.ndarray, n: int) -> tuple:
    return (si[I_NEW_ID, :n].copy(), sf[F_NEW_P, :n].copy(), si[I_NEW_ROW, :n].copy(),
            sf[F_NEW_W, :n].copy(), si[I_NEW_ST, :n].copy())


@examples(3.0)
@given(case=held_selection())
def test_held_slots_equal_steady_slots(case) -> None:
    ids, p, rows, old_order = case
    n = len(ids)
    # Scratch as the object pass leaves it: the selection in list order for steady_slots,
    # the same lights as last frame's slots (in any order) with this frame's P and row.
    sf_a, si_a = np.full((F_ROWS, K), np.nan), np.full((I_ROWS, K), -9, np.int64)
    sf_a[F_P, :n], si_a[I_ID, :n], si_a[I_ROW, :n] = p, ids, rows
    sf_b, si_b = sf_a.copy(), si_a.copy()
    for m, t in enumerate(old_order):
        si_b[I_OLD_ID, m], sf_b[F_OLD_P, m], si_b[I_OLD_ROW, m] = ids[t], p[t], rows[t]
    steady_slots(sf_a, si_a, n)
    held_slots(sf_b, si_b, n)
    a, b = _new_slots(sf_a, si_a, n), _new_slots(sf_b, si_b, n)
    for x, y in zip(a, b, strict=True):
        np.testing.assert_array_equal(x, y)
    # And the order is the rule's, not merely the same in both.
    key = sorted(range(n), key=lambda t: (-p[t], ids[t]))
    np.testing.assert_array_equal(a[0], np.array([ids[t] for t in key], np.int64))
    assert np.all(a[3] == 1.0) and np.all(a[4] == ON)
