"""Frame: the per-frame outputs of DESIGN section 3, plus the plan and stats of section 6.

Takes the arrays the stages produced and holds them under DESIGN's names; ``empty_frame``
builds the all-empty frame of a given size so every producer agrees on dtypes and shapes;
``changed_rows`` tells which objects' rows differ between two frames (the service sends
only those when asked).
"""

from __future__ import annotations

import sys
from dataclasses import dataclass, field
from typing import Any

import numba as nb
import numpy as np
from numba import literal_unroll

from .fields import FIELDS, FIELDS_BY_NAME, PER_OBJECT_NAMES, axis_size
from .jit import OBJECT_CHUNK, PRANGE_ONLY

# name -> dtype, DESIGN section 3's order (fields.FIELDS).
FRAME_ARRAYS: dict[str, Any] = {f.name: f.dtype for f in FIELDS}

# The word types row_words tiles rows with, widest first, with their sizes in bytes.
_WORDS = ((8, np.uint64), (4, np.uint32), (2, np.uint16))

# The order objects.object_pass takes its output arrays in (after "visible", its input), which
# is the scheduler's; fields.py owns the rest.
_OBJECT_PASS_ORDER = ("visible", "light_ids", "light_index", "priority", "fade_weight",
                      "fade_state", "count", "candidates", "slot_shadow", "residual")
if sorted(_OBJECT_PASS_ORDER) != sorted(PER_OBJECT_NAMES):
    raise RuntimeError("frame._OBJECT_PASS_ORDER must name fields.py's per-object arrays")

# Per-object arrays: dtype, shape ("N", "NK" or "N4") and the value of an empty slot
# (DESIGN section 3), in the order objects.object_pass writes them (residual last: its
# Residual argument's, after the row's slots).
PER_OBJECT: dict[str, tuple[Any, str, Any]] = {
    name: (FIELDS_BY_NAME[name].dtype, FIELDS_BY_NAME[name].kind, FIELDS_BY_NAME[name].empty)
    for name in _OBJECT_PASS_ORDER}


@dataclass
class Frame:
    """One frame's result. Object rows are in ascending object id (DESIGN section 3).

    The arrays are fields.FIELDS, written out so that editors and type checkers see
    them (tests/test_frame.py holds the two equal)."""

    object_id: np.ndarray
    visible: np.ndarray
    count: np.ndarray
    candidates: np.ndarray
    light_ids: np.ndarray
    light_index: np.ndarray
    priority: np.ndarray
    fade_weight: np.ndarray
    fade_state: np.ndarray
    slot_shadow: np.ndarray
    directional_lights: np.ndarray
    visible_lights: np.ndarray
    shadow_lights: np.ndarray
    shadow_tier: np.ndarray
    cascade_splits: np.ndarray
    caster_offsets: np.ndarray
    caster_ids: np.ndarray
    caster_masks: np.ndarray
    residual: np.ndarray
    shadow_views: np.ndarray
    shadow_dirty: np.ndarray
    shadow_static_dirty: np.ndarray
    shadow_update: np.ndarray
    shadow_rect: np.ndarray
    camera_ids: np.ndarray
    stats: dict[str, Any] = field(default_factory=dict)

    def arrays(self) -> dict[str, np.ndarray]:
        return {name: getattr(self, name) for name in FRAME_ARRAYS}


def freeze(frame: Frame) -> Frame:
    """Makes every array of the frame read-only: a frame is a snapshot, and the fast
    scheduler keeps its light_ids and fade_state as the next frame's slot state."""
    for name in FRAME_ARRAYS:
        getattr(frame, name).setflags(write=False)
    return frame


def field_shape(name: str, n: int, k: int, cascades: int = 0) -> tuple[int, ...]:
    """The shape of array ``name`` in a frame of ``n`` objects where nothing is lit, seen
    or shadowed (the per-object arrays' shapes in any frame of n objects)."""
    return tuple(axis_size(axis, n, k, cascades) for axis in FIELDS_BY_NAME[name].shape)


def _empty(name: str, n: int, k: int, cascades: int) -> np.ndarray:
    """One array of a frame where no object has a light (DESIGN section 3 empty slots)."""
    f = FIELDS_BY_NAME[name]
    return np.full(field_shape(name, n, k, cascades), f.empty if f.per_object else 0, f.dtype)


def empty_frame(ids: np.ndarray, k: int, cascades: int, **given: Any) -> Frame:
    """A frame of the objects ``ids`` where no object has a light (empty slots as DESIGN
    section 3 defines them), except for the arrays ``given``, which are taken as they are
    (not copied); object_id is a copy of ``ids`` unless given."""
    fields = {name: given[name] if name in given else _empty(name, ids.size, k, cascades)
              for name in FRAME_ARRAYS if name != "object_id"}
    object_id = given["object_id"] if "object_id" in given else ids.astype(np.int32, copy=True)
    return Frame(object_id=object_id, **fields)


