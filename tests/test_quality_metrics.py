"""The error metrics of bench/quality.py (DESIGN section 4) on tiny hand-made cases."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
import quality as q  # noqa: E402

import lightsched.reference as ref  # noqa: E402
from lightsched.scene import DIRECTIONAL, POINT, SPOT, SceneAPI  # noqa: E402
from lightsched.scenes import city  # noqa: E402

UP = np.array([0.0, 1.0, 0.0])


def store(**fields: object) -> SceneAPI:
    s = SceneAPI()
    s.set_lights(**fields)
    return s


def lit(lights: SceneAPI, rows: list[int], x: np.ndarray, n: np.ndarray) -> np.ndarray:
    return q.light_at_points(lights.lights, np.array(rows), np.asarray(x, float)[None, None, :]
                             .repeat(len(rows), 0), np.asarray(n, float)[None, :])[:, 0]


def test_point_light_lambert_and_window() -> None:
    s = store(id=[0], position=[[0.0, 2.0, 0.0]], radius=[10.0], intensity=[3.0])
    w = 1 - (4 / 100) ** 2
    assert lit(s, [0], [0, 0, 0], UP)[0] == pytest.approx(3 * w * w / (4 + q.R0 ** 2))
    # 60 degrees off the normal: cos = 0.5
    x = np.array([-2.0 * math.sqrt(3.0), 0.0, 0.0])
    d2 = 16.0
    w = 1 - (d2 / 100) ** 2
    assert lit(s, [0], x, UP)[0] == pytest.approx(3 * 0.5 * w * w / (d2 + q.R0 ** 2))
    assert lit(s, [0], [0, 0, 0], -UP)[0] == 0.0  # facing away
    assert lit(s, [0], [0, -8.5, 0], UP)[0] == 0.0  # facing away and out of range
    assert lit(s, [0], [0, 2.0, 0], UP)[0] == 0.0  # at the light


def test_spot_factor_and_directional() -> None:
    s = store(id=[0, 1, 2], type=[SPOT, SPOT, DIRECTIONAL],
              position=[[0.0, 5.0, 0.0], [0.0, 5.0, 0.0], [0.0, 0.0, 0.0]],
              radius=[20.0, 20.0, 1.0], direction=[[0, -1.0, 0], [0, -1.0, 0], [0, -1.0, 0]],
              outer_angle=[0.5, 0.5, 0.5], inner_angle=[0.25, 0.5, 0.4], intensity=[1.0, 1.0, 2.0])
    below = lit(s, [0, 1, 2], [0, 0, 0], UP)
    w = 1 - (25 / 400) ** 2
    assert below[0] == pytest.approx(w * w / (25 + q.R0 ** 2))  # on the axis: s = 1
    assert below[1] == pytest.approx(below[0])  # step spot, inside
    assert below[2] == pytest.approx(2.0)  # directional straight onto the normal
    # a point at angle 0.4 rad from the axis: ramp between cos 0.5 and cos 0.25
    x = np.array([5.0 * math.tan(0.4), 0.0, 0.0])
    c = math.cos(0.4)
    t = (c - math.cos(0.5)) / (math.cos(0.25) - math.cos(0.5))
    d2 = 25.0 + x[0] ** 2
    w = 1 - (d2 / 400) ** 2
    lam = 5.0 / math.sqrt(d2)
    got = lit(s, [0, 1], x, UP)
    assert got[0] == pytest.approx(lam * w * w / (d2 + q.R0 ** 2) * t * t)
    assert got[1] == pytest.approx(lam * w * w / (d2 + q.R0 ** 2))  # step: inside the cone
    x_out = np.array([5.0 * math.tan(0.6), 0.0, 0.0])
    assert np.all(lit(s, [0, 1], x_out, UP) == 0.0)


def test_face_samples_lie_on_faces() -> None:
    lo, hi = np.array([[0.0, 1.0, 2.0]]), np.array([[1.0, 3.0, 2.0]])  # a zero-depth box
    pts, nrm = q.face_samples(lo, hi, seed=3)
    assert pts.shape == (1, 6 * q.SAMPLES_PER_FACE, 3) and nrm.shape == (24, 3)
    assert np.all(pts >= lo[:, None, :]) and np.all(pts <= hi[:, None, :])
    for j in range(24):
        axis = int(np.flatnonzero(nrm[j])[0])
        face = hi[0, axis] if nrm[j, axis] > 0 else lo[0, axis]
        assert pts[0, j, axis] == face
    again, _ = q.face_samples(lo, hi, seed=3)
    assert np.array_equal(pts, again)


def test_set_error() -> None:
    a = np.array([[1, 2, -1], [3, 4, 5], [7, -1, -1], [9, 8, -1]])
    b = np.array([[2, 1, -1], [3, 4, 6], [-1, -1, -1], [9, 8, -1]])
    vis = np.array([True, True, False, True])
    share, differ, n = q.set_error(a, b, vis)
    assert (differ, n) == (1, 3) and share == pytest.approx(1 / 3)
    assert q.set_error(a, a, np.ones(4, bool)) == (0.0, 0, 4)


def test_captured_lighting() -> None:
    best = np.array([4.0, 2.0, 0.0])
    assert q.captured_lighting(best, best) == (1.0, 1.0, 2)
    ratio, mean, n = q.captured_lighting(np.array([2.0, 2.0, 0.0]), best)
    assert ratio == pytest.approx(4 / 6) and mean == pytest.approx(0.75) and n == 2


def tiny_table() -> tuple[SceneAPI, q.LightingTable, np.ndarray]:
    """One unit box at the origin, four point lights above it at rising heights (lighting
    falls with height) and one far away that does not affect it."""
    s = SceneAPI()
    s.set_lights(id=[10, 11, 12, 13, 14], type=[POINT] * 5,
                 position=[[0, 3, 0], [0, 4, 0], [0, 2, 0], [0, 6, 0], [100, 0, 0]],
                 radius=[20.0] * 5, intensity=[1.0] * 5)
    s.set_objects(id=[0], bounds_min=[[-0.5, -0.5, -0.5]], bounds_max=[[0.5, 0.5, 0.5]])
    pts, nrm = q.face_samples(s.objects.bounds_min, s.objects.bounds_max)
    o, lt = q.affecting_pairs(s.lights, s.objects, np.array([0]), np.arange(5))
    assert list(lt) == [0, 1, 2, 3]  # rows in ascending id; the far light does not affect
    table = q.LightingTable(s.lights, pts, nrm, o, lt, 1)
    e = table.e
    assert e[2] > e[0] > e[1] > e[3] > 0  # nearer is brighter
    return s, table, e


def test_captured_is_one_for_the_best_set() -> None:
    _, table, e = tiny_table()
    rows = np.array([0])
    best2 = table.best(2)
    assert best2[0] == pytest.approx(e[2] + e[0])
    assert table.all_lights()[0] == pytest.approx(e.sum())
    chosen, miss = table.selection(rows, np.array([[0, 2]]), np.ones((1, 2)))  # order is free
    assert miss == 0
    assert q.captured_lighting(chosen, best2[rows])[0] == pytest.approx(1.0)
    worse, _ = table.selection(rows, np.array([[1, 3]]), np.ones((1, 2)))
    assert q.captured_lighting(worse, best2[rows])[0] == pytest.approx((e[1] + e[3]) / (e[2] + e[0]))
    half, _ = table.selection(rows, np.array([[0, 2]]), np.array([[0.5, 1.0]]))
    assert half[0] == pytest.approx(0.5 * e[0] + e[2])
    # a slot light that does not affect the object is computed directly (0 here) and counted
    far, miss = table.selection(rows, np.array([[4, -1]]), np.ones((1, 2)))
    assert miss == 1 and far[0] == 0.0


def test_policies_pick_by_their_key() -> None:
    s, table, e = tiny_table()
    near = table.top_by(q.nearest_key(s.lights, s.objects, table.obj, table.light), 2, (1, 2))
    assert sorted(near[0]) == [0, 2]
    bright = table.top_by(q.brightest_key(s.lights, s.objects, table.obj, table.light), 3, (1, 3))
    assert list(bright[0]) == [2, 0, 1]


def test_popping_is_zero_without_changes() -> None:
    _, table, e = tiny_table()
    rows = np.array([0])
    li, w = np.array([[0, 2]]), np.array([[1.0, 1.0]])
    best = table.best(2)
    now, _ = table.selection(rows, li, w)
    before, _ = table.selection(rows, li, w)
    assert q.popping(now, before, best) == (0.0, 0.0, 0, pytest.approx(e[0] + e[2]))
    # a switch of light 2 for light 1 in one frame: the change is the difference, and a pop
    # when it is more than POP_STEP of the object's best-K lighting
    swapped, _ = table.selection(rows, np.array([[0, 1]]), w)
    change, steps, pops, total = q.popping(swapped, now, best)
    assert change == pytest.approx(e[2] - e[1]) and total == pytest.approx(e[0] + e[1])
    assert (e[2] - e[1]) > q.POP_STEP * best[0]
    assert steps == pytest.approx(change) and pops == 1
    # a fade step (1/15 of one light) is below POP_STEP: counted in the sum, not as a pop
    ramp, _ = table.selection(rows, li, np.array([[1.0, 14 / 15]]))
    change, steps, pops, _ = q.popping(ramp, now, best)
    assert change == pytest.approx(e[2] / 15) and steps == 0.0 and pops == 0


def test_popping_accumulator_counts_only_selection_changes() -> None:
    _, table, e = tiny_table()
    acc = q.Acc()
    vis = np.array([True])
    li, w = np.array([[0, 2]]), np.array([[1.0, 1.0]])
    for _ in range(3):
        acc.add(table, np.array([0]), vis, li, w, table.best(2), table.all_lights())
    r = acc.result()
    assert r["popping"] == 0.0 and r["pops"] == 0.0 and r["captured"] == pytest.approx(1.0)
    assert r["of_all"] == pytest.approx((e[0] + e[2]) / e.sum())
    # then the weaker light 1 replaces light 2 at once: one pop over 3 object-frames
    acc.add(table, np.array([0]), vis, np.array([[0, 1]]), w, table.best(2), table.all_lights())
    r = acc.result()
    assert r["popping"] == pytest.approx((e[2] - e[1]) / (3 * (e[0] + e[2]) - e[2] + e[1]))
    assert r["pops"] == pytest.approx(1000 / (3 * q.DT))


def test_affecting_pairs_match_the_oracle_candidates() -> None:
    sc = city(300, 40, seed=5)
    frame = ref.schedule(sc.lights, sc.objects, sc.cameras)
    s = SceneAPI()
    s.set_lights(**sc.lights)
    s.set_objects(**sc.objects)
    rows = np.flatnonzero(frame.visible)
    vis_l = np.searchsorted(s.lights.id, frame.visible_lights)
    o, _ = q.affecting_pairs(s.lights, s.objects, rows, vis_l, chunk=7)
    counts = np.bincount(o, minlength=len(s.objects))
    assert np.array_equal(counts[rows], frame.candidates[rows])
    assert counts.sum() > len(rows)  # not a vacuous scene


def test_pareto() -> None:
    assert q.pareto([(1, 5), (2, 3), (3, 4), (1, 5)]) == [True, True, False, True]
