"""The service core, free of HTTP: sessions, limits, request documents in, response
documents out. app.py translates HTTP and WebSocket traffic to these calls.

A frame request runs in this order: structure check (models.py), camera and dt check,
the scene changes all or nothing (``Scheduler.apply``), the per-session size limits, the
frame. Anything refused raises a Problem and leaves the session as it was; so does a frame
that fails (a 500 problem: ``SceneAPI.transaction`` puts the session back). Frames of one
session run one at a time in arrival order (an asyncio lock, FIFO); the compute runs in a
worker thread (the numba kernels release the GIL), so different sessions run in parallel.
"""

from __future__ import annotations

import asyncio
import logging
import re
import secrets
import time
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import anyio
import numba as nb
import numpy as np
from pydantic import BaseModel
from pydantic import ValidationError as PydanticError

import lightsched as ls
from lightsched.explain import Explanation
from lightsched.fields import FRAME_FIELDS, PER_OBJECT_NAMES
from lightsched.frame import changed_rows
from lightsched.scene import validate_cameras, validate_dt

from .metrics import Metrics
from .models import FrameRequest, ScheduleRequest, SessionRequest
from .problems import Problem, invalid, not_found
from .settings import Settings

# The arrays changed_only sends by rows.
PER_OBJECT = frozenset(PER_OBJECT_NAMES)
log = logging.getLogger(__name__)
SWEEP = 1.0  # seconds between sweeps for idle sessions on lookups
# Client-chosen session ids (PUT /v1/sessions/{id}): one URL path segment without escapes,
# which a load balancer can hash as it comes; token_urlsafe's alphabet, so that the
# service's own ids (32 characters) are valid ones too.
SESSION_ID = re.compile(r"[A-Za-z0-9_-]{1,64}")
# What "changed" means for changed_only: the set, its order, weights, states and the
# residual (DESIGN's per-object outputs except priority, which moves whenever a light does
# and only orders the slots; the residual moves as often but is lighting the shader adds).
CHANGE_KEYS = tuple(name for name in PER_OBJECT_NAMES if name != "priority")


def parse(model: type[BaseModel], doc: Any) -> Any:
    """The request document checked against its model; 422 naming the first bad part."""
    if not isinstance(doc, dict):
        raise Problem(422, "validation", "Invalid input", "the request must be a map",
                      pointer="")
    try:
        return model.model_validate(doc)
    except PydanticError as e:
        err = e.errors()[0]
        loc = [str(p) for p in err["loc"]]
        names = [p for p in loc if not p.isdigit()]
        index = next((int(p) for p in reversed(loc) if p.isdigit()), None)
        raise Problem(422, "validation", "Invalid input",
                      f"{'.'.join(loc) or 'request'}: {err['msg']}",
                      field=".".join(names) or None, index=index,
                      pointer="/" + "/".join(loc)) from None


def config_of(model: Any) -> ls.Config:
    given = {} if model is None else model.model_dump(exclude_none=True)
    try:
        return ls.Config(**given)
    except ls.ValidationError as e:
        raise invalid(e, "/config") from None


def cameras_of(req: Any) -> list[ls.Camera]:
    try:
        # The models' own field maps (validate_cameras only reads them): model_dump would
        # copy each at ~5 us a camera.
        return validate_cameras([vars(c) for c in req.cameras])
    except ls.ValidationError as e:
        raise invalid(e) from None


def frame_document(f: ls.Frame, outputs: list[str] | None, frame_index: int,
                   prev: ls.Frame | None = None, stats: bool = True) -> dict[str, Any]:
    """The response map of a frame: the arrays asked for (all by default) and stats; with
    ``prev`` (changed_only), per-object arrays only for the changed rows."""
    names = FRAME_FIELDS if outputs is None else [n for n in FRAME_FIELDS if n in outputs]
    doc: dict[str, Any] = {"frame_index": frame_index, "changed_only": prev is not None}
    if prev is None:
        for name in names:
            doc[name] = getattr(f, name)
        if stats:
            doc["stats"] = f.stats
        return doc
    same_set = np.array_equal(prev.object_id, f.object_id)
    changed = changed_rows(prev, f, CHANGE_KEYS)
    rows = np.flatnonzero(changed)
    doc["rows"] = f.object_id[rows]
    for name in names:
        if name == "object_id":
            if not same_set:
                doc["object_id"] = f.object_id
        elif name in PER_OBJECT:
            doc[name] = getattr(f, name)[rows]
        else:
            doc[name] = getattr(f, name)
    if stats:
        doc["stats"] = f.stats
    return doc


