"""DESIGN section 5: degenerate but valid scenes, translation invariance, independence of
input order and of numba's thread count. Every scene runs through the fast path and the
oracle (helpers.Twin: compared per DESIGN section 4, outputs checked for NaN/Inf)."""

from __future__ import annotations

import math

import numba
import numpy as np
import pytest
from helpers import OracleP, Twin, assert_frame_sane, assert_frames_match, camera, frames_identical

import lightsched as ls
import lightsched.reference as ref

# The tests that make fast schedulers run with both kinds of object grid of the fast path:
# they take the ``tuning`` fixture (conftest.py) and give it to each.

GRID = 2.0**-16


def snap(x):
    """Rounds to the 2^-16 m grid."""
    return np.round(np.asarray(x, float) / GRID) * GRID


def run(lights, objects, cams, config=None, frames=1, plan=None, tie_rel=1e-9, *, tuning):
    t = Twin(config or ls.Config(), tie_rel=tie_rel, tuning=tuning)
    t.set_lights(**lights)
    t.set_objects(**objects)
    out = [t.frame(cams, dt=0.1, plan=plan) for _ in range(frames)]
    return t, out


def mixed_lights(rng, n, centre=(0.0, 0.0, 20.0), spread=15.0, radius=(1.0, 20.0), ids=None):
    c = np.asarray(centre, float)
    outer = rng.uniform(0.1, 1.4, n)
    return {"id": np.arange(n) if ids is None else ids,
            "type": rng.choice([0, 0, 1, 2], n),
            "position": c + rng.uniform(-spread, spread, (n, 3)),
            "radius": rng.uniform(*radius, n),
            "direction": rng.normal(size=(n, 3)) + 1e-3,
            "outer_angle": outer, "inner_angle": outer * rng.choice([0.0, 0.5, 1.0], n),
            "intensity": rng.choice([0.0, 1.0, 7.0], n),
            "priority": rng.choice([0.0, 0.0, 1.5], n)}


def boxes(rng, n, centre=(0.0, 0.0, 20.0), spread=15.0, half=(0.0, 3.0), ids=None):
    c = np.asarray(centre, float) + rng.uniform(-spread, spread, (n, 3))
    h = rng.uniform(*half, (n, 3))
    return {"id": np.arange(n) if ids is None else ids, "bounds_min": c - h, "bounds_max": c + h}


CONFIGS = [ls.Config(max_lights=4), ls.Config(max_lights=3, model="thesis"),
           ls.Config(max_lights=8, directional_in_slots=True, hysteresis=0.0)]
CFG_IDS = ["contribution", "thesis", "dir-in-slots"]


# --------------------------------------------------------------------------- geometry


@pytest.mark.parametrize("cfg", CONFIGS, ids=CFG_IDS)
def test_zero_extent_objects(cfg, tuning):
    rng = np.random.default_rng(1)
    lights = mixed_lights(rng, 30)
    objs = boxes(rng, 40, half=(0.0, 0.0))
    # Points exactly on light spheres, and on a light's position.
    objs["bounds_min"][:3] = objs["bounds_max"][:3] = lights["position"][:3] + [[0, 0, 0]]
    objs["bounds_min"][3] = objs["bounds_max"][3] = lights["position"][3] + [lights["radius"][3], 0, 0]
    _, [(ff, _)] = run(lights, objs, [camera(position=(0, 0, -10))], cfg, tuning=tuning)
    assert ff.visible.sum() > 30 and ff.count[:3].min() >= 1


@pytest.mark.parametrize("cfg", CONFIGS, ids=CFG_IDS)
def test_light_inside_object(cfg, tuning):
    rng = np.random.default_rng(2)
    lights = mixed_lights(rng, 20)
    lights["type"][:] = np.where(lights["type"] == 2, 0, lights["type"])
    objs = boxes(rng, 20, half=(0.5, 4.0))
    c = (objs["bounds_min"] + objs["bounds_max"]) / 2
    lights["position"] = c  # every light at its box's centre
    objs["bounds_min"][5] = objs["bounds_max"][5] = c[5]  # and one box is the light's point
    _, [_, (ff, _)] = run(lights, objs, [camera(position=(0, 0, -10))], cfg, frames=2, tuning=tuning)
    assert np.all(ff.count[ff.visible] >= 1)


