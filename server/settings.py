"""Service limits and access, from keyword arguments or LIGHTSCHED_* environment variables."""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path


@dataclass(frozen=True)
class Settings:
    """max_body_bytes: largest request body (413 above). max_lights / max_objects: per
    session (413 above). max_sessions: live sessions (429 above). session_ttl: seconds a
    session may stay idle before it is dropped. max_pending_frames: frames of one session
    waiting for it (they run in arrival order; 429 above). frame_threads: numba threads
    per frame; 0 picks one thread below small_scene objects (waking a second core costs a
    small frame more in latency tails than it saves, and sessions run side by side anyway)
    and every thread above. api_keys: when set, every /v1 call needs
    ``Authorization: Bearer <key>``. cors_origins: the web origins (``scheme://host[:port]``,
    or ``*`` for any) whose pages may call the service (CORS) and open its streams; none by
    default, and a page of the service's own origin always may. ticket_ttl: seconds a stream
    ticket (POST /v1/sessions/{id}/tickets, for browsers, which cannot send a key on a
    WebSocket) stays redeemable."""

    max_body_bytes: int = 64 * 1024 * 1024
    max_lights: int = 1_000_000
    max_objects: int = 2_000_000
    max_sessions: int = 256
    session_ttl: float = 600.0
    max_pending_frames: int = 8
    frame_threads: int = 0
    small_scene: int = 4096
    api_keys: frozenset[str] | None = field(default=None)
    cors_origins: tuple[str, ...] = ()
    ticket_ttl: float = 30.0

    @classmethod
    def from_env(cls, **overrides: object) -> Settings:
        """LIGHTSCHED_MAX_BODY_BYTES, _MAX_LIGHTS, _MAX_OBJECTS, _MAX_SESSIONS,
        _SESSION_TTL, _MAX_PENDING_FRAMES, _FRAME_THREADS, _SMALL_SCENE, _TICKET_TTL;
        LIGHTSCHED_CORS_ORIGINS (comma-separated); keys from LIGHTSCHED_API_KEYS
        (comma-separated) and/or LIGHTSCHED_API_KEYS_FILE (one key per line, # comments)."""
        env = os.environ
        kw: dict[str, object] = {}
        for name, conv in (("max_body_bytes", int), ("max_lights", int), ("max_objects", int),
                           ("max_sessions", int), ("session_ttl", float),
                           ("max_pending_frames", int), ("frame_threads", int),
                           ("small_scene", int), ("ticket_ttl", float)):
            raw = env.get("LIGHTSCHED_" + name.upper())
            if raw:
                kw[name] = conv(raw)
        origins = [o.strip().rstrip("/") for o in env.get("LIGHTSCHED_CORS_ORIGINS", "").split(",")]
        if any(origins):
            kw["cors_origins"] = tuple(o for o in origins if o)
        keys = {k.strip() for k in env.get("LIGHTSCHED_API_KEYS", "").split(",") if k.strip()}
        path = env.get("LIGHTSCHED_API_KEYS_FILE")
        if path:
            for line in Path(path).read_text().splitlines():
                line = line.split("#", 1)[0].strip()
                if line:
                    keys.add(line)
        if keys:
            kw["api_keys"] = frozenset(keys)
        kw.update(overrides)
        return cls(**kw)  # type: ignore[arg-type]
