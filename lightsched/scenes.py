"""Seeded test and benchmark scenes: a procedural city of boxes lit by many moving lights,
and the benchmark harness's named scenes built on the same ``CityScene``: ``dungeon22`` (the
thesis's shipped level: 22 lights, K = 4), ``stadium`` (1000 floodlights over one field),
``large_world`` (the city 1e7 m from the origin) and ``split_screen`` (the city, 4 cameras).

Pure numpy, no I/O. A scene is plain field arrays, usable as ``s.set_lights(**scene.lights)``
and ``s.set_objects(**scene.objects)``, plus a list of ``lightsched.Camera``; ``scene.config``
is the Config a generator recommends (None: the defaults).

World convention: y is up, (x, z) is the ground plane, metres.

Everything is reproducible from ``seed``; objects and lights draw from independent streams,
so ``city(N, L1, seed)`` and ``city(N, L2, seed)`` share their objects. Ids are a random
sample of a range larger than the count and come in no particular order, so every store
has to sort them.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .scene import DIRECTIONAL, POINT, SPOT, Camera, Config

__all__ = ["CityScene", "city", "city_camera", "city_sequence", "city_side", "demo_scene",
           "dense", "dungeon22", "large_world", "move_lights", "split_screen", "stadium"]

DT = 1.0 / 60.0
GOLDEN_ANGLE = math.pi * (3.0 - math.sqrt(5.0))


@dataclass
class CityScene:
    """A generated scene: field arrays for lights and objects, and the cameras."""

    lights: dict[str, np.ndarray]
    objects: dict[str, np.ndarray]
    cameras: list[Camera]
    side: float = 0.0  # edge of the square the city stands on, metres
    seed: int = 0
    params: dict[str, Any] = field(default_factory=dict)
    config: Config | None = None  # the Config the generator recommends; None: Config()

    def __getitem__(self, key: str) -> Any:  # scene["lights"] works too
        return getattr(self, key)

    @property
    def n_lights(self) -> int:
        return int(self.lights["id"].size)

    @property
    def n_objects(self) -> int:
        return int(self.objects["id"].size)


def city_side(n_objects: int) -> float:
    """Edge of the city square: 1000 m for 100k objects, constant density."""
    return 1000.0 * math.sqrt(max(n_objects, 1) / 100_000.0)


def _ids(rng: np.random.Generator, n: int) -> np.ndarray:
    """n distinct non-negative int32 ids drawn from range(2n + 16), in random order."""
    return rng.permutation(2 * n + 16)[:n].astype(np.int32)


def _z_order(centre: np.ndarray, cell: float) -> np.ndarray:
    """Z-order (Morton) key of each centre's (x, z) column of edge ``cell``: interleaved
    bits, so rows sorted by it walk the ground plane in nested squares."""
    q = np.floor((centre[:, [0, 2]] - centre[:, [0, 2]].min(0, initial=np.inf)) / cell)
    q = q.astype(np.uint64)
    key = np.zeros(centre.shape[0], np.uint64)
    for b in range(32):
        for a in range(2):
            key |= ((q[:, a] >> np.uint64(b)) & np.uint64(1)) << np.uint64(2 * b + a)
    return key


def city_camera(side: float, height: float = 200.0, fov_y_deg: float = 60.0,
                aspect: float = 16.0 / 9.0, near: float = 0.5, far: float = 3000.0,
                camera_id: int = 0) -> Camera:
    """A camera over the (-x, -z) corner of the square, ``height`` up, looking at the centre."""
    h = 0.5 * side
    pos = np.array([-h, height, -h])
    return Camera(position=pos, forward=-pos, up=np.array([0.0, 1.0, 0.0]),
                  fov_y=math.radians(fov_y_deg), aspect=aspect, near=near, far=far,
                  id=camera_id)


def city(n_objects: int, n_lights: int, seed: int = 0, spot_fraction: float = 0.1,
         directional: int = 1, shadow_fraction: float = 0.0, sun_shadows: bool = False,
         object_ids: str = "random") -> CityScene:
    """A city of ``n_objects`` boxes and ``n_lights`` lights on a square centred at the origin.

    Objects: half-extents uniform in 0.5..5 m per axis, centres uniform over the square
    (side ``city_side(n_objects)``), centre heights y uniform in 0..100 m.

    Lights: ``directional`` of them (at most ``n_lights``) are suns pointing down and
    sideways; of the rest, ``round(spot_fraction * rest)`` are spots (axis within 1 rad of
    straight down, outer_angle 0.3..1.2, default inner_angle) and the others point lights.
    Point and spot lights: positions uniform over the square, heights 0..100 m, radius
    5..30 m; every light has intensity 1..100. ``shadow_fraction`` of the point and spot
    lights get ``shadows=True``, and the suns if ``sun_shadows`` (both off by default: the
    shadow stage then does no work).

    ``object_ids``: "random" (default), the ids in no spatial order; "spatial", the same ids
    and boxes with the ids ascending along a Z-order curve of the centres over 16 m
    columns, as a game that spawns its world section by section numbers its objects. The
    stores keep rows by id, so this is the order the core's object rows take.

    Every row carries finite values in every field (DESIGN section 3): directional rows get
    a position and radius they ignore; point rows a straight-down direction.
    """
    if n_objects < 0 or n_lights < 0:
        raise ValueError("n_objects and n_lights must be >= 0")
    if not 0.0 <= spot_fraction <= 1.0 or not 0.0 <= shadow_fraction <= 1.0:
        raise ValueError("spot_fraction and shadow_fraction must be in [0, 1]")
    side = city_side(n_objects)
    h = 0.5 * side
    obj_ss, light_ss = np.random.SeedSequence(seed).spawn(2)

    # --- objects
    rng = np.random.default_rng(obj_ss)
    oid = _ids(rng, n_objects)
    centre = np.empty((n_objects, 3))
    centre[:, 0] = rng.uniform(-h, h, n_objects)
    centre[:, 1] = rng.uniform(0.0, 100.0, n_objects)
    centre[:, 2] = rng.uniform(-h, h, n_objects)
    half = rng.uniform(0.5, 5.0, (n_objects, 3))
    if object_ids == "spatial":
        oid = np.sort(oid)[np.argsort(np.argsort(_z_order(centre, 16.0), kind="stable"))]
    elif object_ids != "random":
        raise ValueError('object_ids must be "random" or "spatial"')
    objects = {"id": oid, "bounds_min": centre - half, "bounds_max": centre + half}

    # --- lights
    rng = np.random.default_rng(light_ss)
    lid = _ids(rng, n_lights)
    n_dir = min(max(int(directional), 0), n_lights)
    n_spot = int(round(spot_fraction * (n_lights - n_dir)))
    ltype = np.full(n_lights, POINT, np.uint8)
    ltype[:n_dir] = DIRECTIONAL
    ltype[n_dir:n_dir + n_spot] = SPOT
    ltype = ltype[rng.permutation(n_lights)]

    position = np.empty((n_lights, 3))
    position[:, 0] = rng.uniform(-h, h, n_lights)
    position[:, 1] = rng.uniform(0.0, 100.0, n_lights)
    position[:, 2] = rng.uniform(-h, h, n_lights)
    radius = rng.uniform(5.0, 30.0, n_lights)
    intensity = rng.uniform(1.0, 100.0, n_lights)

    # Spot axes: within 1 rad of straight down. Suns: 30..70 degrees below the horizon.
    tilt = rng.uniform(0.0, 1.0, n_lights)
    azim = rng.uniform(0.0, 2.0 * math.pi, n_lights)
    elev = rng.uniform(math.radians(30.0), math.radians(70.0), n_lights)
    outer = rng.uniform(0.3, 1.2, n_lights)
    shadow_draw = rng.uniform(0.0, 1.0, n_lights)

    direction = np.zeros((n_lights, 3))
    direction[:, 1] = -1.0
    spot = ltype == SPOT
    direction[spot, 0] = np.sin(tilt[spot]) * np.cos(azim[spot])
    direction[spot, 1] = -np.cos(tilt[spot])
    direction[spot, 2] = np.sin(tilt[spot]) * np.sin(azim[spot])
    sun = ltype == DIRECTIONAL
    direction[sun, 0] = np.cos(elev[sun]) * np.cos(azim[sun])
    direction[sun, 1] = -np.sin(elev[sun])
    direction[sun, 2] = np.cos(elev[sun]) * np.sin(azim[sun])
    outer_angle = np.where(spot, outer, math.pi / 4)
    shadows = np.where(sun, bool(sun_shadows), shadow_draw < shadow_fraction)

    lights = {"id": lid, "type": ltype, "position": position, "radius": radius,
              "direction": direction, "outer_angle": outer_angle, "intensity": intensity,
              "shadows": shadows.astype(np.bool_)}

    params = {"n_objects": n_objects, "n_lights": n_lights, "spot_fraction": spot_fraction,
              "directional": n_dir, "shadow_fraction": shadow_fraction,
              "sun_shadows": bool(sun_shadows), "object_ids": object_ids}
    return CityScene(lights=lights, objects=objects, cameras=[city_camera(side)], side=side,
                     seed=seed, params=params)


def demo_scene(seed: int = 0, n_objects: int = 3000, n_lights: int = 300) -> CityScene:
    """The demo city: about 3000 objects and 300 lights, a few of them casting shadows."""
    return city(n_objects, n_lights, seed=seed, shadow_fraction=0.02, sun_shadows=True)


def dense(n_objects: int = 10_000, n_lights: int = 1_000, seed: int = 0) -> CityScene:
    """Random boxes among big point lights: every object is reached by about 33 competing
    lights (41.9 away from the faces), so the object pass chooses K among many (issue 49).

    A cube of side 1 km at 1000 lights, scaled with the cube root of ``n_lights`` / 1000 so
    that the density of lights holds. Objects: half-extents 0.5..5 m, centres uniform in
    the cube. Lights: point lights uniform in the cube, radius 100..300 m, intensity
    1..100. One camera at twice the half-side from the centre, its far plane past the
    cube's far corner, sees every object."""
    if n_objects < 0 or n_lights < 0:
        raise ValueError("n_objects and n_lights must be >= 0")
    side = 1000.0 * (max(n_lights, 1) / 1000.0) ** (1.0 / 3.0)
    h = 0.5 * side
    obj_ss, light_ss = np.random.SeedSequence(seed).spawn(2)
    rng = np.random.default_rng(obj_ss)
    centre = rng.uniform(-h, h, (n_objects, 3))
    half = rng.uniform(0.5, 5.0, (n_objects, 3))
    objects = {"id": _ids(rng, n_objects), "bounds_min": centre - half,
               "bounds_max": centre + half}
    rng = np.random.default_rng(light_ss)
    ltype = np.full(n_lights, POINT, np.uint8)
    direction = np.zeros((n_lights, 3))
    direction[:, 1] = -1.0
    lights = _light_arrays(rng, ltype, rng.uniform(-h, h, (n_lights, 3)),
                           rng.uniform(100.0, 300.0, n_lights), direction,
                           np.full(n_lights, math.pi / 4), np.full(n_lights, 0.8),
                           rng.uniform(1.0, 100.0, n_lights), np.zeros(n_lights, np.bool_))
    camera = _look_camera((0.0, 0.5 * h, 2.0 * side), (0.0, 0.0, 0.0), fov_y=math.radians(70.0),
                          far=4.0 * side)
    params = {"n_objects": n_objects, "n_lights": n_lights}
    return CityScene(lights=lights, objects=objects, cameras=[camera], side=side, seed=seed,
                     params=params)


