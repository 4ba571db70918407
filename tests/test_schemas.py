"""schemas/: the committed JSON Schemas and golden examples are what the code produces, a
live server answers the golden requests with the golden bytes (HTTP and WebSocket), and the
Python client builds the golden requests and reads the golden answers as the embedded
scheduler's frames."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
from lightsched_client.client import frame_of
from lightsched_client.wire import JSON, MSGPACK, dumps, loads
from lightsched_server import schemas
from live import LiveServer
from websockets.sync.client import connect

import lightsched as ls
from lightsched.frame import FRAME_ARRAYS

ROOT = schemas.ROOT
INDEX = json.loads((ROOT / "examples" / "index.json").read_text())


@pytest.fixture(scope="module")
def server():
    s = LiveServer()
    yield s
    s.stop()


def test_committed_files_match_the_code():
    """The schemas are generated from the pydantic models and the examples from the
    client's encoder and a live server; regenerate with python -m lightsched_server.schemas."""
    files = schemas.all_files()
    for name, data in files.items():
        path = ROOT / name
        assert path.exists(), f"schemas/{name} is missing"
        assert path.read_bytes() == data, f"schemas/{name} drifted from the code"
    stale = {p.relative_to(ROOT).as_posix() for p in ROOT.rglob("*") if p.is_file()} \
        - set(files) - {"wire.md"}
    assert not stale, f"files no generator writes: {sorted(stale)}"


def test_frame_field_files_match_lightsched_fields():
    """schemas/frame_fields.json and the client package's copy are what lightsched.fields
    generates (python -m lightsched_server.schemas writes both), and the client's names,
    empty values and Frame fields come from it."""
    from lightsched_client import client

    from lightsched.fields import FIELDS, FRAME_FIELDS, fields_json

    for path, data in schemas.field_files().items():
        assert path.exists(), f"{path} is missing"
        want = {".ts": schemas.fields_ts, ".hpp": schemas.fields_cpp}.get(path.suffix, fields_json)()
        assert path.read_text("utf-8") == data.decode() == want, \
            f"{path} drifted from lightsched/fields.py"
    names = [f.name for f in FIELDS]
    assert client.FRAME_FIELDS == FRAME_FIELDS == tuple(names)
    assert client.PER_OBJECT == {f.name: f.empty for f in FIELDS if f.per_object}
    assert [f.name for f in dataclasses.fields(client.Frame)] == names + ["stats", "frame_index"]
    assert client.Frame().light_ids is None and client.Frame().stats == {}


@pytest.mark.parametrize("ext,encoding", [("msgpack", MSGPACK), ("json", JSON)])
def test_live_server_answers_golden_requests_byte_for_byte(server, ext, encoding):
    send = schemas.http_send(server.url)
    sid = ""
    for ex in INDEX:
        body = (ROOT / "examples" / f"{ex['name']}.request.{ext}").read_bytes()
        status, answer = send(ex["method"], ex["path"].replace("{id}", sid), body, encoding)
        assert status == ex["status"], (ex["name"], answer[:200])
        if ex["name"] == "session":
            sid = loads(answer, encoding)["id"]
            continue
        assert answer == (ROOT / "examples" / f"{ex['name']}.response.{ext}").read_bytes(), ex["name"]


def test_websocket_answers_golden_frames_byte_for_byte(server):
    send = schemas.http_send(server.url)
    session = (ROOT / "examples" / "session.request.msgpack").read_bytes()
    sid = loads(send("POST", "/v1/sessions", session, MSGPACK)[1], MSGPACK)["id"]
    url = server.url.replace("http://", "ws://") + f"/v1/sessions/{sid}/stream"
    with connect(url, compression=None) as ws:
        for name in ("frame-0", "frame-1-changed"):
            ws.send((ROOT / "examples" / f"{name}.request.msgpack").read_bytes())
            assert ws.recv() == (ROOT / "examples" / f"{name}.response.msgpack").read_bytes(), name


@pytest.mark.parametrize("ext,encoding", [("msgpack", MSGPACK), ("json", JSON)])
def test_client_reads_golden_answers_as_embedded_frames(ext, encoding):
    def answer(name):
        return loads((ROOT / "examples" / f"{name}.response.{ext}").read_bytes(), encoding)

    want = ls.schedule(schemas.LIGHTS, schemas.OBJECTS, [schemas.CAMERA], schemas.CONFIG)
    got = frame_of(answer("schedule"))
    embedded = ls.Scheduler(schemas.CONFIG)
    embedded.set_lights(**schemas.LIGHTS)
    embedded.set_objects(**schemas.OBJECTS)
    frames = [(got, want), (frame_of(answer("frame-0")), embedded.frame([schemas.CAMERA]))]
    embedded.update_lights(id=[3], position=[[1.0, 4.0, 2.0]])
    frames.append((frame_of(answer("frame-1-changed"), frames[-1][0]),
                   embedded.frame([schemas.CAMERA], dt=0.1)))
    for k, (g, w) in enumerate(frames):
        for name in FRAME_ARRAYS:
            if k == 2 and name == "priority":
                continue  # changed_only sends priority with changed rows only
            assert np.array_equal(getattr(g, name), getattr(w, name)), (k, name)
    problem = answer("schedule-invalid")
    assert (problem["status"], problem["field"], problem["index"]) == (422, "radius", 1)
    # The client's encoder still writes the golden request bytes.
    for ex in schemas.example_requests():
        assert dumps(ex["request"], encoding) == \
            (ROOT / "examples" / f"{ex['name']}.request.{ext}").read_bytes(), ex["name"]
