"""Sessions behind HAProxy: client-chosen ids, frames that are safe to retry, and sessions
that outlive their worker. Real processes on 127.0.0.1: Debian's haproxy with
deploy/haproxy.cfg in front of two ``lightsched serve`` workers (lightsched_server.cluster),
and LiveServer for the single-worker rules."""

from __future__ import annotations

import asyncio
import http.client
import os
import socket
import struct
import subprocess
import threading
import time
from pathlib import Path

import msgpack
import numpy as np
import pytest
import yaml
from lightsched_client import AsyncClient, Client
from lightsched_client.client import camera_doc
from lightsched_client.wire import MSGPACK, dumps
from lightsched_server.cluster import Cluster, haproxy_config
from live import LiveServer
from test_service import assert_same_frame, raw

import lightsched as ls
from lightsched.scenes import city, city_sequence

SCENE = city(300, 30, seed=5, shadow_fraction=0.2)
CONFIG = ls.Config(max_lights=4, shadow_budget=2)
MP = {"Content-Type": MSGPACK, "Accept": MSGPACK}
DEPLOY = Path(__file__).resolve().parent.parent / "deploy"


def compile_for(config, scene):
    """The kernels a scene runs, compiled into numba's cache by this process (or loaded
    from it), so that workers started without warm-up load them on their first frames
    instead of compiling for longer than a client waits for an answer."""
    twin = ls.Scheduler(config)
    twin.set_lights(**scene.lights)
    twin.set_objects(**scene.objects)
    twin.frame(scene.cameras)


@pytest.fixture(scope="module", autouse=True)
def compiled():
    compile_for(CONFIG, SCENE)


@pytest.fixture(scope="module")
def server():
    s = LiveServer()
    yield s
    s.stop()


def frame_doc(seq=None, changes=()):
    doc = {"cameras": [camera_doc(SCENE.cameras[0])], "changes": list(changes), "stats": False}
    if seq is not None:
        doc["seq"] = seq
    return doc


def post(server, path, doc):
    return raw(server, "POST", path, dumps(doc, MSGPACK), MP)


def post_bytes(port, path, doc):
    """(status, body bytes) of one POST on a connection of its own."""
    conn = http.client.HTTPConnection("127.0.0.1", port, timeout=30)
    conn.request("POST", path, body=dumps(doc, MSGPACK), headers=MP)
    r = conn.getresponse()
    out = r.status, r.read()
    conn.close()
    return out


def test_put_session_creates_returns_and_validates_the_id(server):
    body = dumps({"config": {"max_lights": 4}}, MSGPACK)
    status, _, info = raw(server, "PUT", "/v1/sessions/renderer-7_a", body, MP)
    assert status == 201 and info["id"] == "renderer-7_a" and info["config"]["max_lights"] == 4
    status, _, again = raw(server, "PUT", "/v1/sessions/renderer-7_a", body, MP)
    assert status == 200 and again["frame_index"] == 0  # a retried PUT: the same session
    status, _, problem = raw(server, "PUT", "/v1/sessions/renderer-7_a",
                             dumps({"config": {"max_lights": 8}}, MSGPACK), MP)
    assert status == 409 and problem["field"] == "id"
    for bad, index in (("ab.cd", 2), ("x" * 65, 64), ("%C3%A9t%C3%A9", 0)):
        status, _, problem = raw(server, "PUT", f"/v1/sessions/{bad}", body, MP)
        assert status == 422 and problem["field"] == "id" and problem["index"] == index, bad
        assert raw(server, "GET", f"/v1/sessions/{bad}")[0] == 404  # nothing made


def test_repeated_seq_gets_the_same_answer_and_applies_nothing_twice(server):
    with Client(server.url) as c:
        sid = c.session(CONFIG).id
    path = f"/v1/sessions/{sid}/frames"
    setup = [{"op": "set_lights", "fields": SCENE.lights},
             {"op": "set_objects", "fields": SCENE.objects}]
    assert post(server, path, frame_doc(0, setup))[0] == 200
    # Removing a light twice would be refused (unknown id): the repeat must not run it.
    gone = [{"op": "remove_lights", "fields": {"id": SCENE.lights["id"][:1]}}]
    first = post_bytes(server.port, path, frame_doc(1, gone))
    assert first[0] == 200 and msgpack.unpackb(first[1])["frame_index"] == 1
    for _ in range(2):  # the answer already sent, byte for byte
        assert post_bytes(server.port, path, frame_doc(1, gone)) == first
    status, _, info = raw(server, "GET", f"/v1/sessions/{sid}", headers={"Accept": MSGPACK})
    assert info["frame_index"] == 2 and info["lights"] == len(SCENE.lights["id"]) - 1
    for seq in (0, 3, 7):  # older than the last frame, or ahead of the next
        status, _, problem = post(server, path, frame_doc(seq))
        assert status == 409 and problem["field"] == "seq", seq
    assert post(server, path, frame_doc(2))[0] == 200  # the next one runs
    status, _, problem = post(server, path, frame_doc(-1))
    assert status == 422 and problem["field"] == "seq"