@pytest.mark.parametrize("cfg", CONFIGS, ids=CFG_IDS)
def test_camera_inside_light_and_light_at_camera(cfg, tuning):
    rng = np.random.default_rng(3)
    cam_pos = np.array([1.0, 2.0, -3.0])
    lights = mixed_lights(rng, 12, centre=cam_pos, spread=2.0, radius=(3.0, 30.0))
    lights["position"][0] = cam_pos  # a light at the camera position
    lights["type"][0] = 0
    lights["position"][1] = cam_pos
    lights["type"][1] = 1
    objs = boxes(rng, 30, centre=cam_pos + [0, 0, 10], spread=10.0)
    cams = [camera(position=cam_pos, forward=(0.2, 0.1, 1.0)),
            camera(position=cam_pos, forward=(-1.0, 0.0, 0.0), focus=(0.5, -0.9), id=1)]
    _, [_, (ff, _)] = run(lights, objs, cams, cfg, frames=2, tuning=tuning)
    assert 0 in ff.visible_lights.tolist() and 1 in ff.visible_lights.tolist()


@pytest.mark.parametrize("cfg", CONFIGS, ids=CFG_IDS)
@pytest.mark.parametrize("forward,up", [((0, 1, 0), (0, 0, 1)), ((0, -1, 0), (1, 0, 0)),
                                        ((0, 1e-150, 0), (0, 0, -1))],
                         ids=["up", "down", "tiny-forward"])
def test_looking_straight_up_and_down(cfg, forward, up, tuning):
    rng = np.random.default_rng(4)
    sign = 1.0 if forward[1] > 0 else -1.0
    lights = mixed_lights(rng, 30, centre=(0, 20 * sign, 0))
    objs = boxes(rng, 40, centre=(0, 20 * sign, 0))
    _, [(ff, _)] = run(lights, objs, [camera(forward=forward, up=up, fov_y=1.2, aspect=1.7)], cfg,
                       tuning=tuning)
    assert ff.visible.sum() > 5


@pytest.mark.parametrize("cfg", CONFIGS, ids=CFG_IDS)
@pytest.mark.parametrize("fov", [1e-6, math.pi - 1e-6, 1e-12, math.pi - 1e-12])
def test_extreme_fov(cfg, fov, tuning):
    rng = np.random.default_rng(5)
    lights = mixed_lights(rng, 40)
    objs = boxes(rng, 50)
    # Something on the axis, so a needle frustum still sees it.
    objs["bounds_min"][0] = (-0.5, -0.5, 10.0)
    objs["bounds_max"][0] = (0.5, 0.5, 11.0)
    lights["position"][0] = (0.0, 0.0, 12.0)
    lights["type"][0] = 0
    for aspect in (1.0, 1e-3, 1e3):
        _, [(ff, _)] = run(lights, objs, [camera(position=(0, 0, -10), fov_y=fov, aspect=aspect)],
                           cfg, tuning=tuning)
        assert ff.visible[0]


@pytest.mark.parametrize("n_lights,n_objects", [(0, 10), (10, 0), (0, 0)])
@pytest.mark.parametrize("cfg", CONFIGS, ids=CFG_IDS)
def test_empty_scenes(cfg, n_lights, n_objects, tuning):
    rng = np.random.default_rng(6)
    lights = mixed_lights(rng, n_lights)
    objs = boxes(rng, n_objects)
    t, frames = run(lights, objs, [camera(position=(0, 0, -10))], cfg, frames=3, tuning=tuning)
    for ff, fo in frames:
        assert ff.light_ids.shape == (n_objects, cfg.max_lights)
        assert ff.count.sum() == 0 and fo.count.sum() == 0
        assert ff.stats["plan"]["pairs"].startswith("none")


# --------------------------------------------------------------------------- many lights