def move_lights(lights: dict[str, np.ndarray], frame_index: int, speed: float = 3.0,
                circle: float = 3.0, dt: float = DT) -> np.ndarray:
    """Positions of ``lights`` at ``frame_index`` of an animation, rows as in ``lights``.

    Each point or spot light runs round a horizontal circle of radius ``circle`` metres at
    ``speed`` metres per second, starting (frame 0) at its position in ``lights``; phase and
    sense of rotation come from its id, so the motion does not depend on row order.
    Directional rows keep their (ignored) position. Pass the scene's original light arrays
    every frame: the result is a function of the frame index, not an integration.
    """
    base = np.asarray(lights["position"], dtype=np.float64)
    ids = np.asarray(lights["id"]).astype(np.int64)
    ltype = np.asarray(lights.get("type", np.zeros(ids.size, np.uint8)))
    if circle <= 0.0:
        return base.copy()
    t = frame_index * dt
    phase = np.mod(ids * GOLDEN_ANGLE, 2.0 * math.pi)
    sense = np.where(ids % 2 == 0, 1.0, -1.0)
    angle = phase + sense * (speed / circle) * t
    out = base.copy()
    moving = ltype != DIRECTIONAL
    out[moving, 0] += circle * (np.cos(angle[moving]) - np.cos(phase[moving]))
    out[moving, 2] += circle * (np.sin(angle[moving]) - np.sin(phase[moving]))
    return out


