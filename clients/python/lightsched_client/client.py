"""Client of the LightSched service, mirroring the embedded API (DESIGN section 7).

``Client(url, api_key=None)`` gives ``.schedule(lights, objects, cameras, config)`` and
``.session(config)``, a RemoteScheduler with the methods of ``lightsched.Scheduler``:
set_/update_/remove_ of lights and objects, and ``frame(cameras, dt, cut)`` returning a
Frame with the same fields. Scene changes are kept until the next frame and travel with it
in one round trip (all or nothing: if the service refuses one, none is applied and the
frame raises). ``session(config, stream=True)`` sends frames over the session's WebSocket
instead of HTTP. AsyncClient / AsyncRemoteScheduler are the asyncio versions.

Sessions survive a sharded service (deploy/haproxy.cfg routes by session id): the client
chooses the id (PUT /v1/sessions/{id}); every frame carries a sequence number (``seq``), so
that a frame whose answer was lost (a reset connection, a 502/503 while a worker is replaced)
is sent again without being applied twice; and a session that answers 404 (its worker died
and another now owns the id) is created again and given the scene the client mirrors
(SceneMirror), within that frame, which then counts as a cut. ``recoveries`` counts those. HTTP
connections are kept alive between calls: the sync client uses the standard library's
http.client (a 1k-object frame costs ~0.5 ms less than through httpx, 10k ~2.5 ms), the
asyncio one httpx.AsyncClient.
"""

from __future__ import annotations

import asyncio
import contextlib
import http.client
import json
import secrets
import time
from dataclasses import field, make_dataclass
from importlib import resources
from typing import Any
from urllib.parse import urlsplit

import httpx
import numpy as np
from websockets.exceptions import ConnectionClosed

from .wire import JSON, MSGPACK, WireError, dumps, loads, media_type

# The frame's arrays (DESIGN section 3), generated from lightsched.fields: this package
# does not import lightsched (numba is heavy).
_FIELD_LIST = json.loads(
    resources.files(__package__).joinpath("frame_fields.json").read_text("utf-8"))
FIELDS: tuple[dict[str, Any], ...] = tuple(_FIELD_LIST["fields"])
# explain's columns (DESIGN section 7) and its reasons, in their order.
EXPLAIN_FIELDS: tuple[str, ...] = tuple(f["name"] for f in _FIELD_LIST["explain_fields"])
REASONS: tuple[str, ...] = tuple(_FIELD_LIST["reasons"])
FRAME_FIELDS: tuple[str, ...] = tuple(f["name"] for f in FIELDS)
# Per-object arrays and their empty-slot value (DESIGN section 3).
PER_OBJECT: dict[str, Any] = {f["name"]: f["empty"] for f in FIELDS if f["per_object"]}
CAMERA_FIELDS = ("id", "position", "forward", "up", "fov_y", "aspect", "near", "far", "focus",
                 "height_px")

Frame = make_dataclass(
    "Frame",
    [(name, np.ndarray | None, None) for name in FRAME_FIELDS]
    + [("stats", dict[str, Any], field(default_factory=dict)), ("frame_index", int, 0)])
Frame.__module__ = __name__
Frame.__doc__ = """One frame (DESIGN section 3): the arrays asked for (others None), stats, and
the session's frame index. Its array fields are FRAME_FIELDS."""

Explanation = make_dataclass(
    "Explanation", [("object_id", int), ("frame_index", int)]
    + [(name, Any) for name in EXPLAIN_FIELDS])
Explanation.__module__ = __name__
Explanation.__doc__ = """lightsched.Scheduler.explain's answer: one row per light, in ascending
light id; its columns are EXPLAIN_FIELDS (arrays, and ``reason`` a list of REASONS)."""


def explanation_of(doc: dict[str, Any]) -> Any:
    return Explanation(**{name: doc[name] for name in ("object_id", "frame_index",
                                                       *EXPLAIN_FIELDS)})


class RemoteError(Exception):
    """The service refused a call: ``status`` and the problem document (RFC 9457)."""

    def __init__(self, status: int, problem: dict[str, Any]) -> None:
        self.status = status
        self.problem = problem
        super().__init__(f"{status} {problem.get('title', '')}: {problem.get('detail', '')}")


