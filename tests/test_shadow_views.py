"""Shadow views, updates and the atlas (DESIGN section 2) against the oracle alone: a
renderer replayed frame by frame that draws exactly shadow_update and checks that no view
left clean is stale; the budget's bound; the atlas' tiles; caster_culling = "light"; the
sampling rule. tests/test_equivalence.py compares the fast path with the oracle; the
frames here where the fast path patches or keeps its caster lists are compared too."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest
from helpers import Twin

import lightsched as ls
import lightsched.reference as ref

DIRECTIONAL = 2
# The replay and the rules hold for the oracle and, through the equivalence tests, for
# the fast path; these tests run on both.
SCHEDULERS = pytest.mark.parametrize("cls", [ref.Scheduler, ls.Scheduler], ids=["oracle", "fast"])


def cam(position=(0.0, 0.0, 0.0), forward=(0.0, 0.0, 1.0), cid=None, far=200.0):
    return ls.Camera(position=list(position), forward=list(forward), up=[0.0, 1.0, 0.0],
                     fov_y=1.0, aspect=1.5, near=0.1, far=far, id=cid)


class Scene:
    """A random scene that moves: point, spot and one directional shadowed light, static
    and moving objects, a camera that may move. Drives any scheduler through the same
    calls (``s``)."""

    def __init__(self, seed: int, n_lights: int = 7, n_objects: int = 40) -> None:
        self.rng = rng = np.random.default_rng(seed)
        self.n_lights, self.n_objects = n_lights, n_objects
        types = rng.choice([0, 0, 1], n_lights)
        types[-1] = DIRECTIONAL
        self.lights = dict(
            id=np.arange(n_lights) * 3 + 1, type=types,
            position=rng.uniform(-8, 8, (n_lights, 3)) + [0, 0, 20],
            radius=rng.uniform(3, 9, n_lights),
            direction=np.tile([0.0, -0.6, 0.8], (n_lights, 1)) / 1.0,
            intensity=rng.uniform(0.5, 2, n_lights), shadows=np.ones(n_lights, bool))
        self.lo = rng.uniform(-12, 12, (n_objects, 3)) + [0, 0, 20]
        self.size = rng.uniform(0.2, 2.0, (n_objects, 3))
        self.static = rng.random(n_objects) < 0.5
        self.camera = np.array([0.0, 0.0, 0.0])

    def install(self, s: Any) -> None:
        s.set_lights(**self.lights)
        s.set_objects(id=np.arange(self.n_objects), bounds_min=self.lo,
                      bounds_max=self.lo + self.size, static=self.static)

    def step(self, s: Any, move_objects: float = 0.3, move_lights: float = 0.2,
             move_camera: bool = True, resend: float = 0.05) -> None:
        """Moves some dynamic objects and lights (and the camera), re-sends a few objects
        unchanged (an animated mesh in a fixed box)."""
        rng = self.rng
        movers = np.flatnonzero(~self.static & (rng.random(self.n_objects) < move_objects))
        if movers.size:
            self.lo[movers] += rng.normal(0, 0.3, (movers.size, 3))
        resent = np.flatnonzero(rng.random(self.n_objects) < resend)
        rows = np.union1d(movers, resent)
        if rows.size:
            s.update_objects(id=rows, bounds_min=self.lo[rows],
                             bounds_max=self.lo[rows] + self.size[rows])
        moved = np.flatnonzero(rng.random(self.n_lights - 1) < move_lights)
        if moved.size:
            self.lights["position"][moved] += rng.normal(0, 0.3, (moved.size, 3))
            s.update_lights(id=self.lights["id"][moved],
                            position=self.lights["position"][moved])
        if move_camera:
            self.camera = self.camera + rng.normal(0, 0.2, 3)
        return rows

    def cameras(self) -> list[ls.Camera]:
        return [cam(self.camera, cid=5)]


class Renderer:
    """Draws exactly shadow_update each frame and remembers, per view, what it drew: the
    casters with their bounds and flags, the light's depth-shaping fields, the tier, the
    tile, the camera. Checks that a view not marked dirty still holds what it was drawn
    with, and that update_objects calls are seen."""

    def __init__(self, s: Any) -> None:
        self.s = s
        self.drawn: dict[tuple[Any, ...], dict[str, Any]] = {}
        self.named: dict[tuple[Any, ...], set[int]] = {}
        self.waited: dict[tuple[Any, ...], int] = {}  # frames a dirty view waited

    def name(self, ids: Any) -> None:
        for key in self.drawn:
            self.named.setdefault(key, set()).update(int(i) for i in ids)

    def truth(self, f: ls.Frame, cameras: list[ls.Camera]) -> dict[tuple[Any, ...], Any]:
        """What each view of the frame must show, from the scheduler's scene and the
        frame's caster lists."""
        s, cfg = self.s, self.s.config
        lights, objects = s.lights, s.objects
        row_of_obj = {int(i): r for r, i in enumerate(objects.id)}
        out = {}
        for j, lid in enumerate(f.shadow_lights.tolist()):
            r = int(np.flatnonzero(lights.id == lid)[0])
            typ = int(lights.type[r])
            if typ == DIRECTIONAL:
                light = (typ, tuple(lights.direction[r]))
            else:
                light = (typ, tuple(lights.position[r]), float(lights.radius[r]))
                if typ == 1:
                    light += (tuple(lights.direction[r]), float(lights.outer_angle[r]))
            a, b = f.caster_offsets[j], f.caster_offsets[j + 1]
            ids, masks = f.caster_ids[a:b], f.caster_masks[a:b]
            views = int(f.shadow_views[j])
            for bit in range(32):
                if not views >> bit & 1:
                    continue
                casters = {}
                for oid in ids[(masks >> np.uint32(bit)) & 1 == 1].tolist():
                    o = row_of_obj[oid]
                    casters[oid] = (tuple(objects.bounds_min[o]), tuple(objects.bounds_max[o]),
                                    bool(objects.casts_shadows[o]), int(objects.mask[o]),
                                    bool(objects.static[o]))
                if typ == DIRECTIONAL:
                    k, c = divmod(bit, cfg.cascades)
                    cm = cameras[k]
                    key = (lid, int(f.camera_ids[k]), c)
                    camera = (tuple(cm.position), tuple(cm.forward), tuple(cm.up), cm.fov_y,
                              cm.aspect, cm.near, cm.far, tuple(f.cascade_splits[k]))
                else:
                    key, camera = (lid, bit), None
                out[key] = dict(light=light, tier=int(f.shadow_tier[j]),
                                tile=tuple(f.shadow_rect[j, bit].tolist()), camera=camera,
                                casters=casters, j=j, bit=bit)
        return out

    def frame(self, cameras: list[ls.Camera]) -> tuple[ls.Frame, dict[tuple[Any, ...], Any]]:
        f = self.s.frame(cameras)
        truth = self.truth(f, cameras)
        live = set(f.shadow_lights.tolist())
        # A light that left shadow_lights forgets its views (so does the renderer).
        self.drawn = {k: v for k, v in self.drawn.items() if k[0] in live}
        assert (f.shadow_update & ~f.shadow_dirty).max(initial=0) == 0
        assert (f.shadow_static_dirty & ~f.shadow_dirty).max(initial=0) == 0
        assert (f.shadow_dirty & ~f.shadow_views).max(initial=0) == 0
        for key, now in truth.items():
            j, bit = now["j"], now["bit"]
            dirty = bool(f.shadow_dirty[j] >> bit & 1)
            update = bool(f.shadow_update[j] >> bit & 1)
            if not dirty:
                held = self.drawn.get(key)
                assert held is not None, f"view {key} clean but never drawn"
                for name in ("light", "tier", "tile", "camera", "casters"):
                    assert held[name] == now[name], f"view {key} clean but its {name} changed"
                seen = self.named.get(key, set()) & (held["casters"].keys()
                                                     | now["casters"].keys())
                assert not seen, f"view {key} clean but update_objects named {seen}"
                self.waited[key] = 0
            if update:
                self.drawn[key] = now
                self.named.pop(key, None)
                self.waited[key] = 0
            elif dirty:
                self.waited[key] = self.waited.get(key, 0) + 1
        return f, truth


