"""The shadow views stage (DESIGN section 2, "Shadow views, updates and the atlas"): per
shadow light its views, their atlas tiles, which views are dirty (and whether their static
layer is), which are rendered this frame within shadow_update_budget, and which lights have
every view ready to be sampled.

Runs after the casters stage and before the pair cache: readiness decides slot_shadow
(ShadowSet.shadow_of_row) and, with unshadowed = "skip", which shadow lights may light
anything (ShadowSet.live); the ShadowSet it returns is the one the rest of the frame sees.
Its memory (``ShadowViews.memory``: what each view held when last rendered, its age,
whether it is ready) is the next frame's input, never changed after the stage returns it:
each frame writes a new one.

The dirty test, the budget order and readiness are one numba kernel over every view of
every shadow light (``view_pass``), the only definition of those rules in the fast path
(the oracle, lightsched.reference, holds the deliberate second copy). The fit rule is
shadows.fit_atlas; the tile allocator is ``allocate_tiles`` here.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import NamedTuple

import numba as nb
import numpy as np

from .casters import Casters
from .frustum import Cameras
from .scene import DIRECTIONAL, SPOT, Camera, Config, LightStore, ObjectStore
from .shadows import MIN_TIER, ShadowSet

# A view's caster values, one row a caster: bounds_min (3), bounds_max (3), casts_shadows,
# mask, static, all exact in float64 (a uint32 mask is).
N_VALUES = 9
_STATIC = 8
# A light as its views remember it: type, position (3), radius, direction (3),
# outer_angle; what its type's depth does not depend on stays 0 (point: no direction or
# angle; directional: direction only).
N_LIGHT = 9
# A camera as its directional views remember it: position, forward, up (3 each), fov_y,
# aspect, near, far; its cascade_splits follow.
N_CAMERA = 13


class ViewMemory(NamedTuple):
    """Every remembered view (DESIGN "Dirty"), row m one view: what it held when last
    rendered, and its state since. Views of a light that left shadow_lights are dropped."""

    key: np.ndarray           # int64 [M, 4]: light id, 1 directional (else 0), camera id
    #                           (directional; else 0), bit (point/spot) or cascade
    order: np.ndarray         # int64 [M]: the rows by ascending key (``_find`` searches it)
    light: np.ndarray         # float64 [M, N_LIGHT]: the light rendered with
    tier: np.ndarray          # int64 [M]: the tier rendered at
    tile: np.ndarray          # int64 [M, 3]: the tile (x, y, size) rendered in; -1: none
    camera: np.ndarray        # float64 [M, N_CAMERA + C + 1]: the camera (directional)
    placed: np.ndarray        # int64 [M, 4]: last frame's tier and tile; tier -1: never
    rendered: np.ndarray      # bool [M]: rendered at least once (else the above are unset)
    ready: np.ndarray         # bool [M]: its map holds it at its current tier and tile
    age: np.ndarray           # int64 [M]: consecutive frames dirty and not rendered
    named: np.ndarray         # bool [M]: update_objects named a caster of it since rendered
    named_static: np.ndarray  # bool [M]: ... a static one (then or now)
    cast_at: np.ndarray       # int64 [M + 1]: view m's casters are cast_at[m]..[m + 1] - 1
    cast_ids: np.ndarray      # int64 [m]: their ids, ascending per view
    cast_values: np.ndarray   # float64 [m, N_VALUES]: their values when rendered


class ViewLights(NamedTuple):
    """The shadow lights in rank order (index j) and the light store's columns."""

    rows: np.ndarray         # int64 [S]: store rows
    ids: np.ndarray          # int64 [S]
    tier: np.ndarray         # int64 [S]: shadow_tier
    importance: np.ndarray   # float64 [S]: the ranking's, without the hysteresis bonus
    rect: np.ndarray         # int32 [S, 6, 3]: the atlas tile of each view, -1: none
    type: np.ndarray         # the store's columns, by store row
    position: np.ndarray
    radius: np.ndarray
    direction: np.ndarray
    outer_angle: np.ndarray


