"""The service over real sockets: a uvicorn server on a free port (tests/live.py), real
msgpack / JSON bytes, the Python client (HTTP, WebSocket, asyncio) and raw http.client
requests. Round trips must equal the embedded Scheduler bit for bit; every refusal is a 4xx
problem document that names the field and first bad index as the embedded API does, and
leaves the session as it was."""

from __future__ import annotations

import asyncio
import http.client
import json
import time

import msgpack
import numpy as np
import pytest
from lightsched_client import AsyncClient, Client, RemoteError
from lightsched_client import ValidationError as RemoteValidationError
from lightsched_client.client import camera_doc
from lightsched_client.wire import JSON, MSGPACK, dumps, loads
from lightsched_server import Settings
from live import LiveServer

import lightsched as ls
from lightsched.frame import FRAME_ARRAYS
from lightsched.scene import LIGHT_FIELDS, OBJECT_FIELDS, ObjectStore
from lightsched.scenes import city, move_lights

SCENE = city(300, 40, seed=1, shadow_fraction=0.2, sun_shadows=True)
CONFIG = ls.Config(max_lights=4, shadow_budget=3)


@pytest.fixture(scope="module")
def server():
    s = LiveServer()
    yield s
    s.stop()


@pytest.fixture(scope="module")
def limited():
    # small_scene=0: every frame goes to a worker thread, so a burst queues up.
    s = LiveServer(Settings(max_body_bytes=200_000, max_lights=60, max_objects=400,
                            max_pending_frames=2, small_scene=0))
    yield s
    s.stop()


def assert_same_frame(remote, embedded, what="", skip=()):
    for name, dtype in FRAME_ARRAYS.items():
        if name in skip:
            continue
        a, b = getattr(remote, name), getattr(embedded, name)
        assert a is not None, f"{what}: {name} missing"
        assert a.dtype == np.dtype(dtype) and a.shape == b.shape, (what, name, a.dtype, a.shape)
        assert np.array_equal(a, b), f"{what}: {name} differs"


def script(sched, frame):
    """The same session for every backend: set, frames with moving lights, updates,
    removals, a camera change and a cut. ``frame(cams, dt, cut)`` steps one frame."""
    sched.set_lights(**SCENE.lights)
    sched.set_objects(**SCENE.objects)
    out = [frame(SCENE.cameras, 1 / 60, False)]
    for i in range(1, 4):
        sched.update_lights(id=SCENE.lights["id"], position=move_lights(SCENE.lights, i))
        out.append(frame(SCENE.cameras, 0.05, False))
    sched.remove_lights(id=SCENE.lights["id"][:5])
    sched.update_objects(id=SCENE.objects["id"][:10], bounds_max=SCENE.objects["bounds_max"][:10] + 1)
    sched.remove_objects(id=SCENE.objects["id"][10:20])
    out.append(frame([MOVED], 0.1, False))
    out.append(frame([MOVED, SCENE.cameras[0]], 0.0, True))
    return out


_CAM = SCENE.cameras[0]
MOVED = ls.Camera(position=np.asarray(_CAM.position) + 5.0, forward=_CAM.forward, up=_CAM.up,
                  fov_y=_CAM.fov_y, aspect=_CAM.aspect, near=_CAM.near, far=_CAM.far, id=_CAM.id + 1)


def embedded_run():
    s = ls.Scheduler(CONFIG)
    return script(s, lambda c, dt, cut: s.frame(c, dt=dt, cut=cut))


@pytest.mark.parametrize("stream", [False, True], ids=["http", "websocket"])
def test_session_frames_equal_embedded(server, stream):
    want = embedded_run()
    with Client(server.url) as c:
        s = c.session(CONFIG, stream=stream)
        got = script(s, lambda cams, dt, cut: s.frame(cams, dt=dt, cut=cut))
        s.close()
    for k, (a, b) in enumerate(zip(got, want, strict=True)):
        assert_same_frame(a, b, f"frame {k}")
        assert a.frame_index == k