class ValidationError(RemoteError, ValueError):
    """Bad input (422): ``field`` and ``index`` as lightsched.ValidationError has them."""

    def __init__(self, status: int, problem: dict[str, Any]) -> None:
        super().__init__(status, problem)
        self.field = problem.get("field")
        self.index = problem.get("index")
        self.message = problem.get("detail", "")


def _error(status: int, problem: Any) -> RemoteError:
    doc = problem if isinstance(problem, dict) else {"detail": str(problem)}
    return (ValidationError if status == 422 else RemoteError)(status, doc)


def _array(value: Any) -> Any:
    return value if isinstance(value, np.ndarray) else np.asarray(value)


def camera_doc(cam: Any) -> dict[str, Any]:
    """A camera (lightsched.Camera, any object with its attributes, or a mapping) as a
    wire map."""
    get = cam.get if isinstance(cam, dict) else (lambda k, d=None: getattr(cam, k, d))
    doc: dict[str, Any] = {}
    for name in CAMERA_FIELDS:
        value = get(name, None)
        if value is None:
            continue
        if name in ("position", "forward", "up", "focus"):
            doc[name] = np.asarray(value, dtype=np.float64)
        elif name == "id":
            doc[name] = int(value)
        else:
            doc[name] = float(value)
    return doc


def config_doc(config: Any) -> dict[str, Any] | None:
    """None, a mapping, or lightsched.Config (anything with to_dict())."""
    if config is None:
        return None
    given = config.to_dict() if hasattr(config, "to_dict") else dict(config)
    out = {}
    for k, v in given.items():
        if v is None:
            continue
        out[k] = v.item() if isinstance(v, np.generic) else v
    return out


def fields_doc(fields: dict[str, Any]) -> dict[str, Any]:
    return {k: _array(v) for k, v in fields.items() if v is not None}


def merge_changed(prev: Frame | None, doc: dict[str, Any]) -> Frame:
    """The full frame from a changed_only answer and the previous full frame: per-object
    arrays keep the previous values of ids that did not change (aligned by id)."""
    same_set = "object_id" not in doc and prev is not None and prev.object_id is not None
    ids = prev.object_id if same_set else doc.get("object_id", np.zeros(0, np.int32))
    f = Frame(stats=doc.get("stats") or {}, frame_index=doc["frame_index"], object_id=ids)
    at = np.searchsorted(ids, doc["rows"])  # where the rows sent go (ids ascend)
    if not same_set and prev is not None and prev.object_id is not None and prev.object_id.size:
        pos = np.minimum(np.searchsorted(prev.object_id, ids), prev.object_id.size - 1)
        kept = prev.object_id[pos] == ids
    for name in FRAME_FIELDS:
        if name == "object_id" or name not in doc:
            continue
        part = doc[name]
        if name not in PER_OBJECT:
            setattr(f, name, part)
            continue
        old = getattr(prev, name, None) if prev is not None else None
        if same_set and old is not None:
            full = old.copy()
        else:
            full = np.full((ids.size,) + part.shape[1:], PER_OBJECT[name], dtype=part.dtype)
            if old is not None and prev.object_id.size:
                full[kept] = old[pos[kept]]
        full[at] = part
        setattr(f, name, full)
    return f


def frame_of(doc: dict[str, Any], prev: Frame | None = None) -> Frame:
    if doc.get("changed_only"):
        return merge_changed(prev, doc)
    f = Frame(stats=doc.get("stats") or {}, frame_index=doc["frame_index"])
    for name in FRAME_FIELDS:
        if name in doc:
            setattr(f, name, doc[name])
    return f


def camera_docs(cameras: Any) -> list[dict[str, Any]]:
    """One camera or a list of them, as wire maps."""
    if isinstance(cameras, dict) or not isinstance(cameras, (list, tuple)):
        cameras = [cameras]
    return [camera_doc(c) for c in cameras]


def schedule_doc(lights: dict[str, Any], objects: dict[str, Any], cameras: Any, config: Any,
                 outputs: list[str] | None) -> dict[str, Any]:
    """The body of POST /v1/schedule."""
    doc: dict[str, Any] = {"lights": fields_doc(lights), "objects": fields_doc(objects),
                           "cameras": camera_docs(cameras)}
    if config is not None:
        doc["config"] = config_doc(config)
    if outputs is not None:
        doc["outputs"] = list(outputs)
    return doc