class ViewCasters(NamedTuple):
    """The casters stage's lists: light j's casters at offsets[j]..offsets[j + 1] - 1."""

    offsets: np.ndarray  # int64 [S + 1]
    rows: np.ndarray     # int64: object store rows, ascending per light
    masks: np.ndarray    # uint32: caster_masks


class ViewObjects(NamedTuple):
    """The object store's columns a view's casters are compared on, by store row."""

    id: np.ndarray
    bounds_min: np.ndarray
    bounds_max: np.ndarray
    casts_shadows: np.ndarray
    mask: np.ndarray
    static: np.ndarray


class ViewCameras(NamedTuple):
    """This frame's cameras in list order (k) as their directional views remember them."""

    ids: np.ndarray    # int64 [K]: camera_ids
    state: np.ndarray  # float64 [K, N_CAMERA + C + 1]


class NamedIds(NamedTuple):
    """The object ids update_objects calls named since last frame."""

    ids: np.ndarray     # int64, ascending, unique
    static: np.ndarray  # bool: the object is static now (False: no longer in the store)


class ViewState(NamedTuple):
    """view_pass' findings per view of this frame (index v; views in shadow_lights order,
    then bit), before rendering."""

    light: np.ndarray         # int64: its light's index in shadow_lights
    bit: np.ndarray           # int64: its bit in shadow_views
    key: np.ndarray           # int64 [V, 4]: its key, as ViewMemory.key
    camera: np.ndarray        # int64: its camera's position in the list (directional), -1
    memory_row: np.ndarray    # int64: its row in last frame's memory, -1: none
    tile: np.ndarray          # int64 [V, 3]: its atlas tile now, -1: none
    ready: np.ndarray         # bool: ready (before this frame's rendering)
    age: np.ndarray           # int64: its age before this frame
    named: np.ndarray         # bool: ViewMemory.named, this frame's names included
    named_static: np.ndarray  # bool
    dirty: np.ndarray         # bool
    chosen: np.ndarray        # bool: in shadow_update


class ViewPass(NamedTuple):
    """view_pass' output: per shadow light its bits (uint32 [S]) and whether every view is
    ready (bool [S]); the views rendered and their texels; the next frame's memory (its
    ``order`` still to be set)."""

    views: np.ndarray
    dirty: np.ndarray
    static_dirty: np.ndarray
    update: np.ndarray
    ready: np.ndarray
    drawn: int
    texels: int
    memory: ViewMemory


@dataclass(slots=True)
class ShadowViews:
    """The views stage's output: shadow_views, shadow_dirty, shadow_static_dirty,
    shadow_update ([S] uint32), shadow_rect ([S, 6, 3] int32), camera_ids; per shadow light
    whether every view is ready; the memory of every view and of the atlas tiles by
    point/spot key (light id, bit), with the shadow lights' (ids, tiers, types) they were
    allocated for; ``quiet``: no view was dirty (the next frame may then be "unchanged");
    the stats counts; the plan's entry."""

    views: np.ndarray
    dirty: np.ndarray
    static_dirty: np.ndarray
    update: np.ndarray
    rect: np.ndarray
    camera_ids: np.ndarray
    ready: np.ndarray
    memory: ViewMemory
    tiles: dict[tuple[int, int], tuple[int, int, int]]
    placement: tuple[np.ndarray, np.ndarray, np.ndarray] | None
    quiet: bool
    tiles_moved: int
    texels: int
    how: str


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


@nb.njit(cache=True, nogil=True, inline="always")
def _key_less(a: np.ndarray, b: np.ndarray) -> bool:
    """a < b for two view keys a, b [4] (ViewMemory.key's layout), lexicographically."""
    for i in range(4):
        if a[i] != b[i]:
            return a[i] < b[i]
    return False


@nb.njit(cache=True, nogil=True, inline="always")
def _find(memory, key):
    """The row of ``memory`` (ViewMemory) that remembers view ``key`` [4] (its layout:
    DESIGN section 2, "Shadow views": a directional view is remembered by light id, camera
    id and cascade, a point or spot view by light id and bit), -1 if none: a binary search
    of memory.order, the rows by ascending key."""
    keys, order = memory.key, memory.order
    lo, hi = 0, order.shape[0]
    while lo < hi:
        mid = (lo + hi) // 2
        if _key_less(keys[order[mid]], key):
            lo = mid + 1
        else:
            hi = mid
    if lo < order.shape[0]:
        m = order[lo]
        if (keys[m, 0] == key[0] and keys[m, 1] == key[1] and keys[m, 2] == key[2]
                and keys[m, 3] == key[3]):
            return m
    return -1


