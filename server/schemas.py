"""schemas/: the JSON Schema of every request and response (from models.py), the frame's
field list (frame_fields.json, from lightsched.fields; the Python client ships a copy) and
the golden examples, request/response pairs in both encodings that the server's and every
client's tests replay byte for byte, and the conformance scenarios every client runs
(conformance.py).

    python -m lightsched_server.schemas          # rewrite schemas/ and the client's copy
    python -m lightsched_server.schemas --check  # exit 1 if the committed files drifted
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np
from lightsched_client.client import _Changes, camera_doc, config_doc, fields_doc
from lightsched_client.wire import JSON, MSGPACK, dumps, loads

import lightsched as ls
from lightsched.fields import fields_json

from .conformance import conformance_files
from .models import SCHEMAS

REPO = Path(__file__).resolve().parent.parent
ROOT = REPO / "schemas"
# The client package reads the field list as package data, from its own folder: it cannot
# reach schemas/ once installed.
CLIENT_FIELDS = REPO / "clients" / "python" / "lightsched_client" / "frame_fields.json"
ENCODINGS = {"msgpack": MSGPACK, "json": JSON}


def schema_files() -> dict[str, bytes]:
    out = {}
    for name, model in SCHEMAS.items():
        schema = model.model_json_schema()
        schema["$schema"] = "https://json-schema.org/draft/2020-12/schema"
        schema["$id"] = f"urn:lightsched:schema:v1:{name}"
        out[f"{name}.schema.json"] = (json.dumps(schema, indent=2, sort_keys=True) + "\n").encode()
    return out


TS_FIELDS = REPO / "clients" / "typescript" / "src" / "fields.ts"
# The typed array a TypeScript frame holds per dtype (wire.ts's ARRAY_OF).
TS_ARRAYS = {"bool": "Uint8Array", "int8": "Int8Array", "uint8": "Uint8Array",
             "int16": "Int16Array", "uint16": "Uint16Array", "int32": "Int32Array",
             "uint32": "Uint32Array", "int64": "BigInt64Array", "uint64": "BigUint64Array",
             "float32": "Float32Array", "float64": "Float64Array"}


def fields_ts() -> str:
    """The field list as a TypeScript module for the TypeScript client: the list, and
    the frame's arrays as typed properties."""
    from lightsched.fields import FIELDS

    docs = [f.document() for f in FIELDS]
    rows = ",\n".join("  " + json.dumps(d) for d in docs)
    props = "\n".join(
        f"  /** {d['description']} ({d['dtype']} [{', '.join(d['shape'])}]) */\n"
        f"  {d['name']}?: NdArray<{TS_ARRAYS[d['dtype']]}>;" for d in docs)
    return ("// Generated from lightsched/fields.py by python -m lightsched_server.schemas; do "
            "not edit.\n// DESIGN section 3's frame arrays, in its order (schemas/"
            "frame_fields.json).\n\nimport type { DType, NdArray } from \"./wire.js\";\n\n"
            "export interface FrameField {\n  name: FieldName;\n  dtype: DType;\n"
            "  shape: string[];\n  per_object: boolean;\n  empty: number | boolean | null;\n"
            "  description: string;\n}\n\n"
            f"export const FRAME_FIELDS: readonly FrameField[] = [\n{rows},\n];\n\n"
            "export type FieldName =\n"
            + "\n".join(f"  | {json.dumps(d['name'])}" for d in docs) + ";\n\n"
            "/** The arrays of a frame; those not asked for (outputs) are absent. */\n"
            f"export interface FrameArrays {{\n{props}\n}}\n" + _explain_ts())