def city_sequence(scene: CityScene, frames: int, speed: float = 3.0, circle: float = 3.0,
                  dt: float = DT) -> Iterator[tuple[int, dict[str, np.ndarray]]]:
    """Yields (frame index, update_lights keyword arrays) for ``frames`` frames.

    Frame 0 yields an empty dict (the scene as set); later frames move every light, so a
    caller does ``s.update_lights(**upd)`` when ``upd`` is not empty, then ``s.frame(...)``.
    """
    for i in range(frames):
        if i == 0:
            yield i, {}
        else:
            yield i, {"id": scene.lights["id"],
                      "position": move_lights(scene.lights, i, speed, circle, dt)}


# --------------------------------------------------------------------------- harness scenes


def _unit(v: np.ndarray) -> np.ndarray:
    """Rows of ``v`` scaled to unit length (rows must be non-zero)."""
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _look_camera(position: Any, target: Any, camera_id: int = 0, fov_y: float = math.radians(60.0),
                 aspect: float = 16.0 / 9.0, near: float = 0.1, far: float = 500.0,
                 height_px: float = 1080.0) -> Camera:
    """A y-up camera at ``position`` looking at ``target`` (never straight up or down)."""
    pos = np.asarray(position, dtype=np.float64)
    fwd = np.asarray(target, dtype=np.float64) - pos
    return Camera(position=pos, forward=fwd, up=np.array([0.0, 1.0, 0.0]), fov_y=fov_y,
                  aspect=aspect, near=near, far=far, height_px=height_px, id=camera_id)


class _Boxes:
    """Collects axis-aligned boxes (min, max) with a static flag and a group label."""

    def __init__(self) -> None:
        self.lo: list[tuple[float, float, float]] = []
        self.hi: list[tuple[float, float, float]] = []
        self.static: list[bool] = []
        self.group: list[str] = []

    def add(self, lo: Any, hi: Any, group: str, static: bool = True) -> None:
        lo3 = tuple(float(v) for v in lo)
        hi3 = tuple(float(v) for v in hi)
        self.lo.append(tuple(min(a, b) for a, b in zip(lo3, hi3, strict=True)))
        self.hi.append(tuple(max(a, b) for a, b in zip(lo3, hi3, strict=True)))
        self.static.append(bool(static))
        self.group.append(group)

    def objects(self, rng: np.random.Generator) -> tuple[dict[str, np.ndarray], np.ndarray]:
        """(object field arrays with random distinct ids, the group label of each row)."""
        n = len(self.lo)
        lo = np.array(self.lo, dtype=np.float64).reshape(n, 3)
        hi = np.array(self.hi, dtype=np.float64).reshape(n, 3)
        objects = {"id": _ids(rng, n), "bounds_min": lo, "bounds_max": hi,
                   "casts_shadows": np.ones(n, np.bool_),
                   "static": np.array(self.static, dtype=np.bool_).reshape(n)}
        return objects, np.array(self.group, dtype=object).reshape(n)