@nb.njit(cache=True, nogil=True, inline="always")
def _caster_causes(memory, m, objects, now, named):
    """Which caster changes dirty view m of ``memory`` (DESIGN section 2, "Dirty"), against
    its casters now: ``now`` the object store rows (ascending, so ascending ids) of
    ``objects`` (ViewObjects); named: NamedIds. Returns (a non-static caster joined, left or
    changed; a static one did; update_objects named a non-static caster of it, then or now;
    a static one): static means static now or when the view was rendered."""
    ids, values = memory.cast_ids, memory.cast_values
    a, a_end = memory.cast_at[m], memory.cast_at[m + 1]
    b, b_end = 0, now.shape[0]
    # The union of both lists comes in ascending id: the named ids are walked along it.
    names, p = named.ids, 0
    dyn = stat = n_dyn = n_stat = False
    while a < a_end or b < b_end:
        then_id = ids[a] if a < a_end else np.int64(2**62)
        if b < b_end:
            o = now[b]
            now_id = np.int64(objects.id[o])
        else:
            o = -1
            now_id = np.int64(2**62)
        held = then_id <= now_id
        here = now_id <= then_id
        was_static = held and values[a, _STATIC] != 0
        is_static = here and objects.static[o]
        differ = held != here
        if held and here:
            vals = (objects.bounds_min[o, 0], objects.bounds_min[o, 1], objects.bounds_min[o, 2],
                    objects.bounds_max[o, 0], objects.bounds_max[o, 1], objects.bounds_max[o, 2],
                    np.float64(objects.casts_shadows[o]), np.float64(objects.mask[o]),
                    np.float64(objects.static[o]))
            for i in range(N_VALUES):
                differ = differ or values[a, i] != vals[i]
        if differ:
            if was_static or is_static:
                stat = True
            else:
                dyn = True
        oid = then_id if held else now_id
        while p < names.shape[0] and names[p] < oid:
            p += 1
        if p < names.shape[0] and names[p] == oid:
            if named.static[p] or was_static:
                n_stat = True
            else:
                n_dyn = True
        if held:
            a += 1
        if here:
            b += 1
    return dyn, stat, n_dyn, n_stat


@nb.njit(cache=True, nogil=True, inline="always")
def _light_state(lights, r, out):
    """out [N_LIGHT] = the light of store row r as its views remember it (DESIGN "Dirty":
    point: position, radius; spot: also direction and outer_angle; directional:
    direction), after its type."""
    typ = lights.type[r]
    out[:] = 0.0
    out[0] = typ
    if typ != DIRECTIONAL:
        for i in range(3):
            out[1 + i] = lights.position[r, i]
        out[4] = lights.radius[r]
    if typ != DIRECTIONAL and typ != SPOT:
        return
    for i in range(3):
        out[5 + i] = lights.direction[r, i]
    if typ == SPOT:
        out[8] = lights.outer_angle[r]


@nb.njit(cache=True, nogil=True)
def _budget_pick(local, ready, age, score, budget):
    """The point and spot views rendered within shadow_update_budget (DESIGN "Budget"):
    of the dirty views ``local`` (view indices in shadow_lights order, then bit) those not
    ready first, in that order, then by ``score`` = (1 + age) max(importance, 0)
    descending, ``age`` descending, then that order; the first ``budget``. ready, age,
    score: per view. Stable sorts, the least significant key first."""
    n = local.shape[0]
    neg_age = np.empty(n)
    neg_score = np.empty(n)
    not_first = np.empty(n, np.int64)
    for i in range(n):
        v = local[i]
        neg_age[i] = -age[v] if ready[v] else 0.0
        neg_score[i] = -score[v] if ready[v] else 0.0
        not_first[i] = 1 if ready[v] else 0
    order = np.argsort(neg_age, kind="mergesort")
    order = order[np.argsort(neg_score[order], kind="mergesort")]
    order = order[np.argsort(not_first[order], kind="mergesort")]
    return local[order[:budget]]


