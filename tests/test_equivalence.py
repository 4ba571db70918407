"""Fast path (lightsched.Scheduler) == oracle (lightsched.reference) on generated scenes,
DESIGN section 4: one frame, multi-frame sequences with every kind of scene edit, both pair
paths of the fast scheduler (brute force and grid), and an animated small city."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest
from helpers import Twin, assert_frames_match, by_row_or_grid, examples, up_for
from hypothesis import given
from hypothesis import strategies as st

import lightsched as ls
import lightsched.reference as ref
from lightsched.scenes import city, move_lights

# The tests that make fast schedulers run with both kinds of object grid of the fast path:
# they take the ``tuning`` fixture (conftest.py) and give it to each.

# --------------------------------------------------------------------------- strategies

finite = {"allow_nan": False, "allow_infinity": False}
# Integer coordinates make coincidences (exact ties, lights on box faces, boxes holding
# lights) likely; floats cover the rest.
coord = st.one_of(st.integers(-12, 12).map(float), st.floats(-25.0, 25.0, **finite))
unit_interval = st.floats(0.0, 1.0, **finite)
MASKS_L = [0xFFFFFFFF, 0xFFFFFFFF, 1, 2, 3, 0, 0x80000000]
MASKS_O = [0xFFFFFFFF, 0xFFFFFFFF, 1, 2, 6, 0, 0x80000001]


@st.composite
def direction(draw) -> tuple[float, float, float]:
    v = draw(st.tuples(st.floats(-1, 1, **finite), st.floats(-1, 1, **finite),
                       st.floats(-1, 1, **finite)))
    if math.sqrt(v[0] ** 2 + v[1] ** 2 + v[2] ** 2) <= 1e-3:
        return (0.0, 0.0, 1.0)
    return v


@st.composite
def light_row(draw) -> dict[str, Any]:
    outer = draw(st.one_of(st.floats(0.05, 1.5, **finite), st.just(math.pi / 4)))
    frac = draw(st.one_of(st.sampled_from([0.0, 0.8, 1.0]), unit_interval))
    return {
        "type": draw(st.sampled_from([0, 0, 0, 1, 1, 2])),
        "position": (draw(coord), draw(coord), draw(coord) + 15.0),
        "radius": draw(st.one_of(st.floats(0.5, 40.0, **finite), st.floats(8.0, 40.0, **finite),
                                 st.sampled_from([1e-3, 1.0, 5.0, 100.0]))),
        "direction": draw(direction()),
        "outer_angle": outer,
        "inner_angle": min(outer, frac * outer),
        "intensity": draw(st.one_of(st.just(0.0), st.sampled_from([1.0, 10.0]),
                                    st.floats(0.0, 100.0, **finite))),
        "priority": draw(st.one_of(st.just(0.0), st.just(100.0), st.floats(-3.0, 3.0, **finite))),
        "shadows": draw(st.booleans()),
        "mask": draw(st.sampled_from(MASKS_L)),
    }


@st.composite
def object_row(draw, light_positions: list[tuple[float, float, float]]) -> dict[str, Any]:
    if light_positions and draw(st.integers(0, 4)) == 0:
        c = draw(st.sampled_from(light_positions))  # a box around a light
    else:
        c = (draw(coord), draw(coord), draw(coord) + 15.0)
    half = [draw(st.one_of(st.just(0.0), st.floats(0.0, 6.0, **finite))) for _ in range(3)]
    return {
        "bounds_min": tuple(c[a] - half[a] for a in range(3)),
        "bounds_max": tuple(c[a] + half[a] for a in range(3)),
        "casts_shadows": draw(st.booleans()),
        "mask": draw(st.sampled_from(MASKS_O)),
        "static": draw(st.booleans()),
    }


@st.composite
def camera_list(draw) -> list[ls.Camera]:
    n = draw(st.integers(1, 3))
    cams = []
    for k in range(n):
        pos = np.array([draw(coord), draw(coord), draw(coord) - 15.0])
        if k == 0 or draw(st.booleans()):
            target = np.array([draw(coord), draw(coord), draw(coord) + 15.0])
            if k == 0:
                target = target / 3.0  # the first camera looks roughly at the scene
            fwd = target - pos
            if np.linalg.norm(fwd) < 1e-3:
                fwd = np.array([0.0, 0.0, 1.0])
        else:
            fwd = np.array(draw(direction()))
        near = draw(st.floats(0.05, 2.0, **finite))
        focus = draw(st.one_of(st.just((0.0, 0.0)),
                               st.tuples(st.floats(-1, 1, **finite), st.floats(-1, 1, **finite))))
        cams.append(ls.Camera(position=pos, forward=fwd, up=up_for(fwd),
                              fov_y=draw(st.floats(0.3, 2.8, **finite) if k else
                                         st.floats(1.2, 2.8, **finite)),
                              aspect=draw(st.floats(0.5, 2.5, **finite)), near=near,
                              far=near + draw(st.floats(5.0, 200.0, **finite)),
                              focus=focus, id=k))
    return cams


@st.composite
def configs(draw) -> ls.Config:
    k = draw(st.one_of(st.sampled_from([1, 2, 2, 3]), st.integers(1, 8)))
    return ls.Config(
        max_lights=k,
        shadow_budget=draw(st.sampled_from([0, 1, 2, 4, 4, 127])),
        max_shadowed_per_object=draw(st.integers(0, min(k, 3))),
        model=draw(st.sampled_from(["contribution", "thesis"])),
        hysteresis=draw(st.sampled_from([0.0, 0.1, 0.5])),
        hysteresis_abs=draw(st.sampled_from([0.0, 0.0, 0.05])),
        fade_in=draw(st.sampled_from([0.0, 0.1, 0.25, 1.0])),
        fade_out=draw(st.sampled_from([0.0, 0.1, 0.25, 1.0])),
        directional_in_slots=draw(st.booleans()),
        unshadowed=draw(st.sampled_from(["light", "light", "skip"])),
        cascades=draw(st.integers(1, 4)),
        shadow_distance=draw(st.sampled_from([150.0, 30.0, 5.0, 0.5])),
        cascade_overlap=draw(st.sampled_from([0.1, 0.0, 0.5])),
        shadow_update_budget=draw(st.sampled_from([0, 0, 1, 3, 8])),
        shadow_atlas_size=draw(st.sampled_from([8192, 8192, 4096, 0])),
        caster_culling=draw(st.sampled_from(["camera", "light"])),
    )


def as_kwargs(rows: dict[int, dict[str, Any]], order: list[int] | None = None,
              kind: str = "lights") -> dict[str, Any]:
    """Field arrays (rows in ``order``, default dict order) for set_lights/set_objects."""
    ids = list(rows) if order is None else order
    if not ids:
        vec = ("position", "direction") if kind == "lights" else ("bounds_min", "bounds_max")
        return {"id": np.zeros(0, np.int64), **{f: np.zeros((0, 3)) for f in vec}}
    fields = rows[ids[0]].keys()
    out: dict[str, Any] = {"id": np.array(ids, np.int64)}
    for f in fields:
        out[f] = np.array([rows[i][f] for i in ids])
    return out


@st.composite
def scenes(draw, max_lights: int = 16, max_objects: int = 12) -> dict[str, Any]:
    nl = draw(st.one_of(st.integers(0, max_lights), st.integers(4, max_lights)))
    no = draw(st.one_of(st.integers(0, max_objects), st.integers(3, max_objects)))
    lids = draw(st.lists(st.integers(0, 100), unique=True, min_size=nl, max_size=nl))
    oids = draw(st.lists(st.integers(0, 100), unique=True, min_size=no, max_size=no))
    lights = {i: draw(light_row()) for i in lids}
    positions = [r["position"] for r in lights.values()]
    objects = {i: draw(object_row(positions)) for i in oids}
    return {"lights": lights, "objects": objects, "cameras": draw(camera_list()),
            "config": draw(configs())}


# --------------------------------------------------------------------------- one frame


@examples(4.0)
@given(sc=scenes())
def test_one_frame_matches_oracle(sc, tuning):
    t = Twin(sc["config"], tuning=tuning)
    t.set_lights(**as_kwargs(sc["lights"]))
    t.set_objects(**as_kwargs(sc["objects"], kind="objects"))
    dt = 1 / 60
    t.frame(sc["cameras"], dt=dt)
    assert not t.plans[0].startswith("grid"), t.plans[0]


def _visibility_scene(cams: list, seed: int, n: int) -> tuple:
    """n boxes round an axis-aligned camera added to ``cams`` (zero-extent boxes, integer
    coordinates on its planes), the cameras' frames, and the oracle's visibility."""
    rng = np.random.default_rng(seed)
    centre = np.where(rng.random((n, 3)) < 0.5, rng.integers(-25, 26, (n, 3)),
                      rng.uniform(-30.0, 30.0, (n, 3))) + [0.0, 0.0, 10.0]
    half = np.where(rng.random((n, 3)) < 0.3, 0.0, rng.uniform(0.0, 4.0, (n, 3)))
    lo, hi = centre - half, centre + half
    frames, want = _oracle_visibility(cams, lo, hi)
    return rng, lo, hi, frames, want


def _oracle_visibility(cams: list, lo: np.ndarray, hi: np.ndarray) -> tuple:
    """The frames of ``cams`` and an axis-aligned camera at the origin looking along +z,
    and the oracle's visibility of the boxes (lo, hi) from them."""
    from lightsched.frustum import CameraFrames

    cams = [*cams, ls.Camera(position=np.zeros(3), forward=np.array([0.0, 0.0, 1.0]),
                             up=np.array([0.0, 1.0, 0.0]), fov_y=math.pi / 2, aspect=1.0,
                             near=1.0, far=20.0, id=len(cams))]
    planes = [ref.CameraFrame(c).planes for c in cams]
    want = np.array([any(ref.aabb_in_planes(p, tuple(lo[o]), tuple(hi[o])) for p in planes)
                     for o in range(lo.shape[0])], bool)
    return CameraFrames(cams), want


