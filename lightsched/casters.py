"""Shadow casters (DESIGN section 2, "Casters"): the culling volumes of the shadow lights,
the caster test and its bit masks, and the casters stage.

Volumes are convex plane sets (normal, point) [.., MAX_PLANES, 3] with a plane count; the
normals of the added edge planes are not normalised (the AABB test needs only the sign).
The corner numbering, edge-plane construction and evaluation order are those written in
reference.py's docstring, so both agree bit for bit.

Point and spot lights find their casters by walking the object grids of the light pass
(``grid_casters``, the walker of walk.py); directional casters are a parallel scan over
every object (``sweep_casters``), since their influence volume is everything, or, over a
grid of every object, over boxes round runs of its positions first (``sweep_groups``): a
shadow distance keeps few of them. A frame where only a few objects changed keeps each
list but at those objects, which alone it tests (``changed_casters``, ``sweep_casters``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from itertools import accumulate
from typing import TYPE_CHECKING, NamedTuple

import numba as nb
import numpy as np

from .buffers import read_only_view
from .frustum import CameraFrames
from .grid import (
    SWEEP_GROUP,
    Grid,
    GridIndex,
    Records,
    frame_box,
    grid_shape,
    group_boxes_of,
    records_grid,
    records_of,
)
from .jit import PRANGE_ONLY
from .priority import box_d2, spot_cone
from .scene import DIRECTIONAL, SPOT, LightStore, ObjectStore
from .walk import light_bounds, light_runs

if TYPE_CHECKING:
    from .changes import Changes
    from .frustum import Cameras
    from .plan import FramePlan
    from .priority import Packed, PackedLights
    from .shadows import ShadowSet
    from .tuning import Tuning

MAX_PLANES = 18  # a convex volume here has at most 6 faces plus 12 edge planes
SWEEP_BLOCK = 512  # boxes per block of sweep_casters: its [6, 512] float64 columns fit L1
SWEEP_PARTS = 64  # sweep_casters' parallel parts, each a run of blocks


class Volumes(NamedTuple):
    """The culling volumes of L shadow lights (culling_volumes), V = cameras x cascades
    each: volume k of a point or spot light is its hull with camera k's frustum, volume
    k*C + c of a directional light camera k's cascade c swept towards it."""

    vn: np.ndarray      # float64 [L, V, MAX_PLANES, 3]: plane normals (edge planes' not unit)
    vq: np.ndarray      # float64 [L, V, MAX_PLANES, 3]: a point of each plane
    vm: np.ndarray      # int64 [L, V]: plane count, -1 for a volume the light does not have
    shared: np.ndarray  # int64 [L, C]: leading planes of camera k's cascades (directional)


class CasterObjects(NamedTuple):
    """The object store's columns a caster test reads, by object row, in world space like
    the culling volumes."""

    casts: np.ndarray  # bool [N]: casts_shadows
    mask: np.ndarray   # uint32 [N]
    lo: np.ndarray     # float64 [N, 3]: bounds_min
    hi: np.ndarray     # float64 [N, 3]: bounds_max


class CasterLists(NamedTuple):
    """grid_casters' output: light t writes its casters from offsets[t] on."""

    rows: np.ndarray   # int64 [offsets[-1]]: object rows
    masks: np.ndarray  # uint32 [offsets[-1]]: their caster masks


# The 12 edges of a frustum: (face a, face b, corner c0, corner c1), faces 0 near, 1 far,
# 2 left, 3 right, 4 bottom, 5 top; corner z*4 + x*2 + y (z 0 near / 1 far, x 0 left /
# 1 right, y 0 bottom / 1 top); c0 < c1 are the two corners the faces share.
EDGES = np.array([[0, 2, 0, 1], [0, 3, 2, 3], [0, 4, 0, 2], [0, 5, 1, 3],
                  [1, 2, 4, 5], [1, 3, 6, 7], [1, 4, 4, 6], [1, 5, 5, 7],
                  [2, 4, 0, 4], [2, 5, 1, 5], [3, 4, 2, 6], [3, 5, 3, 7]], np.int64)


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _corners(cam_p, basis, tan_xy, z_near, z_far, out):
    """out[8, 3] = p + z f + (+-z t_x) r + (+-z t_y) u, corner z*4 + x*2 + y; returns the
    centroid (their mean)."""
    cen = np.zeros(3)
    for zi in range(2):
        z = z_near if zi == 0 else z_far
        for xi in range(2):
            sx = z * tan_xy[0] if xi else -z * tan_xy[0]
            for yi in range(2):
                sy = z * tan_xy[1] if yi else -z * tan_xy[1]
                c = zi * 4 + xi * 2 + yi
                for i in range(3):
                    out[c, i] = cam_p[i] + z * basis[0, i] + sx * basis[1, i] + sy * basis[2, i]
    for i in range(3):
        acc = 0.0
        for c in range(8):
            acc += out[c, i]
        cen[i] = acc / 8
    return cen


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _edge_plane(a, b, anchor, cen, vn, vq, m):
    """Appends plane m: normal a x b, point ``anchor``, flipped when the centroid is on its
    negative side."""
    n0 = a[1] * b[2] - a[2] * b[1]
    n1 = a[2] * b[0] - a[0] * b[2]
    n2 = a[0] * b[1] - a[1] * b[0]
    if n0 * (cen[0] - anchor[0]) + n1 * (cen[1] - anchor[1]) + n2 * (cen[2] - anchor[2]) < 0:
        n0, n1, n2 = -n0, -n1, -n2
    vn[m, 0], vn[m, 1], vn[m, 2] = n0, n1, n2
    for i in range(3):
        vq[m, i] = anchor[i]
    return m + 1


@nb.njit(cache=True, nogil=True, error_model="numpy")
def _hull(p, corners, cen, face_n, face_q, vn, vq):
    """Convex hull of point p and a frustum (faces face_n/face_q [6, 3]): the faces with p at
    signed distance >= 0, then for every edge whose faces see p on opposite sides the plane
    through p and that edge (normal (c0 - p) x (c1 - p)). Returns the plane count."""
    side = np.empty(6, np.bool_)
    m = 0
    for f in range(6):
        d = (face_n[f, 0] * (p[0] - face_q[f, 0]) + face_n[f, 1] * (p[1] - face_q[f, 1])
             + face_n[f, 2] * (p[2] - face_q[f, 2]))
        side[f] = d >= 0
        if side[f]:
            vn[m] = face_n[f]
            vq[m] = face_q[f]
            m += 1
    a = np.empty(3)
    b = np.empty(3)
    for e in range(12):
        if side[EDGES[e, 0]] != side[EDGES[e, 1]]:
            for i in range(3):
                a[i] = corners[EDGES[e, 2], i] - p[i]
                b[i] = corners[EDGES[e, 3], i] - p[i]
            m = _edge_plane(a, b, p, cen, vn, vq, m)
    return m