def _explain_ts() -> str:
    """explain's reasons and columns (lightsched.fields) as TypeScript."""
    from lightsched.fields import EXPLAIN_FIELDS, REASONS

    cols = "\n".join(
        f"  /** {f.description} */\n  {f.name}: "
        + ("Reason[]" if f.dtype is None else f"NdArray<{TS_ARRAYS[np.dtype(f.dtype).name]}>")
        + ";" for f in EXPLAIN_FIELDS)
    return ("\n// Scheduler.explain (DESIGN section 7): its reasons, in their order, and its "
            "columns.\n"
            f"export const REASONS = {json.dumps(list(REASONS))} as const;\n\n"
            "export type Reason = (typeof REASONS)[number];\n\n"
            f"export const EXPLAIN_FIELDS = {json.dumps([f.name for f in EXPLAIN_FIELDS])} "
            "as const;\n\n"
            "/** One row per light that was visible, held a slot of the object or held one when "
            "the last frame\n * began, in ascending light id; NaN or -1 where a value does not "
            "exist. */\n"
            "export interface Explanation {\n  object_id: number;\n  /** the frame explained "
            f"*/\n  frame_index: number;\n{cols}\n}}\n")


CPP_FIELDS = REPO / "clients" / "cpp" / "include" / "lightsched" / "fields.hpp"


def fields_cpp() -> str:
    """The field list as a C++17 header for the C++ client."""
    from lightsched.fields import FIELDS

    def empty(value: object) -> str:
        assert value is None or float(value) == int(value), "the header's empty is an int"
        return "0" if value is None else str(int(value))

    rows = ",\n".join(
        f"    {{\"{f.name}\", \"{np.dtype(f.dtype).name}\", {int(len(f.shape))}, "
        f"{'true' if f.per_object else 'false'}, {empty(f.empty)}}}" for f in FIELDS)
    return ("// Generated from lightsched/fields.py by python -m lightsched_server.schemas; do "
            "not edit.\n// DESIGN section 3's frame arrays, in its order (schemas/"
            "frame_fields.json).\n#pragma once\n\n#include <array>\n\nnamespace lightsched {\n\n"
            "struct FrameField {\n  const char* name;\n  const char* dtype;\n"
            "  int ndim;\n  bool per_object;  // sent by rows with changed_only\n"
            "  int empty;  // a per-object row's value when the object has nothing\n};\n\n"
            f"inline constexpr std::array<FrameField, {len(FIELDS)}> FRAME_FIELDS{{{{\n{rows},\n}}}};"
            "\n\n}  // namespace lightsched\n")


def field_files() -> dict[Path, bytes]:
    """schemas/frame_fields.json, the Python client package's copy, the TypeScript
    client's module and the C++ client's header (no server needed)."""
    data = fields_json().encode()
    return {ROOT / "frame_fields.json": data, CLIENT_FIELDS: data, TS_FIELDS: fields_ts().encode(),
            CPP_FIELDS: fields_cpp().encode()}


# The golden scene: a point light, a shadowed spot, a shadowed sun; four boxes; one camera.
LIGHTS = {
    "id": np.array([3, 7, 9], np.int32),
    "type": np.array([0, 1, 2], np.uint8),
    "position": np.array([[0.0, 4.0, 2.0], [3.0, 6.0, 0.0], [0.0, 0.0, 0.0]]),
    "radius": np.array([10.0, 12.0, 1.0]),
    "direction": np.array([[0.0, -1.0, 0.0], [0.0, -1.0, 0.0], [0.5, -1.0, 0.25]]),
    "outer_angle": np.array([0.8, 0.6, 0.8]),
    "intensity": np.array([5.0, 8.0, 1.0]),
    "shadows": np.array([False, True, True]),
}
OBJECTS = {
    "id": np.array([10, 11, 12, 13], np.int32),
    "bounds_min": np.array([[-1.0, 0.0, -1.0], [2.0, 0.0, 1.0], [-4.0, 0.0, 3.0],
                            [-20.0, -0.5, -20.0]]),
    "bounds_max": np.array([[1.0, 2.0, 1.0], [3.0, 5.0, 2.0], [-3.0, 1.0, 4.0],
                            [20.0, 0.0, 20.0]]),
}
CAMERA = ls.Camera(position=np.array([0.0, 5.0, -15.0]), forward=np.array([0.0, -0.3, 1.0]),
                   up=np.array([0.0, 1.0, 0.0]), fov_y=1.0, aspect=16 / 9, near=0.1, far=100.0,
                   height_px=720.0)
CONFIG = ls.Config(max_lights=2, shadow_budget=2, cascades=2)


