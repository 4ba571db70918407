"""The oracle: DESIGN section 2 in float64 Python floats and plain loops.

Every light is tested against every object, every rule is written out where it is used, in
the order DESIGN writes its formulas (no fused multiply-add, no vectorisation, no
acceleration structure). numpy is used only to read the stores and to build the output
arrays. The fast path (``lightsched.scheduler``) must agree with this module as DESIGN
section 4 says.

Decisions taken where DESIGN is silent (the fast path makes the same ones):

- ``visible_lights`` lists every visible light (directional always), whatever the masks and
  the unshadowed rule.
- Shadowed lights, tiers and ``slot_shadow`` follow DESIGN. Directional candidates rank
  among themselves by i + p_user, raised by the same hysteresis as the others when
  shadowed last frame. 2^ceil(log2 s) is evaluated exactly (math.frexp). ``cascade_splits`` is computed.
- Casters (DESIGN "Casters"): a frustum's corners are numbered z*4 + x*2 + y (z 0 near, 1
  far; x 0 left, 1 right; y 0 bottom, 1 top), computed as p + z f + (+-z t_x) r + (+-z t_y) u
  left to right, and its centroid is their mean. A hull edge plane through light position
  p has normal (c0 - p) x (c1 - p) and point p; a sweep edge plane has normal (c1 - c0) x v
  and point c0 (c0 the lower-numbered corner); either is flipped when the centroid is on
  its negative side. Normals are not normalised: the AABB test only needs their sign.
  A cube-face pyramid's planes are evaluated at the box corner farthest along each
  normal, x' = corner - p per axis. A point light's listed objects are those with some face
  bit set; a slice whose far depth is below its near depth (shadow_distance < near) is
  tested as written.
- Directional lights are ranked by P = i + p_user whatever the masks; with
  ``directional_in_slots`` they compete for slots instead (masks apply).
- Hysteresis looks at last frame's selected set, including selected lights that waited
  without a slot; that set is empty for a new object or one invisible last frame.
- An object that is new, was invisible last frame, on the first frame, or in a cut frame
  gets exactly its selected lights, on at weight 1.
- Residual: the lights competing for o's slots are those with a P for o (``_priorities``:
  visible, masks, Affects, not removed by "skip"); with "skip" those with shadows = true are
  then left out too, shadow lights included. u = (0, 0, 0) when v . v == 0 (which also
  covers a v so short that its square underflows). The residual is computed for both
  models: E does not depend on P.
- Thesis eccentricity uses the focal ray g = f + (focus_x t_x) r + (focus_y t_y) u and
  theta = atan2(|g x v|, g . v); P is the max over all cameras.
- Shadow views (DESIGN "Shadow views, updates and the atlas"): values are compared as
  stored (float equality, so -0.0 == 0.0); a directional view's camera as given (position,
  forward, up unnormalised). A directional view of a camera absent this frame keeps its
  memory while its light stays shadowed (split screens come and go). An update_objects
  call names a view's caster when the id is among the casters it held when rendered or
  holds now; the view remembers it until it is rendered, as static when the object is
  static now or was when rendered. A view is not ready from the frame its (tier, tile)
  differs from last frame's until it is rendered, even if it comes back to the tile it was
  last drawn in (another view may have been drawn there since).
- Atlas: the tile allocator is ``allocate_tiles``: a view keeps its tile while its tier
  holds; new and re-tiered views go largest first (then shadow_lights order, bit) to the
  first free aligned square in Morton order; if fragmentation leaves one without room,
  everything is packed again from an empty atlas the same way. stats counts
  ``tiles_moved`` (views of last frame and this one whose rect differs, re-tiered ones
  included) and ``texels_rendered`` (tier^2 over shadow_update's views, cascades at 4096).
"""

from __future__ import annotations

import copy
import math
import time
from typing import Any

import numpy as np

from .explain import ExplainRow, Explanation, explanation, object_row
from .frame import Frame, empty_frame, freeze
from .scene import (
    DIRECTIONAL,
    FADING_IN,
    FADING_OUT,
    ON,
    SPOT,
    Camera,
    Config,
    SceneAPI,
    ValidationError,
)

R0 = 0.1  # metres: the falloff's softening distance r0
EPS = 1e-6  # a weight within EPS of 1 is 1, a fading-out weight within EPS of 0 is 0

Vec = tuple[float, float, float]


# --------------------------------------------------------------------------- vectors


def _cross(a: Vec, b: Vec) -> Vec:
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def _dot(a: Vec, b: Vec) -> float:
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def _length(v: Vec) -> float:
    return math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])


def _normalize(v: Vec) -> Vec:
    n = math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
    return (v[0] / n, v[1] / n, v[2] / n)


def _vec(a: Any) -> Vec:
    return (float(a[0]), float(a[1]), float(a[2]))


def _sqrt0(x: float) -> float:
    """sqrt with a negative radicand counted as 0."""
    return math.sqrt(x) if x > 0.0 else 0.0


# --------------------------------------------------------------------------- cameras


class CameraFrame:
    """DESIGN section 2, "Camera frame": basis, tangents and the six inward planes."""

    def __init__(self, cam: Camera) -> None:
        self.position = p = _vec(cam.position)
        self.f = f = _normalize(_vec(cam.forward))
        self.r = r = _normalize(_cross(f, _vec(cam.up)))
        self.u = u = _cross(r, f)
        self.t_y = t_y = math.tan(float(cam.fov_y) / 2)
        self.t_x = t_x = float(cam.aspect) * t_y
        self.near = near = float(cam.near)
        self.far = far = float(cam.far)
        self.focus = (float(cam.focus[0]), float(cam.focus[1]))
        self.height_px = float(cam.height_px)
        sx = math.sqrt(1 + t_x * t_x)
        sy = math.sqrt(1 + t_y * t_y)
        near_point = (p[0] + near * f[0], p[1] + near * f[1], p[2] + near * f[2])
        far_point = (p[0] + far * f[0], p[1] + far * f[1], p[2] + far * f[2])
        # (inward unit normal, point on the plane)
        self.planes: list[tuple[Vec, Vec]] = [
            (f, near_point),
            ((-f[0], -f[1], -f[2]), far_point),
            (((r[0] + t_x * f[0]) / sx, (r[1] + t_x * f[1]) / sx, (r[2] + t_x * f[2]) / sx), p),
            (((-r[0] + t_x * f[0]) / sx, (-r[1] + t_x * f[1]) / sx, (-r[2] + t_x * f[2]) / sx),
             p),
            (((u[0] + t_y * f[0]) / sy, (u[1] + t_y * f[1]) / sy, (u[2] + t_y * f[2]) / sy), p),
            (((-u[0] + t_y * f[0]) / sy, (-u[1] + t_y * f[1]) / sy, (-u[2] + t_y * f[2]) / sy),
             p),
        ]
        fx, fy = self.focus
        ax = fx * t_x
        ay = fy * t_y
        # The focal ray through the focus point (thesis eccentricity).
        self.g: Vec = (f[0] + ax * r[0] + ay * u[0],
                       f[1] + ax * r[1] + ay * u[1],
                       f[2] + ax * r[2] + ay * u[2])