def explanation_document(e: Explanation) -> dict[str, Any]:
    """The response map of an explanation: object_id, frame_index and its columns
    (fields.EXPLAIN_FIELDS; reason as a list of strings)."""
    doc: dict[str, Any] = {"object_id": e.object_id, "frame_index": e.frame_index}
    doc.update(e.columns())
    doc["reason"] = list(e.reason)
    return doc


class StreamTicket(NamedTuple):
    """What a stream ticket stands for: its session, the key that made it, and when it
    expires (time.monotonic())."""

    sid: str
    owner: str | None
    expires: float


@dataclass
class Session:
    id: str
    owner: str | None
    scheduler: ls.Scheduler
    lock: asyncio.Lock = field(default_factory=asyncio.Lock)
    pending: int = 0
    last_used: float = field(default_factory=time.monotonic)
    prev: ls.Frame | None = None
    # The last frame's answer document, for a retried request of the same seq: encoding it
    # again gives the same bytes.
    answer: dict[str, Any] | None = None

    def info(self) -> dict[str, Any]:
        s = self.scheduler
        return {"id": self.id, "config": s.config.to_dict(), "frame_index": s.frame_index,
                "lights": len(s.lights), "objects": len(s.objects),
                "idle_seconds": time.monotonic() - self.last_used}


