"""Input validation and the scene stores (DESIGN sections 1, 3 "Details every implementation
must agree on" and 7).

Every class of bad input must raise ``lightsched.ValidationError`` whose ``field`` names the
first bad field in the table order of section 1 and whose ``index`` is the first offending
row of that call (None when no row applies: shapes, missing fields, Config), and must leave
the scheduler exactly as it was. Both the fast Scheduler and the oracle's are exercised; they
share ``SceneAPI`` (stores, validation, ``frame``'s camera/dt/cut checks), so no frame is
ever computed here.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import lightsched as ls
import lightsched.reference as reference
from lightsched import Camera, Config, ValidationError
from lightsched.scene import LIGHT_FIELDS, OBJECT_FIELDS

SCHEDULERS = [ls.Scheduler, reference.Scheduler]
SCHEDULER_IDS = ["fast", "reference"]

NAN, INF = math.nan, math.inf
BAD_FLOATS = [NAN, INF, -INF]
UINT32_ALL = 0xFFFFFFFF
INT32_MAX = 2**31 - 1

# Base light set: rows in call order, ids deliberately unsorted.
# row:          0   1   2  3   4  5  6  7
LIGHT_IDS = [40, 3, 17, 8, 25, 1, 9, 30]
LIGHT_TYPES = [0, 1, 2, 0, 1, 2, 0, 1]
POINT_ROWS = [0, 3, 6]
SPOT_ROWS = [1, 4, 7]
DIR_ROWS = [2, 5]
N_L = len(LIGHT_IDS)

OBJECT_IDS = [12, 5, 7, 100, 0, 33]
N_O = len(OBJECT_IDS)

STATE_FILL = -7


def light_kwargs() -> dict[str, np.ndarray]:
    """A valid, fully specified light set (fresh arrays, safe to corrupt)."""
    rng = np.random.default_rng(1)
    return {
        "id": np.array(LIGHT_IDS, np.int64),
        "type": np.array(LIGHT_TYPES, np.int64),
        "position": rng.uniform(-50, 50, (N_L, 3)),
        "radius": rng.uniform(1, 10, N_L),
        "direction": rng.uniform(-1, 1, (N_L, 3)) + np.array([0.0, 0.0, 3.0]),
        "outer_angle": np.full(N_L, 0.6),
        "inner_angle": np.full(N_L, 0.4),
        "intensity": rng.uniform(0, 5, N_L),
        "priority": rng.uniform(-1, 1, N_L),
        "shadows": np.arange(N_L) % 2 == 0,
        "mask": np.full(N_L, 0x0F0F, np.int64),
    }


def object_kwargs() -> dict[str, np.ndarray]:
    rng = np.random.default_rng(2)
    lo = rng.uniform(-50, 50, (N_O, 3))
    return {
        "id": np.array(OBJECT_IDS, np.int64),
        "bounds_min": lo,
        "bounds_max": lo + rng.uniform(0, 4, (N_O, 3)),
        "casts_shadows": np.arange(N_O) % 3 != 0,
        "mask": np.full(N_O, 0xF0F0, np.int64),
        "static": np.arange(N_O) % 2 == 1,
    }


def camera(**kw) -> Camera:
    base = dict(position=[0.0, 1.0, 5.0], forward=[0.0, 0.0, -1.0], up=[0.0, 1.0, 0.0],
                fov_y=1.0, aspect=16 / 9, near=0.1, far=200.0)
    base.update(kw)
    return Camera(**base)


def snapshot(s) -> dict[str, object]:
    """Copies of everything validation must leave alone: every store column, is_new, every
    registered ``objects.state`` array (with its fill), versions, frame_index and config."""
    snap: dict[str, object] = {}
    for f in LIGHT_FIELDS:
        snap[f"lights.{f}"] = np.array(getattr(s.lights, f), copy=True)
    for f in OBJECT_FIELDS:
        snap[f"objects.{f}"] = np.array(getattr(s.objects, f), copy=True)
    snap["objects.is_new"] = np.array(s.objects.is_new, copy=True)
    for name, (arr, fill) in s.objects.state.items():
        snap[f"objects.state.{name}"] = np.array(arr, copy=True)
        snap[f"objects.state.{name}.fill"] = fill
    snap["lights.version"] = s.lights.version
    snap["objects.version"] = s.objects.version
    snap["frame_index"] = s.frame_index
    snap["config"] = s.config.to_dict()
    return snap


def assert_same(a: dict[str, object], b: dict[str, object]) -> None:
    assert a.keys() == b.keys()
    for k in a:
        x, y = a[k], b[k]
        if isinstance(x, np.ndarray):
            assert isinstance(y, np.ndarray), k
            assert x.dtype == y.dtype and x.shape == y.shape, k
            assert np.array_equal(x, y, equal_nan=x.dtype.kind == "f"), k
        else:
            assert x == y, k


def rejects(s, call, field: str, index: int | None, *args, **kwargs) -> ValidationError:
    """``call(*args, **kwargs)`` raises ValidationError(field, index); s is unchanged."""
    before = snapshot(s)
    with pytest.raises(ValidationError) as info:
        call(*args, **kwargs)
    err = info.value
    assert (err.field, err.index) == (field, index), str(err)
    assert_same(before, snapshot(s))
    return err


@pytest.fixture(params=SCHEDULERS, ids=SCHEDULER_IDS)
def sched_cls(request):
    return request.param


@pytest.fixture
def s(sched_cls):
    """A scheduler holding the base lights and objects, with a registered state array
    holding non-fill values (so a half-applied call would show)."""
    sch = sched_cls(Config())
    sch.set_lights(**light_kwargs())
    sch.set_objects(**object_kwargs())
    sch.objects.add_state("slots", (3,), np.int32, STATE_FILL)
    sch.objects.put("slots", np.arange(N_O * 3, dtype=np.int32).reshape(N_O, 3))
    sch.objects.is_new[:] = False  # as after a frame
    return sch


# --------------------------------------------------------------------------- non-finite


LIGHT_FLOAT_FIELDS = ["position", "radius", "direction", "outer_angle", "inner_angle",
                      "intensity", "priority"]


def corrupt(kw: dict, field: str, row: int, value) -> None:
    """Puts value into row (component 1 of a vector field) of a float field."""
    a = np.array(kw[field], dtype=np.float64, copy=True)
    if a.ndim == 2:
        a[row, 1] = value
    else:
        a[row] = value
    kw[field] = a


@pytest.mark.parametrize("bad", BAD_FLOATS, ids=["nan", "inf", "-inf"])
@pytest.mark.parametrize("row", [POINT_ROWS[1], SPOT_ROWS[1], DIR_ROWS[0]],
                         ids=["point", "spot", "directional"])
@pytest.mark.parametrize("field", LIGHT_FLOAT_FIELDS)
def test_light_nonfinite_rejected_in_every_row_type(s, field, row, bad):
    kw = light_kwargs()
    corrupt(kw, field, row, bad)
    corrupt(kw, field, row + 2, bad)  # a later bad row is not the one named
    rejects(s, s.set_lights, field, row, **kw)


@pytest.mark.parametrize("bad", BAD_FLOATS, ids=["nan", "inf", "-inf"])
@pytest.mark.parametrize("field", LIGHT_FLOAT_FIELDS)
def test_light_update_nonfinite_rejected(s, field, bad):
    ids = [9, 40, 1]  # point, point, directional rows, store order differs from call order
    kw = {field: light_kwargs()[field][[LIGHT_IDS.index(i) for i in ids]]}
    corrupt(kw, field, 1, bad)
    rejects(s, s.update_lights, field, 1, id=ids, **kw)


@pytest.mark.parametrize("bad", BAD_FLOATS, ids=["nan", "inf", "-inf"])
@pytest.mark.parametrize("field", ["bounds_min", "bounds_max"])
def test_object_nonfinite_rejected(s, field, bad):
    kw = object_kwargs()
    corrupt(kw, field, 3, bad)
    corrupt(kw, field, 4, bad)
    rejects(s, s.set_objects, field, 3, **kw)
    rejects(s, s.update_objects, field, 1, id=[0, 5],
            **{field: np.array([[0.0, 0.0, 0.0], [bad, 0.0, 0.0]])})


@pytest.mark.parametrize("bad", BAD_FLOATS, ids=["nan", "inf", "-inf"])
@pytest.mark.parametrize("field, value", [
    ("position", lambda b: [0.0, b, 0.0]),
    ("forward", lambda b: [0.0, 0.0, b]),
    ("up", lambda b: [b, 1.0, 0.0]),
    ("fov_y", lambda b: b),
    ("aspect", lambda b: b),
    ("near", lambda b: b),
    ("far", lambda b: b),
    ("focus", lambda b: [b, 0.0]),
    ("height_px", lambda b: b),
])
def test_camera_nonfinite_rejected(s, field, value, bad):
    cams = [camera(id=0), camera(id=1, **{field: value(bad)}), camera(id=2, **{field: value(bad)})]
    rejects(s, s.frame, f"cameras.{field}", 1, cams, dt=1 / 60)


@pytest.mark.parametrize("dt", [-1e-9, -1.0, NAN, INF, -INF, "fast", None])
def test_bad_dt_rejected(s, dt):
    rejects(s, s.frame, "dt", None, [camera()], dt=dt)


@pytest.mark.parametrize("cut", ["yes", None, 1.0])
def test_bad_cut_rejected(s, cut):
    rejects(s, s.frame, "cut", None, [camera()], dt=0.0, cut=cut)


# --------------------------------------------------------------------------- light rules


@pytest.mark.parametrize("r", [0.0, -0.0, -1.0, -1e-300])
@pytest.mark.parametrize("row", [POINT_ROWS[1], SPOT_ROWS[1]], ids=["point", "spot"])
def test_radius_must_be_positive_on_point_and_spot(s, row, r):
    kw = light_kwargs()
    kw["radius"][row] = r
    kw["radius"][row + 3] = r
    rejects(s, s.set_lights, "radius", row, **kw)


def test_radius_zero_or_negative_fine_on_directional(s):
    kw = light_kwargs()
    kw["radius"][DIR_ROWS] = [0.0, -3.0]
    s.set_lights(**kw)
    assert s.lights.radius[np.searchsorted(s.lights.id, LIGHT_IDS[DIR_ROWS[0]])] == 0.0


def test_directional_needs_no_position_or_radius(sched_cls):
    sch = sched_cls()
    sch.set_lights(id=[4, 2], type=[2, 2], direction=[[0, -1, 0], [1, 0, 0]])
    assert sch.lights.id.tolist() == [2, 4]
    np.testing.assert_array_equal(sch.lights.direction, [[1, 0, 0], [0, -1, 0]])


@pytest.mark.parametrize("ids, index", [
    ([40, 3, 17, 3, 25, 1, 9, 30], 3),
    ([40, 3, 17, 8, 25, 1, 9, 40], 7),
    ([40, 3, 17, 8, 8, 1, 3, 30], 4),  # two repeats: the first repeating row
    ([5, 5, 5, 5, 5, 5, 5, 5], 1),
])
def test_duplicate_light_ids(s, ids, index):
    kw = light_kwargs()
    kw["id"] = np.array(ids)
    rejects(s, s.set_lights, "id", index, **kw)


def test_duplicate_object_ids(s):
    kw = object_kwargs()
    kw["id"] = np.array([12, 5, 7, 100, 7, 12])
    rejects(s, s.set_objects, "id", 4, **kw)


@pytest.mark.parametrize("bad", [-1, -(2**31), 2**31, 2**32, 2**40])
def test_ids_must_be_nonnegative_int32(s, bad):
    kw = light_kwargs()
    kw["id"] = np.array(LIGHT_IDS, np.int64)
    kw["id"][2] = bad
    kw["id"][5] = bad
    rejects(s, s.set_lights, "id", 2, **kw)
    okw = object_kwargs()
    okw["id"][1] = bad
    rejects(s, s.set_objects, "id", 1, **okw)
    rejects(s, s.update_lights, "id", 1, id=[3, bad])
    rejects(s, s.remove_objects, "id", 0, id=[bad])


@pytest.mark.parametrize("bad", [1.5, NAN, True])
def test_ids_must_be_integers(s, bad):
    ids = [1.0, bad, 2.0] if not isinstance(bad, bool) else [True, False, True]
    index = 1 if not isinstance(bad, bool) else 0
    rejects(s, s.set_objects, "id", index, id=ids, bounds_min=np.zeros((3, 3)),
            bounds_max=np.ones((3, 3)))


@pytest.mark.parametrize("span", [3, 1000], ids=["dense ids", "sparse ids"])
def test_large_updates_find_the_same_rows_and_errors_as_small_ones(sched_cls, span):
    """An update finds its rows through an id -> row table kept until the ids change
    (scene._bulk_rows; sparse ids fall back to binary search), its repeated ids by marking
    rows (many) or sorting them (few): the same stored rows whether sent at once or 63 at
    a time, and for bad ids the same error (the duplicate check comes before the
    unknown-id check in either)."""
    rng = np.random.default_rng(5)
    n = 4000
    ids = rng.permutation(span * n)[:n]
    lights = dict(id=ids, position=rng.uniform(-50, 50, (n, 3)), radius=np.ones(n))
    bulk, chunked = sched_cls(), sched_cls()
    for sch in (bulk, chunked):
        sch.set_lights(**lights)
    order = rng.permutation(n)
    moved = rng.uniform(-50, 50, (n, 3))
    bulk.update_lights(id=ids[order], position=moved)
    for part in np.array_split(np.arange(n), 64):  # 63 rows a call: binary search
        chunked.update_lights(id=ids[order][part], position=moved[part])
    for f in LIGHT_FIELDS:
        assert np.array_equal(getattr(bulk.lights, f), getattr(chunked.lights, f)), f
    assert np.array_equal(bulk.lights.position[np.searchsorted(bulk.lights.id, ids[order])],
                          moved)
    bulk.update_lights(id=ids[order], radius=np.full(n, 2.0))  # the table, kept, again
    assert (bulk.lights.radius == 2.0).all()
    unknown = int(ids.max()) + 1
    dup = ids[order].copy()
    dup[3000] = dup[10]
    rejects(bulk, bulk.update_lights, "id", 3000, id=dup, radius=np.ones(n))
    bad = ids[order].copy()
    bad[2000] = unknown
    rejects(bulk, bulk.update_lights, "id", 2000, id=bad, radius=np.ones(n))
    bad[3000] = bad[10]  # an unknown id and a repeat: the repeat is named
    rejects(bulk, bulk.update_lights, "id", 3000, id=bad, radius=np.ones(n))
    bad = ids[order].copy()
    bad[1500] = -1
    rejects(bulk, bulk.remove_lights, "id", 1500, id=bad)
    bulk.remove_lights(id=ids[order][: n // 2])  # new ids: the table is made again
    rest = np.sort(ids[order][n // 2:])
    assert np.array_equal(bulk.lights.id, rest)
    bulk.update_lights(id=rest[::-1], radius=np.full(rest.size, 3.0))
    assert (bulk.lights.radius == 3.0).all()


UPDATE_LIGHT_FIELDS = ("position", "radius", "direction", "angles", "intensity", "priority",
                      "shadows", "mask")


@settings(max_examples=60, deadline=None)
@given(n=st.integers(1, 40), rows_kind=st.sampled_from(["every, in order", "every, permuted",
                                                        "some"]),
       fields=st.sets(st.sampled_from(UPDATE_LIGHT_FIELDS), min_size=1),
       fortran=st.booleans(), seed=st.integers(0, 2**16))
def test_updates_write_the_given_rows_and_nothing_else(n, rows_kind, fields, fortran, seed):
    """update_lights and update_objects through each way of writing (every row in row
    order: the validated columns become the store's; otherwise a copy with the rows put
    in, 2-D rows moved as one item each): the given rows hold the given values (as
    validation defines them: cast, directions normalised), the other rows and fields keep
    their bits, the arrays the last frame held are untouched (copy on write), and the
    store's arrays stay C-contiguous, of their dtype, and none is the caller's array."""
    rng = np.random.default_rng(seed)
    ids = rng.permutation(3 * n)[:n]
    s = ls.Scheduler()
    s.set_lights(id=ids, type=rng.integers(0, 3, n), position=rng.uniform(-50, 50, (n, 3)),
                 radius=rng.uniform(1, 9, n), direction=rng.uniform(0.5, 1.0, (n, 3)),
                 intensity=rng.uniform(0, 4, n), shadows=rng.random(n) < 0.5,
                 mask=rng.integers(0, 2**32, n))
    lo = rng.uniform(-50, 50, (n, 3))
    s.set_objects(id=ids, bounds_min=lo, bounds_max=lo + 1.0, mask=rng.integers(0, 2**32, n))
    if rows_kind == "every, in order":
        rows = np.arange(n)
    elif rows_kind == "every, permuted":
        rows = rng.permutation(n)
    else:
        rows = rng.permutation(n)[:rng.integers(1, n + 1)]
    m = rows.size
    given: dict[str, np.ndarray] = {}
    if "position" in fields:
        given["position"] = rng.uniform(-50, 50, (m, 3))
    if "radius" in fields:
        given["radius"] = rng.uniform(1, 9, m)
    if "direction" in fields:
        given["direction"] = rng.uniform(0.5, 1.0, (m, 3))
    if "angles" in fields:
        given["outer_angle"] = rng.uniform(0.2, 1.5, m)
        given["inner_angle"] = given["outer_angle"] * 0.5
    if "intensity" in fields:
        given["intensity"] = rng.uniform(0, 4, m)
    if "priority" in fields:
        given["priority"] = rng.uniform(-1, 1, m).astype(np.float32)
    if "shadows" in fields:
        given["shadows"] = rng.integers(0, 2, m)
    if "mask" in fields:
        given["mask"] = rng.integers(0, 2**32, m, dtype=np.uint64)
    if fortran:
        given = {k: np.asfortranarray(v) for k, v in given.items()}
    sent = {k: v.copy() for k, v in given.items()}
    row_of = np.searchsorted(s.lights.id, ids[rows])
    for store, call, kw in (
            (s.lights, s.update_lights, given),
            (s.objects, s.update_objects,
             {"bounds_min": lo[rows] - 2.0, "bounds_max": lo[rows] + 3.0,
              "static": rng.random(m) < 0.5, "mask": rng.integers(0, 2**32, m)})):
        names = LIGHT_FIELDS if store is s.lights else OBJECT_FIELDS
        held = {f: getattr(store, f) for f in names}
        kept = {f: a.copy() for f, a in held.items()}
        call(id=ids[rows], **kw)
        for f in names:
            now, old = getattr(store, f), kept[f]
            assert np.array_equal(held[f], old), f"{f}: last frame's array was written"
            assert now.dtype == old.dtype and now.shape == old.shape, f
            assert now.flags.c_contiguous, f
            assert not any(np.shares_memory(now, v) for v in kw.values()), f
            want = old.copy()
            if f in kw:
                value = np.asarray(kw[f])
                if f == "direction":
                    value = value / np.sqrt((value * value).sum(axis=1))[:, None]
                want[row_of] = value
            assert np.array_equal(now, want), f
        assert np.array_equal(store.touched[-1], row_of)
    for k, v in sent.items():
        assert np.array_equal(given[k], v), f"the caller's {k} was written"


def test_max_int32_id_is_fine(sched_cls):
    sch = sched_cls()
    sch.set_lights(id=[INT32_MAX, 0], position=np.zeros((2, 3)), radius=[1, 1])
    assert sch.lights.id.dtype == np.int32
    assert sch.lights.id.tolist() == [0, INT32_MAX]


def test_bounds_min_above_max(s):
    kw = object_kwargs()
    kw["bounds_min"][2, 1] = kw["bounds_max"][2, 1] + 1e-9
    kw["bounds_min"][4] = kw["bounds_max"][4] + 1.0
    rejects(s, s.set_objects, "bounds_min", 2, **kw)


def test_bounds_update_crossing_stored_bounds(s):
    hi = s.objects.bounds_max[np.searchsorted(s.objects.id, 7)]
    rejects(s, s.update_objects, "bounds_min", 1, id=[0, 7],
            bounds_min=np.array([[-1e9] * 3, hi + 1.0]))
    rejects(s, s.update_objects, "bounds_min", 0, id=[7],
            bounds_max=np.array([hi - 1e6]))


def test_zero_extent_object_is_fine(sched_cls):
    sch = sched_cls()
    sch.set_objects(id=[1], bounds_min=[[1.0, 2.0, 3.0]], bounds_max=[[1.0, 2.0, 3.0]])
    assert len(sch.objects) == 1


@pytest.mark.parametrize("d", [[0.0, 0.0, 0.0], [-0.0, 0.0, -0.0], [1e-200, 0.0, 0.0],
                               [1e200, 1e200, 0.0]],
                         ids=["zero", "negzero", "underflow", "overflow"])
@pytest.mark.parametrize("row", [SPOT_ROWS[1], DIR_ROWS[0]], ids=["spot", "directional"])
def test_zero_length_direction_on_spot_and_directional(s, row, d):
    kw = light_kwargs()
    kw["direction"][row] = d
    kw["direction"][7] = d
    rejects(s, s.set_lights, "direction", row, **kw)


@pytest.mark.parametrize("d", [[0.0, 0.0, 0.0], [1e-200, 0.0, 0.0], [1e200, 1e200, 0.0]],
                         ids=["zero", "underflow", "overflow"])
def test_unnormalisable_direction_fine_on_point_rows(s, d):
    kw = light_kwargs()
    kw["direction"][POINT_ROWS] = d
    s.set_lights(**kw)
    rows = np.searchsorted(s.lights.id, np.array(LIGHT_IDS)[SPOT_ROWS + DIR_ROWS])
    n = np.linalg.norm(s.lights.direction[rows], axis=1)
    np.testing.assert_allclose(n, 1.0, rtol=0, atol=1e-15)
    # ... but turning such a row into a spot needs a direction.
    rejects(s, s.update_lights, "direction", 1, id=[LIGHT_IDS[1], LIGHT_IDS[POINT_ROWS[2]]],
            type=[1, 1])


@pytest.mark.parametrize("t", [3, -1, 255, 256, 1.5])
def test_unknown_light_type(s, t):
    kw = light_kwargs()
    kw["type"] = np.array(LIGHT_TYPES, np.float64 if isinstance(t, float) else np.int64)
    kw["type"][4] = t
    kw["type"][6] = t
    rejects(s, s.set_lights, "type", 4, **kw)
    rejects(s, s.update_lights, "type", 1, id=[1, 3], type=[2, t])


@pytest.mark.parametrize("o", [0.0, -0.1, math.pi / 2, 2.0, math.pi])
def test_outer_angle_range_on_spot_rows(s, o):
    kw = light_kwargs()
    kw["outer_angle"][SPOT_ROWS[1]] = o
    kw["outer_angle"][SPOT_ROWS[2]] = o
    kw["inner_angle"][:] = 0.0
    rejects(s, s.set_lights, "outer_angle", SPOT_ROWS[1], **kw)


def test_angles_ignored_on_non_spot_rows(s):
    kw = light_kwargs()
    kw["outer_angle"][POINT_ROWS + DIR_ROWS] = 3.0
    kw["inner_angle"][POINT_ROWS + DIR_ROWS] = -5.0
    s.set_lights(**kw)
    assert len(s.lights) == N_L


@pytest.mark.parametrize("inner", [-1e-12, -0.5, 0.6 + 1e-12, 1.0])
def test_inner_angle_range_on_spot_rows(s, inner):
    kw = light_kwargs()  # outer 0.6
    kw["inner_angle"][SPOT_ROWS[1]] = inner
    kw["inner_angle"][SPOT_ROWS[2]] = inner
    rejects(s, s.set_lights, "inner_angle", SPOT_ROWS[1], **kw)


def test_inner_angle_bounds_inclusive(s):
    kw = light_kwargs()
    kw["inner_angle"][SPOT_ROWS[0]] = 0.0
    kw["inner_angle"][SPOT_ROWS[1]] = 0.6
    s.set_lights(**kw)


def test_default_inner_checked_against_explicit_outer(s):
    # inner defaults to 0.8 * outer row by row, so it is always in range.
    kw = light_kwargs()
    del kw["inner_angle"]
    kw["outer_angle"] = np.linspace(0.1, 1.5, N_L)
    s.set_lights(**kw)
    np.testing.assert_array_equal(s.lights.inner_angle,
                                  0.8 * s.lights.outer_angle)


@pytest.mark.parametrize("i", [-1e-300, -1.0])
@pytest.mark.parametrize("row", [POINT_ROWS[0], SPOT_ROWS[0], DIR_ROWS[0]])
def test_negative_intensity(s, row, i):
    kw = light_kwargs()
    kw["intensity"][row] = i
    kw["intensity"][-1] = i
    rejects(s, s.set_lights, "intensity", row, **kw)


def test_zero_intensity_and_any_priority_fine(s):
    kw = light_kwargs()
    kw["intensity"][:] = 0.0
    kw["priority"][:] = [-1e300, 1e300, 0, -1, 1, 0, 0, 5]
    s.set_lights(**kw)


@pytest.mark.parametrize("bad", [-1, 2**32, 2**40, 2**64, 1.5, -0.5, NAN, INF, 1e300],
                         ids=lambda v: repr(v))
def test_mask_range(s, bad):
    masks = [1, 2, UINT32_ALL, bad, 5, bad, 7, 8]
    kw = light_kwargs()
    kw["mask"] = masks  # a Python list: 2**64 makes numpy pick dtype object
    rejects(s, s.set_lights, "mask", 3, **kw)
    okw = object_kwargs()
    okw["mask"] = masks[:N_O]
    rejects(s, s.set_objects, "mask", 3, **okw)
    rejects(s, s.update_objects, "mask", 1, id=[5, 12], mask=[0, bad])


@pytest.mark.parametrize("bad", [2, -1, 0.5, NAN])
@pytest.mark.parametrize("field", ["shadows"])
def test_light_bool_fields(s, field, bad):
    kw = light_kwargs()
    kw[field] = np.array([0, 1, 1, 0, 0, bad, 0, bad], dtype=type(bad))
    rejects(s, s.set_lights, field, 5, **kw)


@pytest.mark.parametrize("field", ["casts_shadows", "static"])
def test_object_bool_fields(s, field):
    kw = object_kwargs()
    kw[field] = np.array([0, 1, 3, 1, 0, 1])
    rejects(s, s.set_objects, field, 2, **kw)


@pytest.mark.parametrize("junk", [None, "x", object()], ids=["None", "str", "object"])
@pytest.mark.parametrize("field", ["id", "type", "position", "radius", "direction", "mask"])
def test_non_numeric_values(s, field, junk):
    kw = light_kwargs()
    a = np.array(kw[field], dtype=object)
    if a.ndim == 2:
        a[2, 1] = junk
        a[5, 0] = junk
    else:
        a[2] = junk
        a[5] = junk
    kw[field] = a
    rejects(s, s.set_lights, field, 2, **kw)


# --------------------------------------------------------------------------- shapes


@pytest.mark.parametrize("field, value, index", [
    # 2-D where 1-D expected
    ("radius", np.ones((N_L, 1)), None),
    ("intensity", np.ones((1, N_L)), None),
    ("type", np.zeros((N_L, 2), np.int64), None),
    ("mask", np.ones((N_L, 1), np.int64), None),
    # wrong width / rank for vectors
    ("position", np.zeros((N_L, 2)), None),
    ("position", np.zeros((N_L, 4)), None),
    ("position", np.zeros(N_L * 3), None),
    ("direction", np.zeros((N_L, 3, 1)), None),
    # length mismatch with id: index is the first missing or extra row
    ("radius", np.ones(N_L - 1), N_L - 1),
    ("radius", np.ones(N_L + 2), N_L),
    ("position", np.zeros((N_L + 1, 3)), N_L),
    ("direction", np.ones((0, 3)), 0),
    # scalars and single rows are never broadcast
    ("radius", 1.0, None),
    ("intensity", np.float64(1.0), None),
    ("type", 0, None),
    ("shadows", True, None),
    ("mask", UINT32_ALL, None),
    ("position", [0.0, 0.0, 0.0], None),
    ("position", np.zeros((1, 3)), 1),
    ("radius", [1.0], 1),
])
def test_light_wrong_shapes(s, field, value, index):
    kw = light_kwargs()
    kw[field] = value
    rejects(s, s.set_lights, field, index, **kw)


@pytest.mark.parametrize("value", [5, np.int64(5), [[1, 2]], np.zeros((2, 2), np.int64)])
def test_id_scalar_or_2d(s, value):
    rejects(s, s.set_lights, "id", None, id=value, position=np.zeros((1, 3)), radius=[1.0])
    rejects(s, s.update_lights, "id", None, id=value, radius=[1.0])
    rejects(s, s.remove_objects, "id", None, id=value)


@pytest.mark.parametrize("field, value, index", [
    ("bounds_min", np.zeros((N_O, 2)), None),
    ("bounds_max", np.zeros(N_O * 3), None),
    ("bounds_min", np.zeros(3), None),
    ("bounds_max", np.zeros((N_O - 1, 3)), N_O - 1),
    ("static", False, None),
    ("mask", np.ones((N_O, 1), np.int64), None),
    ("casts_shadows", np.ones(N_O + 1, bool), N_O),
])
def test_object_wrong_shapes(s, field, value, index):
    kw = object_kwargs()
    kw[field] = value
    rejects(s, s.set_objects, field, index, **kw)


def test_update_length_must_match_update_ids(s):
    rejects(s, s.update_lights, "radius", 2, id=[1, 3, 8], radius=[1.0, 2.0])
    rejects(s, s.update_objects, "bounds_min", None, id=[0, 5], bounds_min=[0.0, 0.0, 0.0])


# --------------------------------------------------------------------------- missing fields


def test_missing_required_light_fields(s):
    kw = light_kwargs()
    del kw["position"]
    rejects(s, s.set_lights, "position", POINT_ROWS[0], **kw)
    kw = light_kwargs()
    kw["type"][0] = 2
    del kw["radius"]
    rejects(s, s.set_lights, "radius", 1, **kw)
    kw = light_kwargs()
    del kw["direction"]
    rejects(s, s.set_lights, "direction", SPOT_ROWS[0], **kw)
    kw = light_kwargs()
    kw["type"][:] = 0
    kw["type"][5] = 2
    del kw["direction"]
    rejects(s, s.set_lights, "direction", 5, **kw)
    kw = light_kwargs()
    del kw["id"]
    rejects(s, s.set_lights, "id", None, **kw)
    kw = light_kwargs()
    kw["position"] = None  # None means "not given"
    rejects(s, s.set_lights, "position", POINT_ROWS[0], **kw)


def test_point_only_set_needs_no_direction(sched_cls):
    sch = sched_cls()
    sch.set_lights(id=[1, 2], position=np.zeros((2, 3)), radius=[1.0, 2.0])
    assert sch.lights.type.tolist() == [0, 0]


@pytest.mark.parametrize("missing", ["bounds_min", "bounds_max", "id"])
def test_missing_required_object_fields(s, missing):
    kw = object_kwargs()
    del kw[missing]
    rejects(s, s.set_objects, missing, None, **kw)


def test_update_and_remove_need_ids(s):
    rejects(s, s.update_lights, "id", None, radius=[1.0])
    rejects(s, s.update_objects, "id", None, static=[True])
    rejects(s, s.remove_lights, "id", None, id=None)


def test_unknown_keyword_fields(s):
    kw = light_kwargs()
    kw["colour"] = np.ones(N_L)
    rejects(s, s.set_lights, "colour", None, **kw)
    okw = object_kwargs()
    okw["bounds"] = np.ones(N_O)
    rejects(s, s.set_objects, "bounds", None, **okw)
    rejects(s, s.update_lights, "radii", None, id=[1], radii=[2.0])
    rejects(s, s.update_objects, "visible", None, id=[5], visible=[True])


# --------------------------------------------------------------------------- field order


@pytest.mark.parametrize("mods, expected", [
    ({"radius": (5, NAN), "position": (7, NAN)}, ("position", 7)),
    ({"radius": (5, 0.0), "position": (7, INF)}, ("position", 7)),
    ({"type": (0, 3), "id": (7, 40)}, ("id", 7)),
    ({"position": (0, NAN), "type": (6, 9)}, ("type", 6)),
    ({"direction": (1, 0.0), "radius": (6, -1.0)}, ("radius", 6)),
    ({"outer_angle": (7, 2.0), "direction": (7, NAN)}, ("direction", 7)),
    ({"inner_angle": (1, -1.0), "outer_angle": (4, 0.0)}, ("outer_angle", 4)),
    ({"intensity": (0, -1.0), "inner_angle": (7, 1.0)}, ("inner_angle", 7)),
    ({"priority": (0, NAN), "intensity": (6, -1.0)}, ("intensity", 6)),
    ({"mask": (0, -1), "priority": (3, INF)}, ("priority", 3)),
    ({"mask": (0, -1), "shadows": (2, 5)}, ("shadows", 2)),
])
def test_light_field_order(s, mods, expected):
    kw = light_kwargs()
    for field, (row, value) in mods.items():
        if field == "direction":
            kw[field][row] = value
        else:
            a = np.array(kw[field], dtype=np.float64 if field not in ("id", "type", "mask")
                         else np.int64)
            if a.ndim == 2:
                a[row, 0] = value
            else:
                a[row] = value
            kw[field] = a
    rejects(s, s.set_lights, *expected, **kw)


def test_object_field_order(s):
    kw = object_kwargs()
    kw["bounds_max"][1, 0] = NAN
    kw["bounds_min"][4, 2] = INF
    rejects(s, s.set_objects, "bounds_min", 4, **kw)
    kw = object_kwargs()
    kw["mask"] = [0, 0, 0, 0, 0, -1]
    kw["bounds_min"][3] = kw["bounds_max"][3] + 1.0
    rejects(s, s.set_objects, "bounds_min", 3, **kw)
    kw = object_kwargs()
    kw["static"] = [0, 2, 0, 0, 0, 0]
    kw["mask"] = [0, 0, 0, 0, -1, 0]
    kw["casts_shadows"] = [0, 0, 0, 0, 0, 7]
    rejects(s, s.set_objects, "casts_shadows", 5, **kw)


def test_camera_field_order_within_a_camera(s):
    rejects(s, s.frame, "cameras.fov_y", 0, [camera(fov_y=0.0, height_px=NAN)])
    rejects(s, s.frame, "cameras.near", 0, [camera(near=-1.0, far=NAN)])
    rejects(s, s.frame, "cameras.aspect", 0, [camera(aspect=0.0, focus=[2.0, 0.0])])
    rejects(s, s.frame, "cameras.position", 0,
            [camera(position=[NAN, 0, 0], forward=[0, 0, 0], fov_y=NAN)])
    rejects(s, s.frame, "cameras.forward", 0, [camera(forward=[0, 0, 0], up=[0, 0, 0])])


# --------------------------------------------------------------------------- update/remove


@pytest.mark.parametrize("method", ["update_lights", "remove_lights"])
def test_light_update_remove_unknown_and_duplicate_ids(s, method):
    call = getattr(s, method)
    extra = {"intensity": [1.0, 2.0, 3.0]} if method == "update_lights" else {}
    rejects(s, call, "id", 1, id=[3, 4, 41], **extra)
    rejects(s, call, "id", 2, id=[3, 40, 3], **extra)
    rejects(s, call, "id", 0, id=[-1, 40, 3], **extra)


@pytest.mark.parametrize("method", ["update_objects", "remove_objects"])
def test_object_update_remove_unknown_and_duplicate_ids(s, method):
    call = getattr(s, method)
    extra = {"static": [True, False, True]} if method == "update_objects" else {}
    rejects(s, call, "id", 2, id=[0, 100, 101], **extra)
    rejects(s, call, "id", 1, id=[33, 33, 12], **extra)


def test_update_remove_on_empty_scheduler(sched_cls):
    sch = sched_cls()
    rejects(sch, sch.update_lights, "id", 0, id=[0], radius=[1.0])
    rejects(sch, sch.remove_lights, "id", 0, id=[0])
    rejects(sch, sch.remove_objects, "id", 0, id=[0])
    sch.remove_lights(id=[])  # nothing to remove is fine


def test_update_that_makes_a_row_invalid(s):
    point_ids = [LIGHT_IDS[r] for r in POINT_ROWS]
    spot_ids = [LIGHT_IDS[r] for r in SPOT_ROWS]
    # point -> spot without a direction: the stored direction is that of a point row
    sch = type(s)()
    sch.set_lights(id=[1, 2], position=np.zeros((2, 3)), radius=[1.0, 1.0])
    rejects(sch, sch.update_lights, "direction", 1, id=[1, 2], type=[0, 1])
    rejects(sch, sch.update_lights, "direction", 0, id=[2], type=[2])
    # directional -> point without a radius (directional rows may have radius 0)
    sch.set_lights(id=[1, 2], type=[0, 2], position=np.zeros((2, 3)), radius=[1.0, 0.0],
                   direction=[[0, 0, 0], [0, 0, 1]])
    rejects(sch, sch.update_lights, "radius", 0, id=[2], type=[0])
    # outer shrinks below the stored inner of a spot
    rejects(s, s.update_lights, "inner_angle", 1, id=[spot_ids[0], spot_ids[1]],
            outer_angle=[0.6, 0.3])
    # radius 0 on a point row, negative intensity, zero direction on a spot
    rejects(s, s.update_lights, "radius", 0, id=[point_ids[2]], radius=[0.0])
    rejects(s, s.update_lights, "intensity", 1, id=point_ids[:2], intensity=[1.0, -2.0])
    rejects(s, s.update_lights, "direction", 0, id=[spot_ids[2]], direction=[[0, 0, 0]])
    # a spot turned point may drop its direction
    s.update_lights(id=[spot_ids[0]], type=[0], direction=[[0, 0, 0]])


# --------------------------------------------------------------------------- Config


@pytest.mark.parametrize("kwargs, field", [
    ({"max_lights": 0}, "max_lights"),
    ({"max_lights": 33}, "max_lights"),
    ({"max_lights": -1}, "max_lights"),
    ({"max_lights": 8.5}, "max_lights"),
    ({"max_lights": None}, "max_lights"),
    ({"max_lights": True}, "max_lights"),
    ({"shadow_budget": -1}, "shadow_budget"),
    ({"shadow_budget": 128}, "shadow_budget"),
    ({"max_shadowed_per_object": 9}, "max_shadowed_per_object"),
    ({"max_lights": 4, "max_shadowed_per_object": 5}, "max_shadowed_per_object"),
    ({"max_shadowed_per_object": -1}, "max_shadowed_per_object"),
    ({"hysteresis": -0.01}, "hysteresis"),
    ({"hysteresis": NAN}, "hysteresis"),
    ({"hysteresis_abs": -1.0}, "hysteresis_abs"),
    ({"hysteresis_abs": INF}, "hysteresis_abs"),
    ({"fade_in": -1e-9}, "fade_in"),
    ({"fade_out": -0.25}, "fade_out"),
    ({"fade_out": INF}, "fade_out"),
    ({"cascade_overlap": -0.1}, "cascade_overlap"),
    ({"c1": 0.0}, "c1"),
    ({"c1": -0.25}, "c1"),
    ({"c1": NAN}, "c1"),
    ({"cascades": 0}, "cascades"),
    ({"cascades": 5}, "cascades"),
    ({"shadow_distance": 0.0}, "shadow_distance"),
    ({"shadow_distance": -150.0}, "shadow_distance"),
    ({"shadow_distance": INF}, "shadow_distance"),
    ({"model": "Contribution"}, "model"),
    ({"model": "eriksson"}, "model"),
    ({"model": None}, "model"),
    ({"unshadowed": "drop"}, "unshadowed"),
    ({"unshadowed": ""}, "unshadowed"),
    ({"precision": "float32"}, "precision"),
    ({"precision": "FAST"}, "precision"),
    ({"w_ecc": NAN}, "w_ecc"),
    ({"w_dist": INF}, "w_dist"),
    ({"w_obj": "x"}, "w_obj"),
    ({"w_int": -INF}, "w_int"),
    ({"directional_in_slots": "yes"}, "directional_in_slots"),
    ({"residual": 1}, "residual"),
    ({"residual": "true"}, "residual"),
    ({"shadow_update_budget": -1}, "shadow_update_budget"),
    ({"shadow_update_budget": 2**31}, "shadow_update_budget"),
    ({"shadow_update_budget": 1.0}, "shadow_update_budget"),
    ({"shadow_atlas_size": 2048}, "shadow_atlas_size"),
    ({"shadow_atlas_size": 12288}, "shadow_atlas_size"),
    ({"shadow_atlas_size": 131072}, "shadow_atlas_size"),
    ({"shadow_atlas_size": True}, "shadow_atlas_size"),
    ({"caster_culling": "Light"}, "caster_culling"),
    ({"caster_culling": None}, "caster_culling"),
])
def test_config_ranges(kwargs, field):
    with pytest.raises(ValidationError) as info:
        Config(**kwargs)
    assert (info.value.field, info.value.index) == (field, None)


def test_config_defaults_and_edges():
    c = Config()
    assert c.to_dict() == {
        "max_lights": 8, "model": "contribution", "w_ecc": 1.0, "w_dist": -0.01,
        "w_obj": -0.1, "w_int": 0.1, "c1": 0.25, "hysteresis": 0.1, "hysteresis_abs": 0.0,
        "fade_in": 0.25, "fade_out": 0.25, "directional_in_slots": False, "shadow_budget": 4,
        "cascades": 4, "shadow_distance": 150.0, "cascade_overlap": 0.1,
        "max_shadowed_per_object": 2, "unshadowed": "light", "precision": "exact",
        "residual": True, "shadow_update_budget": 0, "shadow_atlas_size": 8192,
        "caster_culling": "camera"}
    assert Config(max_lights=1).max_shadowed_per_object == 1
    for k in (1, 32):
        Config(max_lights=k, max_shadowed_per_object=k)
    Config(max_lights=5, max_shadowed_per_object=0)
    for budget in (0, 127):
        Config(shadow_budget=budget)
    for c_ in (1, 4):
        Config(cascades=c_)
    Config(hysteresis=0.0, hysteresis_abs=0.0, fade_in=0.0, fade_out=0.0,
           cascade_overlap=0.0, c1=1e-300, shadow_distance=1e-300, model="thesis",
           unshadowed="skip", precision="fast", directional_in_slots=True,
           max_lights=np.int64(3), residual=np.False_)


def test_scheduler_rejects_non_config(sched_cls):
    with pytest.raises(ValidationError) as info:
        sched_cls({"max_lights": 8})
    assert info.value.field == "config"


# --------------------------------------------------------------------------- cameras


@pytest.mark.parametrize("count", [0, 9, 20])
def test_camera_count(s, count):
    rejects(s, s.frame, "cameras", None, [camera(id=i) for i in range(count)])


def test_cameras_not_a_list(s):
    rejects(s, s.frame, "cameras", None, 5)
    rejects(s, s.frame, "cameras", 1, [camera(), "camera"])


@pytest.mark.parametrize("field, value", [
    ("fov_y", 0.0), ("fov_y", math.pi), ("fov_y", -0.5), ("fov_y", 4.0),
    ("aspect", 0.0), ("aspect", -1.0),
    ("near", 0.0), ("near", -0.1),
    ("far", 0.1), ("far", 0.05), ("far", -1.0),
    ("up", [0.0, 0.0, -1.0]), ("up", [0.0, 0.0, 2.0]), ("up", [0.0, 0.0, -1e-30]),
    ("up", [0.0, 0.0, 0.0]), ("up", [1e-200, 0.0, 0.0]),
    ("forward", [0.0, 0.0, 0.0]), ("forward", [0.0, -0.0, 0.0]),
    ("forward", [1e-200, 0.0, 0.0]), ("forward", [1e200, 0.0, 1e200]),
    ("focus", [1.5, 0.0]), ("focus", [0.0, -1.0000001]), ("focus", [-2.0, 2.0]),
    ("focus", [0.0, 0.0, 0.0]), ("focus", 0.0),
    ("position", [0.0, 0.0]), ("position", 1.0), ("up", [[0.0, 1.0, 0.0]]),
    ("height_px", 0.0), ("height_px", -1080.0),
    ("id", -1), ("id", 2**31), ("id", 1.0), ("id", True),
    ("fov_y", "wide"), ("near", None),
])
def test_bad_camera_fields(s, field, value):
    cams = [camera(id=10), camera(id=11), camera(**{"id": 12, field: value})]
    rejects(s, s.frame, f"cameras.{field}", 2, cams, dt=1 / 60)


def test_duplicate_camera_ids(s):
    rejects(s, s.frame, "cameras.id", 2, [camera(id=3), camera(id=1), camera(id=3)])


def test_cameras_without_ids_take_their_position(sched_cls):
    """DESIGN section 1: a camera given without an id takes its position in the list (two
    of them are cameras 0 and 1, not a duplicate 0); explicit unique ids are kept."""
    from lightsched.scene import validate_cameras

    plain = {"position": [2.0, 1.0, 5.0], "forward": [0.0, 0.0, -1.0], "up": [0.0, 1.0, 0.0],
             "fov_y": 1.0, "aspect": 1.0, "near": 0.1, "far": 100.0}
    assert [c.id for c in validate_cameras([camera(), camera(), plain])] == [0, 1, 2]
    assert [c.id for c in validate_cameras([camera(id=7), camera(id=3)])] == [7, 3]
    assert [c.id for c in validate_cameras([camera(id=5), camera()])] == [5, 1]
    frames = []
    for cams in ([camera(), plain], [camera(id=0), {**plain, "id": 1}]):
        s = sched_cls(Config())
        s.set_lights(**light_kwargs())
        s.set_objects(**object_kwargs())
        frames.append(s.frame(cams))
    for name, a in frames[0].arrays().items():
        assert np.array_equal(a, getattr(frames[1], name)), name


def test_camera_without_id_must_not_take_a_given_id(s):
    """[id 1, no id]: the second camera's id would be 1 again, rejected naming cameras.id
    and index 1 (and likewise a given id after a camera that took it)."""
    err = rejects(s, s.frame, "cameras.id", 1, [camera(id=1), camera()])
    assert "without an id" in err.message
    rejects(s, s.frame, "cameras.id", 1, [camera(), camera(id=0)])


def test_transaction_puts_back_changes_and_a_frame_that_fails(monkeypatch):
    """SceneAPI.transaction (the service runs each frame request in one): a block that
    raises leaves the scene, the fade state written in place, the config and the frame
    index as before it, and the frames go on as those of a twin that never ran it."""
    from lightsched.scene import ObjectStore
    from lightsched.scenes import city, move_lights

    sc = city(300, 40, seed=1)
    a, twin = ls.Scheduler(Config(max_lights=4)), ls.Scheduler(Config(max_lights=4))
    for x in (a, twin):
        x.set_lights(**sc.lights)
        x.set_objects(**sc.objects)
        x.frame(sc.cameras, dt=0.05)
    ids = sc.lights["id"]
    with a.transaction():  # kept: no exception
        a.update_lights(id=ids, position=move_lights(sc.lights, 1))
        a.frame(sc.cameras, dt=0.05)
    twin.update_lights(id=ids, position=move_lights(sc.lights, 1))
    twin.frame(sc.cameras, dt=0.05)
    before = snapshot(a)
    put, wrote = ObjectStore.put, []

    def broken_put(store, name, value):
        monkeypatch.setattr(ObjectStore, "put", put)  # once: after the object pass
        wrote.append(not np.array_equal(store.get("slot_weight"),
                                        before["objects.state.slot_weight"]))
        raise RuntimeError("injected fault")

    monkeypatch.setattr(ObjectStore, "put", broken_put)
    with pytest.raises(RuntimeError, match="injected"), a.transaction():
        a.update_lights(id=ids, position=move_lights(sc.lights, 2))
        a.frame(sc.cameras, dt=0.05)
    assert wrote == [True]  # the fade weights were written in place, then put back
    assert_same(before, snapshot(a))
    for x in (a, twin):
        x.update_lights(id=ids, position=move_lights(sc.lights, 3))
    got, want = a.frame(sc.cameras, dt=0.05), twin.frame(sc.cameras, dt=0.05)
    for name, arr in got.arrays().items():
        assert np.array_equal(arr, getattr(want, name)), name


@pytest.mark.parametrize("cls", [ls.Scheduler, reference.Scheduler],
                         ids=["fast", "oracle"])
def test_transaction_that_fails_after_its_frame_puts_back_the_frame_state(cls):
    """A block that raises after its frame returned: what the scheduler keeps beside the
    stores (the fast one's last-frame cache and shadowed set, the oracle's fade state by
    id and shadowed set) goes back too, so the frames after it are those of a twin that
    never ran the block (here the block's frame shadowed two other lights, which the
    ranking's hysteresis would otherwise keep)."""
    from lightsched.scenes import city, move_lights

    sc = city(300, 40, seed=2, shadow_fraction=0.5)
    cfg = Config(max_lights=3, fade_in=0.2, fade_out=0.2, shadow_budget=2, hysteresis=1.0)
    a, twin = cls(cfg), cls(cfg)
    ids = sc.lights["id"]
    for x in (a, twin):
        x.set_lights(**sc.lights)
        x.set_objects(**sc.objects)
        first = x.frame(sc.cameras, dt=0.05)
    others = np.setdiff1d(ids[sc.lights["shadows"]], first.shadow_lights)
    with pytest.raises(RuntimeError, match="after the frame"), a.transaction():
        a.update_lights(id=others, intensity=np.full(others.size, 1e4))
        undone = a.frame(sc.cameras, dt=0.05)
        raise RuntimeError("after the frame")
    assert not np.array_equal(undone.shadow_lights, first.shadow_lights)
    for i in (1, 2, 3):
        for x in (a, twin):
            x.update_lights(id=ids, position=move_lights(sc.lights, i))
        got, want = a.frame(sc.cameras, dt=0.05), twin.frame(sc.cameras, dt=0.05)
        for name, arr in got.arrays().items():
            assert np.array_equal(arr, getattr(want, name)), (i, name)


def test_camera_mappings(s):
    good = dict(position=[0, 0, 0], forward=[0, 0, -1], up=[0, 1, 0], fov_y=1.0, aspect=1.0,
                near=0.1, far=10.0)
    for missing in ("position", "forward", "up", "fov_y", "aspect", "near", "far"):
        d = {k: v for k, v in good.items() if k != missing}
        rejects(s, s.frame, f"cameras.{missing}", 1, [good, d])
    rejects(s, s.frame, "cameras.zoom", 0, [{**good, "zoom": 2.0}])


def test_valid_camera_edges_pass_validation():
    from lightsched.scene import validate_cameras

    cams = validate_cameras([
        camera(id=0, fov_y=1e-6, focus=[-1.0, 1.0]),
        camera(id=1, fov_y=math.pi - 1e-6, aspect=1e-6, near=1e-9, far=2e-9),
        camera(id=2, forward=[0.0, -1.0, 0.0], up=[0.0, 0.0, 1.0]),
        camera(id=3, forward=[0, 0, -5], up=[0, 1e-3, 0], position=[1e7, 0, -1e7]),
        {"position": (0, 0, 0), "forward": (1, 0, 0), "up": (0, 0, 1), "fov_y": 1,
         "aspect": 1, "near": 1, "far": 2, "id": 4},
        camera(id=INT32_MAX),
    ] + [camera(id=10 + i) for i in range(2)])
    assert len(cams) == 8
    assert all(c.position.dtype == np.float64 for c in cams)


def test_camera_vectors_of_every_kind_validate_alike():
    """Vectors given as float64 arrays, lists or tuples of floats (validate_cameras' fast
    paths) or of ints, or float32 arrays (numpy's path) give the same validated camera:
    new read-only float64 arrays, the same bits."""
    from lightsched.scene import validate_cameras

    vecs = {"position": [1.5, -2.0, 1e7], "forward": [0.0, -3.0, 0.25], "up": [0.0, 1.0, 0.0],
            "focus": [0.5, -1.0]}
    ints = {"position": [1, -2, 10_000_000], "forward": [0, -12, 1], "up": [0, 1, 0],
            "focus": [1, -1]}
    kinds = [lambda v: np.array(v, np.float64), list, tuple]
    want = validate_cameras([camera(**{k: np.array(v) for k, v in vecs.items()})])[0]
    for kind in kinds:
        given = {k: kind(v) for k, v in vecs.items()}
        got = validate_cameras([camera(**given)])[0]
        for name in vecs:
            a = getattr(got, name)
            assert a.dtype == np.float64 and not a.flags.writeable
            assert a is not given[name]
            assert a.tobytes() == getattr(want, name).tobytes()
    for kind in (list, tuple, lambda v: np.array(v, np.float32)):
        got = validate_cameras([camera(**{k: kind(v) for k, v in ints.items()})])[0]
        for name, v in ints.items():
            assert getattr(got, name).tolist() == [float(x) for x in v]


def test_validated_cameras_pass_again_until_a_field_is_replaced(s):
    """A camera validate_cameras returned passes again as itself (the service checks a
    request's cameras, then the frame would check them again); its vectors are read-only,
    and a field set afterwards makes it checked again like any other camera."""
    from lightsched.scene import validate_cameras

    cams = validate_cameras([camera(id=1), camera(id=2)])
    again = validate_cameras(cams)
    assert all(a is b for a, b in zip(again, cams, strict=True))
    with pytest.raises(ValueError, match="read-only"):
        cams[0].position[0] = np.nan
    rejects(s, s.frame, "cameras.id", 1, [cams[0], cams[0]])
    cams[1].fov_y = -1.0
    rejects(s, s.frame, "cameras.fov_y", 1, cams)
    cams[1].fov_y = 1.0
    cams[1].forward = np.array([0.0, 0.0, 0.0])
    rejects(s, s.frame, "cameras.forward", 1, cams)
    fixed = validate_cameras([cams[0], {**vars(camera(id=2))}])
    assert fixed[0] is cams[0] and fixed[1] is not cams[1]


# --------------------------------------------------------------------------- positive


def test_light_defaults(sched_cls):
    sch = sched_cls()
    outer = np.array([0.2, 0.5, 1.0, 1.5])
    sch.set_lights(id=[3, 1, 2, 0], type=[1, 1, 0, 2], position=np.zeros((4, 3)),
                   radius=[1.0, 2.0, 3.0, 0.0], direction=[[0, 0, 1]] * 4, outer_angle=outer)
    L = sch.lights
    order = np.array([3, 1, 2, 0])  # row of id 0, 1, 2, 3 in the call
    np.testing.assert_array_equal(L.outer_angle, outer[order])
    np.testing.assert_array_equal(L.inner_angle, 0.8 * outer[order])
    np.testing.assert_array_equal(L.intensity, np.ones(4))
    np.testing.assert_array_equal(L.priority, np.zeros(4))
    np.testing.assert_array_equal(L.shadows, np.zeros(4, bool))
    np.testing.assert_array_equal(L.mask, np.full(4, UINT32_ALL, np.uint32))

    sch.set_lights(id=[7], position=[[1.0, 2.0, 3.0]], radius=[4.0])
    L = sch.lights
    assert L.type.tolist() == [0]
    assert L.outer_angle.tolist() == [math.pi / 4]
    assert L.inner_angle.tolist() == [0.8 * (math.pi / 4)]
    assert L.mask.tolist() == [UINT32_ALL]


def test_store_dtypes(s):
    L, O = s.lights, s.objects
    assert L.id.dtype == np.int32 and L.type.dtype == np.uint8
    assert L.position.dtype == np.float64 and L.position.shape == (N_L, 3)
    assert L.direction.shape == (N_L, 3)
    for f in ("radius", "outer_angle", "inner_angle", "intensity", "priority"):
        assert getattr(L, f).dtype == np.float64 and getattr(L, f).shape == (N_L,)
    assert L.shadows.dtype == np.bool_ and L.mask.dtype == np.uint32
    assert O.id.dtype == np.int32 and O.mask.dtype == np.uint32
    assert O.bounds_min.shape == O.bounds_max.shape == (N_O, 3)
    assert O.casts_shadows.dtype == O.static.dtype == O.is_new.dtype == np.bool_


def test_object_defaults(sched_cls):
    sch = sched_cls()
    sch.set_objects(id=[9, 4], bounds_min=[[0, 0, 0], [1, 1, 1]], bounds_max=[[1, 1, 1]] * 2)
    O = sch.objects
    assert O.id.tolist() == [4, 9]
    np.testing.assert_array_equal(O.bounds_min, [[1, 1, 1], [0, 0, 0]])
    assert O.casts_shadows.tolist() == [True, True]
    assert O.mask.tolist() == [UINT32_ALL] * 2
    assert O.static.tolist() == [False, False]
    assert O.is_new.tolist() == [True, True]


def test_directions_stored_normalised(sched_cls):
    sch = sched_cls()
    d = np.array([[0.0, 0.0, -2.0], [3.0, 4.0, 0.0], [1e-150, 1e-150, 0.0], [1e150, 0, 0],
                  [1.0, 1.0, 1.0]])
    sch.set_lights(id=[0, 1, 2, 3, 4], type=[1, 2, 1, 2, 1], position=np.zeros((5, 3)),
                   radius=np.ones(5), direction=d)
    n = np.sqrt(d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1] + d[:, 2] * d[:, 2])
    np.testing.assert_array_equal(sch.lights.direction, d / n[:, None])  # bit for bit
    np.testing.assert_allclose(np.linalg.norm(sch.lights.direction, axis=1), 1.0, atol=1e-15)
    assert sch.lights.direction[1].tolist() == [0.6, 0.8, 0.0]
    sch.update_lights(id=[4], direction=[[0.0, 5.0, 0.0]])
    assert sch.lights.direction[4].tolist() == [0.0, 1.0, 0.0]