def signed_distance(n: Vec, point: Vec, x: Vec) -> float:
    """n . (x - point), written left to right."""
    return n[0] * (x[0] - point[0]) + n[1] * (x[1] - point[1]) + n[2] * (x[2] - point[2])


def ball_in_planes(planes: list[tuple[Vec, Vec]], centre: Vec, radius: float) -> bool:
    for n, point in planes:
        if not signed_distance(n, point, centre) >= -radius:
            return False
    return True


def aabb_in_planes(planes: list[tuple[Vec, Vec]], lo: Vec, hi: Vec) -> bool:
    for n, point in planes:
        corner = (hi[0] if n[0] >= 0 else lo[0],
                  hi[1] if n[1] >= 0 else lo[1],
                  hi[2] if n[2] >= 0 else lo[2])
        if not signed_distance(n, point, corner) >= 0:
            return False
    return True


def cascade_splits(cam: CameraFrame, config: Config) -> list[float]:
    """z_0..z_C of DESIGN section 2 (Casters, directional)."""
    near = cam.near
    d = min(cam.far, config.shadow_distance)
    c = config.cascades
    return [0.5 * near * (d / near) ** (i / c) + 0.5 * (near + (d - near) * i / c)
            for i in range(c + 1)]


# --------------------------------------------------------------------------- pairs


class _Light:
    __slots__ = ("row", "id", "type", "position", "radius", "direction", "outer", "inner",
                 "intensity", "p_user", "shadows", "mask")


class _Object:
    __slots__ = ("row", "id", "lo", "hi", "mask", "centre", "R", "e2", "casts", "static")


def _read_lights(store: Any) -> list[_Light]:
    out = []
    for row in range(len(store)):
        lt = _Light()
        lt.row = row
        lt.id = int(store.id[row])
        lt.type = int(store.type[row])
        lt.position = _vec(store.position[row])
        lt.radius = float(store.radius[row])
        lt.direction = _vec(store.direction[row])
        lt.outer = float(store.outer_angle[row])
        lt.inner = float(store.inner_angle[row])
        lt.intensity = float(store.intensity[row])
        lt.p_user = float(store.priority[row])
        lt.shadows = bool(store.shadows[row])
        lt.mask = int(store.mask[row])
        out.append(lt)
    return out


def _read_objects(store: Any) -> list[_Object]:
    out = []
    for row in range(len(store)):
        ob = _Object()
        ob.row = row
        ob.id = int(store.id[row])
        lo = ob.lo = _vec(store.bounds_min[row])
        hi = ob.hi = _vec(store.bounds_max[row])
        ob.mask = int(store.mask[row])
        ob.casts = bool(store.casts_shadows[row])
        ob.static = bool(store.static[row])
        ob.centre = ((lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, (lo[2] + hi[2]) / 2)
        ex, ey, ez = hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]
        ob.e2 = ex * ex + ey * ey + ez * ez
        ob.R = math.sqrt(ex * ex + ey * ey + ez * ez) / 2
        out.append(ob)
    return out


def box_distance2(lo: Vec, hi: Vec, p: Vec) -> float:
    """d2: squared distance from p to the box [lo, hi]."""
    dx = max(lo[0] - p[0], 0.0, p[0] - hi[0])
    dy = max(lo[1] - p[1], 0.0, p[1] - hi[1])
    dz = max(lo[2] - p[2], 0.0, p[2] - hi[2])
    return dx * dx + dy * dy + dz * dz


def _spot_geometry(lt: _Light, ob: _Object) -> tuple[float, float, float]:
    """(n, a, sqrt(n^2 - R^2)) for the sphere of ``ob`` seen from spot ``lt``."""
    c, p, axis = ob.centre, lt.position, lt.direction
    v = (c[0] - p[0], c[1] - p[1], c[2] - p[2])
    n = math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
    a = v[0] * axis[0] + v[1] * axis[1] + v[2] * axis[2]
    root = _sqrt0(n * n - ob.R * ob.R)
    return n, a, root


def affects_geometry(lt: _Light, ob: _Object) -> float | None:
    """The range and cone part of Affects for a point or spot light: d2, or None."""
    r = lt.radius
    d2 = box_distance2(ob.lo, ob.hi, lt.position)
    if not d2 <= r * r:
        return None
    if lt.type == SPOT:
        n, a, root = _spot_geometry(lt, ob)
        R = ob.R
        if not (n <= R or a >= math.cos(lt.outer) * root - R * math.sin(lt.outer)):
            return None
    return d2


def spot_factor(lt: _Light, ob: _Object) -> float:
    """s of the contribution model for a spot light."""
    n, a, root = _spot_geometry(lt, ob)
    R = ob.R
    if n <= R or a >= root:
        c = 1.0
    else:
        n2 = n * n
        c = (a * root + R * _sqrt0(n2 - a * a)) / n2 if n2 > 0.0 else 1.0
    cos_o = math.cos(lt.outer)
    cos_i = math.cos(lt.inner)
    # inner == outer is DESIGN's step; so is inner a few ulps from outer, where the cosines
    # round to the same value and the ramp would divide by zero.
    if lt.inner == lt.outer or cos_i == cos_o:
        return 1.0 if c >= cos_o else 0.0
    t = (c - cos_o) / (cos_i - cos_o)
    t = min(max(t, 0.0), 1.0)
    return t * t


def contribution_priority(lt: _Light, ob: _Object, d2: float) -> float:
    r = lt.radius
    q = d2 / (r * r)
    w = max(0.0, 1 - q * q)
    g = 1.0 if ob.e2 == 0 else min(1.0, 4 * r * r / ob.e2)
    s = spot_factor(lt, ob) if lt.type == SPOT else 1.0
    return lt.intensity * w * w * g / (d2 + R0 * R0) * s + lt.p_user