@pytest.mark.parametrize("n_objects", [1, 2], ids=["brute", "grid"])
def test_twenty_thousand_lights_on_one_point_fast(n_objects, tuning):
    """Fast only (the oracle would take minutes): equal P, so the K lowest ids win."""
    n, k = 20000, 8
    rng = np.random.default_rng(7)
    ids = rng.permutation(3 * n)[:n]
    p = np.array([1.0, 2.0, 30.0])
    lights = {"id": ids, "position": np.tile(p, (n, 1)), "radius": np.full(n, 5.0),
              "intensity": np.full(n, 3.0)}
    lo = np.array([[0.0, 1.0, 29.0], [-2.0, 1.5, 30.5]])[:n_objects]
    objs = {"id": np.arange(n_objects) + 10, "bounds_min": lo, "bounds_max": lo + 2.0}
    s = ls.Scheduler(ls.Config(max_lights=k), tuning)
    s.set_lights(**lights)
    s.set_objects(**objs)
    cams = [camera(position=(0, 0, -10))]
    for i in range(3):
        f = s.frame(cams, dt=0.1, cut=i == 2)
        assert_frame_sane(f, k)
        assert f.stats["plan"]["pairs"].startswith("grid" if n_objects == 2 else "brute force")
        want = np.sort(ids)[:k]
        for o in range(n_objects):
            assert f.candidates[o] == n and f.count[o] == k
            assert f.light_ids[o].tolist() == want.tolist()
            assert np.all(f.fade_state[o] == 2) and np.all(f.fade_weight[o] == 1)
            assert len(set(f.priority[o].tolist())) == 1
        assert f.light_index[0].tolist() == list(range(k))


def test_three_hundred_lights_on_one_point_vs_oracle(tuning):
    n = 300
    rng = np.random.default_rng(8)
    ids = rng.permutation(1000)[:n]
    types = rng.choice([0, 1], n)
    lights = {"id": ids, "type": types, "position": np.tile([0.0, 0.0, 20.0], (n, 1)),
              "radius": np.full(n, 6.0), "direction": np.tile([0.0, 0.0, 1.0], (n, 1)),
              "intensity": np.full(n, 2.0)}
    objs = boxes(rng, 30, centre=(0, 0, 22), spread=4.0)
    for cfg in CONFIGS:
        t, frames = run(lights, objs, [camera(position=(0, 0, -10))], cfg, frames=2, tuning=tuning)
        assert not t.diverged
        ff, _ = frames[0]
        for o in np.flatnonzero(ff.count):
            # Equal P within each type: the lowest ids among the best type.
            row = ff.light_ids[o, :ff.count[o]]
            pr = ff.priority[o, :ff.count[o]]
            for a in range(len(row) - 1):
                if pr[a] == pr[a + 1]:
                    assert row[a] < row[a + 1]


def test_radii_from_micrometres_to_a_million_km(tuning):
    rng = np.random.default_rng(9)
    n = 120
    lights = mixed_lights(rng, n)
    lights["radius"] = 10.0 ** rng.uniform(-6, 9, n)
    lights["radius"][:4] = [1e-6, 1e9, 1e-6, 1e9]
    lights["position"][2] = lights["position"][3] = (0.0, 0.0, 20.0)
    lights["type"][:4] = 0
    lights["intensity"][:4] = 7.0
    objs = boxes(rng, 150)
    objs["bounds_min"][0] = (-1.0, -1.0, 19.0)
    objs["bounds_max"][0] = (1.0, 1.0, 21.0)
    objs["bounds_min"][1] = objs["bounds_max"][1] = (0.0, 0.0, 20.0)
    cams = [camera(position=(0, 0, -10), far=1e4)]
    for cfg in CONFIGS:
        _, [(f1, _)] = run(lights, objs, cams, cfg, plan="brute force", tuning=tuning)
        assert f1.candidates[1] >= 2
        if cfg.model == "contribution":
            assert 3 in f1.light_ids[0].tolist()  # r = 1e9 at the box centre: P = 7 / r0^2
    # precision "fast" (float32 paths): no overflow, no NaN; not compared with the oracle.
    s = ls.Scheduler(ls.Config(max_lights=4, precision="fast"), tuning)
    s.set_lights(**lights)
    s.set_objects(**objs)
    for _ in range(2):
        assert_frame_sane(s.frame(cams, dt=0.1), 4, "precision fast")
    # Grid path: enough pairs, a mix of micro and huge radii (the huge go global).
    lights2 = mixed_lights(rng, 300)
    lights2["radius"] = 10.0 ** rng.uniform(-6, 9, 300)
    objs2 = boxes(rng, 200)
    run(lights2, objs2, cams, ls.Config(max_lights=6), plan="grid", tuning=tuning)