def test_rows_sorted_by_id_and_follow_their_ids(s):
    kw = light_kwargs()
    order = np.argsort(LIGHT_IDS)
    assert s.lights.id.tolist() == sorted(LIGHT_IDS)
    np.testing.assert_array_equal(s.lights.position, kw["position"][order])
    np.testing.assert_array_equal(s.lights.radius, kw["radius"][order])
    np.testing.assert_array_equal(s.lights.type, np.array(LIGHT_TYPES)[order])
    np.testing.assert_array_equal(s.lights.shadows, kw["shadows"][order])
    okw = object_kwargs()
    oorder = np.argsort(OBJECT_IDS)
    assert s.objects.id.tolist() == sorted(OBJECT_IDS)
    np.testing.assert_array_equal(s.objects.bounds_max, okw["bounds_max"][oorder])
    np.testing.assert_array_equal(s.objects.static, okw["static"][oorder])


def test_set_lights_replaces_the_set(s):
    s.set_lights(id=[2], position=[[0, 0, 0]], radius=[1])
    assert s.lights.id.tolist() == [2]
    s.set_lights(id=[])
    assert len(s.lights) == 0 and s.lights.position.shape == (0, 3)


def test_update_changes_only_named_rows_and_fields(s):
    before = snapshot(s)
    s.update_lights(id=[30, 1], radius=[7.0, 8.0], intensity=np.array([0, 2]))
    rows = np.searchsorted(s.lights.id, [30, 1])
    after = snapshot(s)
    for f in LIGHT_FIELDS:
        a, b = before[f"lights.{f}"], after[f"lights.{f}"]
        if f in ("radius", "intensity"):
            keep = np.ones(N_L, bool)
            keep[rows] = False
            np.testing.assert_array_equal(a[keep], b[keep])
        else:
            np.testing.assert_array_equal(a, b)
    assert s.lights.radius[rows].tolist() == [7.0, 8.0]
    assert s.lights.intensity[rows].tolist() == [0.0, 2.0]
    s.update_objects(id=[100], bounds_min=[[-1e9] * 3], static=[0])
    assert s.objects.bounds_min[np.searchsorted(s.objects.id, 100)].tolist() == [-1e9] * 3


