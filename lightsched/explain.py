"""explain: why a light is (not) on an object in the last frame (DESIGN section 7).

It is for people, not for the frame loop, so it runs the obvious way on one object, from
what the last frame kept (ExplainRecord): the scene as that frame saw it, its outputs, its
pair cache (the competing lights and their P, as the object pass read them) and the slot
and selection state of its object rows before and after. The fast Scheduler keeps the
record; the oracle (reference.Scheduler.explain) answers the same question its own way.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from .fields import EXPLAIN_FIELDS, REASONS
from .frame import Frame
from .group import PairHeap
from .priority import box_d2
from .scene import DIRECTIONAL, FADING_OUT, Config, LightStore, ObjectStore, ValidationError

NAN = math.nan


@dataclass(frozen=True)
class Explanation:
    """explain's answer: one row per light that was visible, held a slot of the object, or
    held one when the frame began, in ascending light id (columns: fields.EXPLAIN_FIELDS);
    NaN or -1 where a value does not exist."""

    object_id: int
    frame_index: int
    light_id: np.ndarray
    priority: np.ndarray
    selection_priority: np.ndarray
    d2: np.ndarray
    slot: np.ndarray
    fade_weight: np.ndarray
    fade_state: np.ndarray
    reason: tuple[str, ...]

    def columns(self) -> dict[str, Any]:
        return {f.name: getattr(self, f.name) for f in EXPLAIN_FIELDS}

    def __str__(self) -> str:
        head = f"object {self.object_id}, frame {self.frame_index}"
        cols = self.columns()
        lines = [head, "  ".join(f"{f.name:>12}" for f in EXPLAIN_FIELDS)]
        for i in range(self.light_id.size):
            lines.append("  ".join(f"{cols[f.name][i]:>12.6g}" if f.dtype is np.float64
                                   else f"{cols[f.name][i]!s:>12}" for f in EXPLAIN_FIELDS))
        return "\n".join(lines)


class ExplainRow(NamedTuple):
    """One light's row while an explanation is assembled."""

    priority: float
    selection_priority: float
    d2: float
    slot: int
    fade_weight: float
    fade_state: int
    reason: str


def explanation(object_id: int, frame_index: int, rows: dict[int, ExplainRow]) -> Explanation:
    """The Explanation of ``rows`` (light id -> its row), in ascending light id."""
    ids = sorted(rows)
    col = {name: [getattr(rows[lid], name) for lid in ids] for name in ExplainRow._fields}
    for reason in col["reason"]:
        assert reason in REASONS, reason
    return Explanation(
        object_id=int(object_id), frame_index=int(frame_index),
        light_id=np.array(ids, np.int32), priority=np.array(col["priority"], np.float64),
        selection_priority=np.array(col["selection_priority"], np.float64),
        d2=np.array(col["d2"], np.float64), slot=np.array(col["slot"], np.int32),
        fade_weight=np.array(col["fade_weight"], np.float64),
        fade_state=np.array(col["fade_state"], np.int32), reason=tuple(col["reason"]))


def object_row(ids: np.ndarray, object_id: Any) -> int:
    """The row of ``object_id`` among the last frame's ascending ``ids``; ValidationError
    naming object_id when it is not one of them."""
    if isinstance(object_id, (bool, np.bool_)) or not isinstance(object_id, (int, np.integer)):
        raise ValidationError("object_id", None, "must be an integer object id")
    row = int(np.searchsorted(ids, object_id))
    if row >= ids.size or ids[row] != object_id:
        raise ValidationError("object_id", None,
                              f"no object with id {object_id} in the last frame")
    return row