@pytest.mark.parametrize("stream", [False, True], ids=["http", "websocket"])
def test_async_client_equals_embedded(server, stream):
    want = embedded_run()

    async def run():
        async with AsyncClient(server.url) as c:
            s = await c.session(CONFIG, stream=stream)
            frames = []
            # The script is synchronous; it records the calls, each frame awaited in turn.
            s.set_lights(**SCENE.lights)
            s.set_objects(**SCENE.objects)
            frames.append(await s.frame(SCENE.cameras, dt=1 / 60))
            for i in range(1, 4):
                s.update_lights(id=SCENE.lights["id"], position=move_lights(SCENE.lights, i))
                frames.append(await s.frame(SCENE.cameras, dt=0.05))
            await s.close()
            return frames

    got = asyncio.run(run())
    for k, (a, b) in enumerate(zip(got, want[:4], strict=True)):
        assert_same_frame(a, b, f"frame {k}")


@pytest.mark.parametrize("encoding", [MSGPACK, JSON])
def test_schedule_equals_embedded(server, encoding):
    want = ls.schedule(SCENE.lights, SCENE.objects, SCENE.cameras, CONFIG)
    with Client(server.url, encoding=encoding) as c:
        got = c.schedule(SCENE.lights, SCENE.objects, SCENE.cameras, CONFIG)
    assert_same_frame(got, want, encoding)
    assert got.stats["plan"] == want.stats["plan"]


def test_changed_only_rebuilds_the_frame_and_sends_less(server):
    full_frames = embedded_run()
    with Client(server.url) as c:
        s = c.session(CONFIG)
        got = script(s, lambda cams, dt, cut: s.frame(cams, dt=dt, cut=cut, changed_only=True))
        # Nothing moves: no object row changes, so none is sent.
        raw = c.call("POST", f"/v1/sessions/{s.id}/frames",
                     {"cameras": [camera_doc(MOVED), camera_doc(SCENE.cameras[0])],
                      "dt": 0.0, "changed_only": True})
        s.close()
    for k, (a, b) in enumerate(zip(got, full_frames, strict=True)):
        for name in FRAME_ARRAYS:
            if name == "priority":
                continue  # priority is not part of "changed"; unchanged rows keep the last sent
            assert np.array_equal(getattr(a, name), getattr(b, name)), (k, name)
    assert raw["rows"].size == 0 and raw["light_ids"].shape == (0, 4)
    # The residual's rows (a trailing axis of 4) are merged too, and are not all zero here.
    assert raw["residual"].shape == (0, 4) and raw["residual"].dtype == np.float32
    assert all(f.residual[:, 0].any() for f in full_frames)
    assert "object_id" not in raw  # the object set did not change


def test_outputs_selection(server):
    with Client(server.url) as c:
        f = c.schedule(SCENE.lights, SCENE.objects, SCENE.cameras, outputs=["light_ids", "caster_ids"])
    assert f.light_ids is not None and f.caster_ids is not None
    assert f.fade_weight is None and f.object_id is None


# --------------------------------------------------------------------------- refusals

BAD = {
    "nan position": ("set_lights", dict(id=[1, 2], position=[[0, 0, 0], [0, np.nan, 0]],
                                        radius=[1.0, 1.0])),
    "inf bounds": ("set_objects", dict(id=[1], bounds_min=[[0, 0, 0]], bounds_max=[[np.inf, 1, 1]])),
    "radius <= 0": ("set_lights", dict(id=[1, 2, 3], position=[[0, 0, 0]] * 3, radius=[1.0, 2.0, 0.0])),
    "duplicate id": ("set_lights", dict(id=[4, 5, 4], position=[[0, 0, 0]] * 3, radius=[1.0] * 3)),
    "min > max": ("set_objects", dict(id=[1, 2], bounds_min=[[0, 0, 0], [2, 0, 0]],
                                      bounds_max=[[1, 1, 1], [1, 1, 1]])),
    "zero direction": ("set_lights", dict(id=[1], type=[1], position=[[0, 0, 0]], radius=[1.0],
                                          direction=[[0, 0, 0]])),
    "unknown type": ("set_lights", dict(id=[1, 2], type=[0, 7], position=[[0, 0, 0]] * 2,
                                        radius=[1.0, 1.0])),
    "unknown id": ("update_lights", dict(id=[999999], radius=[2.0])),
    "remove unknown": ("remove_objects", dict(id=[123456])),
    "bad shape": ("set_lights", dict(id=[1, 2], position=[[0, 0]] * 2, radius=[1.0, 1.0])),
    "mask too big": ("set_objects", dict(id=[1], bounds_min=[[0, 0, 0]], bounds_max=[[1, 1, 1]],
                                         mask=[2**33])),
    "unknown field": ("set_lights", dict(id=[1], position=[[0, 0, 0]], radius=[1.0], colour=[1])),
    "spot outer angle": ("set_lights", dict(id=[1], type=[1], position=[[0, 0, 0]], radius=[1.0],
                                            direction=[[0, 0, 1]], outer_angle=[2.0])),
}