@nb.njit(cache=True, nogil=True, error_model="numpy")
def _sweep(v, corners, cen, face_n, face_q, vn, vq):
    """A frustum slice (faces face_n/face_q [6, 3]) swept along v: the faces with n . v >= 0,
    plus for every edge between a kept and a dropped face the plane containing the edge
    and v (normal (c1 - c0) x v, point c0). Returns (plane count, shared): the kept side
    faces come first, ``shared`` of them; they are the camera's own planes, bit for bit
    the same in every cascade, so a caster scan tests them once per camera. Then the edge
    planes, then the kept near/far face (the order of an AND does not change it; this one
    rejects early)."""
    keep = np.empty(6, np.bool_)
    for f in range(6):
        keep[f] = face_n[f, 0] * v[0] + face_n[f, 1] * v[1] + face_n[f, 2] * v[2] >= 0
    m = 0
    for f in range(2, 6):
        if keep[f]:
            vn[m] = face_n[f]
            vq[m] = face_q[f]
            m += 1
    shared = m
    a = np.empty(3)
    for e in range(12):
        if keep[EDGES[e, 0]] != keep[EDGES[e, 1]]:
            for i in range(3):
                a[i] = corners[EDGES[e, 3], i] - corners[EDGES[e, 2], i]
            m = _edge_plane(a, v, corners[EDGES[e, 2]], cen, vn, vq, m)
    for f in range(2):
        if keep[f]:
            vn[m] = face_n[f]
            vq[m] = face_q[f]
            m += 1
    return m, shared


@nb.njit(cache=True, nogil=True, error_model="numpy")
def _volumes(rows, light_type, position, direction, cams, splits, overlap):
    """Kernel of ``culling_volumes`` (DESIGN section 2, "Casters"): per light of the store
    rows ``rows`` its volumes. light_type, position, direction: the light store's columns,
    read at those rows here, not by three numpy gathers, whose per-call overhead a small
    frame feels; cams: frustum.CameraArrays; splits [C, n_casc + 1]: cascade_splits; overlap:
    cascade_overlap. Returns the fields of Volumes: normals and points
    [L, n_vol, MAX_PLANES, 3], plane counts [L, n_vol] (-1 for the volumes a point or spot
    light does not have: it has one per camera) and, for a directional light, the number
    of leading planes its cascades of camera k share [L, n_cam]."""
    cam_p, basis, tan_xy = cams.position, cams.basis, cams.tan_xy
    plane_n, plane_p, near_far = cams.plane_n, cams.plane_p, cams.near_far
    n_cam = cam_p.shape[0]
    n_casc = splits.shape[1] - 1
    n_l = rows.shape[0]
    vn = np.zeros((n_l, n_cam * n_casc, MAX_PLANES, 3))
    vq = np.zeros((n_l, n_cam * n_casc, MAX_PLANES, 3))
    vm = np.full((n_l, n_cam * n_casc), -1, np.int64)
    shared = np.zeros((n_l, n_cam), np.int64)
    corners = np.empty((8, 3))
    face_n = np.empty((6, 3))
    face_q = np.empty((6, 3))
    v = np.empty(3)
    for t in range(n_l):
        j = rows[t]
        if light_type[j] != DIRECTIONAL:
            for k in range(n_cam):
                cen = _corners(cam_p[k], basis[k], tan_xy[k], near_far[k, 0], near_far[k, 1],
                               corners)
                vm[t, k] = _hull(position[j], corners, cen, plane_n[k], plane_p[k], vn[t, k],
                                 vq[t, k])
            continue
        for i in range(3):
            v[i] = -direction[j, i]
        for k in range(n_cam):
            z = splits[k]
            for c in range(n_casc):
                z_near = near_far[k, 0] if c == 0 else z[c] - overlap * (z[c] - z[c - 1])
                z_far = z[c + 1]
                cen = _corners(cam_p[k], basis[k], tan_xy[k], z_near, z_far, corners)
                face_n[:] = plane_n[k]
                face_q[:] = plane_p[k]
                for i in range(3):
                    face_q[0, i] = cam_p[k, i] + z_near * basis[k, 0, i]
                    face_q[1, i] = cam_p[k, i] + z_far * basis[k, 0, i]
                b = k * n_casc + c
                vm[t, b], shared[t, k] = _sweep(v, corners, cen, face_n, face_q, vn[t, b],
                                                vq[t, b])
    return vn, vq, vm, shared