@SCHEDULERS
@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("culling", ["camera", "light"])
def test_replay_no_budget_nothing_stale(seed, culling, cls):
    s = cls(ls.Config(caster_culling=culling, shadow_budget=6))
    scene = Scene(seed)
    scene.install(s)
    r = Renderer(s)
    for _ in range(12):
        f, _ = r.frame(scene.cameras())
        # B = 0: every dirty view is drawn this frame.
        assert f.shadow_update.tolist() == f.shadow_dirty.tolist()
        r.name(scene.step(s))


@SCHEDULERS
@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("budget", [1, 3, 8])
def test_replay_budget_draws_every_dirty_view_in_time(seed, budget, cls):
    """While the scene moves, nothing clean is stale and at most B point/spot views are
    drawn per frame; once it stops, the D dirty views left are all drawn within ceil(D/B)
    frames (the budget rule: B per frame, none added)."""
    s = cls(ls.Config(shadow_budget=6, shadow_update_budget=budget, caster_culling="light"))
    scene = Scene(seed)
    scene.install(s)
    r = Renderer(s)
    still = scene.cameras()
    for _ in range(10):
        f, truth = r.frame(still)
        local = sum(bin(int(f.shadow_update[v["j"]]) >> v["bit"] & 1).count("1")
                    for v in truth.values() if v["camera"] is None)
        assert local <= budget
        r.name(scene.step(s, move_camera=False))
    f, truth = r.frame(still)
    pending = sum(1 for v in truth.values() if v["camera"] is None
                  and (f.shadow_dirty[v["j"]] & ~f.shadow_update[v["j"]]) >> v["bit"] & 1)
    for _ in range(math.ceil(pending / budget)):
        f, _ = r.frame(still)
    assert not f.shadow_dirty.any() or not (f.shadow_dirty & ~f.shadow_update).any()
    f, _ = r.frame(still)
    assert not f.shadow_dirty.any(), "a still scene with everything drawn reports dirty views"


