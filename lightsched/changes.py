"""What changed since the last frame (DESIGN section 6: only what moved is recomputed).

Takes the arrays the last frame read (a scheduler keeps references to them: stores never
change an array in place, they copy on write) and the stores as they are now; returns the
rows whose fields differ, bit for bit, or None when the rows themselves changed (a set_ or
remove_ call renumbered them). Only the rows that update_ calls touched since the last
frame (``touched`` on the stores) are compared, so a frame where a few of 100k objects
moved compares a few rows. Cameras are compared as one key of their parameters.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from .frame import row_words, rows_differ
from .scene import LIGHT_FIELDS, OBJECT_FIELDS, Camera

# The object fields whose change alters an object's pairs (casts_shadows changes only
# casters).
PAIR_OBJECT_FIELDS = ("id", "bounds_min", "bounds_max", "mask")


@dataclass(slots=True)
class Changes:
    """What differs from the last frame's scene. ``lights`` and ``objects``: the stores'
    arrays this frame reads (the next frame compares against them); the rows are None
    when there is no last frame or a set_/remove_ call renumbered either kind (then all
    three are None): ``light_rows`` changed in any field, ``object_rows`` in a field of
    PAIR_OBJECT_FIELDS, ``cast_rows`` in casts_shadows; ``light_fields``: the light fields
    whose arrays were replaced (update_ or set_ calls), which the packing reads."""

    lights: dict[str, np.ndarray]
    objects: dict[str, np.ndarray]
    light_rows: np.ndarray | None = None
    object_rows: np.ndarray | None = None
    cast_rows: np.ndarray | None = None
    light_fields: tuple[str, ...] = LIGHT_FIELDS
    # Why the rows are None: "lights" or "objects" (the set changed), "" (no last frame).
    renumbered: str = ""


def find_changes(last: Changes | None, lights: Any, objects: Any) -> Changes:
    """This frame's Changes against the scene the last frame read (``last``, or None)."""
    now_l = {f: getattr(lights, f) for f in LIGHT_FIELDS}
    now_o = {f: getattr(objects, f) for f in OBJECT_FIELDS}
    if last is None:
        return Changes(now_l, now_o)
    lrows = changed_rows(last.lights, lights, LIGHT_FIELDS)
    if lrows is None:
        return Changes(now_l, now_o, renumbered="lights")
    orows = changed_rows(last.objects, objects, PAIR_OBJECT_FIELDS)
    if orows is None:
        return Changes(now_l, now_o, renumbered="objects")
    cast = changed_rows(last.objects, objects, ("id", "casts_shadows"))
    fields = tuple(f for f in LIGHT_FIELDS if last.lights[f] is not now_l[f])
    return Changes(now_l, now_o, lrows, orows, cast, fields)


def camera_key(cameras: list[Camera]) -> np.ndarray:
    """Every parameter of the validated cameras, in order, as one float64 array."""
    vals: list[float] = []
    for cam in cameras:
        vals.append(float(cam.id))
        vals.extend(cam.position.tolist())
        vals.extend(cam.forward.tolist())
        vals.extend(cam.up.tolist())
        vals.extend((cam.fov_y, cam.aspect, cam.near, cam.far))
        vals.extend(cam.focus.tolist())
        vals.append(cam.height_px)
    return np.array(vals)


def same_key(a: np.ndarray, b: np.ndarray) -> bool:
    """Bit-identical camera keys (0.0 and -0.0 differ: a sign can reach a result). Their
    bytes compared: cheaper than two int64 views and np.array_equal."""
    return a.tobytes() == b.tobytes()


def changed_rows(last: dict[str, np.ndarray], store: Any, fields: tuple[str, ...]
                 ) -> np.ndarray | None:
    """Rows of ``store`` whose ``fields`` (the first is "id") differ from ``last`` (the
    arrays the last frame read) bit for bit, ascending int64; None when the ids differ."""
    ids = store.id
    if ids is not last["id"]:
        if ids.shape != last["id"].shape or not np.array_equal(ids, last["id"]):
            return None
        rows = None  # a set_ call with the same ids: compare every row
    elif store.touched:
        touched = store.touched
        rows = _sorted_unique(touched[0] if len(touched) == 1 else np.concatenate(touched),
                              ids.size)
    else:
        return np.zeros(0, np.int64)
    n = ids.size if rows is None else rows.size
    changed = np.zeros(n, np.bool_)
    for f in fields[1:]:
        a, b = last[f], getattr(store, f)
        if a is not b and a.shape[0]:
            same = np.zeros(0, np.int64) if rows is None else rows
            rows_differ(row_words(a), same, row_words(b), same, changed)
    out = np.flatnonzero(changed) if rows is None else rows[changed]
    return out.astype(np.int64, copy=False)


def _sorted_unique(rows: np.ndarray, n: int) -> np.ndarray:
    """The distinct values of ``rows`` (in 0..n-1), ascending. Many rows (an update of
    every light, in the caller's order): marked in an [n] mask, linear, where sorting them
    costs far more. Few: sorted, then deduplicated (np.unique costs more here)."""
    if rows.size * 16 > n:
        mark = np.zeros(n, np.bool_)
        mark[rows] = True
        return np.flatnonzero(mark)
    rows = np.sort(rows)
    return rows[np.concatenate(([True], rows[1:] != rows[:-1]))]