def culling_volumes(lights: LightStore, rows: np.ndarray, frames: CameraFrames,
                    splits: np.ndarray, overlap: float, light_culling: bool = False) -> Volumes:
    """The culling volumes of the shadowed lights ``rows`` (DESIGN section 2, "Casters"):
    for a point or spot light one hull of its position and each camera's frustum (volume
    k = camera k); for a directional light each camera's cascade slices [a_c, z_c+1] swept
    towards the light (volume k*C + c, its caster_masks bit). With ``light_culling``
    (caster_culling = "light", DESIGN "Shadow views") a point or spot light has a single
    volume of no planes, which every box is in: no camera test."""
    vn, vq, vm, shared = _volumes(rows, lights.type, lights.position, lights.direction,
                                  frames.arrays(), splits, overlap)
    if light_culling:
        local = lights.type[rows] != DIRECTIONAL
        vm[local] = -1
        vm[local, 0] = 0
    return Volumes(vn, vq, vm, shared)


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _plane_ok(vn, vq, t, b, i, lo, hi, v):
    """The corner of box v ([lo, hi] rows of [n, 3] arrays) farthest along the normal of
    plane i of volume b of light t has signed distance >= 0."""
    n0 = vn[t, b, i, 0]
    n1 = vn[t, b, i, 1]
    n2 = vn[t, b, i, 2]
    c0 = hi[v, 0] if n0 >= 0.0 else lo[v, 0]
    c1 = hi[v, 1] if n1 >= 0.0 else lo[v, 1]
    c2 = hi[v, 2] if n2 >= 0.0 else lo[v, 2]
    return n0 * (c0 - vq[t, b, i, 0]) + n1 * (c1 - vq[t, b, i, 1]) + n2 * (c2 - vq[t, b, i, 2]) >= 0.0


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def box_in_volume(vn, vq, vm, t, b, lo, hi, v):
    """The conservative AABB test of box v against volume b of light t (DESIGN "Tests");
    vn, vq, vm = the culling volumes' normals, points and plane counts."""
    for i in range(vm[t, b]):
        if not _plane_ok(vn, vq, t, b, i, lo, hi, v):
            return False
    return True


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def cube_faces(p0, p1, p2, r, lo_v, hi_v, v):
    """Bit f for every cube-face pyramid (+x, -x, +y, -y, +z, -z) box v is in: for +x with
    x' = x - p: x' >= 0, x' -+ y' >= 0, x' -+ z' >= 0, r - x' >= 0, each at the box corner
    farthest along the plane's normal."""
    lo = (lo_v[v, 0] - p0, lo_v[v, 1] - p1, lo_v[v, 2] - p2)
    hi = (hi_v[v, 0] - p0, hi_v[v, 1] - p1, hi_v[v, 2] - p2)
    bits = 0
    for a in range(3):
        for neg in range(2):
            top = -lo[a] if neg else hi[a]
            bottom = -hi[a] if neg else lo[a]
            ok = top >= 0 and r - bottom >= 0
            for b in range(3):
                if b != a:
                    ok = ok and top - lo[b] >= 0 and top + hi[b] >= 0
            if ok:
                bits |= 1 << (2 * a + neg)
    return bits


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def caster_bits(hot, lf, j, typ, t, vn, vq, vm, lo, hi, v, w_lo, w_hi, o):
    """caster_masks entry of an object for point or spot light row j, whose culling volumes
    are (vn, vq, vm)[t] (one per camera), once the caller has checked casts_shadows, the
    mask and d2 <= r*r: the spot cone, then some camera's hull, then the cube faces (point)
    or bit 0 (spot). 0: not a caster. (lo, hi, v): the box as row v of the grid records,
    in the light's frame (the packed light's); (w_lo, w_hi, o): the box as row o of the
    store, in world space like the volumes. (Arrays one by one: casters.grid_casters calls
    it once an object.)"""
    if typ == SPOT:
        # float64 whatever the records' precision (float32 + float32 rounds in float32).
        lx, ly, lz = np.float64(lo[v, 0]), np.float64(lo[v, 1]), np.float64(lo[v, 2])
        hx, hy, hz = np.float64(hi[v, 0]), np.float64(hi[v, 1]), np.float64(hi[v, 2])
        ex = hx - lx
        ey = hy - ly
        ez = hz - lz
        e2 = ex * ex + ey * ey + ez * ez
        geo = ((lx + hx) / 2, (ly + hy) / 2, (lz + hz) / 2, math.sqrt(e2) / 2, e2)
        meets, _ = spot_cone(hot, lf, j, geo, False)
        if not meets:
            return 0
    for k in range(vm.shape[1]):
        if vm[t, k] >= 0 and box_in_volume(vn, vq, vm, t, k, w_lo, w_hi, o):
            if typ == SPOT:
                return 1
            return cube_faces(hot[j, 0], hot[j, 1], hot[j, 2], hot[j, 3], lo, hi, v)
    return 0


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _block_in_planes(vn, vq, t, b, first, end, lead, box, inside):
    """inside[r] &= box r of the block is on the inner side of planes first..end-1 of
    volume b of light t, by the AABB test of ``_plane_ok`` with the same arithmetic. Plane
    by plane over the whole block: the corner a plane picks is the same for every box, so
    the loop has no branch and vectorises over the block's coordinates (box [6, m]: lo x,
    y, z, hi x, y, z). Plane ``lead`` goes first, and the scan stops once no box is left.
    Returns (any box left, the plane that emptied the block, else lead)."""
    has_lead = first <= lead < end
    for step in range(end - first):
        i = first + step
        if has_lead:
            i = lead if step == 0 else (i - 1 if i - 1 < lead else i)
        n0 = vn[t, b, i, 0]
        n1 = vn[t, b, i, 1]
        n2 = vn[t, b, i, 2]
        q0 = vq[t, b, i, 0]
        q1 = vq[t, b, i, 1]
        q2 = vq[t, b, i, 2]
        c0 = box[3] if n0 >= 0.0 else box[0]
        c1 = box[4] if n1 >= 0.0 else box[1]
        c2 = box[5] if n2 >= 0.0 else box[2]
        left = 0
        for r in range(inside.shape[0]):
            k = inside[r] & (n0 * (c0[r] - q0) + n1 * (c1[r] - q1) + n2 * (c2[r] - q2) >= 0.0)
            inside[r] = k
            left += k
        if left == 0:
            return False, i
    return True, lead