def test_haproxy_config_lists_each_worker_in_both_backends():
    text = haproxy_config([9001, 9002, 9003])
    assert text.count("127.0.0.1:9003 check") == 1
    assert "server w3 127.0.0.1:9003 track sessions/w3" in text
    assert "balance hash path,field(4,/)" in text and "hash-type consistent" in text


def owner(cluster, sid):
    """The worker (index) that holds the session, asked of each worker directly."""
    held = []
    for i, _ in enumerate(cluster.ports):
        if cluster.workers[i].poll() is None:
            with Client(cluster.worker_url(i), retry_seconds=0) as c:
                try:
                    c.call("GET", f"/v1/sessions/{sid}")
                    held.append(i)
                except Exception:
                    pass
    assert len(held) == 1, (sid, held)
    return held[0]


class Renderer(threading.Thread):
    """One client of the cluster with an embedded twin: moving lights, a few object
    updates and a removal, each frame checked against the twin. When the client rebuilds
    its session (recoveries goes up), the twin becomes a new Scheduler given the scene as
    it is and the frame as a cut: what the rebuilt session is."""

    def __init__(self, url, n, frames, stream):
        super().__init__(daemon=True)
        self.client = Client(url, retry_seconds=20)
        self.session = self.client.session(CONFIG, stream=stream)
        self.n, self.frames, self.stream = n, frames, stream
        self.done = 0
        self.recovered_at = []
        self.error = None

    def run(self):
        try:
            self._run()
        except BaseException as e:  # reported by the test
            self.error = e
        finally:
            self.client.close()

    def _run(self):
        lights = {k: v.copy() for k, v in SCENE.lights.items()}
        objects = {k: v.copy() for k, v in SCENE.objects.items()}
        twin = ls.Scheduler(CONFIG)
        for target in (self.session, twin):
            target.set_lights(**lights)
            target.set_objects(**objects)
        for i, upd in city_sequence(SCENE, self.frames):
            calls = []
            if upd:
                keep = np.isin(upd["id"], lights["id"])
                upd = {k: v[keep] for k, v in upd.items()}
                calls.append(("update_lights", upd))
                row = {int(x): r for r, x in enumerate(lights["id"])}
                lights["position"][[row[int(x)] for x in upd["id"]]] = upd["position"]
            if i % 7 == 3:  # a box moves
                j = (i + self.n) % len(objects["id"])
                lo, hi = objects["bounds_min"][j] + 1.0, objects["bounds_max"][j] + 1.0
                calls.append(("update_objects", {"id": objects["id"][j:j + 1],
                                                 "bounds_min": lo[None], "bounds_max": hi[None]}))
                objects["bounds_min"][j], objects["bounds_max"][j] = lo, hi
            if i == 5:  # a light goes
                calls.append(("remove_lights", {"id": lights["id"][:1]}))
                lights = {k: v[1:] for k, v in lights.items()}
            for name, fields in calls:
                getattr(self.session, name)(**fields)
                getattr(twin, name)(**fields)
            before = self.session.recoveries
            changed_only = i % 2 == 1
            remote = self.session.frame(SCENE.cameras, changed_only=changed_only)
            if self.session.recoveries != before:
                self.recovered_at.append(i)
                twin = ls.Scheduler(CONFIG)
                twin.set_lights(**lights)
                twin.set_objects(**objects)
                embedded = twin.frame(SCENE.cameras, cut=True)
            else:
                embedded = twin.frame(SCENE.cameras)
            # changed_only: rows whose priority alone changed do not travel.
            assert_same_frame(remote, embedded, f"client {self.n} frame {i}",
                              skip=("priority",) if changed_only else ())
            self.done = i + 1


