"""Caster lists (DESIGN section 2, "Casters"), checked without trusting either scheduler.

Hand-built scenes show the rules: an off-screen pole whose shadow falls into view is
listed, a caster on the far side of the light is not, the cube-face, spot and cascade bits.
Then the never-missed property on random scenes: for sample points on visible receivers
lit by a shadowed light, the segment to the light (for a directional light: along
-direction, far away) is cast, and every casting AABB it crosses must be listed for that
light with the bit of the face or cascade the point is in. The geometry here (frustum
membership, cube faces, cascade slices, segment-box hits) is written from scratch, with a
small margin so that a point or a hit on a boundary within rounding is not asked about.
test_equivalence.py compares fast and oracle lists at random.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest
from helpers import assert_frames_match, by_row_or_grid, camera, examples, up_for
from hypothesis import given
from hypothesis import strategies as st

import lightsched as ls
import lightsched.reference as ref
from lightsched.casters import MAX_PLANES, SWEEP_BLOCK, Volumes, sweep_casters, sweep_groups
from lightsched.grid import group_boxes, widen_group_boxes
from lightsched.tuning import Tuning

# The tests that make fast schedulers run with both kinds of object grid of the fast path:
# they take the ``tuning`` fixture (conftest.py) and give it to each.

SCHEDULERS = pytest.mark.parametrize("cls", [ls.Scheduler, ref.Scheduler], ids=["fast", "oracle"])
MARGIN = 1e-6
FAR_AWAY = 1e4  # metres along -direction: the segment towards a directional light


def new_scheduler(cls: type, cfg: ls.Config, tuning: Tuning) -> Any:
    """A fast scheduler with ``tuning``, or an oracle (which has none)."""
    return cls(cfg, tuning) if cls is ls.Scheduler else cls(cfg)


def casters_of(f: ls.Frame, light_id: int) -> dict[int, int]:
    """{object id: caster mask} of one shadow light."""
    s = f.shadow_lights.tolist().index(light_id)
    a, b = int(f.caster_offsets[s]), int(f.caster_offsets[s + 1])
    ids = f.caster_ids[a:b].tolist()
    assert ids == sorted(ids), "caster ids must ascend within a light"
    return dict(zip(ids, f.caster_masks[a:b].tolist(), strict=True))


def boxes(rows: list[tuple[tuple[float, ...], tuple[float, ...]]], **extra) -> dict:
    return dict(id=list(range(len(rows))), bounds_min=[r[0] for r in rows],
                bounds_max=[r[1] for r in rows], **extra)


# The camera at the origin looks along +x with z up; the ground in front is a receiver.
VIEW = camera(forward=(1.0, 0.0, 0.0), up=(0.0, 0.0, 1.0), fov_y=1.0, aspect=1.5, near=0.1,
              far=80.0)
GROUND = ((2.0, -20.0, -0.1), (60.0, 20.0, 0.0))
POLE = ((-3.2, -0.2, 0.0), (-2.8, 0.2, 20.0))       # behind the camera: never on screen
FAR_SIDE = ((-12.2, -0.2, 0.0), (-11.8, 0.2, 20.0))  # behind the light, seen from the view


@SCHEDULERS
def test_pole_behind_the_camera_casts_into_view_and_far_side_does_not(cls, tuning):
    s = new_scheduler(cls, ls.Config(shadow_budget=4), tuning)
    s.set_objects(**boxes([GROUND, POLE, FAR_SIDE]))
    s.set_lights(id=[9], position=[[-6.0, 0.0, 12.0]], radius=[60.0], intensity=[10.0],
                 shadows=[True])
    f = s.frame([VIEW])
    assert f.visible.tolist() == [True, False, False]
    assert f.shadow_lights.tolist() == [9]
    listed = casters_of(f, 9)
    # Ground point (5, 0, 0) is 11 m ahead of the light and 12 m below it: face -z (bit 5);
    # its segment to the light crosses the pole.
    assert 1 in listed and listed[1] & (1 << 5)
    assert 2 not in listed
    # The ground holds the light's -z and +x faces from where it is seen.
    assert listed[0] & (1 << 5)


@SCHEDULERS
def test_cube_face_bits_and_spot_bit(cls, tuning):
    cam = camera(position=(0.0, 0.0, -30.0), forward=(0.0, 0.0, 1.0), fov_y=2.0, far=200.0)
    s = new_scheduler(cls, ls.Config(shadow_budget=4), tuning)
    # Boxes at each face of a point light at the origin, one straddling the +x/+y diagonal.
    rows = [((2.0, -0.5, -0.5), (3.0, 0.5, 0.5)), ((-3.0, -0.5, -0.5), (-2.0, 0.5, 0.5)),
            ((-0.5, 2.0, -0.5), (0.5, 3.0, 0.5)), ((-0.5, -3.0, -0.5), (0.5, -2.0, 0.5)),
            ((-0.5, -0.5, 2.0), (0.5, 0.5, 3.0)), ((-0.5, -0.5, -3.0), (0.5, 0.5, -2.0)),
            ((2.0, 1.5, -0.5), (3.0, 2.5, 0.5))]
    s.set_objects(**boxes(rows))
    s.set_lights(id=[1], position=[[0.0, 0.0, 0.0]], radius=[10.0], shadows=[True])
    f = s.frame([cam])
    assert casters_of(f, 1) == {0: 1, 1: 2, 2: 4, 3: 8, 4: 16, 5: 32, 6: 1 | 4}
    # A spot pointing +x lists what its cone meets, all with bit 0.
    s.set_lights(id=[1], type=[1], position=[[0.0, 0.0, 0.0]], radius=[10.0],
                 direction=[[1.0, 0.0, 0.0]], outer_angle=[0.5], shadows=[True])
    f = s.frame([cam])
    assert casters_of(f, 1) == {0: 1, 6: 1}


@SCHEDULERS
def test_directional_bits_per_camera_and_cascade(cls, tuning):
    # Sun straight down; two cameras looking along +x and -x at 5 m height.
    cams = [camera(position=(0.0, 0.0, 5.0), forward=(1.0, 0.0, 0.0), up=(0.0, 0.0, 1.0),
                   fov_y=1.0, near=1.0, far=200.0, id=0),
            camera(position=(0.0, 0.0, 5.0), forward=(-1.0, 0.0, 0.0), up=(0.0, 0.0, 1.0),
                   fov_y=1.0, near=1.0, far=200.0, id=1)]
    cfg = ls.Config(cascades=4, shadow_distance=100.0, cascade_overlap=0.0)
    s = new_scheduler(cls, cfg, tuning)
    z = ref.cascade_splits(ref.CameraFrame(cams[0]), cfg)
    mid = [(z[c] + z[c + 1]) / 2 for c in range(4)]
    # One high roof above the middle of each of camera 0's cascades (out of view, above
    # the frustum: shadows fall down into it), one far beyond shadow_distance, one
    # casting nothing, and one behind camera 1 in its cascade 0.
    rows = [((m - 0.2, -0.2, 60.0), (m + 0.2, 0.2, 61.0)) for m in mid]
    rows += [((150.0, -0.2, 60.0), (150.4, 0.2, 61.0)), ((mid[0], 0.0, 60.0), (mid[0], 0.0, 61.0)),
             ((-mid[0] - 0.2, -0.2, 60.0), (-mid[0] + 0.2, 0.2, 61.0))]
    s.set_objects(**boxes(rows, casts_shadows=[True] * 5 + [False, True]))
    s.set_lights(id=[3], type=[2], direction=[[0.0, 0.0, -1.0]], shadows=[True])
    f = s.frame(cams)
    assert f.shadow_lights.tolist() == [3] and not f.visible[:4].any()
    listed = casters_of(f, 3)
    for c in range(4):
        assert listed[c] & (1 << c), (c, listed)          # camera 0, cascade c
    assert 4 not in listed and 5 not in listed
    assert listed[6] & (1 << 4)                           # camera 1 (bit 1*C + 0)
    assert not listed[6] & 0b1111


# --------------------------------------------------------------------------- never missed


def _basis(cam: ls.Camera) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    f = np.asarray(cam.forward, float) / np.linalg.norm(cam.forward)
    r = np.cross(f, cam.up)
    r /= np.linalg.norm(r)
    return f, r, np.cross(r, f)


def _depth_if_inside(cam: ls.Camera, x: np.ndarray) -> float | None:
    """x's depth along the view axis if x is inside the frustum by MARGIN, else None."""
    f, r, u = _basis(cam)
    d = x - np.asarray(cam.position, float)
    z = float(d @ f)
    t_y = math.tan(cam.fov_y / 2)
    t_x = cam.aspect * t_y
    inside = (cam.near + MARGIN < z < cam.far - MARGIN
              and abs(float(d @ r)) < z * t_x - MARGIN and abs(float(d @ u)) < z * t_y - MARGIN)
    return z if inside else None


