"""The frame's output arrays (DESIGN section 3), listed once.

Every producer and consumer of a frame derives its field names from ``FIELDS``: the
Frame and its empty frame (frame.py), the service's per-object set and its response model
(server/service.py, server/models.py) and, through the generated file
schemas/frame_fields.json (copied into the client package as
lightsched_client/frame_fields.json; ``python -m lightsched_server.schemas`` writes both),
the clients, which must not import lightsched (numba is heavy). This module imports numpy
only, so that the generator and anything else can read the list without compiling kernels.

A DESIGN section 3 array the frame does not produce yet has no row here: add it when the
Frame gets it, and regenerate.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Any

import numpy as np

# Axis symbols of a shape, DESIGN section 3's: N objects, K slots, D directional lights,
# V visible lights, S shadowed lights (S' in DESIGN), M casters, one row per camera, C
# cascades; an axis of digits is that fixed length (residual's 4 coefficients).
# Per-object arrays are "N", "N" by "K", or "N" by a fixed length.
PER_OBJECT_SHAPES = (("N",), ("N", "K"), ("N", "4"))


@dataclass(frozen=True)
class FrameField:
    """One output array. ``per_object``: one row per object, in object_id order, sent by
    rows in changed_only answers; ``empty`` is the value of such a row's element when the
    object has nothing (an invisible object, an empty slot), None for the others.
    object_id is the key of those rows, not one of them: it travels whole."""

    name: str
    dtype: type[np.generic]
    shape: tuple[str, ...]
    per_object: bool
    empty: Any
    description: str

    @property
    def kind(self) -> str:
        """"N" (per object), "NK" (per object slot), "N4" (per object, 4 values), or the
        shape's axes joined by "," for a per-frame array."""
        return "".join(self.shape) if self.shape in PER_OBJECT_SHAPES else ",".join(self.shape)

    def document(self) -> dict[str, Any]:
        """The field as frame_fields.json writes it (dtype by numpy's name)."""
        return {"name": self.name, "dtype": np.dtype(self.dtype).name, "shape": list(self.shape),
                "per_object": self.per_object, "empty": self.empty,
                "description": self.description}


def _per_object(name: str, dtype: type[np.generic], shape: tuple[str, ...], empty: Any,
                description: str) -> FrameField:
    return FrameField(name, dtype, shape, True, empty, description)


def _per_frame(name: str, dtype: type[np.generic], shape: tuple[str, ...],
               description: str) -> FrameField:
    return FrameField(name, dtype, shape, False, None, description)


# DESIGN section 3's order; empty values are its "Empty slots" (and nothing for an object
# out of view: not visible, no lights, no candidates).
FIELDS: tuple[FrameField, ...] = (
    _per_frame("object_id", np.int32, ("N",), "object ids, ascending: the rows of the "
               "per-object arrays"),
    _per_object("visible", np.bool_, ("N",), False, "the object is in view of a camera"),
    _per_object("count", np.int32, ("N",), 0, "slots in use"),
    _per_object("candidates", np.int32, ("N",), 0, "lights competing for its slots (before the cut to K)"),
    _per_object("light_ids", np.int32, ("N", "K"), -1, "light id per slot"),
    _per_object("light_index", np.int32, ("N", "K"), -1,
                "row of the slot's light among the lights in ascending id"),
    _per_object("priority", np.float32, ("N", "K"), 0.0, "P of the slot's light"),
    _per_object("fade_weight", np.float32, ("N", "K"), 0.0, "fade weight in [0, 1]"),
    _per_object("fade_state", np.uint8, ("N", "K"), 0,
                "0 off, 1 fading in, 2 on, 3 fading out"),
    _per_object("slot_shadow", np.int8, ("N", "K"), -1,
                "index into shadow_lights of the slot's shadow map, -1 none"),
    _per_frame("directional_lights", np.int32, ("D",),
               "directional lights applied outside the slots"),
    _per_frame("visible_lights", np.int32, ("V",), "lights in view, ascending id"),
    _per_frame("shadow_lights", np.int32, ("S",), "shadowed lights, in rank order"),
    _per_frame("shadow_tier", np.uint16, ("S",), "map size in texels of each"),
    _per_frame("cascade_splits", np.float64, ("cameras", "C+1"),
               "cascade split distances per camera"),
    _per_frame("caster_offsets", np.int64, ("S+1",),
               "caster_ids[caster_offsets[s]:caster_offsets[s + 1]] are shadow light s's"),
    _per_frame("caster_ids", np.int32, ("M",), "shadow caster object ids, ascending per light"),
    _per_frame("caster_masks", np.uint32, ("M",),
               "per caster: the views it is drawn into (point: cube faces; spot: "
               "bit 0; directional: bit camera * C + cascade)"),
    _per_object("residual", np.float32, ("N", "4"), 0.0,
                "L1 SH irradiance (a, b_x, b_y, b_z) of the competing lights not wholly in "
                "the slots; the shader adds max(0, a/4 + (b . n)/2)"),
    _per_frame("shadow_views", np.uint32, ("S",),
               "per shadow light its views, as caster_masks' bits (point: the six faces; "
               "spot: bit 0; directional: bit camera * C + cascade)"),
    _per_frame("shadow_dirty", np.uint32, ("S",),
               "the views whose casters, light, camera, tier or tile changed since they were "
               "last rendered (or never were)"),
    _per_frame("shadow_static_dirty", np.uint32, ("S",),
               "the dirty views whose cached static-caster layer must be redrawn too"),
    _per_frame("shadow_update", np.uint32, ("S",),
               "the dirty views to render this frame (shadow_update_budget)"),
    _per_frame("shadow_rect", np.int32, ("S", "6", "3"),
               "per shadow light and view bit its atlas tile (x, y, size); -1 where there "
               "is none (directional lights, unused rows, no atlas)"),
    _per_frame("camera_ids", np.int32, ("cameras",),
               "the cameras' ids in list order (directional view bits and cascade_splits "
               "rows follow it)"),
)