def test_a_killed_worker_loses_no_client():
    with Cluster(2, warm_up=False) as cluster:
        frames = 90
        clients = [Renderer(cluster.url, n, frames, stream=n % 3 == 2) for n in range(6)]
        owners = [owner(cluster, c.session.id) for c in clients]
        if len(set(owners)) < 2:  # every id hashed to one worker: add one for the other
            while len(set(owners)) < 2:
                extra = Renderer(cluster.url, len(clients), frames, stream=False)
                clients.append(extra)
                owners.append(owner(cluster, extra.session.id))
        victim = owners[0]
        for c in clients:
            c.start()
        deadline = time.monotonic() + 300
        while min(c.done for c in clients) < 30 and time.monotonic() < deadline:
            if any(c.error for c in clients):
                break
            time.sleep(0.01)
        cluster.kill(victim)  # while every client is mid-run
        for c in clients:
            c.join(timeout=300)
        errors = [(c.n, c.error) for c in clients if c.error is not None]
        assert not errors, errors
        for c, o in zip(clients, owners, strict=True):
            assert c.done == frames
            if o == victim:
                # Rebuilt once, on the survivor, mid-run (not before the kill).
                assert len(c.recovered_at) == 1 and c.recovered_at[0] >= 30, c.recovered_at
                assert owner(cluster, c.session.id) != victim
            else:
                assert c.recovered_at == [], c.recovered_at  # never moved


def test_cluster_routes_every_request_of_a_session_to_one_worker():
    with Cluster(2, warm_up=False) as cluster, Client(cluster.url) as c:
        sessions = [c.session(CONFIG) for _ in range(12)]
        held = [owner(cluster, s.id) for s in sessions]
        assert set(held) == {0, 1}  # 12 random ids all on one of two workers: 2^-11
        for s in sessions:
            s.set_lights(**SCENE.lights)
            s.set_objects(**SCENE.objects)
            for _ in range(3):
                s.frame(SCENE.cameras)
            assert s.info()["frame_index"] == 3 and s.recoveries == 0
        # The stream (a WebSocket upgrade through HAProxy) reaches the same worker.
        ws = c.session(CONFIG, stream=True, id=sessions[0].id + "-ws")
        ws.set_lights(**SCENE.lights)
        assert ws.frame(SCENE.cameras).frame_index == 0 and ws.recoveries == 0
        ws.close()
        status = Client(cluster.url).call("GET", "/healthz")["status"]
        assert status == "ok"
        # POST /v1/sessions (the worker picks the id) cannot be routed: refused.
        conn = http.client.HTTPConnection("127.0.0.1", cluster.port, timeout=10)
        conn.request("POST", "/v1/sessions", body=b"", headers={"Accept": "application/json"})
        assert conn.getresponse().status == 405
        conn.close()


def test_deploy_files_hold_together():
    """HAProxy takes deploy/haproxy.cfg with the addresses docker-compose.yml and k8s.yaml
    give it, and those name the workers they define."""
    compose = yaml.safe_load((DEPLOY / "docker-compose.yml").read_text())
    env = compose["services"]["haproxy"]["environment"]
    workers = {k for k in compose["services"] if k.startswith("worker")}
    assert {v.split(":")[0] for k, v in env.items() if k.startswith("LIGHTSCHED_W")} == workers
    docs = list(yaml.safe_load_all((DEPLOY / "k8s.yaml").read_text()))
    kinds = {d["kind"]: d for d in docs}
    replicas = kinds["StatefulSet"]["spec"]["replicas"]
    lb_env = {e["name"]: e["value"] for e in kinds["Deployment"]["spec"]["template"]["spec"]
              ["containers"][0]["env"]}
    assert sorted(v for k, v in lb_env.items() if k.startswith("LIGHTSCHED_W")) == [
        f"lightsched-{i}.lightsched-workers:8080" for i in range(replicas)]
    for given in ({}, env, lb_env):
        # Names that do not resolve here are allowed (init-addr none): the check still
        # parses every line.
        out = subprocess.run(["haproxy", "-c", "-f", str(DEPLOY / "haproxy.cfg")],
                             env={**os.environ, **given}, capture_output=True, text=True)
        assert out.returncode == 0, out.stderr