def _light_arrays(rng: np.random.Generator, ltype: np.ndarray, position: np.ndarray,
                  radius: np.ndarray, direction: np.ndarray, outer: np.ndarray,
                  inner_frac: np.ndarray, intensity: np.ndarray, shadows: np.ndarray
                  ) -> dict[str, np.ndarray]:
    """Light field arrays with random distinct ids; every row finite in every field (point
    rows keep the default angles and whatever unit direction they were given)."""
    n = ltype.size
    spot = ltype == SPOT
    outer_angle = np.where(spot, outer, math.pi / 4)
    inner_angle = np.where(spot, inner_frac * outer, 0.8 * math.pi / 4)
    return {"id": _ids(rng, n), "type": ltype.astype(np.uint8), "position": position.astype(np.float64),
            "radius": radius.astype(np.float64), "direction": _unit(direction),
            "outer_angle": outer_angle.astype(np.float64), "inner_angle": inner_angle.astype(np.float64),
            "intensity": intensity.astype(np.float64), "shadows": shadows.astype(np.bool_)}


# The course of dungeon22: six rooms on a 3 x 2 grid, visited as a loop (a race track is a
# circuit), consecutive rooms joined by a corridor. (column, row) of each room in course order.
_DUNGEON_LOOP = ((0, 0), (1, 0), (2, 0), (2, 1), (1, 1), (0, 1))
_ROOM = 16.0       # room edge (x and z), metres
_ROOM_H = 5.0      # room height
_CORRIDOR = 8.0    # corridor length between two rooms
_CORR_W = 4.0      # corridor (and door) width
_CORR_H = 4.0      # corridor height
_WALL = 0.5        # wall, floor and ceiling thickness
_DUNGEON_LIGHTS = 22
_DUNGEON_SPOTS = 4
_DUNGEON_LIT_CORRIDORS = 4  # 6 rooms x 3 lights + 4 corridor lights = 22


def _dungeon_corridors(centres: list[tuple[float, float]], h: float
                       ) -> tuple[list[set[str]], list[tuple[tuple[float, float, float],
                                                             tuple[float, float, float]]],
                                  list[int]]:
    """dungeon22's course: per room the sides its doors are on, and per corridor its box
    and the axis it runs along (0: x, 2: z), room i to room i + 1 round the loop."""
    n_rooms = len(_DUNGEON_LOOP)
    # Doors: for room i, the sides ("+x", "-x", "+z", "-z") a corridor leaves from.
    doors: list[set[str]] = [set() for _ in range(n_rooms)]
    corridors: list[tuple[tuple[float, float, float], tuple[float, float, float]]] = []
    corridor_axis: list[int] = []
    for i in range(n_rooms):
        j = (i + 1) % n_rooms
        (ci, ri), (cj, rj) = _DUNGEON_LOOP[i], _DUNGEON_LOOP[j]
        (xi, zi), (xj, zj) = centres[i], centres[j]
        if ri == rj:  # along x
            sgn = 1.0 if cj > ci else -1.0
            doors[i].add("+x" if sgn > 0 else "-x")
            doors[j].add("-x" if sgn > 0 else "+x")
            x0, x1 = sorted((xi + sgn * h, xj - sgn * h))
            corridors.append(((x0, 0.0, zi - 0.5 * _CORR_W), (x1, _CORR_H, zi + 0.5 * _CORR_W)))
            corridor_axis.append(0)
        else:  # along z
            sgn = 1.0 if rj > ri else -1.0
            doors[i].add("+z" if sgn > 0 else "-z")
            doors[j].add("-z" if sgn > 0 else "+z")
            z0, z1 = sorted((zi + sgn * h, zj - sgn * h))
            corridors.append(((xi - 0.5 * _CORR_W, 0.0, z0), (xi + 0.5 * _CORR_W, _CORR_H, z1)))
            corridor_axis.append(2)

    return doors, corridors, corridor_axis


