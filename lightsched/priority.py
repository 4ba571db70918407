"""The Affects test and the two priority models (DESIGN section 2, "Affects", "Priority").

Takes a packed light row (see ``pack_lights``) and an object's box; returns whether the light
affects the object and the pair's priority P, as pieces: ``box_d2`` (the range test is
d2 <= r*r), ``spot_cone`` (cone test and spot factor s), ``falloff`` (contribution:
P = falloff * s + p_user), ``thesis`` (Eriksson eq. 3.1); directional lights have
P = i + p_user. walk.light_pass composes them per pair; this module owns the rules.

Packed lights, two float64 row arrays, so that a point light's whole pair computation
reads one 64-byte record: ``light_hot[L, 8]``: 0-2 position, 3 radius, 4 mask, 5 code =
row * 32 + type * 8, 6 intensity i, 7 user priority p_user (all exact in float64);
``light_f[L, 8]``: 0-2 axis (normalised direction), 3 cos(outer), 4 sin(outer),
5 cos(inner), 6 id, 7 thesis camera term A. Spot lights with inner == outer (or whose
cosines round equal) get cos(inner) = NaN, which selects the step profile; other lights
have no cone: 1, 0, NaN there, never read.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, NamedTuple

import numba as nb
import numpy as np

from .frustum import SERIAL_LIGHTS, CameraFrames
from .jit import PRANGE_ONLY
from .scene import DIRECTIONAL, SPOT, Config, LightStore

if TYPE_CHECKING:
    from .plan import FramePlan

R0 = 0.1  # metres: keeps the contribution finite when a light sits on the object
MODEL_CONTRIBUTION, MODEL_THESIS = 0, 1


class PairParams(NamedTuple):
    """What a pair's P needs beside the light and the object (DESIGN section 2,
    "Priority"): the model and the thesis model's weights."""

    model: int    # MODEL_CONTRIBUTION or MODEL_THESIS
    w_obj: float
    w_int: float

    @staticmethod
    def of(config: Config) -> PairParams:
        return PairParams(MODEL_CONTRIBUTION if config.model == "contribution" else MODEL_THESIS,
                          float(config.w_obj), float(config.w_int))
CACHE_LINE = 64  # bytes


def aligned_empty(shape: int | tuple[int, ...], dtype: object = np.float64) -> np.ndarray:
    """An uninitialised C-order array that starts on a cache line. numpy gives 16 bytes of
    alignment (a large array: a page plus malloc's 16-byte header) and numba's allocator
    32, so a 64-byte row (a packed light, an object record) would straddle two lines and
    every row read at random (a candidate list's lights, a spot's hits) would miss twice."""
    dt = np.dtype(dtype)
    size = math.prod((shape,) if isinstance(shape, int) else shape) * dt.itemsize
    buf = np.empty(size + CACHE_LINE, np.uint8)
    at = -buf.ctypes.data % CACHE_LINE
    return buf[at:at + size].view(dt).reshape(shape)


# The parts of a packed row, each written from its own fields (``pack_parts``): an update
# of some fields rewrites only their parts, and a row's light_f line not at all when none of
# its parts changed (moving lights: the hot line only).
PACK_POSITION = 1  # light_hot 0-2: position - origin
PACK_SCALARS = 2  # light_hot 3-7: radius, mask, row and type, intensity, p_user
PACK_AXIS = 4  # light_f 0-2
PACK_CONE = 8  # light_f 3-5: the spot cone's two cosines and sine
PACK_ID = 16  # light_f 6
PACK_CAMERA = 32  # light_f 7: the thesis camera term
PACK_ALL = 63
_FIELD_PARTS = {"type": PACK_SCALARS | PACK_CONE | PACK_CAMERA, "position": PACK_POSITION,
                "radius": PACK_SCALARS, "direction": PACK_AXIS, "outer_angle": PACK_CONE,
                "inner_angle": PACK_CONE, "intensity": PACK_SCALARS,
                "priority": PACK_SCALARS, "mask": PACK_SCALARS, "id": PACK_ID}


