"""The conformance suite (schemas/conformance, server/conformance.py) run by the Python
client against a live service, over HTTP in both encodings and over the stream: every
frame equals the embedded scheduler's (changed_only answers merged), every refusal is the
problem document the suite names. The TypeScript and C++ clients run the same files."""

from __future__ import annotations

import json
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from lightsched_client import Client, RemoteError
from lightsched_client.wire import JSON, MSGPACK, from_wire
from live import LiveServer

from lightsched.scene import CHANGE_OPS

SUITE = sorted((Path(__file__).resolve().parent.parent / "schemas" / "conformance").glob("*.json"))
MODES = [("http", MSGPACK), ("http", JSON), ("stream", MSGPACK)]


@pytest.fixture(scope="module")
def server():
    s = LiveServer()
    yield s
    s.stop()


def check_frame(frame: Any, expect: dict[str, Any], where: str) -> None:
    assert frame.frame_index == expect["frame_index"], where
    for name, wire in expect["arrays"].items():
        want, got = from_wire(wire), getattr(frame, name)
        assert got is not None, f"{where}: {name} missing"
        assert got.dtype == want.dtype and got.shape == want.shape, (where, name)
        assert np.array_equal(got, want), f"{where}: {name} differs"


def check_explanation(e: Any, expect: dict[str, Any], where: str) -> None:
    for name, want in expect.items():
        got = getattr(e, name)
        if isinstance(want, dict):
            want = from_wire(want)
            assert got.dtype == want.dtype, (where, name)
            assert np.array_equal(got, want, equal_nan=want.dtype.kind == "f"), (where, name)
        else:
            assert got == want, (where, name)


def outcome(call: Any, step: dict[str, Any], where: str, check: Any = check_frame) -> None:
    if "expect" in step:
        check(call(), step["expect"], where)
        return
    with pytest.raises(RemoteError) as e:
        call()
    want, got = step["error"], e.value.problem
    assert e.value.status == want["status"], (where, got)
    for key in ("status", "type", "field", "index", "pointer"):
        assert got.get(key) == want[key], (where, key, got)


def run(doc: dict[str, Any], client: Client, stream: bool) -> None:
    session: Any = None
    for i, step in enumerate(doc["steps"]):
        call, where = step["call"], f"{doc['name']} step {i} ({step['call']})"
        if call == "session":
            session = client.session(step["config"], stream=stream)
        elif call in CHANGE_OPS:
            getattr(session, call)(**from_wire(step["fields"]))
        elif call == "frame":
            outcome(partial(session.frame, from_wire(step["cameras"]), dt=step["dt"],
                            cut=step["cut"], outputs=step["outputs"],
                            changed_only=step["changed_only"]), step, where)
        elif call == "schedule":
            outcome(partial(client.schedule, from_wire(step["lights"]),
                            from_wire(step["objects"]), from_wire(step["cameras"]),
                            step["config"], step["outputs"]), step, where)
        elif call == "explain":
            outcome(partial(session.explain, step["object_id"]), step, where,
                    check_explanation)
        elif call == "info":
            info = session.info()
            assert {k: info[k] for k in step["expect"]} == step["expect"], where
        elif call == "close":
            session.close()
        elif call == "lose":  # as a dead worker loses it
            client.call("DELETE", f"/v1/sessions/{session.id}")
        else:
            raise AssertionError(f"{where}: unknown call")


def test_the_suite_covers_every_call():
    calls = {s["call"] for path in SUITE for s in json.loads(path.read_text())["steps"]}
    assert calls == {"session", "frame", "explain", "info", "close", "schedule", "lose",
                     *CHANGE_OPS}
    errors = [s["error"]["status"] for path in SUITE for s in json.loads(path.read_text())["steps"]
              if "error" in s]
    assert 404 in errors and errors.count(422) >= 5


@pytest.mark.parametrize("mode,encoding", MODES)
@pytest.mark.parametrize("path", SUITE, ids=lambda p: p.stem)
def test_python_client_passes_the_suite(server, path, mode, encoding):
    with Client(server.url, encoding=encoding) as client:
        run(json.loads(path.read_text()), client, stream=mode == "stream")