# --------------------------------------------------------------------------- exact ties


def tie_scene():
    """On the 2^-16 m grid: light pairs mirrored through the centre of a symmetric box,
    and exact copies of lights under other ids, so many P are exactly equal."""
    c = np.array([0.25, -0.5, 20.0])
    half = np.array([1.0, 0.5, 2.0])
    objs = {"id": np.array([5, 3, 9]),
            "bounds_min": np.array([c - half, c - half * 2, c - 0.0]),
            "bounds_max": np.array([c + half, c + half * 2, c + 0.0])}
    offs = np.array([[3.0, 0, 0], [0, 2.5, 0], [0, 0, 3.5], [1.5, 1.5, 0], [0.75, -1.25, 2.5]])
    pos, rad, inten = [], [], []
    for j, d in enumerate(offs):
        for sgn in (1.0, -1.0):
            pos.append(c + sgn * d)
            rad.append(6.0 + j * 0.5)
            inten.append(2.0)
    pos = np.array(pos * 2)  # exact copies under other ids
    ids = np.arange(len(pos))[::-1] * 3 + 1  # ids descending in row order
    return ({"id": ids, "position": pos, "radius": np.array(rad * 2), "intensity": np.array(inten * 2)},
            objs)


@pytest.mark.parametrize("model", ["contribution", "thesis"])
@pytest.mark.parametrize("k", [1, 3, 6])
def test_exact_ties_on_grid_identity(model, k, tuning):
    lights, objs = tie_scene()
    assert np.array_equal(snap(lights["position"]), lights["position"])
    cam = camera(position=(0.25, -0.5, 0.0), near=0.5, far=64.0)
    cfg = ls.Config(max_lights=k, model=model, hysteresis=0.0)
    t = Twin(cfg, tie_rel=0.0, tuning=tuning)
    t.set_lights(**lights)
    t.set_objects(**objs)
    ff, fo = t.frame([cam])
    # Hand expectation: within a row, equal P go to the lower id.
    for f in (ff, fo):
        for o in range(3):
            row = f.light_ids[o, :f.count[o]].tolist()
            pr = f.priority[o, :f.count[o]].tolist()
            for a in range(len(row) - 1):
                assert pr[a] > pr[a + 1] or (pr[a] == pr[a + 1] and row[a] < row[a + 1])
    # Hand expectation from the oracle's float64 P of every affecting light: the K best by
    # (-P, id); at least one object has an exact tie straddling the cut.
    p64 = OracleP(t.ref, [cam])
    ties_at_cut = 0
    for o in range(3):
        ps = {int(lid): p64(o, lid) for lid in lights["id"]}
        ps = {lid: p for lid, p in ps.items() if p is not None}
        best = sorted(ps, key=lambda lid: (-ps[lid], lid))
        assert ff.light_ids[o, :ff.count[o]].tolist() == best[:k]
        if len(best) > k and ps[best[k - 1]] == ps[best[k]]:
            ties_at_cut += 1
    assert ties_at_cut > 0
    # Hysteresis 0 and moving nothing: identical later frames, still exact.
    for _ in range(2):
        t.frame([cam], dt=0.05)


# --------------------------------------------------------------------------- huge objects


def test_huge_object_touched_by_thousands_of_lights(tuning):
    rng = np.random.default_rng(10)
    n = 3000
    lights = mixed_lights(rng, n, centre=(0, 0, 2000), spread=1000.0, radius=(5.0, 60.0))
    lights["position"][:, 1] = rng.uniform(-30, 30, n)  # all within reach of the slab
    objs = {"id": np.arange(22),
            "bounds_min": np.array([[-5000.0, -1.0, -3000.0]] + [[x, 0.0, 2000.0] for x in range(21)]),
            "bounds_max": np.array([[5000.0, 1.0, 7000.0]] + [[x + 2.0, 2.0, 2003.0] for x in range(21)])}
    cam = camera(position=(0, 50, -100), forward=(0, -0.2, 1), far=1e4, fov_y=1.5, aspect=2.0)
    for cfg in (ls.Config(max_lights=8), ls.Config(max_lights=5, model="thesis", hysteresis=0.0)):
        t, [(ff, _), _] = run(lights, objs, [cam], cfg, frames=2, plan="grid", tuning=tuning)
        assert ff.candidates[0] > 1000 and ff.count[0] == cfg.max_lights
    _, [(fb, _)] = run(lights, {k: v[:1] for k, v in objs.items()}, [cam], ls.Config(max_lights=8),
                       plan="brute force", tuning=tuning)
    assert fb.candidates[0] > 1000


