"""HTTP and WebSocket routes over service.Service (which knows nothing of HTTP).

Bodies are read as bytes and decoded by Content-Type (application/msgpack, or
application/json for debugging); responses follow Accept (else the request's encoding,
else JSON). Every refusal is a problem document (RFC 9457) in the response's encoding, with
a 4xx status (500 for a frame that fails by a fault of the service); a frame that fails
changes nothing in its session.

The two hot routes, ``POST /v1/sessions/{sid}/frames`` and the stream, are FastAPI routes
(for /docs and OpenAPI) whose endpoints App.__call__ also calls directly: a frame skips
FastAPI's middleware stack, router and dependency solving (~100 us of Python per request),
and App does what those would do for it (problem documents, the 500, request metrics).
"""

from __future__ import annotations

import re
import time
from collections.abc import Awaitable, Callable
from typing import Any

from fastapi import FastAPI, Request, WebSocket, WebSocketDisconnect
from fastapi.openapi.utils import get_openapi
from fastapi.responses import PlainTextResponse, Response
from lightsched_client.wire import (
    JSON,
    MSGPACK,
    PROBLEM_JSON,
    PROBLEM_MSGPACK,
    WireError,
    dumps,
    loads,
    media_type,
)
from starlette.exceptions import HTTPException as StarletteHTTPException

import lightsched

from .models import SCHEMAS
from .problems import Problem
from .service import Service
from .settings import Settings

BODY_TYPES = {"content": {MSGPACK: {}, JSON: {}}}


def negotiate(accept: str | None, fallback: str | None) -> str:
    """The response encoding: the first of msgpack / JSON that Accept names, else the
    request's encoding, else JSON."""
    for part in (accept or "").split(","):
        kind = media_type(part)
        if kind:
            return kind
    return fallback or JSON


def key_of(headers: Any, settings: Settings) -> str | None:
    """The caller's API key (None when the service has no keys); 401 if missing or wrong."""
    if settings.api_keys is None:
        return None
    auth = headers.get("authorization", "")
    scheme, _, key = auth.partition(" ")
    if scheme.lower() != "bearer" or key.strip() not in settings.api_keys:
        raise Problem(401, "unauthorized", "Unauthorized",
                      "this service needs 'Authorization: Bearer <key>' with a known key",
                      headers={"WWW-Authenticate": "Bearer"})
    return key.strip()


FRAMES_ROUTE = "/v1/sessions/{sid}/frames"
STREAM_ROUTE = "/v1/sessions/{sid}/stream"
# What Starlette's "{sid}" matches: one non-empty path segment.
_FRAMES = re.compile(r"/v1/sessions/([^/]+)/frames")
_STREAM = re.compile(r"/v1/sessions/([^/]+)/stream")


def _route_path(scope: dict[str, Any]) -> str:
    """The path the router matches (Starlette's get_route_path: without the root path)."""
    path: str = scope["path"]
    root = scope.get("root_path", "")
    if root and path.startswith(root) and (len(path) == len(root) or path[len(root)] == "/"):
        return path[len(root):]
    return path


class App(FastAPI):
    """FastAPI, with the frame route and the stream dispatched before its middleware stack
    to their endpoints (set by create_app)."""

    hot_frame: Callable[[Request, str], Awaitable[Response]] | None = None
    hot_stream: Callable[[WebSocket, str], Awaitable[None]] | None = None
    on_problem: Callable[[Request, Problem], Response] | None = None
    metrics: Any = None

    async def __call__(self, scope: Any, receive: Any, send: Any) -> None:
        kind = scope["type"]
        if kind == "http" and scope["method"] == "POST" and self.hot_frame is not None:
            m = _FRAMES.fullmatch(_route_path(scope))
            if m is not None:
                await self._frame(scope, receive, send, m.group(1))
                return
        elif kind == "websocket" and self.hot_stream is not None:
            m = _STREAM.fullmatch(_route_path(scope))
            if m is not None:
                scope["app"] = self
                await self.hot_stream(WebSocket(scope, receive, send), m.group(1))
                return
        await super().__call__(scope, receive, send)

    async def _frame(self, scope: Any, receive: Any, send: Any, sid: str) -> None:
        """What the middleware stack does around the frame endpoint: Problem -> its
        document, anything else -> 500 (re-raised for the server's log), and the request
        metrics (Observe)."""
        assert self.hot_frame is not None and self.on_problem is not None
        t = time.perf_counter()
        scope["app"] = self
        request = Request(scope, receive)
        status = 500
        try:
            try:
                response = await self.hot_frame(request, sid)
            except Problem as p:
                response = self.on_problem(request, p)
            status = response.status_code
            await response(scope, receive, send)
        except Exception:
            if status == 500:  # nothing sent yet: ServerErrorMiddleware's answer
                await PlainTextResponse("Internal Server Error", 500)(scope, receive, send)
            raise
        finally:
            self.metrics.observe_request(FRAMES_ROUTE, status, time.perf_counter() - t)


