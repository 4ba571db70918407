"""The LightSched service: HTTP/msgpack and WebSocket routes (app.py) over a core of
sessions and limits (service.py) that calls the embedded lightsched API. Import name
lightsched_server; ``lightsched serve`` runs it."""

from .app import create_app, serve
from .settings import Settings

__all__ = ["Settings", "create_app", "serve"]
