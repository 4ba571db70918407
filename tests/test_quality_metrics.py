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
from lightsched import Config  # noqa: E402
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


# --------------------------------------------------------------------------- issue 53 metrics


def sphere_directions(n: int = 40_000) -> np.ndarray:
    """n nearly uniform unit vectors (a Fibonacci sphere): each stands for 4 pi / n sr."""
    i = np.arange(n) + 0.5
    y = 1 - 2 * i / n
    r = np.sqrt(1 - y * y)
    phi = math.pi * (3 - math.sqrt(5)) * i
    return np.column_stack([r * np.cos(phi), y, r * np.sin(phi)])


def band1_projection(f: np.ndarray, dirs: np.ndarray, at: np.ndarray) -> np.ndarray:
    """The band-0 and band-1 real spherical-harmonic projection of samples ``f`` over
    ``dirs``, evaluated at the unit vectors ``at``."""
    w = 4 * math.pi / dirs.shape[0]
    y0, y1 = 0.5 / math.sqrt(math.pi), math.sqrt(3 / (4 * math.pi))
    c0 = (f * y0).sum() * w
    c1 = (f[:, None] * y1 * dirs).sum(0) * w
    return c0 * y0 + y1 * (at @ c1)


def one_light_one_object() -> tuple[SceneAPI, np.ndarray, np.ndarray]:
    """A small box 10 m below a point light: E and u of the residual, for rho = 1."""
    s = SceneAPI()
    s.set_lights(id=[3], position=[[0.0, 10.0, 0.0]], radius=[30.0], intensity=[50.0])
    s.set_objects(id=[0], bounds_min=[[-0.1, -0.1, -0.1]], bounds_max=[[0.1, 0.1, 0.1]])
    e, u = q.residual_terms(s.lights, s.objects, np.array([0]), np.array([0]))
    return s, e, u


def test_residual_terms_of_a_point_light() -> None:
    _, e, u = one_light_one_object()
    w = 1 - (100 / 900) ** 2
    assert e[0] == pytest.approx(50 * w * w / (100 + q.R0 ** 2))
    assert np.allclose(u[0], UP)


def test_one_lights_residual_is_its_lambert_term_up_to_band_1() -> None:
    s, e, u = one_light_one_object()
    res = q.residual_vectors(np.array([0]), e, u, np.array([1.0]), 1)
    assert np.allclose(res[0], e[0] * np.r_[1.0, u[0]])
    normals = np.vstack([UP, sphere_directions(64)])
    got = q.residual_at(res, normals)[0]
    # the light's Lambert term at each direction n, as a function on the sphere
    dirs = sphere_directions()
    lambert = e[0] * np.maximum(0.0, dirs @ u[0])
    want = np.maximum(0.0, band1_projection(lambert, dirs, normals))
    assert np.allclose(got, want, rtol=1e-3, atol=1e-3 * e[0])
    # facing the light: 1/4 + 1/2 of the Lambert term E (band 1 stops there), and the
    # face's Lambert term from light_at_points at the box's top is E within the box's size
    assert got[0] == pytest.approx(0.75 * e[0])
    top = lit(s, [0], [0.0, 0.1, 0.0], UP)[0]
    assert top == pytest.approx(e[0], rel=0.05)


def test_residual_matches_the_oracle() -> None:
    from lightsched.scenes import stadium

    for sc in (city(300, 40, seed=5), stadium(60, seed=1, n_lights=120)):
        frame = ref.schedule(sc.lights, sc.objects, sc.cameras, Config(max_lights=2))
        s = SceneAPI()
        s.set_lights(**sc.lights)
        s.set_objects(**sc.objects)
        rows = np.flatnonzero(frame.visible)
        vis_l = np.searchsorted(s.lights.id, frame.visible_lights)
        o, lt = q.affecting_pairs(s.lights, s.objects, rows, vis_l)
        e, u = q.residual_terms(s.lights, s.objects, o, lt)
        # a cut frame: every selected light on at weight 1, the others wholly in the residual
        slot = np.zeros(o.size, bool)
        for j, (oo, ll) in enumerate(zip(o, lt, strict=True)):
            slot[j] = ll in frame.light_index[oo]
        mine = q.residual_vectors(np.searchsorted(rows, o), e, u, 1.0 - slot, rows.size)
        theirs = np.asarray(frame.residual, np.float64)[rows]
        scale = np.maximum(np.abs(theirs[:, :1]), 1e-30)
        assert np.all(np.abs(mine - theirs) / scale <= 1e-5)
        assert (theirs[:, 0] > 0).sum() > 5  # some objects have lights past K


def test_lighting_error() -> None:
    a = np.array([[1.0, 2.0], [0.0, 3.0]])
    assert q.lighting_error(a, a) == (0.0, 6.0)
    d = np.array([[0.5, 2.0], [1.0, 3.0]])
    err, total = q.lighting_error(d, a)
    assert (err, total) == (1.5, 6.0)  # |D - A| counts light missing and light in excess


def test_abrupt_pops_jump_and_ramp() -> None:
    a = np.ones(16)
    jump = np.r_[1.0, 0.5, np.full(14, 0.5)]
    pops = [bool(q.abrupt_pops(jump[t], jump[t - 1], a[t], a[t - 1])) for t in range(1, 16)]
    assert pops == [True] + [False] * 14  # one frame jumps by half: one pop
    ramp = 1.0 - np.arange(16) / 15  # the same light faded out over 15 frames
    assert not any(q.abrupt_pops(ramp[t], ramp[t - 1], a[t], a[t - 1]) for t in range(1, 16))
    # D following A (motion, or a light that changes while it is delivered) is not a pop
    moving = np.linspace(1.0, 5.0, 16)
    assert not any(q.abrupt_pops(moving[t], moving[t - 1], moving[t], moving[t - 1])
                   for t in range(1, 16))
    # ... but A changing while D stays is: the definition is symmetric
    assert q.abrupt_pops(1.0, 1.0, 2.0, 1.0)


