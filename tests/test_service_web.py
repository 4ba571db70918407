"""The service as a web page and a new client author meet it, over real sockets: CORS
preflights and answers, stream tickets for browsers (which cannot send a key on a
WebSocket) and the Origin check on streams, Accept with q-values, Server-Timing on every
computing route, the stream's size limit answered with a problem document, and array maps
with extra keys refused as malformed."""

from __future__ import annotations

import http.client
import time

import numpy as np
import pytest
from lightsched_client import Client
from lightsched_client.client import camera_doc
from lightsched_client.wire import JSON, MSGPACK, dumps, loads
from lightsched_server import Settings
from lightsched_server.app import negotiate
from live import LiveServer
from websockets.exceptions import ConnectionClosed
from websockets.sync.client import connect

import lightsched as ls
from lightsched.scenes import city

SCENE = city(200, 20, seed=3, shadow_fraction=0.2)
CONFIG = ls.Config(max_lights=4)
PAGE = "http://viewer.example:8080"
KEY = "page-key"


@pytest.fixture(scope="module")
def web():
    """Keys on, one allowed page origin, short tickets, a small body limit."""
    s = LiveServer(Settings(api_keys=frozenset({KEY}), cors_origins=(PAGE,), ticket_ttl=0.5,
                            max_body_bytes=100_000))
    yield s
    s.stop()


@pytest.fixture(scope="module")
def plain():
    """The defaults: no CORS, no keys."""
    s = LiveServer()
    yield s
    s.stop()


def request(server, method, path, body=b"", headers=None):
    """One raw request: (status, headers with lower-case names, body bytes)."""
    conn = http.client.HTTPConnection("127.0.0.1", server.port, timeout=30)
    conn.request(method, path, body=body, headers=headers or {})
    r = conn.getresponse()
    data = r.read()
    conn.close()
    return r.status, {k.lower(): v for k, v in r.getheaders()}, data


def session(server, key=None):
    with Client(server.url, api_key=key) as c:
        s = c.session(CONFIG)
        s.set_lights(**SCENE.lights)
        s.set_objects(**SCENE.objects)
        s.frame(SCENE.cameras)  # sends the scene
        return s.id


def frame_body():
    return dumps({"cameras": [camera_doc(c) for c in SCENE.cameras], "stats": False}, MSGPACK)


def ws_url(server, sid, query=""):
    return f"ws://127.0.0.1:{server.port}/v1/sessions/{sid}/stream{query}"


def test_cors_preflight_and_answers(web, plain):
    """A page of an allowed origin gets through the preflight and can read the answers and
    the headers it needs; other origins, and every origin by default, get no CORS grant."""
    sid = session(web, KEY)
    path = f"/v1/sessions/{sid}/frames"
    pre = {"Origin": PAGE, "Access-Control-Request-Method": "POST",
           "Access-Control-Request-Headers": "authorization, content-type"}
    status, h, _ = request(web, "OPTIONS", path, headers=pre)
    assert status == 200 and h["access-control-allow-origin"] == PAGE
    assert {"POST", "GET", "DELETE"} <= set(h["access-control-allow-methods"].split(", "))
    assert "authorization" in h["access-control-allow-headers"].lower()
    status, h, _ = request(web, "OPTIONS", path, headers={**pre, "Origin": "http://evil.example"})
    assert status == 400 and "access-control-allow-origin" not in h
    # The frame itself (the hot route) and another route, from the page.
    auth = {"Authorization": f"Bearer {KEY}", "Content-Type": MSGPACK, "Accept": MSGPACK}
    for p, body in ((path, frame_body()), ("/v1/sessions", b"")):
        status, h, data = request(web, "POST", p, body, {**auth, "Origin": PAGE})
        assert status in (200, 201) and h["access-control-allow-origin"] == PAGE
        exposed = h["access-control-expose-headers"].lower()
        assert "server-timing" in exposed and "location" in exposed
    status, h, data = request(web, "POST", path, frame_body(), auth)  # no Origin: no CORS
    assert status == 200 and "access-control-allow-origin" not in h
    assert loads(data, MSGPACK)["frame_index"] >= 1
    # A refusal reaches the page too (it must read the problem document).
    status, h, data = request(web, "POST", path, b"\xc1", {**auth, "Origin": PAGE})
    assert status == 400 and h["access-control-allow-origin"] == PAGE
    # Off by default.
    status, h, _ = request(plain, "OPTIONS", "/v1/sessions", headers=pre)
    assert status == 405 and "access-control-allow-origin" not in h


