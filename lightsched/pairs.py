"""The pairs stage (DESIGN section 2, "Affects" and "Priority"): per competing light the
visible objects it affects, with the pair's P, found in one of four ways:

- ``candidates``: a full frame whose objects and grid of every object are last frame's
  takes every object's pairs from its candidate list (candidates.py) in the pair cache
  stage; here the lists are only kept up to date (the lights that left their widened
  sphere walk the grid again);
- ``lists``: an incremental frame whose lights changed under still cameras and objects
  takes the pairs of the objects those lights may reach from their candidate lists (no
  walk, no scan of the pair cache, no grouping): here those objects are marked;
- ``walk``: a full frame walks every competing light through the grid (walk.py);
- ``patch``: an incremental frame walks the lights that changed or entered or left the
  competition, and tests the objects that moved or came into view against every light
  (fresh_pairs.py); the pair cache stage patches last frame's cache with both.

The pairs themselves are plain arrays (object row, P) per light, or (P, light row) per
object, never Python objects.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from .buffers import Buffers
from .candidates import Candidates, list_objects, update_candidates
from .fresh_pairs import LightGrid, fresh_object_pairs, light_grid
from .grid import Grid, light_order
from .group import PairHeap
from .priority import Packed, PairParams
from .scene import Config, LightStore, ObjectStore
from .tuning import Tuning
from .walk import LightPairs, walk_lights

if TYPE_CHECKING:
    from .plan import FramePlan
    from .scheduler import FrameState
    from .visibility import Visibility

CANDIDATES, LISTS, WALK, PATCH = "candidates", "lists", "walk", "patch"
_NO_LIGHTS = np.zeros(0, np.int64)
# The fresh pairs of no object: pair_cache.replace_lists reads the start of none, so N + 1
# zeros (memory mapped anew each frame at 100k objects) are not needed.
_NO_FRESH = (np.zeros(1, np.int64), PairHeap.empty(0))


@dataclass(slots=True)
class Pairs:
    """The pairs stage's output. ``path``: one of the four above. ``walked``: the light
    rows whose cached pairs are replaced (lists, patch); ``lights``: their new pairs, light
    by light (walk, patch); ``objects``: the pairs of the objects that moved or came into
    view, grouped by object row (patch); ``reach``: per object row, whether a changed
    light's list holds it (lists); ``candidates``: the candidate lists, kept for the next
    frame (None when there are none); ``light_grid``: the grid of the point and spot lights
    fresh_pairs made, kept while no light changes; ``params``: the pairs' P's; ``how``:
    the plan's entry."""

    path: str
    params: PairParams
    walked: np.ndarray = field(default_factory=lambda: _NO_LIGHTS)
    lights: LightPairs | None = None
    objects: tuple[np.ndarray, PairHeap] | None = None
    reach: np.ndarray | None = None
    candidates: Candidates | None = None
    light_grid: LightGrid | None = None
    how: str = ""


def find_pairs(plan: FramePlan, last: FrameState | None, lights: LightStore,
               objects: ObjectStore, vis: Visibility, packed: Packed, grid: Grid,
               light_rows: np.ndarray | None, config: Config, tuning: Tuning,
               buffers: Buffers) -> Pairs:
    """The pairs stage. ``light_rows``: the lights that changed (changes.Changes)."""
    params = PairParams.of(config)
    # Candidate lists serve while the objects, the records' origin and the grid of every
    # object are the ones they were made with (plan.candidates, grid.kept).
    serve = plan.candidates and grid.kept and grid.shown is not None
    cands = _kept_candidates(last, vis, grid) if serve else None
    # Where each light was last frame (the rows did not change), for the lists' lead.
    last_position = (last.changes.lights["position"]
                     if last is not None and light_rows is not None else None)
    changed = None
    if not plan.full:
        # Lights that changed or entered or left the competition (light_rows ascending
        # and distinct: the union only when some entered or left).
        entered = np.flatnonzero(packed.compete != last.packed.compete)
        changed = np.union1d(light_rows, entered) if entered.size else light_rows
    update = dict(lights=lights, objects=objects, packed=packed, grid=grid, tuning=tuning,
                  buffers=buffers)
    if plan.full and serve:
        cands, walk, made = update_candidates(cands, hidden=plan.cameras_moved,
                                              last_position=last_position, **update)
        return Pairs(CANDIDATES, params, candidates=cands,
                     how=_lists_text(tuning, packed, made, walk))
    if plan.by_lists and serve and cands is not None and changed.size > 0:
        # The objects in the lists of the changed lights before and after they change
        # (the pair cache stage adds those of lights whose shadow map or "skip" status
        # changed).
        reach = np.zeros(len(objects), np.bool_)
        list_objects(cands.by_light, changed, reach)
        cands, walk, made = update_candidates(cands, hidden=False, last_position=last_position,
                                              **update)
        list_objects(cands.by_light, walk, reach)
        return Pairs(LISTS, params, walked=changed, reach=reach, candidates=cands,
                     how=_lists_text(tuning, packed, made, walk)
                     + f"; the objects in the lists of the {changed.size} changed lights take "
                       "their pairs from their candidate lists")
    if plan.full:
        rows = light_order(packed.rows.hot, np.flatnonzero(packed.compete).astype(np.int32),
                           grid.index.frame, grid.index.dims)
        return Pairs(WALK, params, lights=walk_lights(packed.rows, rows, grid, params, buffers,
                                                      "pair"),
                     how=f", walked by {rows.size} lights")
    pairs = _patch_pairs(last, changed, light_rows, objects, vis, packed, grid, params,
                         (plan.origin, plan.fast), tuning, buffers)
    pairs.candidates = cands
    if plan.by_lists and serve and cands is None:
        # No lists to serve this frame: made for the next ones.
        pairs.candidates, walk, _ = update_candidates(None, hidden=False,
                                                      last_position=last_position, **update)
        pairs.how += _lists_text(tuning, packed, True, walk) + " for the next frames"
    return pairs


