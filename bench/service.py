"""Service benchmark: round-trip latency of a LightSched session frame over HTTP and WebSocket.

    python bench/service.py                   # (1k, 100) and (10k, 1k), HTTP and WebSocket
    python bench/service.py --sizes 1k:100 --frames 0.5 --runs 3
    python bench/service.py --write           # also writes the table into bench/RESULTS.md

Starts the real server (``python -m lightsched serve --no-demo``) as a subprocess on a free
port of 127.0.0.1 and stops it at the end. For each size (N objects, L lights, a seeded
``lightsched.scenes.city``), each transport (HTTP POST /v1/sessions/{id}/frames with
msgpack bodies on one kept-alive connection; the session's WebSocket stream) and each mode
(full frames; ``changed_only``): a new session, one frame that loads the scene, warm-up
frames, then timed frames in which every light moves (``update_lights`` with new positions,
as a game would send them; the call itself is not timed). The client side is the
lightsched_client code path, taken apart to time its pieces.

Per frame: client encode (building the request map and msgpack), client decode (msgpack to
arrays and the Frame, merging changed rows into the previous frame for changed_only), the
server's split from its Server-Timing header (HTTP only: body read + decode, frame, response
encode), the core's compute time (``stats.seconds.total``), the round trip (before encode to
after decode) and the message sizes. "transport" is what is left: for HTTP, round trip minus
client encode and decode minus the server's three parts (the loopback, HTTP parsing on both
sides, the ASGI stack); for WebSocket, round trip minus client encode and decode minus the
compute (so it also holds the server's decode, request checks and encode).

Every case runs ``--runs`` times (a new session each, cases interleaved run by run); the
p50 reported is the median of the runs' p50s, the p99 the largest of the runs' p99s, and the
splits are medians over every timed frame.
"""

from __future__ import annotations

import argparse
import contextlib
import http.client
import os
import shlex
import socket
import subprocess
import sys
import tempfile
import time
import urllib.request
from pathlib import Path
from typing import Any

import numpy as np
from common import (
    SERVER_START_TIMEOUT,
    fmt_count,
    git_commit,
    machine,
    markers,
    parse_sizes,
    say,
    write_results,
)

import lightsched
from lightsched.scenes import DT, city, move_lights

HERE = Path(__file__).resolve().parent
BEGIN, END = markers("service.py")

# A missing client package fails with a clear message.
try:
    from lightsched_client import Client
    from lightsched_client.client import frame_of
    from lightsched_client.wire import MSGPACK, dumps, loads
except ImportError as e:  # pragma: no cover - environment problem
    sys.exit(f"bench/service.py needs the client package (pip install -e '.[server]'): {e}")

HEADERS = {"Content-Type": MSGPACK, "Accept": MSGPACK}
TRANSPORTS = ("HTTP", "WebSocket")
MODES = ("full", "changed_only")
# The targets: session frame over HTTP, round trip on this machine.
TARGETS = ((1000, "p50", 2.0), (1000, "p99", 5.0), (10_000, "p50", 10.0))
SLOW = 3.0  # a frame over 3x its run's p50 counts as slow
SPLITS = ("encode", "decode", "s_decode", "s_frame", "compute", "s_encode", "transport")


def default_frames(n: int) -> int:
    return 300 if n < 5000 else 150 if n < 50_000 else 50


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class Server:
    """``python -m lightsched serve`` on a free port; ``stop()`` terminates, then kills."""

    def __init__(self, timeout: float = SERVER_START_TIMEOUT,
                 env: dict[str, str] | None = None) -> None:
        self.port = free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        self.log = tempfile.TemporaryFile()
        cmd = [sys.executable, "-m", "lightsched", "serve", "--host", "127.0.0.1",
               "--port", str(self.port), "--no-demo", "--log-level", "warning"]
        self.proc = subprocess.Popen(cmd, cwd=HERE.parent, stdout=self.log, env=env,
                                     stderr=subprocess.STDOUT)
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

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(10)
        self.log.close()


def server_timing(header: str | None) -> dict[str, float]:
    """``decode;dur=0.1, frame;dur=1.0, encode;dur=0.2`` as {name: ms}."""
    out: dict[str, float] = {}
    for part in (header or "").split(","):
        name, _, rest = part.strip().partition(";")
        if rest.startswith("dur="):
            out[name] = float(rest[4:])
    return out