class ExplainRecord(NamedTuple):
    """What the fast Scheduler keeps of its last frame for explain: references, and the
    selection the object pass overwrote (explain is for people, so the frame loop keeps
    no more than the rows it rewrites).

    lights, objects: the stores that frame read; frame: its outputs; config; live: per
    light row whether it could light an object (visible and not skipped, ShadowSet.live);
    light_visible: per light row; seg, heap: the pair cache (PairCache); selected: per
    object row the lights selected this frame ([N, K], -1 padded); run: the rows the
    object pass ran on (ascending) and selected_before: their ``selected`` rows before it
    (the other rows did not change); held: the slots' lights when the frame began;
    was_visible, is_new: per object row, when the frame began."""

    frame_index: int
    config: Config
    lights: LightStore
    objects: ObjectStore
    frame: Frame
    live: np.ndarray
    light_visible: np.ndarray
    seg: np.ndarray
    heap: PairHeap
    selected: np.ndarray
    run: np.ndarray
    selected_before: np.ndarray
    held: np.ndarray
    was_visible: np.ndarray
    is_new: np.ndarray


def explain_record(rec: ExplainRecord, object_id: Any) -> Explanation:
    """DESIGN section 7, explain, for the fast path: the competing lights and their P from
    the pair cache, selection and slots from the frame's state and outputs; the reasons a
    light does not compete from the scene the frame read."""
    cfg, frame, lights = rec.config, rec.frame, rec.lights
    row = object_row(frame.object_id, object_id)
    visible = bool(frame.visible[row])
    count = int(frame.count[row])
    slots = {int(frame.light_ids[row, k]): k for k in range(count)}
    held = {int(x) for x in rec.held[row] if x >= 0}
    selected = {int(x) for x in rec.selected[row] if x >= 0} if visible else set()
    earlier = bool(rec.was_visible[row]) and not bool(rec.is_new[row])
    i = int(np.searchsorted(rec.run, row))
    before = (rec.selected_before[i] if i < rec.run.size and rec.run[i] == row
              else rec.selected[row])
    prev_selected = {int(x) for x in before if x >= 0} if earlier else set()
    competing: dict[int, float] = {}
    if visible:
        start, length = (int(x) for x in rec.seg[row])
        for t in range(start, start + length):
            j = int(rec.heap.light_row[t])
            if rec.live[j]:
                competing[int(lights.id[j])] = float(rec.heap.p[t])
    box = np.concatenate([rec.objects.bounds_min[row], rec.objects.bounds_max[row]])[None, :]
    h, h_abs = cfg.hysteresis, cfg.hysteresis_abs

    rows: dict[int, ExplainRow] = {}
    wanted = set(lights.id[rec.light_visible].tolist()) | set(slots) | held
    for lid in wanted:
        j = int(np.searchsorted(lights.id, lid))
        present = j < len(lights) and lights.id[j] == lid
        directional = present and lights.type[j] == DIRECTIONAL
        d2 = NAN if not present or directional else float(box_d2(box, 0, *lights.position[j]))
        p = competing.get(lid, NAN)
        key = NAN if lid not in competing else (p + h * abs(p) + h_abs if lid in prev_selected
                                                 else p)
        if not present:
            reason = "removed"
        elif not visible:
            reason = "object_not_visible"
        elif not rec.light_visible[j]:
            reason = "light_not_visible"
        elif not int(lights.mask[j]) & int(rec.objects.mask[row]):
            reason = "masked"
        elif cfg.unshadowed == "skip" and lights.shadows[j] and not rec.live[j]:
            # (Visible here: not live means skipped, without a map or with a view of it
            # not ready, DESIGN "Sampling".)
            reason = "unshadowed_skip"
        elif directional and not cfg.directional_in_slots:
            reason = "directional"
            p = float(lights.intensity[j] + lights.priority[j])
        elif lid not in competing:
            r = float(lights.radius[j])
            reason = "out_of_range" if not d2 <= r * r else "outside_cone"
        elif lid in slots and frame.fade_state[row, slots[lid]] != FADING_OUT:
            reason = "selected"
        elif lid in selected:
            reason = "waiting"
        elif lid in slots:
            reason = "fading_out"
        else:
            reason = "below_k"
        k = slots.get(lid, -1)
        rows[lid] = ExplainRow(
            p, key, d2, k, NAN if k < 0 else float(frame.fade_weight[row, k]),
            -1 if k < 0 else int(frame.fade_state[row, k]), reason)
    return explanation(int(frame.object_id[row]), rec.frame_index, rows)
