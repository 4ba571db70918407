"""Scheduler and schedule(): a frame is a plan (plan.py), then the stages of DESIGN section 8
in order, each a function of its own room with typed inputs and outputs:

    cameras     frustum.frame_cameras    -> Cameras
    changes     changes.find_changes     -> Changes
    plan        plan.plan_frame          -> FramePlan
    visibility  visibility.see           -> Visibility
    pack        priority.pack            -> Packed
    grid        grid.object_grid         -> Grid
    pairs       pairs.find_pairs         -> Pairs
    shadows     shadows.choose_shadows   -> ShadowSet
    casters     casters.find_casters     -> Casters
    views       shadow_views.update_views -> ShadowViews (and the ShadowSet the slots see)
    lists       pair_cache.update_pair_cache -> PairCache
    objects     objects.select_and_fade  -> Outputs
    output      frame.py                 -> Frame

Last frame's stage outputs (``FrameState``) are what the next frame plans from, keeps or
patches (DESIGN section 6). Each stage is timed in stats["seconds"]; stats["plan"] is the
plan's text with each stage's own account of what it kept (FramePlan.describe).

The per-object state (slots, weights, last frame's selection) lives in the object store's
``state`` so it follows ids through set_/remove_ calls; the slot ids and states are the
last (read-only) frame's light_ids and fade_state.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numba as nb
import numpy as np

from .buffers import Buffers
from .casters import Casters, find_casters
from .changes import Changes, find_changes
from .explain import ExplainRecord, Explanation, explain_record
from .frame import Frame, empty_frame, freeze
from .frustum import Cameras, frame_cameras
from .grid import Grid, object_grid
from .objects import STATE, Outputs, select_and_fade
from .pair_cache import PairCache, update_pair_cache
from .pairs import Pairs, find_pairs
from .plan import UNCHANGED, FramePlan, plan_frame
from .priority import Packed, pack
from .scene import Camera, Config, SceneAPI, ValidationError
from .shadow_views import ShadowViews, update_views
from .shadows import ShadowSet, choose_shadows
from .tuning import Tuning
from .visibility import Visibility, see


@dataclass(slots=True)
class FrameState:
    """Last frame's stage outputs. Store arrays are never changed in place, so the arrays
    ``changes`` holds (those the frame read) are enough to see later which rows changed.
    A stage's output is not changed after its stage returns it (the next frame reads it
    as it was); the stage output classes are plain slotted dataclasses rather than frozen
    ones, whose field-by-field ``object.__setattr__`` costs microseconds a frame."""

    changes: Changes
    cameras: Cameras
    visibility: Visibility
    packed: Packed
    grid: Grid
    pairs: Pairs
    shadows: ShadowSet
    casters: Casters
    views: ShadowViews
    cache: PairCache
    outputs: Outputs
    frame: Frame


class Scheduler(SceneAPI):
    """Stateful fast-path scheduler (DESIGN section 7). ``tuning`` sets the thresholds by
    which frames choose their paths (tuning.py); it never changes a result."""

    def __init__(self, config: Config | None = None, tuning: Tuning | None = None) -> None:
        super().__init__(config)
        self.tuning = Tuning() if tuning is None else tuning
        k = self.config.max_lights
        for name, dtype, fill in STATE:
            self.objects.add_state(name, (k,), dtype, fill)
        self.objects.add_state("was_visible", (), np.bool_, False)
        self._last: FrameState | None = None
        # Last frame's shadow lights: the ranking's hysteresis remembers them even after a
        # frame that stopped half way (which leaves no FrameState behind).
        self._shadows: ShadowSet | None = None
        # Last frame's shadow views (what each view held when rendered, the atlas tiles),
        # kept like the shadow lights.
        self._views: ShadowViews | None = None
        self._buffers = Buffers()
        # What explain reads of the last frame; dropped when the next one starts, so that
        # the output arrays it references can be taken back (buffers.SpareOutputs).
        self._explained: ExplainRecord | None = None

    def _memory(self) -> tuple[ShadowSet | None, ExplainRecord | None, ShadowViews | None]:
        return self._shadows, self._explained, self._views

    def _put_back(self, memory: tuple[ShadowSet | None, ExplainRecord | None,
                                      ShadowViews | None]) -> None:
        # The stores are put back, not the frames: last frame's stage outputs may be of
        # the frame that was undone, so the next frame is a full one. explain goes on
        # answering for the last frame that was not undone.
        self._last = None
        self._shadows, self._explained, self._views = memory

    def _frame(self, cameras: list[Camera], dt: float, cut: bool) -> Frame:
        cfg, tuning, buffers = self.config, self.tuning, self._buffers
        lights, objects = self.lights, self.objects
        # Installed again at the end: a frame that stops half way (an exception) leaves no
        # state behind, so the next frame is full instead of trusting half-updated lists.
        last, self._last = self._last, None
        prior, self._explained = self._explained, None
        clock = _Clock()
        cams = clock.lap("cameras", frame_cameras(
            cameras, None if last is None else last.cameras, cfg.cascades, cfg.shadow_distance))
        changes = clock.lap("changes", find_changes(
            None if last is None else last.changes, lights, objects))
        plan = plan_frame(last, changes, cams, cut, self.frame_index, cfg, tuning,
                          quiet=_quiet(last, objects))
        if plan.kind == UNCHANGED:
            return self._repeat(last, plan, clock, prior)
        # explain's view of the object rows as the frame begins (replaced whole, never
        # written in place): the slots' lights, was_visible and is_new.
        began = objects.get("slot_light"), objects.get("was_visible"), objects.is_new
        # The last record holds the outputs of the frame before the last, which the objects
        # stage takes back when nothing else holds them.
        del prior
        vis = clock.lap("visibility", see(plan, last, lights, objects, cams,
                                          changes.object_rows))
        packed = clock.lap("pack", pack(plan, None if last is None else last.packed, lights,
                                        cams.frames, cfg, vis.lights, changes.light_rows))
        grid = clock.lap("grid", object_grid(plan, last, objects, vis, packed,
                                             changes.object_rows, tuning, buffers))
        pairs = clock.lap("pairs", find_pairs(plan, last, lights, objects, vis, packed, grid,
                                              changes.light_rows, cfg, tuning, buffers))
        shadows = clock.lap("shadows", choose_shadows(self._shadows, lights, cams.frames,
                                                      vis.lights, packed, grid, cfg))
        casters = clock.lap("casters", find_casters(
            plan, None if last is None else last.casters, changes, lights, objects, shadows,
            packed, grid, cams, vis.objects, cfg.cascade_overlap, tuning,
            cfg.caster_culling == "light"))
        views, shadows_seen = clock.lap("views", update_views(
            self._views, shadows, casters, lights, objects, cams, cameras, cfg))
        # The ranking's memory is the set as ranked; the slots see which maps are ready.
        self._shadows = shadows
        shadows = shadows_seen
        cache = clock.lap("lists", update_pair_cache(plan, last, pairs, shadows, vis, packed,
                                                     grid, changes.light_rows, tuning, buffers))
        outputs = clock.lap("objects", select_and_fade(
            plan, last, cache, packed, shadows, vis.objects, lights, objects,
            changes.object_rows is None, cfg, dt, tuning, buffers))
        frame = self._output(last, cams, vis, shadows, casters, views, outputs)
        self._views = views
        self._explained = ExplainRecord(
            self.frame_index, cfg, *self.snapshot(), frame, shadows.live, vis.lights, cache.seg,
            cache.heap, objects.get("selected"), outputs.run, outputs.selected_before, *began)
        self._last = FrameState(changes, cams, vis, packed, grid, pairs, shadows, casters, views,
                                cache, outputs, frame)
        clock.lap("output", None)
        how = {"visibility": vis.how, "grid": grid.text, "pairs": pairs.how,
               "shadows": shadows.how, "casters": casters.how, "views": views.how,
               "lists": cache.how,
               "objects": outputs.how}
        frame.stats = {"plan": plan.describe(cfg, tuning, len(cams.frames), how),
                       "counts": self._counts(changes, vis, packed, shadows, casters, views,
                                              cache, outputs, frame),
                       "seconds": clock.seconds()}
        return frame

    def explain(self, object_id: Any) -> Explanation:
        """Why each light is (not) on object ``object_id`` in the last frame (DESIGN section
        7; explain.py)."""
        if self._explained is None:
            raise ValidationError("object_id", None, "no frame has run yet")
        return explain_record(self._explained, object_id)

    def _output(self, last: FrameState | None, cams: Cameras, vis: Visibility,
                shadows: ShadowSet, casters: Casters, views: ShadowViews,
                outputs: Outputs) -> Frame:
        """The output stage: the frame (read-only) from the stages' outputs."""
        objects = self.objects
        given = dict(outputs.arrays)
        # The ids as last frame's while the store's id array is the same one (frames are
        # read-only, so they share it).
        if last is not None and last.changes.objects["id"] is objects.id:
            given["object_id"] = last.frame.object_id
        return freeze(empty_frame(
            objects.id, self.config.max_lights, self.config.cascades, **given,
            directional_lights=shadows.directional, visible_lights=self.lights.id[vis.lights],
            cascade_splits=cams.splits, shadow_lights=shadows.ids, shadow_tier=shadows.tier,
            caster_offsets=casters.offsets, caster_ids=casters.ids, caster_masks=casters.masks,
            shadow_views=views.views, shadow_dirty=views.dirty,
            shadow_static_dirty=views.static_dirty, shadow_update=views.update,
            shadow_rect=views.rect, camera_ids=views.camera_ids))

    def _counts(self, changes: Changes, vis: Visibility, packed: Packed, shadows: ShadowSet,
                casters: Casters, views: ShadowViews, cache: PairCache, outputs: Outputs,
                frame: Frame) -> dict[str, int]:
        n, n_l, k = len(self.objects), len(self.lights), self.config.max_lights
        return {
            "objects": n,
            "visible_objects": int(np.count_nonzero(vis.objects)),
            "lights": n_l,
            "visible_lights": int(np.count_nonzero(vis.lights)),
            "competing_lights": int(np.count_nonzero(packed.compete)),
            "pairs": cache.pairs,
            # (An int32 sum of int32 counts is several times faster.)
            "slots": int(frame.count.sum(dtype=np.int32 if n * k < 2**31 else np.int64)),
            "shadow_lights": int(shadows.rows.size),
            "casters": int(casters.ids.size),
            "tiles_moved": views.tiles_moved,
            "texels_rendered": views.texels,
            "recomputed_objects": int(outputs.run.size),
            "changed_lights": n_l if changes.light_rows is None else int(changes.light_rows.size),
            "changed_objects": n if changes.object_rows is None
            else int(changes.object_rows.size),
            "threads": nb.get_num_threads(),
        }

    def _repeat(self, last: FrameState, plan: FramePlan, clock: _Clock,
                prior: ExplainRecord | None) -> Frame:
        """An UNCHANGED frame: the last frame's arrays are this frame's (frames are
        read-only, so they can share them)."""
        self._last = last
        frame = Frame(**last.frame.arrays())
        if prior is not None:
            objects = self.objects
            self._explained = prior._replace(
                frame_index=self.frame_index, frame=frame, run=prior.run[:0],
                held=objects.get("slot_light"), was_visible=objects.get("was_visible"),
                is_new=objects.is_new)
        plan_text = {stage: f"{text} (kept: nothing changed)"
                     for stage, text in last.frame.stats["plan"].items() if stage != "frame"}
        plan_text["frame"] = f"{plan.kind}: {plan.why}"
        frame.stats = {
            "plan": plan_text,
            "counts": dict(last.frame.stats["counts"], recomputed_objects=0, changed_lights=0,
                           changed_objects=0, tiles_moved=0, texels_rendered=0),
            "seconds": clock.seconds(),
        }
        return frame