def _dungeon_boxes(rng: np.random.Generator, centres: list[tuple[float, float]], h: float,
                   doors: list[set[str]], corridors: list, corridor_axis: list[int],
                   props_per_room: int, racers: int) -> tuple[_Boxes, list]:
    """dungeon22's objects: per room a floor, a ceiling, walls split round its doors and
    props; per corridor a floor, a ceiling and two walls; the racers. Also the rooms'
    boxes."""
    boxes = _Boxes()
    rooms = []
    t, H = _WALL, _ROOM_H
    for i, (xc, zc) in enumerate(centres):
        x0, x1, z0, z1 = xc - h, xc + h, zc - h, zc + h
        rooms.append(((x0, 0.0, z0), (x1, H, z1)))
        boxes.add((x0, -t, z0), (x1, 0.0, z1), "floor")
        boxes.add((x0, H, z0), (x1, H + t, z1), "ceiling")
        for side in ("+x", "-x", "+z", "-z"):
            # A wall along the side, inside the room's square, with a door gap if needed.
            along = 2 if side[1] == "x" else 0  # the axis the wall runs along
            a0, a1 = (z0, z1) if along == 2 else (x0, x1)
            mid = 0.5 * (a0 + a1)
            spans = [(a0, mid - 0.5 * _CORR_W), (mid + 0.5 * _CORR_W, a1)] if side in doors[i] \
                else [(a0, a1)]
            for s0, s1 in spans:
                if side[1] == "x":
                    xa, xb = (x1 - t, x1) if side[0] == "+" else (x0, x0 + t)
                    boxes.add((xa, 0.0, s0), (xb, H, s1), "wall")
                else:
                    za, zb = (z1 - t, z1) if side[0] == "+" else (z0, z0 + t)
                    boxes.add((s0, 0.0, za), (s1, H, zb), "wall")
        # Props: crates (0.4..1.5 m) on the floor, one in five a pillar to the ceiling.
        for _ in range(props_per_room):
            px = rng.uniform(x0 + 1.0, x1 - 1.0)
            pz = rng.uniform(z0 + 1.0, z1 - 1.0)
            if rng.uniform() < 0.2:
                e = rng.uniform(0.3, 0.5)
                boxes.add((px - e, 0.0, pz - e), (px + e, H, pz + e), "prop")
            else:
                e = rng.uniform(0.2, 0.75, 3)
                boxes.add((px - e[0], 0.0, pz - e[2]), (px + e[0], 2.0 * e[1], pz + e[2]), "prop")
    for (lo, hi), axis in zip(corridors, corridor_axis, strict=True):
        boxes.add((lo[0], -t, lo[2]), (hi[0], 0.0, hi[2]), "floor")
        boxes.add((lo[0], _CORR_H, lo[2]), (hi[0], _CORR_H + t, hi[2]), "ceiling")
        if axis == 0:
            boxes.add((lo[0], 0.0, lo[2] - t), (hi[0], _CORR_H, lo[2]), "wall")
            boxes.add((lo[0], 0.0, hi[2]), (hi[0], _CORR_H, hi[2] + t), "wall")
        else:
            boxes.add((lo[0] - t, 0.0, lo[2]), (lo[0], _CORR_H, hi[2]), "wall")
            boxes.add((hi[0], 0.0, lo[2]), (hi[0] + t, _CORR_H, hi[2]), "wall")
    # Racers: dynamic 1 x 1.2 x 2 m boxes spread along the loop (room centres and corridors).
    stops = [(xc, zc) for xc, zc in centres] + [(0.5 * (lo[0] + hi[0]), 0.5 * (lo[2] + hi[2]))
                                                for lo, hi in corridors]
    for _ in range(racers):
        sx, sz = stops[int(rng.integers(len(stops)))]
        px, pz = sx + rng.uniform(-1.5, 1.5), sz + rng.uniform(-1.5, 1.5)
        boxes.add((px - 0.5, 0.1, pz - 1.0), (px + 0.5, 1.3, pz + 1.0), "racer", static=False)
    return boxes, rooms


def _dungeon_lights(rng: np.random.Generator, centres: list[tuple[float, float]], h: float,
                    corridors: list, sun: bool) -> list[tuple]:
    """dungeon22's lights as rows (type, position, radius, direction, intensity, spot
    fraction, shadows): per room two ceiling points and a wall spot or a low lamp, a
    ceiling point in some corridors, and the sun if asked for."""
    n_rooms = len(centres)
    H = _ROOM_H
    spot_rooms = set(rng.choice(n_rooms, _DUNGEON_SPOTS, replace=False).tolist())
    lit = rng.choice(n_rooms, _DUNGEON_LIT_CORRIDORS, replace=False)
    rows: list[tuple[int, tuple[float, float, float], float, tuple[float, float, float], float,
                     float, bool]] = []
    down = (0.0, -1.0, 0.0)
    for i, (xc, zc) in enumerate(centres):
        for sgn in (-1.0, 1.0):  # two ceiling lights along the room's x axis
            p = (xc + sgn * 0.25 * _ROOM + rng.uniform(-1.0, 1.0), H - 0.3,
                 zc + rng.uniform(-2.0, 2.0))
            rows.append((POINT, p, rng.uniform(10.0, 14.0), down, rng.uniform(20.0, 60.0), 0.5, False))
        if i in spot_rooms:  # a wall-mounted spot aimed at the floor near the room centre
            side = rng.uniform(-0.5 * math.pi, 1.5 * math.pi)
            p = (xc + (h - 0.8) * math.cos(side), H - 0.5, zc + (h - 0.8) * math.sin(side))
            aim = (xc + rng.uniform(-3.0, 3.0), 0.0, zc + rng.uniform(-3.0, 3.0))
            d = (aim[0] - p[0], aim[1] - p[1], aim[2] - p[2])
            rows.append((SPOT, p, rng.uniform(15.0, 18.0), d, rng.uniform(60.0, 120.0),
                         rng.uniform(0.5, 0.8), True))
        else:  # a low lamp (torch) near a corner
            p = (xc + rng.choice([-1.0, 1.0]) * (h - 1.5), 2.0, zc + rng.choice([-1.0, 1.0]) * (h - 1.5))
            rows.append((POINT, p, rng.uniform(10.0, 13.0), down, rng.uniform(5.0, 20.0), 0.5, False))
    for c in sorted(lit.tolist()):
        lo, hi = corridors[c]
        p = (0.5 * (lo[0] + hi[0]), _CORR_H - 0.3, 0.5 * (lo[2] + hi[2]))
        rows.append((POINT, p, rng.uniform(9.0, 12.0), down, rng.uniform(10.0, 40.0), 0.5, False))
    if sun:
        rows.append((DIRECTIONAL, (0.0, 50.0, 0.0), 1.0, (0.4, -0.8, 0.3), 1.0, 0.5, False))
    return rows


