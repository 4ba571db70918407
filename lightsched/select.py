"""Top-K selection with hysteresis (DESIGN section 2, "Selection").

Takes the competing lights of one object as a stream of (key, id, P, row) and keeps the K
of highest key, ties to the lower light id; key = P, or P + h|P| + hysteresis_abs for a light
that was in the object's selected set last frame, so near-equal lights do not flicker in
and out of the set. Returns the selected set in key order. The insertion
is inlined into the fused object pass of pairs.py.
"""

from __future__ import annotations

import numba as nb


@nb.njit(cache=True, nogil=True, inline="always")
def ranks_before(key_a, id_a, key_b, id_b):
    """True if (key_a, id_a) ranks before (key_b, id_b): higher key, ties lower id."""
    return key_a > key_b or (key_a == key_b and id_a < id_b)


@nb.njit(cache=True, nogil=True, inline="always")
def hysteresis_key(p, lid, prev_selected, h, h_abs):
    """P, raised by h|P| + h_abs if lid was selected last frame (selection only)."""
    for m in range(prev_selected.shape[0]):
        q = prev_selected[m]
        if q < 0:
            break
        if q == lid:
            return p + h * abs(p) + h_abs
    return p


@nb.njit(cache=True, nogil=True, inline="always")
def topk_insert(best_key, best_id, best_p, best_row, nbest, key, lid, p, row):
    """Inserts one candidate into the sorted top-K arrays; returns the new size."""
    k = best_key.shape[0]
    if nbest == k and not ranks_before(key, lid, best_key[k - 1], best_id[k - 1]):
        return nbest
    i = nbest if nbest < k else k - 1
    while i > 0 and ranks_before(key, lid, best_key[i - 1], best_id[i - 1]):
        best_key[i] = best_key[i - 1]
        best_id[i] = best_id[i - 1]
        best_p[i] = best_p[i - 1]
        best_row[i] = best_row[i - 1]
        i -= 1
    best_key[i] = key
    best_id[i] = lid
    best_p[i] = p
    best_row[i] = row
    return nbest + 1 if nbest < k else k
