"""Camera frames, frustum planes and visibility (DESIGN section 2, "Camera frame", "Tests",
"Visibility").

Takes validated cameras and the light/object stores; returns per camera the basis (f, r, u),
t_x, t_y and six planes as (inward unit normal, point) pairs, and per light / per object a
visibility flag. Signed distances are n . (x - point) summed x, y, z in that order, so the
results are bit-identical to the oracle and translation-invariant on the 2^-16 m grid.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numba as nb
import numpy as np

from .changes import camera_key, same_key
from .jit import PRANGE_ONLY
from .scene import DIRECTIONAL, Camera


def _normalize(v: tuple[float, float, float]) -> tuple[float, float, float]:
    n = math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
    return (v[0] / n, v[1] / n, v[2] / n)


def _cross(a: tuple[float, ...], b: tuple[float, ...]) -> tuple[float, float, float]:
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


class CameraArrays(NamedTuple):
    """The arrays of a CameraFrames as a kernel takes them (casters._volumes), C cameras."""

    position: np.ndarray  # float64 [C, 3]
    basis: np.ndarray     # float64 [C, 3, 3]: rows f, r, u
    tan_xy: np.ndarray    # float64 [C, 2]: (t_x, t_y)
    plane_n: np.ndarray   # float64 [C, 6, 3]: inward unit normals, near far left right bottom top
    plane_p: np.ndarray   # float64 [C, 6, 3]: a point of each plane, in the same order
    near_far: np.ndarray  # float64 [C, 2]


class CameraFrames:
    """Per camera basis and planes as float64 arrays.

    basis [C, 3, 3] rows f, r, u; tan_xy [C, 2] = (t_x, t_y); position [C, 3];
    plane_n [C, 6, 3] and plane_p [C, 6, 3] in the order near, far, left, right, bottom,
    top; focus [C, 2]; height_px [C]; near_far [C, 2].
    """

    def __init__(self, cameras: list[Camera]) -> None:
        # Plain floats, then one array per field: a frame builds these every call, and
        # numpy's per-call cost would dominate three-element vectors.
        basis, tan_xy, position, plane_n, plane_p = [], [], [], [], []
        for cam in cameras:
            p = tuple(cam.position.tolist())
            f = _normalize(tuple(cam.forward.tolist()))
            r = _normalize(_cross(f, tuple(cam.up.tolist())))
            u = _cross(r, f)
            t_y = math.tan(cam.fov_y / 2)
            t_x = cam.aspect * t_y
            sx = math.sqrt(1 + t_x * t_x)
            sy = math.sqrt(1 + t_y * t_y)
            plane_n.append((f, tuple(-f[i] for i in range(3)),
                            tuple((r[i] + t_x * f[i]) / sx for i in range(3)),
                            tuple((-r[i] + t_x * f[i]) / sx for i in range(3)),
                            tuple((u[i] + t_y * f[i]) / sy for i in range(3)),
                            tuple((-u[i] + t_y * f[i]) / sy for i in range(3))))
            plane_p.append((tuple(p[i] + cam.near * f[i] for i in range(3)),
                            tuple(p[i] + cam.far * f[i] for i in range(3)), p, p, p, p))
            basis.append((f, r, u))
            tan_xy.append((t_x, t_y))
            position.append(p)
        self.basis = np.array(basis)
        self.tan_xy = np.array(tan_xy)
        self.position = np.array(position)
        self.plane_n = np.array(plane_n)
        self.plane_p = np.array(plane_p)
        self.focus = np.array([(float(c.focus[0]), float(c.focus[1])) for c in cameras])
        self.height_px = np.array([float(c.height_px) for c in cameras])
        self.near_far = np.array([(float(c.near), float(c.far)) for c in cameras])

    def __len__(self) -> int:
        return self.position.shape[0]

    def arrays(self) -> CameraArrays:
        """The frames' arrays a kernel reads (the same arrays, not copies)."""
        return CameraArrays(self.position, self.basis, self.tan_xy, self.plane_n, self.plane_p,
                            self.near_far)


