"""The command line (lightsched/__main__.py): the demo runs and prints a summary."""

from __future__ import annotations

import re
import subprocess
import sys

import pytest


def test_demo_runs_and_prints_a_summary():
    proc = subprocess.run(
        [sys.executable, "-m", "lightsched", "demo", "--objects", "300", "--lights", "30",
         "--frames", "5"],
        capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    out = proc.stdout
    assert "LightSched demo: 300 objects, 30 lights" in out
    assert "5 frames" in out
    for line in ("visible objects", "visible lights", "mean set size", "milliseconds per frame",
                 "frame() wall time", "plan of the last frame"):
        assert line in out, out


def test_demo_rejects_zero_frames():
    proc = subprocess.run([sys.executable, "-m", "lightsched", "demo", "--frames", "0"],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 2 and "--frames" in proc.stderr


def test_serve_help_explains_the_options():
    proc = subprocess.run([sys.executable, "-m", "lightsched", "serve", "--help"],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0
    for word in ("--host", "--port", "--no-demo", "--no-warm-up", "LIGHTSCHED_API_KEYS",
                 "LIGHTSCHED_MAX_BODY_BYTES"):
        assert word in proc.stdout, proc.stdout


@pytest.mark.slow  # a child process that warms every kernel up
def test_warm_up_prepares_the_kernels_asked_for():
    proc = subprocess.run([sys.executable, "-m", "lightsched", "warm-up", "--max-lights", "8",
                           "--precision", "exact"], capture_output=True, text=True, timeout=900)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    last = proc.stdout.strip().splitlines()[-1]
    # A fresh process holds no kernel: each signature is loaded or compiled once.
    loaded, compiled = (int(w) for w in re.findall(r"(\d+) (?:signatures loaded|compiled)",
                                                   last))
    assert last.startswith("kernels ready in ") and loaded + compiled >= 20, last


def test_warm_up_rejects_an_unknown_precision():
    proc = subprocess.run([sys.executable, "-m", "lightsched", "warm-up", "--precision", "half"],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2 and "--precision" in proc.stderr


@pytest.mark.slow  # a child process that warms every kernel up
def test_serve_then_a_client_drives_the_demo_session():
    """`make run`'s command in a process of its own; the Python client drives the preloaded
    demo session and a new one from this process, as a second shell would."""
    import socket
    import time

    from lightsched_client import Client

    from lightsched.scenes import demo_scene

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    proc = subprocess.Popen([sys.executable, "-m", "lightsched", "serve", "--port", str(port),
                             "--log-level", "warning"], stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)
    try:
        banner = proc.stdout.readline()
        assert f"http://127.0.0.1:{port}/docs" in banner and "demo" in banner, banner
        # The port opens once every kernel is ready (lightsched.warmup).
        assert "preparing kernels" in proc.stdout.readline()
        ready = proc.stdout.readline()
        assert ready.startswith("kernels ready in ") and "compiled" in ready, ready
        with Client(f"http://127.0.0.1:{port}") as c:
            deadline = time.monotonic() + 60
            while True:
                try:
                    c.health()
                    break
                except OSError:
                    assert time.monotonic() < deadline and proc.poll() is None
                    time.sleep(0.1)
            scene = demo_scene(seed=0)
            info = c.call("GET", "/v1/sessions/demo")
            assert info["objects"] == len(scene.objects["id"])
            demo = c.call("POST", "/v1/sessions/demo/frames",
                          {"cameras": [{"position": list(map(float, cam.position)),
                                        "forward": list(map(float, cam.forward)),
                                        "up": list(map(float, cam.up)), "fov_y": cam.fov_y,
                                        "aspect": cam.aspect, "near": cam.near, "far": cam.far}
                                       for cam in scene.cameras], "outputs": ["count"]})
            assert demo["count"].sum() > 0
            s = c.session()
            s.set_lights(**scene.lights)
            s.set_objects(**scene.objects)
            assert s.frame(scene.cameras).light_ids.shape == (len(scene.objects["id"]), 8)
    finally:
        proc.terminate()
        proc.wait(timeout=30)


def test_server_extra_ships_and_declares_the_wire_codec():
    """`pip install ".[server]"` alone gives a server that starts: the root distribution
    ships lightsched_client (the server's wire codec) with its package data, and the
    server extra names every dependency of the client distribution. (An install into a
    fresh venv needs the network, so that one is checked by hand.)"""
    import tomllib
    from pathlib import Path

    root = Path(__file__).resolve().parent.parent
    project = tomllib.loads((root / "pyproject.toml").read_text())
    client = tomllib.loads((root / "clients" / "python" / "pyproject.toml").read_text())
    tool = project["tool"]["setuptools"]
    for package in ("lightsched", "lightsched_server", "lightsched_client"):
        assert package in tool["packages"], package
        assert (root / tool["package-dir"][package] / "__init__.py").is_file(), package
    source = root / tool["package-dir"]["lightsched_client"]
    for data in client["tool"]["setuptools"]["package-data"]["lightsched_client"]:
        assert data in tool["package-data"]["lightsched_client"], data
        assert (source / data).is_file(), data

    def names(requirements):
        return {re.split(r"[<>=!~\[; ]", r, maxsplit=1)[0].lower() for r in requirements}

    assert names(client["project"]["dependencies"]) <= \
        names(project["project"]["dependencies"] + project["project"]["optional-dependencies"]["server"])