def test_remove_keeps_other_rows_and_state(s):
    slots_before = s.objects.get("slots").copy()
    ids_before = s.objects.id.copy()
    s.remove_objects(id=[100, 0])
    keep = ~np.isin(ids_before, [100, 0])
    assert s.objects.id.tolist() == ids_before[keep].tolist()
    np.testing.assert_array_equal(s.objects.get("slots"), slots_before[keep])
    s.remove_lights(id=np.array([9, 40], np.uint16))
    assert s.lights.id.tolist() == sorted(set(LIGHT_IDS) - {9, 40})


def test_state_of_kept_ids_survives_set_objects(s):
    old_ids = s.objects.id.tolist()  # [0, 5, 7, 12, 33, 100]
    slots = s.objects.get("slots").copy()
    by_id = {i: slots[r] for r, i in enumerate(old_ids)}
    s.objects.add_state("weight", (), np.float64, 0.0)
    s.objects.put("weight", np.arange(N_O, dtype=np.float64) + 0.5)
    weights = {i: s.objects.get("weight")[r] for r, i in enumerate(old_ids)}
    s.objects.is_new[old_ids.index(33)] = True  # new since the last frame, still new

    new_ids = [100, 6, 33, 5, 2]  # keeps 100, 33, 5; drops 0, 7, 12; adds 6, 2
    lo = np.arange(15, dtype=np.float64).reshape(5, 3)
    s.set_objects(id=new_ids, bounds_min=lo, bounds_max=lo + 1)
    assert s.objects.id.tolist() == [2, 5, 6, 33, 100]
    got = s.objects.get("slots")
    w = s.objects.get("weight")
    assert got.shape == (5, 3) and got.dtype == np.int32
    for r, i in enumerate(s.objects.id.tolist()):
        if i in by_id:
            np.testing.assert_array_equal(got[r], by_id[i])
            assert w[r] == weights[i]
        else:
            assert (got[r] == STATE_FILL).all() and w[r] == 0.0
    assert s.objects.is_new.tolist() == [True, False, True, True, False]
    s.objects.is_new[:] = False  # as after a frame
    # a removed id that comes back is new and starts from the fill value
    s.remove_objects(id=[5])
    s.set_objects(id=[5, 33], bounds_min=np.zeros((2, 3)), bounds_max=np.ones((2, 3)))
    assert s.objects.is_new.tolist() == [True, False]
    assert (s.objects.get("slots")[0] == STATE_FILL).all()
    np.testing.assert_array_equal(s.objects.get("slots")[1], by_id[33])