# --------------------------------------------------------------------------- translations


def grid_scene(seed, n_l=60, n_o=80, snap_it=True):
    rng = np.random.default_rng(seed)
    lights = mixed_lights(rng, n_l, radius=(2.0, 18.0))
    objs = boxes(rng, n_o, half=(0.0, 4.0))
    lights["id"] = rng.permutation(5 * n_l)[:n_l]
    objs["id"] = rng.permutation(5 * n_o)[:n_o]
    if snap_it:
        for d, f in ((lights, "position"), (objs, "bounds_min"), (objs, "bounds_max")):
            d[f] = snap(d[f])
        lights["radius"] = snap(lights["radius"])
    return lights, objs


def grid_cameras(offset):
    """Axis-aligned forwards, positions and near/far on the grid: exact plane points."""
    o = np.asarray(offset, float)
    return [camera(position=o + (0.5, -0.25, -12.0), forward=(0, 0, 1), near=0.5, far=96.0,
                   fov_y=1.3, aspect=1.5, focus=(0.25, -0.5)),
            camera(position=o + (40.0, 0.75, 20.0), forward=(-1, 0, 0), up=(0, 1, 0), near=1.0,
                   far=64.0, id=3)]


def new_scheduler(cls, cfg, tuning):
    """A fast scheduler with ``tuning``, or an oracle (which has none)."""
    return cls(cfg, tuning) if cls is ls.Scheduler else cls(cfg)


def translated_run(cls, cfg, lights, objs, offset, frames=4, *, tuning):
    s = new_scheduler(cls, cfg, tuning)
    o = np.asarray(offset, float)
    s.set_lights(**{**lights, "position": lights["position"] + o})
    s.set_objects(**{**objs, "bounds_min": objs["bounds_min"] + o, "bounds_max": objs["bounds_max"] + o})
    out = []
    rng = np.random.default_rng(99)
    for i in range(frames):
        if i:
            rows = rng.choice(len(lights["id"]), 10, replace=False)
            step = snap(rng.normal(0, 1.5, (10, 3)))
            lights["position"][rows] += step  # the caller's copy moves too (same for all offsets)
            s.update_lights(id=lights["id"][rows], position=lights["position"][rows] + o)
        out.append(s.frame(grid_cameras(o), dt=[0.0, 0.05, 0.1, 1 / 60][i % 4], cut=i == 3))
    return out


OFFSETS = [(1e3, 0, 0), (0, -1e6, 1e6), (1e7, 1e7, -1e7)]
MODELS = [ls.Config(max_lights=5), ls.Config(max_lights=4, model="thesis"),
          ls.Config(max_lights=6, directional_in_slots=True, hysteresis=0.3)]


@pytest.mark.parametrize("cfg", MODELS, ids=CFG_IDS)
@pytest.mark.parametrize("cls", [ls.Scheduler, ref.Scheduler], ids=["fast", "oracle"])
def test_translation_on_grid_is_exact(cls, cfg, tuning):
    base_l, base_o = grid_scene(11)
    base = translated_run(cls, cfg, {k: v.copy() for k, v in base_l.items()}, base_o, (0, 0, 0),
                          tuning=tuning)
    assert sum(int(f.count.sum()) for f in base) > 50
    for off in OFFSETS:
        moved = translated_run(cls, cfg, {k: v.copy() for k, v in base_l.items()}, base_o, off, tuning=tuning)
        for i, (a, b) in enumerate(zip(base, moved, strict=True)):
            assert_frames_match(b, a, tie_rel=0.0, bitwise=True, what=f"offset {off} frame {i}")


