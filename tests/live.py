"""A real LightSched server for the tests: lightsched_server's ServerThread, uvicorn on a
free port of 127.0.0.1 in a background thread of the test process.

The kernels are compiled (or loaded from numba's cache) once per test process before the
first server starts: on a fresh machine the first frame compiles for a minute or more,
longer than a client should wait for an answer."""

from __future__ import annotations

import functools

from lightsched_server import Settings
from lightsched_server.app import ServerThread

import lightsched as ls
from lightsched.scenes import city


@functools.cache
def _compiled() -> None:
    for config in (ls.Config(), ls.Config(model="thesis", directional_in_slots=True)):
        sc = city(300, 30, seed=0, shadow_fraction=0.3, sun_shadows=True)
        ls.schedule(sc.lights, sc.objects, sc.cameras, config)


class LiveServer(ServerThread):
    def __init__(self, settings: Settings | None = None, demo: bool = False) -> None:
        _compiled()
        super().__init__(settings, demo)


__all__ = ["LiveServer"]