def pack_parts(fields: list[str], camera_term: bool) -> int:
    """The parts of a packed row that depend on the light ``fields`` (names of the light
    store's; "shadows" is not packed). The thesis camera term also reads the position and
    the radius."""
    parts = 0
    for f in fields:
        parts |= _FIELD_PARTS.get(f, 0)
        if camera_term and f in ("position", "radius"):
            parts |= PACK_CAMERA
    return parts


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _pack_cone(j, lf, typ, outer, inner):
    if typ[j] == SPOT:
        lf[j, 3] = math.cos(outer[j])
        lf[j, 4] = math.sin(outer[j])
        cos_i = math.cos(inner[j])
        # The step profile: inner == outer, or so close that the cosines are equal.
        lf[j, 5] = cos_i if inner[j] != outer[j] and cos_i != lf[j, 3] else np.nan
    else:
        # Only a spot light's cone is read (its type is packed with it): the three
        # cosines and sines were most of the time of packing the lights.
        lf[j, 3] = 1.0
        lf[j, 4] = 0.0
        lf[j, 5] = np.nan


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _pack_row(j, hot, lf, typ, position, radius, direction, outer, inner, intensity, prio,
              mask, ids, cam_pos, cam_basis, cam_tan, cam_focus, thesis_w, origin, parts):
    # The arrays come one by one, not as _pack's tuples: a tuple unpacked once a row kept
    # its reference counting in the loop, 20 atomic operations a light on counts both
    # threads share, which cost several times the packing itself.
    if parts & PACK_POSITION:
        for k in range(3):
            hot[j, k] = position[j, k] - origin[k]
    if parts & PACK_SCALARS:
        hot[j, 3] = radius[j]
        hot[j, 4] = mask[j]
        hot[j, 5] = j * 32 + typ[j] * 8
        hot[j, 6] = intensity[j]
        hot[j, 7] = prio[j]
    if parts & PACK_AXIS:
        for k in range(3):
            lf[j, k] = direction[j, k]
    if parts & PACK_CONE:
        _pack_cone(j, lf, typ, outer, inner)
    if parts & PACK_ID:
        lf[j, 6] = ids[j]
    if parts & PACK_CAMERA:
        best = 0.0
        if typ[j] != DIRECTIONAL:
            best = -np.inf
            for c in range(cam_pos.shape[0]):
                a = thesis_camera_term(position[j], radius[j], cam_pos[c], cam_basis[c],
                                       cam_tan[c], cam_focus[c], thesis_w[0], thesis_w[1],
                                       thesis_w[2])
                if a > best:
                    best = a
        lf[j, 7] = best


@nb.njit(cache=True, nogil=True, parallel=PRANGE_ONLY, error_model="numpy")
def _pack(rows, store, cams, thesis_w, origin, out, parts):
    """store = the light store's (type, position, radius, direction, outer_angle,
    inner_angle, intensity, priority, mask, id); cams = the cameras' (position, basis,
    tan_xy, focus), zero cameras for the contribution model (column 7 stays -inf);
    out = (hot, lf), [L, 8] each: the ``parts`` (PACK_* bits) of the light rows ``rows``
    written (of every row when it is None)."""
    hot, lf = out
    typ, position, radius, direction, outer, inner, intensity, prio, mask, ids = store
    cam_pos, cam_basis, cam_tan, cam_focus = cams
    n = typ.shape[0] if rows is None else rows.shape[0]
    if n < SERIAL_LIGHTS:
        for t in range(n):
            j = np.int64(t) if rows is None else np.int64(rows[t])
            _pack_row(j, hot, lf, typ, position, radius, direction, outer, inner, intensity,
                      prio, mask, ids, cam_pos, cam_basis, cam_tan, cam_focus, thesis_w,
                      origin, parts)
    else:
        for t in nb.prange(n):
            j = np.int64(t) if rows is None else np.int64(rows[t])
            _pack_row(j, hot, lf, typ, position, radius, direction, outer, inner, intensity,
                      prio, mask, ids, cam_pos, cam_basis, cam_tan, cam_focus, thesis_w,
                      origin, parts)
    return hot, lf