def dungeon22(seed: int = 0, props_per_room: int = 40, racers: int = 8, sun: bool = False
              ) -> CityScene:
    """The thesis's shipped level as a closed course of rooms and corridors: 22 dynamic
    lights, recommended K = 4 (``scene.config = Config(max_lights=4)``).

    What Eriksson (2006) says, and what was taken from it: the light manager "is used for
    managing the 22 dynamic lights on the last level of the game" (Coldwood Interactive's
    game "SXR", figure 4.1, Gamebryo engine; the company's earlier titles were ski-racing
    games), with "a two lights per pass shader with four lights in total per object" --
    hence exactly 22 lights and K = 4. Point lights are the main case (the manager bounds
    every light by a sphere "since the point lights have a spherical falloff"); spot lights
    had their own Phong-Blinn shader -- hence mostly point lights and a few spots. The
    baseline shader had "only one directional light" -- ``sun=True`` adds it as a 23rd light
    (it takes no slot by default). The game used the thesis's shadows (from one directional
    light, not joined to the light manager) but not its fading (too costly there);
    ``Config(max_lights=4, model="thesis", fade_in=0, fade_out=0)`` mimics the shipped
    manager, the recommended config keeps LightSched's default model and fading.

    The thesis does NOT describe the level's layout: no map, no room, track or light
    placement; only that 50k-140k triangles were drawn "depending on what was visible on the
    level". The rooms-and-corridors shape is this generator's own. It borrows the thesis's
    batching example (chapter 4: "a house with ten rooms where each room [...] is lit by
    four light dynamic light sources" [sic]) for rooms lit by a handful of lights each, and
    closes the course into a loop as a race track would be. So: six 16 x 16 x 5 m rooms on a
    3 x 2 grid, joined in a loop by six 8 m long, 4 m wide, 4 m high corridors.

    Lights (22): per room two ceiling point lights and a third light, which in
    ``_DUNGEON_SPOTS`` = 4 rooms (seeded choice) is a shadow-casting spot on a wall aimed at
    the room's floor and otherwise a low point lamp; plus one ceiling point light in 4 of the
    6 corridors (seeded). Radii (9..18 m) reach through doors and walls into corridors and
    neighbouring rooms, so floors, walls, corridor pieces and props near doors often have
    more than K = 4 candidates. Positions, radii and intensities are jittered per seed.

    Objects: per room a floor, a ceiling, walls (split around each door), ``props_per_room``
    crates and pillars; per corridor a floor, a ceiling and two side walls; ``racers``
    dynamic boxes (static=False, the rest static=True) on the course. The camera (id 0)
    stands at eye height in the first room looking along the course towards the first
    corridor. ``params`` holds the room and corridor boxes (``rooms``, ``corridors``: lists of
    (min, max)), the level's bounds and the group of each object row (``groups``).
    """
    if props_per_room < 0 or racers < 0:
        raise ValueError("props_per_room and racers must be >= 0")
    geo_ss, light_ss, id_ss = np.random.SeedSequence(seed).spawn(3)
    rng = np.random.default_rng(geo_ss)
    pitch = _ROOM + _CORRIDOR
    h = 0.5 * _ROOM
    ncol = 1 + max(c for c, _ in _DUNGEON_LOOP)
    nrow = 1 + max(r for _, r in _DUNGEON_LOOP)
    centres = [((c - 0.5 * (ncol - 1)) * pitch, (r - 0.5 * (nrow - 1)) * pitch) for c, r in _DUNGEON_LOOP]
    doors, corridors, corridor_axis = _dungeon_corridors(centres, h)
    boxes, rooms = _dungeon_boxes(rng, centres, h, doors, corridors, corridor_axis,
                                  props_per_room, racers)
    objects, groups = boxes.objects(np.random.default_rng(id_ss))

    rng = np.random.default_rng(light_ss)
    rows = _dungeon_lights(rng, centres, h, corridors, sun)
    n_l = len(rows)
    ltype = np.array([r[0] for r in rows], np.uint8)
    order = rng.permutation(n_l)  # rows in no particular order, like the city's
    lights = _light_arrays(
        rng, ltype[order], np.array([r[1] for r in rows])[order], np.array([r[2] for r in rows])[order],
        np.array([r[3] for r in rows])[order], np.array([r[5] for r in rows])[order],
        np.full(n_l, 0.7), np.array([r[4] for r in rows])[order], np.array([r[6] for r in rows])[order])

    # --- camera: eye height in the first room, looking along the course to the first door.
    x0c, z0c = centres[0]
    x1c, z1c = centres[1]
    cam_rng = np.random.default_rng(np.random.SeedSequence([seed, 22]))
    pos = (x0c - 0.25 * (x1c - x0c) + cam_rng.uniform(-1.0, 1.0), 1.7,
           z0c - 0.25 * (z1c - z0c) + cam_rng.uniform(-1.0, 1.0))
    target = (x1c + cam_rng.uniform(-3.0, 3.0), 1.2, z1c + cam_rng.uniform(-3.0, 3.0))
    cam = _look_camera(pos, target, fov_y=math.radians(60.0), near=0.1, far=150.0)

    all_lo = np.minimum.reduce([np.array(r[0]) for r in rooms + corridors])
    all_hi = np.maximum.reduce([np.array(r[1]) for r in rooms + corridors])
    params = {"props_per_room": props_per_room, "racers": racers, "sun": bool(sun),
              "rooms": rooms, "corridors": corridors, "spots": _DUNGEON_SPOTS,
              "level_bounds": (tuple(all_lo.tolist()), tuple(all_hi.tolist())), "groups": groups}
    side = float(max(all_hi[0] - all_lo[0], all_hi[2] - all_lo[2]))
    return CityScene(lights=lights, objects=objects, cameras=[cam], side=side, seed=seed,
                     params=params, config=Config(max_lights=4))


# The stadium: a 105 x 68 m football pitch centred at the origin, length along x.
_PITCH = (105.0, 68.0)