class _Changes:
    """The embedded API's scene calls, kept until the next frame."""

    def __init__(self) -> None:
        self._changes: list[dict[str, Any]] = []

    def set_lights(self, **fields: Any) -> None:
        self._changes.append({"op": "set_lights", "fields": fields_doc(fields)})

    def update_lights(self, **fields: Any) -> None:
        self._changes.append({"op": "update_lights", "fields": fields_doc(fields)})

    def remove_lights(self, id: Any) -> None:  # noqa: A002 - the embedded API's keyword
        self._changes.append({"op": "remove_lights", "fields": {"id": _array(id)}})

    def set_objects(self, **fields: Any) -> None:
        self._changes.append({"op": "set_objects", "fields": fields_doc(fields)})

    def update_objects(self, **fields: Any) -> None:
        self._changes.append({"op": "update_objects", "fields": fields_doc(fields)})

    def remove_objects(self, id: Any) -> None:  # noqa: A002
        self._changes.append({"op": "remove_objects", "fields": {"id": _array(id)}})

    def _request(self, cameras: Any, dt: float, cut: bool, outputs: list[str] | None,
                 changed_only: bool) -> dict[str, Any]:
        doc: dict[str, Any] = {"dt": float(dt), "cut": bool(cut),
                               "cameras": camera_docs(cameras), "changes": self._changes}
        self._changes = []  # sent: applied with the frame, or dropped with it
        if outputs is not None:
            doc["outputs"] = list(outputs)
        if changed_only:
            doc["changed_only"] = True
        return doc


def _headers(api_key: str | None, kind: str) -> dict[str, str]:
    h = {"Accept": kind, "Content-Type": kind}
    if api_key:
        h["Authorization"] = f"Bearer {api_key}"
    return h


def _answer(status: int, content_type: str | None, content: bytes) -> Any:
    kind = media_type(content_type) or JSON
    try:
        doc = loads(content, kind) if content else None
    except WireError:
        if status < 400:
            raise
        # Not the service's problem document: a proxy's page (HAProxy's 503 while no
        # worker is up).
        doc = {"status": status, "detail": content[:200].decode("utf-8", "replace")}
    if status >= 400:
        raise _error(status, doc)
    return doc


def _decode(response: httpx.Response) -> Any:
    return _answer(response.status_code, response.headers.get("content-type"), response.content)


# Methods whose request may be sent twice with the effect of once (RFC 9110 9.2.2).
IDEMPOTENT = frozenset({"GET", "HEAD", "PUT", "DELETE", "OPTIONS"})
# Statuses of a proxy with no worker for the request (yet): the request did not run.
UNAVAILABLE = frozenset({502, 503, 504})


def transient(e: BaseException) -> bool:
    """A failure that sending the same request again may get past: the connection broke or
    a proxy had no worker. Only requests safe to repeat (idempotent, or frames with a seq)
    are retried on it."""
    if isinstance(e, RemoteError):
        return e.status in UNAVAILABLE
    return isinstance(e, (OSError, http.client.HTTPException, ConnectionClosed))


def backoff(retry_seconds: float) -> Any:
    """The pauses between attempts: 0, 25 ms, doubling to 1 s, until retry_seconds have
    passed (then the last failure is raised)."""
    end = time.monotonic() + retry_seconds
    pause = 0.0
    while True:
        yield pause
        if time.monotonic() + pause > end:
            return
        pause = min(1.0, max(0.025, 2 * pause))


class _Connection:
    """One kept-alive HTTP/1.1 connection (http.client). An idempotent request that finds
    the connection closed (the server dropped it while idle) is sent once more on a new
    one; any other request is not: a POST may have run before the connection broke."""

    def __init__(self, url: str, headers: dict[str, str], timeout: float) -> None:
        parts = urlsplit(url)
        cls = http.client.HTTPSConnection if parts.scheme == "https" else http.client.HTTPConnection
        self._new = lambda: cls(parts.hostname or "127.0.0.1", parts.port, timeout=timeout)
        self._prefix = parts.path.rstrip("/")
        self._headers = headers
        self._conn = self._new()

    def request(self, method: str, path: str, body: bytes | None) -> Any:
        for attempt in range(2):
            try:
                self._conn.request(method, self._prefix + path, body=body, headers=self._headers)
                r = self._conn.getresponse()
                return _answer(r.status, r.getheader("content-type"), r.read())
            except (http.client.RemoteDisconnected, BrokenPipeError, ConnectionResetError):
                self._reset()
                if attempt or method not in IDEMPOTENT:
                    raise
            except (OSError, http.client.HTTPException):
                self._reset()  # e.g. refused: the next call starts on a fresh connection
                raise
        raise AssertionError("unreachable")

    def _reset(self) -> None:
        self._conn.close()
        self._conn = self._new()

    def close(self) -> None:
        self._conn.close()