@SCHEDULERS
def test_nothing_moved_no_dirty_view(cls):
    s = cls(ls.Config(shadow_budget=6))
    scene = Scene(11)
    scene.install(s)
    f = s.frame(scene.cameras())
    assert f.shadow_dirty.tolist() == f.shadow_views.tolist()  # all new
    f = s.frame(scene.cameras())
    assert f.shadow_views.any() and not f.shadow_dirty.any() and not f.shadow_update.any()
    assert f.stats["counts"]["texels_rendered"] == 0


@SCHEDULERS
def test_budget_order_not_ready_first_then_age_times_importance(cls):
    """Two point lights, budget 6: the first frame draws the first light's six faces (not
    ready, shadow_lights order); the second the other's."""
    s = cls(ls.Config(shadow_update_budget=6))
    s.set_lights(id=[1, 2], position=[[0, 0, 10], [3, 0, 10]], radius=[4, 4],
                 intensity=[1, 2], shadows=[True, True])
    s.set_objects(id=[0], bounds_min=[[-5, -5, 8]], bounds_max=[[5, 5, 9]])
    f = s.frame([cam()])
    assert f.shadow_lights.tolist() == [2, 1]
    assert f.shadow_update.tolist() == [63, 0]
    # Light 1 is not ready: its map is not sampled.
    assert 1 not in [f.shadow_lights[i] for i in f.slot_shadow[f.slot_shadow >= 0]]
    f = s.frame([cam()])
    assert f.shadow_update.tolist() == [0, 63] and f.shadow_dirty.tolist() == [0, 63]
    assert sorted(f.shadow_lights[f.slot_shadow[0][f.slot_shadow[0] >= 0]].tolist()) == [1, 2]


@SCHEDULERS
def test_budget_lets_a_view_of_importance_at_most_0_wait_for_ever(cls):
    """DESIGN's budget order scores a ready view (1 + age) * max(importance, 0): a light
    whose importance is <= 0 (a negative priority) scores 0 however long it waits, so while
    another light's views go dirty every frame it is never drawn again, and its map stays
    stale for good. DESIGN as written; the order would need the age to count alone (or a
    floor on the score) for the wait to be bounded."""
    s = cls(ls.Config(shadow_update_budget=6))
    position = np.array([[0.0, 0.0, 10.0], [3.0, 0.0, 10.0]])
    s.set_lights(id=[1, 2], position=position, radius=[4, 4], intensity=[1, 2],
                 priority=[-100.0, 0.0], shadows=[True, True])
    s.set_objects(id=[0], bounds_min=[[-5, -5, 8]], bounds_max=[[5, 5, 9]])
    drawn_1 = []
    for frame in range(20):
        # Both lights move a little every frame: all twelve faces are dirty every frame.
        s.update_lights(id=[1, 2], position=position + [0.0, 0.01 * frame, 0.0])
        f = s.frame([cam()])
        at = {int(lid): i for i, lid in enumerate(f.shadow_lights)}
        assert set(at) == {1, 2}
        assert f.shadow_dirty[at[1]] == 63 and f.shadow_dirty[at[2]] == 63
        drawn_1.append(int(f.shadow_update[at[1]]))
    # Light 2's faces first, then light 1's (not ready), then light 2's for ever.
    assert drawn_1[:2] == [0, 63] and not any(drawn_1[2:])