def thesis_priority(lt: _Light, ob: _Object, cams: list[CameraFrame], cfg: Config) -> float:
    p, c = lt.position, ob.centre
    do = (p[0] - c[0], p[1] - c[1], p[2] - c[2])
    d_object = math.sqrt(do[0] * do[0] + do[1] * do[1] + do[2] * do[2])
    best = -math.inf
    for cam in cams:
        e = cam.position
        v = (p[0] - e[0], p[1] - e[1], p[2] - e[2])
        d_viewer = math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
        r = lt.radius
        if d_viewer <= r:
            f = 1.0
        else:
            alpha = math.asin(min(1.0, r / d_viewer))
            theta = math.atan2(_length(_cross(cam.g, v)), _dot(cam.g, v))
            f = 1.0 if theta <= alpha else math.exp(-(theta - alpha) / cfg.c1)
        val = (cfg.w_ecc * f + cfg.w_dist * d_viewer + cfg.w_obj * d_object
               + cfg.w_int * lt.intensity)
        if val > best:
            best = val
    return best + lt.p_user


def _eccentricity(cam: CameraFrame, p: Vec, r: float, d_viewer: float, c1: float) -> float:
    """Berka's eccentricity f of DESIGN section 2 ("thesis")."""
    if d_viewer <= r:
        return 1.0
    v = (p[0] - cam.position[0], p[1] - cam.position[1], p[2] - cam.position[2])
    alpha = math.asin(min(1.0, r / d_viewer))
    theta = math.atan2(_length(_cross(cam.g, v)), _dot(cam.g, v))
    return 1.0 if theta <= alpha else math.exp(-(theta - alpha) / c1)


def shadow_importance(lt: _Light, cams: list[CameraFrame], c1: float) -> tuple[float, float]:
    """(importance, s_max) of a point or spot light (DESIGN section 2, "Shadowed lights"):
    s = height_px r / (max(d_viewer, r) t_y), importance = i min(1, s/height_px)^2 f +
    p_user, each the max over cameras."""
    best, s_max = -math.inf, 0.0
    for cam in cams:
        p, e = lt.position, cam.position
        v = (p[0] - e[0], p[1] - e[1], p[2] - e[2])
        d_viewer = math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
        s = cam.height_px * lt.radius / (max(d_viewer, lt.radius) * cam.t_y)
        m = min(1.0, s / cam.height_px)
        f = _eccentricity(cam, p, lt.radius, d_viewer, c1)
        best = max(best, lt.intensity * m * m * f + lt.p_user)
        s_max = max(s_max, s)
    return best, s_max


def pow2_ceil(x: float) -> float:
    """2^ceil(log2 x) for x > 0, exactly."""
    m, e = math.frexp(x)
    return math.ldexp(1.0, e - 1 if m == 0.5 else e)


def _by_priority(items: dict[int, float]) -> list[int]:
    """Light ids by value descending, ties to the lower id."""
    return sorted(items, key=lambda lid: (-items[lid], lid))


# --------------------------------------------------------------------------- casters

Plane = tuple[Vec, Vec]  # (normal, point); signed distance n . (x - point)

# Frustum faces: 0 near, 1 far, 2 left, 3 right, 4 bottom, 5 top. A corner z*4 + x*2 + y
# lies on near (z 0) or far (z 1), left (x 0) or right (x 1), bottom (y 0) or top (y 1).
_FACE_CORNERS = [[c for c in range(8) if test(c)] for test in (
    lambda c: c >> 2 == 0, lambda c: c >> 2 == 1, lambda c: (c >> 1) & 1 == 0,
    lambda c: (c >> 1) & 1 == 1, lambda c: c & 1 == 0, lambda c: c & 1 == 1)]


def _edges() -> list[tuple[int, int, int, int]]:
    """(face a, face b, corner c0 < c1) for the 12 edges: two faces that share two corners."""
    out = []
    for a in range(6):
        for b in range(a + 1, 6):
            common = sorted(set(_FACE_CORNERS[a]) & set(_FACE_CORNERS[b]))
            if len(common) == 2:
                out.append((a, b, common[0], common[1]))
    return out


EDGES = _edges()


def frustum_corners(cam: CameraFrame, z_near: float, z_far: float) -> list[Vec]:
    """The 8 corners p + z f +- z t_x r +- z t_y u at depths z_near and z_far."""
    p, f, r, u = cam.position, cam.f, cam.r, cam.u
    out = []
    for z in (z_near, z_far):
        for sx in (-z * cam.t_x, z * cam.t_x):
            for sy in (-z * cam.t_y, z * cam.t_y):
                out.append(tuple(p[i] + z * f[i] + sx * r[i] + sy * u[i] for i in range(3)))
    return out


def _mean(points: list[Vec]) -> Vec:
    return tuple(sum(q[i] for q in points) / len(points) for i in range(3))


def _sub(a: Vec, b: Vec) -> Vec:
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


def _oriented(n: Vec, point: Vec, inside: Vec) -> Plane:
    """The plane (n, point) flipped if need be so that ``inside`` is not on its negative side."""
    if _dot(n, _sub(inside, point)) < 0:
        n = (-n[0], -n[1], -n[2])
    return n, point


def hull_planes(cam: CameraFrame, p: Vec) -> list[Plane]:
    """Convex hull of point p and the camera frustum F (point/spot culling volume): F's
    planes with p at signed distance >= 0, plus the plane through p and every edge of F
    whose two faces see p on opposite sides."""
    corners = frustum_corners(cam, cam.near, cam.far)
    centroid = _mean(corners)
    side = [signed_distance(n, q, p) >= 0 for n, q in cam.planes]
    planes = [pl for pl, keep in zip(cam.planes, side, strict=True) if keep]
    for a, b, c0, c1 in EDGES:
        if side[a] != side[b]:
            n = _cross(_sub(corners[c0], p), _sub(corners[c1], p))
            planes.append(_oriented(n, p, centroid))
    return planes


def sweep_planes(cam: CameraFrame, z_near: float, z_far: float, v: Vec) -> list[Plane]:
    """The slice [z_near, z_far] of the camera frustum swept along v (towards a directional
    light): the slice's planes with n . v >= 0, plus for every edge between a kept and a
    dropped face the plane containing that edge and v."""
    p, f = cam.position, cam.f
    corners = frustum_corners(cam, z_near, z_far)
    centroid = _mean(corners)
    slice_planes = [(f, tuple(p[i] + z_near * f[i] for i in range(3))),
                    ((-f[0], -f[1], -f[2]), tuple(p[i] + z_far * f[i] for i in range(3)))]
    slice_planes += cam.planes[2:]
    keep = [_dot(n, v) >= 0 for n, _ in slice_planes]
    planes = [pl for pl, k in zip(slice_planes, keep, strict=True) if k]
    for a, b, c0, c1 in EDGES:
        if keep[a] != keep[b]:
            n = _cross(_sub(corners[c1], corners[c0]), v)
            planes.append(_oriented(n, corners[c0], centroid))
    return planes


