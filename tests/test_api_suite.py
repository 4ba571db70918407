"""One API suite, four implementations of DESIGN section 7: the embedded fast Scheduler,
the oracle (lightsched.reference), and the service through the Python client over HTTP and
over the WebSocket stream. The same calls must give the same frames: bit for bit between
the embedded scheduler and the remote ones, and as DESIGN section 4 says (near-ties aside)
against the oracle. A rejected call names the same field and index everywhere and changes
nothing; the remote schedulers raise it at the frame that carries the call."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import assert_frames_match
from lightsched_client import Client
from lightsched_client import ValidationError as RemoteValidationError
from live import LiveServer

import lightsched as ls
import lightsched.reference as ref
from lightsched.frame import FRAME_ARRAYS
from lightsched.scenes import city, move_lights

BACKENDS = ["embedded", "oracle", "http", "websocket"]


@pytest.fixture(scope="module")
def server():
    s = LiveServer()
    yield s
    s.stop()


class Backend:
    """Opens schedulers of one implementation and knows when its errors surface."""

    def __init__(self, kind: str, server: LiveServer) -> None:
        self.kind = kind
        self.client = Client(server.url) if kind in ("http", "websocket") else None

    def open(self, config: ls.Config):
        if self.kind == "embedded":
            return ls.Scheduler(config)
        if self.kind == "oracle":
            return ref.Scheduler(config)
        return self.client.session(config, stream=self.kind == "websocket")

    def rejected(self, sched, call, cameras, **fields):
        """Makes a bad call; returns (field, index) of the error, wherever it surfaces."""
        try:
            getattr(sched, call)(**fields)
            if self.client is not None:
                sched.frame(cameras)
        except (ls.ValidationError, RemoteValidationError) as e:
            return e.field, e.index
        raise AssertionError(f"{self.kind}: {call} was accepted")

    def schedule(self, lights, objects, cameras, config):
        if self.kind == "embedded":
            return ls.schedule(lights, objects, cameras, config)
        if self.kind == "oracle":
            return ref.schedule(lights, objects, cameras, config)
        return self.client.schedule(lights, objects, cameras, config)

    def close(self) -> None:
        if self.client is not None:
            self.client.close()


def run_script(b: Backend, seed: int, config: ls.Config):
    """A session through every call of the API; returns its frames and the errors seen."""
    sc = city(400, 50, seed=seed, shadow_fraction=0.2, sun_shadows=True)
    cams = sc.cameras
    s = b.open(config)
    frames, errors = [], []
    s.set_lights(**sc.lights)
    s.set_objects(**sc.objects)
    frames.append(s.frame(cams, dt=1 / 60))
    for i in range(1, 4):
        s.update_lights(id=sc.lights["id"], position=move_lights(sc.lights, i))
        frames.append(s.frame(cams, dt=0.04 * i))
    errors.append(b.rejected(s, "set_lights", cams, id=[1, 2], position=[[0, 0, 0]] * 2,
                             radius=[1.0, -1.0]))
    errors.append(b.rejected(s, "update_objects", cams, id=[sc.objects["id"][0], -5],
                             bounds_max=[[1, 1, 1]] * 2))
    frames.append(s.frame(cams, dt=0.02))
    keep = slice(10, None)
    s.set_lights(**{k: v[keep] for k, v in sc.lights.items()})  # kept ids keep their state
    s.update_objects(id=sc.objects["id"][:20], bounds_min=sc.objects["bounds_min"][:20] - 2.0)
    s.remove_objects(id=sc.objects["id"][20:40])
    frames.append(s.frame(cams, dt=0.1))
    s.remove_lights(id=sc.lights["id"][10:15])
    frames.append(s.frame(cams, dt=0.0, cut=True))
    if hasattr(s, "close"):
        s.close()
    return frames, errors


@pytest.mark.parametrize("kind", BACKENDS[1:])
@pytest.mark.parametrize("seed,config", [
    (0, ls.Config()),
    (1, ls.Config(max_lights=3, model="thesis", fade_in=0.1, fade_out=0.3, shadow_budget=2,
                  unshadowed="skip")),
    (2, ls.Config(max_lights=5, directional_in_slots=True, hysteresis=0.0, cascades=2)),
])
def test_every_implementation_gives_the_embedded_frames(server, kind, seed, config):
    base = Backend("embedded", server)
    other = Backend(kind, server)
    try:
        want, want_errors = run_script(base, seed, config)
        got, got_errors = run_script(other, seed, config)
    finally:
        other.close()
    assert got_errors == want_errors
    for k, (g, w) in enumerate(zip(got, want, strict=True)):
        if kind == "oracle":
            assert_frames_match(w, g, what=f"frame {k}")
            continue
        for name in FRAME_ARRAYS:
            a, b = getattr(g, name), getattr(w, name)
            assert a.dtype == b.dtype and np.array_equal(a, b), (k, name)


@pytest.mark.parametrize("kind", BACKENDS[1:3])
def test_stateless_schedule(server, kind):
    sc = city(300, 40, seed=5, shadow_fraction=0.3, sun_shadows=True)
    config = ls.Config(max_lights=4)
    b = Backend(kind, server)
    try:
        got = b.schedule(sc.lights, sc.objects, sc.cameras, config)
    finally:
        b.close()
    want = ls.schedule(sc.lights, sc.objects, sc.cameras, config)
    if kind == "oracle":
        assert_frames_match(want, got)
    else:
        for name in FRAME_ARRAYS:
            assert np.array_equal(getattr(got, name), getattr(want, name)), name