def embedded_error(op, fields):
    s = ls.Scheduler(CONFIG)
    s.set_lights(**SCENE.lights)
    s.set_objects(**SCENE.objects)
    with pytest.raises(ls.ValidationError) as e:
        getattr(s, op)(**fields)
    return e.value


@pytest.mark.parametrize("case", list(BAD))
def test_bad_input_is_422_naming_field_and_index_and_changes_nothing(server, case):
    op, fields = BAD[case]
    want = embedded_error(op, fields)
    twin = ls.Scheduler(CONFIG)
    with Client(server.url) as c:
        s = c.session(CONFIG)
        for sched in (s, twin):
            sched.set_lights(**SCENE.lights)
            sched.set_objects(**SCENE.objects)
        assert_same_frame(s.frame(SCENE.cameras), twin.frame(SCENE.cameras), "before")
        before = s.info()
        # A good change first, then the bad one: all or nothing.
        s.update_lights(id=SCENE.lights["id"][:3], radius=[50.0] * 3)
        getattr(s, op)(**fields)
        with pytest.raises(RemoteValidationError) as e:
            s.frame(SCENE.cameras)
        assert e.value.status == 422
        assert (e.value.field, e.value.index) == (want.field, want.index), e.value.problem
        assert e.value.problem["type"] == "urn:lightsched:problem:validation"
        assert e.value.problem["pointer"] == f"/changes/1/fields/{want.field}"
        after = s.info()
        assert {k: after[k] for k in ("frame_index", "lights", "objects")} == \
            {k: before[k] for k in ("frame_index", "lights", "objects")}
        # The session goes on exactly as the embedded scheduler that never saw the request.
        assert_same_frame(s.frame(SCENE.cameras, dt=0.1), twin.frame(SCENE.cameras, dt=0.1), "after")
        s.close()


@pytest.mark.parametrize("case,camera,field,index", [
    ("fov", {"fov_y": 3.5}, "cameras.fov_y", 1),
    ("up parallel", {"up": [0.0, 0.0, 1.0], "forward": [0.0, 0.0, 2.0]}, "cameras.up", 1),
    ("far <= near", {"far": 0.01}, "cameras.far", 1),
    ("focus", {"focus": [0.0, 2.0]}, "cameras.focus", 1),
])
def test_bad_camera_is_422(server, case, camera, field, index):
    good = camera_doc(SCENE.cameras[0])
    bad = {**good, "id": 5, **camera}
    with Client(server.url) as c:
        s = c.session(CONFIG)
        with pytest.raises(RemoteValidationError) as e:
            s.frame([good, bad])
        assert (e.value.field, e.value.index) == (field, index)
        assert s.info()["frame_index"] == 0
        s.close()


def raw(server, method, path, body=b"", headers=None):
    """One raw request; returns (status, content-type, decoded body or text)."""
    conn = http.client.HTTPConnection("127.0.0.1", server.port, timeout=30)
    conn.request(method, path, body=body, headers=headers or {})
    r = conn.getresponse()
    data = r.read()
    ctype = r.getheader("content-type") or ""
    conn.close()
    if "msgpack" in ctype:
        return r.status, ctype, msgpack.unpackb(data)
    if "json" in ctype:
        return r.status, ctype, json.loads(data)
    return r.status, ctype, data.decode()


