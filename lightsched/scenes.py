"""Seeded test and benchmark scenes: a procedural city of boxes lit by many moving lights.

Pure numpy, no I/O. A scene is plain field arrays, usable as ``s.set_lights(**scene.lights)``
and ``s.set_objects(**scene.objects)``, plus a list of ``lightsched.Camera``.

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

from .scene import DIRECTIONAL, POINT, SPOT, Camera

__all__ = ["CityScene", "city", "city_camera", "city_sequence", "city_side", "demo_scene",
           "move_lights"]

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
         directional: int = 1, shadow_fraction: float = 0.0, sun_shadows: bool = False
         ) -> CityScene:
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
              "sun_shadows": bool(sun_shadows)}
    return CityScene(lights=lights, objects=objects, cameras=[city_camera(side)], side=side,
                     seed=seed, params=params)


def demo_scene(seed: int = 0, n_objects: int = 3000, n_lights: int = 300) -> CityScene:
    """The demo city: about 3000 objects and 300 lights, a few of them casting shadows."""
    return city(n_objects, n_lights, seed=seed, shadow_fraction=0.02, sun_shadows=True)


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