FIELDS_BY_NAME: dict[str, FrameField] = {f.name: f for f in FIELDS}
# The names, as lightsched_client.client has them too.
FRAME_FIELDS: tuple[str, ...] = tuple(f.name for f in FIELDS)
PER_OBJECT_NAMES: tuple[str, ...] = tuple(f.name for f in FIELDS if f.per_object)


# Scheduler.explain's answer (DESIGN section 7): one row per light, ascending light id. A
# value that does not exist for a row is NaN (floats) or -1 (integers).
REASONS: tuple[str, ...] = (
    "removed", "object_not_visible", "light_not_visible", "masked", "unshadowed_skip",
    "out_of_range", "outside_cone", "directional", "selected", "waiting", "fading_out",
    "below_k")


@dataclass(frozen=True)
class ExplainField:
    """One column of an explanation (``reason``: strings, one of REASONS)."""

    name: str
    dtype: type[np.generic] | None
    description: str

    def document(self) -> dict[str, Any]:
        return {"name": self.name, "dtype": None if self.dtype is None
                else np.dtype(self.dtype).name, "description": self.description}


EXPLAIN_FIELDS: tuple[ExplainField, ...] = (
    ExplainField("light_id", np.int32, "the light"),
    ExplainField("priority", np.float64, "P of the pair when the light affects the object "
                 "(directional lights: i + p_user)"),
    ExplainField("selection_priority", np.float64, "P with the hysteresis bonus when the "
                 "light was selected last frame: the key selection compared"),
    ExplainField("d2", np.float64, "squared distance from the light to the object's box "
                 "(point and spot lights)"),
    ExplainField("slot", np.int32, "the light's slot in the object's row this frame"),
    ExplainField("fade_weight", np.float64, "that slot's fade weight"),
    ExplainField("fade_state", np.int32, "that slot's state: 1 fading in, 2 on, 3 fading out"),
    ExplainField("reason", None, "the first reason that applies, one of " + ", ".join(REASONS)),
)


def axis_size(axis: str, n: int, k: int, cascades: int) -> int:
    """The length of an axis in a frame of ``n`` objects where nothing is lit, seen or
    shadowed (and no camera ran)."""
    if axis.isdigit():
        return int(axis)
    return {"N": n, "K": k, "C+1": cascades + 1, "S+1": 1}.get(axis, 0)


def fields_json() -> str:
    """schemas/frame_fields.json and its copy in the client package: one field a line."""
    comment = ("Generated from lightsched/fields.py by python -m lightsched_server.schemas; "
               "do not edit. DESIGN section 3's frame arrays, in its order, then the "
               "columns of explain (section 7) and its reasons, in their order.")
    rows = ",\n".join("    " + json.dumps(f.document()) for f in FIELDS)
    explain = ",\n".join("    " + json.dumps(f.document()) for f in EXPLAIN_FIELDS)
    return (f'{{\n  "$comment": {json.dumps(comment)},\n  "fields": [\n{rows}\n  ],\n'
            f'  "explain_fields": [\n{explain}\n  ],\n  "reasons": {json.dumps(list(REASONS))}\n}}\n')


__all__ = ["EXPLAIN_FIELDS", "FIELDS", "FIELDS_BY_NAME", "FRAME_FIELDS", "PER_OBJECT_NAMES",
           "REASONS", "ExplainField", "FrameField", "axis_size", "fields_json"]