def create_app(settings: Settings | None = None, demo: bool = False) -> FastAPI:
    """The ASGI app. ``demo`` preloads a session with id "demo" holding the demo city."""
    service = Service(settings or Settings.from_env())
    app = App(title="LightSched", version=lightsched.__version__,
              description="Per-object light sets, fades and shadow casters for real-time "
                          "renderers. Bodies are application/msgpack (or application/json "
                          "for debugging); see schemas/wire.md.")
    app.state.service = service
    cfg = service.settings

    def reply(request: Request, doc: Any, status: int = 200,
              headers: dict[str, str] | None = None) -> Response:
        kind = negotiate(request.headers.get("accept"), media_type(request.headers.get(
            "content-type")))
        return Response(dumps(doc, kind), status_code=status, media_type=kind, headers=headers)

    def problem(request: Request, p: Problem) -> Response:
        kind = negotiate(request.headers.get("accept"), media_type(request.headers.get(
            "content-type")))
        return Response(dumps(p.document(request.url.path), kind), status_code=p.status,
                        media_type=PROBLEM_MSGPACK if kind == MSGPACK else PROBLEM_JSON,
                        headers=p.headers)

    async def read_doc(request: Request) -> Any:
        kind = media_type(request.headers.get("content-type"))
        if kind is None:
            raise Problem(415, "unsupported-media-type", "Unsupported media type",
                          f"send {MSGPACK} or {JSON}")
        declared = request.headers.get("content-length")
        if declared and declared.isdigit() and int(declared) > cfg.max_body_bytes:
            raise Problem(413, "too-large", "Body too large",
                          f"the body may hold at most {cfg.max_body_bytes} bytes")
        body = bytearray()
        async for chunk in request.stream():
            body += chunk
            if len(body) > cfg.max_body_bytes:
                raise Problem(413, "too-large", "Body too large",
                              f"the body may hold at most {cfg.max_body_bytes} bytes")
        try:
            return loads(bytes(body), kind)
        except WireError as e:
            raise Problem(400, "malformed", "Malformed body", e.message,
                          pointer=e.pointer) from None

    app.add_middleware(Observe, metrics=service.metrics)

    @app.exception_handler(Problem)
    async def on_problem(request: Request, p: Problem) -> Response:
        return problem(request, p)

    @app.exception_handler(StarletteHTTPException)
    async def on_http(request: Request, e: StarletteHTTPException) -> Response:
        kind = "not-found" if e.status_code == 404 else "http"
        return problem(request, Problem(e.status_code, kind, str(e.detail), str(e.detail)))

    @app.get("/healthz", tags=["service"])
    async def healthz(request: Request) -> Response:
        """Liveness: 200 while the service answers."""
        return reply(request, {"status": "ok", "sessions": len(service.sessions)})

    @app.get("/metrics", tags=["service"])
    async def metrics() -> Response:
        """Prometheus text: frames, per-stage latency histograms, sessions, responses by
        status."""
        return Response(service.metrics.render(len(service.sessions)),
                        media_type="text/plain; version=0.0.4")

    @app.post("/v1/schedule", tags=["frames"], openapi_extra=_body("schedule_request"),
              responses=_answers("frame"))
    async def schedule(request: Request) -> Response:
        """The stateless one-frame call (lightsched.schedule): every set on at weight 1."""
        key_of(request.headers, cfg)
        return reply(request, await service.schedule(await read_doc(request)))

    @app.post("/v1/sessions", tags=["sessions"], status_code=201,
              openapi_extra=_body("session_request"), responses=_answers("session", 201))
    async def create_session(request: Request) -> Response:
        """A new session (a lightsched.Scheduler) with this config; returns its id."""
        key = key_of(request.headers, cfg)
        has_body = request.headers.get("content-length", "0") != "0"
        doc = await read_doc(request) if has_body else None
        s = service.create_session(doc, key)
        return reply(request, s.info(), 201, {"Location": f"/v1/sessions/{s.id}"})

    @app.get("/v1/sessions/{sid}", tags=["sessions"], responses=_answers("session"))
    async def get_session(request: Request, sid: str) -> Response:
        """The session's config, frame count and scene size."""
        return reply(request, service.session(sid, key_of(request.headers, cfg)).info())

    @app.delete("/v1/sessions/{sid}", tags=["sessions"], status_code=204)
    async def delete_session(request: Request, sid: str) -> Response:
        """Drops the session."""
        service.delete_session(sid, key_of(request.headers, cfg))
        return Response(status_code=204)

    @app.post(FRAMES_ROUTE, tags=["frames"], openapi_extra=_body("frame_request"),
              responses=_answers("frame"))
    async def frame(request: Request, sid: str) -> Response:
        """Scene changes (set / update / remove of lights and objects, in order, all or
        nothing), then one frame; the arrays asked for, or only the changed rows."""
        key = key_of(request.headers, cfg)
        service.session(sid, key)
        t0 = time.perf_counter()
        doc = await read_doc(request)
        t1 = time.perf_counter()
        answer = await service.frame(sid, key, doc)
        t2 = time.perf_counter()
        response = reply(request, answer)
        t3 = time.perf_counter()
        # Where the server's time went (read and decode, frame, encode), for clients and
        # bench/service.py to split a round trip.
        response.headers["Server-Timing"] = (f"decode;dur={(t1 - t0) * 1e3:.3f}, "
                                             f"frame;dur={(t2 - t1) * 1e3:.3f}, "
                                             f"encode;dur={(t3 - t2) * 1e3:.3f}")
        return response

    @app.websocket(STREAM_ROUTE)
    async def stream(ws: WebSocket, sid: str) -> None:
        """One frame request per message (binary: msgpack, text: JSON), one frame or problem
        document back per message, in order."""
        await ws.accept()
        try:
            key = key_of(ws.headers, cfg)
            service.session(sid, key)
        except Problem as p:
            await ws.send_bytes(dumps(p.document(ws.url.path), MSGPACK))
            await ws.close(code=1008, reason=p.title)
            return
        try:
            while True:
                msg = await ws.receive()
                if msg["type"] == "websocket.disconnect":
                    return
                binary = msg.get("bytes") is not None
                kind = MSGPACK if binary else JSON
                body = msg["bytes"] if binary else (msg.get("text") or "").encode()
                try:
                    if len(body) > cfg.max_body_bytes:
                        raise Problem(413, "too-large", "Message too large",
                                      f"a message may hold at most {cfg.max_body_bytes} bytes")
                    try:
                        doc = loads(body, kind)
                    except WireError as e:
                        raise Problem(400, "malformed", "Malformed message", e.message,
                                      pointer=e.pointer) from None
                    out = dumps(await service.frame(sid, key, doc), kind)
                except Problem as p:
                    out = dumps(p.document(ws.url.path), kind)
                if binary:
                    await ws.send_bytes(out)
                else:
                    await ws.send_text(out.decode())
        except WebSocketDisconnect:
            return

    def openapi() -> dict[str, Any]:
        if app.openapi_schema is None:
            spec = get_openapi(title=app.title, version=app.version,
                               description=app.description, routes=app.routes)
            comps = spec.setdefault("components", {}).setdefault("schemas", {})
            for model in SCHEMAS.values():
                schema = model.model_json_schema(ref_template="#/components/schemas/{model}")
                comps.update(schema.pop("$defs", {}))
                comps[model.__name__] = schema
            app.openapi_schema = spec
        return app.openapi_schema

    app.openapi = openapi  # type: ignore[method-assign]
    app.hot_frame, app.hot_stream, app.on_problem = frame, stream, problem
    app.metrics = service.metrics
    if demo:
        from lightsched.scenes import demo_scene

        session = service.create_session({}, None, sid="demo")
        scene = demo_scene(seed=0)
        session.scheduler.set_lights(**scene.lights)
        session.scheduler.set_objects(**scene.objects)
    return app


