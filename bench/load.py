"""Load test: M simulated 60 fps game clients against one real LightSched server.

    python bench/load.py                  # 1k and 10k objects, M = 1, 8, 32, 64, HTTP and WebSocket
    python bench/load.py --quick          # 1k objects, M = 1, 8, 32, 2 s each (under 30 s)
    python bench/load.py --clients 4,16 --sizes 1k --transports ws --duration 10
    python bench/load.py --write          # also bench/RESULTS.md and bench/plots/load.png
    python bench/load.py --workers 2      # through HAProxy in front of 2 server processes

Starts the server (``python -m lightsched serve --no-demo``, uvicorn, one process) on a free
port of 127.0.0.1 and stops it at the end, also on Ctrl-C; with ``--workers N``, N of them
behind HAProxy (deploy/haproxy.cfg, lightsched_server.cluster), sessions routed by id.
Each client is one session with its own ``lightsched.scenes.city(N, N/10, seed + client)``;
per frame it sends the moving lights (``update_lights`` with every light's new position,
``move_lights``) and waits for the whole frame (msgpack both ways), paced at 60 fps on an absolute schedule:

- slot i of a client is due at t0 + phase + i/60 (phase: a random offset in [0, 1/60) per
  client, or 0 for all with ``--phase aligned``); the client sleeps until then and sends;
- a client has at most one frame in flight; an answer later than due + 1/60 is *late*;
- when the answer comes, the next frame goes at the first slot not yet due: slots whose due
  time passed while waiting are *skipped* (a late answer always skips at least one);
- missed = late + skipped + refused/failed, over the slots due in the measured window
  (after ``--warmup`` seconds, for ``--duration`` seconds).

The clients are asyncio coroutines in ``--procs`` worker processes (uvloop; raw asyncio
streams for HTTP/1.1 keep-alive, the websockets library for the stream), not locust: see
bench/README.md ("Load test") for why. They share the machine's cores with the server, so
the table also gives their CPU.
"""

from __future__ import annotations

import argparse
import asyncio
import math
import multiprocessing as mp
import os
import secrets
import shlex
import signal
import socket
import subprocess
import sys
import tempfile
import time
import urllib.request
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import psutil
from common import (
    PLOTS,
    SERVER_START_TIMEOUT,
    fmt_count,
    git_commit,
    machine,
    markers,
    parse_count,
    say,
    write_results,
)

from lightsched.scenes import city, move_lights

try:
    from lightsched_client.client import _Changes
    from lightsched_client.wire import dumps, loads
except ImportError as e:  # pragma: no cover - environment problem
    sys.exit(f"bench/load.py needs the client package (pip install -e '.[server]'): {e}")

HERE = Path(__file__).resolve().parent
BEGIN, END = markers("load.py")
PERIOD = 1.0 / 60.0
TRANSPORTS = {"http": "HTTP", "ws": "WebSocket"}
MISS_OK = 1.0  # % missed deadlines a box may have and still "hold" its clients
MSGPACK = "application/msgpack"
IDLE = 0.15  # the machine counts as idle under 15% busy (all cores)
BUSY_MARK = 25.0  # other processes' CPU (% of one core) over which a case is marked "*"


# ---------------------------------------------------------------------------- the server
def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class Server:
    """``python -m lightsched serve`` on a free port (as bench/service.py); ``stop()``
    terminates, then kills."""

    def __init__(self, env: dict[str, str], timeout: float = SERVER_START_TIMEOUT) -> None:
        self.port = free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        self.log = tempfile.TemporaryFile()
        cmd = [sys.executable, "-m", "lightsched", "serve", "--host", "127.0.0.1",
               "--port", str(self.port), "--no-demo", "--log-level", "warning"]
        self.proc = subprocess.Popen(cmd, cwd=HERE.parent, stdout=self.log,
                                     stderr=subprocess.STDOUT, env={**os.environ, **env})
        try:
            self._wait(timeout)
        except BaseException:  # Ctrl-C or a failed start: no server left behind
            self.stop()
            raise

    def _wait(self, timeout: float) -> None:
        deadline = time.monotonic() + timeout
        while True:
            if self.proc.poll() is not None:
                raise RuntimeError(f"the server exited with {self.proc.returncode}:\n"
                                   + self.output())
            try:
                with urllib.request.urlopen(self.url + "/healthz", timeout=1.0) as r:
                    if r.status == 200:
                        return
            except OSError:
                pass
            if time.monotonic() > deadline:
                raise RuntimeError(f"the server did not answer /healthz in {timeout:.0f} s:\n"
                                   + self.output())
            time.sleep(0.1)

    def output(self) -> str:
        self.log.seek(0)
        return self.log.read().decode(errors="replace")

    def pids(self) -> list[int]:
        """The processes that serve the frames."""
        return [self.proc.pid]

    lb_pid: int | None = None  # a load balancer's process, if one is in front

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(10)
        self.log.close()