def _segment_hits(a: np.ndarray, b: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> bool:
    """The segment a-b crosses the box shrunk by MARGIN (slab method)."""
    lo, hi = lo + MARGIN, hi - MARGIN
    if np.any(lo > hi):
        return False
    t0, t1 = 0.0, 1.0
    d = b - a
    for k in range(3):
        if abs(d[k]) < 1e-300:
            if not lo[k] <= a[k] <= hi[k]:
                return False
            continue
        s0, s1 = (lo[k] - a[k]) / d[k], (hi[k] - a[k]) / d[k]
        t0, t1 = max(t0, min(s0, s1)), min(t1, max(s0, s1))
        if t0 > t1:
            return False
    return True


def _face_bits(xp: np.ndarray) -> int:
    """The cube faces whose pyramid holds x' = x - p by MARGIN (0 on a diagonal)."""
    a = int(np.argmax(np.abs(xp)))
    others = [abs(xp[b]) for b in range(3) if b != a]
    if abs(xp[a]) <= max(others) + MARGIN:
        return 0
    return 1 << (2 * a + (xp[a] < 0))


def _cascade_bits(cams: list[ls.Camera], cfg: ls.Config, x: np.ndarray) -> int:
    """Bits camera*C + cascade of every slice x is inside by MARGIN (x must be on screen)."""
    bits = 0
    for k, cam in enumerate(cams):
        z = _depth_if_inside(cam, x)
        if z is None:
            continue
        dist = min(cam.far, cfg.shadow_distance)
        cc = cfg.cascades
        splits = [0.5 * cam.near * (dist / cam.near) ** (i / cc)
                  + 0.5 * (cam.near + (dist - cam.near) * i / cc) for i in range(cc + 1)]
        for c in range(cc):
            a = cam.near if c == 0 else splits[c] - cfg.cascade_overlap * (splits[c] - splits[c - 1])
            if a + MARGIN < z < splits[c + 1] - MARGIN:
                bits |= 1 << (k * cc + c)
    return bits


def random_scene(rng: np.random.Generator) -> tuple[dict, dict, list[ls.Camera], ls.Config]:
    """A ground receiver, boxes scattered over and above it, shadowed lights of all types
    (some above and behind the cameras), 1-3 cameras looking at the ground."""
    n_obj = int(rng.integers(8, 30))
    lo = np.column_stack([rng.uniform(-30, 30, n_obj), rng.uniform(-30, 30, n_obj),
                          rng.uniform(0, 15, n_obj)])
    hi = lo + rng.uniform(0.2, 4.0, (n_obj, 3)) * (rng.uniform(size=(n_obj, 1)) < 0.9)
    lo = np.vstack([[-40.0, -40.0, -0.5], lo])
    hi = np.vstack([[40.0, 40.0, 0.0], hi])
    n = lo.shape[0]
    objects = dict(id=rng.permutation(3 * n)[:n], bounds_min=lo, bounds_max=hi,
                   casts_shadows=rng.uniform(size=n) < 0.85,
                   mask=rng.choice([0xFFFFFFFF, 1, 2, 3], n, p=[0.7, 0.1, 0.1, 0.1]))
    n_l = int(rng.integers(1, 6))
    typ = rng.choice([0, 1, 2], n_l, p=[0.5, 0.3, 0.2])
    direction = rng.normal(size=(n_l, 3))
    direction[:, 2] = -np.abs(direction[:, 2]) - 0.2  # lights shine downwards
    lights = dict(id=rng.permutation(50)[:n_l], type=typ,
                  position=np.column_stack([rng.uniform(-40, 40, n_l), rng.uniform(-40, 40, n_l),
                                            rng.uniform(3, 40, n_l)]),
                  radius=rng.uniform(10, 80, n_l), direction=direction,
                  outer_angle=rng.uniform(0.3, 1.4, n_l), intensity=rng.uniform(1, 10, n_l),
                  shadows=np.ones(n_l, bool),
                  mask=rng.choice([0xFFFFFFFF, 1, 2], n_l, p=[0.8, 0.1, 0.1]))
    cams = []
    for k in range(int(rng.integers(1, 4))):
        pos = np.array([rng.uniform(-35, 35), rng.uniform(-35, 35), rng.uniform(2, 30)])
        target = np.array([rng.uniform(-20, 20), rng.uniform(-20, 20), 0.0])
        near = float(rng.uniform(0.1, 1.0))
        cams.append(camera(position=pos, forward=target - pos, up=(0.0, 0.0, 1.0),
                           fov_y=float(rng.uniform(0.5, 1.6)), aspect=float(rng.uniform(1, 2)),
                           near=near, far=near + float(rng.uniform(20, 150)), id=k))
    cfg = ls.Config(shadow_budget=127, cascades=int(rng.integers(1, 5)),
                    shadow_distance=float(rng.choice([150.0, 40.0, 15.0])),
                    cascade_overlap=float(rng.choice([0.0, 0.1, 0.3])))
    return lights, objects, cams, cfg


def assert_never_missed(f: ls.Frame, lights: dict, objects: dict, cams: list[ls.Camera],
                        cfg: ls.Config, rng: np.random.Generator, points: int = 12) -> int:
    """The never-missed property for every shadow light of frame f; returns how many
    (point, caster) hits were checked."""
    row_of = {int(i): k for k, i in enumerate(objects["id"])}
    checked = 0
    for lid in f.shadow_lights.tolist():
        j = list(lights["id"]).index(lid)
        typ, p, r = int(lights["type"][j]), lights["position"][j], lights["radius"][j]
        axis = lights["direction"][j] / np.linalg.norm(lights["direction"][j])
        lmask = int(lights["mask"][j])
        listed = casters_of(f, lid)
        for oid in f.object_id[f.visible].tolist():
            o = row_of[oid]
            if not lmask & int(objects["mask"][o]):
                continue  # this light does not light that receiver
            lo, hi = objects["bounds_min"][o], objects["bounds_max"][o]
            for x in rng.uniform(lo, hi, (points, 3)):
                if typ == 2:
                    want = _cascade_bits(cams, cfg, x)
                    end = x - axis * FAR_AWAY
                else:
                    if not any(_depth_if_inside(c, x) is not None for c in cams):
                        continue
                    d = x - p
                    if np.linalg.norm(d) >= r - MARGIN:
                        continue
                    if typ == 1 and not (d @ axis) > math.cos(lights["outer_angle"][j]) * (
                            np.linalg.norm(d) + MARGIN):
                        continue  # outside the cone: not lit, no shadow to cast
                    want = 1 if typ == 1 else _face_bits(d)
                    end = p
                if not want:
                    continue
                for c in range(len(objects["id"])):
                    if not (objects["casts_shadows"][c] and lmask & int(objects["mask"][c])):
                        continue
                    if _segment_hits(x, end, objects["bounds_min"][c], objects["bounds_max"][c]):
                        cid = int(objects["id"][c])
                        assert cid in listed, (
                            f"light {lid} (type {typ}) misses caster {cid} shadowing point {x} "
                            f"of receiver {oid}")
                        assert listed[cid] & want == want, (
                            f"light {lid}: caster {cid} mask {listed[cid]:#b} lacks {want:#b} "
                            f"for point {x}")
                        checked += 1
    return checked


SCENES = 240


def test_never_missed_on_random_scenes(tuning):
    """Every sampled shadowing caster is listed with the right bit, on SCENES scenes, for
    the fast path; the oracle gives the same frame (so the property holds for it too)."""
    rng = np.random.default_rng(2026)
    checked, with_casters, types = 0, 0, set()
    for i in range(SCENES):
        lights, objects, cams, cfg = random_scene(rng)
        fast, oracle = ls.Scheduler(cfg, tuning), ref.Scheduler(cfg)
        for s in (fast, oracle):
            s.set_lights(**lights)
            s.set_objects(**objects)
        f = fast.frame(cams)
        assert_frames_match(f, oracle.frame(cams), what=f"scene {i}")
        n = assert_never_missed(f, lights, objects, cams, cfg, rng)
        checked += n
        with_casters += n > 0
        types |= {int(lights["type"][list(lights["id"]).index(lid)])
                  for lid in f.shadow_lights.tolist()}
    # The property must have been exercised, not vacuously true.
    assert with_casters >= SCENES // 2 and checked >= 20 * SCENES and types == {0, 1, 2}, (
        with_casters, checked, types)