def _closed(e: ConnectionClosed) -> RemoteError:
    """A stream the service closed: 1009 (message too big) is the WebSocket's 413; one
    closed without a close frame (1006: the worker or the connection died) or by a
    server going away (1001) or restarting (1012) is a 503, worth sending again."""
    code = e.rcvd.code if e.rcvd is not None else 1006
    status = 413 if code == 1009 else 503 if code in (1001, 1006, 1011, 1012) else 400
    return RemoteError(status, {"title": "Stream closed", "status": status,
                                "detail": f"the service closed the stream ({code}): {e}"})


def _ws_url(base: str, sid: str) -> str:
    return base.replace("http://", "ws://").replace("https://", "wss://").rstrip("/") + \
        f"/v1/sessions/{sid}/stream"


class Client:
    """Synchronous client; one kept-alive HTTP connection pool."""

    def __init__(self, url: str, api_key: str | None = None, encoding: str = MSGPACK,
                 timeout: float = 60.0, retry_seconds: float = 10.0) -> None:
        self.url = url.rstrip("/")
        self.api_key = api_key
        self.kind = media_type(encoding) or MSGPACK
        self.retry_seconds = retry_seconds
        self._http = _Connection(self.url, _headers(api_key, self.kind), timeout)

    def call(self, method: str, path: str, doc: Any = None) -> Any:
        """One request: ``doc`` encoded, the answer decoded; RemoteError on a refusal."""
        return self._http.request(method, path, dumps(doc, self.kind) if doc is not None else None)

    def schedule(self, lights: dict[str, Any], objects: dict[str, Any], cameras: Any,
                 config: Any = None, outputs: list[str] | None = None) -> Frame:
        """The stateless one-frame call (lightsched.schedule)."""
        return frame_of(self.call("POST", "/v1/schedule",
                                  schedule_doc(lights, objects, cameras, config, outputs)))

    def session(self, config: Any = None, stream: bool = False,
                id: str | None = None) -> RemoteScheduler:  # noqa: A002 - the wire's name
        """A session (a remote lightsched.Scheduler) of this id, or of a new random one."""
        sid = id or new_session_id()
        body = session_body(config)
        info = retrying(self.retry_seconds, lambda: self.call("PUT", f"/v1/sessions/{sid}", body))
        return RemoteScheduler(self, info, stream, body)

    def health(self) -> Any:
        return self.call("GET", "/healthz")

    def close(self) -> None:
        self._http.close()

    def __enter__(self) -> Client:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


def new_session_id() -> str:
    """A random session id: 192 bits, unguessable, as the service's own."""
    return secrets.token_urlsafe(24)


def session_body(config: Any) -> dict[str, Any]:
    return {"config": config_doc(config)} if config is not None else {}


def retrying(retry_seconds: float, call: Any) -> Any:
    """call() until it succeeds or fails other than transiently, or retry_seconds pass.
    Only for calls that are safe to repeat."""
    for pause in backoff(retry_seconds):
        time.sleep(pause)
        try:
            return call()
        except Exception as e:
            if not transient(e):
                raise
            last = e
    raise last


async def aretrying(retry_seconds: float, call: Any, *args: Any) -> Any:
    """retrying for a coroutine function."""
    for pause in backoff(retry_seconds):
        await asyncio.sleep(pause)
        try:
            return await call(*args)
        except Exception as e:
            if not transient(e):
                raise
            last = e
    raise last


def lost(e: BaseException) -> bool:
    """The session is gone from the service: its worker died (another now answers for its
    id) or it idled past the TTL (404); or the session of its id is behind the client
    (409 out-of-order: a worker taken for dead came back with the old copy)."""
    return isinstance(e, RemoteError) and (e.status == 404 or (
        e.status == 409 and str(e.problem.get("type", "")).endswith(":out-of-order")))


