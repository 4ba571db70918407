"""Scene inputs: Config, Camera, the structure-of-arrays light and object stores, validation.

Takes the keyword arrays of DESIGN section 7 (``set_lights(id=..., position=...)``) and
returns stores whose rows are sorted by ascending id, so a row index is the ``light_index``
of DESIGN section 3 and ties "to the lower id" are ties to the lower row.

Validation follows DESIGN sections 1 and 3 ("Details every implementation must agree on"):
every field is checked in the table order of section 1, the first failing field is named
with the first failing row of that call, and nothing is stored until every check passed.
Directions are normalised here, once, so the fast path and the oracle see the same bits.
"""

from __future__ import annotations

import contextlib
import math
import operator
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field, fields
from typing import Any

import numpy as np

UINT32_MAX = 0xFFFFFFFF
INT32_MAX = 2**31 - 1
MAX_CAMERAS = 8

POINT, SPOT, DIRECTIONAL = 0, 1, 2

# Fade states (DESIGN section 2, "Fade").
OFF, FADING_IN, ON, FADING_OUT = 0, 1, 2, 3

# The scene changes SceneAPI.apply runs (DESIGN section 7's calls).
CHANGE_OPS = ("set_lights", "update_lights", "remove_lights", "set_objects", "update_objects",
              "remove_objects")


class ValidationError(ValueError):
    """Bad input: names the field and the first offending index (None when no row applies)."""

    def __init__(self, field: str, index: int | None, message: str) -> None:
        self.field = field
        self.index = index
        self.message = message
        self.position: int | None = None  # which change of a SceneAPI.apply batch
        where = field if index is None else f"{field}[{index}]"
        super().__init__(f"{where}: {message}")


# --------------------------------------------------------------------------- config


def _check_real(name: str, value: Any, lo: float | None = None, lo_open: bool = False) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValidationError(name, None, f"must be a number, got {value!r}") from None
    if not math.isfinite(v):
        raise ValidationError(name, None, "must be finite")
    if lo is not None and (v <= lo if lo_open else v < lo):
        raise ValidationError(name, None, f"must be {'>' if lo_open else '>='} {lo}, got {v}")
    return v