@nb.njit(cache=True, nogil=True, parallel=PRANGE_ONLY, error_model="numpy")
def sweep_casters(lo, hi, casts, omask, lmask, vols):
    """caster_masks of every object for each directional light t (DESIGN section 2,
    "Casters"; parallel over blocks of SWEEP_BLOCK objects): bit b set iff the object
    casts, its mask matches lmask[t] and its box [lo, hi] is in volume b (camera*C +
    cascade sweep). lo, hi [N, 3] float64, casts [N] bool, omask [N]: the objects' boxes,
    casts_shadows and masks; lmask [T] int64: the lights' masks; vols: Volumes of the T
    lights (culling_volumes), the shared leading planes tested once per camera. Returns
    bits [T, N] uint32.

    A shadow distance is small beside a large scene, so most boxes are rejected, each by
    whichever plane it lies outside of. Box by box with an early exit (the version before
    this one) the loop does not vectorise; plane by plane over blocks of boxes copied into
    columns (``_block_in_planes``), each block left once it is empty, it does, and most of
    what remains is the copy (bench/RESULTS.md, issue 6)."""
    vm, shared = vols.vm, vols.shared
    n = lo.shape[0]
    bits = np.empty((lmask.shape[0], n), np.uint32)
    n_blocks = (n + SWEEP_BLOCK - 1) // SWEEP_BLOCK
    n_parts = min(n_blocks, SWEEP_PARTS)
    for part in nb.prange(n_parts):
        box = np.empty((6, SWEEP_BLOCK))
        base = np.empty(SWEEP_BLOCK, np.bool_)
        in_cam = np.empty(SWEEP_BLOCK, np.bool_)
        inside = np.empty(SWEEP_BLOCK, np.bool_)
        acc = np.empty(SWEEP_BLOCK, np.uint32)
        # The plane that emptied the part's last block goes first in the next one.
        lead = np.full(vm.shape, -1, np.int64)
        lead_shared = np.full(shared.shape, -1, np.int64)
        for blk in range(n_blocks * part // n_parts, n_blocks * (part + 1) // n_parts):
            o0 = blk * SWEEP_BLOCK
            m = min(n, o0 + SWEEP_BLOCK) - o0
            _sweep_block(lo, hi, casts, omask, lmask, vols, o0, box[:, :m], base[:m],
                         in_cam[:m], inside[:m], acc[:m], lead, lead_shared, bits)
    return bits


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _sweep_block(lo, hi, casts, omask, lmask, vols, o0, box, base, in_cam, inside, acc, lead,
                 lead_shared, bits):
    """sweep_casters on the boxes o0.. of one block: box [6, m], base, in_cam, inside [m]
    bool and acc [m] uint32 its scratch, sized to the block (_block_masks); lead,
    lead_shared the part's first planes (_block_masks); bits as sweep_casters returns
    it. (Separate arrays: a tuple of them would be built inside sweep_casters' parallel
    loop.)"""
    m = acc.shape[0]
    for r in range(m):
        for a in range(3):
            box[a, r] = lo[o0 + r, a]
            box[3 + a, r] = hi[o0 + r, a]
    for t in range(lmask.shape[0]):
        for r in range(m):
            base[r] = casts[o0 + r] and (np.int64(omask[o0 + r]) & lmask[t]) != 0
        _block_masks(vols, t, box, base, in_cam, inside, acc, lead, lead_shared)
        bits[t, o0:o0 + m] = acc


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _block_masks(vols, t, box, base, in_cam, inside, acc, lead, lead_shared):
    """acc[r] = the caster mask of light t of box r of a block (DESIGN section 2,
    "Casters"), 0 where base[r] is False: per camera its shared planes, then each
    cascade's own. vols: Volumes; box [6, m]: the block in columns, as _block_in_planes
    reads them; base, in_cam, inside [m] bool (the middle two scratch), acc [m] uint32;
    lead [T, V], lead_shared [T, C] int64: per volume and per camera's shared planes, the
    plane that emptied the last block (-1: none), tried first and updated here."""
    vn, vq, vm, shared = vols.vn, vols.vq, vols.vm, vols.shared
    n_cam = shared.shape[1]
    n_casc = vm.shape[1] // n_cam
    acc[:] = 0
    for k in range(n_cam):
        b0 = k * n_casc
        in_cam[:] = base
        left, lead_shared[t, k] = _block_in_planes(vn, vq, t, b0, 0, shared[t, k],
                                                   lead_shared[t, k], box, in_cam)
        if not left:
            continue
        for c in range(n_casc):
            b = b0 + c
            inside[:] = in_cam
            left, lead[t, b] = _block_in_planes(vn, vq, t, b, shared[t, k], vm[t, b],
                                                lead[t, b], box, inside)
            if left:
                for r in range(acc.shape[0]):
                    acc[r] |= np.uint32(inside[r]) << b


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _in_sweep(vn, vq, vm, shared, t, k, n_casc, lo, hi, v):
    """Whether box v of [lo, hi] is in any volume of camera k: the camera's shared planes
    (kept in its first volume), then each cascade's own, by ``_plane_ok``."""
    b0 = k * n_casc
    for i in range(shared[t, k]):
        if not _plane_ok(vn, vq, t, b0, i, lo, hi, v):
            return False
    for c in range(n_casc):
        b = b0 + c
        ok = True
        for i in range(shared[t, k], vm[t, b]):
            if not _plane_ok(vn, vq, t, b, i, lo, hi, v):
                ok = False
                break
        if ok:
            return True
    return False


@nb.njit(cache=True, nogil=True, parallel=PRANGE_ONLY, error_model="numpy")
def sweep_groups(casts, omask, lmask, vols, at, gbox):
    """sweep_casters' caster masks (DESIGN section 2, "Casters") over a grid of every
    object, a group box at a time: a group of SWEEP_GROUP grid positions whose box
    ``gbox`` [G, 6] (grid.group_boxes) is in none of a light's volumes holds no caster of
    it and is skipped; the boxes of the others take the test plane by plane, copied into
    columns (_block_masks, as sweep_casters' blocks). casts, omask, lmask as in
    sweep_casters; vols: Volumes; at: grid.BoxSource (rows: the object row of each
    position). Returns (offsets [T + 1], object rows, caster masks): light t's casters at
    offsets[t]..offsets[t+1]-1, rows ascending, the nonzero entries of sweep_casters'.

    Exact, not approximate: each plane test is the same float64 expression at the box
    corner farthest along the normal, and every operation in it (a difference, a product
    by the normal's component, a sum) is rounded monotonically, so a corner of the group
    box that lies further along the normal than each of its objects' corners gives a
    signed distance at least theirs: a plane the group box fails, each of them fails
    (bench/RESULTS.md, issue 6). Groups go to the parallel parts in turn (part p takes
    groups p, p + parts, ...): the few a shadow distance keeps lie together in the grid."""
    vn, vq, vm, shared = vols.vn, vols.vq, vols.vm, vols.shared
    lo, hi, rows, by_row = at.lo, at.hi, at.rows, at.by_row
    n_t = lmask.shape[0]
    n_cam = shared.shape[1]
    n_casc = vm.shape[1] // n_cam
    n_g = gbox.shape[0]
    nv = rows.shape[0]
    n_parts = max(1, min(n_g, SWEEP_PARTS))
    # Each position's mask, written for the groups let through only; counted per part,
    # then gathered at the places the counts give (the output does not depend on the
    # threads).
    bits = np.empty((n_t, nv), np.uint32)
    through = np.zeros((n_t, n_g), np.bool_)
    count = np.zeros((n_t, n_parts + 1), np.int64)
    g_lo, g_hi = gbox[:, :3], gbox[:, 3:]
    for part in nb.prange(n_parts):
        # The boxes of a group let through, in columns, tested plane by plane as
        # sweep_casters' blocks are (box by box with an early exit a plane was slower, as
        # there).
        box = np.empty((6, SWEEP_GROUP))
        base, in_cam, inside = (np.empty(SWEEP_GROUP, np.bool_), np.empty(SWEEP_GROUP, np.bool_),
                                np.empty(SWEEP_GROUP, np.bool_))
        acc = np.empty(SWEEP_GROUP, np.uint32)
        lead = np.full(vm.shape, -1, np.int64)
        lead_shared = np.full(shared.shape, -1, np.int64)
        for g in range(part, n_g, n_parts):
            v0 = g * SWEEP_GROUP
            m = min(nv, v0 + SWEEP_GROUP) - v0
            copied = False
            for t in range(n_t):
                hit = False
                for k in range(n_cam):
                    hit = hit or _in_sweep(vn, vq, vm, shared, t, k, n_casc, g_lo, g_hi, g)
                if not hit:
                    continue
                through[t, g] = True
                if not copied:
                    for r in range(m):
                        p = rows[v0 + r] if by_row else v0 + r
                        for a in range(3):
                            box[a, r] = lo[p, a]
                            box[3 + a, r] = hi[p, a]
                    copied = True
                for r in range(m):
                    o = rows[v0 + r]
                    base[r] = casts[o] and (np.int64(omask[o]) & lmask[t]) != 0
                _block_masks(vols, t, box[:, :m], base[:m], in_cam[:m], inside[:m], acc[:m],
                             lead, lead_shared)
                c = 0
                for r in range(m):
                    bits[t, v0 + r] = acc[r]
                    c += acc[r] != 0
                count[t, part + 1] += c
    offsets = np.zeros(n_t + 1, np.int64)
    for t in range(n_t):
        for part in range(n_parts):
            count[t, part + 1] += count[t, part]
        offsets[t + 1] = offsets[t] + count[t, n_parts]
    out_rows = np.empty(offsets[n_t], np.int64)
    masks = np.empty(offsets[n_t], np.uint32)
    for part in nb.prange(n_parts):
        for t in range(n_t):
            d = offsets[t] + count[t, part]
            for g in range(part, n_g, n_parts):
                if not through[t, g]:
                    continue
                for v in range(g * SWEEP_GROUP, min(nv, (g + 1) * SWEEP_GROUP)):
                    if bits[t, v] != 0:
                        out_rows[d] = rows[v]
                        masks[d] = bits[t, v]
                        d += 1
    # Grid order to row order, light by light: a sort of the casters when they are few
    # beside the objects, else their masks spread over a row-indexed array and read back.
    n = casts.shape[0]
    for t in range(n_t):
        a, b = offsets[t], offsets[t + 1]
        if (b - a) * 16 <= n:
            order = np.argsort(out_rows[a:b])
            r = out_rows[a:b][order]
            m = masks[a:b][order]
            out_rows[a:b] = r
            masks[a:b] = m
        else:
            spread = np.zeros(n, np.uint32)
            for i in range(a, b):
                spread[out_rows[i]] = masks[i]
            d = a
            for o in range(n):
                if spread[o] != 0:
                    out_rows[d] = o
                    masks[d] = spread[o]
                    d += 1
    return offsets, out_rows, masks


@nb.njit(cache=True, nogil=True, parallel=PRANGE_ONLY, error_model="numpy")
def hidden_near(lo, hi, casts, visible, box):
    """Rows (ascending) of the invisible casting objects whose box meets ``box`` (lo, hi
    [6]): the candidates a point or spot light's casters need beside the visible objects.
    Per-chunk counts, then each chunk writes its own range (parallel, in row order)."""
    n = lo.shape[0]
    n_chunks = (n + 4095) // 4096
    counts = np.zeros(n_chunks + 1, np.int64)
    keep = np.zeros(n, np.bool_)
    for ch in nb.prange(n_chunks):
        c = 0
        for o in range(ch * 4096, min(n, (ch + 1) * 4096)):
            k = casts[o] and not visible[o]
            for a in range(3):
                k = k and hi[o, a] >= box[a] and lo[o, a] <= box[3 + a]
            keep[o] = k
            c += k
        counts[ch + 1] = c
    for ch in range(n_chunks):
        counts[ch + 1] += counts[ch]
    rows = np.empty(counts[n_chunks], np.int64)
    for ch in nb.prange(n_chunks):
        d = counts[ch]
        for o in range(ch * 4096, min(n, (ch + 1) * 4096)):
            if keep[o]:
                rows[d] = o
                d += 1
    return rows


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _caster(hot, lf, j, typ, t, v, box, box_rows, casts, omask, lo, hi, w_lo, w_hi, vn, vq, vm,
            out_rows, out_mask, n):
    """Appends (object row, caster mask) of grid position v for the shadowed light of
    packed row j, of type ``typ``, whose culling volumes are index t of (vn, vq, vm), at n
    when it is a caster (DESIGN section 2, "Casters"): casts_shadows, mask, d2 <= r*r,
    then caster_bits. Returns the new n. hot, lf: PackedLights' arrays; box, box_rows, lo,
    hi: the grid's records, their object rows and lo / hi views; casts, omask, w_lo, w_hi:
    CasterObjects' arrays, the store's (in a grid of every object the records of the
    invisible ones hold no SHOWN bit, so they pair with no light, but invisible objects
    cast); vn, vq, vm: Volumes' arrays; out_rows, out_mask: CasterLists'. The arrays come
    one by one: a tuple of them unpacked once an object kept its reference counting in the
    walk."""
    o = box_rows[v]
    if not casts[o] or np.int64(omask[o]) & np.int64(hot[j, 4]) == 0:
        return n
    r = hot[j, 3]
    if not box_d2(box, v, hot[j, 0], hot[j, 1], hot[j, 2]) <= r * r:
        return n
    bits = caster_bits(hot, lf, j, typ, t, vn, vq, vm, lo, hi, v, w_lo, w_hi, o)
    if bits != 0:
        out_rows[n] = o
        out_mask[n] = bits
        n += 1
    return n


@nb.njit(cache=True, nogil=True, parallel=PRANGE_ONLY, error_model="numpy")
def grid_casters(lights, rows, grid, recs, objects, vols, offsets, out):
    """Casters (DESIGN section 2, "Casters") of the shadowed point and spot lights ``rows``
    (parallel) among the objects of a grid built like the light pass's (visible_order /
    visible_objects): each light walks the same column runs as ``light_pass``
    (walk.light_runs) and keeps the objects that pass ``_caster``. lights: PackedLights;
    rows [T] int64: their packed rows; grid: GridIndex; recs: the grid's Records (rows:
    object rows of the store); objects: CasterObjects of the store, whose world boxes meet
    the culling volumes (the records may be relative to the first camera); vols: Volumes
    indexed like rows; out: CasterLists, light t writing from offsets[t] (``light_bounds``
    on this grid). Returns the count per light; a light's rows come ascending (sorted
    here, per light: the frame keeps them as they are)."""
    # Every field read here: arrays taken out of a tuple inside the parallel loop were
    # written to copies (numba 0.68 parfors), and the stores were lost.
    hot, lf = lights.hot, lights.f
    g_f, dims, cell_start = grid.frame, grid.dims, grid.cell_start
    ext, big_pos = grid.ext, grid.big_pos
    box, box_rows = recs.box, recs.rows
    lo, hi = box[:, 0:3], box[:, 3:6]
    casts, omask, w_lo, w_hi = objects.casts, objects.mask, objects.lo, objects.hi
    vn, vq, vm = vols.vn, vols.vq, vols.vm
    out_rows, out_mask = out.rows, out.masks
    count = np.zeros(rows.shape[0], np.int64)
    for t in nb.prange(rows.shape[0]):
        j = rows[t]
        typ = (np.int64(hot[j, 5]) >> 3) & 3
        t_vol = np.int64(t)
        n = offsets[t]
        m, runs = light_runs(hot, j, g_f, dims, cell_start, ext, np.empty((16, 2), np.int64))
        for i in range(m):
            for v in range(runs[i, 0], runs[i, 1]):
                n = _caster(hot, lf, j, typ, t_vol, v, box, box_rows, casts, omask, lo, hi, w_lo,
                            w_hi, vn, vq, vm, out_rows, out_mask, n)
        for b in range(big_pos.shape[0]):
            n = _caster(hot, lf, j, typ, t_vol, big_pos[b], box, box_rows, casts, omask, lo, hi,
                        w_lo, w_hi, vn, vq, vm, out_rows, out_mask, n)
        a = offsets[t]
        order = np.argsort(out_rows[a:n])
        sorted_rows, sorted_mask = out_rows[a:n][order], out_mask[a:n][order]
        out_rows[a:n] = sorted_rows
        out_mask[a:n] = sorted_mask
        count[t] = n - a
    return count



@nb.njit(cache=True, nogil=True, error_model="numpy")
def changed_casters(lights, rows, recs, objects, vols):
    """Casters (DESIGN section 2, "Casters") of the shadowed point and spot lights ``rows``
    among a few objects, each light testing each of them by ``_caster`` as grid_casters
    does in a walk, on the calling thread (waking a second costs more than a few objects'
    tests). lights: PackedLights; rows [T] int64: their packed rows; recs: Records of the
    objects (grid.records_of, rows ascending); objects: CasterObjects of the store; vols:
    Volumes indexed like rows. Returns (offsets [T + 1], object rows, caster masks): light
    t's casters at offsets[t]..offsets[t + 1] - 1, rows ascending."""
    hot, lf = lights.hot, lights.f
    box, box_rows = recs.box, recs.rows
    lo, hi = box[:, 0:3], box[:, 3:6]
    casts, omask, w_lo, w_hi = objects.casts, objects.mask, objects.lo, objects.hi
    vn, vq, vm = vols.vn, vols.vq, vols.vm
    m = box_rows.shape[0]
    out_rows = np.empty(rows.shape[0] * m, np.int64)
    out_mask = np.empty(rows.shape[0] * m, np.uint32)
    offsets = np.zeros(rows.shape[0] + 1, np.int64)
    n = 0
    for t in range(rows.shape[0]):
        j = rows[t]
        typ = (np.int64(hot[j, 5]) >> 3) & 3
        for v in range(m):
            n = _caster(hot, lf, j, typ, np.int64(t), v, box, box_rows, casts, omask, lo, hi,
                        w_lo, w_hi, vn, vq, vm, out_rows, out_mask, n)
        offsets[t + 1] = n
    return offsets, out_rows[:n], out_mask[:n]


# --------------------------------------------------------------------------- the casters stage


@dataclass(slots=True)
class Casters:
    """The casters stage's output: caster_offsets, caster_ids and caster_masks of the
    shadow lights in rank order (DESIGN section 3), ``rows`` the casters' object rows;
    ``by_light``: per shadow light row its
    (object rows ascending, masks), which the next frame keeps for the lights whose light
    and cameras did not change; ``how``: the plan's entry."""

    offsets: np.ndarray
    ids: np.ndarray
    masks: np.ndarray
    rows: np.ndarray
    by_light: dict[int, tuple[np.ndarray, np.ndarray]]
    how: str


def find_casters(plan: FramePlan, last: Casters | None, changes: Changes, lights: LightStore,
                 objects: ObjectStore, shadows: ShadowSet, packed: Packed, grid: Grid,
                 cameras: Cameras, visible: np.ndarray, cascade_overlap: float,
                 tuning: Tuning, light_culling: bool = False) -> Casters:
    """The casters stage. Casters depend on the light, the cameras (but for point and spot
    lights under caster_culling "light") and every object: with plan.keep_casters (or,
    for point and spot lights, plan.keep_local_casters), a light none of them changed for
    keeps its list; when only objects changed (plan.patch_casters), its list changes only
    at those objects' rows, which alone it tests. ``visible``: the objects' visibility;
    ``light_culling``: caster_culling = "light" (point and spot casters get no camera
    test)."""
    shadow_rows = shadows.rows
    recompute = np.ones(shadow_rows.size, np.bool_)
    patch = None
    if plan.keep_casters or plan.keep_local_casters:
        changed = np.zeros(len(lights), np.bool_)
        changed[changes.light_rows] = True
        again = changed[shadow_rows]
        again |= np.array([int(r) not in last.by_light for r in shadow_rows.tolist()],
                          np.bool_)
        if not plan.keep_casters:
            # The cameras moved: cascades follow them.
            again |= lights.type[shadow_rows] == DIRECTIONAL
        if not plan.keep_local_casters:
            again |= lights.type[shadow_rows] != DIRECTIONAL
        if not plan.patch_casters:
            recompute = again
        else:
            rows = changes.object_rows
            if changes.cast_rows.size:
                mark = np.zeros(len(objects), np.bool_)
                mark[rows] = True
                mark[changes.cast_rows] = True
                rows = np.flatnonzero(mark)
            patch = (rows, again)
    finder = _Finder(lights, objects, packed.rows, grid, (plan.origin, plan.fast), visible,
                     tuning, light_culling)
    return finder.casters(cameras.frames, cameras.splits, shadow_rows, recompute,
                          None if last is None else last.by_light, patch, cascade_overlap,
                          plan.keep_local_casters and not plan.keep_casters)


def _merge(rows_c: np.ndarray, masks_c: np.ndarray, changed: np.ndarray, rows_p: np.ndarray,
           masks_p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A kept list (rows_c ascending, masks_c) without the ``changed`` rows (flags by
    object row), with the changed rows' new casters (rows_p ascending, masks_p, nonzero)
    in their places."""
    keep = ~changed[rows_c]
    at = np.searchsorted(rows_c[keep], rows_p)
    return np.insert(rows_c[keep], at, rows_p), np.insert(masks_c[keep], at, masks_p)


@dataclass
class _Finder:
    """The casters stage's work for one frame: the stores, the packed lights, the light
    pass's grid, the records' frame (origin, single) and the objects' visibility."""

    lights: LightStore
    objects: ObjectStore
    packed: PackedLights
    grid: Grid
    frame: tuple[np.ndarray, bool]
    visible: np.ndarray
    tuning: Tuning
    light_culling: bool = False

    def casters(self, frames: CameraFrames, splits: np.ndarray, shadow_rows: np.ndarray,
                recompute: np.ndarray, cached: dict[int, tuple[np.ndarray, np.ndarray]] | None,
                patch: tuple[np.ndarray, np.ndarray] | None, overlap: float,
                cameras_moved: bool = False) -> Casters:
        """Directional lights scan every object against their cascade sweeps (over a grid
        of every object, boxes round SWEEP_GROUP of its positions' objects first); point
        and spot lights walk the light pass's grid, and when it holds the visible objects
        only, a grid of the same kind over the invisible casting objects that meet their
        spheres' bounding box (objects need not be visible to cast). Lights with
        ``recompute`` False take their lists from ``cached``. ``patch`` = (the object rows
        that changed, per shadow light whether it or the cameras it depends on did): a
        light that did not keeps its cached list but at those rows, which alone it tests
        (a directional light sweeps them, a point or spot light tests each).
        ``cameras_moved``: the cameras moved (lists kept or patched are point and spot
        lists under caster_culling "light")."""
        lights, objs = self.lights, self.objects
        n_s = shadow_rows.size
        if n_s == 0:
            return Casters(np.zeros(1, np.int64), np.zeros(0, np.int32), np.zeros(0, np.uint32),
                           np.zeros(0, np.int64), {}, "skipped: no shadow lights")
        found: list[tuple[np.ndarray, np.ndarray]] = [None] * n_s  # type: ignore[list-item]
        todo = []
        # A few lights: Python lists, not numpy calls, whose per-call overhead dominates
        # on tiny arrays.
        for t, (row, again) in enumerate(zip(shadow_rows.tolist(), recompute.tolist(),
                                             strict=True)):
            if again:
                todo.append(t)
            else:
                found[t] = cached[row]  # type: ignore[index]
        kept = "light and objects unchanged" if cameras_moved else \
            "light, cameras and objects unchanged"
        plan = [f"{n_s - len(todo)} kept ({kept})"] if len(todo) < n_s else []
        if cameras_moved and (len(todo) < n_s or patch is not None):
            plan.append('caster_culling "light": point and spot lists do not depend on the '
                        "cameras, which moved")
        if todo:
            rows_t = shadow_rows[todo]
            vols = culling_volumes(lights, rows_t, frames, splits, overlap,
                                   self.light_culling)
            is_dir = [t == DIRECTIONAL for t in lights.type[rows_t].tolist()]
            sun = [i for i, d in enumerate(is_dir) if d]
            patched = [] if patch is None else [i for i in sun if not patch[1][todo[i]]]
            sun = [i for i in sun if i not in patched]
            if sun:
                plan.append(self._suns(rows_t, sun, todo, vols, found))
            if patched:
                plan.append(self._patched(rows_t, patched, todo, vols, found, cached, patch[0]))
            local = [i for i, d in enumerate(is_dir) if not d]
            patched = [] if patch is None else [i for i in local if not patch[1][todo[i]]]
            local = [i for i in local if i not in patched]
            if patched:
                plan.append(self._patched_locals(rows_t, patched, todo, vols, found, cached,
                                                 patch[0]))
            if local:
                plan.append(self._locals(rows_t, local, todo, vols, found))
        # (np.cumsum of a short Python list costs more than the list.)
        offsets = np.array(list(accumulate((f[0].size for f in found), initial=0)), np.int64)
        rows = np.concatenate([f[0] for f in found]).astype(np.int64, copy=False)
        ids = objs.id[rows].astype(np.int32, copy=False)
        masks = np.concatenate([f[1] for f in found]).astype(np.uint32, copy=False)
        return Casters(offsets, ids, masks, rows, dict(zip(shadow_rows.tolist(), found, strict=True)),
                       "; ".join(plan))

    def _suns(self, rows_t: np.ndarray, sun: list[int], todo: list[int], vols: Volumes,
              found: list) -> str:
        """The casters of the directional lights ``sun`` (indices into rows_t) into
        ``found``; returns the plan's words for them."""
        objs, grid = self.objects, self.grid
        vn, vq, vm, shared = vols
        lmask = self.lights.mask[rows_t[sun]].astype(np.int64)
        sun_vols = Volumes(vn[sun], vq[sun], vm[sun], shared[sun])
        lo, hi, casts = objs.bounds_min, objs.bounds_max, objs.casts_shadows
        if grid.shown is not None:
            # A grid of every object: its group boxes first.
            boxes = group_boxes_of(grid, lo, hi, self.frame[1])
            at, rows, masks = sweep_groups(casts, objs.mask, lmask, sun_vols, boxes,
                                           grid.group_box)
            at = at.tolist()
            for i, t in enumerate(sun):
                found[todo[t]] = (rows[at[i]:at[i + 1]], masks[at[i]:at[i + 1]])
            return (f"{len(sun)} directional: the boxes of {SWEEP_GROUP} grid positions' "
                    f"objects, then the objects of those in a volume, against {vm.shape[1]} "
                    "cascade sweeps")
        bits = sweep_casters(lo, hi, casts, objs.mask, lmask, sun_vols)
        for i, t in enumerate(sun):
            rows = np.flatnonzero(bits[i])
            found[todo[t]] = (rows, bits[i][rows])
        return f"{len(sun)} directional: every object against {vm.shape[1]} cascade sweeps"

    def _patched(self, rows_t: np.ndarray, patched: list[int], todo: list[int], vols: Volumes,
                 found: list, cached: dict, rows_p: np.ndarray) -> str:
        """The directional lights ``patched`` keep their cached lists but at the changed
        object rows ``rows_p``, which alone they sweep."""
        objs = self.objects
        vn, vq, vm, shared = vols
        bits = sweep_casters(objs.bounds_min[rows_p], objs.bounds_max[rows_p],
                             objs.casts_shadows[rows_p], objs.mask[rows_p],
                             self.lights.mask[rows_t[patched]].astype(np.int64),
                             Volumes(vn[patched], vq[patched], vm[patched], shared[patched]))
        changed = np.zeros(len(objs), np.bool_)
        changed[rows_p] = True
        for i, t in enumerate(patched):
            rows_c, masks_c = cached[int(rows_t[t])]
            hit = np.flatnonzero(bits[i])
            found[todo[t]] = _merge(rows_c, masks_c, changed, rows_p[hit], bits[i][hit])
        return (f"{len(patched)} directional: the {rows_p.size} changed objects against "
                f"{vm.shape[1]} cascade sweeps, the others' kept")

    def _patched_locals(self, rows_t: np.ndarray, patched: list[int], todo: list[int],
                        vols: Volumes, found: list, cached: dict, rows_p: np.ndarray) -> str:
        """The point and spot lights ``patched`` keep their cached lists but at the changed
        object rows ``rows_p``, each of which they test (changed_casters) on its record made
        as the light pass's (the same frame), so each gets the bits a full walk gives it."""
        objs = self.objects
        rows_l = rows_t[patched].astype(np.int64)
        if len(patched) < len(todo):
            vols = Volumes(*(v[patched] for v in vols))
        changed = np.zeros(len(objs), np.bool_)
        changed[rows_p] = True
        recs = records_of(objs.bounds_min, objs.bounds_max, objs.mask,
                          rows_p.astype(np.int64), self.frame)
        at, new_rows, new_masks = changed_casters(
            self.packed, rows_l, recs,
            CasterObjects(objs.casts_shadows, objs.mask, objs.bounds_min, objs.bounds_max),
            vols)
        at = at.tolist()
        for i, t in enumerate(patched):
            rows_c, masks_c = cached[int(rows_t[t])]
            found[todo[t]] = _merge(rows_c, masks_c, changed, new_rows[at[i]:at[i + 1]],
                                    new_masks[at[i]:at[i + 1]])
        return (f"{len(patched)} point/spot: the {rows_p.size} changed objects only, the "
                "others' kept")

    def _locals(self, rows_t: np.ndarray, local: list[int], todo: list[int], vols: Volumes,
                found: list) -> str:
        """The casters of the point and spot lights ``local`` (indices into rows_t)."""
        grid = self.grid
        rows_l = rows_t[local].astype(np.int64)
        if len(local) < len(todo):
            vols = Volumes(*(v[local] for v in vols))
        part = self._in_grid(rows_l, grid.index, grid.records, vols)
        if grid.shown is not None:
            for i, t in enumerate(local):
                found[todo[t]] = (part[0][i], part[1][i])
            return f"{len(local)} point/spot: the grid of every object"
        parts = [part]
        hidden, nh = self._hidden(rows_l, vols)
        parts += hidden
        for i, t in enumerate(local):
            rows = np.concatenate([p[0][i] for p in parts])
            masks = np.concatenate([p[1][i] for p in parts])
            order = np.argsort(rows, kind="stable")
            found[todo[t]] = (rows[order], masks[order])
        return (f"{len(local)} point/spot: the grid of visible objects, then a grid of {nh} "
                "invisible casting objects near them")

    def _hidden(self, rows: np.ndarray, vols: Volumes
                ) -> tuple[list[tuple[list[np.ndarray], list[np.ndarray]]], int]:
        """For a grid of the visible objects only: the casters of the point and spot
        lights ``rows`` among the invisible casting objects near their spheres, from a
        grid of just those (the same construction), as a list of at most one part of
        ``_in_grid``; and how many such objects there are."""
        lights, objs = self.lights, self.objects
        lo, hi = objs.bounds_min, objs.bounds_max
        radius = lights.radius[rows]
        reach = lights.position[rows]
        r_box = np.concatenate([(reach - radius[:, None]).min(0),
                                (reach + radius[:, None]).max(0)])
        hidden = hidden_near(lo, hi, objs.casts_shadows, read_only_view(self.visible), r_box)
        nh = hidden.size
        if nh == 0:
            return [], 0
        f_box = frame_box(r_box, self.frame)
        shape = grid_shape(f_box[:3], f_box[3:],
                           self.tuning.cell_per_radius * float(np.median(radius)))
        index, recs, _ = records_grid(
            lo[hidden], hi[hidden], objs.mask[hidden], np.ones(nh, np.bool_), shape,
            self.frame)
        return [self._in_grid(rows, index, recs._replace(rows=hidden[recs.rows]), vols)], nh

    def _in_grid(self, rows: np.ndarray, index: GridIndex, recs: Records, vols: Volumes
                 ) -> tuple[list[np.ndarray], list[np.ndarray]]:
        """Per light of ``rows``, (object rows, masks) of its casters in one grid."""
        offsets = light_bounds(self.packed.hot, rows, index, recs.box.shape[0])
        out = CasterLists(np.empty(int(offsets[-1]), np.int64),
                          np.empty(int(offsets[-1]), np.uint32))
        objs = self.objects
        count = grid_casters(self.packed, rows, index, recs,
                             CasterObjects(objs.casts_shadows, objs.mask, objs.bounds_min,
                                           objs.bounds_max),
                             vols, offsets, out)
        spans = list(zip(offsets.tolist(), count.tolist(), strict=False))
        return ([out.rows[a:a + m] for a, m in spans],
                [out.masks[a:a + m] for a, m in spans])