class Observe:
    """Pure ASGI middleware: latency and status of every HTTP response into the metrics
    (Starlette's BaseHTTPMiddleware would add a task and a stream per request)."""

    def __init__(self, app: Any, metrics: Any) -> None:
        self.app = app
        self.metrics = metrics

    async def __call__(self, scope: dict[str, Any], receive: Any, send: Any) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        t = time.perf_counter()
        status = 500

        async def send_status(message: dict[str, Any]) -> None:
            nonlocal status
            if message["type"] == "http.response.start":
                status = message["status"]
            await send(message)

        try:
            await self.app(scope, receive, send_status)
        finally:
            route = scope.get("route")
            self.metrics.observe_request(getattr(route, "path", "unmatched"), status,
                                         time.perf_counter() - t)


def _title(name: str) -> str:
    return SCHEMAS[name].__name__


def _body(name: str) -> dict[str, Any]:
    ref = {"$ref": f"#/components/schemas/{_title(name)}"}
    return {"requestBody": {"required": True,
                            "content": {MSGPACK: {"schema": ref}, JSON: {"schema": ref}}}}


def _answers(name: str, status: int = 200) -> dict[int | str, Any]:
    ref = {"$ref": f"#/components/schemas/{_title(name)}"}
    problem = {"$ref": f"#/components/schemas/{_title('problem')}"}
    return {status: {"content": {MSGPACK: {"schema": ref}, JSON: {"schema": ref}}},
            "4XX": {"description": "A problem document (RFC 9457)",
                    "content": {PROBLEM_MSGPACK: {"schema": problem},
                                PROBLEM_JSON: {"schema": problem}}}}


