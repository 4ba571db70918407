"""The K-slot fade machine (DESIGN section 2, "Fade").

Takes one object's slots from last frame (light id, float64 weight, state, in output order),
this frame's P and light row of each slot's light (row -1: it no longer affects the object),
and this frame's selected set; writes the new slots in output order and returns how many are
occupied. Eriksson (2006, 3.2) dropped fading because his three-list state cost too much;
here a slot is a fixed row of K entries, so the machine streams with the object pass of
pairs.py, where this function is inlined.
"""

from __future__ import annotations

import numba as nb

from .scene import FADING_IN, FADING_OUT, ON
from .select import ranks_before

ONE_EPS = 1e-6  # DESIGN: within 1e-6 of 1 is 1, a fading-out weight within 1e-6 of 0 is 0


@nb.njit(cache=True, nogil=True, inline="always")
def _slot_before(st_a, p_a, w_a, id_a, st_b, p_b, w_b, id_b):
    """Output order: not fading out by P desc, then fading out by weight desc; ties lower id."""
    out_a = st_a == FADING_OUT
    out_b = st_b == FADING_OUT
    if out_a != out_b:
        return out_b
    if out_a:
        return ranks_before(w_a, id_a, w_b, id_b)
    return ranks_before(p_a, id_a, p_b, id_b)


@nb.njit(cache=True, nogil=True, inline="always")
def fade_object(sel, nsel, old, old_p, old_row, reset, rates, new, scratch):
    """sel = (ids, P, rows) of the selected set; old = (ids, weights, states) of last frame's
    slots; new = (ids, weights, states, P, rows) written in output order; rates =
    (dt/fade_in, dt/fade_out, fade_in, fade_out); scratch = (has_slot, taken) bool[K]."""
    sel_id, sel_p, sel_row = sel
    old_id, old_w, old_st = old
    new_id, new_w, new_st, new_p, new_row = new
    has_slot, taken = scratch
    inc, dec, fade_in, fade_out = rates
    k = new_id.shape[0]
    cnt = 0
    if reset:
        # Step 3: new, just visible, first frame or a cut: only visible changes fade.
        for t in range(nsel):
            new_id[cnt] = sel_id[t]
            new_w[cnt] = 1.0
            new_st[cnt] = ON
            new_p[cnt] = sel_p[t]
            new_row[cnt] = sel_row[t]
            cnt += 1
    else:
        for t in range(nsel):
            has_slot[t] = False
            taken[t] = False
        # Step 1: occupied slots.
        for m in range(k):
            lid = old_id[m]
            if lid < 0:
                break
            if old_row[m] < 0:
                continue  # no longer affects: freed at once, it shows nothing anyway
            chosen = -1
            for t in range(nsel):
                if sel_id[t] == lid:
                    chosen = t
                    break
            w = old_w[m]
            st = old_st[m]
            if chosen >= 0:
                has_slot[chosen] = True
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
            new_id[cnt] = lid
            new_w[cnt] = w
            new_st[cnt] = st
            new_p[cnt] = old_p[m]
            new_row[cnt] = old_row[m]
            cnt += 1
        # Step 2: slotless selected lights take free slots, highest P first.
        while cnt < k:
            best = -1
            for t in range(nsel):
                if has_slot[t] or taken[t]:
                    continue
                if best < 0 or ranks_before(sel_p[t], sel_id[t], sel_p[best], sel_id[best]):
                    best = t
            if best < 0:
                break
            taken[best] = True
            w = 1.0 if fade_in == 0.0 else min(1.0, inc)
            st = FADING_IN
            if w >= 1.0 - ONE_EPS:
                w = 1.0
                st = ON
            new_id[cnt] = sel_id[best]
            new_w[cnt] = w
            new_st[cnt] = st
            new_p[cnt] = sel_p[best]
            new_row[cnt] = sel_row[best]
            cnt += 1
    # Insertion sort into output order (at most K entries).
    for i in range(1, cnt):
        lid = new_id[i]
        w = new_w[i]
        st = new_st[i]
        p = new_p[i]
        row = new_row[i]
        j = i
        while j > 0 and _slot_before(st, p, w, lid, new_st[j - 1], new_p[j - 1],
                                     new_w[j - 1], new_id[j - 1]):
            new_id[j] = new_id[j - 1]
            new_w[j] = new_w[j - 1]
            new_st[j] = new_st[j - 1]
            new_p[j] = new_p[j - 1]
            new_row[j] = new_row[j - 1]
            j -= 1
        new_id[j] = lid
        new_w[j] = w
        new_st[j] = st
        new_p[j] = p
        new_row[j] = row
    return cnt