class Service:
    """Sessions and the calls of the API, on decoded request documents."""

    def __init__(self, settings: Settings | None = None) -> None:
        self.settings = settings or Settings()
        self.sessions: dict[str, Session] = {}
        self.metrics = Metrics()
        self._swept = -float("inf")
        self.tickets: dict[str, StreamTicket] = {}

    # ------------------------------------------------------------------ sessions
    def _idle(self, s: Session, now: float) -> bool:
        return s.pending == 0 and now - s.last_used > self.settings.session_ttl

    def evict_idle(self) -> None:
        now = self._swept = time.monotonic()
        for sid in [k for k, s in self.sessions.items() if self._idle(s, now)]:
            del self.sessions[sid]

    def create_session(self, doc: Any, owner: str | None, sid: str | None = None) -> Session:
        self.evict_idle()
        req = parse(SessionRequest, doc if doc is not None else {})
        config = config_of(req.config)
        if len(self.sessions) >= self.settings.max_sessions:
            raise Problem(429, "too-many-sessions", "Too many sessions",
                          f"the service holds at most {self.settings.max_sessions} sessions",
                          headers={"Retry-After": "1"})
        sid = sid or secrets.token_urlsafe(24)  # 192 random bits: unguessable
        session = self.sessions[sid] = Session(sid, owner, ls.Scheduler(config))
        return session

    def put_session(self, sid: str, doc: Any, owner: str | None) -> tuple[Session, bool]:
        """PUT /v1/sessions/{id}: the session of this id, created if it does not exist
        (True) or returned as it is (False: retrying a PUT is safe). Sharded services route
        by the id, so the client chooses it; a live session of this id with another config
        or another key is a conflict (409), not something to overwrite."""
        if SESSION_ID.fullmatch(sid) is None:
            bad = next((i for i, ch in enumerate(sid) if SESSION_ID.fullmatch(ch) is None), 64)
            raise Problem(422, "validation", "Invalid input",
                          f"id: a session id is 1 to 64 characters of A-Z, a-z, 0-9, '_' and "
                          f"'-' (first bad character at {bad})", field="id", index=bad,
                          pointer="/id")
        req = parse(SessionRequest, doc if doc is not None else {})
        s = self.sessions.get(sid)
        if s is not None and self._idle(s, time.monotonic()):
            del self.sessions[sid]
            s = None
        if s is None:
            return self.create_session(doc, owner, sid), True
        if s.owner != owner or config_of(req.config).to_dict() != s.scheduler.config.to_dict():
            raise Problem(409, "session-conflict", "Session exists",
                          f"session {sid!r} exists with another config or key", field="id",
                          pointer="/id")
        s.last_used = time.monotonic()
        return s, False

    def session(self, sid: str, owner: str | None) -> Session:
        # A frame looks its session up twice: sweeping every session each time would cost
        # ~0.1 us per live session. The one asked for is checked now, the others at most
        # every SWEEP seconds (and on every create_session, which counts them).
        now = time.monotonic()
        if now - self._swept > SWEEP:
            self.evict_idle()
        s = self.sessions.get(sid)
        if s is not None and self._idle(s, now):
            del self.sessions[sid]
            s = None
        # Another key's session is as invisible as one that does not exist.
        if s is None or s.owner != owner:
            raise not_found(f"no session {sid!r}")
        s.last_used = time.monotonic()
        return s

    def delete_session(self, sid: str, owner: str | None) -> None:
        self.session(sid, owner)
        del self.sessions[sid]

    # ------------------------------------------------------------------ stream tickets
    def issue_ticket(self, sid: str, owner: str | None) -> dict[str, Any]:
        """A one-use ticket that opens the session's stream without the key, for browsers
        (whose WebSocket cannot carry an Authorization header); it is redeemable for
        ticket_ttl seconds. A session holds at most max_pending_frames + 8 live tickets (429
        above), so a leaked key cannot fill the service's memory with them."""
        self.session(sid, owner)
        now = time.monotonic()
        self.tickets = {t: v for t, v in self.tickets.items() if v.expires > now}
        live = sum(1 for v in self.tickets.values() if v.sid == sid)
        if live >= self.settings.max_pending_frames + 8:
            raise Problem(429, "too-many-tickets", "Too many tickets",
                          f"session {sid!r} already has {live} unused tickets",
                          headers={"Retry-After": str(int(self.settings.ticket_ttl) + 1)})
        ticket = secrets.token_urlsafe(24)
        self.tickets[ticket] = StreamTicket(sid, owner, now + self.settings.ticket_ttl)
        return {"ticket": ticket, "expires_in": self.settings.ticket_ttl}

    def redeem_ticket(self, sid: str, ticket: str) -> str | None:
        """The owner key a ticket stands for, once: 401 if it is unknown, used, expired or
        another session's."""
        entry = self.tickets.pop(ticket, None)
        if entry is None or entry.sid != sid or entry.expires <= time.monotonic():
            raise Problem(401, "unauthorized", "Unauthorized",
                          "the ticket is unknown, used, expired or for another session; "
                          "get a new one with POST /v1/sessions/{id}/tickets")
        return entry.owner

    # ------------------------------------------------------------------ frames
    async def frame(self, sid: str, owner: str | None, doc: Any) -> dict[str, Any]:
        """One frame request of a session: changes, then the frame (see the module doc)."""
        s = self.session(sid, owner)
        req = parse(FrameRequest, doc)
        cams = cameras_of(req)
        try:
            dt = validate_dt(req.dt)
        except ls.ValidationError as e:
            raise invalid(e) from None
        if s.pending >= self.settings.max_pending_frames:
            raise Problem(429, "session-busy", "Session busy",
                          f"{s.pending} frames of session {sid!r} are already waiting",
                          headers={"Retry-After": "0"})
        s.pending += 1
        try:
            async with s.lock:
                if req.seq is not None and req.seq != s.scheduler.frame_index:
                    return self._repeated(s, req.seq)
                if self._small(s.scheduler, req):
                    return self._step(s, req, cams, dt)
                return await anyio.to_thread.run_sync(self._step, s, req, cams, dt)
        finally:
            s.pending -= 1
            s.last_used = time.monotonic()

    def _repeated(self, s: Session, seq: int) -> dict[str, Any]:
        """The answer to a request whose seq is not the next frame's: the last answer again
        for the last frame's seq (its first answer was lost on the way back), else 409."""
        last = s.scheduler.frame_index - 1
        if seq == last and s.answer is not None and s.answer["frame_index"] == last:
            return s.answer
        raise Problem(409, "out-of-order", "Frame out of order",
                      f"seq {seq}: the next frame of session {s.id!r} is {last + 1} (a "
                      f"repeat of {last} gets its answer again)", field="seq", pointer="/seq")

    def _step(self, s: Session, req: Any, cams: list[ls.Camera], dt: float) -> dict[str, Any]:
        sched = s.scheduler
        try:
            # The changes and the frame, all or nothing: whatever stops them (a refusal or a
            # fault of the frame itself) leaves the scene, the fade state and the frame index
            # as they were; s.prev is set only below.
            with sched.transaction():
                try:
                    sched.apply([(c.op, c.fields) for c in req.changes])
                except ls.ValidationError as e:
                    raise invalid(e) from None
                limits = self.settings
                for what, n, cap in (("lights", len(sched.lights), limits.max_lights),
                                     ("objects", len(sched.objects), limits.max_objects)):
                    if n > cap:
                        raise Problem(413, "too-large", "Scene too large",
                                      f"a session holds at most {cap} {what}; this frame "
                                      f"would make {n}", field=what)
                f = self._run_frame(sched, cams, dt, req.cut)
        except Problem:
            raise
        except Exception as e:
            # A fault, not the request's: logged with its traceback for the operator, and
            # answered as a problem document so that the session (unchanged) and a stream
            # carry on.
            log.exception("frame of session %s failed; the session is as it was", s.id)
            raise Problem(500, "internal", "Internal error",
                          f"the frame failed ({type(e).__name__}); nothing in the session "
                          "changed") from e
        self.metrics.observe_frame(f.stats)
        doc = frame_document(f, req.outputs, sched.frame_index - 1,
                             s.prev if req.changed_only else None, req.stats)
        s.prev, s.answer = f, doc
        return doc

    def _small(self, sched: ls.Scheduler, req: Any) -> bool:
        """A frame small enough to run on the event loop: below small_scene objects (before
        and after its changes, as far as set_objects tells) it is mostly GIL-holding Python
        around short kernels, so a worker thread would not run it beside other sessions,
        and the hop there and back costs about as much as the frame. (Measured with
        bench/load.py at 1k objects and 10-18 clients: on worker threads, with one numba
        thread each, a frame's compute p50 went from 0.55 ms to 10-20 ms, waiting for the
        loop's GIL after every kernel, and the server answered ~40% fewer frames.)"""
        limit = self.settings.small_scene
        if len(sched.objects) >= limit:
            return False
        return not any(c.op == "set_objects" and _rows(c.fields) >= limit for c in req.changes)

    def _run_frame(self, sched: ls.Scheduler, cams: list[ls.Camera], dt: float,
                   cut: bool) -> ls.Frame:
        """sched.frame with this worker thread's numba thread count set (numba's count is
        per calling thread): Settings.frame_threads, or by scene size."""
        n = self.settings.frame_threads or (
            1 if len(sched.objects) < self.settings.small_scene else nb.config.NUMBA_NUM_THREADS)
        nb.set_num_threads(min(n, nb.config.NUMBA_NUM_THREADS))
        return sched.frame(cams, dt=dt, cut=cut)

    async def explain(self, sid: str, owner: str | None, object_id: Any) -> dict[str, Any]:
        """GET .../objects/{object_id}/explain: Scheduler.explain for the session's last
        frame, as a map of its columns (after the session's queued frames)."""
        s = self.session(sid, owner)
        async with s.lock:
            try:
                return explanation_document(s.scheduler.explain(object_id))
            except ls.ValidationError as e:
                raise invalid(e) from None

    async def schedule(self, doc: Any) -> dict[str, Any]:
        """POST /v1/schedule: the stateless one-frame call."""
        req = parse(ScheduleRequest, doc)
        config = config_of(req.config)
        cams = cameras_of(req)
        for what, n, cap in (("lights", _rows(req.lights), self.settings.max_lights),
                             ("objects", _rows(req.objects), self.settings.max_objects)):
            if n > cap:
                raise Problem(413, "too-large", "Scene too large",
                              f"at most {cap} {what} per request, got {n}", field=what)

        def run() -> dict[str, Any]:
            # ls.schedule's steps, so that an error points into lights or objects.
            sched = ls.Scheduler(config)
            for base, call, given in (("/lights", sched.set_lights, req.lights),
                                      ("/objects", sched.set_objects, req.objects)):
                try:
                    call(**given)
                except ls.ValidationError as e:
                    raise invalid(e, base) from None
            f = self._run_frame(sched, cams, 0.0, True)
            self.metrics.observe_frame(f.stats)
            return frame_document(f, req.outputs, 0, stats=req.stats)

        return await anyio.to_thread.run_sync(run)


def _rows(fields: dict[str, Any]) -> int:
    ids = fields.get("id")
    try:
        return len(ids) if ids is not None else 0
    except TypeError:
        return 0


__all__ = ["Service", "Session", "frame_document", "parse"]