def _quiet(last: FrameState | None, objects: Any) -> bool:
    """No update_objects call since last frame named one of its casters: a re-sent caster
    dirties its shadow views even with its values unchanged (DESIGN "Dirty"); other
    objects re-sent unchanged leave the frame unchanged. (Last frame's casters are what a
    clean view holds; a view still dirty keeps the frame from being unchanged anyway.)"""
    if not objects.named:
        return True
    if last is None:
        return False
    return not np.isin(np.concatenate(objects.named), last.casters.ids).any()


class _Clock:
    """The seconds of each stage, lap after lap."""

    def __init__(self) -> None:
        self._laps: dict[str, float] = {}
        self._t = time.perf_counter()

    def lap(self, stage: str, result: Any) -> Any:
        """Ends ``stage``'s lap; returns ``result`` (the stage's output)."""
        now = time.perf_counter()
        self._laps[stage] = now - self._t
        self._t = now
        return result

    def seconds(self) -> dict[str, float]:
        """The laps so far and the total (with the time since the last lap)."""
        seconds = dict(self._laps)
        seconds["total"] = sum(seconds.values()) + (time.perf_counter() - self._t)
        return seconds


def schedule(lights: dict[str, Any], objects: dict[str, Any], cameras: Any,
             config: Config | None = None, tuning: Tuning | None = None) -> Frame:
    """Stateless one frame (DESIGN section 7): every object starts with its selected lights
    on, as on a scheduler's first frame."""
    s = Scheduler(config, tuning)
    s.set_lights(**lights)
    s.set_objects(**objects)
    return s.frame(cameras, dt=0.0, cut=True)