def cube_face_bits(p: Vec, r: float, lo: Vec, hi: Vec) -> int:
    """Bit f for each cube face pyramid (+x, -x, +y, -y, +z, -z) the box is in: for +x,
    x' >= 0, x' -+ y' >= 0, x' -+ z' >= 0, r - x' >= 0 with x' = x - p, each at the box
    corner farthest along the plane's normal."""
    bits = 0
    for a in range(3):
        for sign in (1, -1):
            lo_a, hi_a = lo[a] - p[a], hi[a] - p[a]
            top = hi_a if sign > 0 else -lo_a      # the largest sign * x' over the box
            bottom = lo_a if sign > 0 else -hi_a   # the smallest
            ok = top >= 0 and r - bottom >= 0
            for b in range(3):
                if b != a:
                    ok = ok and top - (lo[b] - p[b]) >= 0 and top + (hi[b] - p[b]) >= 0
            if ok:
                bits |= 1 << (2 * a + (sign < 0))
    return bits


def caster_mask(lt: _Light, ob: _Object, volumes: list[list[Plane]] | None) -> int:
    """caster_masks entry of object ``ob`` for shadowed light ``lt`` (0: not a caster).
    ``volumes`` are the light's culling volumes: one hull per camera (point/spot) or one
    sweep per camera and cascade, bit camera*C + cascade (directional); None for a point
    or spot light under caster_culling = "light" (no camera test)."""
    if not (ob.casts and lt.mask & ob.mask):
        return 0
    if lt.type == DIRECTIONAL:
        bits = 0
        for bit, planes in enumerate(volumes):
            if aabb_in_planes(planes, ob.lo, ob.hi):
                bits |= 1 << bit
        return bits
    if affects_geometry(lt, ob) is None:
        return 0
    if volumes is not None and not any(aabb_in_planes(planes, ob.lo, ob.hi)
                                       for planes in volumes):
        return 0
    return 1 if lt.type == SPOT else cube_face_bits(lt.position, lt.radius, ob.lo, ob.hi)


def culling_volumes(lt: _Light, cams: list[CameraFrame], cfg: Config
                    ) -> list[list[Plane]] | None:
    """The light's culling volumes (DESIGN section 2, "Casters"); None for a point or spot
    light under caster_culling = "light" ("Shadow views": no camera test)."""
    if lt.type != DIRECTIONAL:
        if cfg.caster_culling == "light":
            return None
        return [hull_planes(cam, lt.position) for cam in cams]
    v = (-lt.direction[0], -lt.direction[1], -lt.direction[2])
    volumes = []
    for cam in cams:
        z = cascade_splits(cam, cfg)
        for c in range(cfg.cascades):
            a = cam.near if c == 0 else z[c] - cfg.cascade_overlap * (z[c] - z[c - 1])
            volumes.append(sweep_planes(cam, a, z[c + 1], v))
    return volumes


# --------------------------------------------------------------------------- scheduler


class _ObjectState:
    __slots__ = ("slots", "selected", "visible")

    def __init__(self) -> None:
        self.slots: list[list[Any]] = []  # [light_id, weight, state]
        self.selected: set[int] = set()
        self.visible = False


