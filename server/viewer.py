"""The viewer page (/viewer) and the city it draws (/viewer/city.msgpack).

The page is the TypeScript client's viewer bundle (clients/typescript/viewer, built into
clients/typescript/dist/viewer by `make viewer`); it runs in the browser and talks to this
service like any other client (its own session, frames over the WebSocket). Until it is
built, /viewer answers a 503 problem saying so. LIGHTSCHED_VIEWER_DIR points elsewhere (an
installed service has no checkout beside it).
"""

from __future__ import annotations

import functools
import os
from pathlib import Path

import numpy as np
from fastapi import APIRouter
from fastapi.responses import FileResponse, RedirectResponse, Response
from lightsched_client.wire import MSGPACK, dumps

from lightsched.scenes import city

from .problems import Problem

# The city of the benchmarks at a size a browser draws at once (bench/ uses city() at
# several sizes; seed 0 is theirs). A few point and spot lights cast shadows, so that the
# shadow overlay has lights and casters to show; the flag does not move any light.
CITY_OBJECTS = 2000
CITY_LIGHTS = 150
CITY_SHADOW_FRACTION = 0.05


def viewer_dir() -> Path:
    """Where the built page is: LIGHTSCHED_VIEWER_DIR, else the checkout's
    clients/typescript/dist/viewer."""
    env = os.environ.get("LIGHTSCHED_VIEWER_DIR")
    if env:
        return Path(env)
    return Path(__file__).resolve().parent.parent / "clients" / "typescript" / "dist" / "viewer"


@functools.cache
def city_message() -> bytes:
    """lightsched.scenes.city(2000, 150, seed 0) as one msgpack map: its light and object
    field arrays, the side of its square and the camera the benchmarks look from."""
    scene = city(CITY_OBJECTS, CITY_LIGHTS, seed=0, shadow_fraction=CITY_SHADOW_FRACTION)
    camera = scene.cameras[0]
    doc = {"lights": scene.lights, "objects": scene.objects, "side": scene.side,
           "camera": {"position": np.asarray(camera.position, np.float64),
                      "forward": np.asarray(camera.forward, np.float64)}}
    return dumps(doc, MSGPACK)


def router(directory: Path | None = None) -> APIRouter:
    """GET /viewer (redirects to /viewer/, so that the page's relative paths resolve under
    it), /viewer/ and /viewer/{name}: the built files; /viewer/city.msgpack: the scene."""
    root = (directory or viewer_dir()).resolve()
    r = APIRouter(tags=["viewer"])

    def built(name: str) -> Path:
        path = (root / name).resolve()
        if not (root / "index.html").is_file():
            raise Problem(503, "viewer-not-built", "Viewer not built",
                          f"the viewer is not built ({root} has no index.html): run `make viewer` "
                          "(or `make run`, which builds it)")
        if not path.is_relative_to(root) or not path.is_file():
            raise Problem(404, "not-found", "Not found", f"the viewer has no file {name!r}")
        return path

    @r.get("/viewer", include_in_schema=False)
    async def viewer_redirect() -> Response:
        return RedirectResponse("/viewer/", status_code=307)

    @r.get("/viewer/city.msgpack")
    async def viewer_city() -> Response:
        """The city the viewer draws: lightsched.scenes.city(2000, 150, seed=0), a few
        lights shadowed, as msgpack field arrays (schemas/wire.md)."""
        return Response(city_message(), media_type=MSGPACK)

    @r.get("/viewer/", include_in_schema=False)
    async def viewer_page() -> Response:
        return FileResponse(built("index.html"), headers={"Cache-Control": "no-cache"})

    @r.get("/viewer/{name}", include_in_schema=False)
    async def viewer_file(name: str) -> Response:
        return FileResponse(built(name), headers={"Cache-Control": "no-cache"})

    return r