@examples(0.04)
@given(seed=st.integers(0, 2**32 - 1))
def test_sun_casters_of_a_large_scene_match_the_oracle(seed, tuning):
    """The sun's sweep at scale: ~70k boxes over a town, two cameras looking at it, a
    slanted sun with a shadow distance that keeps a fraction of them (955 to 20k casters
    over 63 seeds), some objects not casting or masked out; equal to the oracle's frame.
    The cameras see over half of the objects, so the frame keeps a grid of every object
    and sweeps its group boxes first (casters.sweep_groups; ~1100 groups). The flat sweep
    (sweep_casters, each of its parallel parts scanning 2-3 blocks here) and the plane
    order a part carries from block to block are checked below, on plane sets built to
    empty whole blocks."""
    rng = np.random.default_rng(seed)
    n = 70_000
    centre = rng.uniform(-600.0, 600.0, (n, 3))
    centre[:, 1] = rng.uniform(0.0, 30.0, n)
    half = rng.uniform(0.2, 6.0, (n, 3))
    objects = dict(id=rng.permutation(3 * n)[:n], bounds_min=centre - half,
                   bounds_max=centre + half, mask=rng.choice([1, 2, 3], n),
                   casts_shadows=rng.random(n) < 0.9)
    down = rng.uniform(-1.0, 1.0, 3)
    down[1] = -rng.uniform(0.3, 1.0)
    lights = dict(id=[5], type=[2], direction=[down], mask=[1], shadows=[True],
                  intensity=[1.0], position=[[0.0, 0.0, 0.0]], radius=[1.0])
    cams = []
    for k in range(2):
        # Over the town, looking at a point of it: the view always holds some of it.
        position = rng.uniform(-300.0, 300.0, 3) * (1.0, 0.1, 1.0) + (0.0, 35.0, 0.0)
        forward = rng.uniform(-200.0, 200.0, 3) * (1.0, 0.0, 1.0) - position
        cams.append(camera(position=position, forward=forward, up=up_for(forward), fov_y=1.0,
                           aspect=1.6, near=0.5, far=900.0, id=k))
    cfg = ls.Config(shadow_distance=float(rng.uniform(100.0, 500.0)), max_lights=2)
    frames = []
    for cls in (ls.Scheduler, ref.Scheduler):
        s = new_scheduler(cls, cfg, tuning)
        s.set_objects(**objects)
        s.set_lights(**lights)
        frames.append(s.frame(cams))
    assert frames[0].caster_ids.size > 100  # the sweep kept some, and rejected most
    assert frames[0].caster_ids.size < n // 2
    assert_frames_match(frames[0], frames[1], what=f"seed {seed}")