class Scheduler(SceneAPI):
    """Steps frames the slow, obvious way (DESIGN section 7, the oracle)."""

    def __init__(self, config: Config | None = None) -> None:
        super().__init__(config)
        self._state: dict[int, _ObjectState] = {}
        self._shadowed: dict[int, int] = {}  # light id -> tier, last frame's shadow lights
        # Shadow views by key (light id, bit) for point and spot lights, (light id,
        # "camera", camera id, cascade) for directional ones; last frame's atlas tiles by
        # point/spot key.
        self._views: dict[tuple[Any, ...], _View] = {}
        self._tiles: dict[tuple[int, int], tuple[int, int, int]] = {}
        self._explained: dict[str, Any] | None = None  # what explain reads of the last frame

    def _memory(self) -> Any:
        return copy.deepcopy((self._state, self._shadowed, self._views, self._tiles)), \
            self._explained

    def _put_back(self, memory: Any) -> None:
        (self._state, self._shadowed, self._views, self._tiles), self._explained = memory

    def _frame(self, cameras: list[Camera], dt: float, cut: bool) -> Frame:
        t0 = time.perf_counter()
        cfg = self.config
        cams = [CameraFrame(c) for c in cameras]
        lights = _read_lights(self.lights)
        objects = _read_objects(self.objects)
        is_new = [bool(x) for x in self.objects.is_new]
        restart = self.frame_index == 0 or cut

        # Fade state follows ids; ids gone from the store lose it.
        live = {ob.id for ob in objects}
        self._state = {oid: st for oid, st in self._state.items() if oid in live}
        began = {ob.id: (set() if is_new[ob.row] or ob.id not in self._state
                         else {s[0] for s in self._state[ob.id].slots})
                 for ob in objects}

        light_visible, object_visible = _visibility(lights, objects, cams)
        shadow_ids, tiers, importance = self._shadow_lights(lights, objects, cams,
                                                            light_visible, object_visible)
        frame = empty_frame(self.objects.id, cfg.max_lights, cfg.cascades)
        casters = _write_casters(frame, lights, objects, shadow_ids, cams, cfg)
        ready, view_counts = self._shadow_views(frame, lights, objects, shadow_ids, tiers,
                                                importance, casters, cameras)
        # slot_shadow samples only maps whose every view is ready ("Sampling").
        shadow_index = {lid: k for k, lid in enumerate(shadow_ids) if ready[k]}
        # With "skip", a shadowed light that did not get a shadow map, or whose map has a
        # view not ready, affects nothing.
        skipped = [cfg.unshadowed == "skip" and lt.shadows and lt.id not in shadow_index
                   for lt in lights]
        competing = [lt for lt in lights if light_visible[lt.row] and not skipped[lt.row]]

        row_of = {lt.id: lt.row for lt in lights}
        by_id = {lt.id: lt for lt in lights}
        pairs = 0
        explained: dict[int, Any] = {}  # object id -> (last selection, slots, selection)
        for ob in objects:
            st = self._state.get(ob.id)
            new = is_new[ob.row] or st is None
            if new:
                st = self._state[ob.id] = _ObjectState()
            prev_selected = st.selected if st.visible and not new else set()
            if not object_visible[ob.row]:
                st.slots, st.selected, st.visible = [], set(), False
                continue
            frame.visible[ob.row] = True
            prio = _priorities(competing, ob, cams, cfg)
            frame.candidates[ob.row] = len(prio)
            pairs += len(prio)
            selected = _select(prio, prev_selected, cfg)
            if new or not st.visible or restart:
                st.slots = [[lid, 1.0, ON] for lid in selected]
            else:
                st.slots = _fade(st.slots, prio, selected, dt, cfg)
            st.selected = set(selected)
            st.visible = True
            _write_object(frame, ob.row, st.slots, prio, row_of, shadow_index, cfg)
            if cfg.residual:
                frame.residual[ob.row] = _residual(ob, st.slots, prio, by_id, cfg)
            explained[ob.id] = (prev_selected, copy.deepcopy(st.slots), set(selected))

        directional = {lt.id: lt.intensity + lt.p_user for lt in lights
                       if lt.type == DIRECTIONAL and not skipped[lt.row]}
        frame.directional_lights = np.array(
            [] if cfg.directional_in_slots else _by_priority(directional), dtype=np.int32)
        frame.shadow_lights = np.array(shadow_ids, dtype=np.int32)
        frame.shadow_tier = np.array(tiers, dtype=np.uint16)
        frame.camera_ids = np.array([camera_id(k, c) for k, c in enumerate(cameras)], np.int32)
        frame.visible_lights = np.array([lt.id for lt in lights if light_visible[lt.row]],
                                        dtype=np.int32)
        frame.cascade_splits = np.array([cascade_splits(cam, cfg) for cam in cams],
                                        dtype=np.float64).reshape(len(cams), cfg.cascades + 1)
        self._explained = {
            "frame_index": self.frame_index, "config": cfg, "cameras": cams,
            "lights": lights, "objects": objects, "light_visible": light_visible,
            "object_visible": object_visible, "skipped": skipped, "competing": competing,
            "began": began, "objects_state": explained}
        frame.stats = {
            "plan": {"all": "reference"},
            "counts": {
                "visible_objects": int(sum(object_visible)),
                "visible_lights": int(sum(light_visible)),
                "pairs": pairs,
                **view_counts,
            },
            "seconds": {"total": time.perf_counter() - t0},
        }
        return freeze(frame)

    def explain(self, object_id: Any) -> Explanation:
        """DESIGN section 7, explain: each light that was visible, holds a slot of the
        object or held one when the last frame began, with the first reason that applies."""
        rec = self._explained
        if rec is None:
            raise ValidationError("object_id", None, "no frame has run yet")
        objects: list[_Object] = rec["objects"]
        ob = objects[object_row(np.array([o.id for o in objects], np.int64), object_id)]
        cfg: Config = rec["config"]
        lights: list[_Light] = rec["lights"]
        by_id = {lt.id: lt for lt in lights}
        visible = rec["object_visible"][ob.row]
        prev_selected, slots, selected = rec["objects_state"].get(ob.id, (set(), [], set()))
        prio = _priorities(rec["competing"], ob, rec["cameras"], cfg) if visible else {}
        lit = sorted((s for s in slots if s[2] != FADING_OUT), key=lambda s: (-prio[s[0]], s[0]))
        out = sorted((s for s in slots if s[2] == FADING_OUT), key=lambda s: (-s[1], s[0]))
        slot_of = {s[0]: (k, s) for k, s in enumerate(lit + out)}
        wanted = ({lt.id for lt in lights if rec["light_visible"][lt.row]}
                  | set(slot_of) | rec["began"][ob.id])
        rows: dict[int, ExplainRow] = {}
        for lid in wanted:
            lt = by_id.get(lid)
            d2 = math.nan if lt is None or lt.type == DIRECTIONAL else \
                box_distance2(ob.lo, ob.hi, lt.position)
            p = prio.get(lid, math.nan)
            key = math.nan
            if lid in prio:
                key = p + cfg.hysteresis * abs(p) + cfg.hysteresis_abs \
                    if lid in prev_selected else p
            if lt is None:
                reason = "removed"
            elif not visible:
                reason = "object_not_visible"
            elif not rec["light_visible"][lt.row]:
                reason = "light_not_visible"
            elif not lt.mask & ob.mask:
                reason = "masked"
            elif rec["skipped"][lt.row]:
                reason = "unshadowed_skip"
            elif lt.type == DIRECTIONAL and not cfg.directional_in_slots:
                reason, p = "directional", lt.intensity + lt.p_user
            elif lid not in prio:
                reason = "out_of_range" if not d2 <= lt.radius * lt.radius else "outside_cone"
            elif lid in slot_of and slot_of[lid][1][2] != FADING_OUT:
                reason = "selected"
            elif lid in selected:
                reason = "waiting"
            elif lid in slot_of:
                reason = "fading_out"
            else:
                reason = "below_k"
            k, slot = slot_of.get(lid, (-1, None))
            rows[lid] = ExplainRow(p, key, d2, k, math.nan if slot is None else slot[1],
                                   -1 if slot is None else slot[2], reason)
        return explanation(ob.id, rec["frame_index"], rows)

    def _shadow_lights(self, lights: list[_Light], objects: list[_Object],
                       cams: list[CameraFrame], light_visible: list[bool],
                       object_visible: list[bool]
                       ) -> tuple[list[int], list[int], dict[int, float]]:
        """Shadowed lights (DESIGN section 2, "Shadowed lights"): visible, shadows = true,
        affecting a visible object (Affects without the unshadowed rule); ranked by
        importance with hysteresis, directional lights first; their ids and tiers, which
        the next frame's hysteresis remembers, then fitted to the atlas ("Atlas": lights
        past the longest prefix that fits at 256 leave, then tiers drop from the back; the
        hysteresis remembers the tiers before). Also each candidate's importance without
        the hysteresis bonus (the update budget's order)."""
        cfg = self.config
        h = cfg.hysteresis
        keys_dir: dict[int, float] = {}
        keys_other: dict[int, float] = {}
        s_max_of: dict[int, float] = {}
        importance: dict[int, float] = {}
        for lt in lights:
            if not (lt.shadows and light_visible[lt.row]):
                continue
            if not any(object_visible[ob.row] and lt.mask & ob.mask
                       and (lt.type == DIRECTIONAL or affects_geometry(lt, ob) is not None)
                       for ob in objects):
                continue
            if lt.type == DIRECTIONAL:
                imp = lt.intensity + lt.p_user
            else:
                imp, s_max_of[lt.id] = shadow_importance(lt, cams, cfg.c1)
            importance[lt.id] = imp
            if lt.id in self._shadowed:
                imp = imp + h * abs(imp) + cfg.hysteresis_abs
            (keys_dir if lt.type == DIRECTIONAL else keys_other)[lt.id] = imp
        shadow_ids = (_by_priority(keys_dir) + _by_priority(keys_other))[:cfg.shadow_budget]
        tiers = []
        for lid in shadow_ids:
            if lid in keys_dir:
                tiers.append(4096)
                continue
            s_max = s_max_of[lid]
            tier = int(min(max(pow2_ceil(s_max), 256.0), 4096.0))
            prev = self._shadowed.get(lid)
            if prev is not None and prev / (2 * (1 + h)) <= s_max <= prev * (1 + h):
                tier = prev
            tiers.append(tier)
        if cfg.shadow_atlas_size:
            types = {lt.id: lt.type for lt in lights}
            views = [0 if types[lid] == DIRECTIONAL else view_count(types[lid])
                     for lid in shadow_ids]
            kept, fitted = fit_atlas(views, tiers, cfg.shadow_atlas_size)
            shadow_ids, tiers = shadow_ids[:kept], tiers[:kept]
        else:
            fitted = tiers
        self._shadowed = dict(zip(shadow_ids, tiers, strict=True))
        return shadow_ids, fitted, importance

    def _shadow_views(self, frame: Any, lights: list[_Light], objects: list[_Object],
                      shadow_ids: list[int], tiers: list[int], importance: dict[int, float],
                      casters: list[list[tuple[_Object, int]]], cameras: list[Camera]
                      ) -> tuple[list[bool], dict[str, int]]:
        """DESIGN section 2, "Shadow views, updates and the atlas": every shadow light's
        views with their atlas tiles, which are dirty (and why: static or not), which are
        rendered this frame within the budget, and what each view now holds. Writes
        shadow_views, shadow_dirty, shadow_static_dirty, shadow_update and shadow_rect;
        returns per shadow light whether every view is ready, and the stats counts."""
        cfg = self.config
        atlas, n_casc = cfg.shadow_atlas_size, cfg.cascades
        by_id = {lt.id: lt for lt in lights}
        obj_by_id = {ob.id: ob for ob in objects}
        named = {int(x) for ids in self.objects.named for x in ids}
        cam_ids = [camera_id(k, c) for k, c in enumerate(cameras)]
        cam_states = [_camera_state(c, cascade_splits(CameraFrame(c), cfg)) for c in cameras]
        # A light that leaves shadow_lights forgets its views.
        live = set(shadow_ids)
        self._views = {key: v for key, v in self._views.items() if key[0] in live}

        wanted = []
        for j, lid in enumerate(shadow_ids):
            lt = by_id[lid]
            if lt.type != DIRECTIONAL:
                wanted += [((lid, bit), tiers[j], (j, bit)) for bit in range(view_count(lt.type))]
        prev_tiles = self._tiles
        tiles = allocate_tiles(wanted, prev_tiles, atlas) if atlas else {}
        moved = sum(1 for key, t in tiles.items() if key in prev_tiles and prev_tiles[key] != t)
        self._tiles = tiles

        S = len(shadow_ids)
        out = {name: [0] * S for name in ("views", "dirty", "static", "update")}
        rect = np.full((S, 6, 3), -1, np.int32)
        entries = []  # (j, bit, view, state, directional, dirty)
        for j, lid in enumerate(shadow_ids):
            lt = by_id[lid]
            if lt.type == DIRECTIONAL:
                light_state: tuple[Any, ...] = (lt.type, lt.direction)
                bits = [(k * n_casc + c, (lid, "camera", cam_ids[k], c), cam_states[k])
                        for k in range(len(cameras)) for c in range(n_casc)]
            else:
                light_state = (lt.type, lt.position, lt.radius)
                if lt.type == SPOT:
                    light_state += (lt.direction, lt.outer)
                bits = [(bit, (lid, bit), None) for bit in range(view_count(lt.type))]
            for bit, key, cam_state in bits:
                held_now = {ob.id: (ob.lo, ob.hi, ob.casts, ob.mask, ob.static)
                            for ob, mask in casters[j] if mask >> bit & 1}
                tile = tiles.get(key)
                if tile is not None:
                    rect[j, bit] = tile
                state = {"light": light_state, "tier": tiers[j], "tile": tile,
                         "camera": cam_state, "casters": held_now}
                view = self._views.get(key)
                if view is None:
                    view = self._views[key] = _View()
                # A new tile or tier holds nothing of the view until it is drawn there.
                if view.placed != (tiers[j], tile):
                    view.ready = False
                    view.placed = (tiers[j], tile)
                dirty, static = _view_dirty(view, state, named, obj_by_id)
                entries.append((j, bit, view, state, lt.type == DIRECTIONAL, dirty, static))
                out["views"][j] |= 1 << bit
                out["dirty"][j] |= dirty << bit
                out["static"][j] |= static << bit

        budget = cfg.shadow_update_budget
        local = [e for e in entries if e[5] and not e[4]]
        if budget and len(local) > budget:
            def order(e: tuple[Any, ...]) -> tuple[Any, ...]:
                j, bit, view = e[0], e[1], e[2]
                if not view.ready:
                    return (0, j, bit)
                imp = importance[shadow_ids[j]]
                return (1, -((1 + view.age) * max(imp, 0.0)), -view.age, j, bit)
            local = sorted(local, key=order)[:budget]
        chosen = {id(e) for e in local}
        texels = 0
        for e in entries:
            j, bit, view, state, directional, dirty, _ = e
            if dirty and (directional or id(e) in chosen):
                view.rendered = state
                view.ready = True
                view.named = view.named_static = False
                view.age = 0
                out["update"][j] |= 1 << bit
                texels += tiers[j] * tiers[j]
            elif dirty:
                view.age += 1
            else:
                view.age = 0
        ready = [True] * S
        for j, _, view, *_ in entries:
            ready[j] = ready[j] and view.ready
        frame.shadow_views = np.array(out["views"], np.uint32)
        frame.shadow_dirty = np.array(out["dirty"], np.uint32)
        frame.shadow_static_dirty = np.array(out["static"], np.uint32)
        frame.shadow_update = np.array(out["update"], np.uint32)
        frame.shadow_rect = rect
        return ready, {"tiles_moved": moved, "texels_rendered": texels}