def light_columns(lights: LightStore) -> tuple[np.ndarray, ...]:
    """The store's columns ``_pack`` reads, in its order."""
    return (lights.type, lights.position, lights.radius, lights.direction, lights.outer_angle,
            lights.inner_angle, lights.intensity, lights.priority, lights.mask, lights.id)


class PackedLights(NamedTuple):
    """The lights in the packed layout above, [L, 8] float64 each, by light row."""

    hot: np.ndarray  # light_hot: what the range test and the contribution model read
    f: np.ndarray    # light_f: the spot cone, id and the thesis camera term


def pack_lights(lights: LightStore, frames: CameraFrames, w_ecc: float, w_dist: float,
                c1: float, camera_term: bool = True, origin: np.ndarray | None = None,
                into: tuple[PackedLights, np.ndarray | None] | None = None,
                parts: int = PACK_ALL) -> PackedLights:
    """Packs the light store into the row layout above (one cache-friendly row per light).
    Without ``camera_term`` (the contribution model, which does not read it) light_f
    column 7 is -inf: the eccentricity is the packing's costliest part. Positions are
    relative to ``origin`` (the object records' frame; 0 in exact precision, where x - 0
    is x). ``into`` = (last frame's packed lights of the same light rows, the rows that
    changed or None for every row): only those rows are packed again, in place, and of
    them only the ``parts`` (``pack_parts``) that changed; the rest (other rows and parts,
    the cameras where they count, the origin) as they were."""
    cams = slice(None) if camera_term else slice(0)
    cam_columns = (frames.position[cams], frames.basis[cams], frames.tan_xy[cams],
                   frames.focus[cams])
    if into is None:
        # One buffer for both: rows of 64 bytes, so light_f starts on a cache line too.
        out = aligned_empty((2, len(lights.id), 8))
        packed, rows, parts = PackedLights(out[0], out[1]), None, PACK_ALL
    else:
        packed, rows = into
    return PackedLights(*_pack(rows, light_columns(lights), cam_columns, np.array([w_ecc, w_dist, c1]),
                 np.zeros(3) if origin is None else origin, packed,
                                np.int64(parts)))


@dataclass(slots=True)
class Packed:
    """The pack stage's output: the lights as packed rows (``rows`` = (light_hot,
    light_f), above) relative to ``origin`` (the object records' frame); which lights
    compete for slots (visible, and not directional unless directional_in_slots); which
    are directional (``is_dir``, and their rows ``dir_all``, a few)."""

    rows: PackedLights
    origin: np.ndarray
    compete: np.ndarray
    is_dir: np.ndarray
    dir_all: np.ndarray