class ResettingProxy:
    """A TCP proxy to a server that, once armed, lets the next frame request through and
    then resets the client's connection as the answer comes back: the frame ran, and the
    client never hears of it (what a dying worker or a broken network does)."""

    def __init__(self, port):
        self.upstream = port
        self.sock = socket.create_server(("127.0.0.1", 0))
        self.url = f"http://127.0.0.1:{self.sock.getsockname()[1]}"
        self.armed = False
        self.resets = 0
        threading.Thread(target=self._accept, daemon=True).start()

    def _accept(self):
        while True:
            try:
                client, _ = self.sock.accept()
            except OSError:
                return
            server = socket.create_connection(("127.0.0.1", self.upstream))
            state = {"victim": False}
            threading.Thread(target=self._up, args=(client, server, state), daemon=True).start()
            threading.Thread(target=self._down, args=(server, client, state), daemon=True).start()

    def _up(self, client, server, state):
        while data := _recv(client):
            if self.armed and b"/frames" in data:
                self.armed, state["victim"] = False, True
            server.sendall(data)
        server.close()

    def _down(self, server, client, state):
        while data := _recv(server):
            if state["victim"]:
                self.resets += 1
                client.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
                # Wakes the other thread's recv first: a socket closed while another
                # thread reads it is not closed until that read returns.
                client.shutdown(socket.SHUT_RD)
                client.close()  # RST: the answer is lost
                server.close()
                return
            client.sendall(data)
        client.close()

    def close(self):
        self.sock.close()


def _recv(sock):
    try:
        return sock.recv(1 << 16)
    except OSError:
        return b""


def test_a_frame_whose_answer_is_lost_is_sent_again_and_runs_once(server):
    proxy = ResettingProxy(server.port)
    try:
        with Client(proxy.url) as c:
            s, twin = c.session(CONFIG), ls.Scheduler(CONFIG)
            for target in (s, twin):
                target.set_lights(**SCENE.lights)
                target.set_objects(**SCENE.objects)
            assert_same_frame(s.frame(SCENE.cameras), twin.frame(SCENE.cameras), "frame 0")
            for i, upd in city_sequence(SCENE, 4):
                if not upd:
                    continue
                for target in (s, twin):
                    target.update_lights(**{k: v[:20] for k, v in upd.items()})
                    target.remove_lights(id=SCENE.lights["id"][-i:][:1])  # twice: a 422
                proxy.armed = True
                assert_same_frame(s.frame(SCENE.cameras), twin.frame(SCENE.cameras), f"frame {i}")
            assert proxy.resets == 3 and s.recoveries == 0
            assert s.info()["frame_index"] == twin.frame_index == 4  # each ran once
            # A POST without seq is not sent again: the caller hears of the reset.
            proxy.armed = True
            with pytest.raises(ConnectionError):
                c.call("POST", f"/v1/sessions/{s.id}/frames", frame_doc())
            assert proxy.resets == 4 and s.info()["frame_index"] == 5  # it ran, once
    finally:
        proxy.close()


def test_async_client_rebuilds_a_lost_session(server):
    async def run():
        async with AsyncClient(server.url) as c:
            s, twin = await c.session(CONFIG), ls.Scheduler(CONFIG)
            for target in (s, twin):
                target.set_lights(**SCENE.lights)
                target.set_objects(**SCENE.objects)
            assert_same_frame(await s.frame(SCENE.cameras), twin.frame(SCENE.cameras))
            await c.call("DELETE", f"/v1/sessions/{s.id}")  # as a dead worker loses it
            moved = {"id": SCENE.lights["id"][:3], "position": SCENE.lights["position"][:3] + 1}
            s.update_lights(**moved)
            twin.update_lights(**moved)
            fresh = ls.Scheduler(CONFIG)
            fresh.set_lights(**{**SCENE.lights, "position": twin_positions(moved)})
            fresh.set_objects(**SCENE.objects)
            f = await s.frame(SCENE.cameras)
            assert s.recoveries == 1 and f.frame_index == 0
            assert_same_frame(f, fresh.frame(SCENE.cameras, cut=True), "rebuilt")
            assert_same_frame(await s.frame(SCENE.cameras), fresh.frame(SCENE.cameras), "after")

    def twin_positions(moved):
        pos = SCENE.lights["position"].copy()
        row = {int(x): r for r, x in enumerate(SCENE.lights["id"])}
        pos[[row[int(x)] for x in moved["id"]]] = moved["position"]
        return pos

    asyncio.run(run())