def session_id(server):
    with Client(server.url) as c:
        return c.session(CONFIG).id


def test_malformed_wrong_types_and_media(server):
    sid = session_id(server)
    path = f"/v1/sessions/{sid}/frames"
    mp = {"Content-Type": MSGPACK, "Accept": MSGPACK}
    status, ctype, doc = raw(server, "POST", path, b"\xc1\xc1garbage", mp)
    assert status == 400 and ctype == "application/problem+msgpack"
    assert doc["type"] == "urn:lightsched:problem:malformed" and doc["status"] == 400
    status, ctype, doc = raw(server, "POST", path, b"{not json", {"Content-Type": JSON})
    assert status == 400 and ctype == "application/problem+json"
    cam = camera_doc(SCENE.cameras[0])
    for body, field in [({"cameras": [cam], "dt": "fast"}, "dt"),
                        ({"cameras": [cam], "cut": 1}, "cut"),
                        ({"cameras": []}, "cameras"),
                        ({"cameras": [cam], "bogus": 1}, "bogus"),
                        ({"cameras": [cam], "changes": [{"op": "explode", "fields": {}}]},
                         "changes.op"),
                        ({"cameras": [cam], "dt": -1.0}, "dt"),
                        ([1, 2, 3], None)]:
        status, _, doc = raw(server, "POST", path, dumps(body, MSGPACK), mp)
        assert status == 422, (body, doc)
        assert doc.get("field") == field, (body, doc)
    bad_array = {"cameras": [cam], "changes": [{"op": "set_lights", "fields": {
        "id": {"dtype": "int32", "shape": [3], "data": b"\x00" * 5}}}]}
    status, _, doc = raw(server, "POST", path, dumps(bad_array, MSGPACK), mp)
    assert status == 400 and doc["pointer"] == "/changes/0/fields/id/data"
    status, _, doc = raw(server, "POST", path, b"hello", {"Content-Type": "text/plain"})
    assert status == 415
    status, _, doc = raw(server, "GET", path, headers={"Accept": JSON})
    assert status == 405 and doc["status"] == 405
    status, _, doc = raw(server, "GET", "/v1/nowhere", headers={"Accept": JSON})
    assert status == 404 and doc["type"] == "urn:lightsched:problem:not-found"
    with Client(server.url) as c:
        assert c.call("GET", f"/v1/sessions/{sid}")["frame_index"] == 0


def test_frame_route_outside_fastapi_keeps_its_behaviour(server):
    """POST .../frames and the stream skip FastAPI's stack (lightsched_server.app.App): the
    answer's headers, the request metrics and the routes FastAPI still serves on the same
    paths are as before."""
    sid = session_id(server)
    path = f"/v1/sessions/{sid}/frames"
    conn = http.client.HTTPConnection("127.0.0.1", server.port, timeout=30)
    conn.request("POST", path, body=dumps({"cameras": [camera_doc(SCENE.cameras[0])]}, MSGPACK),
                 headers={"Content-Type": MSGPACK, "Accept": MSGPACK})
    r = conn.getresponse()
    data = r.read()
    conn.close()
    names = [k.lower() for k, _ in r.getheaders()]
    assert r.status == 200 and r.getheader("content-type") == MSGPACK
    assert names[-3:] == ["content-length", "content-type", "server-timing"]
    assert int(r.getheader("content-length")) == len(data)
    assert [p.split(";")[0] for p in r.getheader("server-timing").split(", ")] == \
        ["decode", "frame", "encode"]
    status, ctype, doc = raw(server, "POST", "/v1/sessions/nope/frames",
                             dumps({"cameras": []}, MSGPACK), {"Content-Type": MSGPACK})
    assert (status, ctype, doc["instance"]) == (404, "application/problem+msgpack",
                                                "/v1/sessions/nope/frames")
    text = raw(server, "GET", "/metrics")[2]
    assert 'lightsched_requests_total{route="/v1/sessions/{sid}/frames",status="200"}' in text
    assert 'lightsched_requests_total{route="/v1/sessions/{sid}/frames",status="404"}' in text
    # Other methods and near-miss paths are FastAPI's, as before.
    assert raw(server, "PUT", path, headers={"Accept": JSON})[0] == 405
    assert raw(server, "POST", f"/v1/sessions/{sid}/frames/x", b"", {"Accept": JSON})[0] == 404