def stadium(n_objects: int = 3000, seed: int = 0, n_lights: int = 1000, n_masts: int = 8,
            n_shadowed: int = 8, field_fraction: float = 0.25) -> CityScene:
    """A stadium: ``n_lights`` (1000) floodlights on ``n_masts`` masts around one pitch, every
    one aimed at the pitch; a selection-heavy scene (every object on the pitch is reached by
    hundreds of lights, K of them are chosen).

    Pitch: 105 x 68 m at the origin (x along its length), y up. Floodlights: spots on the
    head of their mast (masts evenly spread on an ellipse just outside the stands, heads
    45..50 m up, lamps in rows of 10, 0.8 m apart, stacked upwards), dealt round the masts
    in turn, each aimed at a uniform point of the pitch, outer_angle 0.35..0.6 rad, inner
    0.6 * outer, intensity 500..1500, radius 1.2..1.5 times the distance to the farthest
    pitch corner (so every light's ball covers the whole pitch); ``n_shadowed`` of them
    (seeded) cast shadows.

    Objects (``n_objects`` in all, at least 4): the pitch slab itself (one huge object every
    floodlight touches), two goals, one box per mast, ``field_fraction`` of the remaining
    count as players and props on the pitch (players 0.5 x 1.8 x 0.5 m, balls and cones;
    static=False), and the rest as blocks of seats in the stands (8..40 m beyond the lines,
    tiered: the farther from the pitch, the higher). ``params["field_ids"]`` holds the ids of
    the objects on the pitch (slab, goals, players, props), ascending; ``params["groups"]``
    labels every row. Camera (id 0): a broadcast camera 40 m up, 50 m behind one touchline,
    looking at the centre spot and seeing the whole pitch. Recommended config:
    ``Config(max_lights=8)`` (the default K). For an oracle-sized version keep the lights and
    lower ``n_objects`` (``stadium(400)``: every field object still has hundreds of candidates).
    """
    if n_objects < 4 or n_lights < 0 or n_masts < 1 or n_shadowed < 0:
        raise ValueError("need n_objects >= 4, n_lights >= 0, n_masts >= 1, n_shadowed >= 0")
    if not 0.0 <= field_fraction <= 1.0:
        raise ValueError("field_fraction must be in [0, 1]")
    obj_ss, light_ss = np.random.SeedSequence(seed).spawn(2)
    hx, hz = 0.5 * _PITCH[0], 0.5 * _PITCH[1]
    stand_in, stand_out = 8.0, 40.0   # stands from 8 m to 40 m beyond the touch/goal lines

    # --- lights: masts on an ellipse just outside the stands, starting at a corner direction;
    # on each mast head a grid of lamps 10 wide, 0.8 m apart, across the line to the pitch.
    rng = np.random.default_rng(light_ss)
    ang = math.pi / 4 + 2.0 * math.pi * np.arange(n_masts) / n_masts
    mast_xz = np.stack([(hx + stand_out + 6.0) * np.cos(ang), (hz + stand_out + 6.0) * np.sin(ang)], 1)
    tang = np.stack([-np.sin(ang), np.cos(ang)], 1)  # horizontal, along the mast head
    head_h = rng.uniform(45.0, 50.0, n_masts)
    mast_of = np.arange(n_lights) % n_masts
    slot = np.arange(n_lights) // n_masts  # the lamp's place on its mast head
    cols = 10
    across = (slot % cols - 0.5 * (cols - 1)) * 0.8
    position = np.empty((n_lights, 3))
    position[:, 0] = mast_xz[mast_of, 0] + across * tang[mast_of, 0]
    position[:, 1] = head_h[mast_of] + (slot // cols) * 0.8
    position[:, 2] = mast_xz[mast_of, 1] + across * tang[mast_of, 1]
    aim = np.stack([rng.uniform(-hx, hx, n_lights), np.zeros(n_lights), rng.uniform(-hz, hz, n_lights)], 1)
    corners = np.array([[sx * hx, 0.0, sz * hz] for sx in (-1, 1) for sz in (-1, 1)])
    farthest = np.max(np.linalg.norm(position[:, None, :] - corners[None, :, :], axis=2), axis=1) \
        if n_lights else np.zeros(0)
    radius = farthest * rng.uniform(1.2, 1.5, n_lights)
    outer = rng.uniform(0.35, 0.6, n_lights)
    intensity = rng.uniform(500.0, 1500.0, n_lights)
    shadows = np.zeros(n_lights, np.bool_)
    shadows[rng.choice(n_lights, min(n_shadowed, n_lights), replace=False)] = True
    lights = _light_arrays(rng, np.full(n_lights, SPOT, np.uint8), position, radius, aim - position,
                           outer, np.full(n_lights, 0.6), intensity, shadows)

    # --- objects
    rng = np.random.default_rng(obj_ss)
    boxes = _Boxes()
    boxes.add((-hx, -0.1, -hz), (hx, 0.0, hz), "pitch")
    for sgn in (-1.0, 1.0):
        boxes.add((sgn * hx, 0.0, -3.66), (sgn * (hx + 2.0), 2.44, 3.66), "goal")
    masts = min(n_masts, n_objects - 3)
    n_field = int(round(field_fraction * (n_objects - 3 - masts)))
    for _ in range(n_field):
        px, pz = rng.uniform(-hx + 1.0, hx - 1.0), rng.uniform(-hz + 1.0, hz - 1.0)
        if rng.uniform() < 0.85:  # a player
            boxes.add((px - 0.25, 0.0, pz - 0.25), (px + 0.25, 1.8, pz + 0.25), "player", static=False)
        else:  # a ball or a cone
            e = rng.uniform(0.11, 0.3)
            boxes.add((px - e, 0.0, pz - e), (px + e, 2.0 * e, pz + e), "prop", static=False)
    for m in range(masts):
        mx, mz = mast_xz[m]
        top = float(position[mast_of == m, 1].max()) + 1.0 if np.any(mast_of == m) else 50.0
        boxes.add((mx - 1.0, 0.0, mz - 1.0), (mx + 1.0, top, mz + 1.0), "mast")
    # Seat blocks: a point uniform over the stand ring (a rectangular annulus), tiered by depth.
    for _ in range(n_objects - len(boxes.lo)):
        depth = rng.uniform(stand_in, stand_out)
        t = rng.uniform(-1.0, 1.0)
        side = int(rng.integers(4))
        if side < 2:  # behind a touchline
            px, pz = t * (hx + depth), (1.0 if side == 0 else -1.0) * (hz + depth)
        else:  # behind a goal line
            px, pz = (1.0 if side == 2 else -1.0) * (hx + depth), t * (hz + depth)
        y0 = 0.6 * (depth - stand_in)
        e = rng.uniform(1.0, 3.0)
        boxes.add((px - e, y0, pz - e), (px + e, y0 + 1.0, pz + e), "stand")
    objects, groups = boxes.objects(rng)
    field_rows = np.isin(groups, ["pitch", "goal", "player", "prop"])

    cam = _look_camera((0.0, 40.0, -(hz + 50.0)), (0.0, 0.0, 0.0), fov_y=math.radians(60.0),
                       near=0.5, far=400.0)
    params = {"n_objects": n_objects, "n_lights": n_lights, "n_masts": n_masts,
              "n_shadowed": n_shadowed, "field_fraction": field_fraction, "pitch": _PITCH,
              "field_ids": np.sort(objects["id"][field_rows]), "groups": groups}
    return CityScene(lights=lights, objects=objects, cameras=[cam],
                     side=float(2.0 * (hx + stand_out)), seed=seed, params=params,
                     config=Config(max_lights=8))


def large_world(n_objects: int, n_lights: int, seed: int = 0, offset: float = 1e7,
                **city_kw: Any) -> CityScene:
    """``city(n_objects, n_lights, seed, **city_kw)`` moved ``offset`` metres along x and
    along z (lights, every row's position included, object bounds and the camera): a
    float precision stress (DESIGN section 5: the same results as at the origin, near-ties
    aside). The arrays are the city's plus ``offset`` in float64, so x and z carry the
    rounding of that sum (about 1e-9 m at 1e7); ``params["offset"]`` records it."""
    sc = city(n_objects, n_lights, seed=seed, **city_kw)
    off = np.array([float(offset), 0.0, float(offset)])
    if not np.all(np.isfinite(off)):
        raise ValueError("offset must be finite")
    sc.lights["position"] = sc.lights["position"] + off
    sc.objects["bounds_min"] = sc.objects["bounds_min"] + off
    sc.objects["bounds_max"] = sc.objects["bounds_max"] + off
    sc.cameras = [Camera(position=np.asarray(c.position, np.float64) + off, forward=c.forward, up=c.up,
                         fov_y=c.fov_y, aspect=c.aspect, near=c.near, far=c.far, focus=c.focus,
                         height_px=c.height_px, id=c.id) for c in sc.cameras]
    sc.params = {**sc.params, "offset": float(offset)}
    return sc


def split_screen(n_objects: int, n_lights: int, seed: int = 0, players: int = 4,
                 **city_kw: Any) -> CityScene:
    """``city(n_objects, n_lights, seed, **city_kw)`` seen by ``players`` (4) cameras, ids
    0..players-1: split-screen players racing round a circuit through the city, each at a
    different place and heading. Player k is near angle k * 360/players degrees (+-15) of a
    circle of radius 0.2..0.35 * side round the centre, 2..40 m up, heading along the circle
    (+-30 degrees, senses alternating) and pitched 0..15 degrees down. Each view is a
    quadrant of a 1920 x 1080 screen: aspect 16/9, height_px 540, fov_y 60 degrees, near
    0.3, far 600 m. The cameras draw from their own stream, so the lights and objects are
    exactly ``city``'s."""
    if not 1 <= players <= 8:
        raise ValueError("players must be in 1..8")
    sc = city(n_objects, n_lights, seed=seed, **city_kw)
    rng = np.random.default_rng(np.random.SeedSequence(seed).spawn(3)[2])
    cams = []
    for k in range(players):
        theta = 2.0 * math.pi * k / players + math.radians(rng.uniform(-15.0, 15.0))
        ring = rng.uniform(0.2, 0.35) * sc.side
        pos = np.array([ring * math.cos(theta), rng.uniform(2.0, 40.0), ring * math.sin(theta)])
        sense = 1.0 if k % 2 == 0 else -1.0
        yaw = theta + sense * 0.5 * math.pi + math.radians(rng.uniform(-30.0, 30.0))
        pitch = math.radians(rng.uniform(0.0, 15.0))
        fwd = np.array([math.cos(pitch) * math.cos(yaw), -math.sin(pitch), math.cos(pitch) * math.sin(yaw)])
        cams.append(Camera(position=pos, forward=fwd, up=np.array([0.0, 1.0, 0.0]),
                           fov_y=math.radians(60.0), aspect=16.0 / 9.0, near=0.3, far=600.0,
                           height_px=540.0, id=k))
    sc.cameras = cams
    sc.params = {**sc.params, "players": players}
    return sc
