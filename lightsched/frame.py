"""Frame: the per-frame outputs of DESIGN section 3, plus the plan and stats of section 6.

Takes the arrays the stages produced and holds them under DESIGN's names; ``empty_frame``
builds the all-empty frame of a given size so every producer agrees on dtypes and shapes.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

# name -> (dtype, shape suffix kind): "N" per object, "NK" per object slot, others 1-D.
FRAME_ARRAYS: dict[str, Any] = {
    "object_id": np.int32,
    "visible": np.bool_,
    "count": np.int32,
    "candidates": np.int32,
    "light_ids": np.int32,
    "light_index": np.int32,
    "priority": np.float32,
    "fade_weight": np.float32,
    "fade_state": np.uint8,
    "slot_shadow": np.int8,
    "directional_lights": np.int32,
    "visible_lights": np.int32,
    "shadow_lights": np.int32,
    "shadow_tier": np.uint16,
    "cascade_splits": np.float64,
    "caster_offsets": np.int64,
    "caster_ids": np.int32,
    "caster_masks": np.uint32,
}


# Per-object arrays and the value of an empty slot (DESIGN section 3).
_PER_OBJECT = {"visible": False, "count": 0, "candidates": 0, "light_ids": -1,
               "light_index": -1, "priority": 0, "fade_weight": 0, "fade_state": 0,
               "slot_shadow": -1}


@dataclass
class Frame:
    """One frame's result. Object rows are in ascending object id (DESIGN section 3)."""

    object_id: np.ndarray
    visible: np.ndarray
    count: np.ndarray
    candidates: np.ndarray
    light_ids: np.ndarray
    light_index: np.ndarray
    priority: np.ndarray
    fade_weight: np.ndarray
    fade_state: np.ndarray
    slot_shadow: np.ndarray
    directional_lights: np.ndarray
    visible_lights: np.ndarray
    shadow_lights: np.ndarray
    shadow_tier: np.ndarray
    cascade_splits: np.ndarray
    caster_offsets: np.ndarray
    caster_ids: np.ndarray
    caster_masks: np.ndarray
    stats: dict[str, Any] = field(default_factory=dict)

    def arrays(self) -> dict[str, np.ndarray]:
        return {name: getattr(self, name) for name in FRAME_ARRAYS}


def freeze(frame: Frame) -> Frame:
    """Makes every array of the frame read-only: a frame is a snapshot, and the fast
    scheduler keeps its light_ids and fade_state as the next frame's slot state."""
    for arr in frame.arrays().values():
        arr.flags.writeable = False
    return frame


def empty_frame(object_id: np.ndarray, k: int, cascades: int, **given: Any) -> Frame:
    """A frame where no object has a light (empty slots as DESIGN section 3 defines them),
    except for the arrays ``given``, which are taken as they are (not copied)."""
    n = object_id.size
    if given:
        empty = empty_frame(np.zeros(0, np.int32), k, cascades)
        fields = {name: given.get(name) for name in FRAME_ARRAYS}
        for name, arr in fields.items():
            if arr is None:
                arr = getattr(empty, name)
                if arr.ndim and arr.shape[0] == 0 and name in _PER_OBJECT:
                    fill = _PER_OBJECT[name]
                    arr = np.full((n,) + arr.shape[1:], fill, arr.dtype)
                fields[name] = arr
        if "object_id" not in given:
            fields["object_id"] = object_id.astype(np.int32, copy=True)
        return Frame(**fields)
    return Frame(
        object_id=object_id.astype(np.int32, copy=True),
        visible=np.zeros(n, np.bool_),
        count=np.zeros(n, np.int32),
        candidates=np.zeros(n, np.int32),
        light_ids=np.full((n, k), -1, np.int32),
        light_index=np.full((n, k), -1, np.int32),
        priority=np.zeros((n, k), np.float32),
        fade_weight=np.zeros((n, k), np.float32),
        fade_state=np.zeros((n, k), np.uint8),
        slot_shadow=np.full((n, k), -1, np.int8),
        directional_lights=np.zeros(0, np.int32),
        visible_lights=np.zeros(0, np.int32),
        shadow_lights=np.zeros(0, np.int32),
        shadow_tier=np.zeros(0, np.uint16),
        cascade_splits=np.zeros((0, cascades + 1), np.float64),
        caster_offsets=np.zeros(1, np.int64),
        caster_ids=np.zeros(0, np.int32),
        caster_masks=np.zeros(0, np.uint32),
    )