# --------------------------------------------------------------------------- shadow views

MIN_TIER = 256


class _View:
    """One shadow view's memory: what it held when last rendered (None: never), whether
    its map is ready, its age, whether an update_objects call named a (static) caster of it
    since, and the (tier, tile) it had last frame."""

    __slots__ = ("rendered", "ready", "age", "named", "named_static", "placed")

    def __init__(self) -> None:
        self.rendered: dict[str, Any] | None = None
        self.ready = False
        self.age = 0
        self.named = False
        self.named_static = False
        self.placed: tuple[int, Any] | None = None


def view_count(light_type: int) -> int:
    """Views of a point (six cube faces) or spot light (one)."""
    return 1 if light_type == SPOT else 6


def camera_id(position: int, cam: Camera) -> int:
    """A camera's id: its own, or its position in the frame's list (DESIGN section 1)."""
    return position if cam.id is None else int(cam.id)


def _camera_state(cam: Camera, splits: list[float]) -> tuple[Any, ...]:
    """What a directional view remembers of its camera (DESIGN "Dirty")."""
    return (_vec(cam.position), _vec(cam.forward), _vec(cam.up), float(cam.fov_y),
            float(cam.aspect), float(cam.near), float(cam.far), tuple(splits))


def fit_atlas(views: list[int], tiers: list[int], atlas: int) -> tuple[int, list[int]]:
    """DESIGN "Atlas", the fit: ``views`` per shadow light in shadow_lights order (0 for
    directional ones). Returns how many lights stay (the longest prefix that fits at 256,
    or all) and their tiers after lowering the last light above 256, one tier at a time,
    while sum views * tier^2 > atlas^2."""
    room = atlas * atlas
    kept, used = len(views), 0
    for j, v in enumerate(views):
        used += v * MIN_TIER * MIN_TIER
        if used > room:
            kept = j
            break
    tiers = list(tiers[:kept])
    while sum(v * t * t for v, t in zip(views, tiers, strict=False)) > room:
        j = max(j for j in range(kept) if views[j] and tiers[j] > MIN_TIER)
        tiers[j] //= 2
    return kept, tiers


