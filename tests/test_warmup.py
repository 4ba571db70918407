"""lightsched.warmup: once ``warm_up`` ran, no frame of any scene, path or setting it covers
compiles or loads a kernel (the first frame of a cold machine would otherwise take about a
minute, bench/RESULTS.md "cold start").

The battery runs in a fresh interpreter, so that signatures compiled by other tests of this
process cannot hide one that ``warm_up`` misses."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import lightsched as ls
from lightsched.frame import PER_OBJECT, changed_rows
from lightsched.scenes import city, dungeon22, large_world, move_lights, split_screen, stadium
from lightsched.tuning import Tuning
from lightsched.warmup import GENERIC_K, WarmUp, kernels, warm_up

CONFIGS = [
    ls.Config(),
    *(ls.Config(max_lights=k) for k in (1, 2, 3, 4, 16)),
    ls.Config(residual=False),
    ls.Config(residual=False, max_lights=GENERIC_K + 1, precision="fast"),
    ls.Config(precision="fast"),
    ls.Config(precision="fast", max_lights=4),
    ls.Config(precision="fast", max_lights=GENERIC_K + 1),
    ls.Config(model="thesis"),
    ls.Config(model="thesis", precision="fast", max_lights=4),
    ls.Config(unshadowed="skip", max_shadowed_per_object=1),
    ls.Config(directional_in_slots=True, shadow_budget=0),
    ls.Config(shadow_budget=1, cascades=1, fade_in=0.0, fade_out=0.0),
]

# The scenes are small: the candidate lists' path is opened to them.
TUNING = Tuning(candidate_min_objects=0)


def _scenes() -> list[ls.scenes.CityScene]:
    return [city(1500, 150, seed=3, shadow_fraction=0.2, sun_shadows=True),
            dungeon22(seed=1, sun=True), stadium(n_objects=800, n_lights=120),
            large_world(800, 80, seed=2, shadow_fraction=0.1),
            split_screen(1200, 120, seed=4, shadow_fraction=0.1, sun_shadows=True)]


def _sequence(config: ls.Config, sc: ls.scenes.CityScene) -> None:
    """A scene through moves of every kind, property changes, removals, additions, cuts, a
    camera that sees little and one that sees nothing."""
    s = ls.Scheduler(config, TUNING)
    lights, objects = sc.lights, sc.objects
    s.set_lights(**lights)
    s.set_objects(**objects)
    ids, oids = lights["id"], objects["id"]
    cams = sc.cameras
    away = [ls.Camera(position=np.asarray(c.position) + 5000.0, forward=c.forward, up=c.up,
                      fov_y=c.fov_y, aspect=c.aspect, near=c.near, far=c.far, id=c.id)
            for c in cams]
    prev = s.frame(cams)
    for i in range(1, 14):
        if i % 4 == 1:
            s.update_lights(id=ids, position=move_lights(lights, i))
        elif i % 4 == 2:
            s.update_lights(id=ids[::7], position=move_lights(lights, i)[::7],
                            radius=lights["radius"][::7] * 1.1)
        elif i % 4 == 3:
            s.update_objects(id=oids[::11], bounds_min=objects["bounds_min"][::11] + 0.3 * i,
                             bounds_max=objects["bounds_max"][::11] + 0.3 * i)
        f = s.frame(cams if i != 9 else away, dt=1 / 60, cut=i == 6)
        changed_rows(prev, f, tuple(PER_OBJECT))
        prev = f
    s.update_lights(id=ids[::5], shadows=~lights["shadows"][::5],
                    intensity=lights["intensity"][::5] * 2.0)
    s.remove_lights(id=ids[:3])
    s.remove_objects(id=oids[:10])
    s.frame(cams, dt=1 / 60)
    s.set_lights(**{k: v[: len(ids) // 2] for k, v in lights.items()})
    s.frame(cams, dt=1 / 60)
    s.frame(cams, dt=0.0)
    ls.schedule(lights, objects, cams, config, TUNING)


def _other_dtypes(sc: ls.scenes.CityScene) -> ls.scenes.CityScene:
    """The scene's arrays as an engine might send them: float32 vectors, int64 ids."""
    def cast(d: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        return {k: v.astype(np.float32) if v.dtype == np.float64 else
                v.astype(np.int64) if v.dtype == np.int32 else v for k, v in d.items()}
    sc.lights, sc.objects = cast(sc.lights), cast(sc.objects)
    return sc


def _battery() -> dict[str, int]:
    """Runs warm_up, then every config on every scene; the kernels that gained signatures.
    The scenes are small: the candidate lists' path is opened to them (TUNING)."""
    warm_up()
    before = {name: len(d.signatures) for name, d in kernels().items()}
    for config in CONFIGS:
        for sc in _scenes():
            _sequence(config, sc)
        _sequence(config, _other_dtypes(city(900, 90, seed=5, shadow_fraction=0.2)))
        empty = ls.Scheduler(config, TUNING)
        empty.frame(city(10, 3).cameras)
    return {name: len(d.signatures) - before.get(name, 0) for name, d in kernels().items()
            if len(d.signatures) != before.get(name, 0)}


@pytest.mark.slow  # warms every K variant and precision up
def test_no_frame_compiles_after_warm_up():
    proc = subprocess.run([sys.executable, str(Path(__file__).resolve())],
                          capture_output=True, text=True, timeout=1800)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    grown = json.loads(proc.stdout.strip().splitlines()[-1])
    assert grown == {}, f"kernels compiled after warm_up: {grown}"


@pytest.mark.slow  # warms every K variant and precision up
def test_warm_up_twice_loads_nothing_the_second_time():
    warm_up(max_lights=(8,), precisions=("exact",))
    again = warm_up(max_lights=(8,), precisions=("exact",))
    assert isinstance(again, WarmUp) and again.seconds > 0
    assert (again.loaded, again.compiled) == (0, 0)
    assert "lightsched.objects.object_pass" in kernels()


if __name__ == "__main__":
    print(json.dumps(_battery()))
