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
    ``Authorization: Bearer <key>``."""

    max_body_bytes: int = 64 * 1024 * 1024
    max_lights: int = 1_000_000
    max_objects: int = 2_000_000
    max_sessions: int = 256
    session_ttl: float = 600.0
    max_pending_frames: int = 8
    frame_threads: int = 0
    small_scene: int = 4096
    api_keys: frozenset[str] | None = field(default=None)

    @classmethod
    def from_env(cls, **overrides: object) -> Settings:
        """LIGHTSCHED_MAX_BODY_BYTES, _MAX_LIGHTS, _MAX_OBJECTS, _MAX_SESSIONS,
        _SESSION_TTL, _MAX_PENDING_FRAMES; keys from LIGHTSCHED_API_KEYS (comma-separated)
        and/or LIGHTSCHED_API_KEYS_FILE (one key per line, # comments)."""
        env = os.environ
        kw: dict[str, object] = {}
        for name, conv in (("max_body_bytes", int), ("max_lights", int), ("max_objects", int),
                           ("max_sessions", int), ("session_ttl", float),
                           ("max_pending_frames", int), ("frame_threads", int),
                           ("small_scene", int)):
            raw = env.get("LIGHTSCHED_" + name.upper())
            if raw:
                kw[name] = conv(raw)
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