@nb.njit(cache=True, nogil=True)
def view_pass(lights, casters, objects, cameras, named, memory, n_casc, budget):
    """The views stage's rules over every view of every shadow light at once (DESIGN
    section 2, "Shadow views, updates and the atlas": the views, "Dirty", "Ready",
    "Budget"; section 3: shadow_views, shadow_dirty, shadow_static_dirty, shadow_update).

    lights: ViewLights (the shadow lights in rank order, their tiers, importance and
    atlas tiles, and the light store's columns); casters: ViewCasters (this frame's lists
    in rank order); objects: ViewObjects (the store's columns the casters are compared
    on); cameras: ViewCameras (this frame's camera ids and states, list order); named:
    NamedIds (ids update_objects named since last frame); memory: last frame's ViewMemory;
    n_casc: Config.cascades; budget: Config.shadow_update_budget (0: no budget). Returns a
    ViewPass, whose memory holds this frame's views (rendered ones as rendered now) and
    last frame's views of shadow lights whose view is not among them (a directional
    light's views of a camera absent this frame), its ``order`` unset."""
    n_s = lights.rows.shape[0]
    n_cam = cameras.ids.shape[0]
    n_v = 0
    for j in range(n_s):
        typ = lights.type[lights.rows[j]]
        n_v += n_cam * n_casc if typ == DIRECTIONAL else (1 if typ == SPOT else 6)
    vj = np.empty(n_v, np.int64)
    vbit = np.empty(n_v, np.int64)
    vkey = np.zeros((n_v, 4), np.int64)
    vcam = np.full(n_v, -1, np.int64)
    v = 0
    for j in range(n_s):
        typ = lights.type[lights.rows[j]]
        if typ == DIRECTIONAL:
            for k in range(n_cam):
                for c in range(n_casc):
                    vj[v], vbit[v], vcam[v] = j, k * n_casc + c, k
                    vkey[v, 0], vkey[v, 1], vkey[v, 2], vkey[v, 3] = (
                        lights.ids[j], 1, cameras.ids[k], c)
                    v += 1
        else:
            for bit in range(1 if typ == SPOT else 6):
                vj[v], vbit[v] = j, bit
                vkey[v, 0], vkey[v, 3] = lights.ids[j], bit
                v += 1

    views = np.zeros(n_s, np.uint32)
    dirty = np.zeros(n_s, np.uint32)
    static_dirty = np.zeros(n_s, np.uint32)
    update = np.zeros(n_s, np.uint32)
    # Per view, its state before rendering: memory row, ready, age, named flags, tile.
    vmem = np.empty(n_v, np.int64)
    ready = np.zeros(n_v, np.bool_)
    age = np.zeros(n_v, np.int64)
    v_named = np.zeros(n_v, np.bool_)
    v_named_static = np.zeros(n_v, np.bool_)
    is_dirty = np.zeros(n_v, np.bool_)
    tile = np.full((n_v, 3), -1, np.int64)
    score = np.zeros(n_v)
    light_now = np.empty((n_s, N_LIGHT))
    for j in range(n_s):
        _light_state(lights, lights.rows[j], light_now[j])
    matched = np.zeros(memory.key.shape[0], np.bool_)
    now = np.empty(casters.rows.shape[0], np.int64)
    for v in range(n_v):
        j, bit = vj[v], vbit[v]
        tier = lights.tier[j]
        if vcam[v] < 0:
            for i in range(3):
                tile[v, i] = lights.rect[j, bit, i]
        m = _find(memory, vkey[v])
        vmem[v] = m
        rendered = False
        if m >= 0:
            matched[m] = True
            rendered = memory.rendered[m]
            ready[v] = memory.ready[m]
            age[v] = memory.age[m]
            v_named[v] = memory.named[m]
            v_named_static[v] = memory.named_static[m]
            placed = memory.placed[m]
            if (placed[0] != tier or placed[1] != tile[v, 0] or placed[2] != tile[v, 1]
                    or placed[3] != tile[v, 2]):
                # A new tile or tier holds nothing of the view until it is drawn there.
                ready[v] = False
        views[j] |= np.uint32(1) << np.uint32(bit)
        if not rendered:
            stat = dyn = True
        else:
            stat = memory.tier[m] != tier
            for i in range(3):
                stat = stat or memory.tile[m, i] != tile[v, i]
            for i in range(N_LIGHT):
                stat = stat or memory.light[m, i] != light_now[j, i]
            if vcam[v] >= 0:
                for i in range(cameras.state.shape[1]):
                    stat = stat or memory.camera[m, i] != cameras.state[vcam[v], i]
            n = 0
            for i in range(casters.offsets[j], casters.offsets[j + 1]):
                if (casters.masks[i] >> np.uint32(bit)) & np.uint32(1):
                    now[n] = casters.rows[i]
                    n += 1
            dyn, c_stat, n_dyn, n_stat = _caster_causes(memory, m, objects, now[:n], named)
            v_named[v] = v_named[v] or n_dyn
            v_named_static[v] = v_named_static[v] or n_stat
            stat = stat or c_stat or v_named_static[v]
            dyn = dyn or v_named[v]
        if stat or dyn:
            is_dirty[v] = True
            dirty[j] |= np.uint32(1) << np.uint32(bit)
            if stat:
                static_dirty[j] |= np.uint32(1) << np.uint32(bit)
        if ready[v]:
            score[v] = (1 + age[v]) * max(lights.importance[j], 0.0)

    n_local = 0
    for v in range(n_v):
        n_local += is_dirty[v] and vcam[v] < 0
    local = np.empty(n_local, np.int64)
    i = 0
    for v in range(n_v):
        if is_dirty[v] and vcam[v] < 0:
            local[i] = v
            i += 1
    chosen = np.zeros(n_v, np.bool_)
    # Directional views are outside the budget.
    for v in range(n_v):
        chosen[v] = is_dirty[v] and vcam[v] >= 0
    if budget > 0 and n_local > budget:
        local = _budget_pick(local, ready, age, score, budget)
    for v in local:
        chosen[v] = True

    drawn = 0
    texels = 0
    for v in range(n_v):
        if chosen[v]:
            update[vj[v]] |= np.uint32(1) << np.uint32(vbit[v])
            drawn += 1
            texels += lights.tier[vj[v]] * lights.tier[vj[v]]
    ready_light = np.ones(n_s, np.bool_)
    for v in range(n_v):
        if vcam[v] < 0 and not (ready[v] or chosen[v]):
            ready_light[vj[v]] = False
    state = ViewState(vj, vbit, vkey, vcam, vmem, tile, ready, age, v_named, v_named_static,
                      is_dirty, chosen)
    out = _remember(lights, casters, objects, cameras, memory, state, light_now, matched)
    return ViewPass(views, dirty, static_dirty, update, ready_light, drawn, texels, out)