@dataclass(slots=True)
class Cameras:
    """The cameras stage's output: every parameter of the cameras as one key
    (changes.camera_key), their frames and cascade_splits, whether they differ from last
    frame's (if not, last frame's frames and splits are these), and the frame's
    camera_ids (int32: last frame's array while they are the same ids)."""

    key: np.ndarray
    frames: CameraFrames
    splits: np.ndarray
    moved: bool
    ids: np.ndarray


def frame_cameras(cameras: list[Camera], last: Cameras | None, cascades: int,
                  shadow_distance: float) -> Cameras:
    """The cameras stage: the frames and splits of ``cameras`` (validated), last frame's
    when they did not move."""
    key = camera_key(cameras)
    if last is not None and same_key(key, last.key):
        return Cameras(key, last.frames, last.splits, False, last.ids)
    ids = camera_ids(cameras)
    if last is not None and ids.tobytes() == last.ids.tobytes():
        ids = last.ids
    return Cameras(key, CameraFrames(cameras),
                   cascade_splits(cameras, cascades, shadow_distance), True, ids)


def camera_ids(cameras: list[Camera]) -> np.ndarray:
    """The ids the frame runs with: a camera's own, or its position in the list."""
    return np.array([k if c.id is None else int(c.id) for k, c in enumerate(cameras)], np.int32)


def cascade_splits(cameras: list[Camera], cascades: int, shadow_distance: float) -> np.ndarray:
    """z_0..z_C per camera: z_i = 0.5 near (D/near)^(i/C) + 0.5 (near + (D - near) i/C),
    D = min(far, shadow_distance) (DESIGN section 2, "Casters", practical split scheme)."""
    out = np.zeros((len(cameras), cascades + 1))
    for k, cam in enumerate(cameras):
        near = float(cam.near)
        d = min(float(cam.far), shadow_distance)
        for i in range(cascades + 1):
            out[k, i] = 0.5 * near * (d / near) ** (i / cascades) + 0.5 * (
                near + (d - near) * i / cascades)
    return out


# objects_visible tests this many boxes at a time, copied into columns (24 KB: L1).
VISIBLE_BLOCK = 512


@nb.njit(cache=True, nogil=True, parallel=PRANGE_ONLY, error_model="numpy")
def objects_visible(bounds_min, bounds_max, plane_n, plane_p):
    """visible[o] iff o's AABB (bounds_min, bounds_max [N, 3]) is in at least one camera
    frustum (plane_n, plane_p [C, 6, 3]; DESIGN section 2, "Visibility", "Tests"): for
    every plane of it, the box's corner farthest along the plane's normal n (hi on an axis
    where n >= 0, lo elsewhere) is at a signed distance >= 0. Also returns the
    bounding box of the visible objects (lo, hi) [6], +-inf when none is visible, from
    per-block boxes so the reduction stays parallel.

    A block of boxes is copied into six columns, then each plane runs over the block with
    its farthest corner's columns chosen once: a loop without branches over contiguous
    columns, which LLVM vectorises (it does not over [N, 3] rows tested box by box with an
    exit at the first failed plane; bench/RESULTS.md, "Measurements behind the code")."""
    n = bounds_min.shape[0]
    out = np.zeros(n, np.bool_)
    n_blocks = (n + VISIBLE_BLOCK - 1) // VISIBLE_BLOCK
    boxes = np.empty((n_blocks, 6))
    for blk in nb.prange(n_blocks):
        a0 = blk * VISIBLE_BLOCK
        size = min(n, a0 + VISIBLE_BLOCK) - a0
        # Columns lo x, y, z, hi x, y, z: the corner along n >= 0 is column a + 3.
        col = np.empty((6, VISIBLE_BLOCK))
        ok = np.empty(VISIBLE_BLOCK, np.bool_)
        vis = np.zeros(VISIBLE_BLOCK, np.bool_)
        for i in range(size):
            for a in range(3):
                col[a, i] = bounds_min[a0 + i, a]
                col[3 + a, i] = bounds_max[a0 + i, a]
        for cam in range(plane_n.shape[0]):
            ok[:size] = True
            for j in range(6):
                _plane_columns(plane_n, plane_p, cam, j, col, size, ok)
            for i in range(size):
                vis[i] = vis[i] | ok[i]
        b = _hull(boxes, 0)
        for i in range(size):
            v = vis[i]
            out[a0 + i] = v
            for a in range(3):
                b[a] = min(b[a], col[a, i] if v else np.inf)
                b[3 + a] = max(b[3 + a], col[3 + a, i] if v else -np.inf)
        boxes[blk] = b
    return out, _hull(boxes, n_blocks)


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _plane_columns(plane_n, plane_p, cam, j, col, size, ok):
    """ok[i] &= box i in columns col ([lo, hi] rows of 6, the first ``size`` taken) passes
    plane j of camera ``cam`` (plane_n, plane_p [C, 6, 3]): its corner farthest along the
    normal (column a + 3 on an axis where n >= 0) at a signed distance n . (x - q), summed
    in x, y, z order, >= 0 (DESIGN section 2, "Tests"). One loop without branches over
    contiguous columns, which LLVM vectorises."""
    n0, n1, n2 = plane_n[cam, j, 0], plane_n[cam, j, 1], plane_n[cam, j, 2]
    q0, q1, q2 = plane_p[cam, j, 0], plane_p[cam, j, 1], plane_p[cam, j, 2]
    c0 = 3 if n0 >= 0.0 else 0
    c1 = 4 if n1 >= 0.0 else 1
    c2 = 5 if n2 >= 0.0 else 2
    for i in range(size):
        d = n0 * (col[c0, i] - q0) + n1 * (col[c1, i] - q1) + n2 * (col[c2, i] - q2)
        ok[i] = ok[i] & (d >= 0.0)