def test_unknown_session_is_404(server):
    with Client(server.url) as c:
        for method in ("GET", "DELETE"):
            with pytest.raises(RemoteError) as e:
                c.call(method, "/v1/sessions/nope")
            assert e.value.status == 404
        with pytest.raises(RemoteError) as e:
            c.call("POST", "/v1/sessions/nope/frames", {"cameras": [camera_doc(SCENE.cameras[0])]})
        assert e.value.status == 404
    from websockets.sync.client import connect
    with connect(server.url.replace("http", "ws") + "/v1/sessions/nope/stream") as ws:
        doc = loads(ws.recv(), MSGPACK)
    assert doc["status"] == 404


def test_oversize_bodies_are_413(limited):
    with Client(limited.url) as c:
        s = c.session(CONFIG)
        s.set_objects(id=np.arange(5_000), bounds_min=np.zeros((5_000, 3)),
                      bounds_max=np.ones((5_000, 3)))
        with pytest.raises(RemoteError) as e:
            s.frame(SCENE.cameras)
        assert e.value.status == 413 and e.value.problem["type"].endswith("too-large")
        assert s.info()["objects"] == 0
        ws = c.session(CONFIG, stream=True)
        ws.set_objects(id=np.arange(5_000), bounds_min=np.zeros((5_000, 3)),
                       bounds_max=np.ones((5_000, 3)))
        with pytest.raises(RemoteError) as e:
            ws.frame(SCENE.cameras)
        # ~0.3 MB: over the 0.2 MB limit, under twice it (where the WebSocket layer would
        # close the stream): a 413 problem document, and the stream goes on.
        assert e.value.status == 413 and e.value.problem["type"].endswith("too-large")
        assert ws.frame(SCENE.cameras).object_id.size == 0  # the refused changes were dropped


def test_scene_over_session_limits_is_413_and_changes_nothing(limited):
    with Client(limited.url) as c:
        s = c.session(CONFIG)
        s.set_lights(**{k: v[:30] for k, v in SCENE.lights.items()})
        s.frame(SCENE.cameras)
        s.set_lights(**SCENE.lights)  # 40 lights > 60? no: add objects over the limit
        s.set_objects(id=np.arange(401), bounds_min=np.zeros((401, 3)), bounds_max=np.ones((401, 3)))
        with pytest.raises(RemoteError) as e:
            s.frame(SCENE.cameras)
        assert e.value.status == 413 and e.value.problem["field"] == "objects"
        info = s.info()
        assert (info["lights"], info["objects"], info["frame_index"]) == (30, 0, 1)


def session_state(sched):
    """Copies of everything a frame request may change in a session's scheduler: the
    stores, the per-object (fade) state, the config and the frame index."""
    return {"lights": {f: getattr(sched.lights, f).copy() for f in LIGHT_FIELDS},
            "objects": {f: getattr(sched.objects, f).copy() for f in OBJECT_FIELDS},
            "is_new": sched.objects.is_new.copy(),
            "state": {name: arr.copy() for name, (arr, _) in sched.objects.state.items()},
            "config": sched.config, "frame_index": sched.frame_index}


def assert_same_state(a, b):
    assert a.keys() == b.keys()
    for key in a:
        if isinstance(a[key], dict):
            assert a[key].keys() == b[key].keys(), key
            for name in a[key]:
                x, y = a[key][name], b[key][name]
                assert x.dtype == y.dtype and np.array_equal(x, y), (key, name)
        elif isinstance(a[key], np.ndarray):
            assert np.array_equal(a[key], b[key]), key
        else:
            assert a[key] == b[key], key


