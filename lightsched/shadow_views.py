"""The shadow views stage (DESIGN section 2, "Shadow views, updates and the atlas"): per
shadow light its views, their atlas tiles, which views are dirty (and whether their static
layer is), which are rendered this frame within shadow_update_budget, and which lights have
every view ready to be sampled.

Runs after the casters stage and before the pair cache: readiness decides slot_shadow
(ShadowSet.shadow_of_row) and, with unshadowed = "skip", which shadow lights may light
anything (ShadowSet.live); the ShadowSet it returns is the one the rest of the frame sees.
Its memory (``ShadowViews.held``: what each view held when last rendered, its age, whether
it is ready) is the next frame's input, never changed after the stage returns it: a view
that changes gets a new record.

The fit rule is shadows.fit_atlas; the tile allocator is ``allocate_tiles`` here, the one
definition of it (the oracle, lightsched.reference, holds the deliberate second copy).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import numpy as np

from .casters import Casters
from .frustum import Cameras
from .scene import DIRECTIONAL, SPOT, Camera, Config, LightStore, ObjectStore
from .shadows import MIN_TIER, ShadowSet

# Columns of a view's caster values: bounds_min (3), bounds_max (3), casts_shadows, mask,
# static, all exact in float64 (a uint32 mask is).
_STATIC = 8


@dataclass(frozen=True, slots=True)
class ViewRecord:
    """One view's memory. ``light``, ``tier``, ``tile``, ``camera``: what it was rendered
    with (None for a view never rendered: then ``ids`` and ``values`` are empty);
    ``ids`` (ascending) and ``values`` [m, 9]: its casters then; ``ready``: its map holds
    it at its current tier and tile; ``age``: consecutive frames it was dirty and not
    rendered; ``named`` / ``named_static``: an update_objects call named one of its
    (static) casters since it was rendered; ``placed``: its (tier, tile) last frame."""

    light: Any
    tier: int
    tile: Any
    camera: Any
    ids: np.ndarray
    values: np.ndarray
    ready: bool
    age: int
    named: bool
    named_static: bool
    placed: Any
    rendered: bool


_NEVER = ViewRecord(None, 0, None, None, np.zeros(0, np.int32), np.zeros((0, 9)), False, 0,
                    False, False, None, False)


@dataclass(slots=True)
class ShadowViews:
    """The views stage's output: shadow_views, shadow_dirty, shadow_static_dirty,
    shadow_update ([S] uint32), shadow_rect ([S, 6, 3] int32), camera_ids; per shadow light
    whether every view is ready; the memory of every view by key ((light id, bit) for
    point and spot views, (light id, camera id, cascade) for directional ones) and of the
    atlas tiles by point/spot key; ``quiet``: no view was dirty (the next frame may then be
    "unchanged"); the stats counts; the plan's entry."""

    views: np.ndarray
    dirty: np.ndarray
    static_dirty: np.ndarray
    update: np.ndarray
    rect: np.ndarray
    camera_ids: np.ndarray
    ready: np.ndarray
    held: dict[tuple[int, ...], ViewRecord]
    tiles: dict[tuple[int, int], tuple[int, int, int]]
    quiet: bool
    tiles_moved: int
    texels: int
    how: str


def camera_ids(cameras: list[Camera]) -> np.ndarray:
    """The ids the frame runs with: a camera's own, or its position in the list."""
    return np.array([k if c.id is None else int(c.id) for k, c in enumerate(cameras)], np.int32)


def first_fit(tiles: list[tuple[int, int, int]], atlas: int, size: int
              ) -> tuple[int, int] | None:
    """Lowest square of ``size`` in Morton order (quadrants x first: (0, 0), (1, 0),
    (0, 1), (1, 1)) at a multiple of ``size`` that no tile of ``tiles`` overlaps. Tiles are
    aligned power-of-two squares, so each either covers a quadtree node, lies inside it or
    misses it; a depth-first walk with an explicit stack of (x, y, s, tiles inside)."""
    stack = [(0, 0, atlas, tiles)]
    while stack:
        x, y, s, inside = stack.pop()
        if not inside:
            return x, y
        if s == size or max(t[2] for t in inside) >= s:
            continue
        h = s // 2
        # Pushed in reverse so that (0, 0) is walked first.
        for qx, qy in ((x + h, y + h), (x, y + h), (x + h, y), (x, y)):
            stack.append((qx, qy, h, [t for t in inside if t[0] < qx + h and qx < t[0] + t[2]
                                      and t[1] < qy + h and qy < t[1] + t[2]]))
    return None