def pack(plan: FramePlan, last: Packed | None, lights: LightStore, frames: CameraFrames,
         config: Config, visible: np.ndarray, light_rows: np.ndarray | None) -> Packed:
    """The pack stage: every light packed, or only the parts of the changed rows
    (``light_rows``) that read a field whose array changed, in last frame's arrays (moving
    lights: the position only, one line a light), or last frame's kept, as the plan says.
    ``visible``: the lights' visibility."""
    if plan.packing == "kept":
        rows = last.rows
    else:
        into = None
        if plan.pack_into_last:
            into = (last.rows, None if plan.packing == "all" else light_rows.astype(np.int64))
        rows = pack_lights(lights, frames, config.w_ecc, config.w_dist, config.c1,
                           config.model == "thesis", plan.origin, into=into,
                           parts=plan.pack_parts)
    is_dir = lights.type == DIRECTIONAL
    # Pairs are found for every visible light: the shadow ranking needs to know which
    # shadowed lights affect a visible object before "skip" removes the others.
    compete = visible & (~is_dir if not config.directional_in_slots else True)
    return Packed(rows, plan.origin, compete, is_dir, np.flatnonzero(is_dir))


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def berka_eccentricity(v0, v1, v2, d_viewer, r, basis, tan_xy, focus, c1):
    """Berka's eccentricity f (DESIGN section 2, "Priority", the thesis model; shadow importance uses it too)
    of a light at v = p - camera position, d_viewer = |v|: 1 if d_viewer <= r, else
    1 if theta <= alpha, else exp(-(theta - alpha)/c1), alpha = asin(min(1, r/d_viewer)),
    theta = atan2(|g x v|, g . v), g the focal ray f + (x t_x) r + (y t_y) u."""
    if d_viewer <= r:
        return 1.0
    sx = focus[0] * tan_xy[0]
    sy = focus[1] * tan_xy[1]
    g0 = basis[0, 0] + sx * basis[1, 0] + sy * basis[2, 0]
    g1 = basis[0, 1] + sx * basis[1, 1] + sy * basis[2, 1]
    g2 = basis[0, 2] + sx * basis[1, 2] + sy * basis[2, 2]
    x0 = g1 * v2 - g2 * v1
    x1 = g2 * v0 - g0 * v2
    x2 = g0 * v1 - g1 * v0
    theta = math.atan2(math.sqrt(x0 * x0 + x1 * x1 + x2 * x2), g0 * v0 + g1 * v1 + g2 * v2)
    alpha = math.asin(min(1.0, r / d_viewer))
    return 1.0 if theta <= alpha else math.exp(-(theta - alpha) / c1)


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def thesis_camera_term(p, r, cam_p, basis, tan_xy, focus, w_ecc, w_dist, c1):
    """w_ecc f + w_dist d_viewer for one camera (Eriksson eq. 3.1, Berka's eccentricity).

    The rest of eq. 3.1 does not depend on the camera and rounding is monotone, so the
    max over cameras of the whole sum equals the sum built on the max of this term.

    p: the light's position f64[3]; r: its radius; cam_p: the camera's position f64[3];
    basis [3, 3] (rows f, r, u), tan_xy (t_x, t_y), focus (x, y): CameraFrames' row;
    w_ecc, w_dist, c1: Config's. DESIGN section 2, "Priority" (the "thesis" model).
    """
    v0 = p[0] - cam_p[0]
    v1 = p[1] - cam_p[1]
    v2 = p[2] - cam_p[2]
    d_viewer = math.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
    f = berka_eccentricity(v0, v1, v2, d_viewer, r, basis, tan_xy, focus, c1)
    return w_ecc * f + w_dist * d_viewer


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def box_d2(boxes, i, p0, p1, p2):
    """Squared distance from p to box i of boxes [n, 6] (lo, hi): delta_k = max(lo_k - p_k,
    0, p_k - hi_k), d2 = dx*dx + dy*dy + dz*dz. Records [n, 8] too (columns 0-5 read);
    i: the row; p0, p1, p2: the light's position in the boxes' frame. DESIGN section 2,
    "Affects"."""
    dx = max(boxes[i, 0] - p0, 0.0, p0 - boxes[i, 3])
    dy = max(boxes[i, 1] - p1, 0.0, p1 - boxes[i, 4])
    dz = max(boxes[i, 2] - p2, 0.0, p2 - boxes[i, 5])
    return dx * dx + dy * dy + dz * dz


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def falloff(i, r, d2, e2):
    """i*w*w*g/(d2 + r0*r0) of the contribution model: q = d2/(r*r), w = max(0, 1 - q*q),
    g = min(1, 4 r*r / e2) (1 for e2 = 0). P = falloff * s + p_user.

    g skips its division when 4 r*r >= e2: a correctly rounded a/b with a >= b > 0 is >= 1,
    so min(1, a/b) is exactly 1 (most objects are small beside the light's range).
    i: intensity; r: radius; d2: box_d2's; e2 = |hi - lo|^2; all float64. DESIGN
    section 2, "Priority" (the "contribution" model)."""
    q = d2 / (r * r)
    w = max(0.0, 1.0 - q * q)
    a = 4.0 * r * r
    g = 1.0 if e2 == 0.0 or a >= e2 else min(1.0, a / e2)
    return i * w * w * g / (d2 + R0 * R0)


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def spot_cone(hot, lf, j, geo, contribution):
    """(meets, s) of spot row j and the object's bounding sphere geo = (c0, c1, c2, R, e2):
    the one-nappe cone test, and the spot factor s of the contribution model (1 when not
    needed). c is the cosine of the smallest angle from the axis to the sphere. hot, lf:
    priority.PackedLights' [L, 8] rows; j: the light's row; geo as record_geometry gives
    it; contribution: bool, whether s is needed. DESIGN section 2, "Affects" (the cone
    test) and "Priority" (the spot factor s)."""
    v0 = geo[0] - hot[j, 0]
    v1 = geo[1] - hot[j, 1]
    v2 = geo[2] - hot[j, 2]
    big_r = geo[3]
    n = math.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
    a = v0 * lf[j, 0] + v1 * lf[j, 1] + v2 * lf[j, 2]
    sq = math.sqrt(max(n * n - big_r * big_r, 0.0))
    if not (n <= big_r or a >= lf[j, 3] * sq - big_r * lf[j, 4]):
        return False, 0.0
    if not contribution:
        return True, 1.0
    if n <= big_r or a >= sq or n * n == 0.0:
        c = 1.0  # (n*n == 0 only when n*n underflows: the light is on the centre)
    else:
        c = (a * sq + big_r * math.sqrt(max(n * n - a * a, 0.0))) / (n * n)
    if math.isnan(lf[j, 5]):
        return True, 1.0 if c >= lf[j, 3] else 0.0
    t = (c - lf[j, 3]) / (lf[j, 5] - lf[j, 3])
    t = min(max(t, 0.0), 1.0)
    return True, t * t


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def thesis(hot, lf, j, geo, w_obj, w_int):
    """Eriksson eq. 3.1 with the camera term A = max over cameras (light_f column 7):
    P = A + w_obj d_object + w_int i + p_user, d_object = |p - c|. hot, lf, j, geo as
    spot_cone's; w_obj, w_int: PairParams'. DESIGN section 2, "Priority" (the "thesis"
    model)."""
    u0 = hot[j, 0] - geo[0]
    u1 = hot[j, 1] - geo[1]
    u2 = hot[j, 2] - geo[2]
    d_object = math.sqrt(u0 * u0 + u1 * u1 + u2 * u2)
    return lf[j, 7] + w_obj * d_object + w_int * hot[j, 6] + hot[j, 7]


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def residual_term(hot, lf, j, geo):
    """(E_l, u_x, u_y, u_z) of light row j over the object geo = (c0, c1, c2, R, e2) for
    the residual: the light over the whole object, so from the box centre c, not the
    nearest point. Point and spot: v = p - c, dc2 = max(v . v, R*R), q = dc2/(r*r),
    w = max(0, 1 - q*q), E = i*w*w/(dc2 + r0*r0) * s (s: spot_cone's spot factor, 0 off
    the cone), u = v/|v| ((0, 0, 0) when v . v is 0); directional: E = i, u = -direction.
    hot, lf: PackedLights' rows; j: the light's row; geo as record_geometry gives it, in
    the packed rows' frame. DESIGN section 2, "Residual" (its per-light term; the
    object pass's residual_flush sums them)."""
    typ = (np.int64(hot[j, 5]) >> 3) & 3
    if typ == DIRECTIONAL:
        return hot[j, 6], -lf[j, 0], -lf[j, 1], -lf[j, 2]
    v0 = hot[j, 0] - geo[0]
    v1 = hot[j, 1] - geo[1]
    v2 = hot[j, 2] - geo[2]
    vv = v0 * v0 + v1 * v1 + v2 * v2
    dc2 = max(vv, geo[3] * geo[3])
    r2 = hot[j, 3] * hot[j, 3]
    if dc2 >= r2:
        # The centre out of range (q >= 1, so w = 0 and E = 0): most of a city's lights
        # that reach a box past its slots, and the divisions are the term's cost.
        return 0.0, 0.0, 0.0, 0.0
    q = dc2 / r2
    w = max(0.0, 1.0 - q * q)
    e = hot[j, 6] * w * w / (dc2 + R0 * R0)
    if typ == SPOT:
        e = e * spot_cone(hot, lf, j, geo, True)[1]
    # vv = 0 (also when v is so short that its square underflows): no direction.
    inv = 1.0 / math.sqrt(vv) if vv > 0.0 else 0.0
    return e, v0 * inv, v1 * inv, v2 * inv


