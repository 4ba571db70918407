"""A real LightSched server for the tests: uvicorn on a free port of 127.0.0.1, in a
background thread of the test process, with the options ``lightsched serve`` uses."""

from __future__ import annotations

import socket
import threading
import time

import uvicorn
from lightsched_server import Settings, create_app
from lightsched_server.app import uvicorn_options


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class LiveServer:
    def __init__(self, settings: Settings | None = None, demo: bool = False) -> None:
        self.settings = settings or Settings()
        self.app = create_app(self.settings, demo=demo)
        self.service = self.app.state.service
        self.port = free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        config = uvicorn.Config(self.app, host="127.0.0.1", port=self.port, log_level="warning",
                                **uvicorn_options(self.settings))
        self.server = uvicorn.Server(config)
        self.thread = threading.Thread(target=self.server.run, daemon=True)
        self.thread.start()
        deadline = time.monotonic() + 30
        while not self.server.started:
            if time.monotonic() > deadline or not self.thread.is_alive():
                raise RuntimeError("the test server did not start")
            time.sleep(0.01)

    def stop(self) -> None:
        self.server.should_exit = True
        self.thread.join(timeout=10)