@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _widen(b, boxes, i):
    """b ([lo, hi], 6) widened to hold boxes[i]."""
    for a in range(3):
        b[a] = min(b[a], boxes[i, a])
        b[3 + a] = max(b[3 + a], boxes[i, 3 + a])


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _hull(boxes, k):
    """The box round boxes[:k], +-inf when k is 0 (the reduction of per-part boxes)."""
    b = np.empty(6)
    for a in range(3):
        b[a] = np.inf
        b[3 + a] = -np.inf
    for i in range(k):
        _widen(b, boxes, i)
    return b


# objects_visible_groups deals the groups to this many parallel parts in turn (not
# jit.GROUP_PARTS, the histograms of the pairs' grouping).
VISIBLE_PARTS = 64


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _plane_d(plane_n, plane_p, cam, j, box, i, far):
    """Signed distance to plane j of camera cam of the corner of boxes[i] ([lo, hi] rows of
    6) farthest along the normal (``far``) or nearest: n . (x - q) in x, y, z order, as
    objects_visible sums it."""
    d = 0.0
    for a in range(3):
        n_a = plane_n[cam, j, a]
        at = a + 3 if (n_a >= 0.0) == far else a
        d = d + n_a * (box[i, at] - plane_p[cam, j, a])
    return d


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _box_visible(plane_n, plane_p, box, i, far):
    """Whether boxes[i] is in some camera's frustum by the corners ``far`` along each
    normal (objects_visible's test); with far False, whether it lies wholly inside one."""
    for cam in range(plane_n.shape[0]):
        ok = True
        for j in range(6):
            if not _plane_d(plane_n, plane_p, cam, j, box, i, far) >= 0.0:
                ok = False
                break
        if ok:
            return True
    return False


# The OUT/ACROSS/IN classes of a group box against the frusta (objects_visible_groups).
OUT = 0
ACROSS = 1
IN = 2