def input_forms():
    ids = [5, 1, 3]
    pos = [[0.0, 1.0, 2.0], [3.0, 4.0, 5.0], [6.0, 7.0, 8.0]]
    dirs = [[0, 0, 1], [0, 2, 0], [3, 0, 0]]
    base = dict(id=ids, type=[1, 0, 2], position=pos, radius=[1.0, 2.0, 3.0], direction=dirs,
                outer_angle=[0.5, 0.5, 0.5], intensity=[1, 2, 3], priority=[0, 0, 1],
                shadows=[True, False, True], mask=[1, 2, UINT32_ALL])
    yield "lists", base
    yield "tuples", {k: tuple(tuple(x) if isinstance(x, list) else x for x in v)
                     for k, v in base.items()}
    yield "numpy", {k: np.asarray(v) for k, v in base.items()}
    yield "int32/float32/uint8", dict(
        id=np.array(ids, np.int32), type=np.array([1, 0, 2], np.uint8),
        position=np.array(pos, np.float32), radius=np.array([1, 2, 3], np.int16),
        direction=np.array(dirs, np.int8), outer_angle=np.array([0.5] * 3, np.float32),
        intensity=np.array([1, 2, 3], np.uint64), priority=np.array([0, 0, 1], np.int64),
        shadows=np.array([1, 0, 1], np.uint8), mask=np.array([1, 2, UINT32_ALL], np.uint32))
    yield "floats for ints", dict(base, id=np.array(ids, np.float64),
                                  type=np.array([1.0, 0.0, 2.0]),
                                  mask=np.array([1.0, 2.0, float(UINT32_ALL)]),
                                  shadows=np.array([1.0, 0.0, 1.0]))
    yield "mask as uint64/int64", dict(base, mask=np.array([1, 2, UINT32_ALL], np.uint64),
                                       id=np.array(ids, np.int64))


