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
With CORS on, a frame request that carries an Origin (a page's) takes the whole stack, for
the CORS middleware's headers.
"""

from __future__ import annotations

import re
import time
from collections.abc import Awaitable, Callable
from typing import Any

from fastapi import FastAPI, Request, WebSocket, WebSocketDisconnect
from fastapi.middleware.cors import CORSMiddleware
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
from .viewer import router as viewer_router

BODY_TYPES = {"content": {MSGPACK: {}, JSON: {}}}


def negotiate(accept: str | None, fallback: str | None) -> str:
    """The response encoding from Accept (RFC 9110 12.5.1): of msgpack and JSON, the one
    with the highest q (a type's q is that of the most specific range naming it:
    ``application/msgpack`` over ``application/*`` over ``*/*``; q=0 refuses it); on a tie
    the one named first, or, if only wildcards name them, the request's encoding, else JSON.
    When Accept names neither, or refuses both, the answer is the request's encoding, else
    JSON (the other one when only that one is refused): a client that cannot read it will
    say so better than a 406 would."""
    if not accept:
        return fallback or JSON
    if "," not in accept and ";" not in accept:  # the usual one-type header
        return media_type(accept) or fallback or JSON
    default = fallback or JSON
    # Per type: (specificity, q, position) of the range that decides it.
    best: dict[str, tuple[int, float, int]] = {}
    for pos, part in enumerate(accept.split(",")):
        name, *params = part.split(";")
        name = name.strip().lower()
        q = 1.0
        for param in params:
            key, _, value = param.partition("=")
            if key.strip().lower() == "q":
                try:
                    q = min(max(float(value), 0.0), 1.0)
                except ValueError:
                    q = 0.0
        kind = media_type(name)
        if kind is not None:
            ranges = [(kind, 2)]
        elif name in ("*/*", "application/*"):
            ranges = [(k, 0 if name == "*/*" else 1) for k in (MSGPACK, JSON)]
        else:
            continue
        for k, specificity in ranges:
            if k not in best or specificity > best[k][0]:
                # A wildcard's position does not rank: only the type it defaults to does.
                best[k] = (specificity, q, pos if specificity == 2 else 1 << 30)
    ranked = sorted(((-q, position, k != default, k) for k, (_, q, position) in best.items()
                     if q > 0))
    if ranked:
        return ranked[0][3]
    other = JSON if default == MSGPACK else MSGPACK
    return other if default in best and other not in best else default


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


def _has_origin(scope: dict[str, Any]) -> bool:
    return any(name == b"origin" for name, _ in scope["headers"])


def origin_allowed(origin: str | None, headers: Any, scheme: str,
                   settings: Settings) -> bool:
    """Whether a WebSocket handshake may proceed: browsers send Origin and do not apply
    the same-origin policy to WebSockets, so a page of another site could otherwise open
    a stream of a service that has no keys (cross-site WebSocket hijacking). Programs send
    no Origin; a page of the service's own origin, or of one in cors_origins, may."""
    if origin is None:
        return True
    origin = origin.rstrip("/")
    own = f"{'https' if scheme == 'wss' else 'http'}://{headers.get('host', '')}"
    return origin == own or "*" in settings.cors_origins or origin in settings.cors_origins


def server_timing(t0: float, t1: float, t2: float, t3: float) -> str:
    """Where the server's time went (read and decode, compute, encode), for clients and
    bench/service.py to split a round trip."""
    return (f"decode;dur={(t1 - t0) * 1e3:.3f}, frame;dur={(t2 - t1) * 1e3:.3f}, "
            f"encode;dur={(t3 - t2) * 1e3:.3f}")


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
    cors: bool = False

    async def __call__(self, scope: Any, receive: Any, send: Any) -> None:
        kind = scope["type"]
        if kind == "http" and scope["method"] == "POST" and self.hot_frame is not None and not (
                self.cors and _has_origin(scope)):  # a page's request: the CORS middleware
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

    async def optional_doc(request: Request) -> Any:
        """The body, or None when there is none (a session with the default config)."""
        has_body = request.headers.get("content-length", "0") != "0"
        return await read_doc(request) if has_body else None

    async def answer(request: Request, compute: Callable[[Any], Awaitable[Any]]) -> Response:
        """The body decoded, computed and encoded, with a Server-Timing header."""
        t0 = time.perf_counter()
        doc = await read_doc(request)
        t1 = time.perf_counter()
        result = await compute(doc)
        t2 = time.perf_counter()
        response = reply(request, result)
        response.headers["Server-Timing"] = server_timing(t0, t1, t2, time.perf_counter())
        return response

    app.add_middleware(Observe, metrics=service.metrics)
    if cfg.cors_origins:
        # Keys travel in Authorization, not cookies: no credentials mode. A preflight may
        # be cached for 10 minutes.
        app.add_middleware(CORSMiddleware, allow_origins=list(cfg.cors_origins),
                           allow_methods=["GET", "POST", "PUT", "DELETE"],
                           allow_headers=["Authorization", "Content-Type", "Accept"],
                           expose_headers=["Server-Timing", "Location", "Retry-After",
                                           "WWW-Authenticate"], max_age=600)
        app.cors = True

    @app.exception_handler(Problem)
    async def on_problem(request: Request, p: Problem) -> Response:
        return problem(request, p)

    @app.exception_handler(StarletteHTTPException)
    async def on_http(request: Request, e: StarletteHTTPException) -> Response:
        kind = "not-found" if e.status_code == 404 else "http"
        return problem(request, Problem(e.status_code, kind, str(e.detail), str(e.detail)))

    @app.get("/healthz", tags=["service"])
    async def healthz(request: Request) -> Response:
        """Liveness: 200 while the service answers. It sweeps idle sessions first (the
        count is of live ones), so that a worker no client calls still frees them: its load
        balancer's health checks come every second or so."""
        service.evict_idle()
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
        return await answer(request, service.schedule)

    @app.post("/v1/sessions", tags=["sessions"], status_code=201,
              openapi_extra=_body("session_request"), responses=_answers("session", 201))
    async def create_session(request: Request) -> Response:
        """A new session (a lightsched.Scheduler) with this config; returns its id."""
        key = key_of(request.headers, cfg)
        s = service.create_session(await optional_doc(request), key)
        return reply(request, s.info(), 201, {"Location": f"/v1/sessions/{s.id}"})

    @app.put("/v1/sessions/{sid}", tags=["sessions"], openapi_extra=_body("session_request"),
             responses=_answers("session", 201))
    async def put_session(request: Request, sid: str) -> Response:
        """The session of this id (1-64 characters of A-Za-z0-9_-), created with this config
        (201) or, if it exists with the same config, returned (200). A sharded service
        routes every request of a session by this id (deploy/haproxy.cfg), so clients choose
        it; a retried PUT is safe."""
        key = key_of(request.headers, cfg)
        s, created = service.put_session(sid, await optional_doc(request), key)
        return reply(request, s.info(), 201 if created else 200,
                     {"Location": f"/v1/sessions/{s.id}"})

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
        return await answer(request, lambda doc: service.frame(sid, key, doc))

    @app.get("/v1/sessions/{sid}/objects/{object_id}/explain", tags=["sessions"],
             responses=_answers("explanation"))
    async def explain(request: Request, sid: str, object_id: str) -> Response:
        """Why each light is (not) on the object in the session's last frame
        (lightsched.Scheduler.explain): one row per light that was visible, holds a slot of
        the object or held one when the frame began, with the first reason that applies."""
        key = key_of(request.headers, cfg)
        oid: Any = int(object_id) if object_id.lstrip("-").isdigit() else object_id
        return reply(request, await service.explain(sid, key, oid))

    @app.post("/v1/sessions/{sid}/tickets", tags=["sessions"], status_code=201,
              responses=_answers("ticket", 201))
    async def ticket(request: Request, sid: str) -> Response:
        """A one-use ticket that opens this session's stream without the key
        (``.../stream?ticket=<ticket>``), for browsers: a page's WebSocket cannot send an
        Authorization header. It expires after ``expires_in`` seconds."""
        return reply(request, service.issue_ticket(sid, key_of(request.headers, cfg)), 201)

    @app.websocket(STREAM_ROUTE)
    async def stream(ws: WebSocket, sid: str) -> None:
        """One frame request per message (binary: msgpack, text: JSON), one frame or problem
        document back per message, in order. The key comes in Authorization or as a ticket
        (``?ticket=``, from POST .../tickets)."""
        await ws.accept()
        try:
            if not origin_allowed(ws.headers.get("origin"), ws.headers, ws.url.scheme, cfg):
                raise Problem(403, "forbidden-origin", "Origin not allowed",
                              f"pages of {ws.headers.get('origin')} may not open streams; "
                              "the service's cors_origins list the origins that may")
            ticket = ws.query_params.get("ticket")
            key = (service.redeem_ticket(sid, ticket) if ticket is not None
                   else key_of(ws.headers, cfg))
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

    app.include_router(viewer_router())

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
    """uvicorn settings the service relies on: the C HTTP parser and event loop, stream
    messages up to twice the body limit (so that one somewhat over it is read whole and
    answered with a 413 problem document: a limit in the WebSocket layer closes the
    connection while the client is still sending, which the client sees as 1006), and no
    permessage-deflate (arrays barely compress, and deflating a frame costs more than
    sending it). The access log is on only where its lines are
    printed (log level info or below): uvicorn formats a line's arguments before the
    logger drops it, a few microseconds per request."""
    return {"http": "httptools", "loop": "uvloop",
            "ws_max_size": 2 * settings.max_body_bytes + 4096, "ws_per_message_deflate": False,
            "log_level": log_level,
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