class GroupPass(NamedTuple):
    """What a pass of objects_visible_groups over a grid's positions left, for the next
    pass over the same positions."""

    visible: np.ndarray  # bool [N]: each object row's flag, as the pass left it
    classes: np.ndarray  # int8 [G]: OUT, ACROSS or IN per group; size 0 for no pass


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _group_class(plane_n, plane_p, gbox, g):
    """IN when gbox[g] lies wholly inside some camera's frustum, OUT when it is in none
    by objects_visible's test, else ACROSS (on a plane)."""
    if _box_visible(plane_n, plane_p, gbox, g, False):
        return IN
    if _box_visible(plane_n, plane_p, gbox, g, True):
        return ACROSS
    return OUT


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _across(plane_n, plane_p, gbox, g, col, m, seen, ok):
    """objects_visible's test of the m boxes in columns col ([lo, hi] rows of 6) of group
    g, whose box gbox[g] is across a plane (DESIGN section 2, "Visibility"): seen[:m] the
    flags, ok [>= m] scratch. Each camera takes only the planes the group box is across:
    every object is inside a plane the group box is wholly inside, and outside one it is
    wholly outside (the argument of objects_visible_groups), so that camera sees none of
    them."""
    seen[:m] = False
    for cam in range(plane_n.shape[0]):
        ok[:m] = True
        for j in range(6):
            if not _plane_d(plane_n, plane_p, cam, j, gbox, g, True) >= 0.0:
                ok[:m] = False
                break
            if not _plane_d(plane_n, plane_p, cam, j, gbox, g, False) >= 0.0:
                _plane_columns(plane_n, plane_p, cam, j, col, m, ok)
        for i in range(m):
            seen[i] = seen[i] | ok[i]


@nb.njit(cache=True, nogil=True, parallel=PRANGE_ONLY, error_model="numpy")
def objects_visible_groups(at, plane_n, plane_p, groups, last):
    """objects_visible (DESIGN section 2, "Visibility", by the AABB test of "Tests") over a
    grid of every object, a group of its positions at a time.

    at: grid.BoxSource, the boxes as grid.group_boxes reads them (a grid's float64
    records in order: the objects of a group are then read as one run, not from 64 random
    rows, cache misses at large sizes); plane_n, plane_p [C, 6, 3]: the cameras' planes
    (CameraFrames); groups: grid.GroupBoxes; last: GroupPass of a pass over the
    same positions (objects may have moved since within their group boxes), classes of
    size 0 for none. Returns (visible [N], a box holding the visible objects, class [G]):
    the box is the IN groups' boxes and the visible objects' of the ACROSS ones, so it may
    be larger than theirs (it only sets a grid's extent).

    Exact, not approximate, as casters.sweep_groups: the group box's corner nearest along
    a normal lies no further along it than any of its objects' farthest corners, and each
    operation of the distance (a difference, a product by the normal's component, a sum)
    rounds monotonically, so the group's distance is at most each object's; the same for
    the farthest corners the other way. So an IN group (_group_class) holds only visible
    objects, an OUT one none, and the objects of an ACROSS one take objects_visible's test
    one by one. With ``last``, a group whose class is IN or OUT again keeps its objects'
    flags (they are all that class's): under a moving camera only the groups across a
    plane and the few that changed class are written, at their rows. Without, the flags
    are written by position, a group's in one run, then gathered into row order at
    pos_of, so the parallel parts never write to one cache line at random rows (faster
    than objects_visible, which reads every object's bounds; bench/RESULTS.md,
    "Measurements behind the code")."""
    lo, hi, rows, by_row = at.lo, at.hi, at.rows, at.by_row
    pos_of, gbox, size = groups.pos_of, groups.box, groups.size
    vis_last, class_last = last.visible, last.classes
    since = class_last.shape[0] > 0
    n_g = gbox.shape[0]
    n = pos_of.shape[0]
    # (A copy, not a loop: numba's loop over bools is not vectorised.)
    flags = vis_last.copy() if since else np.zeros(rows.shape[0], np.bool_)
    cls = np.empty(n_g, np.int8)
    parts = min(VISIBLE_PARTS, n_g)
    boxes = np.empty((parts, 6))
    for part in nb.prange(parts):
        b = _hull(gbox, 0)
        col = np.empty((6, size))
        seen = np.empty(size, np.bool_)
        ok = np.empty(size, np.bool_)
        for g in range(part, n_g, parts):
            v0 = g * size
            v1 = min(rows.shape[0], v0 + size)
            c = _group_class(plane_n, plane_p, gbox, g)
            cls[g] = c
            if c == IN:
                _widen(b, gbox, g)
            if c == ACROSS:
                m = v1 - v0
                for i in range(m):
                    p = rows[v0 + i] if by_row else v0 + i
                    for a in range(3):
                        col[a, i] = lo[p, a]
                        col[3 + a, i] = hi[p, a]
                _across(plane_n, plane_p, gbox, g, col, m, seen, ok)
                for i in range(m):
                    hit = seen[i]
                    flags[rows[v0 + i] if since else v0 + i] = hit
                    for a in range(3):
                        b[a] = min(b[a], col[a, i] if hit else np.inf)
                        b[3 + a] = max(b[3 + a], col[3 + a, i] if hit else -np.inf)
            elif c != (class_last[g] if since else OUT):
                for v in range(v0, v1):
                    flags[rows[v] if since else v] = c == IN
        boxes[part] = b
    if since:
        return flags, _hull(boxes, parts), cls
    out = np.empty(n, np.bool_)
    n_blocks = (n + VISIBLE_BLOCK - 1) // VISIBLE_BLOCK
    for blk in nb.prange(n_blocks):
        for o in range(blk * VISIBLE_BLOCK, min(n, (blk + 1) * VISIBLE_BLOCK)):
            out[o] = flags[pos_of[o]]
    return out, _hull(boxes, parts), cls