@pytest.mark.parametrize("stream", [False, True], ids=["http", "websocket"])
@pytest.mark.parametrize("fault", ["frame raises", "after the object pass"])
def test_frame_that_fails_changes_nothing(server, monkeypatch, fault, stream):
    """The changes of a request are applied, then its frame fails: a 500 problem document,
    and the session is as before the request (scene, fade state, config, frame index, the
    previous frame changed_only compares with), so its next frames equal those of an
    embedded scheduler that never saw the request. "after the object pass" fails once the
    frame has written the fade state in place (at ObjectStore.put, which comes next)."""
    twin = ls.Scheduler(CONFIG)
    with Client(server.url) as c:
        s = c.session(CONFIG, stream=stream)
        for sched in (s, twin):
            sched.set_lights(**SCENE.lights)
            sched.set_objects(**SCENE.objects)
        for i in range(1, 4):  # moving lights: slots fade in and out
            for sched in (s, twin):
                sched.update_lights(id=SCENE.lights["id"], position=move_lights(SCENE.lights, i))
            assert_same_frame(s.frame(SCENE.cameras, dt=0.05), twin.frame(SCENE.cameras, dt=0.05),
                              f"frame {i}")
        session = server.service.sessions[s.id]
        sched = session.scheduler
        before, prev = session_state(sched), session.prev
        wrote = []
        if fault == "frame raises":
            def broken_frame(*args, **kwargs):
                raise RuntimeError("injected fault")

            monkeypatch.setattr(sched, "frame", broken_frame)
        else:
            put = ObjectStore.put

            def broken_put(store, name, value):
                monkeypatch.setattr(ObjectStore, "put", put)  # once
                weight = store.get("slot_weight")
                assert weight.shape == before["state"]["slot_weight"].shape
                wrote.append(not np.array_equal(weight, before["state"]["slot_weight"]))
                raise RuntimeError("injected fault")

            monkeypatch.setattr(ObjectStore, "put", broken_put)
        # Updates only: the objects keep their rows, so the frame writes the very state
        # arrays the session held (a set_ or remove_ would make new ones).
        s.update_lights(id=SCENE.lights["id"], position=move_lights(SCENE.lights, 9))
        s.update_objects(id=SCENE.objects["id"][:5], bounds_max=SCENE.objects["bounds_max"][:5] + 2)
        with pytest.raises(RemoteError) as e:
            s.frame([MOVED], dt=0.05, changed_only=True)
        assert e.value.status == 500 and e.value.problem["type"].endswith(":internal")
        monkeypatch.undo()
        assert wrote == ([] if fault == "frame raises" else [True])
        assert server.service.sessions[s.id] is session and session.scheduler is sched
        assert_same_state(session_state(sched), before)
        assert session.prev is prev
        # The session goes on as the twin that never saw the failed request; changed_only
        # answers (rows changed since session.prev) rebuild its frames.
        for i in range(4, 6):
            for x in (s, twin):
                x.update_lights(id=SCENE.lights["id"], position=move_lights(SCENE.lights, i))
            got, want = s.frame(SCENE.cameras, dt=0.05, changed_only=True), \
                twin.frame(SCENE.cameras, dt=0.05)
            for name in FRAME_ARRAYS:
                if name != "priority":  # not part of "changed"
                    assert np.array_equal(getattr(got, name), getattr(want, name)), (i, name)
        assert s.info()["frame_index"] == 5
        s.close()


def test_session_count_and_idle_ttl():
    srv = LiveServer(Settings(max_sessions=2, session_ttl=0.5))
    try:
        with Client(srv.url) as c:
            a, b = c.session(), c.session()
            with pytest.raises(RemoteError) as e:
                c.session()
            assert e.value.status == 429 and e.value.problem["type"].endswith("too-many-sessions")
            b.close()
            c.session()  # room again
            time.sleep(0.8)
            with pytest.raises(RemoteError) as e:
                a.info()
            assert e.value.status == 404  # dropped when idle too long
    finally:
        srv.stop()