@pytest.mark.parametrize("name, kw", list(input_forms()), ids=[n for n, _ in input_forms()])
def test_input_forms_give_identical_stores(sched_cls, name, kw):
    ref = sched_cls()
    ref.set_lights(**dict(input_forms())["lists"])
    sch = sched_cls()
    sch.set_lights(**kw)
    for f in LIGHT_FIELDS:
        a, b = getattr(ref.lights, f), getattr(sch.lights, f)
        assert a.dtype == b.dtype and a.shape == b.shape, f
        np.testing.assert_array_equal(a, b, err_msg=f)
    assert sch.lights.id.tolist() == [1, 3, 5]


def test_object_input_forms(sched_cls):
    a, b = sched_cls(), sched_cls()
    a.set_objects(id=[3, 1], bounds_min=[[0, 0, 0], [1, 1, 1]], bounds_max=[[1, 1, 1], [2, 2, 2]],
                  casts_shadows=[False, True], mask=[7, 8], static=[1, 0])
    b.set_objects(id=(3.0, 1.0), bounds_min=np.array([[0, 0, 0], [1, 1, 1]], np.int32),
                  bounds_max=((1, 1, 1), (2, 2, 2)), casts_shadows=np.array([0, 1]),
                  mask=np.array([7, 8], np.uint8), static=(True, False))
    for f in OBJECT_FIELDS:
        x, y = getattr(a.objects, f), getattr(b.objects, f)
        assert x.dtype == y.dtype
        np.testing.assert_array_equal(x, y, err_msg=f)


