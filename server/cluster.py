"""HAProxy (Debian's package) in front of N ``lightsched serve`` workers on this machine,
with deploy/haproxy.cfg: what ``make cluster`` runs, and what the cluster tests and
bench/load.py --workers start.

    python -m lightsched_server.cluster [--workers 2] [--port 8080]

Each worker is its own process (its own event loop and GIL: one process's event loop is
the limit of one worker, bench/RESULTS.md), on a free port of 127.0.0.1; HAProxy listens on
``--port`` and routes each session by its id.
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
import urllib.request
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
CONFIG = REPO / "deploy" / "haproxy.cfg"
# The worker lines of deploy/haproxy.cfg, rewritten for the cluster's workers.
_SERVER = re.compile(r"^(\s+server )w\d+ \S+ (check|track \w+/)w?\d*\s*$")


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def haproxy_config(ports: list[int], text: str | None = None) -> str:
    """deploy/haproxy.cfg with one server line per worker port in each backend, in place
    of the file's own."""
    out: list[str] = []
    for line in (text if text is not None else CONFIG.read_text()).splitlines():
        m = _SERVER.match(line)
        if m is None:
            out.append(line)
            continue
        if out and _SERVER.match(out[-1]) is not None:
            continue  # the backend's workers were written at its first server line
        for i, port in enumerate(ports, 1):
            how = "check" if m.group(2) == "check" else f"{m.group(2)}w{i}"
            out.append(f"{m.group(1)}w{i} 127.0.0.1:{port} {how}")
    return "\n".join(out) + "\n"


def wait_healthy(url: str, timeout: float, process: subprocess.Popen | None = None) -> None:
    deadline = time.monotonic() + timeout
    while True:
        try:
            with urllib.request.urlopen(url + "/healthz", timeout=2) as r:
                if r.status == 200:
                    return
        except OSError:
            pass
        if process is not None and process.poll() is not None:
            raise RuntimeError(f"{process.args[0]} exited ({process.returncode}) before "
                               f"{url} answered")
        if time.monotonic() > deadline:
            raise RuntimeError(f"{url} did not answer /healthz within {timeout} s")
        time.sleep(0.05)


class Cluster:
    """HAProxy on ``port`` (0: a free one) of 127.0.0.1 in front of ``workers`` processes of
    ``python -m lightsched serve --no-demo``. ``warm_up`` False opens the workers' ports at
    once (their first frames then load the kernels: fine when numba's cache is filled).
    ``env`` is added to the workers' environment (LIGHTSCHED_* settings)."""

    def __init__(self, workers: int = 2, port: int = 0, warm_up: bool = True,
                 env: dict[str, str] | None = None, timeout: float = 600.0,
                 log_level: str = "warning") -> None:
        haproxy = shutil.which("haproxy") or "/usr/sbin/haproxy"
        if not Path(haproxy).exists():
            raise RuntimeError("haproxy is not installed (Debian: apt-get install haproxy; "
                               "`make cluster-deps` does)")
        self.port = port or free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        self.ports = [free_port() for _ in range(workers)]
        self.workers: list[subprocess.Popen] = []
        self._dir = tempfile.TemporaryDirectory(prefix="lightsched-cluster-")
        worker_env = {**os.environ, **(env or {})}
        try:
            for p in self.ports:
                cmd = [sys.executable, "-m", "lightsched", "serve", "--no-demo", "--host",
                       "127.0.0.1", "--port", str(p), "--log-level", log_level]
                if not warm_up:
                    cmd.append("--no-warm-up")
                self.workers.append(subprocess.Popen(cmd, env=worker_env,
                                                     stdout=subprocess.DEVNULL))
            for p, w in zip(self.ports, self.workers, strict=True):
                wait_healthy(f"http://127.0.0.1:{p}", timeout, w)
            cfg = Path(self._dir.name) / "haproxy.cfg"
            cfg.write_text(haproxy_config(self.ports))
            self.haproxy = subprocess.Popen(
                [haproxy, "-db", "-f", str(cfg)], stdout=subprocess.DEVNULL,
                env={**os.environ, "LIGHTSCHED_BIND": f"127.0.0.1:{self.port}"})
            wait_healthy(self.url, 30, self.haproxy)
        except BaseException:
            self.stop()
            raise

    def worker_url(self, i: int) -> str:
        return f"http://127.0.0.1:{self.ports[i]}"

    def kill(self, i: int) -> None:
        """Worker i dies at once (SIGKILL by its pid: no goodbye to its clients)."""
        os.kill(self.workers[i].pid, signal.SIGKILL)
        self.workers[i].wait()

    def stop(self) -> None:
        procs = [*self.workers, *([self.haproxy] if hasattr(self, "haproxy") else [])]
        for p in procs:
            if p.poll() is None:
                p.terminate()
        for p in procs:
            try:
                p.wait(timeout=10)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()
        self._dir.cleanup()

    def __enter__(self) -> Cluster:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--workers", type=int, default=2, help="lightsched serve processes (2)")
    ap.add_argument("--port", type=int, default=8080, help="HAProxy's port (8080)")
    args = ap.parse_args(argv)
    with Cluster(args.workers, args.port, log_level="info") as c:
        print(f"HAProxy on {c.url} in front of {args.workers} workers on ports "
              f"{', '.join(map(str, c.ports))}; Ctrl-C stops them", flush=True)
        try:
            c.haproxy.wait()
        except KeyboardInterrupt:
            pass
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