def allocate_tiles(wanted: list[tuple[tuple[int, int], int, tuple[int, int]]],
                   last: dict[tuple[int, int], tuple[int, int, int]], atlas: int
                   ) -> dict[tuple[int, int], tuple[int, int, int]]:
    """The atlas tiles (x, y, size) of the point and spot views ``wanted`` = (key, tier,
    (shadow index, bit)), which fit (DESIGN "Atlas"). Sticky: a view keeps last frame's
    tile while its tier holds, so nothing moves while the shadow lights and their tiers
    do. New and re-tiered views go largest first, then in shadow_lights order and bit, to
    the first free aligned square in Morton order (``first_fit``), as a buddy allocator
    would. Only when fragmentation leaves one of them no room is everything packed again
    from an empty atlas the same way, which always fits what the fit rule admits (squares
    of descending power-of-two sizes fill Morton order without gaps)."""
    tiles = {key: last[key] for key, size, _ in wanted
             if key in last and last[key][2] == size}
    todo = sorted((t for t in wanted if t[0] not in tiles), key=lambda t: (-t[1], t[2]))
    for key, size, _ in todo:
        at = first_fit(list(tiles.values()), atlas, size)
        if at is None:
            break
        tiles[key] = (at[0], at[1], size)
    else:
        return tiles
    tiles = {}
    for key, size, _ in sorted(wanted, key=lambda t: (-t[1], t[2])):
        at = first_fit(list(tiles.values()), atlas, size)
        if at is None:
            raise AssertionError("the fit rule admitted views the atlas cannot hold")
        tiles[key] = (at[0], at[1], size)
    return tiles


def _caster_change(then: ViewRecord, ids: np.ndarray, values: np.ndarray) -> tuple[bool, bool]:
    """(a non-static caster joined, left or changed; a static one did): static means
    static now or when the view was rendered."""
    if then.ids.size == ids.size and np.array_equal(then.ids, ids):
        differ = ~(then.values == values).all(axis=1)
        if not differ.any():
            return False, False
        static = (then.values[differ, _STATIC] != 0) | (values[differ, _STATIC] != 0)
    else:
        _, ia, ib = np.intersect1d(then.ids, ids, assume_unique=True, return_indices=True)
        gone = np.ones(then.ids.size, np.bool_)
        gone[ia] = False
        came = np.ones(ids.size, np.bool_)
        came[ib] = False
        differ = ~(then.values[ia] == values[ib]).all(axis=1)
        static = np.concatenate([then.values[gone, _STATIC] != 0, values[came, _STATIC] != 0,
                                 (then.values[ia[differ], _STATIC] != 0)
                                 | (values[ib[differ], _STATIC] != 0)])
    return bool((~static).any()), bool(static.any())