def test_empty_sets(sched_cls):
    sch = sched_cls()
    sch.set_lights(id=[], position=np.zeros((0, 3)), radius=np.zeros(0))
    sch.set_objects(id=np.zeros(0, np.int32), bounds_min=np.zeros((0, 3)),
                    bounds_max=np.zeros((0, 3)))
    assert len(sch.lights) == 0 and len(sch.objects) == 0
    sch.update_lights(id=[])
    sch.remove_objects(id=[])


def test_caller_arrays_not_aliased(sched_cls):
    sch = sched_cls()
    pos = np.zeros((2, 3))
    r = np.ones(2)
    sch.set_lights(id=[0, 1], position=pos, radius=r)
    pos[:] = NAN
    r[:] = -1
    assert np.isfinite(sch.lights.position).all() and (sch.lights.radius == 1).all()


# --------------------------------------------------------------------------- properties


@st.composite
def light_sets(draw):
    n = draw(st.integers(0, 12))
    ids = draw(st.lists(st.integers(0, INT32_MAX), min_size=n, max_size=n, unique=True))
    fin = st.floats(-1e6, 1e6, allow_nan=False, allow_infinity=False)
    types = draw(st.lists(st.integers(0, 2), min_size=n, max_size=n))
    pos = draw(st.lists(st.tuples(fin, fin, fin), min_size=n, max_size=n))
    radius = draw(st.lists(st.floats(1e-6, 1e9), min_size=n, max_size=n))
    unit = st.floats(-1.0, 1.0)
    # |d| by DESIGN's formula must not underflow to 0 (subnormal components can)
    dirs = draw(st.lists(st.tuples(unit, unit, unit).filter(
        lambda v: v[0] * v[0] + v[1] * v[1] + v[2] * v[2] > 0.0), min_size=n, max_size=n))
    outer = draw(st.lists(st.floats(1e-3, 1.5), min_size=n, max_size=n))
    frac = draw(st.lists(st.floats(0.0, 1.0), min_size=n, max_size=n))
    kw = {
        "id": ids, "type": types, "position": np.array(pos, np.float64).reshape(n, 3),
        "radius": radius, "direction": np.array(dirs, np.float64).reshape(n, 3),
        "outer_angle": outer, "inner_angle": [o * f for o, f in zip(outer, frac, strict=True)],
        "intensity": draw(st.lists(st.floats(0.0, 1e3), min_size=n, max_size=n)),
        "priority": draw(st.lists(fin, min_size=n, max_size=n)),
        "shadows": draw(st.lists(st.booleans(), min_size=n, max_size=n)),
        "mask": draw(st.lists(st.integers(0, UINT32_ALL), min_size=n, max_size=n)),
    }
    perm = draw(st.permutations(list(range(n))))
    return kw, perm