def _check_int(name: str, value: Any, lo: int, hi: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise ValidationError(name, None, f"must be an integer, got {value!r}")
    if not lo <= int(value) <= hi:
        raise ValidationError(name, None, f"must be in {lo}..{hi}, got {value}")
    return int(value)


def _check_bool(config: Any, name: str) -> None:
    """A boolean field of a frozen Config, numpy's bool taken as Python's."""
    value = getattr(config, name)
    if not isinstance(value, (bool, np.bool_)):
        raise ValidationError(name, None, "must be a boolean")
    object.__setattr__(config, name, bool(value))


@dataclass(frozen=True)
class Config:
    """Per-scheduler settings; names and defaults are DESIGN section 1's."""

    max_lights: int = 8
    model: str = "contribution"
    w_ecc: float = 1.0
    w_dist: float = -0.01
    w_obj: float = -0.1
    w_int: float = 0.1
    c1: float = 0.25
    hysteresis: float = 0.1
    hysteresis_abs: float = 0.0
    fade_in: float = 0.25
    fade_out: float = 0.25
    directional_in_slots: bool = False
    shadow_budget: int = 4
    cascades: int = 4
    shadow_distance: float = 150.0
    cascade_overlap: float = 0.1
    max_shadowed_per_object: int | None = None  # None means min(2, max_lights)
    unshadowed: str = "light"
    precision: str = "exact"
    residual: bool = True
    shadow_update_budget: int = 0  # point/spot views rendered per frame; 0 = no limit
    shadow_atlas_size: int = 8192  # texels; 0 = no atlas
    caster_culling: str = "camera"

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        k = _check_int("max_lights", self.max_lights, 1, 32)
        set_(self, "max_lights", k)
        if self.model not in ("contribution", "thesis"):
            raise ValidationError("model", None, f"must be 'contribution' or 'thesis', got {self.model!r}")
        for name in ("w_ecc", "w_dist", "w_obj", "w_int"):
            set_(self, name, _check_real(name, getattr(self, name)))
        set_(self, "c1", _check_real("c1", self.c1, 0.0, lo_open=True))
        for name in ("hysteresis", "hysteresis_abs", "fade_in", "fade_out"):
            set_(self, name, _check_real(name, getattr(self, name), 0.0))
        _check_bool(self, "directional_in_slots")
        set_(self, "shadow_budget", _check_int("shadow_budget", self.shadow_budget, 0, 127))
        set_(self, "cascades", _check_int("cascades", self.cascades, 1, 4))
        set_(self, "shadow_distance",
             _check_real("shadow_distance", self.shadow_distance, 0.0, lo_open=True))
        set_(self, "cascade_overlap", _check_real("cascade_overlap", self.cascade_overlap, 0.0))
        mspo = min(2, k) if self.max_shadowed_per_object is None else self.max_shadowed_per_object
        set_(self, "max_shadowed_per_object", _check_int("max_shadowed_per_object", mspo, 0, k))
        if self.unshadowed not in ("light", "skip"):
            raise ValidationError("unshadowed", None, f"must be 'light' or 'skip', got {self.unshadowed!r}")
        if self.precision not in ("exact", "fast"):
            raise ValidationError("precision", None, f"must be 'exact' or 'fast', got {self.precision!r}")
        _check_bool(self, "residual")
        set_(self, "shadow_update_budget",
             _check_int("shadow_update_budget", self.shadow_update_budget, 0, 2**31 - 1))
        atlas = _check_int("shadow_atlas_size", self.shadow_atlas_size, 0, 65536)
        if atlas != 0 and (atlas < 4096 or atlas & (atlas - 1)):
            raise ValidationError("shadow_atlas_size", None,
                                  f"must be 0 or a power of two from 4096 to 65536, got {atlas}")
        set_(self, "shadow_atlas_size", atlas)
        if self.caster_culling not in ("camera", "light"):
            raise ValidationError("caster_culling", None,
                                  f"must be 'camera' or 'light', got {self.caster_culling!r}")

    def to_dict(self) -> dict[str, Any]:
        return {f.name: getattr(self, f.name) for f in fields(self)}


# --------------------------------------------------------------------------- cameras


@dataclass
class Camera:
    """One view (DESIGN section 1). Vectors are float64[3]; focus is NDC (x, y)."""

    position: Any
    forward: Any
    up: Any
    fov_y: float
    aspect: float
    near: float
    far: float
    focus: Any = (0.0, 0.0)
    height_px: float = 1080.0
    id: int | None = None  # None: the camera's position in the frame's list


_CAMERA_FIELDS = ("id", "position", "forward", "up", "fov_y", "aspect", "near", "far",
                  "focus", "height_px")
_camera_fields = operator.attrgetter(*_CAMERA_FIELDS)


def _camera_vector(name: str, i: int, value: Any, n: int) -> tuple[np.ndarray, list[float]]:
    """The camera field ``name`` as a new float64 [n] array and as Python floats."""
    kind = type(value)
    if kind is np.ndarray and value.shape == (n,) and value.dtype == np.float64:
        # What the wire and the Python client send: three Python floats checked cost a
        # fraction of numpy's checks on a three-element array.
        values = value.tolist()
    elif (kind is tuple or kind is list) and len(value) == n and all(
            type(v) is float for v in value):
        # Camera's default focus, and the vectors of a mapping: np.asarray, np.isfinite and
        # a copy were a large share of checking a camera.
        values = list(value)
    else:
        values = None
    if values is not None and all(map(math.isfinite, values)):
        return np.array(values), values
    try:
        a = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValidationError(f"cameras.{name}", i, "must be numeric") from None
    if a.shape != (n,):
        raise ValidationError(f"cameras.{name}", i, f"must have shape ({n},), got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValidationError(f"cameras.{name}", i, "must be finite")
    return a.copy(), a.tolist()


def validate_cameras(cameras: Any) -> list[Camera]:
    """Returns validated copies (numpy vectors, float scalars) of 1..8 cameras.

    Accepts Camera instances or mappings with Camera's field names. The error field is
    ``cameras.<field>`` and the index the camera's position in the list. A camera without
    an id gets its position as its id (DESIGN section 1); ids must still be unique, so
    [id 1, no id] is rejected at index 1.
    """
    if isinstance(cameras, (Camera, dict)):
        cameras = [cameras]
    try:
        cams = list(cameras)
    except TypeError:
        raise ValidationError("cameras", None, "must be a list of cameras") from None
    if not 1 <= len(cams) <= MAX_CAMERAS:
        raise ValidationError("cameras", None, f"need 1..{MAX_CAMERAS} cameras, got {len(cams)}")
    out: list[Camera] = []
    seen: set[int] = set()
    for i, c in enumerate(cams):
        if isinstance(c, dict):
            unknown = set(c) - set(_CAMERA_FIELDS)
            if unknown:
                raise ValidationError(f"cameras.{sorted(unknown)[0]}", i, "unknown field")
            missing = [f for f in _CAMERA_FIELDS[1:8] if f not in c]
            if missing:
                raise ValidationError(f"cameras.{missing[0]}", i, "required")
            c = Camera(**c)
        elif not isinstance(c, Camera):
            raise ValidationError("cameras", i, f"must be a Camera or a mapping, got {type(c).__name__}")
        cid = i if c.id is None else c.id
        if isinstance(cid, bool) or not isinstance(cid, (int, np.integer)) or not 0 <= cid <= INT32_MAX:
            raise ValidationError("cameras.id", i, "must be a non-negative int32")
        if int(cid) in seen:
            given = "" if c.id is not None else " (a camera without an id takes its position)"
            raise ValidationError("cameras.id", i, f"duplicate camera id {cid}{given}")
        seen.add(int(cid))
        if _sealed(c):
            out.append(c)
            continue
        pos, _ = _camera_vector("position", i, c.position, 3)
        fwd, (fx, fy, fz) = _camera_vector("forward", i, c.forward, 3)
        fwd_n = math.sqrt(fx * fx + fy * fy + fz * fz)
        if not 0.0 < fwd_n < math.inf:
            raise ValidationError("cameras.forward", i, "must have a non-zero length that "
                                  "sqrt(x*x + y*y + z*z) can represent")
        up, (ux, uy, uz) = _camera_vector("up", i, c.up, 3)
        # Plain floats: a frame validates its cameras every call, numpy's per-call cost
        # would dominate three-element vectors.
        fx, fy, fz = fx / fwd_n, fy / fwd_n, fz / fwd_n
        cx, cy, cz = fy * uz - fz * uy, fz * ux - fx * uz, fx * uy - fy * ux
        upn = math.sqrt(ux * ux + uy * uy + uz * uz)
        if not 0.0 < upn < math.inf or math.sqrt(cx * cx + cy * cy + cz * cz) <= 1e-9 * upn:
            raise ValidationError("cameras.up", i, "must be non-zero and not parallel to forward")
        # Each field is parsed and range-checked before the next one (table order).
        fov_y = _camera_real(c, "fov_y", i)
        if not 0.0 < fov_y < math.pi:
            raise ValidationError("cameras.fov_y", i, "must be in (0, pi)")
        aspect = _camera_real(c, "aspect", i)
        if not aspect > 0.0:
            raise ValidationError("cameras.aspect", i, "must be > 0")
        near = _camera_real(c, "near", i)
        if not near > 0.0:
            raise ValidationError("cameras.near", i, "must be > 0")
        far = _camera_real(c, "far", i)
        if not far > near:
            raise ValidationError("cameras.far", i, "must be > near")
        focus, (fx_ndc, fy_ndc) = _camera_vector("focus", i, c.focus, 2)
        if not (abs(fx_ndc) <= 1.0 and abs(fy_ndc) <= 1.0):
            raise ValidationError("cameras.focus", i, "must be in [-1, 1]^2")
        height_px = _camera_real(c, "height_px", i)
        if not height_px > 0.0:
            raise ValidationError("cameras.height_px", i, "must be > 0")
        out.append(_seal(Camera(position=pos, forward=fwd, up=up, fov_y=fov_y, aspect=aspect,
                                near=near, far=far, focus=focus, height_px=height_px,
                                id=int(cid))))
    return out


def _camera_real(c: Camera, name: str, i: int) -> float:
    """A scalar camera field as a finite float."""
    try:
        v = float(getattr(c, name))
    except (TypeError, ValueError):
        raise ValidationError(f"cameras.{name}", i, "must be a number") from None
    if not math.isfinite(v):
        raise ValidationError(f"cameras.{name}", i, "must be finite")
    return v


def _seal(c: Camera) -> Camera:
    """Marks a camera validate_cameras made: its vectors read-only and the objects of its
    fields recorded, so that it passes again unchecked while they are the same. The
    service checks a request's cameras before its scene changes (a bad camera refuses the
    request with nothing changed), then ``Scheduler.frame`` would check them again, a cost
    a small service frame feels."""
    for v in (c.position, c.forward, c.up, c.focus):
        v.setflags(write=False)
    c.__dict__["_checked"] = _camera_fields(c)
    return c


def _sealed(c: Camera) -> bool:
    checked = c.__dict__.get("_checked")
    return checked is not None and all(
        a is b for a, b in zip(_camera_fields(c), checked, strict=True))


def validate_dt(dt: Any) -> float:
    return _check_real("dt", dt, 0.0)


# --------------------------------------------------------------------------- field parsing


def _first_bad(mask: np.ndarray) -> int | None:
    """Index of the first True row of a per-row mask (rows may have trailing axes)."""
    # Valid input is the rule: one any() then, cheaper than the row reduction.
    if not mask.any():
        return None
    if mask.ndim > 1:
        mask = mask.reshape(mask.shape[0], -1).any(axis=1)
    return int(np.flatnonzero(mask)[0])


def _parse(name: str, value: Any, n: int, kind: str, width: int = 0) -> np.ndarray:
    """Converts one keyword array; checks shape (never broadcast), numeric kind, finiteness."""
    try:
        raw = np.asarray(value)
    except Exception:  # noqa: BLE001 - anything numpy cannot take is a bad field
        raise ValidationError(name, None, "is not an array") from None
    shape = (n, width) if width else (n,)
    if raw.ndim != len(shape) or (width and raw.shape[1] != width):
        raise ValidationError(name, None, f"must have shape {_shape_str(shape)}, got {raw.shape}")
    if raw.shape[0] != n:
        raise ValidationError(name, min(raw.shape[0], n),
                              f"has {raw.shape[0]} rows, id has {n}")
    if n == 0:
        return np.zeros(shape, dtype={"f": np.float64, "b": np.bool_}.get(kind, np.int64))
    if raw.dtype.kind not in "biuf":
        raise ValidationError(name, _first_non_numeric(raw),
                              f"must be numeric, got dtype {raw.dtype}")
    if kind == "f":
        a = raw.astype(np.float64)
        bad = _first_bad(~np.isfinite(a))
        if bad is not None:
            raise ValidationError(name, bad, "must be finite")
        return a
    if kind == "b":
        if raw.dtype.kind == "f":
            bad = _first_bad(~np.isin(raw, (0.0, 1.0)))
            if bad is not None:
                raise ValidationError(name, bad, "must be a boolean")
        elif raw.dtype.kind in "iu":
            bad = _first_bad((raw != 0) & (raw != 1))
            if bad is not None:
                raise ValidationError(name, bad, "must be a boolean")
        return raw.astype(np.bool_)
    # integers
    if raw.dtype.kind == "f":
        bad = _first_bad(~np.isfinite(raw) | (raw != np.floor(raw)))
        if bad is not None:
            raise ValidationError(name, bad, "must be an integer")
        bad = _first_bad(np.abs(raw) > 2.0**62)  # before the cast, which would wrap
        if bad is not None:
            raise ValidationError(name, bad, "out of range")
    if raw.dtype.kind == "b":
        raise ValidationError(name, 0, "must be an integer, got booleans")
    if raw.dtype.kind == "u" or raw.dtype.kind == "i":
        return raw.astype(np.int64) if raw.dtype != np.uint64 else _u64_checked(name, raw)
    return raw.astype(np.int64)


def _first_non_numeric(raw: np.ndarray) -> int:
    """First row of a non-numeric array (e.g. an int beyond 64 bits made it dtype object)
    holding an element numpy cannot take as a number; 0 when every row is alike."""
    if raw.dtype.kind == "O":
        for i, row in enumerate(raw.reshape(raw.shape[0], -1)):
            for v in row:
                try:
                    if np.asarray(v).dtype.kind not in "biuf":
                        return i
                except Exception:  # noqa: BLE001
                    return i
    return 0


def _u64_checked(name: str, raw: np.ndarray) -> np.ndarray:
    bad = _first_bad(raw > np.uint64(2**62))
    if bad is not None:
        raise ValidationError(name, bad, "out of range")
    return raw.astype(np.int64)


def _shape_str(shape: tuple[int, ...]) -> str:
    return "(" + ", ".join(str(s) for s in shape) + ("," if len(shape) == 1 else "") + ")"


def _check_ids(ids: np.ndarray) -> np.ndarray:
    bad = _first_bad((ids < 0) | (ids > INT32_MAX))
    if bad is not None:
        raise ValidationError("id", bad, "must be a non-negative int32")
    ids = ids.astype(np.int32)
    _check_unique(ids)
    return ids


def _check_unique(ids: np.ndarray) -> None:
    if ids.size < 2:
        return
    order = np.argsort(ids, kind="stable")
    s = ids[order]
    dup = np.flatnonzero(s[1:] == s[:-1])
    if dup.size:
        # The first row (in call order) that repeats an earlier id.
        later = order[dup + 1]
        raise ValidationError("id", int(later.min()), "duplicate id")


def _check_mask(name: str, a: np.ndarray) -> np.ndarray:
    bad = _first_bad((a < 0) | (a > UINT32_MAX))
    if bad is not None:
        raise ValidationError(name, bad, "must be a uint32")
    return a.astype(np.uint32)


def _norm3(d: np.ndarray) -> np.ndarray:
    """Row-wise |d| = sqrt(x*x + y*y + z*z); 0 on underflow, inf on overflow."""
    with np.errstate(over="ignore", under="ignore"):
        return np.sqrt(d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1] + d[:, 2] * d[:, 2])


def _normalise(d: np.ndarray) -> np.ndarray:
    """Row-wise d / |d| with |d| = sqrt(x*x + y*y + z*z); rows whose |d| is 0 or inf stay
    as given (only rows whose type ignores direction can have them)."""
    n = _norm3(d)
    out = d.copy()
    ok = (n > 0.0) & (n < np.inf)
    out[ok] = d[ok] / n[ok, None]
    return out


# --------------------------------------------------------------------------- stores

LIGHT_FIELDS = ("id", "type", "position", "radius", "direction", "outer_angle", "inner_angle",
                "intensity", "priority", "shadows", "mask")
OBJECT_FIELDS = ("id", "bounds_min", "bounds_max", "casts_shadows", "mask", "static")


def _id_rows(store: Any, ids_in: Any, what: str) -> tuple[np.ndarray, np.ndarray]:
    """Validates ids of an update_/remove_ call; returns (ids, store rows)."""
    if ids_in is None:
        raise ValidationError("id", None, "required")
    raw = _parse("id", ids_in, _len_of("id", ids_in), "i")
    store_ids = store.id
    if raw.size:
        rows = _bulk_rows(store, raw)
        if rows is not None:
            return raw.astype(np.int32), rows
    # Some id is bad (or the ids too sparse for a table): the checks in their order, for
    # the error they give.
    ids = _check_ids(raw)
    rows = np.searchsorted(store_ids, ids)
    rows_c = np.minimum(rows, max(store_ids.size - 1, 0))
    known = (rows < store_ids.size) & (store_ids[rows_c] == ids) if store_ids.size else \
        np.zeros(ids.size, dtype=bool)
    bad = _first_bad(~known)
    if bad is not None:
        raise ValidationError("id", bad, f"unknown {what} id {int(ids[bad])}")
    return ids, rows


def _bulk_rows(store: Any, ids: np.ndarray) -> np.ndarray | None:
    """Store rows of ``ids`` (at least one) by an id -> row table kept until the store's
    ids change, and duplicates found by marking rows (many ids) or sorting the rows (few):
    where np.searchsorted and the duplicate check's np.argsort cost far more, for many ids
    as for a few among many rows. Made at the first update after
    a set_ (its O(N) is that of the copy every update makes of each array it writes).
    None if an id is out of range, unknown or repeated (the caller's checks then name
    it), or if the ids are too sparse for a table."""
    store_ids = store.id
    n = store_ids.size
    # (Two reductions, no temporary masks.)
    if n == 0 or ids.min() < 0 or ids.max() > int(store_ids[-1]):
        return None
    cached = store.rows_by_id
    if cached is None or cached[0] is not store_ids:
        span = int(store_ids[-1]) + 1
        table = None
        if span <= 4 * n + 1024:
            table = np.full(span, -1, np.int32)
            table[store_ids] = np.arange(n, dtype=np.int32)
        cached = store.rows_by_id = (store_ids, table)
    table = cached[1]
    if table is None:
        return None
    rows = table[ids].astype(np.int64)
    if rows.min() < 0:
        return None
    if rows.size * 16 <= n:
        ordered = np.sort(rows)
        return None if (ordered[1:] == ordered[:-1]).any() else rows
    mark = np.zeros(n, np.bool_)
    mark[rows] = True
    return rows if np.count_nonzero(mark) == rows.size else None


def _len_of(name: str, value: Any) -> int:
    try:
        a = np.asarray(value)
    except Exception:  # noqa: BLE001
        raise ValidationError(name, None, "is not an array") from None
    if a.ndim != 1:
        raise ValidationError(name, None, f"must be one-dimensional, got shape {a.shape}")
    return a.shape[0]


@dataclass
class LightStore:
    """Lights as structure of arrays, rows in ascending id (DESIGN section 1, Light)."""

    id: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int32))
    type: np.ndarray = field(default_factory=lambda: np.zeros(0, np.uint8))
    position: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    radius: np.ndarray = field(default_factory=lambda: np.zeros(0))
    direction: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    outer_angle: np.ndarray = field(default_factory=lambda: np.zeros(0))
    inner_angle: np.ndarray = field(default_factory=lambda: np.zeros(0))
    intensity: np.ndarray = field(default_factory=lambda: np.zeros(0))
    priority: np.ndarray = field(default_factory=lambda: np.zeros(0))
    shadows: np.ndarray = field(default_factory=lambda: np.zeros(0, np.bool_))
    mask: np.ndarray = field(default_factory=lambda: np.zeros(0, np.uint32))
    version: int = 0
    # Rows that update_lights calls wrote since the last frame (dirty rows; a scheduler
    # compares them with last frame's values and clears this after each frame).
    touched: tuple[np.ndarray, ...] = ()
    # (the id array it was built from, id -> row table or None): see _bulk_rows.
    rows_by_id: Any = field(default=None, repr=False, compare=False)

    def __len__(self) -> int:
        return int(self.id.size)

    def columns(self, rows: np.ndarray | slice = slice(None)) -> dict[str, np.ndarray]:
        return {f: getattr(self, f)[rows].copy() for f in LIGHT_FIELDS}

    @staticmethod
    def validate(given: dict[str, Any], base: dict[str, np.ndarray] | None, n: int
                 ) -> dict[str, np.ndarray]:
        """Checks the fields in table order and returns the columns. In an update,
        ``base`` holds the rows' stored values (a _StoredRows, which reads them when a rule
        does) and is returned, the given fields written into it.

        In an update, a rule runs only when one of the fields it reads was given: the
        stored rows passed every rule when they were written, so a rule over stored values
        alone cannot fail, and the first failing rule is the same as with every rule run
        (with every rule run, validating an update of positions only was most of a
        service frame's ``update_lights``)."""
        unknown = [k for k in given if k not in LIGHT_FIELDS]
        if unknown:
            raise ValidationError(unknown[0], None, "unknown light field")
        sent = {k for k, v in given.items() if v is not None}

        def due(*reads: str) -> bool:
            return base is None or not sent.isdisjoint(reads)

        cols: dict[str, np.ndarray] = {} if base is None else base
        kinds = {"id": "i", "type": "i", "position": "f", "radius": "f", "direction": "f",
                 "outer_angle": "f", "inner_angle": "f", "intensity": "f", "priority": "f",
                 "shadows": "b", "mask": "i"}
        widths = {"position": 3, "direction": 3}
        for name in LIGHT_FIELDS:
            if name in given and given[name] is not None:
                cols[name] = _parse(name, given[name], n, kinds[name], widths.get(name, 0))
            if name == "id":
                if base is None:
                    cols["id"] = _check_ids(cols["id"])
            elif name == "type":
                if "type" not in cols:
                    cols["type"] = np.zeros(n, np.uint8)
                if due("type"):
                    t = cols["type"]
                    bad = _first_bad((t < 0) | (t > 2))
                    if bad is not None:
                        raise ValidationError("type", bad, "unknown light type "
                                              "(0 point, 1 spot, 2 directional)")
                    cols["type"] = t.astype(np.uint8)
            elif name in ("position", "radius"):
                if name not in cols:
                    bad = _first_bad(cols["type"] != DIRECTIONAL)
                    if bad is not None:
                        raise ValidationError(name, bad, "required for point and spot lights")
                    cols[name] = np.zeros((n, 3)) if name == "position" else np.zeros(n)
                if name == "radius" and due("type", "radius"):
                    bad = _first_bad((cols["type"] != DIRECTIONAL) & ~(cols["radius"] > 0.0))
                    if bad is not None:
                        raise ValidationError("radius", bad, "must be > 0 on point and spot lights")
            elif name == "direction":
                if "direction" not in cols:
                    bad = _first_bad(cols["type"] != POINT)
                    if bad is not None:
                        raise ValidationError("direction", bad, "required for spot and directional lights")
                    cols["direction"] = np.zeros((n, 3))
                if due("type", "direction"):
                    # Judged by |d| = sqrt(x*x + y*y + z*z): a length that under- or
                    # overflows cannot be normalised (rows that ignore direction keep it
                    # as given).
                    norm = _norm3(cols["direction"])
                    bad = _first_bad((cols["type"] != POINT) & ~((norm > 0.0) & (norm < np.inf)))
                    if bad is not None:
                        raise ValidationError("direction", bad, "must have a non-zero length "
                                              "that sqrt(x*x + y*y + z*z) can represent")
                if "direction" in given:
                    cols["direction"] = _normalise(cols["direction"])
            elif name == "outer_angle":
                if "outer_angle" not in cols:
                    cols["outer_angle"] = np.full(n, math.pi / 4)
                if due("type", "outer_angle"):
                    o = cols["outer_angle"]
                    bad = _first_bad((cols["type"] == SPOT) & ~((o > 0.0) & (o < math.pi / 2)))
                    if bad is not None:
                        raise ValidationError("outer_angle", bad, "must be in (0, pi/2) on spot lights")
            elif name == "inner_angle":
                if "inner_angle" not in cols:
                    cols["inner_angle"] = 0.8 * cols["outer_angle"]
                if due("type", "outer_angle", "inner_angle"):
                    inner = cols["inner_angle"]
                    bad = _first_bad((cols["type"] == SPOT)
                                     & ~((inner >= 0.0) & (inner <= cols["outer_angle"])))
                    if bad is not None:
                        raise ValidationError("inner_angle", bad,
                                              "must be in [0, outer_angle] on spot lights")
            elif name == "intensity":
                if "intensity" not in cols:
                    cols["intensity"] = np.ones(n)
                if due("intensity"):
                    bad = _first_bad(cols["intensity"] < 0.0)
                    if bad is not None:
                        raise ValidationError("intensity", bad, "must be >= 0")
            elif name == "priority":
                if "priority" not in cols:
                    cols["priority"] = np.zeros(n)
            elif name == "shadows":
                if "shadows" not in cols:
                    cols["shadows"] = np.zeros(n, np.bool_)
            elif name == "mask":
                if "mask" not in cols:
                    cols["mask"] = np.full(n, UINT32_MAX, np.uint32)
                elif due("mask"):
                    cols["mask"] = _check_mask("mask", cols["mask"])
        return cols

    def assign(self, cols: dict[str, np.ndarray]) -> None:
        order = np.argsort(cols["id"], kind="stable")
        for f in LIGHT_FIELDS:
            setattr(self, f, np.ascontiguousarray(cols[f][order]))
        self.touched = ()  # rows are renumbered: a scheduler compares ids instead
        self.version += 1