@nb.njit(cache=True, nogil=True)
def _remember(lights, casters, objects, cameras, memory, state, light_now, matched):
    """The next frame's ViewMemory (DESIGN section 2, "Dirty", "Ready", "Budget"): a view
    rendered now (``state.chosen``) holds this frame's light, tier, tile, camera and
    casters, is ready, of age 0; a dirty one not rendered ages by one; a clean one is of
    age 0; each keeps the named flags and readiness view_pass found (its placement is this
    frame's). Then last frame's rows no view of this frame matched whose light is still a
    shadow light. lights, casters, objects, cameras, memory: view_pass' arguments; state:
    ViewState, per view of this frame; light_now [S, N_LIGHT]: each shadow light as its
    views remember it; matched [M]: memory rows a view of this frame found."""
    vj, vbit, vkey, vcam, vmem, tile = (state.light, state.bit, state.key, state.camera,
                                        state.memory_row, state.tile)
    ready, age, v_named, v_named_static = (state.ready, state.age, state.named,
                                           state.named_static)
    is_dirty, chosen = state.dirty, state.chosen
    n_v = vj.shape[0]
    n_m = memory.key.shape[0]
    live = np.sort(lights.ids)
    carried = np.zeros(n_m, np.bool_)
    n_c = 0
    for m in range(n_m):
        if not matched[m]:
            at = np.searchsorted(live, memory.key[m, 0])
            carried[m] = at < live.shape[0] and live[at] == memory.key[m, 0]
            n_c += carried[m]
    size = 0
    for v in range(n_v):
        j = vj[v]
        if chosen[v]:
            for i in range(casters.offsets[j], casters.offsets[j + 1]):
                size += (casters.masks[i] >> np.uint32(vbit[v])) & np.uint32(1)
        elif vmem[v] >= 0:
            size += memory.cast_at[vmem[v] + 1] - memory.cast_at[vmem[v]]
    for m in range(n_m):
        if carried[m]:
            size += memory.cast_at[m + 1] - memory.cast_at[m]
    n_out = n_v + n_c
    out = ViewMemory(
        np.empty((n_out, 4), np.int64), np.empty(0, np.int64), np.zeros((n_out, N_LIGHT)),
        np.zeros(n_out, np.int64), np.full((n_out, 3), -1, np.int64),
        np.zeros((n_out, cameras.state.shape[1])), np.full((n_out, 4), -1, np.int64),
        np.zeros(n_out, np.bool_), np.zeros(n_out, np.bool_), np.zeros(n_out, np.int64),
        np.zeros(n_out, np.bool_), np.zeros(n_out, np.bool_), np.zeros(n_out + 1, np.int64),
        np.empty(size, np.int64), np.empty((size, N_VALUES)))
    d = 0
    for v in range(n_v):
        j, m = vj[v], vmem[v]
        out.key[v] = vkey[v]
        out.placed[v, 0] = lights.tier[j]
        out.placed[v, 1:] = tile[v]
        if chosen[v]:
            out.light[v] = light_now[j]
            out.tier[v] = lights.tier[j]
            out.tile[v] = tile[v]
            if vcam[v] >= 0:
                out.camera[v] = cameras.state[vcam[v]]
            out.rendered[v] = True
            out.ready[v] = True
            for i in range(casters.offsets[j], casters.offsets[j + 1]):
                if (casters.masks[i] >> np.uint32(vbit[v])) & np.uint32(1):
                    o = casters.rows[i]
                    out.cast_ids[d] = objects.id[o]
                    for a in range(3):
                        out.cast_values[d, a] = objects.bounds_min[o, a]
                        out.cast_values[d, 3 + a] = objects.bounds_max[o, a]
                    out.cast_values[d, 6] = objects.casts_shadows[o]
                    out.cast_values[d, 7] = objects.mask[o]
                    out.cast_values[d, 8] = objects.static[o]
                    d += 1
        else:
            if m >= 0:
                d = _copy_row(memory, m, out, v, d)
            out.ready[v] = ready[v]
            out.age[v] = age[v] + 1 if is_dirty[v] else 0
            out.named[v] = v_named[v]
            out.named_static[v] = v_named_static[v]
        out.cast_at[v + 1] = d
    v = n_v
    for m in range(n_m):
        if carried[m]:
            out.key[v] = memory.key[m]
            out.placed[v] = memory.placed[m]
            d = _copy_row(memory, m, out, v, d)
            out.ready[v] = memory.ready[m]
            out.age[v] = memory.age[m]
            out.named[v] = memory.named[m]
            out.named_static[v] = memory.named_static[m]
            out.cast_at[v + 1] = d
            v += 1
    return out


