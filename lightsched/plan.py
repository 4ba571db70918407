"""The frame's plan (DESIGN section 6, "Skip what a scene doesn't need"): which stages run
and which of last frame's results they keep, decided before any of them runs from last
frame's stage outputs and this frame's changes alone.

A stage may still find that what the plan allows it to keep no longer serves (a kept grid
whose objects moved out of their cells, candidate lists of objects that came into view):
it then makes its result anew and says so in its own ``how``; stats["plan"] is this plan's
text with each stage's ``how`` (``FramePlan.describe``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from .changes import Changes
from .frustum import Cameras
from .priority import PACK_ALL, PACK_CAMERA, PACK_POSITION, pack_parts
from .scene import Config
from .tuning import Tuning

if TYPE_CHECKING:
    from .scheduler import FrameState

FULL, INCREMENTAL, UNCHANGED = "full", "incremental", "unchanged"


@dataclass(slots=True)
class FramePlan:
    """What a frame runs. ``kind``: FULL (every pair found again, though inputs that did
    not change may still be kept), INCREMENTAL (last frame's pair cache patched) or
    UNCHANGED (last frame's outputs shared); ``why`` says why."""

    kind: str
    why: str
    cut: bool = False
    # Every object starts with its selected lights on at weight 1 (first frame or a cut).
    reset_all: bool = False
    cameras_moved: bool = True
    # The origin of the object records and packed lights: 0, or in "fast" precision the
    # first camera's position when they were made (kept while it stays near).
    origin: np.ndarray | None = None
    same_origin: bool = False
    fast: bool = False
    # Object visibility: "kept" (objects, cameras and origin as last frame), "changed"
    # (only the changed objects tested), "groups" (last frame's grid of every object, its
    # group boxes first) or "all".
    visibility: str = "all"
    changed_objects: int = 0
    # Packed lights: "kept", "rows" (the changed rows packed again, in last frame's
    # arrays) or "all" (into last frame's arrays when ``pack_into_last``); ``pack_parts``
    # the parts of a row that are packed (priority.PACK_*), ``packed_fields`` the fields
    # (and "cameras", "origin") they are packed for.
    packing: str = "all"
    pack_parts: int = PACK_ALL
    pack_into_last: bool = False
    packed_fields: tuple[str, ...] = ()
    changed_lights: int = 0
    # Last frame's candidate lists may serve (if the grid of every object is kept too).
    candidates: bool = False
    # An incremental frame may take the pairs of the objects its changed lights reach from
    # those lists (no walk, no scan of the pair cache).
    by_lists: bool = False
    # Shadowed lights whose light and cameras did not change keep their caster lists;
    # ``keep_local_casters``: point and spot lights whose light did not change do, the
    # cameras unchanged or, under caster_culling "light", moved (their lists do not
    # depend on them then); with ``patch_casters``, a kept list is patched at the
    # changed objects.
    keep_casters: bool = False
    keep_local_casters: bool = False
    patch_casters: bool = False

    @property
    def full(self) -> bool:
        return self.kind == FULL

    def describe(self, config: Config, tuning: Tuning, frames: int, how: dict[str, str]
                 ) -> dict[str, str]:
        """stats["plan"]: this plan's entries (frame, visibility, priority, fade) and the
        stages' own (``how``: visibility, grid, pairs, shadows, casters, lists, objects),
        in DESIGN section 8's stage order."""
        vis = f"frustum planes, {frames} camera(s)" + {
            "kept": "; the objects' kept (they and the cameras did not change)",
            "changed": f"; the {self.changed_objects} changed objects' only (the cameras did "
                       "not change)",
        }.get(self.visibility, how.get("visibility", ""))
        only = f" ({', '.join(self.packed_fields)} only)" if self.pack_parts != PACK_ALL else ""
        packing = {
            "kept": "; the packed lights kept",
            "all": "; every light packed" + (" again" + only if self.pack_into_last else ""),
            "rows": f"; the {self.changed_lights} changed lights packed again{only}, the "
                    "others kept",
        }[self.packing]
        precision = (" (fast: float32 object records relative to the first camera's "
                     f"position, re-anchored beyond {tuning.reanchor:g} m; float64 arithmetic)"
                     if self.fast else " (exact float64)")
        return {
            "frame": f"{self.kind}: {self.why}",
            "visibility": vis,
            "priority": config.model + precision + packing,
            "pairs": how["grid"] + how["pairs"],
            "shadows": how["shadows"],
            "casters": how["casters"],
            "views": how["views"],
            "lists": how["lists"] + how["objects"],
            "fade": "fused with selection in the object pass",
        }


def plan_frame(last: FrameState | None, changes: Changes, cameras: Cameras, cut: bool,
               frame_index: int, config: Config, tuning: Tuning, quiet: bool = True
               ) -> FramePlan:
    """The plan of a frame, from last frame's stage outputs (``last``: None after the
    first frame or a frame that stopped half way) and this frame's changes and cameras.
    ``quiet``: no update_objects call named an object since last frame (even unchanged,
    a named caster dirties its shadow views)."""
    n_l, n = changes.lights["id"].size, changes.objects["id"].size
    thesis, fast = config.model == "thesis", config.precision == "fast"
    moved = cameras.moved
    lrows, orows = changes.light_rows, changes.object_rows
    why = _why_full(last, changes, cameras, frame_index, config, tuning)
    if why is None:
        assert last is not None and lrows is not None and orows is not None
        assert changes.cast_rows is not None
        if (lrows.size == 0 and orows.size == 0 and changes.cast_rows.size == 0 and not moved
                and not cut and last.shadows.settled and not last.outputs.fading.any()
                and quiet and last.views.quiet):
            return FramePlan(UNCHANGED, "nothing moved, no slot is fading and no shadow view "
                             "was dirty; the last frame's outputs are shared",
                             cameras_moved=False)
        why = _why_incremental(last, changes, moved, cut)
        kind = INCREMENTAL
    else:
        kind = FULL
    full = kind == FULL
    origin = np.zeros(3) if not fast else (
        last.packed.origin if last is not None and not full
        else cameras.frames.position[0].copy())
    same_origin = last is not None and origin.tolist() == last.packed.origin.tolist()
    still = same_origin and not moved and orows is not None
    if still and orows.size == 0:
        visibility = "kept"
    elif still and orows.size > 0:
        visibility = "changed"
    elif (last is not None and last.grid.shown is not None and orows is not None
          and orows.size == 0):
        visibility = "groups"
    else:
        visibility = "all"
    parts, fields = PACK_ALL, ()
    if last is not None and lrows is not None:
        parts, fields = pack_parts(list(changes.light_fields), thesis), changes.light_fields
        if thesis and moved:
            parts, fields = parts | PACK_CAMERA, (*fields, "cameras")
        if not same_origin:
            parts, fields = parts | PACK_POSITION, (*fields, "origin")
    if parts == 0:
        packing = "kept"
    elif full or (thesis and moved):
        packing = "all"
    else:
        packing = "rows" if lrows.size else "kept"
    candidates = (tuning.candidate_lists and last is not None and lrows is not None
                  and orows is not None and orows.size == 0 and same_origin
                  and n >= tuning.candidate_min_objects)
    keep_casters = last is not None and lrows is not None and not moved
    # In "fast" precision a point or spot light's test reads records relative to the
    # origin: its list is kept only while the origin holds.
    keep_local = (last is not None and lrows is not None and same_origin
                  and (not moved or config.caster_culling == "light"))
    return FramePlan(
        kind, why, cut=cut, reset_all=frame_index == 0 or cut, cameras_moved=moved,
        origin=origin, same_origin=same_origin, fast=fast, visibility=visibility,
        changed_objects=0 if orows is None else orows.size, packing=packing,
        pack_parts=parts, pack_into_last=last is not None and lrows is not None,
        packed_fields=fields, changed_lights=n_l if lrows is None else lrows.size,
        candidates=candidates,
        by_lists=(not full and candidates and not moved and config.model == "contribution"
                  and not fast and not config.directional_in_slots),
        keep_casters=keep_casters, keep_local_casters=keep_local,
        patch_casters=(keep_casters or keep_local)
        and bool(orows.size or changes.cast_rows.size))


def _why_full(last: FrameState | None, changes: Changes, cameras: Cameras, frame_index: int,
              config: Config, tuning: Tuning) -> str | None:
    """Why the frame must find every pair again, or None."""
    if last is None:
        return "first frame" if frame_index == 0 else "the last frame stopped half way"
    if changes.renumbered == "lights":
        return "the light set changed (set_lights or remove_lights)"
    if changes.renumbered == "objects":
        return "the object set changed (set_objects or remove_objects)"
    assert changes.light_rows is not None and changes.object_rows is not None
    n_l, n = changes.lights["id"].size, changes.objects["id"].size
    if cameras.moved and config.model == "thesis":
        return "the cameras moved (thesis priorities depend on them)"
    if (cameras.moved and config.precision == "fast"
            and np.abs(cameras.frames.position[0] - last.packed.origin).max() > tuning.reanchor):
        return (f"the first camera moved over {tuning.reanchor:g} m from the fast records' "
                "origin (they are made again around it)")
    if changes.light_rows.size > tuning.full_share * max(n_l, 1):
        return f"{changes.light_rows.size} of {n_l} lights changed"
    if changes.object_rows.size > tuning.full_share * max(n, 1):
        return f"{changes.object_rows.size} of {n} objects changed"
    return None


def _why_incremental(last: FrameState, changes: Changes, moved: bool, cut: bool) -> str:
    assert changes.light_rows is not None and changes.object_rows is not None
    why = [f"{changes.light_rows.size} lights and {changes.object_rows.size} objects changed",
           "cameras " + ("moved" if moved else "unchanged")]
    fading = np.count_nonzero(last.outputs.fading)
    if fading:
        why.append(f"{fading} objects fading")
    if not last.shadows.settled:
        why.append("the shadowed set changed last frame")
    if cut:
        why.append("a cut")
    return ", ".join(why)
