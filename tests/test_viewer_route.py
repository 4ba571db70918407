"""The service's /viewer routes without a browser: the built files, the 503 problem until
`make viewer` has run, no file outside the build, and the city the page draws."""

from __future__ import annotations

import http.client

import numpy as np
import pytest
from lightsched_client.wire import JSON, MSGPACK, loads
from lightsched_server import Settings
from lightsched_server.app import ServerThread

from lightsched.scenes import city


def get(url: str, path: str) -> tuple[int, dict[str, str], bytes]:
    host, port = url.removeprefix("http://").split(":")
    conn = http.client.HTTPConnection(host, int(port), timeout=30)
    try:
        conn.request("GET", path, headers={"Accept": JSON})
        r = conn.getresponse()
        return r.status, {k.lower(): v for k, v in r.getheaders()}, r.read()
    finally:
        conn.close()


@pytest.fixture
def serve(monkeypatch, tmp_path):
    servers = []

    def start(built: bool) -> str:
        page = tmp_path / "viewer"
        page.mkdir(exist_ok=True)
        if built:
            (page / "index.html").write_text("<!doctype html><title>viewer</title>")
            (page / "main.js").write_text("export {};")
        (tmp_path / "secret.txt").write_text("not the viewer's")
        monkeypatch.setenv("LIGHTSCHED_VIEWER_DIR", str(page))
        servers.append(ServerThread(Settings()))
        return servers[-1].url

    yield start
    for s in servers:
        s.stop()


def test_the_built_page_is_served_under_viewer(serve):
    url = serve(built=True)
    status, headers, _ = get(url, "/viewer")
    assert status == 307 and headers["location"] == "/viewer/"
    status, headers, body = get(url, "/viewer/")
    assert status == 200 and headers["content-type"].startswith("text/html") and b"viewer" in body
    status, headers, body = get(url, "/viewer/main.js")
    assert status == 200 and body == b"export {};"
    for path in ("/viewer/..%2Fsecret.txt", "/viewer/missing.js"):
        status, _, body = get(url, path)
        assert status == 404 and b"not the viewer" not in body


def test_an_unbuilt_viewer_says_how_to_build_it(serve):
    url = serve(built=False)
    status, headers, body = get(url, "/viewer/")
    assert status == 503 and headers["content-type"] == "application/problem+json"
    problem = loads(body, JSON)
    assert problem["type"].endswith("viewer-not-built") and "make viewer" in problem["detail"]


def test_the_city_is_the_benchmarks_city(serve):
    url = serve(built=False)  # the scene does not need the page
    status, headers, body = get(url, "/viewer/city.msgpack")
    assert status == 200 and headers["content-type"] == MSGPACK
    doc = loads(body, MSGPACK)
    scene = city(2000, 150, seed=0)
    for kind in ("lights", "objects"):
        for name, values in getattr(scene, kind).items():
            if name != "shadows":  # the viewer's city casts a few shadows; nothing moves
                np.testing.assert_array_equal(doc[kind][name], values, err_msg=f"{kind}.{name}")
    assert 0 < doc["lights"]["shadows"].sum() < 150 and doc["side"] == scene.side
