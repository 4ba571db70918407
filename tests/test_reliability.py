"""Reliability of one worker (a real ``lightsched serve`` process, or LiveServer) under
generated traffic and many sessions, on 127.0.0.1 only.

- Fuzzing: schemathesis draws requests from the service's own /openapi.json, valid and
  invalid ones, in JSON and msgpack, on every HTTP operation; some go to sessions that hold
  a scene. At least FUZZ_REQUESTS requests, never a 5xx, and afterwards every such session
  still answers like an embedded twin given the requests it accepted.
- 1,000 sessions of a small scene: the memory each costs, the session limit held, and the
  idle TTL freeing them.
"""

from __future__ import annotations

import os
import time

import msgpack
import numpy as np
import psutil
import pytest
import requests
import schemathesis
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from lightsched_client import Client
from lightsched_client.wire import JSON, MSGPACK, loads, media_type
from lightsched_server.cluster import Cluster
from schemathesis.generation import GenerationMode
from test_cluster import compile_for
from test_service import assert_same_frame

import lightsched as ls
from lightsched.scene import validate_cameras
from lightsched.scenes import city

SCENE = city(120, 16, seed=11, shadow_fraction=0.2)
CONFIG = ls.Config(max_lights=4, shadow_budget=2)
# At least this many generated requests in all (10,000: issue 54); LIGHTSCHED_FUZZ scales
# it for a longer run.
FUZZ_REQUESTS = int(os.environ.get("LIGHTSCHED_FUZZ", "10000"))