def serve(host: str = "127.0.0.1", port: int = 8080, demo: bool = True,
          settings: Settings | None = None, log_level: str = "info",
          warm_up: bool = True) -> None:
    """Runs the service with uvicorn until interrupted. With ``warm_up`` every kernel is
    loaded (or, on a machine's first start, compiled: minutes) before the port opens, so
    that no client's first frame waits for it (lightsched.warmup)."""
    import uvicorn

    settings = settings or Settings.from_env()
    app = create_app(settings, demo=demo)
    print(f"LightSched {lightsched.__version__} on http://{host}:{port} "
          f"(docs: http://{host}:{port}/docs"
          + (", demo session id 'demo'" if demo else "") + ")", flush=True)
    if warm_up:
        from lightsched.warmup import warm_up as prepare

        print("preparing kernels before accepting requests (compiling them takes a few "
              "minutes on a machine's first start)", flush=True)
        print(prepare().summary(), flush=True)
    uvicorn.run(app, **uvicorn_options(settings, log_level), host=host, port=port)


def uvicorn_options(settings: Settings, log_level: str = "warning") -> dict[str, Any]:
    """uvicorn settings the service relies on: the C HTTP parser and event loop, messages
    as large as bodies, and no permessage-deflate (arrays barely compress, and deflating a
    frame costs more than sending it). The access log is on only where its lines are
    printed (log level info or below): uvicorn formats a line's arguments before the
    logger drops it, a few microseconds per request."""
    return {"http": "httptools", "loop": "uvloop", "ws_max_size": settings.max_body_bytes,
            "ws_per_message_deflate": False, "log_level": log_level,
            "access_log": log_level.lower() in ("trace", "debug", "info")}


class ServerThread:
    """The service on a free port of 127.0.0.1 in a background thread of this process, with
    serve()'s options (tests, the golden example generator, benchmarks)."""

    def __init__(self, settings: Settings | None = None, demo: bool = False) -> None:
        import socket
        import threading

        import uvicorn

        self.settings = settings or Settings()
        self.app = create_app(self.settings, demo=demo)
        self.service = self.app.state.service
        with socket.socket() as sock:
            sock.bind(("127.0.0.1", 0))
            self.port = sock.getsockname()[1]
        self.url = f"http://127.0.0.1:{self.port}"
        config = uvicorn.Config(self.app, host="127.0.0.1", port=self.port,
                                **uvicorn_options(self.settings))
        self.server = uvicorn.Server(config)
        self.thread = threading.Thread(target=self.server.run, daemon=True)
        self.thread.start()
        deadline = time.monotonic() + 30
        while not self.server.started:
            if time.monotonic() > deadline or not self.thread.is_alive():
                raise RuntimeError("the server thread did not start")
            time.sleep(0.01)

    def stop(self) -> None:
        self.server.should_exit = True
        self.thread.join(timeout=10)
