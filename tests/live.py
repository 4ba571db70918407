"""A real LightSched server for the tests: lightsched_server's ServerThread, uvicorn on a
free port of 127.0.0.1 in a background thread of the test process."""

from lightsched_server.app import ServerThread as LiveServer

__all__ = ["LiveServer"]