@nb.njit(cache=True, nogil=True, inline="always")
def _copy_row(memory, m, out, v, d):
    """Row v of ``out`` (ViewMemory) takes what memory row m was rendered with (light,
    tier, tile, camera, casters from cast_ids[d] on); returns the casters' end."""
    out.light[v] = memory.light[m]
    out.tier[v] = memory.tier[m]
    out.tile[v] = memory.tile[m]
    out.camera[v] = memory.camera[m]
    out.rendered[v] = memory.rendered[m]
    a, b = memory.cast_at[m], memory.cast_at[m + 1]
    out.cast_ids[d:d + b - a] = memory.cast_ids[a:b]
    out.cast_values[d:d + b - a] = memory.cast_values[a:b]
    return d + b - a


def empty_memory(n_camera_values: int) -> ViewMemory:
    """The memory before the first frame: no view."""
    return ViewMemory(np.zeros((0, 4), np.int64), np.zeros(0, np.int64),
                      np.zeros((0, N_LIGHT)), np.zeros(0, np.int64),
                      np.zeros((0, 3), np.int64), np.zeros((0, n_camera_values)),
                      np.zeros((0, 4), np.int64), np.zeros(0, np.bool_),
                      np.zeros(0, np.bool_), np.zeros(0, np.int64), np.zeros(0, np.bool_),
                      np.zeros(0, np.bool_), np.zeros(1, np.int64), np.zeros(0, np.int64),
                      np.zeros((0, N_VALUES)))