def sweep_bits_by_numpy(lo, hi, casts, omask, lmask, vols):
    """DESIGN "Tests" written out for sweep_casters' inputs: bit b of light t iff the box
    casts, masks match, and for every plane of volume b (its camera's shared planes, then
    its own) the box corner farthest along the normal has signed distance >= 0; float64,
    the same expression, one plane at a time over every box."""
    vn, vq, vm, shared = vols
    n_cam = shared.shape[1]
    n_casc = vm.shape[1] // n_cam
    bits = np.zeros((lmask.shape[0], lo.shape[0]), np.uint32)
    for t in range(lmask.shape[0]):
        base = casts & ((omask.astype(np.int64) & lmask[t]) != 0)
        for b in range(vm.shape[1]):
            first = (b // n_casc) * n_casc  # the camera's shared planes are kept there
            inside = base.copy()
            for i in range(vm[t, b]):
                k = first if i < shared[t, b // n_casc] else b
                n = vn[t, k, i]
                c = [np.where(n[a] >= 0.0, hi[:, a], lo[:, a]) for a in range(3)]
                q = vq[t, k, i]
                inside &= n[0] * (c[0] - q[0]) + n[1] * (c[1] - q[1]) + n[2] * (c[2] - q[2]) >= 0.0
            bits[t] |= inside.astype(np.uint32) << np.uint32(b)
    return bits


def random_volumes(rng: np.random.Generator, reach: tuple[float, float] = (0.3, 1.5)
                   ) -> tuple[np.ndarray, ...]:
    """Random convex plane sets in culling_volumes' layout: 2 lights x 2 cameras x 2
    cascades, 1-3 shared planes (kept in each camera's first volume), 3-8 own."""
    n_t, n_cam, n_casc = 2, 2, 2
    n_vol = n_cam * n_casc
    vn = np.zeros((n_t, n_vol, MAX_PLANES, 3))
    vq = np.zeros((n_t, n_vol, MAX_PLANES, 3))
    vm = rng.integers(3, 9, (n_t, n_vol))
    shared = rng.integers(1, 4, (n_t, n_cam))
    for t in range(n_t):
        for b in range(n_vol):
            vm[t, b] += shared[t, b // n_casc]
            m = vm[t, b]
            normals = rng.normal(size=(m, 3))
            # Planes through points around a ball, facing inwards: a convex volume around
            # the origin that holds some of the boxes.
            vn[t, b, :m] = normals
            vq[t, b, :m] = -normals / np.linalg.norm(normals, axis=1)[:, None] * rng.uniform(
                *reach, (m, 1))
    return vn, vq, vm, shared


@examples(0.2)
@given(seed=st.integers(0, 2**32 - 1))
def test_sweep_casters_equals_the_plane_test_box_by_box(seed):
    """casters.sweep_casters on random convex plane sets (2 lights x 2 cameras x 2
    cascades, 1-3 shared planes, 3-8 own) and ~40k boxes, against the test written out
    in numpy. The boxes come in runs: whole blocks far outside one plane (the block is
    emptied and that plane is tried first in the part's next blocks), then blocks near the
    volumes, so a plane the carried order skipped would show."""
    rng = np.random.default_rng(seed)
    vn, vq, vm, shared = random_volumes(rng)
    n = 80 * SWEEP_BLOCK
    centre = rng.uniform(-2.0, 2.0, (n, 3))
    for blk in np.flatnonzero(rng.random(n // SWEEP_BLOCK) < 0.4):
        # A whole block pushed out along one axis.
        rows = slice(blk * SWEEP_BLOCK, (blk + 1) * SWEEP_BLOCK)
        centre[rows, rng.integers(0, 3)] += rng.choice([-8.0, 8.0])
    half = rng.uniform(0.0, 0.3, (n, 3))
    lo, hi = centre - half, centre + half
    casts = rng.random(n) < 0.9
    omask = rng.choice(np.array([1, 2, 3], np.uint32), n)
    lmask = np.array([1, 2], np.int64)
    vols = Volumes(vn, vq, vm, shared)
    got = sweep_casters(lo, hi, casts, omask, lmask, vols)
    want = sweep_bits_by_numpy(lo, hi, casts, omask, lmask, vols)
    assert np.count_nonzero(want) > 100
    assert np.array_equal(got, want)


@examples(0.2)
@given(seed=st.integers(0, 2**32 - 1), order=st.sampled_from(["cells", "random"]),
       reach=st.sampled_from([(0.05, 0.4), (0.3, 1.5), (3.0, 6.0)]))
def test_sweep_groups_equals_the_plane_test_box_by_box(seed, order, reach):
    """casters.sweep_groups (the group boxes of a grid's positions tested first) against
    the test written out in numpy, box by box: the same casters, rows ascending, the same
    masks. Grid positions in cells (coherent groups, most of them rejected whole, some
    across a plane) or in random order (a group box spans everything); volumes that hold a
    few of the boxes (casters sorted into row order), a third or most of them (spread over
    the rows instead). Boxes read by object row ("fast" precision) or from records in
    grid order (exact). Then a quarter of the objects move, their group boxes widened in
    place (widen_group_boxes), and the sweep is the same again."""
    rng = np.random.default_rng(seed)
    vols = Volumes(*random_volumes(rng, reach))
    n = 20_000
    centre = rng.uniform(-4.0, 4.0, (n, 3))
    half = rng.uniform(0.0, 0.3, (n, 3))
    lo, hi = centre - half, centre + half
    casts = rng.random(n) < 0.9
    omask = rng.choice(np.array([1, 2, 3], np.uint32), n)
    lmask = np.array([1, 2], np.int64)
    if order == "cells":
        cell = np.floor(centre / 0.5).astype(np.int64) + 8
        grid_rows = np.argsort((cell[:, 0] * 17 + cell[:, 1]) * 17 + cell[:, 2], kind="stable")
    else:
        grid_rows = rng.permutation(n)
    pos_of = np.empty(n, np.int64)
    pos_of[grid_rows] = np.arange(n)
    by_row = rng.random() < 0.5  # boxes by object row, or copied into grid order
    boxes = group_boxes(by_row_or_grid(lo, hi, grid_rows, by_row))

    def check() -> int:
        at, rows, masks = sweep_groups(casts, omask, lmask, vols,
                                       by_row_or_grid(lo, hi, grid_rows, by_row), boxes)
        want = sweep_bits_by_numpy(lo, hi, casts, omask, lmask, vols)
        for t in range(lmask.size):
            keep = np.flatnonzero(want[t])
            assert np.array_equal(rows[at[t]:at[t + 1]], keep), t
            assert np.array_equal(masks[at[t]:at[t + 1]], want[t][keep]), t
        assert at[-1] == rows.size == masks.size
        return int(at[-1])

    found = check()
    assert 0 < found < 2 * n
    moved = rng.choice(n, n // 4, replace=False)
    step = rng.normal(0.0, 1.0, (moved.size, 3))
    lo, hi = lo.copy(), hi.copy()
    lo[moved] += step
    hi[moved] += step
    widen_group_boxes(boxes, lo, hi, moved, pos_of)
    check()