@dataclass
class ObjectStore:
    """Objects as structure of arrays, rows in ascending id (DESIGN section 1, Object).

    ``state`` holds per-row arrays owned by a scheduler (fade slots, last frame's selection);
    they follow their ids through set_/remove_ calls. ``is_new`` marks rows added since the
    last frame (an id removed and set again counts as new).
    """

    id: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int32))
    bounds_min: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    bounds_max: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    casts_shadows: np.ndarray = field(default_factory=lambda: np.zeros(0, np.bool_))
    mask: np.ndarray = field(default_factory=lambda: np.zeros(0, np.uint32))
    static: np.ndarray = field(default_factory=lambda: np.zeros(0, np.bool_))
    is_new: np.ndarray = field(default_factory=lambda: np.zeros(0, np.bool_))
    state: dict[str, tuple[np.ndarray, Any]] = field(default_factory=dict)
    version: int = 0
    # Rows that update_objects calls wrote since the last frame (see LightStore.touched).
    touched: tuple[np.ndarray, ...] = ()
    # Ids that update_objects calls named since the last frame, whatever the values (DESIGN
    # section 2, "Dirty": a re-sent caster dirties its shadow views); kept through set_ and
    # remove_ calls, which renumber rows but not ids.
    named: tuple[np.ndarray, ...] = ()
    # (the id array it was built from, id -> row table or None): see _bulk_rows.
    rows_by_id: Any = field(default=None, repr=False, compare=False)

    def __len__(self) -> int:
        return int(self.id.size)

    def add_state(self, name: str, tail: tuple[int, ...], dtype: Any, fill: Any) -> None:
        self.state[name] = (np.full((len(self),) + tail, fill, dtype=dtype), fill)

    def get(self, name: str) -> np.ndarray:
        return self.state[name][0]

    def put(self, name: str, value: np.ndarray) -> None:
        self.state[name] = (value, self.state[name][1])

    @staticmethod
    def validate(given: dict[str, Any], base: dict[str, np.ndarray] | None, n: int
                 ) -> dict[str, np.ndarray]:
        """Checks the fields in table order and returns the columns; ``base`` as in
        LightStore.validate."""
        unknown = [k for k in given if k not in OBJECT_FIELDS]
        if unknown:
            raise ValidationError(unknown[0], None, "unknown object field")
        kinds = {"id": "i", "bounds_min": "f", "bounds_max": "f", "casts_shadows": "b",
                 "mask": "i", "static": "b"}
        # In an update, as in LightStore.validate, only the rules over a given field run.
        sent = {k for k, v in given.items() if v is not None}
        cols: dict[str, np.ndarray] = {} if base is None else base
        for name in OBJECT_FIELDS:
            if name in sent:
                cols[name] = _parse(name, given[name], n, kinds[name],
                                    3 if name.startswith("bounds") else 0)
            if name == "id":
                if base is None:
                    cols["id"] = _check_ids(cols["id"])
            elif name in ("bounds_min", "bounds_max") and name not in cols:
                raise ValidationError(name, None, "required")
            elif name == "bounds_max":
                if base is None or not sent.isdisjoint(("bounds_min", "bounds_max")):
                    bad = _first_bad(cols["bounds_min"] > cols["bounds_max"])
                    if bad is not None:
                        raise ValidationError("bounds_min", bad, "must be <= bounds_max")
            elif name == "casts_shadows":
                if "casts_shadows" not in cols:
                    cols["casts_shadows"] = np.ones(n, np.bool_)
            elif name == "mask":
                if "mask" not in cols:
                    cols["mask"] = np.full(n, UINT32_MAX, np.uint32)
                elif base is None or "mask" in sent:
                    cols["mask"] = _check_mask("mask", cols["mask"])
            elif name == "static":
                if "static" not in cols:
                    cols["static"] = np.zeros(n, np.bool_)
        return cols

    def assign(self, cols: dict[str, np.ndarray]) -> None:
        """Replaces the object set; per-row state of kept ids survives."""
        order = np.argsort(cols["id"], kind="stable")
        new_ids = cols["id"][order]
        old_ids = self.id
        pos = np.searchsorted(old_ids, new_ids)
        pos_c = np.minimum(pos, max(old_ids.size - 1, 0))
        kept = (pos < old_ids.size) & (old_ids[pos_c] == new_ids) if old_ids.size else \
            np.zeros(new_ids.size, dtype=bool)
        for name, (arr, fill) in self.state.items():
            new = np.full((new_ids.size,) + arr.shape[1:], fill, dtype=arr.dtype)
            new[kept] = arr[pos_c[kept]]
            self.state[name] = (new, fill)
        new_flag = np.ones(new_ids.size, np.bool_)
        new_flag[kept] = self.is_new[pos_c[kept]]
        for f in OBJECT_FIELDS:
            setattr(self, f, np.ascontiguousarray(cols[f][order]))
        self.is_new = new_flag
        self.touched = ()  # rows are renumbered: a scheduler compares ids instead
        self.version += 1

    def keep_rows(self, keep: np.ndarray) -> None:
        for f in OBJECT_FIELDS:
            setattr(self, f, getattr(self, f)[keep])
        self.is_new = self.is_new[keep]
        for name, (arr, fill) in self.state.items():
            self.state[name] = (arr[keep], fill)
        self.touched = ()
        self.version += 1