def _present(sorted_ids: np.ndarray, probe: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(which ids of ``probe`` are in ``sorted_ids``, their positions there, clipped):
    a binary search, where np.isin costs several times more on these short arrays."""
    if sorted_ids.size == 0:
        return np.zeros(probe.size, np.bool_), np.zeros(probe.size, np.int64)
    pos = np.minimum(np.searchsorted(sorted_ids, probe), sorted_ids.size - 1)
    return sorted_ids[pos] == probe, pos


def _named_causes(then: ViewRecord, ids: np.ndarray, named: np.ndarray,
                  named_static: np.ndarray) -> tuple[bool, bool]:
    """(a non-static, a static) caster of the view, then or now, among the ids an
    update_objects call named since last frame (``named``, ascending, with whether each is
    static now); static counts as when the view was rendered too."""
    was_held, pos = _present(then.ids, named)
    hit = was_held | _present(ids, named)[0]
    if not hit.any():
        return False, False
    static = named_static.copy()
    static[was_held] |= then.values[pos[was_held], _STATIC] != 0
    static = static[hit]
    return bool((~static).any()), bool(static.any())


def update_views(last: ShadowViews | None, shadows: ShadowSet, casters: Casters,
                 lights: LightStore, objects: ObjectStore, cams: Cameras,
                 cameras: list[Camera], config: Config) -> tuple[ShadowViews, ShadowSet]:
    """The views stage (DESIGN section 2, "Shadow views, updates and the atlas"). Returns
    its output and the ShadowSet the rest of the frame uses: slot_shadow samples only
    lights whose views are all ready, and with unshadowed = "skip" a shadow light with a
    view not ready lights nothing."""
    atlas, n_casc = config.shadow_atlas_size, config.cascades
    ids_cam = camera_ids(cameras)
    held_last = {} if last is None else last.held
    tiles_last = {} if last is None else last.tiles
    shadow_ids = shadows.ids.tolist()
    rows = shadows.rows.tolist()
    tiers = shadows.tier.tolist()
    types = lights.type[shadows.rows].tolist()
    n_s = len(shadow_ids)

    wanted = [((lid, bit), tiers[j], (j, bit)) for j, lid in enumerate(shadow_ids)
              if types[j] != DIRECTIONAL for bit in range(1 if types[j] == SPOT else 6)]
    tiles = allocate_tiles(wanted, tiles_last, atlas) if atlas and wanted else {}
    moved = sum(1 for key, t in tiles.items() if key in tiles_last and tiles_last[key] != t)

    named = np.unique(np.concatenate(objects.named)) if objects.named else np.zeros(0, np.int32)
    named_static = np.zeros(named.size, np.bool_)
    if named.size:
        pos = np.minimum(np.searchsorted(objects.id, named), max(len(objects) - 1, 0))
        exists = objects.id[pos] == named if len(objects) else np.zeros(named.size, np.bool_)
        named_static[exists] = objects.static[pos[exists]]
    cam_state = [(*(tuple(np.asarray(v, np.float64).tolist())
                    for v in (c.position, c.forward, c.up)),
                  float(c.fov_y), float(c.aspect), float(c.near), float(c.far),
                  tuple(cams.splits[k].tolist())) for k, c in enumerate(cameras)]

    views = np.zeros(n_s, np.uint32)
    dirty = np.zeros(n_s, np.uint32)
    static_dirty = np.zeros(n_s, np.uint32)
    rect = np.full((n_s, 6, 3), -1, np.int32)
    # Per view: (j, bit, key, record before rendering, state now, dirty, directional).
    entries: list[tuple[Any, ...]] = []
    live_ids = set(shadow_ids)
    # Views of a shadow light survive; a directional light's views of cameras absent this
    # frame too (a split screen comes back); a light that left forgets them.
    held = {key: rec for key, rec in held_last.items() if key[0] in live_ids}
    for j, lid in enumerate(shadow_ids):
        r = rows[j]
        typ = types[j]
        found_rows, found_masks = casters.by_light[r]
        c_ids = objects.id[found_rows]
        values = np.empty((found_rows.size, 9))
        values[:, 0:3] = objects.bounds_min[found_rows]
        values[:, 3:6] = objects.bounds_max[found_rows]
        values[:, 6] = objects.casts_shadows[found_rows]
        values[:, 7] = objects.mask[found_rows]
        values[:, 8] = objects.static[found_rows]
        if typ == DIRECTIONAL:
            light: tuple[Any, ...] = (typ, tuple(lights.direction[r].tolist()))
            bits = [(k * n_casc + c, (lid, int(ids_cam[k]), c), cam_state[k])
                    for k in range(len(cameras)) for c in range(n_casc)]
        else:
            light = (typ, tuple(lights.position[r].tolist()), float(lights.radius[r]))
            if typ == SPOT:
                light += (tuple(lights.direction[r].tolist()), float(lights.outer_angle[r]))
            bits = [(bit, (lid, bit), None) for bit in range(1 if typ == SPOT else 6)]
        for bit, key, camera in bits:
            on = (found_masks >> np.uint32(bit)) & 1 == 1
            v_ids, v_values = c_ids[on], values[on]
            tile = tiles.get(key)
            if tile is not None:
                rect[j, bit] = tile
            rec = held.get(key, _NEVER)
            placed = (tiers[j], tile)
            if rec.placed != placed:
                # A new tile or tier holds nothing of the view until it is drawn there.
                rec = dataclasses.replace(rec, ready=False, placed=placed)
            if not rec.rendered:
                is_dirty = is_static = True
            else:
                is_static = (rec.light != light or rec.tier != tiers[j] or rec.tile != tile
                             or rec.camera != camera)
                dyn, stat = _caster_change(rec, v_ids, v_values)
                is_static = is_static or stat
                if named.size:
                    n_dyn, n_stat = _named_causes(rec, v_ids, named, named_static)
                    if (n_dyn and not rec.named) or (n_stat and not rec.named_static):
                        rec = dataclasses.replace(rec, named=rec.named or n_dyn,
                                                  named_static=rec.named_static or n_stat)
                is_static = is_static or rec.named_static
                is_dirty = is_static or dyn or rec.named
            held[key] = rec
            views[j] |= np.uint32(1 << bit)
            if is_dirty:
                dirty[j] |= np.uint32(1 << bit)
                if is_static:
                    static_dirty[j] |= np.uint32(1 << bit)
                entries.append((j, bit, key, rec, (light, tiers[j], tile, camera, v_ids,
                                                   v_values), typ == DIRECTIONAL))

    update = np.zeros(n_s, np.uint32)
    local = [e for e in entries if not e[5]]
    budget = config.shadow_update_budget
    if budget and len(local) > budget:
        # Not ready first (shadow_lights order, bit), then (1 + age) max(importance, 0)
        # descending, age descending, shadow_lights order, bit.
        j_of = np.array([e[0] for e in local], np.int64)
        bit_of = np.array([e[1] for e in local], np.int64)
        ready = np.array([e[3].ready for e in local], np.bool_)
        age = np.array([e[3].age for e in local], np.int64)
        age = np.where(ready, age, 0)
        score = np.where(ready, (1 + age) * np.maximum(shadows.importance[j_of], 0.0), 0.0)
        order = np.lexsort((bit_of, j_of, -age, -score, ready))[:budget]
        chosen = {(int(j_of[i]), int(bit_of[i])) for i in order}
    else:
        chosen = {(e[0], e[1]) for e in local}
    texels = 0
    drawn = set()
    for j, bit, key, rec, state, directional in entries:
        if directional or (j, bit) in chosen:
            light, tier, tile, camera, v_ids, v_values = state
            held[key] = ViewRecord(light, tier, tile, camera, v_ids, v_values, True, 0, False,
                                   False, rec.placed, True)
            update[j] |= np.uint32(1 << bit)
            texels += tier * tier
            drawn.add(key)
        else:
            held[key] = dataclasses.replace(rec, age=rec.age + 1)
    # A clean view's age is 0.
    for j, lid in enumerate(shadow_ids):
        clean = int(views[j]) & ~int(dirty[j])
        if clean:
            for bit in range(32):
                if clean >> bit & 1:
                    key = ((lid, int(ids_cam[bit // n_casc]), bit % n_casc)
                           if types[j] == DIRECTIONAL else (lid, bit))
                    if held[key].age:
                        held[key] = dataclasses.replace(held[key], age=0)
    ready_light = np.ones(n_s, np.bool_)
    for j, lid in enumerate(shadow_ids):
        if types[j] != DIRECTIONAL:
            ready_light[j] = all(held[(lid, bit)].ready
                                 for bit in range(1 if types[j] == SPOT else 6))
    out = ShadowViews(views, dirty, static_dirty, update, rect, ids_cam, ready_light, held,
                      tiles, not dirty.any(), moved, texels,
                      _how(n_s, int(np.count_nonzero(dirty)), len(drawn), moved))
    return out, sampled(shadows, ready_light, lights, config)


def _how(n_s: int, dirty_lights: int, drawn: int, moved: int) -> str:
    if n_s == 0:
        return "skipped: no shadow lights"
    return (f"{dirty_lights} of {n_s} shadow lights with dirty views, {drawn} views to render, "
            f"{moved} tiles moved")


def sampled(shadows: ShadowSet, ready: np.ndarray, lights: LightStore, config: Config
            ) -> ShadowSet:
    """The ShadowSet the slots see (DESIGN "Sampling"): slot_shadow's map index only for
    lights whose every view is ready; with unshadowed = "skip", a shadow light with a view
    not ready lights nothing this frame."""
    if ready.all():
        return shadows
    shadow_of_row = shadows.shadow_of_row.copy()
    shadow_of_row[shadows.rows[~ready]] = -1
    live = shadows.live
    if config.unshadowed == "skip":
        live = live.copy()
        live[shadows.rows[~ready]] = False
    return dataclasses.replace(shadows, shadow_of_row=shadow_of_row, live=live)


__all__ = ["MIN_TIER", "ShadowViews", "ViewRecord", "allocate_tiles", "camera_ids",
           "first_fit", "sampled", "update_views"]