@SCHEDULERS
def test_skip_light_with_unready_view_affects_nothing(cls):
    s = cls(ls.Config(shadow_update_budget=1, unshadowed="skip"))
    s.set_lights(id=[1], position=[[0, 0, 10]], radius=[4], shadows=[True])
    s.set_objects(id=[0], bounds_min=[[-1, -1, 8]], bounds_max=[[1, 1, 9]])
    for frame in range(5):
        f = s.frame([cam()])
        assert f.shadow_lights.tolist() == [1]
        assert f.count.tolist() == [0], f"frame {frame}: lit before its six faces are drawn"
    f = s.frame([cam()])  # the sixth face is drawn this frame: ready
    assert f.count.tolist() == [1] and f.slot_shadow[0, 0] == 0


@SCHEDULERS
def test_static_dirty_only_for_static_causes(cls):
    s = cls(ls.Config())
    s.set_lights(id=[1], type=[1], position=[[0, 0, 0]], direction=[[0, 0, 1]], radius=[30],
                 shadows=[True])
    s.set_objects(id=[0, 1], bounds_min=[[-1, -1, 8], [2, 2, 9]],
                  bounds_max=[[1, 1, 9], [3, 3, 10]], static=[True, False])
    f = s.frame([cam()])
    assert f.shadow_static_dirty.tolist() == [1]
    s.update_objects(id=[1], bounds_min=[[2, 2, 9.5]], bounds_max=[[3, 3, 10.5]])
    f = s.frame([cam()])
    assert f.shadow_dirty.tolist() == [1] and f.shadow_static_dirty.tolist() == [0]
    s.update_objects(id=[1], bounds_min=[[2, 2, 9.5]])  # re-sent as it is
    f = s.frame([cam()])
    assert f.shadow_dirty.tolist() == [1] and f.shadow_static_dirty.tolist() == [0]
    s.update_objects(id=[0], bounds_min=[[-1, -1, 8]])  # a static caster re-sent
    f = s.frame([cam()])
    assert f.shadow_dirty.tolist() == [1] and f.shadow_static_dirty.tolist() == [1]
    f = s.frame([cam()])
    assert f.shadow_dirty.tolist() == [0]


@SCHEDULERS
def test_light_culling_camera_moving_alone_dirties_no_local_view(cls):
    for seed in range(3):
        s = cls(ls.Config(caster_culling="light", shadow_budget=6))
        scene = Scene(seed)
        scene.install(s)
        last = s.frame(scene.cameras())
        for _ in range(8):
            scene.step(s, move_objects=0.0, move_lights=0.0, resend=0.0)
            f = s.frame(scene.cameras())
            before = {lid: (int(last.shadow_tier[j]), last.shadow_rect[j].tolist())
                      for j, lid in enumerate(last.shadow_lights.tolist())}
            for j, lid in enumerate(f.shadow_lights.tolist()):
                if s.lights.type[s.lights.id == lid][0] == DIRECTIONAL:
                    continue
                if before.get(lid) == (int(f.shadow_tier[j]), f.shadow_rect[j].tolist()):
                    assert f.shadow_dirty[j] == 0, f"light {lid} dirty by a camera move"
            last = f


def _check_atlas(f: ls.Frame, atlas: int, types: dict[int, int]) -> None:
    tiles = []
    for j, lid in enumerate(f.shadow_lights.tolist()):
        n = {0: 6, 1: 1, 2: 0}[types[lid]]
        for bit in range(6):
            x, y, size = f.shadow_rect[j, bit].tolist()
            if bit >= n:
                assert (x, y, size) == (-1, -1, -1)
                continue
            assert size == f.shadow_tier[j] and 0 <= x and 0 <= y
            assert x + size <= atlas and y + size <= atlas
            tiles.append((x, y, size))
    for a in range(len(tiles)):
        for b in range(a + 1, len(tiles)):
            (xa, ya, sa), (xb, yb, sb) = tiles[a], tiles[b]
            assert xa + sa <= xb or xb + sb <= xa or ya + sa <= yb or yb + sb <= ya, \
                f"tiles {tiles[a]} and {tiles[b]} overlap"