@pytest.mark.parametrize("cfg", MODELS[:2], ids=CFG_IDS[:2])
def test_translation_on_grid_fast_equals_oracle(cfg, tuning):
    base_l, base_o = grid_scene(12)
    for off in OFFSETS:
        f = translated_run(ls.Scheduler, cfg, {k: v.copy() for k, v in base_l.items()}, base_o, off,
                           tuning=tuning)
        r = translated_run(ref.Scheduler, cfg, {k: v.copy() for k, v in base_l.items()}, base_o, off,
                           tuning=tuning)
        for i, (a, b) in enumerate(zip(f, r, strict=True)):
            assert_frames_match(a, b, tie_rel=0.0, bitwise=True, what=f"offset {off} frame {i}")


@pytest.mark.parametrize("cfg", MODELS, ids=CFG_IDS)
def test_translation_off_grid_up_to_near_ties(cfg, tuning):
    """Off the grid, coordinates near 1e7 m round to ~2e-9 m: P move by about that over the
    distance, so sets agree up to near-ties of that size (rel 1e-6 here) and P to 1e-6."""
    base_l, base_o = grid_scene(13, snap_it=False)
    for cls in (ls.Scheduler, ref.Scheduler):
        base = translated_run(cls, cfg, {k: v.copy() for k, v in base_l.items()}, base_o, (0, 0, 0),
                              tuning=tuning)
        for off in OFFSETS:
            moved = translated_run(cls, cfg, {k: v.copy() for k, v in base_l.items()}, base_o, off,
                                   tuning=tuning)
            for i, (a, b) in enumerate(zip(base, moved, strict=True)):
                tied = assert_frames_match(b, a, rel=1e-6, tie_rel=1e-6, what=f"offset {off} frame {i}")
                if tied:
                    break  # states may part after a near-tie


# --------------------------------------------------------------------------- order, threads


def shuffled(d, perm):
    return {k: np.asarray(v)[perm] for k, v in d.items()}


@pytest.mark.parametrize("cls", [ls.Scheduler, ref.Scheduler], ids=["fast", "oracle"])
@pytest.mark.parametrize("n", [(40, 60), (220, 260)], ids=["brute", "grid"])
def test_input_order_does_not_matter(cls, n, tuning):
    n_l, n_o = n
    rng = np.random.default_rng(14)
    lights, objs = grid_scene(14, n_l, n_o, snap_it=False)
    # Exact duplicates make order matter if anything is order dependent.
    lights["position"][1] = lights["position"][0]
    lights["radius"][1] = lights["radius"][0]
    cfg = ls.Config(max_lights=4, hysteresis=0.2)
    results = []
    for trial in range(3):
        s = new_scheduler(cls, cfg, tuning)
        pl = rng.permutation(n_l) if trial else np.arange(n_l)
        po = rng.permutation(n_o) if trial else np.arange(n_o)
        s.set_lights(**shuffled(lights, pl))
        s.set_objects(**shuffled(objs, po))
        frames = []
        for i in range(4):
            if i:
                rows = np.arange(i, n_l, 7)
                q = rng.permutation(rows.size) if trial else np.arange(rows.size)
                new = lights["position"][rows] + 0.5 * i
                s.update_lights(id=lights["id"][rows][q], position=new[q])
            frames.append(s.frame(grid_cameras((0, 0, 0)), dt=0.05))
        if cls is ls.Scheduler:
            assert frames[0].stats["plan"]["pairs"].startswith("grid" if n_l > 100 else "brute")
        results.append(frames)
    for trial in (1, 2):
        for i, (a, b) in enumerate(zip(results[0], results[trial], strict=True)):
            frames_identical(a, b, f"trial {trial} frame {i}")


def test_thread_count_does_not_matter(tuning):
    if numba.config.NUMBA_NUM_THREADS < 2:
        pytest.skip("numba has a single thread")
    lights, objs = grid_scene(15, 400, 1500, snap_it=False)
    cfg = ls.Config(max_lights=6)
    before = numba.get_num_threads()
    runs = []
    try:
        for threads in (1, 2):
            numba.set_num_threads(threads)
            s = ls.Scheduler(cfg, tuning)
            s.set_lights(**lights)
            s.set_objects(**objs)
            rng = np.random.default_rng(3)
            frames = []
            for i in range(4):
                if i:
                    rows = rng.choice(400, 100, replace=False)
                    s.update_lights(id=lights["id"][rows],
                                    position=lights["position"][rows] + rng.normal(0, 2, (100, 3)))
                f = s.frame(grid_cameras((0, 0, 0)), dt=0.05)
                assert f.stats["counts"]["threads"] == threads
                assert f.stats["plan"]["pairs"].startswith("grid")
                frames.append(f)
            runs.append(frames)
    finally:
        numba.set_num_threads(before)
    for i, (a, b) in enumerate(zip(*runs, strict=True)):
        frames_identical(a, b, f"frame {i}")


