"""The wire schema as pydantic models: requests are checked against them (structure and
types; the arrays themselves are checked by the core, which names the field and the first
bad row) and schemas/*.schema.json are generated from them (``python -m lightsched_server.
schemas``). Field names are DESIGN's."""

from __future__ import annotations

from typing import Annotated, Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, WithJsonSchema, create_model

from lightsched.fields import EXPLAIN_FIELDS, FIELDS, FRAME_FIELDS, REASONS
from lightsched.scene import CHANGE_OPS, LIGHT_FIELDS, OBJECT_FIELDS

WIRE_ARRAY_SCHEMA = {
    "title": "WireArray",
    "description": "A numeric array: raw little-endian C-order bytes (msgpack bin, or base64 "
                   "text in JSON) of the given dtype and shape; plain nested lists of numbers "
                   "are accepted on input too.",
    "oneOf": [
        {"type": "object", "required": ["dtype", "shape", "data"], "additionalProperties": False,
         "properties": {
             "dtype": {"enum": ["bool", "int8", "uint8", "int16", "uint16", "int32", "uint32",
                                "int64", "uint64", "float32", "float64"]},
             "shape": {"type": "array", "items": {"type": "integer", "minimum": 0}},
             # JSON Schema has no bytes type: a msgpack bin is not a string, so data is
             # left untyped here and the encodings are named in x-msgpack / x-json.
             "data": {"description": "the raw bytes: a msgpack bin, or in JSON standard "
                                     "base64 text with padding",
                      "x-msgpack": "bin", "x-json": {"type": "string",
                                                     "contentEncoding": "base64"}}}},
        {"type": "array"},
    ],
}
# Arrays reach the models already decoded (numpy) or as lists; the core validates them.
WireArray = Annotated[Any, WithJsonSchema(WIRE_ARRAY_SCHEMA)]
OutputName = Literal[FRAME_FIELDS]  # type: ignore[valid-type]

STRICT = ConfigDict(extra="forbid", strict=True, arbitrary_types_allowed=True)


class ConfigModel(BaseModel):
    """lightsched.Config (DESIGN section 1); omitted fields take their defaults."""

    model_config = STRICT
    max_lights: int | None = None
    model: Literal["contribution", "thesis"] | None = None
    w_ecc: float | None = None
    w_dist: float | None = None
    w_obj: float | None = None
    w_int: float | None = None
    c1: float | None = None
    hysteresis: float | None = None
    hysteresis_abs: float | None = None
    fade_in: float | None = None
    fade_out: float | None = None
    directional_in_slots: bool | None = None
    shadow_budget: int | None = None
    cascades: int | None = None
    shadow_distance: float | None = None
    cascade_overlap: float | None = None
    max_shadowed_per_object: int | None = None
    unshadowed: Literal["light", "skip"] | None = None
    precision: Literal["exact", "fast"] | None = None
    residual: bool | None = None
    shadow_update_budget: int | None = None
    shadow_atlas_size: int | None = None
    caster_culling: Literal["camera", "light"] | None = None


class CameraModel(BaseModel):
    """lightsched.Camera (DESIGN section 1); a camera without an id takes its position in
    the list."""

    model_config = STRICT
    id: int | None = None
    position: WireArray
    forward: WireArray
    up: WireArray
    fov_y: float
    aspect: float
    near: float
    far: float
    focus: WireArray = (0.0, 0.0)
    height_px: float = 1080.0


LightFields = Annotated[dict[Literal[LIGHT_FIELDS], WireArray],  # type: ignore[valid-type]
                        Field(description="set_lights / update_lights keyword arrays")]
ObjectFields = Annotated[dict[Literal[OBJECT_FIELDS], WireArray],  # type: ignore[valid-type]
                         Field(description="set_objects / update_objects keyword arrays")]


class Change(BaseModel):
    """One scene change, the embedded call of the same name (DESIGN section 7); the
    changes of a frame request run in order, all or nothing."""

    model_config = STRICT
    op: Literal[CHANGE_OPS]  # type: ignore[valid-type]
    fields: dict[str, WireArray]


