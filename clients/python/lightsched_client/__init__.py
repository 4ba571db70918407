"""Python client of the LightSched service (import name lightsched_client).

``Client(url, api_key=None)`` mirrors the embedded API: ``.schedule(...)`` and
``.session(config)`` (a RemoteScheduler with lightsched.Scheduler's methods); AsyncClient is
the asyncio version. wire.py is the wire format, shared with the server.
"""

from .client import (
    AsyncClient,
    AsyncRemoteScheduler,
    Client,
    Explanation,
    Frame,
    RemoteError,
    RemoteScheduler,
    ValidationError,
)

__all__ = ["AsyncClient", "AsyncRemoteScheduler", "Client", "Explanation", "Frame",
           "RemoteError", "RemoteScheduler", "ValidationError"]
__version__ = "0.1.0"