def _packable(value: object) -> object:
    """msgpack has no integers past 64 bits: those go as floats (a JSON body keeps them)."""
    if isinstance(value, dict):
        return {k: _packable(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_packable(v) for v in value]
    if isinstance(value, int) and not isinstance(value, bool) and not -2**63 <= value < 2**64:
        return float(value)
    return value


@schemathesis.serializer("application/msgpack")
def _msgpack(ctx: object, value: object) -> bytes:
    # The generated document as msgpack: arrays arrive as nested lists or as maps whose
    # data is text (JSON Schema has no bytes), both of which the service must refuse or
    # take without a 5xx.
    return msgpack.packb(_packable(value))


class Targets:
    """Sessions with a scene that the fuzzer aims some of its requests at, each with an
    embedded twin given every frame request the service answered with a new frame."""

    def __init__(self, url: str, n: int) -> None:
        self.twins: dict[str, ls.Scheduler] = {}
        with Client(url) as c:
            for i in range(n):
                s = c.session(CONFIG, id=f"fuzz-target-{i}")
                twin = ls.Scheduler(CONFIG)
                for target in (s, twin):
                    target.set_lights(**SCENE.lights)
                    target.set_objects(**SCENE.objects)
                s.frame(SCENE.cameras)
                twin.frame(SCENE.cameras)
                self.twins[s.id] = twin
        self.accepted = 0

    def follow(self, sid: str, response: requests.Response) -> None:
        """A frame request the service answered for a target: the twin takes it too."""
        answer = loads(response.content, media_type(response.headers["content-type"]))
        twin = self.twins[sid]
        if answer["frame_index"] != twin.frame_index:
            return  # a repeated seq: the answer of a frame both have run
        req = response.request
        doc = loads(req.body, media_type(req.headers["content-type"]))
        twin.apply([(c["op"], c["fields"]) for c in doc.get("changes", [])])
        twin.frame(validate_cameras(doc["cameras"]), dt=doc.get("dt", 1 / 60),
                   cut=doc.get("cut", False))
        self.accepted += 1

    def check(self, url: str) -> None:
        """Each target, moved on one more frame by a client, equals its twin."""
        with Client(url) as c:
            for sid, twin in self.twins.items():
                s = c.session(CONFIG, id=sid)  # the existing session (same config)
                assert s.frame_index == twin.frame_index, sid
                ids = SCENE.lights["id"][:4]
                for target in (s, twin):
                    target.update_lights(id=ids, position=SCENE.lights["position"][:4] + 0.5)
                assert_same_frame(s.frame(SCENE.cameras), twin.frame(SCENE.cameras), sid)
                assert s.recoveries == 0


@pytest.fixture(scope="module")
def worker():
    compile_for(CONFIG, SCENE)
    # Room for the sessions the fuzzer makes, so that its later requests still reach
    # session code rather than the 429 of a full service.
    with Cluster(1, warm_up=False, env={"LIGHTSCHED_MAX_SESSIONS": "100000"}) as c:
        yield c


@pytest.mark.slow  # ~2.5 minutes on 2 cores: in `make test`, not test-quick
def test_fuzzed_requests_never_get_a_5xx_and_leave_sessions_intact(worker):
    url = worker.worker_url(0)
    schema = schemathesis.openapi.from_url(url + "/openapi.json")
    operations = [r.ok() for r in schema.get_all_operations()]
    assert {op.path for op in operations} >= {"/v1/sessions/{sid}/frames", "/v1/schedule",
                                              "/v1/sessions/{sid}"}
    targets = Targets(url, 4)
    http = requests.Session()
    sent: list[int] = []
    failures: list[str] = []

    def send(case, sid, follows):
        try:
            r = case.call(base_url=url, session=http, timeout=30)
        except requests.RequestException as e:  # a hang or a dropped connection
            failures.append(f"{case.method} {case.formatted_path}: {e!r}")
            return
        sent.append(r.status_code)
        if r.status_code >= 500:
            failures.append(f"{case.method} {case.formatted_path}: {r.status_code} "
                            f"{r.text[:300]}")
        elif sid is not None and r.status_code == 200 and follows:
            targets.follow(sid, r)

    # Each generated request goes out as drawn, then (with a body) in the other encoding,
    # then (on a session's path, but DELETE, which would end the target for good) to a
    # target session: generating costs more than sending.
    def sends(op):
        body = op.body and len(op.body) > 0
        aims = "{sid}" in op.path and op.method.upper() != "DELETE"
        return 1 + bool(body) + bool(aims)

    varied = [op for op in operations if op.path_parameters or op.body or op.query]
    per_op = -(-FUZZ_REQUESTS // sum(sends(op) for op in varied))
    def fuzz(op):
        cases = st.one_of(op.as_strategy(GenerationMode.POSITIVE),
                          op.as_strategy(GenerationMode.NEGATIVE))
        aims = "{sid}" in op.path and op.method.upper() != "DELETE"
        follows = op.method.upper() == "POST" and op.path.endswith("/frames")

        @settings(max_examples=per_op, deadline=None, database=None, derandomize=True,
                  suppress_health_check=list(HealthCheck))
        @given(case=cases, target=st.sampled_from(sorted(targets.twins)))
        def run(case, target):
            send(case, None, False)
            if case.media_type in (MSGPACK, JSON):
                case.media_type = JSON if case.media_type == MSGPACK else MSGPACK
                send(case, None, False)
            if aims:
                case.path_parameters = {**(case.path_parameters or {}), "sid": target}
                send(case, target, follows)

        run()

    for op in operations:
        fuzz(op)
    assert not failures, failures[:5]
    assert len(sent) >= FUZZ_REQUESTS, len(sent)
    counts = {int(k): int(v) for k, v in zip(*np.unique(sent, return_counts=True), strict=True)}
    print(f"\n{len(sent)} requests, by status {counts}; {targets.accepted} frames of "
          "target sessions accepted (their twins took them too)")
    targets.check(url)
    # The worker is still the same process, answering.
    assert worker.workers[0].poll() is None
    assert requests.get(url + "/healthz", timeout=5).status_code == 200


@pytest.mark.slow  # ~25 s, most of it the TTL running out
def test_a_thousand_sessions_fit_their_limits_and_the_ttl_frees_them():
    n, ttl = 1000, 12.0  # the TTL outlasts making them (~5 s here)
    small = city(40, 6, seed=2)
    compile_for(CONFIG, small)
    env = {"LIGHTSCHED_MAX_SESSIONS": str(n), "LIGHTSCHED_SESSION_TTL": str(ttl)}
    with Cluster(1, warm_up=False, env=env) as c, Client(c.worker_url(0)) as client:
        proc = psutil.Process(c.workers[0].pid)

        def fill() -> float:
            """n sessions, each set and stepped once; the seconds it took."""
            t = time.monotonic()
            for _ in range(n):
                s = client.session(CONFIG)
                s.set_lights(**small.lights)
                s.set_objects(**small.objects)
                s.frame(small.cameras)
            return time.monotonic() - t

        # One session first, so that the kernels and the first frame's buffers are counted
        # out of the per-session cost.
        first = client.session(CONFIG)
        first.set_lights(**small.lights)
        first.set_objects(**small.objects)
        first.frame(small.cameras)
        first.close()
        base = proc.memory_info().rss
        took = fill()
        full = proc.memory_info().rss
        per_session = (full - base) / n
        print(f"\n{n} sessions of {len(small.objects['id'])} objects and "
              f"{len(small.lights['id'])} lights: {per_session / 1024:.1f} KiB each "
              f"(RSS {base / 2**20:.0f} -> {full / 2**20:.0f} MiB), made in {took:.1f} s")
        assert per_session < 256 * 1024  # a small scene: well under a quarter MiB
        assert client.health()["sessions"] == n
        with pytest.raises(Exception) as e:  # the limit holds
            client.session(CONFIG)
        assert getattr(e.value, "status", None) == 429
        time.sleep(ttl + 1.5)
        assert client.health()["sessions"] == 0  # a sweep on the next request freed them
        fill()  # the freed memory is used again: no second helping
        again = proc.memory_info().rss
        assert again - base < 1.25 * (full - base) + 8 * 2**20, (base, full, again)
        assert np.isfinite(per_session)