class ClusterServer:
    """HAProxy in front of ``workers`` server processes (lightsched_server.cluster), with
    Server's interface."""

    def __init__(self, env: dict[str, str], workers: int,
                 timeout: float = SERVER_START_TIMEOUT) -> None:
        from lightsched_server.cluster import Cluster

        self.cluster = Cluster(workers, env=env, timeout=timeout)
        self.port = self.cluster.port
        self.url = self.cluster.url
        self.lb_pid = self.cluster.haproxy.pid

    def pids(self) -> list[int]:
        return [w.pid for w in self.cluster.workers]

    def stop(self) -> None:
        self.cluster.stop()


def start_server(env: dict[str, str], workers: int) -> Server | ClusterServer:
    return ClusterServer(env, workers) if workers else Server(env)


# ---------------------------------------------------------------------------- client side
class HttpLink:
    """HTTP/1.1 on one kept-alive asyncio stream: the least client CPU per request (httpx
    costs several times more per call, and this box's cores are shared with the server)."""

    def __init__(self, port: int) -> None:
        self.port = port
        self.r: asyncio.StreamReader | None = None
        self.w: asyncio.StreamWriter | None = None

    async def open(self) -> None:
        self.r, self.w = await asyncio.open_connection("127.0.0.1", self.port, limit=1 << 22)

    async def call(self, method: str, path: str, body: bytes = b"") -> tuple[int, bytes, float]:
        """(status, body, the server's own ms from its Server-Timing header, else nan)"""
        assert self.r is not None and self.w is not None
        head = (f"{method} {path} HTTP/1.1\r\nHost: 127.0.0.1:{self.port}\r\n"
                f"Content-Type: {MSGPACK}\r\nAccept: {MSGPACK}\r\n"
                f"Content-Length: {len(body)}\r\n\r\n").encode()
        self.w.write(head + body)
        await self.w.drain()
        raw = await self.r.readuntil(b"\r\n\r\n")
        lines = raw.decode("latin-1").split("\r\n")
        status = int(lines[0].split(" ", 2)[1])
        size, server = 0, float("nan")
        for line in lines[1:]:
            name, _, value = line.partition(":")
            name = name.strip().lower()
            if name == "content-length":
                size = int(value)
            elif name == "server-timing":
                server = sum(float(part.split("dur=", 1)[1]) for part in value.split(",")
                             if "dur=" in part)
            elif name == "transfer-encoding":
                raise RuntimeError(f"unexpected Transfer-Encoding {value.strip()!r}")
        return status, (await self.r.readexactly(size) if size else b""), server

    async def close(self) -> None:
        if self.w is not None:
            self.w.close()
            try:
                await self.w.wait_closed()
            except OSError:
                pass


@dataclass
class ClientSpec:
    index: int  # client number in the case; its scene seed is seed + index
    phase: float  # seconds added to t0 for its slot 0


@dataclass
class ClientResult:
    slots: int = 0  # slots due in the measured window
    sent: int = 0
    answered: int = 0  # 200 answers to frames due in the window
    late: int = 0  # answered after due + 1/60
    failed: int = 0  # refused (non-200), or no answer (the connection failed)
    latency: list[float] = field(default_factory=list)  # ms, send to answer decoded
    lag: list[float] = field(default_factory=list)  # ms, send - due (the harness's own delay)
    compute: list[float] = field(default_factory=list)  # ms, stats.seconds.total
    server: list[float] = field(default_factory=list)  # ms, Server-Timing sum (HTTP only)
    error: str = ""


def window_slots(base: float, w0: float, w1: float) -> int:
    """How many of i = 0, 1, ... have w0 <= base + i * PERIOD < w1."""
    def first_at(t: float) -> int:
        return max(0, math.ceil((t - base) / PERIOD - 1e-9))
    return first_at(w1) - first_at(w0)