class _Table:
    """One kind of a session's scene (lights or objects) as the client set it: the last
    set_ call's arrays with later updates and removals folded in, so that replaying it
    costs one set_ call however many frames went by. An update naming a field the set_
    did not give (whose default may derive from other fields, as inner_angle does) is kept
    as a call of its own, and so is everything after it, until the next set_."""

    def __init__(self) -> None:
        self.base: dict[str, np.ndarray] | None = None
        self.calls: list[tuple[str, dict[str, np.ndarray]]] = []
        self._order: np.ndarray | None = None

    def apply(self, op: str, fields: dict[str, Any]) -> None:
        # Copies: the caller may reuse its arrays for the next frame.
        fields = {k: np.array(v) for k, v in fields.items()}
        if op == "set":
            self.base, self.calls, self._order = fields, [], None
        elif self.base is None or self.calls or not fields.keys() <= self.base.keys():
            self.calls.append((op, fields))
        elif op == "remove":
            keep = ~np.isin(self.base["id"], fields["id"])
            self.base = {k: v[keep] for k, v in self.base.items()}
            self._order = None
        else:
            rows = self._rows(fields["id"])
            for name, value in fields.items():
                old = self.base[name]
                new = old.astype(np.result_type(old, value))
                new[rows] = value
                self.base[name] = new

    def _rows(self, ids: np.ndarray) -> np.ndarray:
        assert self.base is not None
        if self._order is None:
            self._order = np.argsort(self.base["id"], kind="stable")
        ordered = self.base["id"][self._order]
        return self._order[np.searchsorted(ordered, ids.reshape(-1))]

    def replay(self, kind: str) -> list[dict[str, Any]]:
        out = [] if self.base is None else [{"op": f"set_{kind}", "fields": self.base}]
        return out + [{"op": f"{op}_{kind}", "fields": f} for op, f in self.calls]


class SceneMirror:
    """The scene a session holds, as far as the client gave it (lights and objects; the
    config is the session's): the changes of every frame the service answered. A session
    lost with its worker is rebuilt from it on the worker that owns the id now."""

    def __init__(self) -> None:
        self.tables = {"lights": _Table(), "objects": _Table()}

    def apply(self, changes: list[dict[str, Any]]) -> None:
        for change in changes:
            op, _, kind = change["op"].partition("_")
            self.tables[kind].apply(op, change["fields"])

    def replay(self) -> list[dict[str, Any]]:
        """The changes that rebuild the scene in an empty session."""
        return self.tables["lights"].replay("lights") + self.tables["objects"].replay("objects")


class _Session(_Changes):
    """What a session's client keeps: its id and config, the last full frame (changed_only
    answers are merged into it), the stream, once opened, and the mirror of its scene."""

    def __init__(self, client: Any, info: dict[str, Any], stream: bool,
                 body: dict[str, Any] | None = None) -> None:
        super().__init__()
        self.client = client
        self.id: str = info["id"]
        self.config: dict[str, Any] = info["config"]
        self.frame_index: int = info["frame_index"]
        self.stream = stream
        self.mirror = SceneMirror()
        self.recoveries = 0  # times the session was rebuilt on another worker
        self.closed = False  # deleted by close(): a 404 then is not a loss
        self._body = body if body is not None else {"config": info["config"]}
        self._last: Frame | None = None
        self._ws: Any = None
        self._path = f"/v1/sessions/{self.id}/frames"

    def _request(self, cameras: Any, dt: float, cut: bool, outputs: list[str] | None,
                 changed_only: bool) -> dict[str, Any]:
        doc = super()._request(cameras, dt, cut, outputs, changed_only)
        doc["seq"] = self.frame_index
        return doc

    def _rebuilt(self, doc: dict[str, Any], info: dict[str, Any]) -> dict[str, Any]:
        """The frame request for the session made again (info, from the PUT): the mirrored
        scene first, then the frame's own changes, as a cut."""
        self.recoveries += 1
        self.frame_index = info["frame_index"]
        self._last = None
        return dict(doc, changes=self.mirror.replay() + doc["changes"], cut=True,
                    seq=info["frame_index"])

    def _received(self, answer: dict[str, Any], own: list[dict[str, Any]]) -> Frame:
        """The answer to a frame whose own changes were ``own`` (applied: mirrored now)."""
        self.mirror.apply(own)
        f = frame_of(answer, self._last)
        self._last = f
        self.frame_index = f.frame_index + 1
        return f

    def _put_path(self) -> str:
        return f"/v1/sessions/{self.id}"

    def _explain_path(self, object_id: Any) -> str:
        return f"/v1/sessions/{self.id}/objects/{object_id}/explain"

    def _ws_headers(self) -> dict[str, str] | None:
        key = self.client.api_key
        return {"Authorization": f"Bearer {key}"} if key else None