@examples(1.0)
@given(cams=camera_list(), seed=st.integers(0, 2**32 - 1), n=st.sampled_from([0, 1, 511, 1300]))
def test_object_visibility_matches_oracle(cams, seed, n):
    """frustum.objects_visible tests blocks of boxes plane by plane, in columns: the same
    visibility as the oracle's corner test box by box, across block ends, with zero-extent
    boxes and integer coordinates on the planes of an axis-aligned camera (normals with zero
    components), and the same bounding box of the visible objects."""
    from lightsched.frustum import objects_visible

    _, lo, hi, f, want = _visibility_scene(cams, seed, n)
    vis, box = objects_visible(lo, hi, f.plane_n, f.plane_p)
    assert np.array_equal(vis, want)
    if want.any():
        assert np.array_equal(box, np.concatenate([lo[want].min(0), hi[want].max(0)]))
    else:
        assert np.array_equal(box, [np.inf] * 3 + [-np.inf] * 3)


@examples(1.0)
@given(cams=camera_list(), cams2=camera_list(), seed=st.integers(0, 2**32 - 1),
       n=st.sampled_from([1, 700, 3000]), order=st.sampled_from(["cells", "random"]),
       by_row=st.booleans(), size=st.sampled_from([4, 64]))
def test_object_visibility_by_group_boxes_matches_oracle(cams, cams2, seed, n, order, by_row,
                                                         size):
    """frustum.objects_visible_groups (a grid's group boxes first: those wholly inside a
    frustum, those in none, then the objects of the others) gives the oracle's visibility,
    with grid positions in cells (groups inside, outside and across the planes) or in
    random order (every group across them), boxes read by row or from records in grid
    order, over three passes: the cameras, others after some objects moved within their
    group boxes, widened in place (grid.widen_group_boxes), then the first ones again.
    From the second pass on it is given the last pass's flags and classes too, and gives
    the same as without them. Its box holds the visible objects' and lies within the
    group boxes."""
    from lightsched.frustum import IN, OUT, GroupPass, objects_visible_groups
    from lightsched.grid import GroupBoxes, group_boxes, widen_group_boxes

    rng, lo, hi, f, want = _visibility_scene(cams, seed, n)
    if order == "cells":
        cell = np.floor((lo + hi) / 2 / 6.0).astype(np.int64) + 8
        grid_rows = np.argsort((cell[:, 0] * 17 + cell[:, 1]) * 17 + cell[:, 2], kind="stable")
    else:
        grid_rows = rng.permutation(n)
    pos_of = np.empty(n, np.int64)
    pos_of[grid_rows] = np.arange(n)
    gbox = group_boxes(by_row_or_grid(lo, hi, grid_rows, by_row)) if size == 64 else None
    if gbox is None:
        gbox = np.array([np.concatenate([lo[grid_rows[v:v + size]].min(0),
                                         hi[grid_rows[v:v + size]].max(0)])
                         for v in range(0, n, size)])
    last = GroupPass(np.zeros(0, bool), np.zeros(0, np.int8))
    for step, step_cams in enumerate([cams, cams2, cams]):
        if step == 1:
            # Some objects move within their group's box, which takes in their new box.
            moved = rng.permutation(n)[:n // 4]
            shift = rng.uniform(-2.0, 2.0, (moved.size, 3))
            lo[moved] += shift
            hi[moved] += shift
            if size == 64:
                widen_group_boxes(gbox, lo, hi, moved, pos_of)
            else:
                for o in moved:
                    g = pos_of[o] // size
                    gbox[g] = np.concatenate([np.minimum(gbox[g, :3], lo[o]),
                                              np.maximum(gbox[g, 3:], hi[o])])
        if step:
            f, want = _oracle_visibility(step_cams, lo, hi)
        at = by_row_or_grid(lo, hi, grid_rows, by_row)
        vis, box, classes = objects_visible_groups(at, f.plane_n, f.plane_p,
                                                   GroupBoxes(pos_of, gbox, size), last)
        assert np.array_equal(vis, want), step
        if step:
            fresh = objects_visible_groups(at, f.plane_n, f.plane_p,
                                           GroupBoxes(pos_of, gbox, size),
                                           GroupPass(np.zeros(0, bool), np.zeros(0, np.int8)))
            for x, y in zip((vis, box, classes), fresh, strict=True):
                assert np.array_equal(x, y), step
        for g in range(gbox.shape[0]):
            flags = vis[grid_rows[g * size:(g + 1) * size]]
            assert classes[g] != IN or flags.all()
            assert classes[g] != OUT or not flags.any()
        if want.any():
            assert (box[:3] <= lo[want].min(0)).all() and (box[3:] >= hi[want].max(0)).all()
            assert (box[:3] >= gbox[:, :3].min(0)).all() and (box[3:] <= gbox[:, 3:].max(0)).all()
        else:
            assert np.array_equal(box, [np.inf] * 3 + [-np.inf] * 3)
        last = GroupPass(vis, classes)


@examples(1.0)
@given(sc=scenes())
def test_stateless_schedule_matches_oracle(sc, tuning):
    lk, ok = as_kwargs(sc["lights"]), as_kwargs(sc["objects"], kind="objects")
    ff = ls.schedule(lk, ok, sc["cameras"], sc["config"], tuning=tuning)
    fo = ref.schedule(lk, ok, sc["cameras"], sc["config"])
    assert_frames_match(ff, fo)


# --------------------------------------------------------------------------- sequences

DTS = [0.0, 1 / 60, 1 / 60, 0.05, 0.2, 1.0]


def _fresh_ids(data, used: set[int], n: int) -> list[int]:
    ids = data.draw(st.lists(st.integers(0, 300).filter(lambda i: i not in used), unique=True,
                             min_size=n, max_size=n), label="new ids")
    used.update(ids)
    return ids


def _subset(data, ids: list[int], label: str, min_size: int = 0) -> list[int]:
    if not ids:
        return []
    return data.draw(st.lists(st.sampled_from(sorted(ids)), unique=True, min_size=min_size,
                              max_size=len(ids)), label=label)


def step_scene(data, t: Twin, lights: dict, objects: dict, used_l: set, used_o: set) -> None:
    """One to three random edits of the scene, applied to both schedulers and the model."""
    for _ in range(data.draw(st.integers(0, 3), label="edits")):
        op = data.draw(st.sampled_from(["move", "update_lights", "set_lights", "remove_lights",
                                        "set_objects", "remove_objects", "update_objects"]),
                       label="op")
        if op == "move" and lights:
            ids = _subset(data, list(lights), "moved", 1)
            pos = []
            for i in ids:
                p = lights[i]["position"]
                d = data.draw(st.tuples(st.floats(-3, 3, **finite), st.floats(-3, 3, **finite),
                                        st.floats(-3, 3, **finite)), label="delta")
                lights[i]["position"] = (p[0] + d[0], p[1] + d[1], p[2] + d[2])
                pos.append(lights[i]["position"])
            t.update_lights(id=np.array(ids), position=np.array(pos))
        elif op == "update_lights" and lights:
            ids = _subset(data, list(lights), "updated", 1)
            field = data.draw(st.sampled_from(["intensity", "type", "mask", "priority"]),
                              label="field")
            gen = {"intensity": st.sampled_from([0.0, 0.5, 5.0, 50.0]),
                   "type": st.sampled_from([0, 1, 2]),
                   "mask": st.sampled_from(MASKS_L),
                   "priority": st.sampled_from([0.0, -1.0, 2.0])}[field]
            vals = [data.draw(gen, label=field) for _ in ids]
            for i, v in zip(ids, vals, strict=True):
                lights[i][field] = v
            t.update_lights(id=np.array(ids), **{field: np.array(vals)})
        elif op == "set_lights":
            keep = _subset(data, list(lights), "kept lights")
            extra = _fresh_ids(data, used_l, data.draw(st.integers(0, 4), label="n new"))
            new = {i: lights[i] for i in keep}
            for i in extra:
                new[i] = data.draw(light_row(), label="new light")
            lights.clear()
            lights.update(new)
            order = data.draw(st.permutations(list(lights)), label="order")
            t.set_lights(**as_kwargs(lights, list(order)))
        elif op == "remove_lights" and lights:
            ids = _subset(data, list(lights), "removed lights", 1)
            for i in ids:
                del lights[i]
            t.remove_lights(id=np.array(ids, np.int64))
        elif op == "set_objects":
            keep = _subset(data, list(objects), "kept objects")
            extra = _fresh_ids(data, used_o, data.draw(st.integers(0, 4), label="n new"))
            new = {i: objects[i] for i in keep}
            pos = [r["position"] for r in lights.values()]
            for i in extra:
                new[i] = data.draw(object_row(pos), label="new object")
            objects.clear()
            objects.update(new)
            t.set_objects(**as_kwargs(objects, kind="objects"))
        elif op == "remove_objects" and objects:
            ids = _subset(data, list(objects), "removed objects", 1)
            for i in ids:
                del objects[i]
            t.remove_objects(id=np.array(ids, np.int64))
        elif op == "update_objects" and objects:
            ids = _subset(data, list(objects), "moved objects", 1)
            lo, hi = [], []
            for i in ids:
                d = data.draw(st.tuples(st.floats(-3, 3, **finite), st.floats(-3, 3, **finite),
                                        st.floats(-3, 3, **finite)), label="delta")
                r = objects[i]
                r["bounds_min"] = tuple(r["bounds_min"][a] + d[a] for a in range(3))
                r["bounds_max"] = tuple(r["bounds_max"][a] + d[a] for a in range(3))
                lo.append(r["bounds_min"])
                hi.append(r["bounds_max"])
            t.update_objects(id=np.array(ids), bounds_min=np.array(lo), bounds_max=np.array(hi))


def run_sequence(sc: dict[str, Any], data: Any, tuning: Any, frames: tuple[int, int],
                 check: Callable[[Twin, str], None] | None = None) -> Twin:
    """A random sequence of scene changes, camera moves, dts and cuts on a Twin (which
    compares every frame); ``check(twin, what)`` also runs after each frame and after each
    frame's scene changes."""
    t = Twin(sc["config"], tuning=tuning)
    lights, objects = dict(sc["lights"]), dict(sc["objects"])
    used_l, used_o = set(lights), set(objects)
    t.set_lights(**as_kwargs(lights))
    t.set_objects(**as_kwargs(objects, kind="objects"))
    cams = sc["cameras"]
    n_frames = data.draw(st.integers(*frames), label="frames")
    for i in range(n_frames):
        if i:
            step_scene(data, t, lights, objects, used_l, used_o)
            if check is not None:
                check(t, f"after frame {i - 1} and a scene change")
            if data.draw(st.integers(0, 3), label="camera move") == 0:
                cams = data.draw(camera_list(), label="cameras")
        dt = data.draw(st.sampled_from(DTS), label="dt")
        cut = data.draw(st.integers(0, 5), label="cut") == 0
        t.frame(cams, dt=dt, cut=cut)
        if check is not None:
            check(t, f"frame {i}")
    return t


@examples(2.0)
@given(sc=scenes(), data=st.data())
def test_sequence_matches_oracle(sc, data, tuning):
    t = run_sequence(sc, data, tuning, (3, 8))
    assert not any(p.startswith("grid") for p in t.plans), t.plans


# --------------------------------------------------------------------------- grid path


def big_scene(seed: int, n_obj: int, n_light: int, spot_share: float = 0.3,
              dir_count: int = 2) -> tuple[dict, dict, list[ls.Camera]]:
    """Everything in front of one wide camera, so (competing lights x visible objects)
    passes the brute-force limit of 32768 pairs."""
    rng = np.random.default_rng(seed)
    c = rng.uniform([-30, -30, 20], [30, 30, 80], (n_obj, 3))
    half = rng.uniform(0.0, 4.0, (n_obj, 3))
    half[rng.uniform(size=n_obj) < 0.1] = 0.0
    objects = {"id": rng.permutation(3 * n_obj)[:n_obj], "bounds_min": c - half,
               "bounds_max": c + half, "mask": rng.choice(MASKS_O, n_obj)}
    typ = np.where(rng.uniform(size=n_light) < spot_share, 1, 0)
    typ[:dir_count] = 2
    d = rng.normal(size=(n_light, 3))
    outer = rng.uniform(0.1, 1.4, n_light)
    lights = {"id": rng.permutation(3 * n_light)[:n_light], "type": typ,
              "position": rng.uniform([-30, -30, 20], [30, 30, 80], (n_light, 3)),
              "radius": np.where(rng.uniform(size=n_light) < 0.05, 60.0,
                                 rng.uniform(1.0, 15.0, n_light)),
              "direction": d, "outer_angle": outer,
              "inner_angle": outer * rng.choice([0.0, 0.8, 1.0], n_light),
              "intensity": rng.choice([0.0, 1.0, 20.0], n_light),
              "priority": np.where(rng.uniform(size=n_light) < 0.1, 5.0, 0.0),
              "shadows": rng.uniform(size=n_light) < 0.2,
              "mask": rng.choice(MASKS_L, n_light)}
    cam = ls.Camera(position=np.array([0.0, 0.0, -20.0]), forward=np.array([0.0, 0.0, 1.0]),
                    up=np.array([0.0, 1.0, 0.0]), fov_y=2.0, aspect=1.5, near=0.5, far=200.0,
                    focus=(0.3, -0.2))
    return lights, objects, [cam]


@examples(0.3)
@given(seed=st.integers(0, 2**32 - 1), cfg=configs(), frames=st.integers(2, 4))
def test_grid_path_sequence_matches_oracle(seed, cfg, frames, tuning):
    lights, objects, cams = big_scene(seed, 250, 160)
    t = Twin(cfg, tuning=tuning)
    t.set_lights(**lights)
    t.set_objects(**objects)
    rng = np.random.default_rng(seed + 1)
    grid_expected = cfg.unshadowed == "light"
    for i in range(frames):
        if i:
            rows = rng.choice(160, 40, replace=False)
            pos = lights["position"][rows] + rng.normal(0, 2.0, (40, 3))
            lights["position"][rows] = pos
            t.update_lights(id=lights["id"][rows], position=pos)
            if i == 2:
                t.remove_objects(id=objects["id"][:10])
        ff, _ = t.frame(cams, dt=rng.choice([0.0, 1 / 60, 0.1]), cut=i == frames - 1 and i > 2)
        if grid_expected:
            assert ff.stats["plan"]["pairs"].startswith("grid"), ff.stats["plan"]
        # (with "skip" the shadowed lights leave the competition; the plan then depends on
        # how many are left, and either path must agree with the oracle)


def test_both_pair_paths_are_exercised(tuning):
    lights, objects, cams = big_scene(7, 250, 160)
    t = Twin(ls.Config(max_lights=4), tuning=tuning)
    t.set_lights(**lights)
    t.set_objects(**objects)
    t.frame(cams, plan="grid")
    t2 = Twin(ls.Config(max_lights=4), tuning=tuning)
    small_l, small_o, _ = big_scene(7, 100, 40)
    t2.set_lights(**small_l)
    t2.set_objects(**small_o)
    t2.frame(cams, plan="brute force")


@pytest.mark.parametrize("hist_dtype", [np.int32, np.int64])
@pytest.mark.parametrize("parts", [1, 2, 3])
def test_group_pairs_is_a_stable_sort_by_object(hist_dtype, parts):
    """The pair cache is the light-major pairs sorted by object row, each object's lights in
    the walk's order, with either histogram width (int64 serves from 2^31 pairs) and on
    one thread (one run of lights) or in parallel runs."""
    from lightsched.group import SERIAL_PAIRS, PairHeap, group_pairs, group_parts
    from lightsched.jit import GROUP_PARTS
    from lightsched.walk import LightPairs

    assert group_parts(SERIAL_PAIRS - 1) == 1 and group_parts(SERIAL_PAIRS) == GROUP_PARTS

    rng = np.random.default_rng(3)
    n_obj, n_l = 500, 37
    rows = rng.permutation(n_l).astype(np.int32)
    count = rng.integers(0, 40, n_l)
    offsets = np.concatenate([[0], np.cumsum(count + rng.integers(0, 5, n_l))])
    pair_obj = rng.integers(0, n_obj, offsets[-1]).astype(np.int32)
    pair_p = rng.random(offsets[-1])
    start = np.empty(n_obj + 1, np.int64)
    heap = PairHeap.empty(count.sum())
    group_pairs(LightPairs(rows, offsets, count, pair_obj, pair_p),
                np.full((parts, n_obj + 1), 7, hist_dtype), start, heap)
    seg = [np.arange(offsets[t], offsets[t] + count[t]) for t in range(n_l)]
    e = np.concatenate(seg)
    light = np.repeat(rows, count)
    order = np.argsort(pair_obj[e], kind="stable")
    assert np.array_equal(start, np.searchsorted(pair_obj[e][order], np.arange(n_obj + 1)))
    assert np.array_equal(heap.p, pair_p[e][order])
    assert np.array_equal(heap.light_row, light[order])


def test_per_light_kernels_give_the_same_bits_on_one_thread_and_two(tuning):
    """Below SERIAL_LIGHTS lights the per-light kernels loop on the calling thread (the
    oracle tests' scenes), from it in parallel: a prefix of the lights gets the same rows
    from the serial loop as from the parallel one. The packing of some rows in place (an
    incremental frame's changed lights) writes those rows as a whole packing does, and no
    other; the packing of one part of them (PACK_*) those columns and no other."""
    from lightsched.candidates import SERIAL_SPHERES, left_spheres
    from lightsched.frustum import SERIAL_LIGHTS, lights_visible
    from lightsched.priority import (
        PACK_ALL,
        PACK_AXIS,
        PACK_CAMERA,
        PACK_CONE,
        PACK_ID,
        PACK_POSITION,
        PACK_SCALARS,
        _pack,
        light_columns,
    )
    from lightsched.walk import light_bounds

    scene = city(3000, 3 * SERIAL_LIGHTS, seed=4, shadow_fraction=0.05)
    s = ls.Scheduler(ls.Config(max_lights=8, model="thesis"), tuning)
    s.set_lights(**scene.lights)
    s.set_objects(**scene.objects)
    s.frame(scene.cameras)
    c, lights = s._last, s.lights
    n, few = len(lights), SERIAL_LIGHTS - 1
    f = c.cameras.frames

    UNSET = -7.25e300

    def pack(m: int, rows: np.ndarray | None = None, out: Any = None,
             parts: int = PACK_ALL) -> tuple[np.ndarray, np.ndarray]:
        store = tuple(a[:m] for a in light_columns(lights))
        return _pack(rows, store, (f.position, f.basis, f.tan_xy, f.focus),
                     np.array([s.config.w_ecc, s.config.w_dist, s.config.c1]), np.zeros(3),
                     out or (np.full((m, 8), UNSET), np.full((m, 8), UNSET)), parts)

    for a, b in zip(pack(n), pack(few), strict=True):
        assert np.array_equal(a[:few], b, equal_nan=True)
        assert not (a == UNSET).any()  # every element written
    # Rows packed again in place (an incremental frame's changed lights), a few or many:
    # those rows as a whole packing has them, no other row touched.
    whole = pack(n)
    for rows in (np.array([0, 5, n - 1]), np.arange(1, n, 2)):
        out = tuple(np.full((n, 8), UNSET) for _ in range(2))
        pack(n, rows, out)
        for a, b in zip(out, whole, strict=True):
            assert np.array_equal(a[rows], b[rows], equal_nan=True)
            others = np.setdiff1d(np.arange(n), rows)
            assert (a[others] == UNSET).all()
    # One part of the rows (the columns that read the fields an update changed): those
    # columns as a whole packing has them, every other element as it was.
    columns = {PACK_POSITION: (0, [0, 1, 2]), PACK_SCALARS: (0, [3, 4, 5, 6, 7]),
               PACK_AXIS: (1, [0, 1, 2]), PACK_CONE: (1, [3, 4, 5]), PACK_ID: (1, [6]),
               PACK_CAMERA: (1, [7])}
    assert sum(columns) == PACK_ALL
    for part, (side, cols) in columns.items():
        for rows in (None, np.arange(0, n, 3)):
            out = tuple(np.full((n, 8), UNSET) for _ in range(2))
            pack(n, rows, out, part)
            at = np.arange(n) if rows is None else rows
            written = np.zeros((2, n, 8), np.bool_)
            written[side, at[:, None], cols] = True
            for q in range(2):
                assert np.array_equal(out[q][written[q]], whole[q][written[q]], equal_nan=True)
                assert (out[q][~written[q]] == UNSET).all()
    vis = [lights_visible(lights.type[:m], lights.position[:m], lights.radius[:m], f.plane_n,
                          f.plane_p) for m in (n, few)]
    assert np.array_equal(vis[0][:few], vis[1]) and vis[1].any() and not vis[1].all()
    hot, n_vis = c.packed.rows[0], c.grid.records[0].shape[0]
    bounds = [light_bounds(hot, np.arange(m, dtype=np.int32), c.grid.index, n_vis)
              for m in (n, few)]
    assert np.array_equal(bounds[0][:few + 1], bounds[1]) and bounds[1][-1] > 0
    # left_spheres (serial below SERIAL_SPHERES lights): spheres round the lights' own
    # (these lights' rows repeated), some of which they have left.
    m_big = 2 * SERIAL_SPHERES
    rng = np.random.default_rng(4)
    spheres = hot[np.arange(m_big) % n]
    anchor = np.concatenate([spheres[:, :3] + rng.normal(0.0, 0.5, (m_big, 3)),
                             spheres[:, 3:4] * rng.uniform(0.9, 1.3, (m_big, 1))], axis=1)
    anchor[::7, 3] = 0.0
    own = rng.random(m_big) < 0.9
    few_s = SERIAL_SPHERES - 1
    left = [left_spheres(spheres[:m], anchor[:m], own[:m]) for m in (m_big, few_s)]
    assert np.array_equal(left[0][:few_s], left[1]) and left[1].any() and not left[1].all()
    # The rows read at random (packed lights, object records) start on a cache line.
    assert all(a.ctypes.data % 64 == 0
               for a in (*c.packed.rows, *s._buffers._named.values()))


def test_grid_with_big_objects_big_lights_and_directional_in_slots(tuning):
    """Objects larger than a cell are tested by every light directly; huge lights walk
    every cell; directional lights in slots take every visible object."""
    lights, objects, cams = big_scene(11, 260, 170, dir_count=5)
    lights["radius"][5:25] = 400.0
    objects["bounds_max"][:4] = objects["bounds_min"][:4] + 300.0
    t = Twin(ls.Config(max_lights=8, directional_in_slots=True, hysteresis=0.2),
             tuning=tuning)
    t.set_lights(**lights)
    t.set_objects(**objects)
    ff, _ = t.frame(cams, plan="grid")
    assert "0 objects larger" not in ff.stats["plan"]["pairs"], ff.stats["plan"]["pairs"]
    lights["position"][:60] += 1.5
    t.update_lights(id=lights["id"][:60], position=lights["position"][:60])
    t.frame(cams, dt=0.1, plan="grid")


# --------------------------------------------------------------------------- city


@pytest.mark.parametrize("model", ["contribution", "thesis"])
def test_city_animation_matches_oracle(model, tuning):
    scene = city(2000, 200, seed=3, shadow_fraction=0.1)
    t = Twin(ls.Config(max_lights=6, model=model, fade_in=0.05, fade_out=0.05),
             tuning=tuning)
    t.set_lights(**scene.lights)
    t.set_objects(**scene.objects)
    for i in range(5):
        if i:
            t.update_lights(id=scene.lights["id"], position=move_lights(scene.lights, i, speed=30.0))
        t.frame(scene.cameras, dt=1 / 60, plan="grid")
    assert t.frames == 5 and not t.diverged