@nb.njit(cache=True, nogil=True, error_model="numpy")
def rows_differ(x, x_rows, y, y_rows, changed):
    """changed[i] |= row x_rows[i] of x [., W] differs from row y_rows[i] of y, or
    y_rows[i] < 0 (no such row); an empty x_rows or y_rows stands for row i. Frames compare
    rows remapped by id; the change detection of changes.py the rows an update touched.
    x, y: 2-d arrays of words (row_words); x_rows, y_rows: int64; changed: bool [n], in
    place. DESIGN section 3 (rows by object id) and section 6 (nothing moved, nothing
    recomputed: changes.py's dirty tracking)."""
    for i in range(changed.shape[0]):
        if changed[i]:
            continue
        r = x_rows[i] if x_rows.shape[0] else i
        s = y_rows[i] if y_rows.shape[0] else i
        if s < 0:
            changed[i] = True
            continue
        for w in range(x.shape[1]):
            if x[r, w] != y[s, w]:
                changed[i] = True
                break


def changed_rows(prev: Frame, cur: Frame, names: tuple[str, ...]) -> np.ndarray:
    """Per row of ``cur``: True if its object id is new since ``prev`` or any of the named
    per-object arrays differs from prev's row of the same id (rows ascend by id in both)."""
    n = cur.object_id.size
    if np.array_equal(prev.object_id, cur.object_id):
        prev_row = np.arange(n)
    else:
        pos = np.searchsorted(prev.object_id, cur.object_id)
        pos_c = np.minimum(pos, max(prev.object_id.size - 1, 0))
        kept = (pos < prev.object_id.size) & (prev.object_id[pos_c] == cur.object_id) \
            if prev.object_id.size else np.zeros(n, np.bool_)
        prev_row = np.where(kept, pos_c, -1)
    changed = np.zeros(n, np.bool_)
    for name in names:
        a, b = row_words(getattr(cur, name)), row_words(getattr(prev, name))
        rows_differ(a, np.zeros(0, np.int64), b, prev_row, changed)
    return changed


def row_words(a: np.ndarray) -> np.ndarray:
    """Rows as the widest words that tile them (bitwise: a row "differs" when its bytes
    do), so a row of 8 int32 is compared as 4 int64."""
    rows = np.ascontiguousarray(a)
    rows = rows.reshape(rows.shape[0], -1)
    width = rows.shape[1] * rows.itemsize
    for size, word in _WORDS:
        if width % size == 0:
            return rows.view(word)
    return rows.view(np.uint8)


@nb.njit(cache=True, nogil=True, error_model="numpy")
def _copy_rows_range(src, dst, rows, lo, hi):
    for i in range(lo, hi):
        r = rows[i]
        for w in range(src.shape[1]):
            dst[r, w] = src[r, w]


@nb.njit(cache=True, nogil=True, error_model="numpy")
def _as_rows(a):
    return a.reshape((a.shape[0], -1))


@nb.njit(cache=True, nogil=True, error_model="numpy")
def copy_rows(pairs, rows):
    """dst[r] = src[r] for the rows ``rows`` (int64) of each (src, dst) pair of C-contiguous
    [N] or [N, ...] arrays of the tuple ``pairs`` (each pair one dtype and shape): an
    incremental frame's per-object outputs (DESIGN section 3) keep last frame's rows where
    it does not write them (DESIGN section 6). On the calling thread: a parallel launch
    costs more than a few hundred rows (copy_rows_parallel for more). The arrays go as
    they are, each pair its own compiled loop (literal_unroll): viewing each as bytes
    first cost more than the copy."""
    for pair in literal_unroll(pairs):
        _copy_rows_range(_as_rows(pair[0]), _as_rows(pair[1]), rows, 0, rows.shape[0])


@nb.njit(cache=True, nogil=True, parallel=PRANGE_ONLY, error_model="numpy")
def copy_rows_parallel(pairs, rows):
    """copy_rows with the rows split between the threads, OBJECT_CHUNK rows a work item
    (a parallel loop per array: numba's parallel loops take no tuples of arrays)."""
    n = rows.shape[0]
    for pair in literal_unroll(pairs):
        src, dst = _as_rows(pair[0]), _as_rows(pair[1])
        for ch in nb.prange((n + OBJECT_CHUNK - 1) // OBJECT_CHUNK):
            _copy_rows_range(src, dst, rows, ch * OBJECT_CHUNK,
                             min(n, (ch + 1) * OBJECT_CHUNK))


@nb.njit(cache=True, nogil=True, error_model="numpy")
def rows_not_in(rows, other):
    """The rows of ``rows`` not in ``other`` (both int64, ascending, distinct), ascending:
    a merge, where a mask of every row took three passes over it. DESIGN section 6 (the
    rows of an incremental frame's outputs to copy from last frame's)."""
    out = np.empty(rows.shape[0], np.int64)
    n = 0
    t = 0
    for r in rows:
        while t < other.shape[0] and other[t] < r:
            t += 1
        out[n] = r
        n += t == other.shape[0] or other[t] != r
    return out[:n]


def held_elsewhere(arrays: dict[str, np.ndarray]) -> bool:
    """Whether anything but the dict itself references one of the arrays (a Frame, a view
    of it, a buffer being sent): then they cannot be written again. CPython counts the
    dict's reference, the loop variable's and getrefcount's own argument."""
    return any(sys.getrefcount(a) > 3 for a in arrays.values())