class HttpLink:
    """POSTs frame requests on one kept-alive connection, as lightsched_client does."""

    def __init__(self, port: int, sid: str) -> None:
        self.conn = http.client.HTTPConnection("127.0.0.1", port, timeout=60)
        self.path = f"/v1/sessions/{sid}/frames"

    def call(self, body: bytes) -> tuple[bytes, dict[str, float]]:
        self.conn.request("POST", self.path, body=body, headers=HEADERS)
        r = self.conn.getresponse()
        data = r.read()
        if r.status != 200:
            raise RuntimeError(f"frame refused: {r.status} {data[:300]!r}")
        return data, server_timing(r.getheader("Server-Timing"))

    def close(self) -> None:
        self.conn.close()


class WsLink:
    """One message per frame on the session's stream (no compression, as the client)."""

    def __init__(self, port: int, sid: str) -> None:
        from websockets.sync.client import connect

        # As a context manager: websockets >= 17.1 warns on a bare connect(), and older
        # versions do not know its legacy= flag.
        self._stack = contextlib.ExitStack()
        self.ws = self._stack.enter_context(connect(
            f"ws://127.0.0.1:{port}/v1/sessions/{sid}/stream", max_size=None, compression=None))

    def call(self, body: bytes) -> tuple[bytes, dict[str, float]]:
        self.ws.send(body)
        data = self.ws.recv()
        assert isinstance(data, bytes)
        return data, {}

    def close(self) -> None:
        self._stack.close()


def run_case(client: Any, port: int, scene: Any, transport: str, mode: str, frames: int,
             warmup: int) -> dict[str, Any]:
    """One session: load the scene, ``warmup`` frames, then ``frames`` timed frames."""
    s = client.session()
    link: HttpLink | WsLink = HttpLink(port, s.id) if transport == "HTTP" else WsLink(port, s.id)
    changed = mode == "changed_only"
    rec: dict[str, list[float]] = {k: [] for k in ("total", *SPLITS, "req", "resp")}
    prev = None
    try:
        s.set_lights(**scene.lights)
        s.set_objects(**scene.objects)
        for i in range(1 + warmup + frames):
            if i > 0:
                s.update_lights(id=scene.lights["id"], position=move_lights(scene.lights, i))
            t0 = time.perf_counter()
            body = dumps(s._request(scene.cameras, DT, False, None, changed and i > 0), MSGPACK)
            t1 = time.perf_counter()
            data, st = link.call(body)
            t2 = time.perf_counter()
            doc = loads(data, MSGPACK)
            if "frame_index" not in doc:
                raise RuntimeError(f"frame refused: {doc}")
            prev = frame_of(doc, prev)
            t3 = time.perf_counter()
            if i <= warmup:
                continue
            total, enc, dec = (t3 - t0) * 1e3, (t1 - t0) * 1e3, (t3 - t2) * 1e3
            compute = float(doc["stats"]["seconds"]["total"]) * 1e3
            server = st.get("decode", 0.0) + st.get("frame", 0.0) + st.get("encode", 0.0) \
                if st else compute
            for k, v in (("total", total), ("encode", enc), ("decode", dec),
                         ("s_decode", st.get("decode", np.nan)),
                         ("s_frame", st.get("frame", np.nan)), ("compute", compute),
                         ("s_encode", st.get("encode", np.nan)),
                         ("transport", total - enc - dec - server),
                         ("req", len(body)), ("resp", len(data))):
                rec[k].append(v)
    finally:
        link.close()
        s.close()
    return {k: np.asarray(v, dtype=np.float64) for k, v in rec.items()}


def summarise(runs: list[dict[str, np.ndarray]]) -> dict[str, Any]:
    p50s = [float(np.percentile(r["total"], 50)) for r in runs]
    p99s = [float(np.percentile(r["total"], 99)) for r in runs]
    every = {k: np.concatenate([r[k] for r in runs]) for k in runs[0]}
    out: dict[str, Any] = {"p50": float(np.median(p50s)), "p99": max(p99s), "p50s": p50s,
                           "p99s": p99s, "frames": int(every["total"].size)}
    # Frames over SLOW x their run's p50, and where their time went (compute or the rest).
    slow = np.concatenate([r["total"] > SLOW * p for r, p in zip(runs, p50s, strict=True)])
    out["slow"] = int(slow.sum())
    out["slow_compute"] = float(np.median(every["compute"][slow])) if slow.any() else 0.0
    out["slow_rest"] = float(np.median((every["total"] - every["compute"])[slow])) \
        if slow.any() else 0.0
    for k in (*SPLITS, "req", "resp"):
        v = every[k]
        out[k] = float(np.median(v)) if np.isfinite(v).all() else None
    return out