def test_spot_whose_inner_and_outer_cosines_round_equal(tuning):
    """inner a few ulps below outer: cos(inner) == cos(outer), so DESIGN's ramp would divide
    by zero; both implementations take the step profile (as for inner == outer)."""
    outer = 0.05
    inner = float(np.nextafter(outer, 0.0))
    assert inner != outer and math.cos(inner) == math.cos(outer)
    lights = dict(id=[1, 2], type=[1, 1], position=[[0.0, 0.0, 10.0]] * 2, radius=[20.0] * 2,
                  direction=[[0.0, 0.0, 1.0]] * 2, outer_angle=[outer] * 2,
                  inner_angle=[inner, outer])
    objs = dict(id=[0], bounds_min=[[-0.1, -0.1, 14.9]], bounds_max=[[0.1, 0.1, 15.1]])
    cam = ls.Camera(position=[0, 0, 0], forward=[0, 0, 1], up=[0, 1, 0], fov_y=1.0, aspect=1.0,
                    near=0.1, far=100.0)
    fast = ls.schedule(lights, objs, [cam], tuning=tuning)
    oracle = ref.schedule(lights, objs, [cam])
    assert fast.light_ids[0, :2].tolist() == oracle.light_ids[0, :2].tolist() == [1, 2]
    assert fast.priority[0, 0] == oracle.priority[0, 0] == oracle.priority[0, 1]
    assert np.isfinite(fast.priority).all()


@pytest.mark.parametrize("ulps", [0, 3], ids=["inner == outer", "inner 3 ulps below"])
def test_spot_with_equal_cosines_uses_the_step_profile(ulps):
    """DESIGN section 2: when cos(inner) == cos(outer) in float64, s = [c >= cos o]: an
    object just inside the cone gets the full light (P equal to a point light's of the
    same position, radius and intensity: s = 1), one just outside none, in the fast path
    and the oracle alike. A ramp from an inner angle a little smaller would give s < 1
    there."""
    outer = 0.05
    inner = outer
    for _ in range(ulps):
        inner = float(np.nextafter(inner, 0.0))
    assert math.cos(inner) == math.cos(outer) and (inner != outer) == (ulps > 0)
    apex, along = 10.0, 5.0
    inside = along * math.tan(outer * 0.98)  # centre at 0.98 outer: c > cos(outer)
    outside = along * math.tan(outer * 1.1)
    h = 1e-3
    objs = dict(id=[0, 1],
                bounds_min=[[inside - h, -h, apex + along - h], [outside - h, -h, apex + along - h]],
                bounds_max=[[inside + h, h, apex + along + h], [outside + h, h, apex + along + h]])
    cam = ls.Camera(position=[0, 0, 0], forward=[0, 0, 1], up=[0, 1, 0], fov_y=1.0, aspect=1.0,
                    near=0.1, far=100.0)
    light = dict(id=[1], position=[[0.0, 0.0, apex]], radius=[20.0], intensity=[3.0])
    spot = dict(light, type=[1], direction=[[0.0, 0.0, 1.0]], outer_angle=[outer],
                inner_angle=[inner])
    ramp = dict(spot, inner_angle=[outer * 0.9])
    point = ref.schedule(dict(light, type=[0]), objs, [cam])
    assert point.count.tolist() == [1, 1]
    for impl in (ls, ref):
        f = impl.schedule(spot, objs, [cam])
        assert f.count.tolist() == [1, 0] and f.candidates.tolist() == [1, 0], impl.__name__
        assert f.priority[0, 0] == point.priority[0, 0], impl.__name__
        assert impl.schedule(ramp, objs, [cam]).priority[0, 0] < point.priority[0, 0]