def first_fit(tiles: list[tuple[int, int, int]], atlas: int, size: int
              ) -> tuple[int, int] | None:
    """The first free aligned size x size square of the atlas in Morton order (quadrants
    (0, 0), (1, 0), (0, 1), (1, 1), x first), beside ``tiles`` (aligned power-of-two
    squares: one either holds a node of the quadtree, lies in it or misses it)."""
    def search(x: int, y: int, s: int, inside: list[tuple[int, int, int]]
               ) -> tuple[int, int] | None:
        if not inside:
            return x, y
        if s == size or any(t[2] >= s for t in inside):
            return None
        h = s // 2
        for qx, qy in ((x, y), (x + h, y), (x, y + h), (x + h, y + h)):
            sub = [t for t in inside
                   if t[0] < qx + h and qx < t[0] + t[2] and t[1] < qy + h and qy < t[1] + t[2]]
            found = search(qx, qy, h, sub)
            if found is not None:
                return found
        return None
    return search(0, 0, atlas, list(tiles))


def allocate_tiles(wanted: list[tuple[Any, int, tuple[int, int]]],
                   prev: dict[Any, tuple[int, int, int]], atlas: int
                   ) -> dict[Any, tuple[int, int, int]]:
    """Atlas tiles (x, y, size) of the views ``wanted`` ((key, tier, (shadow index, bit)),
    which fit: sum of tier^2 <= atlas^2). A view keeps last frame's tile (``prev``) while
    its tier holds; the others are placed largest first (then shadow_lights order, bit) at
    the first free square in Morton order. When fragmentation leaves one without room,
    everything is packed again the same way from an empty atlas (largest first in Morton
    order always fits what the fit rule admits)."""
    tiles = {key: prev[key] for key, size, _ in wanted if key in prev and prev[key][2] == size}
    todo = sorted(((size, rank, key) for key, size, rank in wanted if key not in tiles),
                  key=lambda t: (-t[0], t[1]))
    for size, _, key in todo:
        at = first_fit(list(tiles.values()), atlas, size)
        if at is None:
            break
        tiles[key] = (at[0], at[1], size)
    else:
        return tiles
    tiles = {}
    for size, _, key in sorted(((size, rank, key) for key, size, rank in wanted),
                               key=lambda t: (-t[0], t[1])):
        at = first_fit(list(tiles.values()), atlas, size)
        assert at is not None
        tiles[key] = (at[0], at[1], size)
    return tiles


def _view_dirty(view: _View, state: dict[str, Any], named: set[int],
                obj_by_id: dict[int, _Object]) -> tuple[bool, bool]:
    """(dirty, static dirty) of a view whose state is now ``state`` (DESIGN "Dirty"):
    against what it held when last rendered, and the update_objects calls since, which
    the view remembers until it is rendered (``named``: the ids named since last frame)."""
    held = view.rendered
    if held is None:
        return True, True
    static = any(held[k] != state[k] for k in ("light", "tier", "tile", "camera"))
    dynamic = False
    then, now = held["casters"], state["casters"]
    for oid in then.keys() | now.keys():
        a, b = now.get(oid), then.get(oid)
        if a != b:
            if (a is not None and a[4]) or (b is not None and b[4]):
                static = True
            else:
                dynamic = True
    for oid in named & (then.keys() | now.keys()):
        ob = obj_by_id.get(oid)
        if (ob is not None and ob.static) or (oid in then and then[oid][4]):
            view.named_static = True
        else:
            view.named = True
    static = static or view.named_static
    return static or dynamic or view.named, static


def _visibility(lights: list[_Light], objects: list[_Object], cams: list[CameraFrame]
                ) -> tuple[list[bool], list[bool]]:
    """DESIGN section 2, "Visibility": per light row and per object row."""
    light_visible = [lt.type == DIRECTIONAL
                     or any(ball_in_planes(cam.planes, lt.position, lt.radius) for cam in cams)
                     for lt in lights]
    object_visible = [any(aabb_in_planes(cam.planes, ob.lo, ob.hi) for cam in cams)
                      for ob in objects]
    return light_visible, object_visible


def _priorities(competing: list[_Light], ob: _Object, cams: list[CameraFrame],
                cfg: Config) -> dict[int, float]:
    """P of every light of ``competing`` (visible, not skipped) that competes for a slot of
    ``ob`` and affects it (DESIGN section 2, "Slots", "Affects" and "Priority")."""
    prio: dict[int, float] = {}
    for lt in competing:
        if not lt.mask & ob.mask:
            continue
        if lt.type == DIRECTIONAL:
            if cfg.directional_in_slots:
                prio[lt.id] = lt.intensity + lt.p_user
            continue
        d2 = affects_geometry(lt, ob)
        if d2 is None:
            continue
        if cfg.model == "contribution":
            prio[lt.id] = contribution_priority(lt, ob, d2)
        else:
            prio[lt.id] = thesis_priority(lt, ob, cams, cfg)
    return prio