__all__ = ["MODEL_CONTRIBUTION", "MODEL_THESIS", "box_d2", "falloff", "pack_lights",
           "residual_term", "spot_cone", "thesis"]


# ------------------------------------------------------------- a light and an object record


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def record_pair_p(hot, lf, j, typ, v, d2, vis_box, model, w_obj, w_int):
    """(affects, P) of light j and visible object v once d2 <= r*r holds: the spot cone and
    the model's P (priority.py holds the rules). The bounding sphere (centre (lo + hi)/2,
    R = |hi - lo|/2) is only built when a rule needs it. hot, lf: priority.PackedLights'
    rows; j: the (point or spot) light's row; typ: its type (from light_hot column 5); v: the
    record's row in vis_box (grid.Records.box [V, 8], float64 or float32); d2: box_d2's;
    model: MODEL_*; w_obj, w_int: PairParams'. DESIGN section 2, "Affects" and
    "Priority"."""
    e2 = record_e2(vis_box, v)
    if typ == SPOT or model != MODEL_CONTRIBUTION:
        geo = record_geometry(vis_box, v)
        s = 1.0
        if typ == SPOT:
            meets, s = spot_cone(hot, lf, j, geo, model == MODEL_CONTRIBUTION)
            if not meets:
                return False, 0.0
        if model != MODEL_CONTRIBUTION:
            return True, thesis(hot, lf, j, geo, w_obj, w_int)
        return True, falloff(hot[j, 6], hot[j, 3], d2, e2) * s + hot[j, 7]
    return True, falloff(hot[j, 6], hot[j, 3], d2, e2) + hot[j, 7]


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def record_geometry(box, v):
    """(centre x, y, z, R, e2) of record v: centre (lo + hi)/2, e2 = |hi - lo|^2, R =
    sqrt(e2)/2 (DESIGN "Affects"), in float64 whatever the records' precision (float32 +
    float32 would round in float32). A float64 record holds e2 (loading it was measured
    ~12% of a full frame faster than computing it on every pair); a float32 one cannot
    hold it exactly, so it is computed from the record's coordinates."""
    e2 = record_e2(box, v)
    return ((np.float64(box[v, 0]) + np.float64(box[v, 3])) / 2,
            (np.float64(box[v, 1]) + np.float64(box[v, 4])) / 2,
            (np.float64(box[v, 2]) + np.float64(box[v, 5])) / 2, math.sqrt(e2) / 2, e2)


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def record_e2(box, v):
    """e2 = |hi - lo|^2 of record v of box (records [V, 8]: a float64 one holds it in
    column 7, a float32 one has it computed; see record_geometry). DESIGN section 2,
    "Priority" (e2)."""
    if box.itemsize == 8:
        return np.float64(box[v, 7])
    ex = np.float64(box[v, 3]) - np.float64(box[v, 0])
    ey = np.float64(box[v, 4]) - np.float64(box[v, 1])
    ez = np.float64(box[v, 5]) - np.float64(box[v, 2])
    return ex * ex + ey * ey + ez * ez