def _call_rows(fields: dict[str, Any]) -> int:
    """Rows of a set_ call: the length of its (required) id array."""
    if fields.get("id") is None:
        raise ValidationError("id", None, "required")
    return _len_of("id", fields["id"])


class _StoredRows(dict):
    """An update's columns for its validation: the fields it gives, set by the validator,
    and the stored values of the rows it names for the others, read on first use. A rule
    runs only when a field it reads was given (the stored rows passed every rule when they
    were written), so an update of positions reads no other column: gathering all eleven
    light columns was most of such an update (bench/updates.py)."""

    def __init__(self, store: Any, rows: np.ndarray, names: tuple[str, ...]) -> None:
        super().__init__()
        self._store, self._rows, self._names = store, rows, names

    def __missing__(self, name: str) -> np.ndarray:
        value = self[name] = getattr(self._store, name)[self._rows]
        return value

    def __contains__(self, name: object) -> bool:
        return name in self._names or dict.__contains__(self, name)


def _put_rows(dst: np.ndarray, rows: np.ndarray, src: np.ndarray) -> None:
    """dst[rows] = src. Rows of a 2-D array (positions, directions, bounds) are moved as
    one opaque item each: numpy's row-wise fancy assignment is slower."""
    if (dst.ndim == 2 and src.dtype == dst.dtype and src.flags.c_contiguous
            and dst.flags.c_contiguous):
        row = np.dtype((np.void, dst.shape[1] * dst.itemsize))
        dst.view(row).reshape(-1)[rows] = src.view(row).reshape(-1)
    else:
        dst[rows] = src


