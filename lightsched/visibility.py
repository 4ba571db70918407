"""The visibility stage (DESIGN section 2, "Visibility"): which lights and objects are in
at least one camera's frustum, by the kernels of frustum.py.

Lights are tested every frame (a light is one sphere test). Objects are tested as the plan
says: kept when they, the cameras and the records' origin are as last frame; only the
changed ones under still cameras; under moved cameras over last frame's grid of every
object, its group boxes first (frustum.objects_visible_groups); else every object.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from .frustum import (
    Cameras,
    GroupPass,
    lights_visible,
    objects_visible,
    objects_visible_groups,
)
from .grid import SWEEP_GROUP, GroupBoxes, group_boxes_of
from .scene import LightStore, ObjectStore

if TYPE_CHECKING:
    from .plan import FramePlan
    from .scheduler import FrameState

NO_ROWS = np.zeros(0, np.int64)
# A last group pass of none (frustum.objects_visible_groups).
_NO_CLASS = np.zeros(0, np.int8)


@dataclass(slots=True)
class Visibility:
    """``lights`` and ``objects``: the visibility flags; ``box``: a box holding the visible
    objects (it only sets a grid's extent, so it may be larger); ``flipped``: the rows
    whose flag differs from last frame's; ``fresh``: the visible rows that need new pairs
    (they moved or came into view) and ``left`` the rows that left the view, in an
    incremental frame (empty in a full one, which pairs every object), and ``renewed``
    both (ascending: the rows whose pair lists are replaced); ``groups``: (grid
    positions, class per group) of a pass over a grid of every object's groups, for the
    next such pass; ``how``: how the objects were tested, when the plan alone does not
    say."""

    lights: np.ndarray
    objects: np.ndarray
    box: np.ndarray
    flipped: np.ndarray
    fresh: np.ndarray
    left: np.ndarray
    renewed: np.ndarray
    groups: tuple[np.ndarray, np.ndarray] | None = None
    how: str = ""


def see(plan: FramePlan, last: FrameState | None, lights: LightStore, objects: ObjectStore,
        cameras: Cameras, object_rows: np.ndarray | None) -> Visibility:
    """The visibility stage. ``object_rows``: the objects that changed
    (changes.Changes.object_rows)."""
    frames = cameras.frames
    planes = (frames.plane_n, frames.plane_p)
    vis_l = lights_visible(lights.type, lights.position, lights.radius, *planes)
    lo, hi = objects.bounds_min, objects.bounds_max
    groups, how = None, ""
    if plan.visibility == "kept":
        old = last.visibility
        vis_o, box, groups = old.objects, old.box, old.groups
    elif plan.visibility == "changed":
        # The box of the visible objects takes in the changed ones' without letting go of
        # the old one.
        vis_moved, box_moved = objects_visible(lo[object_rows], hi[object_rows], *planes)
        vis_o = last.visibility.objects.copy()
        vis_o[object_rows] = vis_moved
        old = last.visibility.box
        box = np.concatenate([np.minimum(old[:3], box_moved[:3]),
                              np.maximum(old[3:], box_moved[3:])])
    elif plan.visibility == "groups":
        vis_o, box, groups, how = _by_groups(last, lo, hi, planes, plan.fast)
    else:
        vis_o, box = objects_visible(lo, hi, *planes)
    # The rows whose visibility changed, which three stages read.
    flipped = (np.flatnonzero(vis_o != last.visibility.objects)
               if last is not None and object_rows is not None
               and vis_o is not last.visibility.objects else NO_ROWS)
    fresh = left = renewed = NO_ROWS
    if not plan.full and plan.visibility != "kept":
        in_view = vis_o[flipped]
        left = flipped[~in_view]
        if object_rows.size:
            moved = np.zeros(len(objects), np.bool_)
            moved[object_rows] = True
            fresh = np.flatnonzero(vis_o & (moved | ~last.visibility.objects))
            # (Disjoint: fresh rows are in view, left ones not.)
            renewed = np.sort(np.concatenate((fresh, left)))
        else:
            fresh, renewed = flipped[in_view], flipped
    return Visibility(vis_l, vis_o, box, flipped, fresh, left, renewed, groups, how)


def _by_groups(last: FrameState, lo: np.ndarray, hi: np.ndarray,
               planes: tuple[np.ndarray, np.ndarray], fast: bool
               ) -> tuple[np.ndarray, np.ndarray, tuple[np.ndarray, np.ndarray], str]:
    """The objects of last frame's grid of every object, under moved cameras: its group
    boxes first (those wholly in or out of view), then the objects of the groups on a
    frustum's planes. After a pass over the same groups, those wholly in or out of view
    again keep their objects' flags."""
    grid = last.grid
    boxes = group_boxes_of(grid, lo, hi, fast)
    before = last.visibility.groups
    since = before is not None and before[0] is grid.pos_of
    vis_o, box, classes = objects_visible_groups(
        boxes, *planes, GroupBoxes(grid.pos_of, grid.group_box, SWEEP_GROUP),
        GroupPass(last.visibility.objects, before[1] if since else _NO_CLASS))
    how = (f"; by the boxes of {SWEEP_GROUP} positions of last frame's grid of every object "
           "first")
    if since:
        how += (f", {np.count_nonzero(classes != before[1])} of {classes.size} groups "
                "changed class (only their objects' flags and those of the groups across a "
                "plane written)")
    return vis_o, box, (grid.pos_of, classes), how