def _stream_answer(raw: bytes) -> dict[str, Any]:
    answer = loads(raw, MSGPACK)
    if "frame_index" not in answer:
        raise _error(int(answer.get("status", 400)), answer)
    return answer


class RemoteScheduler(_Session):
    """A session: the methods of lightsched.Scheduler, computed by the service."""

    def __init__(self, client: Client, info: dict[str, Any], stream: bool = False,
                 body: dict[str, Any] | None = None) -> None:
        super().__init__(client, info, stream, body)
        self._stack = contextlib.ExitStack()

    def frame(self, cameras: Any, dt: float = 1.0 / 60.0, cut: bool = False,
              outputs: list[str] | None = None, changed_only: bool = False) -> Frame:
        """One frame with the changes made since the last; sent again while the service is
        unreachable (its seq keeps it from running twice), rebuilt if the session was lost
        (the module doc)."""
        doc = self._request(cameras, dt, cut, outputs, changed_only)
        own = doc["changes"]
        for pause in backoff(self.client.retry_seconds):
            time.sleep(pause)
            try:
                return self._received(self._send(doc), own)
            except Exception as e:
                if lost(e) and not self.closed:
                    doc = self._rebuilt(doc, retrying(self.client.retry_seconds, self._remake))
                elif not transient(e):
                    raise
                self._drop_stream()
                last = e
        raise last

    def _remake(self) -> dict[str, Any]:
        """The session made again, empty (a stale copy of it dropped first)."""
        with contextlib.suppress(RemoteError):
            self.client.call("DELETE", self._put_path())
        return self.client.call("PUT", self._put_path(), self._body)

    def _send(self, doc: dict[str, Any]) -> Any:
        if self.stream:
            return self._stream_call(doc)
        return self.client.call("POST", self._path, doc)

    def _drop_stream(self) -> None:
        if self._ws is not None:
            self._stack.close()
            self._ws = None

    def _stream_call(self, doc: dict[str, Any]) -> Any:
        from websockets.sync.client import connect

        if self._ws is None:
            # No permessage-deflate: arrays barely compress and deflate costs milliseconds.
            self._ws = self._stack.enter_context(
                connect(_ws_url(self.client.url, self.id), additional_headers=self._ws_headers(),
                        max_size=None, compression=None))
        ws = self._ws
        try:
            ws.send(dumps(doc, MSGPACK))
            raw = ws.recv()
        except ConnectionClosed as e:
            # A refused handshake sends its problem message, then closes: that message
            # is still buffered when the send finds the stream closed.
            try:
                raw = ws.recv(timeout=0)
            except (ConnectionClosed, TimeoutError):
                raw = None
            self._drop_stream()
            if raw is None:
                raise _closed(e) from e
        return _stream_answer(raw)

    def explain(self, object_id: int) -> Any:
        """Why each light is (not) on the object in the last frame (Scheduler.explain)."""
        return explanation_of(self.client.call("GET", self._explain_path(object_id)))

    def info(self) -> dict[str, Any]:
        return self.client.call("GET", f"/v1/sessions/{self.id}")

    def close(self, delete: bool = True) -> None:
        """Closes the stream and (by default) deletes the session."""
        self._drop_stream()
        self.closed = delete
        if delete:
            self.client.call("DELETE", f"/v1/sessions/{self.id}")