def _update(store: Any, validate: Any, names: tuple[str, ...], fields: dict[str, Any],
            what: str) -> None:
    """update_ of some fields by id: validates the merged rows, then writes them."""
    ids, rows = _id_rows(store, fields.pop("id", None), what)
    given = [f for f in names[1:] if fields.get(f) is not None]
    cols = validate(fields, _StoredRows(store, rows, names), ids.size)
    # Every row, in row order (a game that sends every light each frame): the validated
    # columns are the new arrays, with no copy of the old ones to write them into.
    n = store.id.size
    every_row = rows.size == n and n > 0 and bool((rows[1:] > rows[:-1]).all())
    # Only given fields can change (validate takes the others from the rows as they are).
    for f in given:
        # Copy on write: a store's arrays are never changed in place, so a shallow copy of
        # the store is a snapshot (SceneAPI.apply rolls back to one), and a scheduler can
        # keep last frame's arrays to see which rows changed. (Validated columns are the
        # validator's own arrays, never the caller's.)
        old, new = getattr(store, f), cols[f]
        if every_row and new.dtype == old.dtype and new.flags.c_contiguous:
            arr = new
        else:
            arr = old.copy()
            _put_rows(arr, rows, new)
        setattr(store, f, arr)
    store.touched = store.touched + (rows,)
    if what == "object":
        store.named = store.named + (ids,)
    store.version += 1


