"""Scheduler and schedule(): run the stages of DESIGN section 2 on the fast path, in full or
incrementally (section 6).

Takes the stores (scene.py) and cameras; returns a Frame (frame.py). Stages, each timed in
stats["seconds"]: cameras (frustum.py), changes (what differs from the last frame,
changes.py), visibility (frustum.py), pack (priority.py), grid (the grid of objects: its
shape, their order, their records), pairs (Affects and P per light, pairs.py),
shadows (ranking and tiers, shadows.py), casters (culling volumes and caster lists), lists
(the pair cache: grouping by object, or the rewrite of the changed objects' lists),
objects (top-K and fade per object), output.

A full frame computes every pair; an incremental one keeps the last frame's pair cache
(per object its (P, light row) pairs, pairs.py) and recomputes only what changed:
- lights whose fields changed, or that entered or left the view, walk the grid of objects
  again; the objects that held a pair of theirs or get one now rewrite their lists. Under
  still cameras and objects (and the contribution model, exact precision, no directional
  light in the slots), when the last frame kept candidate lists, the objects in the lists
  of those lights instead take all their pairs again from their lists
  (pairs.candidate_pairs on those rows): no walk, no scan of the cache, no grouping;
- objects that moved or came into view get new lists against every light (each tested
  against every light when they are few, else against the lights of the cells its box
  overlaps in a grid of the lights, kept while no light changes); in a grid of every
  object their records are rewritten where they are while each box stays within reach of
  its cell; objects that left the view lose theirs;
- the object pass runs on those objects, on the objects holding a pair of a light whose
  shadow map or "skip" status changed, and on the objects still fading; the other rows of
  the outputs are the last frame's (shared outright when no row changed).
A full frame's object pass leaves out the objects out of view in it and the two frames
before: the output arrays it takes back (the frame before the last's) hold their empty
rows already.
Results equal a full frame's: an object whose pairs, slots and shadow maps did not change
gets the same row again (selection with hysteresis is a fixed point of unchanged P). The
shadow ranking is redone every frame but an unchanged one: its order is a fixed point only
once the shadowed set has stayed the same for a frame (see _Cache.shadows_settled).

The per-object state (slots, weights, last frame's selection) lives in the object store's
``state`` so it follows ids through set_/remove_ calls; the slot ids and states are the
last (read-only) frame's light_ids and fade_state.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from functools import reduce
from itertools import accumulate
from typing import Any

import numba as nb
import numpy as np

from .changes import camera_key, changed_rows, same_key
from .frame import (
    PER_OBJECT,
    Frame,
    copy_rows,
    empty_frame,
    freeze,
    held_elsewhere,
    rows_not_in,
)
from .frustum import (
    CameraFrames,
    cascade_splits,
    lights_visible,
    objects_visible,
    objects_visible_groups,
)
from .pairs import (
    GROUP_PARTS,
    RUN_SPLIT,
    STATIC_K,
    affects_any,
    candidate_pairs,
    compact_heap,
    compact_light_lists,
    direct_pairs,
    edit_candidates,
    grid_casters,
    grid_pairs,
    grid_shape,
    group_few,
    group_pairs,
    group_parts,
    left_spheres,
    light_bounds,
    light_grid,
    light_lists,
    light_order,
    light_pass,
    list_objects,
    list_room,
    live_ids,
    move_records,
    object_pass,
    reached_rows,
    replace_lists,
    scan_pairs,
    scan_rows,
    spread_lists,
    start_at,
    visible_objects,
    visible_order,
    widen_walkers,
)
from .priority import (
    MODEL_CONTRIBUTION,
    MODEL_THESIS,
    PACK_ALL,
    PACK_CAMERA,
    PACK_POSITION,
    aligned_empty,
    pack_lights,
    pack_parts,
)
from .scene import DIRECTIONAL, LIGHT_FIELDS, OBJECT_FIELDS, Camera, Config, SceneAPI
from .shadows import (
    SWEEP_GROUP,
    culling_volumes,
    group_boxes,
    hidden_near,
    rank_shadow_lights,
    sweep_casters,
    sweep_groups,
    widen_group_boxes,
)
from .simd import SHOWN

# Below this many (competing light, visible object) pairs a grid costs more than it saves.
BRUTE_FORCE_PAIRS = 1 << 15
# An incremental frame tests the objects that moved or came into view against every
# competing point or spot light (pairs.direct_pairs) while those tests number at most this
# many per light plus one per object row; beyond, each against the lights of the cells its
# box overlaps in a grid of the lights (pairs.light_grid, grid_pairs). A test costs ~3.7
# ns (at (10k, 1k), 100 objects against 1000 lights: 0.37 ms; at (100k, 10k), one object:
# the pairs stage 1.2 -> 0.2 ms). The grid of 10k lights takes ~0.9 ms to make, kept while
# no light changes, and ~0.4 us an object (pairs.light_grid); before it, a grid of the
# moved objects walked by every light took ~2.8 ms for 1000 of them at (100k, 10k).
DIRECT_TESTS_PER_LIGHT = 24
# With the grid of the lights kept, an object's pairs from it cost ~0.4 us, ~110 direct
# tests: more point and spot lights than that, and the kept grid serves (at (1M, 100k), 20
# objects coming into view against 78k lights took 3.3 ms direct).
GRID_TESTS_PER_OBJECT = 110
# An incremental frame whose flagged lights (changed, or whose "live" or shadow map
# changed) did not change finds the objects holding their pairs by walking them (~2 us a
# light), not by scanning every object's pairs (~3 ns a pair: ~10 ms at (1M, 100k), where
# a moving camera flags the few lights entering or leaving the view), while there are at
# least this many cached pairs per flagged light.
NEAR_SCAN_PAIRS = 4096
# An incremental frame whose walked lights have at most this many pairs per object groups
# them by sorting (pairs.group_few, ~60 ns a pair), not with a histogram of every object
# (~3 ns an object: ~0.3 ms at 100k objects, for no pair too).
FEW_PAIRS = 1 / 32
# With at least this share of the objects visible, the grid holds every object, so a camera
# move only changes its records' masks and the casters need no second grid of the invisible
# objects. Below it, the grid holds the visible objects only: a view of a small part of a
# large world keeps small cells and a small grid.
EVERY_OBJECT_SHARE = 0.5
# A kept grid of every object serves while its cell edge is within this factor of the one
# the competing lights ask for (the light pass took about the same time from 1.4x to 2.0x
# the median radius at (100k, 10k)); the median moves a little whenever the camera does.
CELL_SLACK = 1.25
# That edge is checked again once this share of the competing lights changed since the
# last check (lights enter and leave the view every frame), or a radius did.
EDGE_DRIFT = 0.01
# Grid cell edge over the median light radius. Cells 4x finer along z (pairs.RUN_SPLIT)
# already trim each column's run, so wider columns pay: 1.0 -> 1.5 took the light pass
# 8.2 -> 7.2 ms at (100k, 10k) and 77 -> 64 ms at 1M with the camera moving; 0.7 was
# slower, 2.0 no better (bench/paired.py, RESULTS.md issue 6).
CELL_PER_RADIUS = 1.5
# An incremental frame beyond this share of changed lights or objects costs about what a
# full one does: run the full frame.
FULL_SHARE = 0.5
# "fast" precision keeps its float32 records relative to an origin, the first camera's
# position when they were made, until that camera is this far from it (metres): within
# 2^8 m of the origin, coordinates on the 2^-16 m grid are exact in float32's 24 bits.
REANCHOR = 256.0

# Candidate lists (pairs.candidate_pairs) hold the objects within each point and spot
# light's radius times 1 + SKIN where the list was made; the light keeps its list while its
# sphere stays inside that one. A share of the radius is scale-free. On the city (radii
# 5..30 m, 3 m/s) a wider skin means more candidates to test, a narrower one more lights
# walking again: at (100k, 10k), frames 70-90 of `full` (medians), 0.05 gave 13.5 ms (1.1k
# lights walking a frame), 0.1 13.6 (570), 0.2 14.6 (255); 0.1 keeps the walks, and their
# spikes, small when lights move faster (RESULTS.md, candidate lists). Measured again in
# steady state with the candidates' stream (2026-11-27): 0.2 no faster (+0.07 ms paired).
SKIN = 0.1
# A light walked again centres its widened sphere this share of SKIN x radius ahead of it,
# along its last frame's step (the sphere still holds it: LEAD < 1).
LEAD = 0.8
# Lists are made again from scratch when more than this share of the lights left theirs.
REBUILD_SHARE = 0.5
# False: full frames walk every light as when nothing is kept (the tests compare the two).
CANDIDATE_LISTS = True
# Grids of fewer objects walk every light: there the lists' upkeep costs more than the walk
# and the grouping they save (bench/paired.py, cached code, `full`, since the candidates
# run in vector code: 1k objects +0.01 ms of 0.57, 3k -0.04 of 1.0, 10k -0.16 of 1.9;
# before it 10k was +-0.08, so the threshold was 2^15).
CANDIDATE_MIN_OBJECTS = 1 << 12

# No rows: no directional light in the slots (pairs.candidate_pairs' dir_rows), no object
# whose visibility changed.
_NO_ROWS = np.zeros(0, np.int64)
# A last group pass of none (frustum.objects_visible_groups).
_NO_CLASS = np.zeros(0, np.int8)

# The fields whose change alters an object's pairs (casts_shadows changes only casters).
PAIR_OBJECT_FIELDS = ("id", "bounds_min", "bounds_max", "mask")

# Per-object state: slot ids and states are the frame's own (read-only) light_ids and
# fade_state outputs; the float64 weights and last frame's selection are kept apart.
_STATE = (("slot_light", np.int32, -1), ("slot_weight", np.float64, 0.0),
          ("slot_state", np.uint8, 0), ("selected", np.int32, -1))

# Per-object outputs the object pass writes ("visible" is the visibility array itself).
_OUT = tuple(name for name in PER_OBJECT if name != "visible")

# light_flag bits of an incremental frame (pairs.scan_pairs): the light's pairs are
# replaced (it changed, or entered or left the view); the objects holding its pairs must
# select again (its shadow map or "skip" status changed).
WALKED, RESELECT = 1, 2


@dataclass
class _Grid:
    """The grid of objects a frame walked: (origin and 1/h, dims, cell_start, ext, big_pos)
    and the per-position records (vis_box [V, 8], its integer view, object row per
    position). Either a grid of the visible objects (``shown`` None), or of every object
    (``shown`` the visibility its records hold: an invisible object's record has no SHOWN
    bit of its mask word, so it pairs with no light (_shown_mask); ``pos_of`` each row's
    position, ``box`` every object's bounding box, which set the grid's extent)."""

    grid: tuple
    vis: tuple
    plan: str
    shown: np.ndarray | None = None
    pos_of: np.ndarray | None = None
    box: np.ndarray | None = None
    # (competing lights, the bytes of their radii, how many compete) when the cell edge of
    # a grid of every object was last checked against the lights' (Scheduler._every_grid).
    edge_of: tuple[np.ndarray, bytes, int] | None = None
    # A grid of every object: the boxes round each SWEEP_GROUP of its positions' objects
    # (shadows.group_boxes), made at the first sweep of a directional light's casters and
    # kept with the grid, widened in place for the objects that move within it.
    group_box: np.ndarray | None = None


@dataclass
class _Candidates:
    """Per object row, the point and spot lights that may affect it while each stays
    inside its anchored sphere (pairs.candidate_pairs): ``anchor`` [L, 4] is per light
    row the centre (records' frame) and radius of the sphere its candidates were found
    with, radius 0 for none; ``lists`` = (seg [N, 2] (start, length), cap [N], light row
    int32, fill) the lists by object row, each in a room with space to grow
    (pairs.spread_lists); ``by_light`` = (seg [L, 2], object row int32) the same by
    light row, from record ``used`` on free (packed when full); ``recs`` the grid's
    records in object row order, their masks following the visibility as the grid's do;
    ``hidden`` whether the lists hold the objects out of view too. Valid while the objects,
    the records' origin and the grid are the ones they were made with and, unless
    ``hidden``, no object came into view (see cands_valid in Scheduler._step)."""

    anchor: np.ndarray
    lists: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]
    by_light: tuple[np.ndarray, np.ndarray]
    used: int
    recs: tuple[np.ndarray, np.ndarray]
    hidden: bool


@dataclass
class _Cache:
    """What a frame keeps for the next one (DESIGN section 6). Store arrays are never
    changed in place, so keeping references to the ones this frame read is enough to see
    later which rows changed."""

    lights: dict[str, np.ndarray]
    objects: dict[str, np.ndarray]
    cam_key: np.ndarray
    frames: CameraFrames
    splits: np.ndarray
    vis_l: np.ndarray
    vis_o: np.ndarray
    box: np.ndarray            # bounding box of the visible objects (lo, hi)
    compete: np.ndarray        # visible lights that compete for slots
    packed: tuple[np.ndarray, np.ndarray]
    grid: _Grid
    seg: np.ndarray            # pair cache: per object (start, length) in heap
    heap: tuple[np.ndarray, np.ndarray]   # (P float64, light row int32) per pair
    used: int                  # heap records in use (live or garbage)
    pairs: int                 # live records: the lengths in seg summed
    live: np.ndarray
    shadow_of_row: np.ndarray
    fading: np.ndarray         # per object: a slot is fading in or out
    # The shadowed set equals the one before it. Then the next frame's ranking gives the
    # same order; after a change it may not: a light that just joined ranks with the
    # hysteresis bonus one frame later (the set itself is a fixed point, its order is not).
    shadows_settled: bool
    frame: Frame
    casters: dict[int, tuple[np.ndarray, np.ndarray]]   # light row -> (object rows, masks)
    # The origin of the object records and packed lights: 0 (exact precision) or, in
    # "fast" precision, the first camera's position when they were made.
    origin: np.ndarray
    cands: _Candidates | None = None
    # The grid of the point and spot lights (pairs.light_grid) while they do not change.
    light_grid: tuple | None = None
    # (pos_of, class per group) of the last group pass of visibility over a grid of every
    # object (frustum.objects_visible_groups), valid while the grid's positions are pos_of.
    # Kept only while vis_o is that pass's: a frame that tests objects otherwise drops it.
    vis_groups: tuple[np.ndarray, np.ndarray] | None = None


class Scheduler(SceneAPI):
    """Stateful fast-path scheduler (DESIGN section 7)."""

    def __init__(self, config: Config | None = None) -> None:
        super().__init__(config)
        k = self.config.max_lights
        for name, dtype, fill in _STATE:
            self.objects.add_state(name, (k,), dtype, fill)
        self.objects.add_state("was_visible", (), np.bool_, False)
        self._buffers: dict[str, np.ndarray] = {}
        # Last frame's shadow lights (ids) and their tiers, for the two hystereses.
        self._shadow_prev = (np.zeros(0, np.int32), np.zeros(0, np.int64))
        self._cache: _Cache | None = None
        # The per-object output arrays of the frame before the last, the rows by which they
        # lag the last frame's (None: all) and that frame's visibility; _outputs takes them
        # back when free.
        self._spare: tuple[dict[str, np.ndarray], np.ndarray | None, np.ndarray] | None = None
        # The pair heap the last frame replaced, which nothing reads any more; _new_heap
        # takes it back.
        self._spare_heap: tuple[np.ndarray, np.ndarray] | None = None
        # (visibility, grid position of each row, and the grid positions and masks of the
        # objects out of view) for the walks of the candidate lists.
        self._hidden: tuple[np.ndarray, ...] | None = None
        # (the three visibilities, the rows in view in any): see _run_rows.
        self._kept_run: tuple[tuple[np.ndarray, ...], np.ndarray] | None = None

    def _scratch(self, name: str, size: int, dtype: Any) -> np.ndarray:
        """A reusable buffer of at least ``size`` elements (grown by half when short), so a
        steady scene allocates no pair or record memory per frame."""
        buf = self._buffers.get(name)
        if buf is None or buf.size < size or buf.dtype != dtype:
            buf = aligned_empty(max(size, int(1.5 * (0 if buf is None else buf.size))), dtype)
            self._buffers[name] = buf
        return buf

    def _rows(self, n: int, read_only: bool = True) -> np.ndarray:
        """0..n-1 (int64), kept while n is (at 1M a new one takes 0.24 ms); a read-only
        view unless asked otherwise (the object pass's rows, of the type of the rows of an
        incremental frame: one signature; it does not write them)."""
        rows = self._buffers.get("rows")
        if rows is None or rows.size != n:
            rows = aligned_empty(n, np.int64)
            rows[:] = np.arange(n)
            self._buffers["rows"] = rows
        return _read_only(rows) if read_only else rows

    def _run_rows(self, vis: tuple[np.ndarray, np.ndarray, np.ndarray]) -> np.ndarray:
        """The rows in view in any of ``vis`` (read-only visibilities: this frame's, the
        last frame's, that of the frame whose arrays are taken back), kept while they are
        the same arrays: under a still camera they are, frame after frame (at 1M objects
        the rows took 0.53 ms a frame)."""
        kept = self._kept_run
        if kept is not None and all(a is b for a, b in zip(kept[0], vis, strict=True)):
            return kept[1]
        run = np.flatnonzero(vis[0] | vis[1] | vis[2])
        # (A visibility made in this frame is frozen with it: kept from the next frame on.)
        self._kept_run = None if any(v.flags.writeable for v in vis) else (vis, run)
        return run

    def _new_heap(self, room: int) -> tuple[np.ndarray, np.ndarray]:
        """A pair heap (P float64, light row int32) of at least ``room`` records, for a frame
        that makes every list anew or packs the cache: the one the last frame replaced when
        it is large enough and not over twice that, else new arrays with an eighth more
        room, so that a scene a little larger next frame takes this one back. At (1M, 100k)
        the P array (~36 MB) is over glibc's mmap threshold: a new one each full frame was
        mapped and faulted in again (bench/frames.py: 18 huge and ~350 small page faults a
        frame), and a new packed heap every few frames of 10% of the lights moving was
        faulted in page by page as the lists were appended to it (~4700 faults a frame).
        """
        spare, self._spare_heap = self._spare_heap, None
        if spare is not None and room <= spare[0].size <= 2 * room + 4096:
            return spare
        room += room // 8
        return (np.empty(room), np.empty(room, np.int32))

    def _pair_room(self, cands: _Candidates, n: int, n_dir: int) -> int:
        """The pair heap's room for a full frame from the candidate lists: a pair is a
        candidate that passes the Affects test, or one of the ``n_dir`` directional lights
        with each of the ``n`` objects. The objects' lists and the lights' hold the same
        (light, object) candidates: the lights' lengths are 10x fewer to sum (at (1M, 100k)
        the objects' took ~0.5 ms). Should it fall short, candidate_pairs writes nothing
        and reports the exact room, which the frame then takes."""
        return int(cands.by_light[0][:, 1].sum()) + n * n_dir

    # ------------------------------------------------------------------ the frame

    def _frame(self, cameras: list[Camera], dt: float, cut: bool) -> Frame:
        cfg = self.config
        seconds: dict[str, float] = {}
        plan: dict[str, str] = {}
        t = time.perf_counter()
        c = self._cache
        # Installed again at the end: a frame that stops half way (an exception) leaves no
        # cache behind, so the next frame is full instead of trusting half-updated lists.
        self._cache = None
        key = camera_key(cameras)
        same_cams = c is not None and same_key(key, c.cam_key)
        if same_cams:
            frames, splits = c.frames, c.splits
        else:
            frames = CameraFrames(cameras)
            splits = cascade_splits(cameras, cfg.cascades, cfg.shadow_distance)
        t = _lap(seconds, "cameras", t)

        why, lrows, orows, orows_cast = self._changes(c, same_cams, frames)
        t = _lap(seconds, "changes", t)
        if why is None:
            assert c is not None
            if (lrows.size == 0 and orows.size == 0 and orows_cast.size == 0 and same_cams
                    and not cut and c.shadows_settled and not c.fading.any()):
                return self._unchanged(c, seconds, t)
        frame = self._step(c, why is not None, frames, splits, key, same_cams, lrows, orows,
                           orows_cast, dt, cut, seconds, plan, t)
        if why is not None:
            plan["frame"] = "full: " + why
        return frame

    def _changes(self, c: _Cache | None, same_cams: bool, frames: CameraFrames
                 ) -> tuple[str | None, Any, Any, Any]:
        """(why the frame must be full, or None; changed light rows; object rows whose
        pairs change; object rows whose casts_shadows changed). The rows are None when the
        rows themselves changed (set_/remove_ with other ids)."""
        if c is None:
            why = "first frame" if self.frame_index == 0 else "the last frame stopped half way"
            return why, None, None, None
        cfg = self.config
        lrows = changed_rows(c.lights, self.lights, LIGHT_FIELDS)
        if lrows is None:
            return "the light set changed (set_lights or remove_lights)", None, None, None
        orows = changed_rows(c.objects, self.objects, PAIR_OBJECT_FIELDS)
        if orows is None:
            return "the object set changed (set_objects or remove_objects)", None, None, None
        orows_cast = changed_rows(c.objects, self.objects, ("id", "casts_shadows"))
        why = None
        if not same_cams and cfg.model == "thesis":
            why = "the cameras moved (thesis priorities depend on them)"
        elif (not same_cams and cfg.precision == "fast"
              and np.abs(frames.position[0] - c.origin).max() > REANCHOR):
            why = (f"the first camera moved over {REANCHOR:g} m from the fast records' origin "
                   "(they are made again around it)")
        elif lrows.size > FULL_SHARE * max(len(self.lights), 1):
            why = f"{lrows.size} of {len(self.lights)} lights changed"
        elif orows.size > FULL_SHARE * max(len(self.objects), 1):
            why = f"{orows.size} of {len(self.objects)} objects changed"
        return why, lrows, orows, orows_cast

    def _unchanged(self, c: _Cache, seconds: dict[str, float], t: float) -> Frame:
        """Nothing moved, nothing fades, no cut: the last frame's arrays are this frame's
        (frames are read-only, so they can share them)."""
        self._cache = c
        last = c.frame
        frame = Frame(**last.arrays())
        seconds["total"] = sum(seconds.values()) + (time.perf_counter() - t)
        plan = {stage: f"{text} (kept: nothing changed)"
                for stage, text in last.stats["plan"].items() if stage != "frame"}
        plan["frame"] = ("unchanged: nothing moved and no slot is fading; the last frame's "
                         "outputs are shared")
        frame.stats = {
            "plan": plan,
            "counts": dict(last.stats["counts"], recomputed_objects=0, changed_lights=0,
                           changed_objects=0),
            "seconds": seconds,
        }
        return frame

    def _step(self, c: _Cache | None, full: bool, frames: CameraFrames, splits: np.ndarray,
              key: np.ndarray, same_cams: bool, lrows: Any, orows: Any, orows_cast: Any,
              dt: float, cut: bool, seconds: dict[str, float], plan: dict[str, str],
              t: float) -> Frame:
        """One frame: in ``full``, or incrementally from the last frame's cache ``c`` with
        the changed light rows ``lrows`` and object rows ``orows`` (pairs) and
        ``orows_cast`` (casts_shadows). A full frame with a cache (many lights changed)
        still keeps the caster lists of the shadowed lights that did not change."""
        cfg = self.config
        lights, objs = self.lights, self.objects
        n, n_l = len(objs), len(lights)
        # Object records and packed lights: world float64 (exact), or float32 relative to
        # the first camera's position ("fast": half the bytes a record; the arithmetic
        # stays float64), kept while that camera stays within REANCHOR of it.
        fast = cfg.precision == "fast"
        origin = np.zeros(3) if not fast else (
            c.origin if c is not None and not full else frames.position[0].copy())
        rec_frame = (origin, fast)
        same_origin = c is not None and _same_point(origin, c.origin)
        # Object visibility and records depend on the objects, the cameras and the records'
        # origin only: a full frame (most lights changed) keeps them too when those are as
        # they were.
        objects_kept = (same_origin and same_cams and orows is not None and orows.size == 0)

        # Visibility (DESIGN "Visibility").
        vis_l = lights_visible(lights.type, lights.position, lights.radius, frames.plane_n,
                               frames.plane_p)
        # With the cameras as they were, only the objects that changed are tested again;
        # the box of the visible objects then takes in theirs without letting go of the
        # old one (it only sets a grid's extent, which may be larger than needed).
        objects_moved = same_origin and same_cams and orows is not None and 0 < orows.size
        vis_how = ""
        vis_groups = None
        if objects_kept:
            vis_o, box, vis_groups = c.vis_o, c.box, c.vis_groups
        elif objects_moved:
            vis_moved, box_moved = objects_visible(objs.bounds_min[orows], objs.bounds_max[orows],
                                                   frames.plane_n, frames.plane_p)
            vis_o = c.vis_o.copy()
            vis_o[orows] = vis_moved
            box = np.concatenate([np.minimum(c.box[:3], box_moved[:3]),
                                  np.maximum(c.box[3:], box_moved[3:])])
        elif (c is not None and c.grid.shown is not None and orows is not None
              and orows.size == 0):
            # The objects of last frame's grid of every object, under moved cameras: its
            # group boxes first (those wholly in or out of view), then the objects of the
            # groups on a frustum's planes. After a pass over the same groups, those wholly
            # in or out of view again keep their objects' flags.
            boxes = _group_boxes(c.grid, objs.bounds_min, objs.bounds_max, fast)
            last = c.vis_groups
            since = last is not None and last[0] is c.grid.pos_of
            vis_o, box, classes = objects_visible_groups(
                boxes, frames.plane_n, frames.plane_p,
                (c.grid.pos_of, c.grid.group_box, SWEEP_GROUP),
                (c.vis_o, last[1] if since else _NO_CLASS))
            vis_groups = (c.grid.pos_of, classes)
            vis_how = (f"; by the boxes of {SWEEP_GROUP} positions of last frame's grid of "
                       "every object first")
            if since:
                vis_how += (f", {np.count_nonzero(classes != last[1])} of {classes.size} "
                            "groups changed class (only their objects' flags and those of "
                            "the groups across a plane written)")
        else:
            vis_o, box = objects_visible(objs.bounds_min, objs.bounds_max, frames.plane_n,
                                         frames.plane_p)
        # The rows whose visibility changed since last frame, which three stages read (at
        # 1M objects each pass over the flags took ~0.2 ms).
        flipped = (np.flatnonzero(vis_o != c.vis_o)
                   if c is not None and orows is not None and vis_o is not c.vis_o
                   else _NO_ROWS)
        t = _lap(seconds, "visibility", t)

        # The light rows as last frame's (lrows is None when they were renumbered): they
        # are packed again in last frame's arrays, and only the parts of a row that read a
        # field whose array changed (moving lights: the position only, one line a light;
        # 10k lights 36 -> 9.5 us).
        thesis = cfg.model == "thesis"
        parts, changed, into = PACK_ALL, [], None
        if c is not None and lrows is not None:
            changed = [f for f in LIGHT_FIELDS if c.lights[f] is not getattr(lights, f)]
            parts = pack_parts(changed, thesis)
            if thesis and not same_cams:
                parts |= PACK_CAMERA
                changed.append("cameras")
            if not same_origin:
                parts |= PACK_POSITION
                changed.append("origin")
            into = c.packed
        only = f" ({', '.join(changed)} only)" if parts != PACK_ALL else ""
        if parts == 0:
            packed, packing = c.packed, "; the packed lights kept"
        elif full or (thesis and not same_cams):
            packing = "; every light packed" + ("" if into is None else " again" + only)
            packed = pack_lights(lights, frames, cfg.w_ecc, cfg.w_dist, cfg.c1, thesis,
                                 rec_frame[0], into=None if into is None else (into, None),
                                 parts=parts)
        elif lrows.size:
            packing = f"; the {lrows.size} changed lights packed again{only}, the others kept"
            # Only the changed rows, in last frame's arrays (this frame's to change): at
            # (100k, 10k) the stage 0.22 -> 0.09 ms with 1000 lights moving, 0.26 -> 0.05
            # with 100 (interleaved frames, medians of 100).
            packed = pack_lights(lights, frames, cfg.w_ecc, cfg.w_dist, cfg.c1, thesis,
                                 rec_frame[0], into=(into, lrows.astype(np.int64)),
                                 parts=parts)
        else:
            packed, packing = c.packed, "; the packed lights kept"
        is_dir = lights.type == DIRECTIONAL
        # The directional rows, a few: the sets of them below are read at these rows (a
        # mask of every light row and its flatnonzero took ~10 us each at 10k lights).
        dir_all = np.flatnonzero(is_dir)
        # Pairs are found for every visible light: the shadow ranking needs to know which
        # shadowed lights affect a visible object before "skip" removes the others.
        compete = vis_l & (~is_dir if not cfg.directional_in_slots else True)
        t = _lap(seconds, "pack", t)

        # The grid: of every object once at least EVERY_OBJECT_SHARE are visible, kept while
        # the objects are (a camera move rewrites the masks of the objects that entered or
        # left the view); else of the visible objects, kept while the visible set and its
        # boxes are. A new one writes its records over the kept one's (nothing reads those
        # once it is made): at (1M, 100k) a fresh 50 MB array (over glibc's 32 MB mmap
        # threshold) was mapped and faulted in again every other frame: the records kernel
        # took ~70 ms, not 20.
        if full or objects_kept:
            # (Kept objects: the visibility is last frame's array; nothing entered or left.)
            fresh_rows = left_rows = np.zeros(0, np.int64)
        else:
            if orows.size:
                moved = np.zeros(n, np.bool_)
                moved[orows] = True
                fresh_rows = np.flatnonzero(vis_o & (moved | ~c.vis_o))
            else:
                fresh_rows = flipped[vis_o[flipped]]
            left_rows = flipped[~vis_o[flipped]]
        if n and np.count_nonzero(vis_o) >= EVERY_OBJECT_SHARE * n:
            grid, grid_kept = self._every_grid(c, same_origin, (vis_o, flipped), orows, packed,
                                               compete, is_dir, rec_frame)
        elif full and objects_kept and c.grid.shown is None:
            # The lights set the cell edge: the kept grid serves while it is the same.
            shape = _grid_shape(int(np.count_nonzero(vis_o)), box, packed, compete, is_dir,
                                rec_frame)
            grid_kept = (np.array_equal(shape[0], c.grid.grid[0])
                         and np.array_equal(shape[1], c.grid.grid[1]))
            grid = (_Grid(c.grid.grid, c.grid.vis, shape[2] or c.grid.plan) if grid_kept
                    else self._visible_grid(vis_o, box, packed, compete, is_dir, rec_frame,
                                            shape, "records"))
        elif full or fresh_rows.size or left_rows.size or c.grid.shown is not None:
            grid_kept = False
            grid = self._visible_grid(vis_o, box, packed, compete, is_dir, rec_frame,
                                      records="records")
        else:
            grid_kept = True
            grid = c.grid
        plan["pairs"] = grid.plan
        if full and grid_kept and grid.shown is None:
            plan["pairs"] += " (kept: the objects and cameras did not change)"
        if not compete.any() or not vis_o.any():
            plan["pairs"] = "none: no competing light or no visible object"
        t = _lap(seconds, "grid", t)

        model = MODEL_CONTRIBUTION if cfg.model == "contribution" else MODEL_THESIS
        p_params = np.array([model, cfg.w_obj, cfg.w_int])
        # Candidate lists serve while the objects, the records' origin and the grid of every
        # object are the ones they were made with; a camera move changes only the masks of
        # the records whose visibility changed, in their row-order copy as in the grid's.
        cands_valid = (CANDIDATE_LISTS and c is not None and orows is not None
                       and orows.size == 0 and same_origin and grid_kept
                       and lrows is not None and grid.shown is not None
                       and n >= CANDIDATE_MIN_OBJECTS)
        cands = c.cands if cands_valid and c is not None else None
        if cands is not None and vis_o is not c.vis_o:
            if not cands.hidden and vis_o[flipped].any():
                # Lists of the objects in view only: those entering it may lack lights.
                cands = None
            else:
                # The grid's records have theirs already (_every_grid).
                cands.recs[1][flipped, 6] = grid.vis[1][grid.pos_of[flipped], 6]
        def cands_plan(built: bool, walk: np.ndarray) -> str:
            return (f"; candidate lists (each point and spot light's sphere widened by "
                    f"{SKIN:g} of its radius) " + ("made: " if built else "kept, ")
                    + f"{walk.size} of {int(np.count_nonzero(compete & ~is_dir))} lights "
                    "walked again (they left their widened sphere or had none)")

        # An incremental frame whose lights changed, under still cameras and objects (so no
        # object enters or leaves the view), takes the pairs of the objects those lights
        # may reach from their candidate lists: no walk, no scan of the pair cache, no
        # grouping (bench/RESULTS.md, lights10). Only with last frame's lists, which name
        # the objects a changed light reached before it changed (lists made now would not:
        # a light that left the view is in none, and its objects would keep its pairs);
        # without them the frame walks the changed lights and makes the lists for the
        # next frames. The candidates' stream only: the contribution model, float64
        # records, no directional light in the slots.
        changed_l = None
        if not full:
            # lrows are ascending and distinct: the union only when lights entered or left
            # the competition (np.union1d sorts: ~50 us for 1000 rows).
            entered = np.flatnonzero(compete != c.compete)
            changed_l = np.union1d(lrows, entered) if entered.size else lrows
        # Where each light was last frame (rows unchanged), for the lists' lead (LEAD).
        last_position = c.lights["position"] if c is not None and lrows is not None else None
        lists_path = (not full and cands_valid and same_cams and cfg.model == "contribution"
                      and not fast and not cfg.directional_in_slots)
        by_lists = lists_path and cands is not None and changed_l.size > 0
        if full and cands_valid:
            cands, walk, built = self._candidates(cands, packed, compete, dir_all, grid,
                                                  not same_cams, last_position)
            fresh = None
            plan["pairs"] += cands_plan(built, walk)
            walked = np.zeros(0, np.int64)
        elif by_lists:
            # The objects in the lists of the changed lights before and after they change,
            # and (lists stage) those of lights whose shadow map or "skip" status changed.
            reach = np.zeros(n, np.bool_)
            list_objects(cands.by_light, changed_l, reach)
            cands, walk, built = self._candidates(cands, packed, compete, dir_all, grid, False,
                                                  last_position)
            list_objects(cands.by_light, walk, reach)
            fresh = None
            walked = changed_l
            plan["pairs"] += cands_plan(built, walk) + (
                f"; the objects in the lists of the {changed_l.size} changed lights take "
                "their pairs from their candidate lists")
        elif full:
            rows = light_order(packed[0], np.flatnonzero(compete).astype(np.int32),
                               grid.grid[0], grid.grid[1])
            fresh = self._walk(packed, rows, grid, p_params, "pair")
            plan["pairs"] += f", walked by {rows.size} lights"
            walked = np.zeros(0, np.int64)
        light_cells = None
        if not full and not by_lists:
            # Lights that changed or entered or left the competition have their pairs
            # replaced: they walk the grid again (the visible ones).
            walked = changed_l
            walk = walked[compete[walked]].astype(np.int32)
            walk = light_order(packed[0], walk, grid.grid[0], grid.grid[1])
            fresh = self._walk(packed, walk, grid, p_params, "pair")
            # Objects that moved or came into view: their pairs with every light, each
            # tested against every light when there are few, else against the lights of
            # the cells of a grid of the lights that their box overlaps.
            how = "tested against"
            n_point = int(np.count_nonzero(compete & ~is_dir)) if fresh_rows.size else 0
            if lrows.size == 0:
                light_cells = c.light_grid
            if not fresh_rows.size:
                fresh_obj = (np.zeros(n + 1, np.int64), (np.zeros(0), np.zeros(0, np.int32)))
            elif fresh_rows.size * n_point <= (
                    DIRECT_TESTS_PER_LIGHT * n_point + n if light_cells is None
                    else GRID_TESTS_PER_OBJECT * fresh_rows.size):
                fresh_obj = self._fresh_pairs(fresh_rows, packed, compete, is_dir, p_params,
                                              rec_frame, None)
            else:
                how = "from the cells of a grid of"
                if light_cells is None:
                    how = "from the cells of a new grid of"
                    light_cells = light_grid(packed[0], np.flatnonzero(~is_dir).astype(np.int32))
                fresh_obj = self._fresh_pairs(fresh_rows, packed, compete, is_dir, p_params,
                                              rec_frame, light_cells)
            plan["pairs"] += (f", walked by {walk.size} changed lights (the other pairs are "
                              f"kept); {fresh_rows.size} moved or newly visible objects get "
                              f"new pairs {how} {np.count_nonzero(compete)} lights; "
                              f"{left_rows.size} objects left the view")
            if lists_path and cands is None:
                cands, walk, _ = self._candidates(None, packed, compete, dir_all, grid, False,
                                                  last_position)
                plan["pairs"] += cands_plan(True, walk) + " for the next frames"
        t = _lap(seconds, "pairs", t)

        # Shadowed lights (DESIGN section 2): candidates affect a visible object.
        candidate = vis_l & lights.shadows
        shadow_rows, shadow_tier = np.zeros(0, np.int32), np.zeros(0, np.uint16)
        if candidate.any():
            cand_rows = np.flatnonzero(candidate).astype(np.int32)
            candidate[cand_rows] = affects_any(packed, cand_rows, grid.grid, grid.vis)
            shadow_rows, shadow_tier = rank_shadow_lights(
                lights, frames, candidate, self._shadow_prev[0], self._shadow_prev[1],
                cfg.shadow_budget, cfg.hysteresis, cfg.hysteresis_abs, cfg.c1)
        shadow_of_row = np.full(n_l, -1, np.int8)
        shadow_of_row[shadow_rows] = np.arange(shadow_rows.size)
        live = vis_l.copy()
        if cfg.unshadowed == "skip":
            # A shadowed light without a shadow map affects nothing (it would leak
            # through walls): its pairs stay cached but do not compete.
            live &= ~(lights.shadows & (shadow_of_row < 0))
        dir_rows = dir_all[live[dir_all]] if not cfg.directional_in_slots else \
            np.zeros(0, np.int64)
        if dir_rows.size > 1:
            dir_p = lights.intensity[dir_rows] + lights.priority[dir_rows]
            dir_rows = dir_rows[np.lexsort((lights.id[dir_rows], -dir_p))]
        # (One sun, the common case, needs no order: five numpy calls fewer.)
        directional = lights.id[dir_rows]
        t = _lap(seconds, "shadows", t)

        recompute = np.ones(shadow_rows.size, np.bool_)
        patch = None
        if c is not None and lrows is not None and same_cams:
            # Casters depend on the light, the cameras and every object: a light none of
            # them changed for keeps its list; when only objects changed, a directional
            # light's list changes only at those objects' rows.
            changed_l = np.zeros(n_l, np.bool_)
            changed_l[lrows] = True
            again = np.array([changed_l[r] or int(r) not in c.casters
                              for r in shadow_rows.tolist()], np.bool_)
            if orows.size == 0 and orows_cast.size == 0:
                recompute = again
            else:
                # (np.union1d took 1.8 ms for 10k rows.)
                rows_p = orows
                if orows_cast.size:
                    mark = np.zeros(n, np.bool_)
                    mark[orows] = True
                    mark[orows_cast] = True
                    rows_p = np.flatnonzero(mark)
                patch = (rows_p, again)
        casters, kept_casters, plan["casters"] = self._casters(
            frames, splits, shadow_rows, packed, grid, rec_frame, vis_o, recompute,
            None if c is None else c.casters, patch)
        t = _lap(seconds, "casters", t)

        # The pair cache: built from this frame's pairs, or the changed lists rewritten.
        n_pairs = -1  # the pairs of the cache, where known without a count
        if full and fresh is None:
            assert cands is not None
            dir_rows = dir_all[compete[dir_all]]
            c_seg, _, c_j, _ = cands.lists
            seg = np.empty((n, 2), np.int64)
            heap = self._new_heap(self._pair_room(cands, n, dir_rows.size))
            args = (self._rows(n), (c_seg, c_j), cands.recs, packed, compete, dir_rows,
                    p_params)
            used, n_pairs, _ = candidate_pairs(*args, (seg, *heap), 0)
            if n_pairs < 0:
                self._spare_heap = heap
                heap = self._new_heap(int(used))
                used, n_pairs, _ = candidate_pairs(*args, (seg, *heap), 0)
            used, n_pairs = int(used), int(n_pairs)
            run = self._rows(n, read_only=False)
            plan["lists"] = "every pair from the objects' candidate lists, by object row"
        elif full:
            start, heap = self._group(fresh, n, cached=True)
            seg = np.empty((n, 2), np.int64)
            seg[:, 0] = start[:-1]
            np.subtract(start[1:], start[:-1], out=seg[:, 1])
            used = n_pairs = int(start[-1])
            run = self._rows(n, read_only=False)
            plan["lists"] = "grouped by object (every pair new)"
        elif by_lists:
            reselect = np.flatnonzero((live != c.live) | (shadow_of_row != c.shadow_of_row))
            list_objects(cands.by_light, reselect, reach)
            # The visibility is last frame's: an object out of view has no pairs. (As
            # bytes: the kernel's loop on bools took ~35% longer.)
            more = (c.fading | vis_o | c.vis_o) if cut else c.fading
            rows, run = reached_rows(reach.view(np.uint8), vis_o.view(np.uint8),
                                     more.view(np.uint8))
            c_seg, _, c_j, _ = cands.lists
            seg, heap, used, n_pairs = c.seg, c.heap, c.used, c.pairs
            if rows.size:
                args = (rows, (c_seg, c_j), cands.recs, packed, compete, _NO_ROWS, p_params)
                at, wrote, dropped = candidate_pairs(*args, (seg, *heap), used)
                if wrote < 0:
                    seg, heap, used = _room(self._new_heap, seg, heap, used, n_pairs,
                                            int(at) - used)
                    at, wrote, dropped = candidate_pairs(*args, (seg, *heap), used)
                need = int(at) - used
                used, n_pairs = int(at), n_pairs - int(dropped) + int(wrote)
                # Packed now, not at the start of the next frame like this one (which would
                # not fit, or would leave the heap mostly garbage): that frame then writes
                # into room it knows it has, without a failed try.
                seg, heap, used = _room(self._new_heap, seg, heap, used, n_pairs, need)
            plan["lists"] = (f"cache kept; the lists of {rows.size} objects made again from "
                             f"their candidates; {run.size} of {np.count_nonzero(vis_o)} visible "
                             "objects recomputed (in reach of changed lights or of lights "
                             "whose shadow map changed, fading slots"
                             + (", a cut" if cut else "") + ")")
        else:
            def near(flagged: np.ndarray) -> np.ndarray | None:
                # The objects that can hold a pair of the lights ``flagged``, when none of
                # them changed this frame: each such pair was made with the light as it
                # is, so an object holding one that is in view now meets the light in the
                # grid (exact records: the same test, the same bits); one that moved, came
                # into view or left it takes new lists whatever it holds. None: scan every
                # object's pairs (a light changed, a directional one, float32 records whose
                # origin may have moved, or more walks than the scan costs).
                if (fast or lrows is None or flagged.size * NEAR_SCAN_PAIRS > c.pairs
                        or is_dir[flagged].any() or np.isin(flagged, lrows).any()):
                    return None
                order = light_order(packed[0], flagged.astype(np.int32), grid.grid[0],
                                    grid.grid[1])
                _, offsets, count, pair_obj, _ = self._walk(packed, order, grid, p_params,
                                                            "near")
                return np.unique(np.concatenate(
                    [pair_obj[offsets[t]:offsets[t] + count[t]] for t in range(order.size)]
                    + [_NO_ROWS]))
            seg, (heap, used, n_pairs), run, scanned = self._patch(
                c, walked, live, shadow_of_row, fresh, fresh_obj, fresh_rows, left_rows, cut,
                vis_o, near)
            plan["lists"] = (f"cache kept; {scanned}; {run.size} of {np.count_nonzero(vis_o)} visible "
                             f"objects recomputed (pairs of changed lights, moved or newly "
                             f"visible objects, shadow-map changes, fading slots"
                             + (", a cut" if cut else "") + ")")
        t = _lap(seconds, "lists", t)

        # Selection and fade of the objects to recompute (every object in a full frame).
        reset = objs.is_new | ~objs.get("was_visible")
        if self.frame_index == 0 or cut:
            reset = np.ones(n, np.bool_)
        k = cfg.max_lights
        state = (_read_only(objs.get("slot_light")), objs.get("slot_weight"),
                 _read_only(objs.get("slot_state")), objs.get("selected"))
        if full:
            out, out_vis = self._outputs(c, None, n, k)
            fading = np.empty(n, np.bool_)
            if out_vis is not None and c is not None and orows is not None:
                # A row out of view now, last frame (whose object is this one: the rows did
                # not change, and its state was cleared then) and in the frame whose arrays
                # these are (an invisible object's row is empty) already holds what the
                # object pass would write. At (1M, 100k) a fifth of the rows: on captured
                # inputs the pass 22.3 -> 18.5 ms without them (bench/RESULTS.md).
                run = self._run_rows((vis_o, c.vis_o, out_vis))
                if run.size < n:
                    fading[:] = False
                    plan["lists"] += (f"; {n - run.size} objects out of view keep their "
                                      "empty rows (and in the two frames before)")
        elif run.size:
            out = self._outputs(c, run, n, k)[0]
            fading = c.fading.copy()
        else:
            out = {name: getattr(c.frame, name) for name in _OUT}
            fading = c.fading
        if c is not None and run.size:
            # The last frame's arrays lag this frame's by the rows this frame recomputes.
            self._spare = ({name: getattr(c.frame, name) for name in _OUT},
                           None if full else run, c.vis_o)
        out["visible"] = vis_o
        if run.size:
            params = np.array([cfg.hysteresis, cfg.hysteresis_abs, _rate(dt, cfg.fade_in),
                               _rate(dt, cfg.fade_out), cfg.fade_in, cfg.fade_out])
            live_id = live_ids(lights.id, live, self._scratch("live_id", n_l, np.int32)[:n_l])
            object_pass(run, (_read_only(vis_o), reset), (seg, heap), live_id, state,
                        tuple(out[name] for name in _OUT) + (fading,), params,
                        (shadow_of_row, cfg.max_shadowed_per_object),
                        (0,) * k if k in STATIC_K else ())
        t = _lap(seconds, "objects", t)

        objs.put("slot_light", out["light_ids"])
        objs.put("slot_state", out["fade_state"])
        objs.put("was_visible", vis_o)
        # The ids as last frame's while the store's id array is the same one (frames are
        # read-only, so they share it): a copy of 100k ids is ~20 us.
        if c is not None and c.objects["id"] is objs.id:
            out["object_id"] = c.frame.object_id
        frame = empty_frame(
            objs.id, k, cfg.cascades, **out, directional_lights=directional.astype(np.int32),
            visible_lights=lights.id[vis_l], cascade_splits=splits,
            shadow_lights=lights.id[shadow_rows], shadow_tier=shadow_tier,
            caster_offsets=casters[0], caster_ids=casters[1], caster_masks=casters[2])
        freeze(frame)
        if c is not None and c.heap[0] is not heap[0]:
            self._spare_heap = c.heap
        prev_ids, shadow_ids = self._shadow_prev[0], lights.id[shadow_rows]
        # (At most shadow_budget <= 127 ids: Python's sort, not numpy's ~5 us of calls.)
        settled = sorted(prev_ids.tolist()) == sorted(shadow_ids.tolist())
        if n_pairs < 0:
            n_pairs = int(seg[:, 1].sum())
        self._shadow_prev = (shadow_ids, shadow_tier.astype(np.int64))
        self._cache = _Cache(
            lights={f: getattr(lights, f) for f in LIGHT_FIELDS},
            objects={f: getattr(objs, f) for f in OBJECT_FIELDS}, cam_key=key,
            frames=frames, splits=splits, vis_l=vis_l, vis_o=vis_o, box=box, compete=compete,
            packed=packed, grid=grid, seg=seg, heap=heap, used=used, pairs=n_pairs, live=live,
            shadow_of_row=shadow_of_row, fading=fading, shadows_settled=settled, frame=frame,
            casters=kept_casters, origin=origin, cands=cands,
            light_grid=light_cells, vis_groups=vis_groups)
        if not full:
            why = [f"{lrows.size} lights and {orows.size} objects changed",
                   "cameras " + ("unchanged" if same_cams else "moved")]
            if c.fading.any():
                why.append(f"{np.count_nonzero(c.fading)} objects fading")
            if not c.shadows_settled:
                why.append("the shadowed set changed last frame")
            if cut:
                why.append("a cut")
            plan["frame"] = "incremental: " + ", ".join(why)
        plan["visibility"] = f"frustum planes, {len(frames)} camera(s)" + (
            "; the objects' kept (they and the cameras did not change)" if objects_kept else
            f"; the {orows.size} changed objects' only (the cameras did not change)"
            if objects_moved else vis_how)
        plan["priority"] = cfg.model + (
            " (fast: float32 object records relative to the first camera's position, re-anchored "
            f"beyond {REANCHOR:g} m; float64 arithmetic)"
            if fast else " (exact float64)") + packing
        plan["fade"] = "fused with selection in the object pass"
        plan["shadows"] = (f"{shadow_rows.size} of {np.count_nonzero(candidate)} candidates "
                           "shadowed (ranking, tiers, slot_shadow)"
                           if candidate.any() else "skipped: no visible shadowed light "
                           "affects a visible object")
        t = _lap(seconds, "output", t)
        seconds["total"] = sum(seconds.values())
        frame.stats = {
            "plan": plan,
            "counts": {
                "objects": n,
                "visible_objects": int(np.count_nonzero(vis_o)),
                "lights": n_l,
                "visible_lights": int(np.count_nonzero(vis_l)),
                "competing_lights": int(np.count_nonzero(compete)),
                "pairs": n_pairs,
                # (An int32 sum of int32 counts is ~3.5x faster: 0.22 -> 0.06 ms at 1M.)
                "slots": int(frame.count.sum(dtype=np.int32 if n * k < 2**31 else np.int64)),
                "shadow_lights": int(shadow_rows.size),
                "casters": int(casters[1].size),
                "recomputed_objects": int(run.size),
                "changed_lights": n_l if lrows is None else int(lrows.size),
                "changed_objects": n if orows is None else int(orows.size),
                "threads": nb.get_num_threads(),
            },
            "seconds": seconds,
        }
        return frame

    # ------------------------------------------------------------------ stages

    def _outputs(self, c: _Cache | None, written_rows: np.ndarray | None, n: int, k: int
                 ) -> tuple[dict[str, np.ndarray], np.ndarray | None]:
        """Arrays for this frame's per-object outputs (PER_OBJECT but "visible"): every row
        is written when ``written_rows`` is None (a full frame), else only those rows are,
        the others must be the last frame's. The arrays of the frame before the last are
        taken back when nothing outside holds them any more (a steady scene allocates no
        output memory) and brought up to date with the rows the last frame changed and this
        one does not write; else new arrays (copies of the last frame's for an incremental
        frame). Also, for a full frame that takes them back, the visibility of the frame
        they held (its invisible objects' rows are empty), else None."""
        spare, lag, spare_vis = self._spare if self._spare is not None else (None, None, None)
        self._spare = None
        if (spare is not None and spare["light_ids"].shape == (n, k)
                and not held_elsewhere(spare)):
            for arr in spare.values():
                arr.setflags(write=True)
            if written_rows is not None:
                assert c is not None
                if lag is not None:
                    # Rows this frame writes need no copy: with the same lights moving
                    # frame after frame, that is nearly all of the lag.
                    lag = rows_not_in(lag, written_rows)
                for name, arr in spare.items():
                    src = getattr(c.frame, name)
                    if lag is None:
                        np.copyto(arr, src)
                    else:
                        copy_rows(src.reshape(n, -1), arr.reshape(n, -1), lag)
                return spare, None
            return spare, spare_vis if spare_vis.shape == (n,) else None
        if written_rows is None:
            return {name: np.empty((n, k) if PER_OBJECT[name][1] == "NK" else n,
                                   PER_OBJECT[name][0]) for name in _OUT}, None
        assert c is not None
        return {name: getattr(c.frame, name).copy() for name in _OUT}, None

    def _every_grid(self, c: _Cache | None, same_origin: bool,
                    visible: tuple[np.ndarray, np.ndarray], orows: Any,
                    packed: tuple[np.ndarray, np.ndarray], compete: np.ndarray,
                    is_dir: np.ndarray, frame: tuple[np.ndarray, bool]) -> tuple[_Grid, bool]:
        """The grid of every object, and whether it was kept: the last frame's serves while
        the records' origin is the same (``same_origin``), its cell edge is within
        CELL_SLACK of the one the lights ask for, and every object that changed (``orows``)
        still lies where the grid's walks look for its record (pairs.move_records, which
        rewrites those records in place); then the records of the objects whose visibility
        changed get their mask word again (_shown_mask). visible = (vis_o, the rows whose
        flag differs from last frame's vis_o)."""
        vis_o, flipped = visible
        objs = self.objects
        n = len(objs)
        kept = (c is not None and c.grid.shown is not None and orows is not None
                and same_origin)
        moved = "the objects did not change"
        if kept and orows.size:
            g = c.grid
            kept = move_records(objs.bounds_min, objs.bounds_max, orows,
                                _shown_mask(vis_o[orows], objs.mask[orows], frame[1]),
                                g.grid, g.vis[:2], g.pos_of, frame)
            if kept and g.group_box is not None:
                widen_group_boxes(g.group_box, objs.bounds_min, objs.bounds_max, orows,
                                  g.pos_of)
            moved = f"{orows.size} changed objects' records rewritten in place"

        def every_box() -> np.ndarray:
            # Axis by axis: numpy's min over axis 0 of an [N, 3] array took 2.6 ms at 100k
            # objects, a strided column 0.04.
            return np.array([objs.bounds_min[:, a].min() for a in range(3)]
                            + [objs.bounds_max[:, a].max() for a in range(3)])

        box = c.grid.box if kept else every_box()
        # The competing lights' radii set the cell edge: the same ones ask for the same grid
        # (their median is ~0.1 ms at 10k lights, ~0.35 at 100k). Lights entering and
        # leaving the view change a few of them every frame; the edge is checked again
        # once EDGE_DRIFT of them changed since it last was, or any radius did. The edge
        # sets the cost of the walks, never their pairs.
        radii = packed[0][:, 3]
        edge_of = c.grid.edge_of if kept else None
        # (Radii of another light count are not equal: the compare below then never runs.
        # Their bytes: radii are > 0, so bitwise equality is equality; ~0.2 us against
        # np.array_equal's ~1.8 on a hundred lights.)
        same_radii = (edge_of is not None and radii.tobytes() == edge_of[1]
                      and np.count_nonzero(compete != edge_of[0]) <= EDGE_DRIFT * edge_of[2])
        shape = None
        if not same_radii:
            shape = _grid_shape(n, box, packed, compete, is_dir, frame)
            edge_of = (compete.copy(), radii.tobytes(), int(np.count_nonzero(compete)))
        if kept and shape is not None:
            g_f = c.grid.grid[0]
            if (shape[2] is not None) != c.grid.plan.startswith("brute"):
                kept = False
            elif shape[2] is not None:
                kept = np.array_equal(shape[0], g_f) and np.array_equal(shape[1], c.grid.grid[1])
            else:
                ratio = shape[0][3] / g_f[3]  # kept edge over the edge asked for
                kept = 1 / CELL_SLACK <= ratio <= CELL_SLACK
            if not kept and orows.size:
                # The kept box missed the objects that moved.
                box = every_box()
                shape = _grid_shape(n, box, packed, compete, is_dir, frame)
        if kept:
            g = c.grid
            rows = (np.zeros(0, np.int64) if vis_o is g.shown
                    else flipped if g.shown is c.vis_o else np.flatnonzero(vis_o != g.shown))
            if rows.size:
                g.vis[1][g.pos_of[rows], 6] = _shown_mask(vis_o[rows], objs.mask[rows],
                                                          frame[1])
            plan = g.plan.split(" (kept", 1)[0] + (
                f" (kept: {moved}; {rows.size} records' visibility updated)")
            return _Grid(g.grid, g.vis, plan, vis_o, g.pos_of, box, edge_of, g.group_box), True
        assert shape is not None
        g_f, dims, plan = shape
        out = self._scratch("records", 8 * n, np.float32 if frame[1] else np.float64)
        grid, recs, pos_of = _object_grid(objs.bounds_min, objs.bounds_max,
                                          _shown_mask(vis_o, objs.mask, frame[1]),
                                          np.ones(n, np.bool_), g_f, dims, frame, out)
        if plan is None:
            plan = _grid_plan("every object, the invisible ones masked out", grid)
        return _Grid(grid, recs, plan, vis_o, pos_of, box, edge_of), False

    def _visible_grid(self, select: np.ndarray, box: np.ndarray,
                      packed: tuple[np.ndarray, np.ndarray], compete: np.ndarray,
                      is_dir: np.ndarray, frame: tuple[np.ndarray, bool],
                      shape: tuple[np.ndarray, np.ndarray, str | None] | None = None,
                      records: str | None = None) -> _Grid:
        """The selected objects sorted into a grid of cells (``_grid_shape``, unless the
        caller has it as ``shape``), with their records in the frame (origin, single) of the
        packed lights, written into the scratch buffer named ``records`` if given."""
        objs = self.objects
        n_sel = int(np.count_nonzero(select))
        g_f, dims, plan = shape if shape is not None else _grid_shape(
            n_sel, box, packed, compete, is_dir, frame)
        out = None if records is None else self._scratch(
            records, 8 * n_sel, np.float32 if frame[1] else np.float64)
        grid, recs, _ = _object_grid(objs.bounds_min, objs.bounds_max, objs.mask, select, g_f,
                                     dims, frame, out)
        if plan is None:
            plan = _grid_plan("visible objects", grid)
        return _Grid(grid, recs, plan)

    def _walk(self, packed: tuple[np.ndarray, np.ndarray], rows: np.ndarray, grid: _Grid,
              p_params: np.ndarray, name: str) -> tuple[np.ndarray, ...]:
        """Affects and P of the lights ``rows`` against the objects of ``grid``:
        (rows, offsets, count, pair_obj, pair_p) in light-major segments (pairs.light_pass)."""
        offsets = light_bounds(packed[0], rows, grid.grid, grid.vis[0].shape[0])
        pair_obj = self._scratch(name + "_obj", int(offsets[-1]), np.int32)
        pair_p = self._scratch(name + "_p", int(offsets[-1]), np.float64)
        count = light_pass(packed, rows, grid.grid, grid.vis, offsets, pair_obj, pair_p,
                           p_params)
        return rows, offsets, count, pair_obj, pair_p

    def _group(self, walked: tuple[np.ndarray, ...], n: int, cached: bool = False
               ) -> tuple[np.ndarray, tuple[np.ndarray, np.ndarray]]:
        """Light-major pairs grouped by object row: (start [N+1], (P float64 [H], light row
        int32 [H])), object o's pairs at start[o]..start[o+1]-1. ``cached``: the pairs are
        the new pair cache, in a heap from _new_heap (H may be larger than the pairs)."""
        rows, offsets, count, pair_obj, pair_p = walked
        n_pairs = int(count.sum())
        start = np.empty(n + 1, np.int64)
        heap = (self._new_heap(n_pairs) if cached
                else (np.empty(n_pairs), np.empty(n_pairs, np.int32)))
        # Positions fit int32 below 2^31 pairs: half the bytes keeps each thread's histogram
        # in its core's L2 at 100k objects (the grouping 3.5 -> 3.2 ms in a full frame).
        wide = n_pairs >= 2**31
        hist = self._scratch("hist64" if wide else "hist", GROUP_PARTS * (n + 1),
                             np.int64 if wide else np.int32)
        parts = group_parts(n_pairs)
        group_pairs(rows, offsets, count, pair_obj, pair_p,
                    (hist[:parts * (n + 1)].reshape(parts, n + 1), start, heap))
        return start, heap

    def _fresh_pairs(self, rows: np.ndarray, packed: tuple[np.ndarray, np.ndarray],
                     compete: np.ndarray, is_dir: np.ndarray, p_params: np.ndarray,
                     frame: tuple[np.ndarray, bool], light_cells: tuple | None
                     ) -> tuple[np.ndarray, tuple[np.ndarray, np.ndarray]]:
        """The pairs of the object ``rows`` (ascending) with every competing light, each
        object tested against all of them (pairs.direct_pairs) or, given a grid of the
        lights, against those of the cells its box overlaps (pairs.grid_pairs), as (start
        [N + 1], (P, light row)) grouped by object row: valid at ``rows`` and the row after
        each, which is all that replace_lists reads of them."""
        objs = self.objects
        recs = np.empty((rows.size, 8), np.float32 if frame[1] else np.float64)
        bits = recs.view(np.uint32 if frame[1] else np.uint64)
        visible_objects(objs.bounds_min, objs.bounds_max, objs.mask, rows, rows.size,
                        (recs, bits), frame[0])
        dir_rows = np.flatnonzero(compete & is_dir)
        if light_cells is not None:
            return grid_pairs(rows, (recs, bits), packed, compete, light_cells, dir_rows,
                              p_params, len(objs))
        point_rows = np.flatnonzero(compete & ~is_dir).astype(np.int32)
        return direct_pairs(rows, (recs, bits), packed, compete, point_rows, dir_rows,
                            p_params, len(objs))

    def _candidates(self, old: _Candidates | None, packed: tuple[np.ndarray, np.ndarray],
                    compete: np.ndarray, dir_all: np.ndarray, grid: _Grid, hidden: bool,
                    last_position: np.ndarray | None = None
                    ) -> tuple[_Candidates, int, bool]:
        """The candidate lists for this frame's lights (``old`` valid or None): a competing
        point or spot light keeps its candidates while its sphere lies inside the one they
        were found with (pairs.left_spheres); the others walk the grid again with
        their sphere widened by SKIN and centred ahead along their last step (LEAD, given
        ``last_position``, each light's position last frame), range test only (every
        light mask bit: the lists must not depend on the lights' masks, which may change
        while they are kept), a light that turned directional is dropped from them, and the
        lists of the objects they leave or enter are edited in place (pairs.edit_candidates;
        a list that outgrows its room moves to the spare room). All are made again when
        there are none, most lights left theirs, or the spare room ran out; made with
        ``hidden`` (the camera moves) they hold the objects out of view too, by their own
        mask, so that they serve the objects a moving camera brings into view; else only the
        objects in view, which keeps the walks and lists of a still camera ~25% smaller at
        (1M, 100k). ``dir_all``: the rows of the directional lights. Returns (lists, the
        rows of the lights whose lists changed: those walked and those dropped, made from
        scratch)."""
        hot = packed[0]
        n_l = hot.shape[0]
        own = compete.copy()
        own[dir_all] = False
        walk_mask = own
        hold = hidden if old is None else old.hidden
        gone = np.zeros(0, np.int64)
        if old is not None:
            walk_mask = left_spheres(hot, old.anchor, own)
            if np.count_nonzero(walk_mask) > REBUILD_SHARE * np.count_nonzero(own):
                old, walk_mask, hold = None, own, hidden
            else:
                # A point or spot light that turned directional still has its objects in
                # the lists (it has an anchor), where candidate_pairs would pair it again
                # beside its directional pair: it is dropped from them, as a walk that
                # found nothing.
                # (Read at the few directional rows: the whole column is ~10 us at 10k
                # lights.)
                gone = dir_all[old.anchor[dir_all, 3] > 0]
        # The walk as the light pass's with every light a point light of the widened radius
        # and every mask bit (its P are not used). The walk reads the rows of the lights it
        # walks only: those are written, into a kept buffer (the copy of every row and its
        # three columns took 0.34 ms at 100k lights, against 0.05 for 2000 rows).
        wide = self._scratch("wide", n_l * 8, np.float64)[:n_l * 8].reshape(n_l, 8)

        now = self.lights.position
        # Centred ahead of a moving light, along its last step: it crosses the widened
        # sphere before it leaves it, ~(1 + LEAD) x as many frames.
        positions = (now, now if last_position is None else last_position)

        exact = grid.vis[0].dtype == np.float64

        def walk_of(mask: np.ndarray) -> tuple[np.ndarray, ...]:
            # Lists that hold the objects out of view: in float64 records those keep their
            # masks in the upper half of the word, which a walker's mask of every bit of
            # the word meets (SHOWN).
            every = -1.0 if hold and exact else float(SHOWN)
            sel = widen_walkers(hot, mask, positions, wide, (SKIN, LEAD, every))
            rows = light_order(hot, sel, grid.grid[0], grid.grid[1])
            p_params = np.array([MODEL_CONTRIBUTION, 0.0, 0.0])
            if not hold or exact:
                return self._walk((wide, packed[1]), rows, grid, p_params, "cand")
            # Float32 records, whose out-of-view objects' masks are 0: those carry their
            # own mask during the walk.
            if (self._hidden is None or self._hidden[0] is not grid.shown
                    or self._hidden[1] is not grid.pos_of):
                # Kept with the visibility and grid they come from (new arrays when those
                # change).
                out_of_view = np.flatnonzero(~grid.shown)
                self._hidden = (grid.shown, grid.pos_of, grid.pos_of[out_of_view],
                                self.objects.mask[out_of_view])
            pos, mask_of = self._hidden[2:]
            grid.vis[1][pos, 6] = mask_of
            try:
                return self._walk((wide, packed[1]), rows, grid, p_params, "cand")
            finally:
                grid.vis[1][pos, 6] = 0

        walked = walk_of(walk_mask)
        if gone.size:
            rows, offsets, count = walked[:3]
            walked = (np.concatenate([rows, gone.astype(rows.dtype)]),
                      np.concatenate([offsets, np.full(gone.size, offsets[-1])]),
                      np.concatenate([count, np.zeros(gone.size, count.dtype)]), *walked[3:])
        if old is not None:
            if edit_candidates(walked[:4], old.lists, old.by_light):
                by_light, used = old.by_light, old.used
                n_new = int(walked[2].sum())
                if used + n_new > by_light[1].size:
                    # Packed, with room for the live lists again (a few dozen frames).
                    l_seg, l_obj, used = compact_light_lists(
                        by_light, int(by_light[0][:, 1].sum()) + n_new + 1024)
                    by_light = (l_seg, l_obj)
                used = light_lists(walked[:4], by_light, used)
                out = _Candidates(old.anchor, old.lists, by_light, used, old.recs, hold)
            else:
                old, walk_mask, hold, gone = None, own, hidden, gone[:0]
                walked = walk_of(own)
        if old is None:
            n = grid.pos_of.size
            start, (_, light_j) = self._group(walked, n)
            room = int(list_room(start))
            lists = (np.empty((n, 2), np.int64), np.empty(n, np.int64),
                     np.empty(room + max(4096, room // 4), np.int32),
                     np.empty((GROUP_PARTS, 2), np.int64))
            spread_lists(start, light_j, lists)
            by_light = (np.zeros((n_l, 2), np.int64),
                        np.empty(2 * light_j.size + 1024, np.int32))
            used = light_lists(walked[:4], by_light, 0)
            box = np.take(grid.vis[0], grid.pos_of, axis=0, mode="wrap",
                          out=aligned_empty((n, 8), grid.vis[0].dtype))
            out = _Candidates(np.zeros((n_l, 4)), lists, by_light, used,
                              (box, box.view(grid.vis[1].dtype)), hold)
        walk = walked[0][:walked[0].size - gone.size]
        out.anchor[walk] = wide[walk, :4]
        out.anchor[gone, 3] = 0.0
        return out, walked[0], old is None

    def _patch(self, c: _Cache, walked: np.ndarray, live: np.ndarray,
               shadow_of_row: np.ndarray, fresh: tuple[np.ndarray, ...],
               fresh_obj: tuple[np.ndarray, tuple[np.ndarray, np.ndarray]],
               fresh_rows: np.ndarray, left_rows: np.ndarray, cut: bool, vis_o: np.ndarray,
               near: Callable[[np.ndarray], np.ndarray | None]
               ) -> tuple[np.ndarray, tuple[tuple[np.ndarray, np.ndarray], int, int],
                          np.ndarray, str]:
        """The cache's pair lists brought up to date (seg, (heap, records used, live pairs)),
        the object rows to recompute, and which pairs were scanned (for the plan).

        Objects holding a pair of a walked light (found by scanning the cache: every
        object's pairs, or those of the objects ``near`` gives for the flagged lights) and
        objects the walk gave pairs keep their other pairs and take the fresh ones; moved
        or newly visible objects take their new lists (``fresh_obj``: grouped by object
        row, start valid at ``fresh_rows`` and the row after each); objects that left the
        view lose theirs."""
        n = vis_o.size
        flag = np.zeros(live.size, np.uint8)
        flag[walked] |= WALKED
        flag[(live != c.live) | (shadow_of_row != c.shadow_of_row)] |= RESELECT
        flagged = np.flatnonzero(flag)
        rows_near = near(flagged) if flagged.size else None
        if rows_near is not None:
            holds, kept = scan_rows(rows_near, c.seg, c.heap[1], flag, WALKED)
            scanned = (f"the pairs of the {rows_near.size} objects the {flagged.size} "
                       "flagged lights reach scanned")
        elif flagged.size:
            holds, kept = scan_pairs(c.seg, c.heap[1], flag, WALKED)
            scanned = f"every object's pairs scanned for {flagged.size} flagged lights"
        else:
            holds, kept = np.zeros(n, np.uint8), np.zeros(0, np.int64)
            scanned = "no light flagged"
        few = int(fresh[2].sum()) <= FEW_PAIRS * n
        rows1 = np.union1d(fresh_rows, left_rows)
        if few:
            w_obj, w_pairs = group_few(*fresh)
        else:
            w_start, w_pairs = self._group(fresh, n)
        if few and rows_near is not None and not cut:
            # Only the objects near the flagged lights, the walk's objects and rows1 can
            # change: the same rows as below, without its passes over every row (~0.6 ms
            # at 1M objects).
            near_holds = holds[rows_near]
            rows2 = np.setdiff1d(np.union1d(rows_near[(near_holds & WALKED) != 0], w_obj),
                                 rows1, assume_unique=True)
            run = reduce(np.union1d, (rows_near[near_holds != 0], rows2, rows1,
                                      np.flatnonzero(c.fading)))
        else:
            rewrite = (holds & WALKED) != 0
            if few:
                rewrite[w_obj] = True
            else:
                rewrite |= w_start[1:] > w_start[:-1]
            rewrite[rows1] = False
            rows2 = np.flatnonzero(rewrite)
            run = (holds != 0) | rewrite | c.fading
            run[rows1] = True
            if cut:
                run |= vis_o | c.vis_o
            run = np.flatnonzero(run)
        if few:
            w_start = start_at(rows2, w_obj, n)
        # replace_lists' modes: 2 (rows2) the kept pairs and the walk's, 1 the new lists of
        # moved or newly visible objects, 0 none for those that left the view.
        mode1 = np.ones(rows1.size, np.int8)
        mode1[np.searchsorted(rows1, left_rows)] = 0
        o_start, o_pairs = fresh_obj
        # The cache is this frame's to change.
        seg, heap, used = _room(self._new_heap, c.seg, c.heap, c.used, c.pairs,
                                w_pairs[0].size + int(c.seg[rows2, 1].sum())
                                + o_pairs[0].size)
        walked_flag = (flag & WALKED) != 0
        # The cache's pairs follow from the rewritten lists' lengths (a sum over every
        # object's took 0.5 ms at 1M objects).
        rewritten = (rows1, rows2)
        n_pairs = c.pairs - sum(int(seg[rows, 1].sum()) for rows in rewritten)
        used = int(replace_lists(rows2, np.full(rows2.size, 2, np.int8), (seg, heap),
                                 walked_flag, kept, (w_start, w_pairs), used))
        used = int(replace_lists(rows1, mode1, (seg, heap), walked_flag, kept,
                                 (o_start, o_pairs), used))
        n_pairs += sum(int(seg[rows, 1].sum()) for rows in rewritten)
        return seg, (heap, used, n_pairs), run, scanned

    def _casters(self, frames: CameraFrames, splits: np.ndarray, shadow_rows: np.ndarray,
                 lights_packed: tuple[np.ndarray, np.ndarray], grid: _Grid,
                 frame: tuple[np.ndarray, bool], vis_o: np.ndarray, recompute: np.ndarray,
                 cached: dict[int, tuple[np.ndarray, np.ndarray]] | None,
                 patch: tuple[np.ndarray, np.ndarray] | None = None
                 ) -> tuple[tuple[np.ndarray, ...], dict[int, tuple[np.ndarray, np.ndarray]], str]:
        """(caster_offsets, caster_ids, caster_masks) of the shadow lights in rank order, the
        per-light lists to keep, and the plan: directional lights scan every object against
        their cascade sweeps (over a grid of every object, boxes round SWEEP_GROUP of its
        positions' objects first); point and spot lights walk the light pass's grid, and
        when it holds the visible objects only, a grid of the same kind over the invisible
        casting objects that meet their spheres' bounding box (objects need not be visible
        to cast). Lights with ``recompute`` False take their lists from ``cached``. ``patch``
        = (the object rows that changed, per shadow light whether it or the cameras did):
        a directional light that did not keeps its cached list but at those rows, which
        alone it sweeps (the sun's sweep of 100k objects took ~0.6 ms)."""
        lights, objs = self.lights, self.objects
        n_s = shadow_rows.size
        if n_s == 0:
            empty = (np.zeros(1, np.int64), np.zeros(0, np.int32), np.zeros(0, np.uint32))
            return empty, {}, "skipped: no shadow lights"
        found: list[tuple[np.ndarray, np.ndarray]] = [None] * n_s  # type: ignore[list-item]
        todo = []
        # A few lights: Python lists, not numpy calls of ~1-5 us each on tiny arrays.
        for t, (row, again) in enumerate(zip(shadow_rows.tolist(), recompute.tolist(),
                                             strict=True)):
            if again:
                todo.append(t)
            else:
                found[t] = cached[row]  # type: ignore[index]
        plan = [f"{n_s - len(todo)} kept (light, cameras and objects unchanged)"] \
            if len(todo) < n_s else []
        if todo:
            rows_t = shadow_rows[todo]
            vn, vq, vm, shared = culling_volumes(lights, rows_t, frames, splits,
                                                 self.config.cascade_overlap)
            lo, hi, casts = objs.bounds_min, objs.bounds_max, objs.casts_shadows
            is_dir = [t == DIRECTIONAL for t in lights.type[rows_t].tolist()]
            sun = [i for i, d in enumerate(is_dir) if d]
            patched = [] if patch is None else [i for i in sun if not patch[1][todo[i]]]
            sun = [i for i in sun if i not in patched]
            if sun:
                lmask = lights.mask[rows_t[sun]].astype(np.int64)
                sun_vols = (vn[sun], vq[sun], vm[sun], shared[sun])
                if grid.shown is not None:
                    # A grid of every object: its group boxes first.
                    boxes = _group_boxes(grid, lo, hi, frame[1])
                    at, rows, masks = sweep_groups(casts, objs.mask, lmask, sun_vols, boxes,
                                                   grid.group_box)
                    at = at.tolist()
                    for i, t in enumerate(sun):
                        found[todo[t]] = (rows[at[i]:at[i + 1]], masks[at[i]:at[i + 1]])
                    plan.append(f"{len(sun)} directional: the boxes of {SWEEP_GROUP} grid "
                                f"positions' objects, then the objects of those in a volume, "
                                f"against {vm.shape[1]} cascade sweeps")
                else:
                    bits = sweep_casters(lo, hi, casts, objs.mask, lmask, sun_vols)
                    for i, t in enumerate(sun):
                        rows = np.flatnonzero(bits[i])
                        found[todo[t]] = (rows, bits[i][rows])
                    plan.append(f"{len(sun)} directional: every object against "
                                f"{vm.shape[1]} cascade sweeps")
            if patched:
                assert patch is not None and cached is not None
                rows_p = patch[0]
                bits = sweep_casters(lo[rows_p], hi[rows_p], casts[rows_p], objs.mask[rows_p],
                                     lights.mask[rows_t[patched]].astype(np.int64),
                                     (vn[patched], vq[patched], vm[patched], shared[patched]))
                changed = np.zeros(len(objs), np.bool_)
                changed[rows_p] = True
                for i, t in enumerate(patched):
                    rows_c, masks_c = cached[int(rows_t[t])]
                    keep = ~changed[rows_c]
                    hit = np.flatnonzero(bits[i])
                    # Both ascending: the new rows go in at their places.
                    at = np.searchsorted(rows_c[keep], rows_p[hit])
                    found[todo[t]] = (np.insert(rows_c[keep], at, rows_p[hit]),
                                      np.insert(masks_c[keep], at, bits[i][hit]))
                plan.append(f"{len(patched)} directional: the {rows_p.size} changed objects "
                            f"against {vm.shape[1]} cascade sweeps, the others' kept")
            local = [i for i, d in enumerate(is_dir) if not d]
            if local:
                rows_l = rows_t[local].astype(np.int64)
                vols = (vn, vq, vm, shared)
                if len(local) < len(todo):
                    vols = (vn[local], vq[local], vm[local], shared[local])
                part = self._grid_casters(lights_packed, rows_l, grid.grid, grid.vis, vols)
                if grid.shown is not None:
                    for i, t in enumerate(local):
                        found[todo[t]] = (part[0][i], part[1][i])
                    plan.append(f"{len(local)} point/spot: the grid of every object")
                else:
                    parts = [part]
                    hidden, nh = self._hidden_casters(lights_packed, rows_l, vols, frame, vis_o)
                    parts += hidden
                    for i, t in enumerate(local):
                        rows = np.concatenate([p[0][i] for p in parts])
                        masks = np.concatenate([p[1][i] for p in parts])
                        order = np.argsort(rows, kind="stable")
                        found[todo[t]] = (rows[order], masks[order])
                    plan.append(f"{len(local)} point/spot: the grid of visible objects, then a "
                                f"grid of {nh} invisible casting objects near them")
        # (np.cumsum of a short Python list costs ~8 us, most of a small frame's glue here.)
        offsets = np.array(list(accumulate((f[0].size for f in found), initial=0)), np.int64)
        ids = objs.id[np.concatenate([f[0] for f in found])].astype(np.int32, copy=False)
        masks = np.concatenate([f[1] for f in found]).astype(np.uint32, copy=False)
        keep = dict(zip(shadow_rows.tolist(), found, strict=True))
        return (offsets, ids, masks), keep, "; ".join(plan)

    def _hidden_casters(self, lights_packed: tuple[np.ndarray, np.ndarray], rows: np.ndarray,
                        vols: tuple, frame: tuple[np.ndarray, bool], vis_o: np.ndarray
                        ) -> tuple[list[tuple[list[np.ndarray], list[np.ndarray]]], int]:
        """For a grid of the visible objects only: the casters of the point and spot lights
        ``rows`` among the invisible casting objects near their spheres, from a grid of
        just those (the same construction), as a list of at most one part of
        ``_grid_casters``; and how many such objects there are."""
        lights, objs = self.lights, self.objects
        lo, hi = objs.bounds_min, objs.bounds_max
        radius = lights.radius[rows]
        reach = lights.position[rows]
        r_box = np.concatenate([(reach - radius[:, None]).min(0),
                                (reach + radius[:, None]).max(0)])
        hidden = hidden_near(lo, hi, objs.casts_shadows, _read_only(vis_o), r_box)
        nh = hidden.size
        if nh == 0:
            return [], 0
        f_box = _frame_box(r_box, frame)
        g_f, dims = grid_shape(f_box[:3], f_box[3:], CELL_PER_RADIUS * float(np.median(radius)))
        h_grid, (h_box, h_bits, h_rows), _ = _object_grid(
            lo[hidden], hi[hidden], objs.mask[hidden], np.ones(nh, np.bool_), g_f, dims, frame)
        return [self._grid_casters(lights_packed, rows, h_grid, (h_box, h_bits, hidden[h_rows]),
                                   vols)], nh

    def _grid_casters(self, lights_packed: tuple[np.ndarray, np.ndarray], rows: np.ndarray,
                      grid: tuple, recs: tuple, vols: tuple
                      ) -> tuple[list[np.ndarray], list[np.ndarray]]:
        """Per light of ``rows``, (object rows, masks) of its casters in one grid."""
        offsets = light_bounds(lights_packed[0], rows, grid, recs[0].shape[0])
        out = (np.empty(int(offsets[-1]), np.int64), np.empty(int(offsets[-1]), np.uint32))
        objs = self.objects
        count = grid_casters(lights_packed, rows, grid, recs,
                             (objs.casts_shadows, objs.mask, objs.bounds_min, objs.bounds_max),
                             vols, offsets, out)
        spans = list(zip(offsets.tolist(), count.tolist(), strict=False))
        return [out[0][a:a + m] for a, m in spans], [out[1][a:a + m] for a, m in spans]


def _frame_box(box: np.ndarray, frame: tuple[np.ndarray, bool]) -> np.ndarray:
    """A world box (lo, hi) in the records' frame: relative to the origin, and in "fast"
    precision widened by float32's rounding so that it holds every rounded record."""
    origin, single = frame
    rel = box - np.concatenate([origin, origin])
    if single:
        pad = np.abs(rel) * 2.0**-22 + 1e-30
        rel = rel + np.concatenate([-pad[:3], pad[3:]])
    return rel


def _grid_shape(n_sel: int, box: np.ndarray, packed: tuple[np.ndarray, np.ndarray],
                compete: np.ndarray, is_dir: np.ndarray, frame: tuple[np.ndarray, bool]
                ) -> tuple[np.ndarray, np.ndarray, str | None]:
    """(g_f, dims, plan or None) of the grid of n_sel objects in the world box ``box``:
    cells of edge CELL_PER_RADIUS x the median radius of the competing point and spot
    lights, or a single cell when there are few enough pairs for brute force (its plan)."""
    point_rows = np.flatnonzero(compete & ~is_dir)
    box = np.zeros(6) if n_sel == 0 else _frame_box(box, frame)
    if point_rows.size * n_sel <= BRUTE_FORCE_PAIRS:
        # One cell holding every selected object: each light tests them all.
        g_f, dims = grid_shape(box[:3], box[3:], 2.0 * max(float(np.max(box[3:] - box[:3])), 1.0))
        return g_f, dims, f"brute force ({np.count_nonzero(compete)} lights x {n_sel} objects)"
    radii = packed[0][point_rows, 3]
    median = float(np.partition(radii, radii.size // 2)[radii.size // 2])
    g_f, dims = grid_shape(box[:3], box[3:], CELL_PER_RADIUS * median)
    return g_f, dims, None


def _grid_plan(what: str, grid: tuple) -> str:
    """The plan of a grid of ``what``: its cells and how many objects it tests directly."""
    g_f, dims, big_pos = grid[0], grid[1], grid[4]
    return (f"grid of {what} ({dims[0]}x{dims[1]}x{dims[2]} cells of {1 / g_f[3]:.3g} m, "
            f"z {RUN_SPLIT}x finer, {big_pos.size} objects larger than a cell tested directly)")


def _group_boxes(grid: _Grid, lo: np.ndarray, hi: np.ndarray, single: bool
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, bool]:
    """The boxes of a grid of every object as shadows.group_boxes reads them, its group
    boxes made from them if it has none yet. Its records hold the world boxes in exact
    precision (origin 0, float64), in grid order; "fast" ones (``single``) are rounded, so
    the stores' boxes (lo, hi) are read by row."""
    boxes = ((lo, hi, grid.vis[2], True) if single else
             (grid.vis[0][:, :3], grid.vis[0][:, 3:6], grid.vis[2], False))
    if grid.group_box is None:
        grid.group_box = group_boxes(boxes)
    return boxes


def _shown_mask(shown: np.ndarray, mask: np.ndarray, single: bool) -> np.ndarray:
    """The mask words of the records of a grid of every object (pairs.visible_objects,
    move_records), per object: its mask when ``shown``; else, so that it pairs with no
    light, 0 in float32 records (``single``) and in float64 records its mask in the upper
    half of the word, where the candidate lists' walk of a moving camera finds it without
    writing it (simd.SHOWN)."""
    if single:
        return np.where(shown, mask, 0).astype(mask.dtype, copy=False)
    wide = mask.astype(np.uint64)
    return np.where(shown, wide, wide << np.uint64(32))


def _object_grid(lo: np.ndarray, hi: np.ndarray, mask: np.ndarray, select: np.ndarray,
                 g_f: np.ndarray, dims: np.ndarray, frame: tuple[np.ndarray, bool],
                 out: np.ndarray | None = None) -> tuple[tuple, tuple, np.ndarray]:
    """The selected rows of (lo, hi, mask) sorted into the grid (g_f, dims), and their
    records: (grid (g_f, dims, cell_start, ext, big_pos), (records [V, 8], their integer
    view, row per position), position per row or -1). Records are float64, or float32 in
    "fast" precision, written into the front of ``out`` (1-d, of that dtype) if given."""
    vis_rows, pos_of, cell_start = visible_order(lo, hi, select, g_f, dims, frame)
    nv = vis_rows.size
    n_small = int(cell_start[int(dims[0] * dims[1] * dims[2])])
    vis_box = (np.empty((nv, 8), np.float32 if frame[1] else np.float64) if out is None
               else out[:8 * nv].reshape(nv, 8))
    vis_bits = vis_box.view(np.uint32 if frame[1] else np.uint64)
    ext = visible_objects(lo, hi, mask, vis_rows, n_small, (vis_box, vis_bits), frame[0])
    big_pos = np.arange(n_small, nv, dtype=np.int32)
    return (g_f, dims, cell_start, ext, big_pos), (vis_box, vis_bits, vis_rows), pos_of


def _room(new_heap: Callable[[int], tuple[np.ndarray, np.ndarray]], seg: np.ndarray,
          heap: tuple[np.ndarray, np.ndarray], used: int, n_live: int, need: int
          ) -> tuple[np.ndarray, tuple[np.ndarray, np.ndarray], int]:
    """A pair cache (seg, heap, records used; ``n_live`` of them live, the lengths in seg
    summed) with room for ``need`` more records. New lists go after the records in use
    (those are not written), the heap packed first when short of room or mostly garbage,
    into ``new_heap(records)`` (Scheduler._new_heap). The room left after packing holds ~4
    more frames like this one: with room for one, a scene moving 10% of its lights packed
    every other frame (~1 ms at 100k objects each time)."""
    if used + need > heap[0].size or used > 2 * (n_live + need) + 4096:
        seg, heap, used = compact_heap(seg, heap,
                                       new_heap(n_live + 4 * need + n_live // 2 + 1024))
    return seg, heap, used


def _same_point(a: np.ndarray, b: np.ndarray) -> bool:
    """Two records' origins (float64 [3]) are equal: as Python floats, ~0.4 us where
    np.array_equal takes ~3 on three elements."""
    return a.tolist() == b.tolist()


def _read_only(a: np.ndarray) -> np.ndarray:
    """A read-only view of ``a``. numba types an array's writability: the object pass's
    slot state and visibility are last frame's frozen outputs after the first frames and
    fresh arrays before, so passing them read-only always gives the kernel one signature,
    compiled once (~15 s on a cold cache) instead of again on the second frame. The same
    for the visibility that ``hidden_near`` reads."""
    view = a.view()
    view.setflags(write=False)
    return view


def _rate(dt: float, fade_time: float) -> float:
    return dt / fade_time if fade_time > 0.0 else 1.0


def _lap(seconds: dict[str, float], stage: str, t: float) -> float:
    now = time.perf_counter()
    seconds[stage] = now - t
    return now


def schedule(lights: dict[str, Any], objects: dict[str, Any], cameras: Any,
             config: Config | None = None) -> Frame:
    """Stateless one frame (DESIGN section 7): every object starts with its selected lights
    on, as on a scheduler's first frame."""
    s = Scheduler(config)
    s.set_lights(**lights)
    s.set_objects(**objects)
    return s.frame(cameras, dt=0.0, cut=True)