class AsyncClient:
    """The asyncio client (httpx.AsyncClient, kept-alive connections)."""

    def __init__(self, url: str, api_key: str | None = None, encoding: str = MSGPACK,
                 timeout: float = 60.0, retry_seconds: float = 10.0) -> None:
        self.url = url.rstrip("/")
        self.api_key = api_key
        self.kind = media_type(encoding) or MSGPACK
        self.retry_seconds = retry_seconds
        self._http = httpx.AsyncClient(base_url=self.url, headers=_headers(api_key, self.kind),
                                       timeout=timeout)

    async def call(self, method: str, path: str, doc: Any = None) -> Any:
        content = dumps(doc, self.kind) if doc is not None else None
        return _decode(await self._http.request(method, path, content=content))

    async def schedule(self, lights: dict[str, Any], objects: dict[str, Any], cameras: Any,
                       config: Any = None, outputs: list[str] | None = None) -> Frame:
        """The stateless one-frame call (lightsched.schedule)."""
        return frame_of(await self.call("POST", "/v1/schedule",
                                        schedule_doc(lights, objects, cameras, config, outputs)))

    async def session(self, config: Any = None, stream: bool = False,
                      id: str | None = None) -> AsyncRemoteScheduler:  # noqa: A002
        """A session of this id, or of a new random one (Client.session)."""
        body = session_body(config)
        info = await aretrying(self.retry_seconds, self.call, "PUT",
                               f"/v1/sessions/{id or new_session_id()}", body)
        return AsyncRemoteScheduler(self, info, stream, body)

    async def close(self) -> None:
        await self._http.aclose()

    async def __aenter__(self) -> AsyncClient:
        return self

    async def __aexit__(self, *exc: Any) -> None:
        await self.close()


class AsyncRemoteScheduler(_Session):
    """RemoteScheduler for asyncio: ``await s.frame(...)``."""

    def __init__(self, client: AsyncClient, info: dict[str, Any], stream: bool = False,
                 body: dict[str, Any] | None = None) -> None:
        super().__init__(client, info, stream, body)
        self._lock = asyncio.Lock()

    async def frame(self, cameras: Any, dt: float = 1.0 / 60.0, cut: bool = False,
                    outputs: list[str] | None = None, changed_only: bool = False) -> Frame:
        """RemoteScheduler.frame: sent again or rebuilt as that one is."""
        async with self._lock:  # one frame at a time: the reply order is the send order
            doc = self._request(cameras, dt, cut, outputs, changed_only)
            own = doc["changes"]
            for pause in backoff(self.client.retry_seconds):
                await asyncio.sleep(pause)
                try:
                    return self._received(await self._send(doc), own)
                except Exception as e:
                    if lost(e) and not self.closed:
                        doc = self._rebuilt(doc, await aretrying(self.client.retry_seconds,
                                                                 self._remake))
                    elif not transient(e):
                        raise
                    self._ws = None
                    last = e
            raise last

    async def _remake(self) -> dict[str, Any]:
        """RemoteScheduler._remake."""
        with contextlib.suppress(RemoteError):
            await self.client.call("DELETE", self._put_path())
        return await self.client.call("PUT", self._put_path(), self._body)

    async def _send(self, doc: dict[str, Any]) -> Any:
        if self.stream:
            return await self._stream_call(doc)
        return await self.client.call("POST", self._path, doc)

    async def _stream_call(self, doc: dict[str, Any]) -> Any:
        from websockets.asyncio.client import connect

        if self._ws is None:
            self._ws = await connect(_ws_url(self.client.url, self.id),
                                     additional_headers=self._ws_headers(), max_size=None,
                                     compression=None)
        ws = self._ws
        try:
            await ws.send(dumps(doc, MSGPACK))
            raw = await ws.recv()
        except ConnectionClosed as e:
            try:  # the refused handshake's problem message, as in RemoteScheduler
                raw = await asyncio.wait_for(ws.recv(), 0.001)
            except (ConnectionClosed, TimeoutError):
                raw = None
            self._ws = None
            if raw is None:
                raise _closed(e) from e
        return _stream_answer(raw)

    async def explain(self, object_id: int) -> Any:
        async with self._lock:  # after the frames sent before it
            return explanation_of(await self.client.call("GET", self._explain_path(object_id)))

    async def close(self, delete: bool = True) -> None:
        self.closed = delete
        if self._ws is not None:
            await self._ws.close()
            self._ws = None
        if delete:
            await self.client.call("DELETE", f"/v1/sessions/{self.id}")