def bench_size(server: Server, n: int, l: int, args: argparse.Namespace) -> list[dict[str, Any]]:
    frames = max(1, round(default_frames(n) * args.frames))
    say(f"\n== N={fmt_count(n)} objects, L={fmt_count(l)} lights: {args.runs} runs of "
        f"{args.warmup} warm-up + {frames} timed frames per case")
    scene = city(n, l, seed=args.seed)
    cases = [(t, m) for t in TRANSPORTS for m in MODES]
    got: dict[tuple[str, str], list[dict[str, np.ndarray]]] = {c: [] for c in cases}
    with Client(server.url) as client:
        for run in range(args.runs):
            for t, m in cases:
                got[(t, m)].append(run_case(client, server.port, scene, t, m, frames,
                                            args.warmup))
            say(f"   run {run + 1}: " + ", ".join(
                f"{t}/{m} {np.percentile(got[(t, m)][-1]['total'], 50):.2f}/"
                f"{np.percentile(got[(t, m)][-1]['total'], 99):.2f}" for t, m in cases)
                + " ms (p50/p99)")
    rows = []
    for t, m in cases:
        r = summarise(got[(t, m)])
        r.update(n=n, l=l, via=t, mode=m)
        rows.append(r)
    return rows


def fmt_ms(v: float | None) -> str:
    return "-" if v is None else f"{v:.2f}"


HEAD = ["N", "L", "transport", "mode", "p50 ms", "p99 ms", "run p50s ms", "client encode",
        "client decode", "server decode", "server frame", "compute", "server encode",
        "transport ms", "request B", "response B", f"frames > {SLOW:g}x p50"]


def cells(r: dict[str, Any]) -> list[str]:
    return [fmt_count(r["n"]), fmt_count(r["l"]), r["via"], r["mode"], f"{r['p50']:.2f}",
            f"{r['p99']:.2f}", "/".join(f"{x:.2f}" for x in r["p50s"]),
            *[fmt_ms(r[k]) for k in SPLITS], f"{r['req']:.0f}", f"{r['resp']:.0f}",
            f"{r['slow']}/{r['frames']}" + (f": compute {r['slow_compute']:.0f} ms, rest "
                                            f"{r['slow_rest']:.0f} ms" if r["slow"] else "")]


def verdicts(rows: list[dict[str, Any]]) -> list[str]:
    out = []
    for n, stat, limit in TARGETS:
        for mode in MODES:
            r = next((x for x in rows if x["n"] == n and x["via"] == "HTTP"
                      and x["mode"] == mode), None)
            if r is None:
                if mode == "full":
                    out.append(f"{fmt_count(n)} objects, HTTP {stat} <= {limit:g} ms: not run")
                continue
            ok = "met" if r[stat] <= limit else "NOT met"
            out.append(f"{fmt_count(n)} objects, HTTP {mode}: {stat} {r[stat]:.2f} ms "
                       f"(target <= {limit:g} ms): {ok}")
    return out


def print_table(rows: list[dict[str, Any]]) -> None:
    table = [HEAD] + [cells(r) for r in rows]
    widths = [max(len(row[i]) for row in table) for i in range(len(HEAD))]
    say()
    for row in table:
        say("  ".join(c.rjust(w) for c, w in zip(row, widths, strict=True)))
    say()
    for v in verdicts(rows):
        say(v)