def _keep_mask(store: Any, ids: Any, what: str) -> np.ndarray:
    """Rows that a remove_ call keeps (every id must exist)."""
    _, rows = _id_rows(store, ids, what)
    keep = np.ones(store.id.size, bool)
    keep[rows] = False
    return keep


def _shallow_copy(store: Any) -> Any:
    """A store's shallow copy (what copy.copy gives, without its __reduce_ex__ round)."""
    new = object.__new__(type(store))
    new.__dict__.update(store.__dict__)
    return new


class SceneAPI:
    """The set_/update_/remove_/frame surface of DESIGN section 7, shared by the fast
    Scheduler and the oracle's; subclasses implement ``_frame``.

    Every call validates everything first and only then mutates, so a rejected call
    leaves the scheduler exactly as it was.
    """

    def __init__(self, config: Config | None = None) -> None:
        if config is None:
            config = Config()
        if not isinstance(config, Config):
            raise ValidationError("config", None, "must be a lightsched.Config")
        self.config = config
        self.lights = LightStore()
        self.objects = ObjectStore()
        self.frame_index = 0
        # Buffers ``transaction`` copies the per-object state into, by state name.
        self._spare_state: dict[str, np.ndarray] = {}

    # lights
    def set_lights(self, **fields: Any) -> None:
        self.lights.assign(LightStore.validate(fields, None, _call_rows(fields)))

    def update_lights(self, **fields: Any) -> None:
        _update(self.lights, LightStore.validate, LIGHT_FIELDS, fields, "light")

    def remove_lights(self, id: Any) -> None:  # noqa: A002 - DESIGN's keyword
        keep = _keep_mask(self.lights, id, "light")
        self.lights.assign(self.lights.columns(keep))

    # objects
    def set_objects(self, **fields: Any) -> None:
        self.objects.assign(ObjectStore.validate(fields, None, _call_rows(fields)))

    def update_objects(self, **fields: Any) -> None:
        _update(self.objects, ObjectStore.validate, OBJECT_FIELDS, fields, "object")

    def remove_objects(self, id: Any) -> None:  # noqa: A002 - DESIGN's keyword
        self.objects.keep_rows(_keep_mask(self.objects, id, "object"))

    def apply(self, changes: Iterable[tuple[str, dict[str, Any]]]) -> None:
        """Runs a batch of scene changes, (method name, keyword fields) with the names of
        CHANGE_OPS, in order and all or nothing: when one is rejected, its ValidationError
        is raised with the position of the change in ``position`` and the scene is as it
        was before the first (the service's frame request carries such a batch)."""
        saved = self.snapshot()
        for i, (op, given) in enumerate(changes):
            try:
                if op not in CHANGE_OPS:
                    raise ValidationError("op", None, f"unknown change {op!r}; one of "
                                          + ", ".join(CHANGE_OPS))
                if not isinstance(given, dict):
                    raise ValidationError("fields", None, "must be a mapping of field arrays")
                getattr(self, op)(**given)
            except ValidationError as e:
                self.restore(saved)
                e.position = i
                raise
            except Exception:
                self.restore(saved)
                raise

    def snapshot(self) -> tuple[LightStore, ObjectStore]:
        """The scene as it is now, for ``restore``: shallow copies, as cheap as a few
        references, because no call changes a store's arrays in place."""
        objects = _shallow_copy(self.objects)
        objects.state = dict(self.objects.state)
        return _shallow_copy(self.lights), objects

    def restore(self, saved: tuple[LightStore, ObjectStore]) -> None:
        """Puts back a ``snapshot`` (the scene, not the frame state of frames since)."""
        self.lights, self.objects = saved

    def _memory(self) -> Any:
        """What a subclass keeps from frame to frame beside the stores, for ``_put_back``
        when a transaction fails (nothing here)."""
        return None

    def _put_back(self, memory: Any) -> None:
        """Puts back (or drops, when it cannot be trusted) what ``_memory`` returned."""

    @contextlib.contextmanager
    def transaction(self) -> Iterator[None]:
        """Scene changes and frames inside happen all or nothing: when the block raises, the
        scene, the per-object state, the config and the frame index are put back as they
        were, and the exception goes on (the service runs each request in one).

        Stores copy on write, so references keep most of it. The per-object state arrays a
        frame writes in place (the writeable ones; read-only ones are replaced whole) are
        copied, into buffers kept from the last transaction: a 10k-object scene with K = 8
        copies ~1 MB. What a subclass keeps beside the stores (last frame's
        shadowed set, a cache) it puts back or drops through ``_memory`` and
        ``_put_back``, so a block may also raise after its frame returned."""
        memory = self._memory()
        lights, objects = self.snapshot()
        frame_index, config = self.frame_index, self.config
        spare, self._spare_state = self._spare_state, {}
        copied: dict[str, np.ndarray] = {}
        for name, (arr, fill) in objects.state.items():
            if arr.flags.writeable:
                buf = spare.get(name)
                if buf is None or buf.shape != arr.shape or buf.dtype != arr.dtype:
                    buf = np.empty_like(arr)
                np.copyto(buf, arr)
                objects.state[name] = (buf, fill)
                copied[name] = buf
        try:
            yield
        except BaseException:
            self.restore((lights, objects))
            self.frame_index, self.config = frame_index, config
            self._put_back(memory)
            raise
        # Nothing else references the copies: the next transaction copies into them.
        self._spare_state = copied

    def frame(self, cameras: Any, dt: float = 1.0 / 60.0, cut: bool = False) -> Any:
        """Steps one frame (DESIGN section 2) and returns its Frame (section 3)."""
        cams = validate_cameras(cameras)
        dt_ = validate_dt(dt)
        if not isinstance(cut, (bool, np.bool_)):
            raise ValidationError("cut", None, "must be a boolean")
        result = self._frame(cams, dt_, bool(cut))
        self.lights.touched = ()
        self.objects.touched = ()
        self.objects.named = ()
        # Replaced, not cleared in place: a snapshot (``transaction``) may share the array.
        if self.objects.is_new.any():
            self.objects.is_new = np.zeros_like(self.objects.is_new)
        self.frame_index += 1
        return result

    def _frame(self, cameras: list[Camera], dt: float, cut: bool) -> Any:
        raise NotImplementedError