def test_api_keys_guard_and_separate_sessions():
    srv = LiveServer(Settings(api_keys=frozenset({"key-one", "key-two"})))
    try:
        status, _, doc = raw(srv, "POST", "/v1/sessions", b"", {"Accept": JSON})
        assert status == 401 and doc["type"].endswith("unauthorized")
        with Client(srv.url, api_key="wrong") as c, pytest.raises(RemoteError) as e:
            c.session()
        assert e.value.status == 401
        with Client(srv.url, api_key="key-one") as one, Client(srv.url, api_key="key-two") as two:
            s = one.session(CONFIG)
            ids = {s.id, one.session().id, one.session().id}
            assert len(ids) == 3 and all(len(i) >= 32 for i in ids)  # 192 random bits each
            for method, path, doc in (("GET", f"/v1/sessions/{s.id}", None),
                                      ("DELETE", f"/v1/sessions/{s.id}", None),
                                      ("POST", f"/v1/sessions/{s.id}/frames",
                                       {"cameras": [camera_doc(SCENE.cameras[0])]})):
                with pytest.raises(RemoteError) as e:
                    two.call(method, path, doc)
                assert e.value.status == 404  # invisible, not forbidden
            s.set_lights(**SCENE.lights)
            s.set_objects(**SCENE.objects)
            assert s.frame(SCENE.cameras).frame_index == 0
            stream = one.session(CONFIG, stream=True)
            stream.set_objects(**SCENE.objects)
            assert stream.frame(SCENE.cameras).object_id.size == len(SCENE.objects["id"])
        assert raw(srv, "GET", "/healthz")[0] == 200  # health and metrics need no key
    finally:
        srv.stop()


def test_concurrent_frames_on_one_session_run_in_order(server, limited, monkeypatch):
    cam = camera_doc(SCENE.cameras[0])

    async def burst(url, n, pending_ok):
        async with AsyncClient(url) as c:
            s = await c.session(CONFIG)
            s.set_lights(**SCENE.lights)
            s.set_objects(**SCENE.objects)
            await s.frame(SCENE.cameras)
            path = f"/v1/sessions/{s.id}/frames"

            async def one():
                try:
                    return await c.call("POST", path, {"cameras": [cam], "dt": 0.02})
                except RemoteError as e:
                    return e

            results = await asyncio.gather(*[one() for _ in range(n)])
            info = await c.call("GET", f"/v1/sessions/{s.id}")
            return results, info

    results, info = asyncio.run(burst(server.url, 6, True))
    assert sorted(r["frame_index"] for r in results) == list(range(1, 7))
    assert info["frame_index"] == 7
    # Same frames as six sequential ones on an embedded twin.
    twin = ls.Scheduler(CONFIG)
    twin.set_lights(**SCENE.lights)
    twin.set_objects(**SCENE.objects)
    twin.frame(SCENE.cameras)
    want = [twin.frame([SCENE.cameras[0]], dt=0.02) for _ in range(6)]
    for r in results:
        assert np.array_equal(r["fade_weight"], want[r["frame_index"] - 1].fade_weight)
    # With at most 2 waiting, a burst of 12 gets some 429s, never a 5xx, and the session
    # counts exactly the frames it answered. Each frame takes 0.1 s more (in its worker
    # thread: small_scene=0), so the burst queues up however fast the core and the routes are.
    run_frame = limited.service._run_frame

    def slow_frame(*args):
        time.sleep(0.1)
        return run_frame(*args)

    monkeypatch.setattr(limited.service, "_run_frame", slow_frame)
    results, info = asyncio.run(burst(limited.url, 12, False))
    ok = [r for r in results if isinstance(r, dict)]
    refused = [r for r in results if isinstance(r, RemoteError)]
    assert refused and all(r.status == 429 for r in refused)
    assert info["frame_index"] == 1 + len(ok)