@SCHEDULERS
@pytest.mark.parametrize("seed", range(3))
def test_atlas_tiles_disjoint_inside_and_sticky(seed, cls):
    atlas = 4096
    s = cls(ls.Config(shadow_atlas_size=atlas, shadow_budget=12))
    rng = np.random.default_rng(seed)
    n = 14
    types = rng.choice([0, 0, 1], n)
    s.set_lights(id=np.arange(n), type=types, position=rng.uniform(-6, 6, (n, 3)) + [0, 0, 8],
                 radius=rng.uniform(1, 6, n), direction=np.tile([0, 0, 1.0], (n, 1)),
                 shadows=np.ones(n, bool))
    lo = rng.uniform(-10, 10, (30, 3)) + [0, 0, 10]
    s.set_objects(id=np.arange(30), bounds_min=lo, bounds_max=lo + 1)
    types_of = dict(enumerate(types.tolist()))
    position = np.zeros(3)
    last = None
    for _ in range(25):
        f = s.frame([cam(position)])
        _check_atlas(f, atlas, types_of)
        used = sum((6 if types_of[lid] == 0 else 1) * int(t) ** 2
                   for lid, t in zip(f.shadow_lights.tolist(), f.shadow_tier.tolist(), strict=True))
        assert used <= atlas * atlas
        if last is not None:
            now = dict(zip(f.shadow_lights.tolist(), f.shadow_tier.tolist(), strict=True))
            then = dict(zip(last.shadow_lights.tolist(), last.shadow_tier.tolist(), strict=True))
            if now == then:
                for j, lid in enumerate(f.shadow_lights.tolist()):
                    k = last.shadow_lights.tolist().index(lid)
                    assert f.shadow_rect[j].tolist() == last.shadow_rect[k].tolist()
                assert f.stats["counts"]["tiles_moved"] == 0
        last = f
        position = position + rng.normal(0, 1.5, 3)


@SCHEDULERS
def test_atlas_fit_lowers_tiers_from_the_back_and_drops_past_the_prefix(cls):
    s = cls(ls.Config(shadow_budget=8))
    # Camera inside every light: s_max = 1080 / tan(0.5) = 1977 px, tier 2048.
    s.set_lights(id=[1, 2, 3, 4], position=[[0, 0, 0.5 + i] for i in range(4)],
                 radius=[10] * 4, intensity=[4, 3, 2, 1], shadows=[True] * 4)
    s.set_objects(id=[0], bounds_min=[[-1, -1, 2]], bounds_max=[[1, 1, 3]])
    f = s.frame([cam()])
    assert f.shadow_lights.tolist() == [1, 2, 3, 4]
    # 4 x 6 x 2048^2 > 8192^2: the last light above 256 drops a tier at a time, so the
    # fourth goes down to 256 before the third drops (to 1024, where they fit).
    assert f.shadow_tier.tolist() == [2048, 2048, 1024, 256]
    _check_atlas(f, 8192, {1: 0, 2: 0, 3: 0, 4: 0})
    # No atlas: the tiers as the ranking made them.
    f = cls(ls.Config(shadow_budget=8, shadow_atlas_size=0))
    f.set_lights(**{k: getattr(s.lights, k) for k in ("id", "position", "radius",
                                                       "intensity", "shadows")})
    f.set_objects(id=[0], bounds_min=[[-1, -1, 2]], bounds_max=[[1, 1, 3]])
    g = f.frame([cam()])
    assert g.shadow_tier.tolist() == [2048] * 4 and (g.shadow_rect == -1).all()
    # 4096^2 holds 42 point lights at 256: the 43rd and after leave shadow_lights.
    n = 50
    s = cls(ls.Config(shadow_budget=60, shadow_atlas_size=4096))
    s.set_lights(id=np.arange(n), position=[[0, 0, 5]] * n, radius=[1] * n,
                 intensity=np.linspace(2, 1, n), shadows=[True] * n)
    s.set_objects(id=[0], bounds_min=[[-1, -1, 4]], bounds_max=[[1, 1, 6]])
    f = s.frame([cam()])
    assert f.shadow_lights.tolist() == list(range(42))
    assert sum(6 * int(t) ** 2 for t in f.shadow_tier) <= 4096 ** 2


