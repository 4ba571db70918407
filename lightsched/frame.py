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


def _empty(name: str, n: int, k: int, cascades: int) -> np.ndarray:
    """One array of a frame where no object has a light (DESIGN section 3 empty slots)."""
    dtype = FRAME_ARRAYS[name]
    if name in _PER_OBJECT:
        shape = (n,) if name in ("visible", "count", "candidates") else (n, k)
        return np.full(shape, _PER_OBJECT[name], dtype)
    if name == "cascade_splits":
        return np.zeros((0, cascades + 1), dtype)
    return np.zeros(1 if name == "caster_offsets" else 0, dtype)


def empty_frame(object_id: np.ndarray, k: int, cascades: int, **given: Any) -> Frame:
    """A frame where no object has a light (empty slots as DESIGN section 3 defines them),
    except for the arrays ``given``, which are taken as they are (not copied)."""
    fields = {name: given[name] if name in given else _empty(name, object_id.size, k, cascades)
              for name in FRAME_ARRAYS if name != "object_id"}
    ids = given["object_id"] if "object_id" in given else object_id.astype(np.int32, copy=True)
    return Frame(object_id=ids, **fields)