def test_stream_ticket_opens_the_stream_once(web):
    """POST .../tickets with the key gives a ticket that opens the stream without it: once,
    for that session only, until it expires. Every refusal is a problem message and a
    close with 1008, and the frames through a ticket equal those through the key."""
    sid = session(web, KEY)
    other = session(web, KEY)
    auth = {"Authorization": f"Bearer {KEY}", "Accept": JSON}
    status, _, _ = request(web, "POST", f"/v1/sessions/{sid}/tickets", headers={"Accept": JSON})
    assert status == 401
    status, h, data = request(web, "POST", f"/v1/sessions/{sid}/tickets", headers=auth)
    assert status == 201 and h["content-type"] == JSON
    doc = loads(data, JSON)
    assert doc["expires_in"] == 0.5 and len(doc["ticket"]) >= 32
    ticket = doc["ticket"]

    with connect(ws_url(web, sid, f"?ticket={ticket}"), origin=PAGE) as ws:
        ws.send(frame_body())
        got = loads(ws.recv(), MSGPACK)
    with connect(ws_url(web, sid), additional_headers={"Authorization": f"Bearer {KEY}"}) as ws:
        ws.send(frame_body())
        want = loads(ws.recv(), MSGPACK)
    assert got["frame_index"] + 1 == want["frame_index"]
    for name in ("light_ids", "fade_weight", "slot_shadow"):
        assert np.array_equal(got[name], want[name])

    def refused(url, **kw):
        with connect(url, **kw) as ws:
            problem = loads(ws.recv(), MSGPACK)
            with pytest.raises(ConnectionClosed) as e:
                ws.recv()
        assert e.value.rcvd.code == 1008
        return problem

    assert refused(ws_url(web, sid, f"?ticket={ticket}"))["status"] == 401  # used
    assert refused(ws_url(web, sid, "?ticket=made-up"))["status"] == 401
    other_ticket = loads(request(web, "POST", f"/v1/sessions/{other}/tickets",
                                 headers=auth)[2], JSON)["ticket"]
    assert refused(ws_url(web, sid, f"?ticket={other_ticket}"))["status"] == 401
    late = loads(request(web, "POST", f"/v1/sessions/{sid}/tickets", headers=auth)[2],
                 JSON)["ticket"]
    time.sleep(0.6)
    assert refused(ws_url(web, sid, f"?ticket={late}"))["status"] == 401  # expired
    assert refused(ws_url(web, sid))["status"] == 401  # neither key nor ticket
    # Unused tickets are bounded per session.
    codes = [request(web, "POST", f"/v1/sessions/{sid}/tickets", headers=auth)[0]
             for _ in range(Settings().max_pending_frames + 9)]
    assert codes[-1] == 429 and set(codes[:-1]) == {201}


def test_stream_origin_check(web, plain):
    """Pages of other sites may not open streams (browsers apply no same-origin policy to
    WebSockets); the service's own origin and the allowed ones may, and programs send no
    Origin."""
    plain_sid, web_sid = session(plain), session(web, KEY)
    auth = {"Authorization": f"Bearer {KEY}"}
    with connect(ws_url(plain, plain_sid), origin=f"http://127.0.0.1:{plain.port}") as ws:
        ws.send(frame_body())
        assert "frame_index" in loads(ws.recv(), MSGPACK)
    for server, sid, headers in ((plain, plain_sid, None), (web, web_sid, auth)):
        with connect(ws_url(server, sid), origin="http://evil.example",
                     additional_headers=headers) as ws:
            problem = loads(ws.recv(), MSGPACK)
            with pytest.raises(ConnectionClosed) as e:
                ws.recv()
        assert problem["status"] == 403 and problem["type"].endswith("forbidden-origin")
        assert e.value.rcvd.code == 1008
    with connect(ws_url(web, web_sid), origin=PAGE, additional_headers=auth) as ws:
        ws.send(frame_body())
        assert "frame_index" in loads(ws.recv(), MSGPACK)


@pytest.mark.parametrize("accept, sent, want", [
    (None, MSGPACK, MSGPACK),
    (None, JSON, JSON),
    ("application/msgpack;q=0.5, application/json", MSGPACK, JSON),
    ("application/json;q=0.1, application/msgpack;q=0.9", JSON, MSGPACK),
    ("application/json;q=0, */*", JSON, MSGPACK),
    ("*/*", MSGPACK, MSGPACK),
    ("application/*;q=0.3, application/json;q=0.2", JSON, MSGPACK),
    ("application/msgpack, application/json", JSON, MSGPACK),
    ("text/html", MSGPACK, MSGPACK),
    ("application/msgpack;q=0", MSGPACK, JSON),
])
def test_accept_q_values(plain, accept, sent, want):
    assert negotiate(accept, sent) == want
    body = dumps({}, sent)
    headers = {"Content-Type": sent, **({"Accept": accept} if accept else {})}
    status, h, data = request(plain, "POST", "/v1/sessions", body, headers)
    assert status == 201 and h["content-type"] == want
    assert len(loads(data, want)["id"]) >= 32
    status, h, _ = request(plain, "POST", f"/v1/sessions/{loads(data, want)['id']}/frames",
                           frame_body() if sent == MSGPACK else b"{}", headers)
    assert h["content-type"] in (want, want.replace("/", "/problem+"))