def test_abrupt_pop_at_an_unlit_point_is_any_change() -> None:
    """DESIGN's threshold, 0.1 * max(A_t, A_t-1), is 0 where no light reaches the point: a
    change of D of any size there is a pop (the residual's band-1 term lights faces that no
    light faces, and it changes as lights and objects move)."""
    assert q.abrupt_pops(1e-9, 0.0, 0.0, 0.0)
    assert not q.abrupt_pops(0.0, 0.0, 0.0, 0.0)
    assert not q.abrupt_pops(1e-9, 0.0, 0.0, 0.0, scale=np.array(1.0))


def test_abrupt_pop_where_only_all_lights_jump() -> None:
    """DESIGN's test is of D's change against A's, so a jump of A that D ramps after is a
    pop too: a light entering the visible lights adds its whole share to A at once while
    its slot fades in by 1/15 a frame (0.25 s at 60 Hz). The viewer sees D move 6.7% of
    that light, no jump; bench/quality.py counts these ("of which D steady") and finds
    most of the city's and dungeon-22's pops are of this kind."""
    light = 1.0
    a_before, a_now = 1.0, 1.0 + light
    d_before, d_now = 1.0, 1.0 + light / 15
    assert q.abrupt_pops(d_now, d_before, a_now, a_before)
    assert abs(d_now - d_before) <= q.POP_SHARE * max(a_now, a_before)  # D held still


def two_frames(residual: bool) -> q.ResidualAcc:
    """tiny_table's object with lights 0 and 2 in its slots, then light 2 dropped to the
    residual in one frame (fade off): the accumulator's popping after the second frame."""
    from types import SimpleNamespace

    s, table, _ = tiny_table()
    rows = np.array([0])
    pts, normals = q.face_samples(s.objects.bounds_min, s.objects.bounds_max)
    e, u = q.residual_terms(s.lights, s.objects, table.obj, table.light)
    group = np.zeros(table.obj.size, np.int64)
    ctx = q.FrameContext(rows, normals, table, table.all_lights_points(rows), e, u, group,
                         group, np.ones(group.size, bool), e, u,
                         np.zeros((1, normals.shape[0])), lambda lr: np.zeros((1, normals.shape[0])))
    acc = q.ResidualAcc(residual=residual, k=2)
    for li, w in (([[0, 2]], [[1.0, 1.0]]), ([[0, -1]], [[1.0, 0.0]])):
        li, w = np.array(li), np.array(w)
        rho = 1.0 - np.isin(table.light, li[0][w[0] > 0])
        res = q.residual_vectors(group, e, u, rho, 1).astype(np.float32)
        acc.add(ctx, SimpleNamespace(light_index=li, fade_weight=w, visible=np.array([True]),
                                     residual=res, directional_lights=np.zeros(0, np.int32)))
        ctx.a_prev[rows] = ctx.a_points
    return acc


def test_popping_with_the_residual_counts_its_change() -> None:
    s, table, ep = tiny_table()
    off, on = two_frames(False), two_frames(True)
    assert off.change == pytest.approx(ep[2])  # light 2's whole lighting vanishes
    # with the residual: both sides carry the residual of their own weights (lights 1 and 3
    # in it on both frames, light 2 joining it), at the same positions
    _, normals = q.face_samples(s.objects.bounds_min, s.objects.bounds_max)
    e, u = q.residual_terms(s.lights, s.objects, table.obj, table.light)
    group = np.zeros(e.size, np.int64)

    def res_sum(rho: list[float]) -> float:
        return float(q.residual_at(q.residual_vectors(group, e, u, np.array(rho), 1),
                                   normals).sum())

    before = ep[0] + ep[2] + res_sum([0.0, 1.0, 0.0, 1.0])
    now = ep[0] + res_sum([0.0, 1.0, 1.0, 1.0])
    assert on.change == pytest.approx(abs(now - before))
    # with the residual, light 2 moves into the residual's band-1 term: the change is what
    # that term misses or adds, more than 0 and less than the light
    assert 0.0 < on.change < off.change
    assert off.object_frames == on.object_frames == 1
    assert off.pop_frames == 1  # losing the brightest light at once is an abrupt pop


def test_every_light_in_a_slot_delivers_all_lights() -> None:
    """With K above every object's count and no fade, D is A at every point (the sun
    outside the slots on both sides, nothing in the residual): no error, no pop, no popping;
    with K = 1 the slots miss light and the residual gives some of it back."""
    sc = city(150, 30, seed=2)
    runs = {r.key: r for r in (q.run("all", max_lights=32, **q.PURE),
                               q.run("one", max_lights=1, residual=False, **q.PURE),
                               q.run("one+", max_lights=1, **q.PURE))}
    out = q.residual_pass(sc, "lights", runs, 4, 10**9, 0, "test")
    assert out["candidate_mismatch"] == 0 and out["sun_share"] > 0
    r = {runs[key].name: m for key, m in out["runs"].items()}
    assert r["all"]["object_frames"] > 0 and r["all"]["residual_dev"] == 0.0
    assert r["all"]["error"] == pytest.approx(0.0, abs=1e-12)
    assert r["all"]["pops"] == 0.0 and r["all"]["popping"] == pytest.approx(0.0, abs=1e-12)
    assert r["one"]["error"] > 0.001  # small: the sun is most of the city's light
    assert r["one+"]["error"] < r["one"]["error"] and r["one+"]["residual_dev"] <= 1e-5
