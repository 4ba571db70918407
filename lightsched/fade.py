"""The K-slot fade machine (DESIGN section 2, "Fade").

Takes one object's slots from last frame (light id, float64 weight, state, in output order),
this frame's P and light row of each slot's light (row -1: it no longer affects the object),
and this frame's selected set; writes the new slots in output order and returns how many are
occupied. Eriksson (2006, 3.2) dropped fading because his three-list state cost too much;
here a slot is a fixed row of K entries, so the machine streams with the object pass of
objects.py, where this function is inlined. Scratch layout: select.py (F_*, I_* rows).
"""

from __future__ import annotations

import numba as nb

from .scene import FADING_IN, FADING_OUT, ON
from .select import (
    F_NEW_P,
    F_NEW_W,
    F_OLD_P,
    F_OLD_W,
    F_P,
    I_HAS_SLOT,
    I_ID,
    I_NEW_ID,
    I_NEW_ROW,
    I_NEW_ST,
    I_OLD_ID,
    I_OLD_ROW,
    I_OLD_ST,
    I_ROW,
    I_TAKEN,
    ranks_before,
)

ONE_EPS = 1e-6  # DESIGN: within 1e-6 of 1 is 1, a fading-out weight within 1e-6 of 0 is 0


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _slot_before(st_a, p_a, w_a, id_a, st_b, p_b, w_b, id_b):
    """Output order: not fading out by P desc, then fading out by weight desc; ties lower id."""
    out_a = st_a == FADING_OUT
    out_b = st_b == FADING_OUT
    if out_a != out_b:
        return out_b
    if out_a:
        return ranks_before(w_a, id_a, w_b, id_b)
    return ranks_before(p_a, id_a, p_b, id_b)


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _put(sf, si, cnt, lid, w, st, p, row):
    si[I_NEW_ID, cnt] = lid
    sf[F_NEW_W, cnt] = w
    si[I_NEW_ST, cnt] = st
    sf[F_NEW_P, cnt] = p
    si[I_NEW_ROW, cnt] = row


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def steady_slots(sf, si, nsel):
    """Slots that are all on: the selection (F_P, I_ID, I_ROW)[:nsel] at weight 1, in
    output order (P descending, ties to the lower id), written to the new-slot rows.
    This is step 3 (an object that starts with its selected lights on); an object whose
    slots were all on and hold exactly its selection gets the same from held_slots. Each
    light's place is the number of lights that rank before it: compares only, no branch
    on the data (an insertion sort mispredicts about once per light on random
    priorities, and step 3 has no earlier order to start from). sf: float64 [F_ROWS, K],
    si: int64 [I_ROWS, K]: the object's scratch (select.py); nsel: the selection's size.
    DESIGN section 2, "Fade" (step 3 and the output order)."""
    for i in range(nsel):
        p = sf[F_P, i]
        lid = si[I_ID, i]
        pos = 0
        for j in range(nsel):
            pos += (sf[F_P, j] > p) | ((sf[F_P, j] == p) & (si[I_ID, j] < lid))
        _put(sf, si, pos, lid, 1.0, ON, p, si[I_ROW, i])


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def held_slots(sf, si, nsel):
    """Slots that were all on and hold exactly the selection (nsel of them, filled slots
    first): what steps 1-2 give them, the same lights at weight 1, each with this frame's P
    and row (F_OLD_P, I_OLD_ROW), put in output order (P descending, ties to the lower id)
    by an insertion sort from last frame's order, written to the new-slot rows. Last
    frame's slots are in last frame's output order and P moves little between frames, so
    the sort's compares mostly stop at once: ~nsel compares where steady_slots' rank
    counts take nsel^2 (a sampling profile put those at a sixth of the object pass).
    sf, si, nsel as steady_slots'. DESIGN section 2, "Fade" (steps 1-2 when nothing
    changes but P, and the output order)."""
    for i in range(nsel):
        lid = si[I_OLD_ID, i]
        p = sf[F_OLD_P, i]
        row = si[I_OLD_ROW, i]
        j = i
        while j > 0 and ranks_before(p, lid, sf[F_NEW_P, j - 1], si[I_NEW_ID, j - 1]):
            _put(sf, si, j, si[I_NEW_ID, j - 1], 1.0, ON, sf[F_NEW_P, j - 1],
                 si[I_NEW_ROW, j - 1])
            j -= 1
        _put(sf, si, j, lid, 1.0, ON, p, row)


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def fade_object(sf, si, nsel, reset, inc, dec, fade_in, fade_out):
    """Selected set in rows (I_ID, F_P, I_ROW)[:nsel]; last frame's slots in (I_OLD_ID,
    F_OLD_W, I_OLD_ST) with this frame's (F_OLD_P, I_OLD_ROW); writes the new slots to
    (I_NEW_ID, F_NEW_W, I_NEW_ST, F_NEW_P, I_NEW_ROW) in output order. inc = dt/fade_in,
    dec = dt/fade_out. sf: float64 [F_ROWS, K], si: int64 [I_ROWS, K]: the object's
    scratch (select.py); nsel: the selection's size; reset: bool, step 3 applies (then
    steady_slots); fade_in, fade_out: Config's, in seconds (0: at once). Returns the
    number of occupied slots. DESIGN section 2, "Fade" (steps 1-3, weights, output order)."""
    k = sf.shape[1]
    cnt = 0
    if reset:
        # Step 3: new, just visible, first frame or a cut: only visible changes fade.
        steady_slots(sf, si, nsel)
        return nsel
    for t in range(nsel):
        si[I_HAS_SLOT, t] = 0
        si[I_TAKEN, t] = 0
    # Step 1: occupied slots.
    for m in range(k):
        lid = si[I_OLD_ID, m]
        if lid < 0:
            break
        if si[I_OLD_ROW, m] < 0:
            continue  # no longer affects: freed at once, it shows nothing anyway
        chosen = -1
        for t in range(nsel):  # compares only: it vectorises, a break would not
            chosen = t if si[I_ID, t] == lid else chosen
        w = sf[F_OLD_W, m]
        st = si[I_OLD_ST, m]
        if chosen >= 0:
            si[I_HAS_SLOT, chosen] = 1
            if st != ON:
                st = FADING_IN
                w = 1.0 if fade_in == 0.0 else w + inc
                if w >= 1.0 - ONE_EPS:
                    w = 1.0
                    st = ON
        else:
            if fade_out == 0.0:
                continue
            w = w - dec
            if w <= ONE_EPS:
                continue
            st = FADING_OUT
        _put(sf, si, cnt, lid, w, st, sf[F_OLD_P, m], si[I_OLD_ROW, m])
        cnt += 1
    # Step 2: slotless selected lights take free slots, highest P first.
    while cnt < k:
        best = -1
        for t in range(nsel):
            if si[I_HAS_SLOT, t] != 0 or si[I_TAKEN, t] != 0:
                continue
            if best < 0 or ranks_before(sf[F_P, t], si[I_ID, t], sf[F_P, best],
                                        si[I_ID, best]):
                best = t
        if best < 0:
            break
        si[I_TAKEN, best] = 1
        w = 1.0 if fade_in == 0.0 else min(1.0, inc)
        st = FADING_IN
        if w >= 1.0 - ONE_EPS:
            w = 1.0
            st = ON
        _put(sf, si, cnt, si[I_ID, best], w, st, sf[F_P, best], si[I_ROW, best])
        cnt += 1
    # Insertion sort into output order (at most K entries).
    for i in range(1, cnt):
        lid = si[I_NEW_ID, i]
        w = sf[F_NEW_W, i]
        st = si[I_NEW_ST, i]
        p = sf[F_NEW_P, i]
        row = si[I_NEW_ROW, i]
        j = i
        while j > 0 and _slot_before(st, p, w, lid, si[I_NEW_ST, j - 1], sf[F_NEW_P, j - 1],
                                     sf[F_NEW_W, j - 1], si[I_NEW_ID, j - 1]):
            _put(sf, si, j, si[I_NEW_ID, j - 1], sf[F_NEW_W, j - 1], si[I_NEW_ST, j - 1],
                 sf[F_NEW_P, j - 1], si[I_NEW_ROW, j - 1])
            j -= 1
        _put(sf, si, j, lid, w, st, p, row)
    return cnt