def _placement(shadows: ShadowSet, types: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    return shadows.ids, shadows.tier, types


def _same_placement(a: tuple[np.ndarray, ...] | None, b: tuple[np.ndarray, ...]) -> bool:
    return a is not None and all(np.array_equal(x, y) for x, y in zip(a, b, strict=True))


def _tiles(last: ShadowViews | None, shadows: ShadowSet, types: np.ndarray, atlas: int
           ) -> tuple[dict[tuple[int, int], tuple[int, int, int]], np.ndarray, int | None]:
    """(the tiles by (light id, bit), shadow_rect, tiles moved): last frame's while the
    shadow lights and their tiers hold (allocate_tiles would keep every tile then; tiles
    moved None), else allocate_tiles'."""
    placement = _placement(shadows, types)
    if last is not None and _same_placement(last.placement, placement):
        return last.tiles, last.rect, None
    tiles_last = {} if last is None else last.tiles
    shadow_ids = shadows.ids.tolist()
    tiers = shadows.tier.tolist()
    kinds = types.tolist()
    wanted = [((lid, bit), tiers[j], (j, bit)) for j, lid in enumerate(shadow_ids)
              if kinds[j] != DIRECTIONAL for bit in range(1 if kinds[j] == SPOT else 6)]
    tiles = allocate_tiles(wanted, tiles_last, atlas) if atlas and wanted else {}
    rect = np.full((len(shadow_ids), 6, 3), -1, np.int32)
    for key, _, (j, bit) in wanted:
        tile = tiles.get(key)
        if tile is not None:
            rect[j, bit] = tile
    moved = sum(1 for key, t in tiles.items() if key in tiles_last and tiles_last[key] != t)
    return tiles, rect, moved


def _named(objects: ObjectStore) -> NamedIds:
    """The ids update_objects named since last frame and whether each is static now."""
    if not objects.named:
        return NamedIds(np.zeros(0, np.int64), np.zeros(0, np.bool_))
    named = np.unique(np.concatenate(objects.named)).astype(np.int64)
    named_static = np.zeros(named.size, np.bool_)
    if len(objects):
        pos = np.minimum(np.searchsorted(objects.id, named), len(objects) - 1)
        exists = objects.id[pos] == named
        named_static[exists] = objects.static[pos[exists]]
    return NamedIds(named, named_static)


def _camera_states(cameras: list[Camera], cams: Cameras) -> np.ndarray:
    """[K, N_CAMERA + C + 1]: each camera as its directional views remember it."""
    out = np.empty((len(cameras), N_CAMERA + cams.splits.shape[1]))
    for k, c in enumerate(cameras):
        out[k, 0:3] = np.asarray(c.position, np.float64)
        out[k, 3:6] = np.asarray(c.forward, np.float64)
        out[k, 6:9] = np.asarray(c.up, np.float64)
        out[k, 9:13] = (float(c.fov_y), float(c.aspect), float(c.near), float(c.far))
        out[k, 13:] = cams.splits[k]
    return out


def update_views(last: ShadowViews | None, shadows: ShadowSet, casters: Casters,
                 lights: LightStore, objects: ObjectStore, cams: Cameras,
                 cameras: list[Camera], config: Config) -> tuple[ShadowViews, ShadowSet]:
    """The views stage (DESIGN section 2, "Shadow views, updates and the atlas"). Returns
    its output and the ShadowSet the rest of the frame uses: slot_shadow samples only
    lights whose views are all ready, and with unshadowed = "skip" a shadow light with a
    view not ready lights nothing. The rules are view_pass'."""
    if shadows.rows.size == 0 and (last is None or (last.memory.key.shape[0] == 0
                                                    and not last.tiles)):
        # (The cameras stage keeps last frame's ids array while the ids are the same.)
        if last is not None and last.placement is None and last.camera_ids is cams.ids:
            return last, shadows
        return _no_views(cams.ids, cams.splits.shape[1]), shadows
    return run_views(last, shadows, casters, lights, objects, cams, cameras, config)


def run_views(last: ShadowViews | None, shadows: ShadowSet, casters: Casters,
              lights: LightStore, objects: ObjectStore, cams: Cameras, cameras: list[Camera],
              config: Config) -> tuple[ShadowViews, ShadowSet]:
    """update_views' general case: the atlas tiles, then view_pass."""
    ids_cam = cams.ids
    types = lights.type[shadows.rows]
    tiles, rect, moved = _tiles(last, shadows, types, config.shadow_atlas_size)
    cam_state = _camera_states(cameras, cams)
    memory = empty_memory(cam_state.shape[1]) if last is None else last.memory
    res = view_pass(
        ViewLights(shadows.rows.astype(np.int64, copy=False),
                   shadows.ids.astype(np.int64, copy=False),
                   shadows.tier.astype(np.int64, copy=False),
                   shadows.importance.astype(np.float64, copy=False), rect, lights.type,
                   lights.position, lights.radius, lights.direction, lights.outer_angle),
        ViewCasters(casters.offsets, casters.rows, casters.masks),
        ViewObjects(objects.id, objects.bounds_min, objects.bounds_max,
                    objects.casts_shadows, objects.mask, objects.static),
        ViewCameras(ids_cam.astype(np.int64), cam_state), _named(objects), memory,
        config.cascades, config.shadow_update_budget)
    key = res.memory.key
    order = np.lexsort((key[:, 3], key[:, 2], key[:, 1], key[:, 0])).astype(np.int64)
    n_s = shadows.rows.size
    out = ShadowViews(res.views, res.dirty, res.static_dirty, res.update, rect, ids_cam,
                      res.ready, res.memory._replace(order=order), tiles,
                      _placement(shadows, types), not res.dirty.any(), moved or 0, res.texels,
                      _how(n_s, int(np.count_nonzero(res.dirty)), res.drawn, moved))
    return out, sampled(shadows, res.ready, lights, config)


def _no_views(ids_cam: np.ndarray, splits: int) -> ShadowViews:
    """What the views stage gives with no shadow light and no view or tile remembered (as
    view_pass would, without its fixed cost: a scene without shadows pays nothing here).
    Its placement is None (no other output has), so that the next such frame with the same
    cameras may share it."""
    return ShadowViews(
        np.zeros(0, np.uint32), np.zeros(0, np.uint32), np.zeros(0, np.uint32),
        np.zeros(0, np.uint32), np.zeros((0, 6, 3), np.int32), ids_cam, np.zeros(0, np.bool_),
        empty_memory(N_CAMERA + splits), {}, None, True, 0, 0, _how(0, 0, 0, None))


def _how(n_s: int, dirty_lights: int, drawn: int, moved: int | None) -> str:
    if n_s == 0:
        return "skipped: no shadow lights"
    if moved is None:
        return (f"{dirty_lights} of {n_s} shadow lights with dirty views, {drawn} views to "
                "render; the atlas tiles kept (shadow lights and tiers unchanged)")
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


__all__ = ["MIN_TIER", "NamedIds", "ShadowViews", "ViewCameras", "ViewCasters", "ViewLights",
           "ViewMemory", "ViewObjects", "ViewPass", "allocate_tiles", "empty_memory",
           "first_fit", "run_views", "sampled", "update_views", "view_pass"]