@pytest.mark.parametrize("cls", SCHEDULERS, ids=SCHEDULER_IDS)
@settings(max_examples=60, deadline=None)
@given(data=light_sets())
def test_input_order_does_not_matter(cls, data):
    kw, perm = data
    a, b = cls(), cls()
    a.set_lights(**kw)
    permuted = {k: np.asarray(v)[list(perm)] for k, v in kw.items()}
    b.set_lights(**permuted)
    assert a.lights.id.tolist() == sorted(kw["id"])
    for f in LIGHT_FIELDS:
        x, y = getattr(a.lights, f), getattr(b.lights, f)
        assert x.dtype == y.dtype and x.shape == y.shape, f
        np.testing.assert_array_equal(x, y, err_msg=f)
    # row r of the store is the input row holding the r-th smallest id
    rows = np.argsort(kw["id"])
    np.testing.assert_array_equal(a.lights.radius, np.asarray(kw["radius"])[rows])


@pytest.mark.parametrize("cls", SCHEDULERS, ids=SCHEDULER_IDS)
@settings(max_examples=60, deadline=None)
@given(data=light_sets(), hits=st.lists(
    st.tuples(st.sampled_from(LIGHT_FLOAT_FIELDS), st.integers(0, 11),
              st.sampled_from(BAD_FLOATS)), min_size=1, max_size=4))