# Below this many lights a per-light kernel (lights_visible, priority._pack,
# walk.light_bounds) runs its loop on the calling thread: waking the second costs more
# than such a short loop saves, while about a thousand lights gain from it.
SERIAL_LIGHTS = 512


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _visible_block(a0, size, light_type, position, radius, plane_n, plane_p, out):
    """lights_visible for the lights a0..a0+size-1 (size <= VISIBLE_BLOCK), as
    objects_visible tests its boxes: the centres and -r copied into columns, then each
    plane over the block in a loop without branches, which LLVM vectorises. A ball fails a
    plane where n . (x - q), summed in x, y, z order, is < -r (DESIGN "Tests")."""
    col = np.empty((4, VISIBLE_BLOCK))
    ok = np.empty(VISIBLE_BLOCK, np.bool_)
    vis = np.zeros(VISIBLE_BLOCK, np.bool_)
    for i in range(size):
        for a in range(3):
            col[a, i] = position[a0 + i, a]
        col[3, i] = -radius[a0 + i]
    for cam in range(plane_n.shape[0]):
        ok[:size] = True
        for j in range(6):
            n0, n1, n2 = plane_n[cam, j, 0], plane_n[cam, j, 1], plane_n[cam, j, 2]
            q0, q1, q2 = plane_p[cam, j, 0], plane_p[cam, j, 1], plane_p[cam, j, 2]
            for i in range(size):
                d = n0 * (col[0, i] - q0) + n1 * (col[1, i] - q1) + n2 * (col[2, i] - q2)
                ok[i] = ok[i] & (not d < col[3, i])
        for i in range(size):
            vis[i] = vis[i] | ok[i]
    for i in range(size):
        out[a0 + i] = vis[i] | (light_type[a0 + i] == DIRECTIONAL)


@nb.njit(cache=True, nogil=True, parallel=PRANGE_ONLY, error_model="numpy")
def lights_visible(light_type, position, radius, plane_n, plane_p):
    """Point/spot: the ball (position, r) is in some frustum; directional: always.

    In blocks of VISIBLE_BLOCK lights (_visible_block), which vectorise, where a loop
    light by light with an exit at the first failed plane does not (and the six planes
    and'ed light by light, on the [L, 3] rows, was slower still; bench/RESULTS.md,
    "Measurements behind the code")."""
    n = light_type.shape[0]
    out = np.empty(n, np.bool_)
    n_blocks = (n + VISIBLE_BLOCK - 1) // VISIBLE_BLOCK
    if n < SERIAL_LIGHTS:
        for blk in range(n_blocks):
            a0 = blk * VISIBLE_BLOCK
            _visible_block(a0, min(n, a0 + VISIBLE_BLOCK) - a0, light_type, position, radius,
                           plane_n, plane_p, out)
    else:
        for blk in nb.prange(n_blocks):
            a0 = blk * VISIBLE_BLOCK
            _visible_block(a0, min(n, a0 + VISIBLE_BLOCK) - a0, light_type, position, radius,
                           plane_n, plane_p, out)
    return out