def _kept_candidates(last: FrameState, vis: Visibility, grid: Grid) -> Candidates | None:
    """Last frame's candidate lists for this frame, if any: a camera move changes only the
    masks of the records whose visibility changed, in their row-order copy as in the
    grid's; lists of the objects in view only cannot serve objects entering it."""
    cands = last.pairs.candidates
    if cands is not None and vis.objects is not last.visibility.objects:
        flipped = vis.flipped
        if not cands.hidden and vis.objects[flipped].any():
            return None
        # The grid's records have theirs already (grid._every_grid).
        cands.records[1][flipped, 6] = grid.records.bits[grid.pos_of[flipped], 6]
    return cands


def _patch_pairs(last: FrameState, changed: np.ndarray, light_rows: np.ndarray,
                 objects: ObjectStore, vis: Visibility, packed: Packed, grid: Grid,
                 params: PairParams, frame: tuple[np.ndarray, bool], tuning: Tuning,
                 buffers: Buffers) -> Pairs:
    """The ``patch`` path: the changed lights that compete walk the grid again; the objects
    that moved or came into view get their pairs with every light, each tested against
    every light when there are few, else against the lights of the cells its box overlaps
    in a grid of the lights (kept while no light changes)."""
    walk = changed[packed.compete[changed]].astype(np.int32)
    walk = light_order(packed.rows.hot, walk, grid.index.frame, grid.index.dims)
    walked = walk_lights(packed.rows, walk, grid, params, buffers, "pair")
    fresh = vis.fresh
    n_point = int(np.count_nonzero(packed.compete & ~packed.is_dir)) if fresh.size else 0
    cells = last.pairs.light_grid if light_rows.size == 0 else None
    how = "tested against"
    if not fresh.size:
        found = _NO_FRESH
    elif fresh.size * n_point <= (
            tuning.direct_tests_per_light * n_point + len(objects) if cells is None
            else tuning.grid_tests_per_object * fresh.size):
        found = fresh_object_pairs(fresh, objects, packed, params, frame, None)
    else:
        how = "from the cells of a grid of"
        if cells is None:
            how = "from the cells of a new grid of"
            cells = light_grid(packed.rows.hot, np.flatnonzero(~packed.is_dir).astype(np.int32))
        found = fresh_object_pairs(fresh, objects, packed, params, frame, cells)
    return Pairs(PATCH, params, walked=changed, lights=walked, objects=found, light_grid=cells,
                 how=(f", walked by {walk.size} changed lights (the other pairs are kept); "
                      f"{fresh.size} moved or newly visible objects get new pairs {how} "
                      f"{np.count_nonzero(packed.compete)} lights; {vis.left.size} objects "
                      "left the view"))


def _lists_text(tuning: Tuning, packed: Packed, made: bool, walk: np.ndarray) -> str:
    return (f"; candidate lists (each point and spot light's sphere widened by "
            f"{tuning.skin:g} of its radius) " + ("made: " if made else "kept, ")
            + f"{walk.size} of {int(np.count_nonzero(packed.compete & ~packed.is_dir))} "
            "lights walked again (they left their widened sphere or had none)")