class Game:
    """One simulated game client: its session, scene and connection."""

    def __init__(self, port: int, spec: ClientSpec, n: int, seed: int, transport: str,
                 changed_only: bool) -> None:
        self.port = port
        self.spec = spec
        self.scene = city(n, max(1, n // 10), seed=seed + spec.index)
        self.transport = transport
        self.changed_only = changed_only
        self.http = HttpLink(port)
        self.ws: Any = None
        self.sid = ""

    async def setup(self) -> None:
        await self.http.open()
        # The client's own id (PUT), which a load balancer routes by.
        sid = secrets.token_urlsafe(24)
        status, data, _ = await self.http.call("PUT", f"/v1/sessions/{sid}", dumps({}, MSGPACK))
        if status != 201:
            raise RuntimeError(f"PUT /v1/sessions/{sid}: {status} {loads(data, MSGPACK)}")
        self.sid = sid
        self.path = f"/v1/sessions/{self.sid}/frames"
        if self.transport == "ws":
            from websockets.asyncio.client import connect

            self.ws = await connect(f"ws://127.0.0.1:{self.port}/v1/sessions/{self.sid}/stream",
                                    max_size=None, compression=None)
        # Frame 0 loads the scene (not timed).
        ch = _Changes()
        ch.set_lights(**self.scene.lights)
        ch.set_objects(**self.scene.objects)
        status, doc, _ = await self.exchange(dumps(ch._request(self.scene.cameras, PERIOD, False,
                                                               None, False), MSGPACK))
        if status != 200:
            raise RuntimeError(f"loading the scene: {status} {doc}")

    async def exchange(self, body: bytes) -> tuple[int, Any, float]:
        """One frame: (status, the decoded answer, the server's ms or nan)."""
        if self.ws is not None:
            await self.ws.send(body)
            doc = loads(await self.ws.recv(), MSGPACK)
            return (200 if "frame_index" in doc else int(doc.get("status", 400))), doc, math.nan
        status, data, server = await self.http.call("POST", self.path, body)
        return status, loads(data, MSGPACK), server

    def request(self, slot: int) -> bytes:
        """The frame request of ``slot``: every light at its position at that frame."""
        ch = _Changes()
        ch.update_lights(id=self.scene.lights["id"], position=move_lights(self.scene.lights,
                                                                          slot + 1))
        return dumps(ch._request(self.scene.cameras, PERIOD, False, None, self.changed_only),
                     MSGPACK)

    async def play(self, t0: float, w0: float, w1: float) -> ClientResult:
        """Slots until w1 on the absolute 60 fps schedule; what happened in [w0, w1)."""
        base = t0 + self.spec.phase
        res = ClientResult(slots=window_slots(base, w0, w1))
        clock = time.monotonic
        i = 0
        while True:
            due = base + i * PERIOD
            if due >= w1:
                break
            # uvloop's timers have 1 ms resolution: sleep again if woken early.
            while (wait := due - clock()) > 2e-4:
                await asyncio.sleep(wait)
            body = self.request(i)
            sent = clock()
            measured = due >= w0
            try:
                status, doc, server = await self.exchange(body)
            except Exception as e:  # the connection failed: this client stops here
                if measured:
                    res.sent += 1
                    res.failed += 1
                res.error = f"{type(e).__name__}: {e}"
                break
            got = clock()
            if measured:
                res.sent += 1
                if status != 200:
                    res.failed += 1
                    res.error = res.error or f"{status} {doc.get('title', '')}: " \
                                             f"{doc.get('detail', '')}"
                else:
                    res.answered += 1
                    res.late += got > due + PERIOD
                    res.latency.append((got - sent) * 1e3)
                    res.lag.append((sent - due) * 1e3)
                    res.compute.append(float(doc["stats"]["seconds"]["total"]) * 1e3)
                    res.server.append(server)
            # The next slot not yet due; the ones that passed while waiting are skipped.
            i = max(i + 1, math.floor((got - base) / PERIOD) + 1)
        return res

    async def close(self) -> None:
        if self.ws is not None:
            await self.ws.close()
        try:
            if self.sid:
                await self.http.call("DELETE", f"/v1/sessions/{self.sid}")
        finally:
            await self.http.close()


async def worker_case(conn: Any, case: dict[str, Any]) -> None:
    """One case in a worker: set up its clients, report ready, wait for the start time, run,
    tear down, send the results."""
    loop = asyncio.get_running_loop()
    games = [Game(case["port"], s, case["n"], case["seed"], case["transport"], case["changed_only"])
             for s in case["specs"]]
    try:
        await asyncio.gather(*(g.setup() for g in games))
        conn.send(("ready", None))
        msg, times = await loop.run_in_executor(None, conn.recv)
        assert msg == "go"
        t0, w0, w1 = times
        results = await asyncio.wait_for(asyncio.gather(*(g.play(t0, w0, w1) for g in games)),
                                         w1 - time.monotonic() + 60.0)
    finally:
        await asyncio.gather(*(g.close() for g in games), return_exceptions=True)
    conn.send(("done", [asdict(r) for r in results]))


def worker_main(conn: Any, use_uvloop: bool) -> None:
    """A client process: runs the cases the main process sends until it sends None."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the main process stops everything
    runner: Any = asyncio.run
    if use_uvloop:
        try:
            import uvloop

            runner = uvloop.run
        except ImportError:
            pass
    while True:
        case = conn.recv()
        if case is None:
            return
        try:
            runner(worker_case(conn, case))
        except Exception as e:  # reported to the main process, which stops the run
            conn.send(("error", f"{type(e).__name__}: {e}"))


# ---------------------------------------------------------------------------- main side
class Workers:
    """``procs`` client processes, kept for the whole run."""

    def __init__(self, procs: int, use_uvloop: bool) -> None:
        ctx = mp.get_context("spawn")
        self.items: list[tuple[Any, Any]] = []
        for _ in range(procs):
            a, b = ctx.Pipe()
            p = ctx.Process(target=worker_main, args=(b, use_uvloop), daemon=True)
            p.start()
            self.items.append((p, a))
        self.ps = [psutil.Process(p.pid) for p, _ in self.items]

    def recv(self, conn: Any, proc: Any, timeout: float) -> Any:
        deadline = time.monotonic() + timeout
        while not conn.poll(0.2):
            if not proc.is_alive():
                raise RuntimeError(f"client process {proc.pid} died ({proc.exitcode})")
            if time.monotonic() > deadline:
                raise RuntimeError(f"client process {proc.pid} did not answer in {timeout:.0f} s")
        kind, value = conn.recv()
        if kind == "error":
            raise RuntimeError(f"client process {proc.pid}: {value}")
        return value

    def stop(self) -> None:
        for p, conn in self.items:
            try:
                if p.is_alive():
                    conn.send(None)
            except OSError:
                pass
        for p, _ in self.items:
            p.join(5)
            if p.is_alive():
                p.terminate()
                p.join(5)


def cpu_seconds(p: psutil.Process) -> float:
    t = p.cpu_times()
    return t.user + t.system


def thread_seconds(p: psutil.Process) -> dict[int, float]:
    return {t.id: t.user_time + t.system_time for t in p.threads()}


def wait_idle(limit: float) -> float:
    """Waits (up to ``limit`` s) until the whole machine is under IDLE busy over half a
    second; returns the seconds waited."""
    t0 = time.monotonic()
    while psutil.cpu_percent(interval=0.5) >= IDLE * 100 and time.monotonic() - t0 < limit:
        pass
    return time.monotonic() - t0


def box_busy(a: Any, b: Any) -> float:
    """Share of all cores busy between two psutil.cpu_times() readings, 0..1."""
    idle = (b.idle - a.idle) + (getattr(b, "iowait", 0.0) - getattr(a, "iowait", 0.0))
    total = sum(b) - sum(a)
    return 1.0 - idle / total if total > 0 else float("nan")


def run_case(server: Server | ClusterServer, workers: Workers, transport: str, n: int, m: int,
             args: argparse.Namespace, nproc: int) -> dict[str, Any]:
    rng = np.random.default_rng(args.seed + 7919 * m)
    phases = np.zeros(m) if args.phase == "aligned" else rng.uniform(0.0, PERIOD, m)
    specs = [ClientSpec(c, float(phases[c])) for c in range(m)]
    k = len(workers.items)
    t_setup = time.monotonic()
    for w, (_, conn) in enumerate(workers.items):
        conn.send({"port": server.port, "n": n, "seed": args.seed, "transport": transport,
                   "changed_only": args.changed_only, "specs": specs[w::k]})
    for p, conn in workers.items:
        workers.recv(conn, p, 120.0)
    setup = time.monotonic() - t_setup
    t0 = time.monotonic() + 0.2
    w0 = t0 + args.warmup
    w1 = w0 + args.duration
    for _, conn in workers.items:
        conn.send(("go", (t0, w0, w1)))
    sps = [psutil.Process(pid) for pid in server.pids()]
    lb = psutil.Process(server.lb_pid) if server.lb_pid else None
    me = psutil.Process()

    def snap() -> tuple[Any, ...]:
        threads: dict[int, float] = {}
        for sp in sps:
            threads.update(thread_seconds(sp))
        return (time.monotonic(), sum(cpu_seconds(sp) for sp in sps), threads,
                [cpu_seconds(p) for p in [*workers.ps, me]], psutil.cpu_times(),
                cpu_seconds(lb) if lb else 0.0)

    time.sleep(max(0.0, w0 - time.monotonic()))
    a = snap()
    time.sleep(max(0.0, w1 - time.monotonic()))
    b = snap()
    results: list[ClientResult] = []
    for p, conn in workers.items:
        results += [ClientResult(**d) for d in workers.recv(conn, p, 120.0)]
    wall = b[0] - a[0]
    loop_ids = [sp.pid for sp in sps]  # each process's event loop: its main thread
    loop_cpu = sum(b[2].get(t, 0.0) - a[2].get(t, 0.0) for t in loop_ids)
    row: dict[str, Any] = {
        "transport": TRANSPORTS[transport], "n": n, "l": max(1, n // 10), "m": m,
        "workers": args.workers, "lb_cpu": 100.0 * (b[5] - a[5]) / wall,
        "setup": setup, "wall": wall,
        "server_cpu": 100.0 * (b[1] - a[1]) / wall,
        "server_loop": 100.0 * loop_cpu / wall,
        "client_cpu": 100.0 * sum(y - x for x, y in zip(a[3], b[3], strict=True)) / wall,
        "box": 100.0 * box_busy(a[4], b[4]),
    }
    # Everything else on the machine (other users' jobs), in % of one core.
    row["other"] = max(0.0, row["box"] * nproc - row["server_cpu"] - row["client_cpu"]
                       - row["lb_cpu"])
    row.update(summarise(results, args.duration))
    return row


def summarise(results: list[ClientResult], duration: float) -> dict[str, Any]:
    slots = sum(r.slots for r in results)
    sent = sum(r.sent for r in results)
    answered = sum(r.answered for r in results)
    late = sum(r.late for r in results)
    failed = sum(r.failed for r in results)
    skipped = slots - sent
    lat = np.concatenate([np.asarray(r.latency, np.float64) for r in results])
    lag = np.concatenate([np.asarray(r.lag, np.float64) for r in results])
    comp = np.concatenate([np.asarray(r.compute, np.float64) for r in results])
    srv = np.concatenate([np.asarray(r.server, np.float64) for r in results])

    def pct(v: np.ndarray, q: float) -> float:
        return float(np.percentile(v, q)) if v.size else float("nan")

    return {"slots": slots, "sent": sent, "answered": answered, "late": late, "failed": failed,
            "skipped": skipped,
            "missed": 100.0 * (late + skipped + failed) / slots if slots else float("nan"),
            "fps": answered / duration, "target": len(results) / PERIOD,
            "p50": pct(lat, 50), "p95": pct(lat, 95), "p99": pct(lat, 99),
            "compute": pct(comp, 50), "lag99": pct(lag, 99),
            "server": pct(srv, 50) if np.isfinite(srv).all() else float("nan"),
            "errors": sorted({r.error for r in results if r.error})}


HEAD = ["transport", "N", "M", "target fps", "fps", "missed %", "late", "skipped", "failed",
        "p50 ms", "p95 ms", "p99 ms", "compute p50 ms", "server p50 ms", "send lag p99 ms", "server CPU %",
        "server % of box", "server loop thread %", "clients CPU %", "other CPU %", "box busy %"]


def cells(r: dict[str, Any], nproc: int) -> list[str]:
    return [r["transport"], fmt_count(r["n"]), str(r["m"]), f"{r['target']:.0f}", f"{r['fps']:.0f}",
            f"{r['missed']:.1f}", str(r["late"]), str(r["skipped"]), str(r["failed"]),
            f"{r['p50']:.2f}", f"{r['p95']:.2f}", f"{r['p99']:.2f}", f"{r['compute']:.2f}",
            "-" if math.isnan(r["server"]) else f"{r['server']:.2f}",
            f"{r['lag99']:.2f}", f"{r['server_cpu']:.0f}", f"{r['server_cpu'] / nproc:.0f}",
            f"{r['server_loop']:.0f}", f"{r['client_cpu']:.0f}",
            f"{r['other']:.0f}" + ("*" if r["other"] > BUSY_MARK else ""), f"{r['box']:.0f}"]


def print_table(rows: list[dict[str, Any]], nproc: int) -> None:
    table = [HEAD] + [cells(r, nproc) for r in rows]
    widths = [max(len(row[i]) for row in table) for i in range(len(HEAD))]
    say()
    for row in table:
        say("  ".join(c.rjust(w) for c, w in zip(row, widths, strict=True)))
    for r in rows:
        for e in r["errors"]:
            say(f"  {r['transport']} {fmt_count(r['n'])} M={r['m']}: {e}")


def capacity(rows: list[dict[str, Any]], n: int) -> list[str]:
    """Per transport: the most clients of ``n`` objects run with under MISS_OK % missed,
    and the fewest run over it."""
    out = []
    for t in TRANSPORTS.values():
        got = sorted((r["m"], r["missed"]) for r in rows if r["n"] == n and r["transport"] == t)
        if not got:
            continue
        ok = [m for m, x in got if x < MISS_OK]
        bad = [m for m, x in got if x >= MISS_OK]
        hi = max(ok) if ok else None
        lo = min((m for m in bad if hi is None or m > hi), default=None)
        if hi is None:
            text = f"none: already {got[0][1]:.1f}% missed at M = {got[0][0]}"
        elif lo is None:
            text = f"at least {hi} (every M run, up to {got[-1][0]}, under {MISS_OK:g}%)"
        elif lo == hi + 1:
            text = f"{hi} ({lo} misses {dict(got)[lo]:.1f}%)"
        else:
            text = f"between {hi} and {lo - 1} ({lo} misses {dict(got)[lo]:.1f}%)"
        out.append(f"{t}: {text}")
    return out


def search_points(rows: list[dict[str, Any]], n: int, t: str) -> tuple[int, int] | None:
    got = sorted((r["m"], r["missed"]) for r in rows if r["n"] == n and r["transport"] == t)
    ok = [m for m, x in got if x < MISS_OK]
    if not ok:
        return None
    hi = max(ok)
    bad = [m for m, x in got if x >= MISS_OK and m > hi]
    return (hi, min(bad)) if bad and min(bad) > hi + 1 else None


def notes(rows: list[dict[str, Any]], args: argparse.Namespace) -> list[str]:
    """Cases run beside other jobs, and the time spent waiting for an idle machine."""
    out = []
    busy = [r for r in rows if r["other"] > BUSY_MARK]
    if busy:
        out.append(f"{len(busy)} of {len(rows)} cases ran beside other jobs using over "
                   f"{BUSY_MARK:g}% of a core (marked * in \"other CPU %\"): their numbers are "
                   "pessimistic.")
    again = [r for r in rows if r.get("runs", 1) > 1]
    if again:
        out.append(f"{len(again)} cases were run again because other jobs ran beside them "
                   f"({sum(r['runs'] - 1 for r in again)} extra runs; the quietest run is shown).")
    waited = sum(r.get("waited", 0.0) for r in rows)
    if args.idle_wait > 0:
        out.append(f"Waited {waited:.0f} s in all for an idle machine before cases (at most "
                   f"{args.idle_wait:g} s each).")
    return out


def plot(rows: list[dict[str, Any]], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4.2))
    keys = sorted({(r["transport"], r["n"]) for r in rows}, key=lambda k: (k[1], k[0]))
    for t, n in keys:
        sel = sorted((r for r in rows if r["transport"] == t and r["n"] == n),
                     key=lambda r: r["m"])
        ms = [r["m"] for r in sel]
        style = "-o" if t == "HTTP" else "--s"
        label = f"{t}, {fmt_count(n)} objects"
        for ax, ys in ((ax1, [r["p99"] for r in sel]),
                       (ax2, [max(r["missed"], 0.01) for r in sel])):
            line, = ax.plot(ms, ys, style, label=label)
            # Cases run beside other jobs: hollow markers.
            busy = [(x, y) for x, y, r in zip(ms, ys, sel, strict=True) if r["other"] > BUSY_MARK]
            if busy:
                ax.plot(*zip(*busy, strict=True), style[-1], color=line.get_color(),
                        markerfacecolor="white", ls="none")
    ax1.axhline(PERIOD * 1e3, color="grey", lw=0.8, ls=":")
    right = max(r["m"] for r in rows)
    ax1.text(right, PERIOD * 1e3 * 1.05, "16.7 ms (one frame)", fontsize=8, color="grey",
             ha="right")
    ax2.axhline(MISS_OK, color="grey", lw=0.8, ls=":")
    ax2.text(right, MISS_OK * 1.1, f"{MISS_OK:g}% missed", fontsize=8, color="grey", ha="right")
    for ax, title, unit in ((ax1, "round-trip latency p99", "ms"),
                            (ax2, "missed 60 fps deadlines", "% of slots (0 shown as 0.01)")):
        ax.set_xscale("log", base=2)
        ax.set_yscale("log")
        ax.set_xlabel("clients M (one session each, 60 fps)")
        ax.set_ylabel(unit)
        ax.set_title(title)
        ax.grid(True, which="both", alpha=0.3)
        ax.set_xticks(sorted({r["m"] for r in rows}))
        ax.get_xaxis().set_major_formatter(matplotlib.ticker.ScalarFormatter())
        ax.yaxis.set_major_formatter(matplotlib.ticker.FormatStrFormatter("%g"))
        ax.yaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    ax2.legend(fontsize=8, title="hollow: other jobs ran beside", title_fontsize=7)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    say(f"wrote {path}")


def render(rows: list[dict[str, Any]], searched: list[dict[str, Any]], args: argparse.Namespace,
           load: tuple[float, float], nproc: int) -> str:
    m = machine()
    cmd = "python bench/load.py" + ("" if len(sys.argv) < 2 else " " + shlex.join(sys.argv[1:]))
    every = rows + searched
    out = [BEGIN, "", "## Load test (`bench/load.py`)", "",
           f"Generated {time.strftime('%Y-%m-%d %H:%M %Z')} by `{cmd}` at commit "
           f"`{git_commit()}`.", "",
           f"Machine: {m['cpu']}, {m['nproc']} CPUs, {m['os']}; Python {m['python']}, numpy "
           f"{m['numpy']}, numba {m['numba']}. One server (`python -m lightsched serve`, uvicorn, "
           f"one process) and the load generator ({args.procs} asyncio client process"
           f"{'es' if args.procs > 1 else ''}, {'uvloop' if args.uvloop else 'asyncio'}) on the same "
           "machine over 127.0.0.1, "
           f"sharing its {nproc} cores; 1-minute load average {load[0]:.2f} before the run, "
           f"{load[1]:.2f} after.", "",
           f"Each of M clients is one session with its own `city(N, N/10, seed={args.seed} + "
           "client)`, one camera, default Config; every frame it sends all its lights' new "
           "positions (`update_lights`) and waits for the whole frame (msgpack, "
           f"{'changed rows only' if args.changed_only else 'every array, full frames'}). "
           "Paced at 60 fps on an absolute schedule (slot i due at t0 + phase + i/60, "
           + ("phase 0 for every client" if args.phase == "aligned"
              else "a random phase in [0, 1/60) per client") + "), "
           "at most one frame in flight per client. Per case: scene load, "
           f"{args.warmup:g} s warm-up (not counted), {args.duration:g} s measured. "
           "**missed %** = (late + skipped + failed) / slots due in the measured window: *late* "
           "= answered more than 16.7 ms after its slot was due; *skipped* = slots that came "
           "due while the client still waited for an answer (it then sends at the next slot, "
           "so a late answer skips at least one); *failed* = refused or unanswered. **fps** = "
           "frames answered (on time or not) per second, all clients; target = 60 M. "
           "Latencies: send to answer decoded, frames answered in the window. *compute* = "
           "the server's `stats.seconds.total` (median); *server* = the sum of the HTTP "
           "answer's Server-Timing (body read and decode, frame, encode; median; the "
           "WebSocket has none); *send lag* = send time - due time, p99 (the client's own "
           "delay; large when the clients lack CPU). CPU over the measured window in % of one "
           "core (psutil): the server process (all threads), its event-loop thread alone, the "
           "client processes (and this coordinating one), *other* = everything else on the "
           "machine (box busy x cores - server - clients); *box busy* = all cores (100% = every "
           "core busy).", "",
           "| " + " | ".join(HEAD) + " |", "|" + "---|" * len(HEAD)]
    out += ["| " + " | ".join(cells(r, nproc)) + " |" for r in rows]
    if searched:
        out += ["", "Extra runs between the grid's last passing and first failing M (1k objects; "
                "same settings; one run each, so the edge is only as sharp as one run is "
                "repeatable):", "",
                "| " + " | ".join(HEAD) + " |", "|" + "---|" * len(HEAD)]
        out += ["| " + " | ".join(cells(r, nproc)) + " |" for r in searched]
    errors = [f"{r['transport']} {fmt_count(r['n'])} M={r['m']}: {e}" for r in every
              for e in r["errors"]]
    if errors:
        out += ["", "Errors:", ""] + [f"- {e}" for e in errors]
    for n in sorted({r["n"] for r in every}):
        out += ["", f"**Answer (60 fps clients of {fmt_count(n)} objects this box serves with under "
                f"{MISS_OK:g}% missed deadlines):** " + "; ".join(capacity(every, n)) + "."]
    got = notes(every, args)
    if got:
        out += [""] + got
    if args.write_plot:
        out += ["", "![p99 latency and missed deadlines against M](plots/load.png)"]
    out += ["", END]
    return "\n".join(out) + "\n"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--clients", default="1,8,32,64",
                   help="comma-separated client counts M (default 1,8,32,64)")
    p.add_argument("--sizes", default="1k,10k",
                   help="comma-separated object counts N, lights N/10 (default 1k,10k)")
    p.add_argument("--transports", default="http,ws", help="http, ws or both (default http,ws)")
    p.add_argument("--duration", type=float, default=5.0, help="measured seconds per case (5)")
    p.add_argument("--warmup", type=float, default=1.0, help="warm-up seconds per case (1)")
    p.add_argument("--procs", type=int, default=1, help="client processes (default 1)")
    p.add_argument("--phase", choices=("random", "aligned"), default="random",
                   help="clients' slot phases: random in [0, 1/60) (default), or all at once")
    p.add_argument("--changed-only", action="store_true", help="ask for changed rows only")
    p.add_argument("--workers", type=int, default=0,
                   help="server processes behind HAProxy (deploy/haproxy.cfg); 0 (default): "
                        "one server, no load balancer")
    p.add_argument("--no-search", dest="search", action="store_false",
                   help="skip the extra runs that narrow down the 1k-object capacity")
    p.add_argument("--search-steps", type=int, default=5,
                   help="most extra runs per transport for the 1k capacity (default 5)")
    p.add_argument("--idle-wait", type=float, default=60.0,
                   help="before each case, wait up to this many seconds for the machine to be "
                        f"idle (under {IDLE * 100:g}%% busy), as other jobs skew the numbers "
                        "(default 60; 0 with --quick)")
    p.add_argument("--retries", type=int, default=2,
                   help=f"runs a case again (up to this many times) when other jobs used over "
                        f"{BUSY_MARK:g}%% of a core during it, keeping the quietest run "
                        "(default 2; 0 with --quick)")
    p.add_argument("--server-env", action="append", default=[], metavar="NAME=VALUE",
                   help="an environment variable for the server, e.g. LIGHTSCHED_FRAME_THREADS=1 "
                        "(repeatable)")
    p.add_argument("--no-uvloop", dest="uvloop", action="store_false")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--quick", action="store_true",
                   help="1k objects, M = 1, 8, 32, 2 s each, 0.5 s warm-up, no search (< 30 s)")
    p.add_argument("--write", action="store_true",
                   help="write the table into bench/RESULTS.md and the plot bench/plots/load.png")
    args = p.parse_args(argv)
    if args.quick:
        args.clients, args.sizes, args.duration, args.warmup, args.search, args.idle_wait = \
            "1,8,32", "1k", 2.0, 0.5, False, 0.0
        args.retries = 0
    try:
        clients = [int(x) for x in args.clients.split(",")]
        sizes = [parse_count(x) for x in args.sizes.split(",")]
        transports = [x.strip().lower() for x in args.transports.split(",")]
    except (ValueError, argparse.ArgumentTypeError) as e:
        p.error(str(e))
    if any(m < 1 for m in clients) or any(n < 10 for n in sizes) or args.procs < 1 \
            or args.duration <= 0 or args.warmup < 0 \
            or any(t not in TRANSPORTS for t in transports):
        p.error("M >= 1, N >= 10, --procs >= 1, --duration > 0, --warmup >= 0, "
                "--transports of http, ws")
    args.write_plot = args.write

    from tqdm import tqdm

    import lightsched

    m = machine()
    nproc = int(m["nproc"])
    say(f"lightsched {lightsched.__version__} at {git_commit()}; {m['cpu']}, {nproc} CPUs")
    cases = [(t, n, k) for n in sizes for t in transports for k in clients]
    t_start = time.perf_counter()
    load0 = os.getloadavg()[0]
    env = {"LIGHTSCHED_MAX_SESSIONS": str(max(256, 2 * max(clients) + 8))}
    for item in args.server_env:
        name, eq, value = item.partition("=")
        if not eq or not name:
            p.error(f"--server-env wants NAME=VALUE, not {item!r}")
        env[name] = value
    rows: list[dict[str, Any]] = []
    searched: list[dict[str, Any]] = []
    workers: Workers | None = None
    bar = None
    starts: list[float] = []
    try:
        workers = Workers(args.procs, args.uvloop)
        say(f"{args.procs} client process(es); {len(cases)} cases of {args.warmup:g} s warm-up + "
            f"{args.duration:g} s; a fresh server for each transport and size")
        bar = tqdm(total=len(cases), unit="case", file=sys.stderr, dynamic_ncols=True)

        def one(server: Server | ClusterServer, t: str, n: int, k: int) -> dict[str, Any]:
            assert workers is not None and bar is not None
            name = f"{TRANSPORTS[t]} {fmt_count(n)} M={k}"
            waited, best = 0.0, None
            for attempt in range(1 + args.retries):
                if args.idle_wait > 0:
                    bar.set_description(f"{name} (waiting for an idle machine)")
                    waited += wait_idle(args.idle_wait)
                bar.set_description(name + (" (again: other jobs ran)" if attempt else ""))
                got = run_case(server, workers, t, n, k, args, nproc)
                got["runs"] = attempt + 1
                if best is None or got["other"] < best["other"]:
                    best = got
                if got["other"] <= BUSY_MARK:
                    break
            assert best is not None
            r = best
            r["waited"] = waited
            bar.set_postfix_str(f"p99 {r['p99']:.1f} ms, missed {r['missed']:.1f}%")
            bar.update()
            return r

        for n in sizes:
            for t in transports:
                # A fresh server per group: a group does not inherit the worker threads (and
                # their OpenMP teams, see bench/README.md) of the groups before it.
                t0 = time.perf_counter()
                server = start_server(env, args.workers)
                starts.append(time.perf_counter() - t0)
                try:
                    for k in clients:
                        rows.append(one(server, t, n, k))
                    for _ in range(args.search_steps if args.search and n == 1000 else 0):
                        pts = search_points(rows + searched, n, TRANSPORTS[t])
                        if pts is None:
                            break
                        bar.total += 1
                        searched.append(one(server, t, n, (pts[0] + pts[1]) // 2))
                finally:
                    server.stop()
    finally:
        if bar is not None:
            bar.close()
        if workers is not None:
            workers.stop()
    say(f"servers started in {', '.join(f'{x:.1f}' for x in starts)} s")
    load = (load0, os.getloadavg()[0])
    print_table(rows, nproc)
    if searched:
        say("\nextra runs narrowing down the 1k-object capacity:")
        print_table(sorted(searched, key=lambda r: (r["transport"], r["m"])), nproc)
    every = rows + searched
    say()
    for n in sizes:
        say(f"60 fps clients of {fmt_count(n)} objects with under {MISS_OK:g}% missed deadlines: "
            + "; ".join(capacity(every, n)))
    for line in notes(every, args):
        say(line)
    if args.workers:
        say(f"through HAProxy with {args.workers} worker(s): HAProxy's CPU (% of one core) "
            + ", ".join(f"{r['transport']} {fmt_count(r['n'])} M={r['m']} {r['lb_cpu']:.0f}"
                        for r in every))
    say(f"\n{time.perf_counter() - t_start:.0f} s in all; 1-minute load average {load[0]:.2f} "
        f"before, {load[1]:.2f} after")
    if args.write:
        plot(every, PLOTS / "load.png")
        write_results(render(rows, sorted(searched, key=lambda r: (r["transport"], r["m"])),
                             args, load, nproc), BEGIN, END)
    return 0


if __name__ == "__main__":
    try:
        sys.exit(main())
    except KeyboardInterrupt:  # the finally blocks have stopped the server and the clients
        say("\ninterrupted (server and client processes stopped)")
        sys.exit(130)
