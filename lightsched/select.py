"""Top-K selection with hysteresis (DESIGN section 2, "Selection").

Takes the competing lights of one object as a stream of (key, id, P, row) and keeps the K
of highest key, ties to the lower light id; key = P, or P + h|P| + hysteresis_abs for a light
that was in the object's selected set last frame, so near-equal lights do not flicker in
and out of the set. Returns the selected set in key order. The insertion is inlined into
the object pass (objects.py), which skips the ranking when every competing light fits in K.
"""

from __future__ import annotations

import numba as nb


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def ranks_before(key_a, id_a, key_b, id_b):
    """True if (key_a, id_a) ranks before (key_b, id_b): higher key, ties lower id.
    DESIGN section 2, "Selection" (and "Fade"'s output order)."""
    return key_a > key_b or (key_a == key_b and id_a < id_b)


# Per-object scratch, one row per quantity and K columns: float64 sf[F_ROWS, K] and int64
# si[I_ROWS, K]. Two matrices instead of many small arrays keep the inlined per-object code
# free of array views (their reference counting costs more than the pair tests).
F_KEY, F_P, F_OLD_P, F_OLD_W, F_NEW_W, F_NEW_P = range(6)
F_ROWS = 6
(I_ID, I_ROW, I_OLD_ID, I_OLD_ROW, I_OLD_ST, I_PREV_SEL, I_NEW_ID, I_NEW_ROW, I_NEW_ST,
 I_HAS_SLOT, I_TAKEN) = range(11)
I_ROWS = 11


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def hysteresis_key(p, lid, si, h, h_abs):
    """P, raised by h|P| + h_abs if lid was selected last frame (row I_PREV_SEL, padded
    with -1). Compares only in the loop, no early exit: it vectorises. p: P; lid: the
    light's id; si: int64 [I_ROWS, K] scratch; h, h_abs: Config.hysteresis,
    hysteresis_abs. DESIGN section 2, "Selection" (hysteresis)."""
    was = False
    for m in range(si.shape[1]):
        was |= si[I_PREV_SEL, m] == lid
    return p + h * abs(p) + h_abs if was else p


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def topk_insert(sf, si, nbest, key, lid, p, row):
    """Inserts one candidate into the sorted top-K rows (F_KEY, F_P, I_ID, I_ROW); returns
    the new size. sf: float64 [F_ROWS, K], si: int64 [I_ROWS, K]: the object's scratch;
    nbest: the rows filled; key: hysteresis_key's; lid: light id; p: P; row: light row.
    DESIGN section 2, "Selection"."""
    k = sf.shape[1]
    # Where it goes: a count of compares (no stores, so it vectorises), then the shift.
    pos = 0
    for m in range(nbest):
        pos += ranks_before(sf[F_KEY, m], si[I_ID, m], key, lid)
    if pos >= k:
        return nbest
    for i in range(min(nbest, k - 1), pos, -1):
        sf[F_KEY, i] = sf[F_KEY, i - 1]
        sf[F_P, i] = sf[F_P, i - 1]
        si[I_ID, i] = si[I_ID, i - 1]
        si[I_ROW, i] = si[I_ROW, i - 1]
    i = pos
    sf[F_KEY, i] = key
    sf[F_P, i] = p
    si[I_ID, i] = lid
    si[I_ROW, i] = row
    return nbest + 1 if nbest < k else k