def test_first_nonfinite_field_in_table_order(cls, data, hits):
    """NaN/Inf put into random (field, row) cells: the error names the earliest field of the
    table with any hit, at that field's first hit row, and nothing changes."""
    kw, _ = data
    n = len(kw["id"])
    hits = [(f, r, v) for f, r, v in hits if r < n]
    if not hits:
        return
    for f, r, v in hits:
        a = np.array(kw[f], np.float64)
        if a.ndim == 2:
            a[r, r % 3] = v
        else:
            a[r] = v
        kw[f] = a
    field = min((f for f, _, _ in hits), key=LIGHT_FIELDS.index)
    row = min(r for f, r, _ in hits if f == field)
    sch = cls()
    sch.set_lights(id=[99], position=[[1, 2, 3]], radius=[4])
    rejects(sch, sch.set_lights, field, row, **kw)


# Values each light field may get in an update: valid ones and every kind of bad one.
UPDATE_VALUES = {
    "type": [-1, 0, 1, 2, 3],
    "position": [NAN, -INF, -3.0, 0.0, 7.5],
    "radius": [NAN, INF, -1.0, 0.0, 0.5, 20.0],
    "direction": [NAN, INF, 0.0, 1e-200, 1e200, -1.0, 0.3],
    "outer_angle": [NAN, -0.1, 0.0, 0.3, 0.6, 1.5, 1.6],
    "inner_angle": [NAN, -0.1, 0.0, 0.3, 0.6, 0.9],
    "intensity": [NAN, INF, -1.0, 0.0, 2.0],
    "priority": [NAN, -5.0, 0.0, 3.0],
    "shadows": [0, 1, 2],
    "mask": [-1, 0, 5, UINT32_ALL, UINT32_ALL + 1],
}


def update_against_every_rule(data: st.DataObject, store: object, validate: object,
                              names: tuple[str, ...], values: dict[str, list],
                              wide: tuple[str, ...]) -> tuple[tuple, tuple, dict]:
    """Draws rows of ``store`` and fields to give them from ``values`` (those in ``wide``
    [n, 3]); runs ``validate`` on the stored rows as an update gives them (read when a
    rule does) and, with every rule, on the merged rows; checks they agree on the first
    error (field, index, message) if any. Returns both outcomes, ("ok", columns) or
    ("error", ...), and the given fields."""
    from lightsched.scene import _StoredRows

    n_rows = len(store)
    rows = data.draw(st.lists(st.integers(0, n_rows - 1), min_size=1, max_size=n_rows,
                              unique=True))
    stored = {f: getattr(store, f)[rows] for f in names}
    base = _StoredRows(store, np.array(rows), names)
    n = len(rows)
    given_fields = {}
    for name in data.draw(st.lists(st.sampled_from(sorted(values)), min_size=1, unique=True)):
        width = 3 if name in wide else 0
        cells = data.draw(st.lists(st.sampled_from(values[name]),
                                   min_size=n * max(width, 1), max_size=n * max(width, 1)))
        a = np.array(cells)
        given_fields[name] = a.reshape(n, width) if width else a

    def outcome(given: dict, rows_base: object) -> tuple:
        try:
            return ("ok", validate(given, rows_base, n))
        except ValidationError as e:
            return ("error", (e.field, e.index, e.message))

    got = outcome(dict(given_fields), base)
    want = outcome({**stored, **given_fields}, None)
    assert got[0] == want[0], (got, want)
    if got[0] == "error":
        assert got[1] == want[1]
    return got, want, given_fields


# Values each object field may get in an update (bounds around the stored ones).
OBJECT_UPDATE_VALUES = {
    "bounds_min": [NAN, -INF, -60.0, 0.0, 60.0],
    "bounds_max": [NAN, INF, -60.0, 0.0, 60.0],
    "casts_shadows": [0, 1, 2],
    "mask": [-1, 0, 5, UINT32_ALL, UINT32_ALL + 1],
    "static": [0, 1, 2],
}


@pytest.mark.parametrize("what", ["lights", "objects"])
@settings(max_examples=150, deadline=None)
@given(data=st.data())
def test_update_runs_only_the_rules_of_given_fields(what, data):
    """An update checks only the rules that read a given field (LightStore.validate and
    ObjectStore.validate: the bounds order, the mask range), on the stored rows as an
    update gives them (read when a rule does); the stored rows passed them all, so the
    outcome equals running every rule on the merged rows: the same first error (field,
    index, message), or the same columns."""
    from lightsched.scene import LightStore, ObjectStore

    s = ls.Scheduler()
    if what == "lights":
        s.set_lights(**light_kwargs())
        got, want, given_fields = update_against_every_rule(
            data, s.lights, LightStore.validate, LIGHT_FIELDS, UPDATE_VALUES,
            ("position", "direction"))
    else:
        s.set_objects(**object_kwargs())
        got, want, given_fields = update_against_every_rule(
            data, s.objects, ObjectStore.validate, OBJECT_FIELDS, OBJECT_UPDATE_VALUES,
            ("bounds_min", "bounds_max"))
    if got[0] == "error":
        return
    for f in want[1]:  # every field (the update's columns read the others on demand)
        if f == "direction" and f not in given_fields:
            # every rule run normalises the stored (unit) directions again: last-bit changes
            np.testing.assert_allclose(got[1][f], want[1][f], rtol=1e-15, atol=0)
        else:
            np.testing.assert_array_equal(got[1][f], want[1][f], err_msg=f)
            assert got[1][f].dtype == want[1][f].dtype, f