@SCHEDULERS
def test_directional_views_follow_camera_ids(cls):
    s = cls(ls.Config(cascades=2))
    s.set_lights(id=[1], type=[2], direction=[[0, -1, 0]], shadows=[True])
    s.set_objects(id=[0], bounds_min=[[-1, -1, 8]], bounds_max=[[1, 1, 9]])
    a, b = cam((0, 0, 0), cid=7), cam((5, 0, 0), cid=3)
    f = s.frame([a, b])
    assert f.camera_ids.tolist() == [7, 3] and f.shadow_views.tolist() == [0b1111]
    f = s.frame([b, a])
    assert f.camera_ids.tolist() == [3, 7] and f.shadow_dirty.tolist() == [0]
    f = s.frame([b, cam((1, 0, 0), cid=7)])
    assert f.shadow_dirty.tolist() == [0b1100] and f.shadow_update.tolist() == [0b1100]


@pytest.mark.parametrize("field,value", [("shadow_update_budget", -1),
                                         ("shadow_update_budget", 2**31),
                                         ("shadow_atlas_size", 2048),
                                         ("shadow_atlas_size", 5000),
                                         ("shadow_atlas_size", 131072),
                                         ("caster_culling", "lights")])
def test_config_rejects(field, value):
    with pytest.raises(ls.ValidationError) as e:
        ls.Config(**{field: value})
    assert e.value.field == field


def test_config_accepts():
    for v in (0, 4096, 8192, 65536):
        assert ls.Config(shadow_atlas_size=v).shadow_atlas_size == v
    assert ls.Config(shadow_update_budget=2**31 - 1).shadow_update_budget == 2**31 - 1


@pytest.mark.parametrize("culling", ["camera", "light"])
@pytest.mark.parametrize("seed", range(3))
def test_patched_and_kept_caster_lists_match_oracle(seed, culling, tuning):
    """A few objects move each frame, the camera every other frame, the lights never: the
    fast path patches its point and spot caster lists at the moved objects (a grid of
    just them) and, under caster_culling "light", keeps them across camera moves. Every
    frame equals the oracle's, and the plan says which lists were patched or kept."""
    scene = Scene(seed, n_lights=9, n_objects=80)
    t = Twin(ls.Config(caster_culling=culling, shadow_budget=6, shadow_update_budget=4),
             tuning=tuning)
    scene.install(t)
    t.frame(scene.cameras())
    plans = []
    for i in range(14):
        scene.step(t, move_objects=0.06, move_lights=0.0, move_camera=i % 2 == 1,
                   resend=0.02)
        f, _ = t.frame(scene.cameras())
        plans.append(f.stats["plan"]["casters"])
    assert t.compared == t.frames, "a near-tie cut the comparison short"
    assert any("point/spot: the" in p and "changed objects only" in p for p in plans), plans
    across = [p for p in plans[1::2] if "do not depend on the cameras" in p]
    assert bool(across) == (culling == "light"), plans


def test_no_shadow_light_skips_the_view_pass_with_its_result():
    """With no shadow light and no view remembered the views stage skips view_pass: what it
    gives instead is what the pass gives (run_views, the general case, on the same frame)."""
    from lightsched.shadow_views import run_views

    scene = Scene(3)
    scene.lights["shadows"] = np.zeros(scene.n_lights, bool)
    s = ls.Scheduler()
    scene.install(s)
    for _ in range(3):
        cams = [cam(scene.camera, cid=5), cam(scene.camera + 1.0)]
        frame = s.frame(cams, dt=0.016)
        last = s._last
        assert last is not None and frame.stats["plan"]["views"] == "skipped: no shadow lights"
        quick = last.views
        general, seen = run_views(None, last.shadows, last.casters, s.lights, s.objects,
                                  last.cameras, cams, s.config)
        assert seen is last.shadows
        for field in ("views", "dirty", "static_dirty", "update", "rect", "camera_ids",
                      "ready"):
            a, b = getattr(quick, field), getattr(general, field)
            assert a.dtype == b.dtype and np.array_equal(a, b), field
        for a, b in zip(quick.memory, general.memory, strict=True):
            assert a.dtype == b.dtype and a.shape == b.shape
        assert (quick.tiles, quick.quiet, quick.tiles_moved, quick.texels, quick.how) == (
            general.tiles, general.quiet, general.tiles_moved, general.texels, general.how)
        scene.step(s)