def render(rows: list[dict[str, Any]], args: argparse.Namespace, load: tuple[float, float]
           ) -> str:
    m = machine()
    cmd = "python bench/service.py" + ("" if len(sys.argv) < 2 else " " + shlex.join(sys.argv[1:]))
    frames = ", ".join(f"{max(1, round(default_frames(n) * args.frames))} at {fmt_count(n)}"
                       for n, _ in args.sizes)
    out = [BEGIN, "", "## Service round trip (`bench/service.py`)", "",
           f"Generated {time.strftime('%Y-%m-%d %H:%M %Z')} by `{cmd}` at commit "
           f"`{git_commit()}`.", "",
           f"Machine: {m['cpu']}, {m['nproc']} CPUs ({m['numba_threads']} numba threads), "
           f"{m['os']}; Python {m['python']}, numpy {m['numpy']}, numba {m['numba']}. Client "
           "and server (`python -m lightsched serve`, uvicorn, one worker) on the same "
           f"machine over 127.0.0.1, sharing its CPUs; 1-minute load average {load[0]:.2f} "
           f"before the run, {load[1]:.2f} after (other processes on the machine count).", "",
           f"Scenes: `lightsched.scenes.city(N, L, seed={args.seed})`, one camera, default "
           "Config; every light moves every frame (`update_lights` with all positions, sent "
           "with the frame). Msgpack both ways; HTTP on one kept-alive connection "
           "(http.client, as `lightsched_client.Client`), WebSocket on the session's stream "
           "without compression. Per case: a new session, one frame loading the scene, "
           f"{args.warmup} warm-up frames, then timed frames ({frames}); {args.runs} runs "
           "(a new session each, cases interleaved). p50 is the median of the runs' p50s "
           "(each run's in \"run p50s\"), p99 the largest of the runs' p99s, of the round "
           "trip (before encoding the request to after decoding the answer into a Frame). "
           "The other columns are medians over every timed frame, in ms: client encode "
           "(request map and msgpack), client decode (msgpack to arrays and the Frame, with "
           "the merge into the previous frame for changed_only), the server's Server-Timing "
           "(body read + decode, frame: request checks, scene changes, compute and the "
           "response map, encode), compute (`stats.seconds.total`, inside server frame), "
           "transport = round trip - client encode - client decode - server decode, frame "
           "and encode (HTTP), or - compute (WebSocket, which has no Server-Timing: its "
           "transport also holds the server's decode, checks and encode). Medians do not "
           "add up to the p50. The last column counts the frames slower than "
           f"{SLOW:g}x their run's p50, with the median compute and rest (round trip - compute) "
           "of those frames.", "",
           "| " + " | ".join(HEAD) + " |", "|" + "---|" * len(HEAD)]
    out += ["| " + " | ".join(cells(r)) + " |" for r in rows]
    out += ["", "Issue targets (session frame over HTTP, round trip): 1k objects p50 <= 2 ms "
            "and p99 <= 5 ms; 10k objects p50 <= 10 ms. This run:", ""]
    out += [f"- {v}" for v in verdicts(rows)]
    full = {r["n"]: r for r in rows if r["via"] == "HTTP" and r["mode"] == "full"}
    if full:
        out += ["", "**Answer (service latency):** a session frame round trip over HTTP takes "
                + "; ".join(f"p50 {r['p50']:.2f} ms, p99 {r['p99']:.2f} ms at {fmt_count(n)} objects"
                            for n, r in sorted(full.items())) + "."]
    out += ["", END]
    return "\n".join(out) + "\n"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--sizes", type=parse_sizes, default=parse_sizes("1k:100,10k:1k"),
                   help="comma-separated N:L pairs (default 1k:100,10k:1k)")
    p.add_argument("--frames", type=float, default=1.0,
                   help="scale of the timed frames per case (default 1: 300 below 5k objects, "
                        "150 below 50k, 50 above)")
    p.add_argument("--warmup", type=int, default=20, help="warm-up frames per case (default 20)")
    p.add_argument("--runs", type=int, default=2,
                   help="runs per case, each with a new session (default 2)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--write", action="store_true", help="write the table into bench/RESULTS.md")
    p.add_argument("--quick", action="store_true",
                   help="a cut for make bench-quick: a fifth of the frames, one run")
    args = p.parse_args(argv)
    if args.quick:
        args.frames, args.runs = args.frames * 0.2, 1
    if args.frames <= 0 or args.warmup < 0 or args.runs < 1:
        p.error("--frames must be > 0, --warmup >= 0 and --runs >= 1")

    m = machine()
    say(f"lightsched {lightsched.__version__} at {git_commit()}; {m['cpu']}, {m['nproc']} CPUs")
    t0 = time.perf_counter()
    load0 = os.getloadavg()[0]
    server = Server()
    try:
        say(f"server up on {server.url} in {time.perf_counter() - t0:.1f} s")
        rows = [r for n, l in args.sizes for r in bench_size(server, n, l, args)]
    finally:
        server.stop()
    load = (load0, os.getloadavg()[0])
    print_table(rows)
    say(f"\n{time.perf_counter() - t0:.0f} s in all; 1-minute load average {load[0]:.2f} before, "
        f"{load[1]:.2f} after")
    if args.write:
        write_results(render(rows, args, load), BEGIN, END)
    return 0


if __name__ == "__main__":
    sys.exit(main())