def example_requests() -> list[dict[str, Any]]:
    """The golden exchanges, in the order a client makes them: method, path ({id} is the
    session made by the "session" exchange), request map, expected status."""
    first, later = _Changes(), _Changes()
    first.set_lights(**LIGHTS)
    first.set_objects(**OBJECTS)
    later.update_lights(id=[3], position=[[1.0, 4.0, 2.0]])
    bad = {k: v.copy() for k, v in LIGHTS.items()}
    bad["radius"][1] = -1.0
    return [
        {"name": "schedule", "method": "POST", "path": "/v1/schedule", "status": 200,
         "request": {"lights": fields_doc(LIGHTS), "objects": fields_doc(OBJECTS),
                     "cameras": [camera_doc(CAMERA)], "config": config_doc(CONFIG),
                     "stats": False}},
        {"name": "schedule-invalid", "method": "POST", "path": "/v1/schedule", "status": 422,
         "request": {"lights": fields_doc(bad), "objects": fields_doc(OBJECTS),
                     "cameras": [camera_doc(CAMERA)], "stats": False}},
        {"name": "session", "method": "POST", "path": "/v1/sessions", "status": 201,
         "request": {"config": config_doc(CONFIG)}},
        {"name": "frame-0", "method": "POST", "path": "/v1/sessions/{id}/frames", "status": 200,
         "request": {**first._request([CAMERA], 1 / 60, False, None, False), "stats": False}},
        {"name": "frame-1-changed", "method": "POST", "path": "/v1/sessions/{id}/frames",
         "status": 200,
         "request": {**later._request([CAMERA], 0.1, False, None, True), "stats": False}},
    ]


def replay(send: Any, encoding: str) -> list[tuple[dict[str, Any], bytes, int, bytes]]:
    """Runs the exchanges through ``send(method, path, body, content_type) -> (status,
    body)``; returns (exchange, request bytes, status, response bytes). The session
    exchange's answer (a random id) is not kept as golden."""
    out, sid = [], None
    for ex in example_requests():
        body = dumps(ex["request"], encoding)
        status, answer = send(ex["method"], ex["path"].replace("{id}", sid or ""), body, encoding)
        if ex["name"] == "session":
            sid = loads(answer, encoding)["id"]
            answer = b""
        out.append((ex, body, status, answer))
    return out


def example_files(send: Any) -> dict[str, bytes]:
    files: dict[str, bytes] = {}
    index = []
    for ext, encoding in ENCODINGS.items():
        for ex, body, status, answer in replay(send, encoding):
            files[f"examples/{ex['name']}.request.{ext}"] = body
            if answer:
                files[f"examples/{ex['name']}.response.{ext}"] = answer
            if ext == "msgpack":
                index.append({"name": ex["name"], "method": ex["method"], "path": ex["path"],
                              "status": status, "response": bool(answer)})
    files["examples/index.json"] = (json.dumps(index, indent=2) + "\n").encode()
    return files


def http_send(url: str) -> Any:
    """send() over one kept-alive HTTP connection to a running service."""
    import http.client
    from urllib.parse import urlsplit

    parts = urlsplit(url)
    conn = http.client.HTTPConnection(parts.hostname, parts.port, timeout=600)

    def send(method: str, path: str, body: bytes, encoding: str) -> tuple[int, bytes]:
        conn.request(method, path, body=body, headers={"Content-Type": encoding,
                                                       "Accept": encoding})
        r = conn.getresponse()
        return r.status, r.read()

    return send


def all_files() -> dict[str, bytes]:
    """Every file of schemas/, the examples answered by a service started for the purpose."""
    from .app import ServerThread

    server = ServerThread()
    try:
        return {**schema_files(), "frame_fields.json": fields_json().encode(),
                **example_files(http_send(server.url)), **conformance_files()}
    finally:
        server.stop()


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--check", action="store_true", help="fail if schemas/ differs")
    args = p.parse_args(argv)
    files = {ROOT / name: data for name, data in all_files().items()} | field_files()
    drift = [path for path, data in files.items()
             if not path.exists() or path.read_bytes() != data]
    if args.check:
        for path in drift:
            print(f"{path.relative_to(REPO)} differs from what the code generates",
                  file=sys.stderr)
        return 1 if drift else 0
    for path in drift:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(files[path])
        print(f"wrote {path.relative_to(REPO)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