def _select(prio: dict[int, float], prev_selected: set[int], cfg: Config) -> list[int]:
    """DESIGN section 2, "Selection": the K lights of highest key, last frame's selection
    raised by the hysteresis."""
    key = {}
    for lid, p in prio.items():
        if lid in prev_selected:
            key[lid] = p + cfg.hysteresis * abs(p) + cfg.hysteresis_abs
        else:
            key[lid] = p
    return _by_priority(key)[:cfg.max_lights]


def _fade(slots: list[list[Any]], prio: dict[int, float], selected: list[int], dt: float,
          cfg: Config) -> list[list[Any]]:
    """DESIGN section 2, "Fade": last frame's slots stepped, then the selected lights
    without a slot take the free ones, by P."""
    selected_set = set(selected)
    out = []
    for lid, weight, state in slots:
        if lid not in prio:
            continue  # no longer affects: freed at once
        if lid in selected_set:
            if state != ON:
                state = FADING_IN
                weight = 1.0 if cfg.fade_in == 0 else weight + dt / cfg.fade_in
                if weight >= 1 - EPS:
                    weight, state = 1.0, ON
            out.append([lid, weight, state])
        else:
            if cfg.fade_out == 0:
                continue
            weight = weight - dt / cfg.fade_out
            if weight <= EPS:
                continue
            out.append([lid, weight, FADING_OUT])
    held = {s[0] for s in out}
    waiting = _by_priority({lid: prio[lid] for lid in selected if lid not in held})
    for lid in waiting[:cfg.max_lights - len(out)]:
        weight = 1.0 if cfg.fade_in == 0 else min(1.0, dt / cfg.fade_in)
        state = FADING_IN
        if weight >= 1 - EPS:
            weight, state = 1.0, ON
        out.append([lid, weight, state])
    return out


def _write_object(frame: Any, row: int, slots: list[list[Any]], prio: dict[int, float],
                  row_of: dict[int, int], shadow_index: dict[int, int], cfg: Config) -> None:
    """Object ``row``'s outputs (DESIGN section 3): its slots in output order, then
    slot_shadow."""
    lit = [s for s in slots if s[2] != FADING_OUT]
    out = [s for s in slots if s[2] == FADING_OUT]
    lit.sort(key=lambda s: (-prio[s[0]], s[0]))
    out.sort(key=lambda s: (-s[1], s[0]))
    ordered = lit + out
    frame.count[row] = len(ordered)
    # slot_shadow: up to max_shadowed_per_object shadowed slots, by weight, then output
    # order (fading-out slots still sample their map).
    shadowed = [(-w, j) for j, (lid, w, _) in enumerate(ordered) if lid in shadow_index]
    for _, j in sorted(shadowed)[:cfg.max_shadowed_per_object]:
        frame.slot_shadow[row, j] = shadow_index[ordered[j][0]]
    for j, (lid, weight, state) in enumerate(ordered):
        frame.light_ids[row, j] = lid
        frame.light_index[row, j] = row_of[lid]
        frame.priority[row, j] = np.float32(prio[lid])
        frame.fade_weight[row, j] = np.float32(weight)
        frame.fade_state[row, j] = state


def residual_term(lt: _Light, ob: _Object) -> tuple[float, Vec]:
    """(E_l, u_l) of DESIGN section 2, "Residual": the light over the whole object, from
    the box centre, without g or p_user."""
    if lt.type == DIRECTIONAL:
        d = lt.direction
        return lt.intensity, (-d[0], -d[1], -d[2])
    p, c = lt.position, ob.centre
    v = (p[0] - c[0], p[1] - c[1], p[2] - c[2])
    vv = v[0] * v[0] + v[1] * v[1] + v[2] * v[2]
    dc2 = max(vv, ob.R * ob.R)
    r = lt.radius
    q = dc2 / (r * r)
    w = max(0.0, 1 - q * q)
    s = spot_factor(lt, ob) if lt.type == SPOT else 1.0
    e = lt.intensity * w * w / (dc2 + R0 * R0) * s
    # v . v == 0 also when v is so short that its square underflows: no direction then
    # either, and no division by zero.
    if vv == 0.0:
        return e, (0.0, 0.0, 0.0)
    n = math.sqrt(vv)
    return e, (v[0] / n, v[1] / n, v[2] / n)


def _residual(ob: _Object, slots: list[list[Any]], prio: dict[int, float],
              by_id: dict[int, _Light], cfg: Config) -> tuple[float, float, float, float]:
    """residual[o] (DESIGN section 2, "Residual"): every light competing for o's slots
    (``prio``'s), weighted by 1 minus its slot's weight, in ascending light id; with
    unshadowed = "skip" the lights with shadows = true are left out."""
    weight = {lid: w for lid, w, _ in slots}
    a = bx = by = bz = 0.0
    for lid in sorted(prio):
        lt = by_id[lid]
        if cfg.unshadowed == "skip" and lt.shadows:
            continue
        rho = 1 - weight.get(lid, 0.0)
        e, u = residual_term(lt, ob)
        t = rho * e
        a += t
        bx += t * u[0]
        by += t * u[1]
        bz += t * u[2]
    return a, bx, by, bz


def _write_casters(frame: Any, lights: list[_Light], objects: list[_Object],
                   shadow_ids: list[int], cams: list[CameraFrame], cfg: Config
                   ) -> list[list[tuple[_Object, int]]]:
    """caster_offsets, caster_ids and caster_masks (DESIGN section 2, "Casters"): per
    shadow light, its casters by object id. Returns them per shadow light as (object,
    bits)."""
    by_id = {lt.id: lt for lt in lights}
    offsets, ids, masks = [0], [], []
    per_light = []
    for lid in shadow_ids:
        lt = by_id[lid]
        volumes = culling_volumes(lt, cams, cfg)
        listed = []
        for ob in sorted(objects, key=lambda o: o.id):
            bits = caster_mask(lt, ob, volumes)
            if bits:
                ids.append(ob.id)
                masks.append(bits)
                listed.append((ob, bits))
        offsets.append(len(ids))
        per_light.append(listed)
    frame.caster_offsets = np.array(offsets, np.int64)
    frame.caster_ids = np.array(ids, np.int32)
    frame.caster_masks = np.array(masks, np.uint32)
    return per_light


def schedule(lights: dict[str, Any], objects: dict[str, Any], cameras: Any,
             config: Config | None = None) -> Frame:
    """Stateless one frame: every object starts with its selected lights on."""
    s = Scheduler(config)
    s.set_lights(**lights)
    s.set_objects(**objects)
    return s.frame(cameras, dt=0.0, cut=True)