def test_never_a_500_on_garbage(server):
    rng = np.random.default_rng(7)
    sid = session_id(server)
    bodies = [rng.bytes(int(n)) for n in rng.integers(0, 300, 40)]
    bodies += [msgpack.packb(x) for x in ({"cameras": "x"}, {"changes": [1]}, [None], 3, "s",
                                          {"cameras": [{"position": {"dtype": "float64",
                                                                     "shape": [-1], "data": b""}}]},
                                          {"cameras": [{"position": [1, 2, 3]}]})]
    for body in bodies:
        for ctype in (MSGPACK, JSON):
            for path in (f"/v1/sessions/{sid}/frames", "/v1/schedule", "/v1/sessions"):
                status, _, _ = raw(server, "POST", path, body, {"Content-Type": ctype})
                assert 400 <= status < 500 or status in (200, 201), (path, body[:40], status)


def test_health_metrics_and_docs(server):
    assert raw(server, "GET", "/healthz", headers={"Accept": JSON})[2]["status"] == "ok"
    with Client(server.url) as c:
        c.schedule(SCENE.lights, SCENE.objects, SCENE.cameras)
    status, ctype, text = raw(server, "GET", "/metrics")
    assert status == 200 and ctype.startswith("text/plain")
    assert "lightsched_frames_total" in text and 'lightsched_stage_seconds_bucket{stage="pairs"' in text
    assert 'lightsched_requests_total{route="/v1/schedule",status="200"}' in text
    status, _, html = raw(server, "GET", "/docs")
    assert status == 200 and "swagger" in html.lower()
    spec = raw(server, "GET", "/openapi.json")[2]
    assert "/v1/sessions/{sid}/frames" in spec["paths"] and "FrameRequest" in spec["components"]["schemas"]


def test_settings_from_environment_and_key_file(tmp_path, monkeypatch):
    keys = tmp_path / "keys"
    keys.write_text("# service keys\nalpha\n\nbeta  # the second\n")
    monkeypatch.setenv("LIGHTSCHED_API_KEYS", "gamma, delta")
    monkeypatch.setenv("LIGHTSCHED_API_KEYS_FILE", str(keys))
    monkeypatch.setenv("LIGHTSCHED_MAX_SESSIONS", "3")
    monkeypatch.setenv("LIGHTSCHED_SESSION_TTL", "2.5")
    monkeypatch.setenv("LIGHTSCHED_CORS_ORIGINS", "http://a.example:8080/, https://b.example")
    monkeypatch.setenv("LIGHTSCHED_TICKET_TTL", "12")
    s = Settings.from_env()
    assert s.cors_origins == ("http://a.example:8080", "https://b.example")
    assert s.ticket_ttl == 12.0 and Settings().cors_origins == ()
    assert s.api_keys == frozenset({"alpha", "beta", "gamma", "delta"})
    assert (s.max_sessions, s.session_ttl, s.max_body_bytes) == (3, 2.5, Settings().max_body_bytes)


def test_sessions_run_side_by_side_on_worker_threads():
    """Frames of different sessions overlap on the thread pool (small_scene=0 sends every
    frame there) and each still equals its embedded twin."""
    srv = LiveServer(Settings(small_scene=0))
    scenes = [city(800, 80, seed=s) for s in (11, 12, 13)]

    async def run():
        async with AsyncClient(srv.url) as c:
            sessions = []
            for sc in scenes:
                s = await c.session(CONFIG)
                s.set_lights(**sc.lights)
                s.set_objects(**sc.objects)
                sessions.append(s)
            out = []
            for i in range(3):
                for s, sc in zip(sessions, scenes, strict=True):
                    s.update_lights(id=sc.lights["id"], position=move_lights(sc.lights, i))
                out.append(await asyncio.gather(*[s.frame(sc.cameras, dt=0.05)
                                                  for s, sc in zip(sessions, scenes, strict=True)]))
            return out

    try:
        got = asyncio.run(run())
    finally:
        srv.stop()
    for k, sc in enumerate(scenes):
        twin = ls.Scheduler(CONFIG)
        twin.set_lights(**sc.lights)
        twin.set_objects(**sc.objects)
        for i in range(3):
            twin.update_lights(id=sc.lights["id"], position=move_lights(sc.lights, i))
            assert_same_frame(got[i][k], twin.frame(sc.cameras, dt=0.05), f"session {k} frame {i}")
