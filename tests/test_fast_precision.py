"""precision = "fast" (DESIGN sections 1 and 4): object records in float32 relative to the
first camera, lights packed relative to it, float64 arithmetic on them.

On the 2^-16 m grid within 256 m of the first camera every relative coordinate is exact
in float32 (24 significant bits), so there "fast" must give the exact path's frames bit
for bit, wherever the scene sits in the world; elsewhere it may differ near ties and
boundaries, and the benchmark measures by how much (bench/quality.py)."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import assert_frame_sane, examples, frames_identical
from hypothesis import given
from hypothesis import strategies as st
from test_equivalence import big_scene, configs

import lightsched as ls
from lightsched.scenes import city, move_lights

# Each test runs with both kinds of object grid of the fast path: it takes the ``tuning``
# fixture (conftest.py) and gives it to every scheduler it makes.

GRID = 2.0**-16


def _on_grid(a: np.ndarray) -> np.ndarray:
    return np.round(np.asarray(a, float) / GRID) * GRID


def _grid_scene(seed: int, offset: float) -> tuple[dict, dict, list[ls.Camera]]:
    lights, objects, cams = big_scene(seed, 180, 110)
    shift = np.array([offset, -offset, offset])
    lights["position"] = _on_grid(lights["position"]) + shift
    objects["bounds_min"] = _on_grid(objects["bounds_min"]) + shift
    objects["bounds_max"] = np.maximum(_on_grid(objects["bounds_max"]) + shift,
                                       objects["bounds_min"])
    cam = cams[0]
    cams = [ls.Camera(position=_on_grid(cam.position) + shift, forward=cam.forward, up=cam.up,
                      fov_y=cam.fov_y, aspect=cam.aspect, near=cam.near, far=cam.far,
                      focus=cam.focus)]
    return lights, objects, cams


@examples(0.2)
@given(seed=st.integers(0, 2**32 - 1), cfg=configs(), offset=st.sampled_from([0.0, 1e7]))
def test_fast_equals_exact_on_the_grid_near_the_first_camera(seed, cfg, offset, tuning):
    lights, objects, cams = _grid_scene(seed, offset)
    exact = ls.Scheduler(cfg, tuning)
    fast = ls.Scheduler(ls.Config(**{**cfg.to_dict(), "precision": "fast"}), tuning)
    for s in (exact, fast):
        s.set_lights(**lights)
        s.set_objects(**objects)
    rng = np.random.default_rng(seed)
    for i in range(4):
        if i:
            rows = rng.choice(110, 20, replace=False)
            lights["position"][rows] += _on_grid(rng.normal(0, 2.0, (20, 3)))
            for s in (exact, fast):
                s.update_lights(id=lights["id"][rows], position=lights["position"][rows])
        if i == 3:
            # A camera step on the grid: the records keep their origin (incremental frame).
            cam = cams[0]
            cams = [ls.Camera(position=cam.position + _on_grid([1.5, 0.25, -2.0]),
                              forward=cam.forward, up=cam.up, fov_y=cam.fov_y,
                              aspect=cam.aspect, near=cam.near, far=cam.far, focus=cam.focus)]
        fe = exact.frame(cams, dt=1 / 30)
        ff = fast.frame(cams, dt=1 / 30)
        frames_identical(ff, fe, f"frame {i}")
        assert "fast" in ff.stats["plan"]["priority"], ff.stats["plan"]
        if i == 3 and cfg.model == "contribution":  # thesis P follows the camera: full
            assert not ff.stats["plan"]["frame"].startswith("full"), ff.stats["plan"]


def test_fast_records_are_made_again_when_the_camera_goes_far(tuning):
    lights, objects, cams = big_scene(9, 150, 90)
    s = ls.Scheduler(ls.Config(precision="fast", max_lights=4), tuning)
    s.set_lights(**lights)
    s.set_objects(**objects)
    s.frame(cams)
    cam = cams[0]
    for step, full in ((10.0, False), (300.0, True)):
        moved = ls.Camera(position=cam.position + [step, 0.0, 0.0], forward=cam.forward,
                          up=cam.up, fov_y=cam.fov_y, aspect=cam.aspect, near=cam.near,
                          far=cam.far + 400.0)
        f = s.frame([moved])
        assert f.stats["plan"]["frame"].startswith("full: the first camera moved") == full, \
            f.stats["plan"]
        assert_frame_sane(f, 4, f"camera + {step} m")


def test_fast_on_a_city_is_close_to_exact(tuning):
    """Off the grid, float32 records round by up to 2^-24 of the distance to the camera:
    pairs at the edge of a light's range and near-ties can change, little else."""
    scene = city(20_000, 2_000, seed=5, shadow_fraction=0.02, sun_shadows=True)
    exact = ls.Scheduler(ls.Config(), tuning)
    fast = ls.Scheduler(ls.Config(precision="fast"), tuning)
    for s in (exact, fast):
        s.set_lights(**scene.lights)
        s.set_objects(**scene.objects)
    for i in range(4):
        if i:
            pos = move_lights(scene.lights, i)
            for s in (exact, fast):
                s.update_lights(id=scene.lights["id"], position=pos)
        fe = exact.frame(scene.cameras)
        ff = fast.frame(scene.cameras)
        assert_frame_sane(ff, 8, f"fast frame {i}")
        vis = fe.visible
        assert np.array_equal(ff.visible, vis)
        differ = np.any(ff.light_ids != fe.light_ids, axis=1)[vis].mean()
        assert differ < 0.005, f"frame {i}: {100 * differ:.3f}% of visible objects differ"
        np.testing.assert_array_equal(ff.shadow_lights, fe.shadow_lights)


@pytest.mark.parametrize("scale", [1e-6, 1.0, 1e9])
def test_fast_precision_takes_extreme_radii(scale, tuning):
    """No overflow or NaN in the float32 records whatever the radii (DESIGN section 5)."""
    lights, objects, cams = big_scene(3, 150, 90)
    lights["radius"] = lights["radius"] * scale
    s = ls.Scheduler(ls.Config(precision="fast", max_lights=4), tuning)
    e = ls.Scheduler(ls.Config(max_lights=4), tuning)
    for x in (s, e):
        x.set_lights(**lights)
        x.set_objects(**objects)
    for _ in range(2):
        f = s.frame(cams)
        assert_frame_sane(f, 4, f"radii x {scale}")
        fe = e.frame(cams)
    if scale == 1e9:
        # Every light reaches every object its mask allows, in either precision.
        np.testing.assert_array_equal(f.candidates, fe.candidates)