def test_server_timing_on_schedule_and_frames(plain):
    sid = session(plain)
    body = dumps({"lights": {k: v for k, v in SCENE.lights.items()},
                  "objects": {k: v for k, v in SCENE.objects.items()},
                  "cameras": [camera_doc(c) for c in SCENE.cameras]}, MSGPACK)
    for path, b in (("/v1/schedule", body), (f"/v1/sessions/{sid}/frames", frame_body())):
        status, h, _ = request(plain, "POST", path, b, {"Content-Type": MSGPACK})
        assert status == 200
        parts = [p.split(";dur=") for p in h["server-timing"].split(", ")]
        assert [name for name, _ in parts] == ["decode", "frame", "encode"]
        assert all(float(ms) >= 0 for _, ms in parts)


def test_stream_message_over_the_limit_is_413_and_the_stream_goes_on(web):
    """One byte over max_body_bytes: read whole, answered with a 413 problem document, the
    stream stays open (a limit in the WebSocket layer would drop the connection mid-send,
    1006 at the client)."""
    sid = session(web, KEY)
    limit = 100_000
    with connect(ws_url(web, sid), additional_headers={"Authorization": f"Bearer {KEY}"},
                 max_size=None) as ws:
        for size in (limit + 1, 2 * limit):
            ws.send(b"\x00" * size)
            problem = loads(ws.recv(), MSGPACK)
            assert problem["status"] == 413 and problem["type"].endswith("too-large")
        ws.send(dumps({"cameras": [camera_doc(SCENE.cameras[0])]}, JSON).decode())
        assert "frame_index" in loads(ws.recv().encode(), JSON)  # text in, text out
    status, _, _ = request(web, "POST", f"/v1/sessions/{sid}/frames", b"\x00" * (limit + 1),
                           {"Content-Type": MSGPACK, "Authorization": f"Bearer {KEY}"})
    assert status == 413


@pytest.mark.parametrize("array", [
    {"dtype": "int32", "shape": [1], "data": b"\x01\x00\x00\x00", "extra": 1},
    {"dtype": "int32", "shape": [1]},
    {"dtype": "int32", "data": b"\x01\x00\x00\x00"},
])
@pytest.mark.parametrize("kind", [MSGPACK, JSON])
def test_array_map_with_wrong_keys_is_malformed(plain, array, kind):
    sid = session(plain)
    if kind == JSON and "data" in array:
        array = {**array, "data": "AQAAAA=="}
    doc = {"cameras": [camera_doc(SCENE.cameras[0])],
           "changes": [{"op": "remove_lights", "fields": {"id": array}}]}
    body = dumps(doc, kind)
    status, _, data = request(plain, "POST", f"/v1/sessions/{sid}/frames", body,
                              {"Content-Type": kind, "Accept": JSON})
    problem = loads(data, JSON)
    assert status == 400 and problem["type"].endswith("malformed"), problem
    assert problem["pointer"] == "/changes/0/fields/id"
    with Client(plain.url) as c:
        assert c.call("GET", f"/v1/sessions/{sid}")["lights"] == len(SCENE.lights["id"])


def test_explain_over_http_names_object_id_when_refused(plain):
    with Client(plain.url) as c:
        s = c.session(CONFIG)
        path = f"/v1/sessions/{s.id}/objects/{int(SCENE.objects['id'][0])}/explain"
        status, _, body = request(plain, "GET", path, headers={"Accept": JSON})
        assert status == 422 and loads(body, JSON)["field"] == "object_id"  # no frame yet
        s.set_lights(**SCENE.lights)
        s.set_objects(**SCENE.objects)
        s.frame(SCENE.cameras)
        status, _, body = request(plain, "GET", path, headers={"Accept": JSON})
        doc = loads(body, JSON)
        assert status == 200 and doc["frame_index"] == 0 and len(doc["reason"]) > 0
        for bad in ("abc", "1.5", "99999999999999999999"):
            status, _, body = request(plain, "GET", path.replace(
                f"/{int(SCENE.objects['id'][0])}/", f"/{bad}/"), headers={"Accept": JSON})
            assert status == 422 and loads(body, JSON)["field"] == "object_id", (bad, body)
        status, _, _ = request(plain, "GET", "/v1/sessions/nope/objects/1/explain")
        assert status == 404
        s.close()