class FrameRequest(BaseModel):
    """POST /v1/sessions/{id}/frames and each WebSocket message: scene changes, then one
    frame. ``outputs`` names the arrays wanted (default all); ``changed_only`` sends the
    per-object arrays only for the objects whose set, order, weights or states changed since
    the session's previous frame (``rows`` lists them); ``stats`` false leaves out the
    plan, counts and timings (the golden examples do, to be byte-for-byte repeatable)."""

    model_config = STRICT
    dt: float = 1.0 / 60.0
    cut: bool = False
    cameras: list[CameraModel] = Field(min_length=1, max_length=8)
    changes: list[Change] = []
    outputs: list[OutputName] | None = None
    changed_only: bool = False
    stats: bool = True
    seq: int | None = Field(
        None, ge=0, description="makes the request safe to retry: the frame_index this frame "
        "will have (the session's frames so far). The same seq as the last frame's gets that "
        "answer again, nothing applied twice; any other is refused (409, field seq).")


class ScheduleRequest(BaseModel):
    """POST /v1/schedule: the stateless one-frame call ``lightsched.schedule``."""

    model_config = STRICT
    lights: LightFields
    objects: ObjectFields
    cameras: list[CameraModel] = Field(min_length=1, max_length=8)
    config: ConfigModel | None = None
    outputs: list[OutputName] | None = None
    stats: bool = True


class SessionRequest(BaseModel):
    """POST /v1/sessions, PUT /v1/sessions/{id}."""

    model_config = STRICT
    config: ConfigModel | None = None


class SessionInfo(BaseModel):
    """A session (POST /v1/sessions, GET /v1/sessions/{id})."""

    id: str
    config: dict[str, Any]
    frame_index: int
    lights: int
    objects: int
    idle_seconds: float


class Ticket(BaseModel):
    """POST /v1/sessions/{id}/tickets: a one-use ticket that opens the session's stream
    (``/v1/sessions/{id}/stream?ticket=<ticket>``) without the key, for browsers."""

    ticket: str
    expires_in: float = Field(description="seconds the ticket stays redeemable")


class _FrameHead(BaseModel):
    frame_index: int
    changed_only: bool = False
    rows: WireArray | None = None
    stats: dict[str, Any] | None = None


def _array_doc(f: Any) -> str:
    shape = ", ".join(f.shape)
    empty = f"; empty: {f.empty!r}" if f.per_object else ""
    return f"{f.description} ({np.dtype(f.dtype).name} [{shape}]{empty})"


# The arrays are lightsched.fields' (also schemas/frame_fields.json), in its order.
FrameResponse = create_model(
    "FrameResponse", __base__=_FrameHead,
    __doc__="A frame (DESIGN section 3) with the arrays asked for. With changed_only, ``rows`` "
            "are the object ids whose per-object arrays follow (in ``rows`` order), and "
            "``object_id`` is present only when the object set changed.",
    **{f.name: (WireArray | None, Field(None, description=_array_doc(f))) for f in FIELDS})


def _column(f: Any) -> tuple[Any, Any]:
    if f.dtype is None:
        return list[str], Field(description=f.description)
    return WireArray, Field(description=f"{f.description} ({np.dtype(f.dtype).name} [L])")


# The columns are lightsched.fields.EXPLAIN_FIELDS, in its order.
ExplanationResponse = create_model(
    "ExplanationResponse",
    __doc__="GET /v1/sessions/{id}/objects/{object_id}/explain (lightsched.Scheduler.explain, "
            "DESIGN section 7): one row per light (L of them) that was visible, holds a slot "
            "of the object or held one when the last frame began, in ascending light id; NaN "
            "or -1 where a value does not exist; reason: the first that applies, one of "
            + ", ".join(REASONS) + ".",
    object_id=(int, ...), frame_index=(int, Field(description="the frame explained")),
    **{f.name: _column(f) for f in EXPLAIN_FIELDS})


class ProblemModel(BaseModel):
    """An error (RFC 9457), with DESIGN's field and first bad index for bad input."""

    type: str
    title: str
    status: int
    detail: str
    instance: str | None = None
    field: str | None = None
    index: int | None = None
    pointer: str | None = None


SCHEMAS: dict[str, type[BaseModel]] = {
    "config": ConfigModel, "camera": CameraModel, "change": Change,
    "frame_request": FrameRequest, "schedule_request": ScheduleRequest,
    "session_request": SessionRequest, "session": SessionInfo, "frame": FrameResponse,
    "problem": ProblemModel, "ticket": Ticket, "explanation": ExplanationResponse,
}
