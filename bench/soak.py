"""Soak: M 60 fps game clients against one real LightSched server for many minutes; does its
memory stay flat and its latency steady?

    python bench/soak.py                        # 10 minutes, 8 clients of 1k objects, HTTP
    python bench/soak.py --minutes 1 --clients 4  # a short check
    python bench/soak.py --write                # also the "Issue 54: soak" part of RESULTS.md

The server is bench/load.py's (``python -m lightsched serve``; with ``--workers N`` HAProxy in
front of N of them), and so are the clients (load.Game: a session each, every light moving
every frame, on an absolute 60 fps schedule, in one asyncio client process). Each minute
is measured on its own: latency percentiles, missed deadlines, and the server's RSS sampled
every 5 s (its mean, and the spread of the samples). The first minute is warm-up (numba's
first frames, allocator pools); RSS growth is the last minute's mean over the second's.
"""

from __future__ import annotations

import argparse
import asyncio
import sys
import threading
import time
from typing import Any

import numpy as np
import psutil
from common import git_commit, machine, parse_count, say
from load import PERIOD, ClientSpec, Game, start_server

GROWTH_OK = 5.0  # % RSS growth after warm-up that still counts as flat (issue 54)


async def soak(port: int, args: argparse.Namespace, rows: list[dict[str, Any]],
               rss: list[list[float]]) -> None:
    rng = np.random.default_rng(args.seed)
    games = [Game(port, ClientSpec(c, float(rng.uniform(0.0, PERIOD))), args.objects,
                  args.seed, args.transport, False) for c in range(args.clients)]
    try:
        await asyncio.gather(*(g.setup() for g in games))
        for minute in range(args.minutes):
            t0 = time.monotonic() + 0.05
            rss.append([])
            results = await asyncio.gather(*(g.play(t0, t0, t0 + args.window)
                                              for g in games))
            lat = np.concatenate([np.asarray(r.latency) for r in results]) if results else []
            slots = sum(r.slots for r in results)
            missed = slots - sum(r.answered - r.late for r in results)
            errors = [r.error for r in results if r.error]
            row = {"minute": minute + 1, "frames": int(sum(r.answered for r in results)),
                   "missed": 100.0 * missed / max(slots, 1),
                   "rss": float(np.mean(rss[-1])) if rss[-1] else float("nan"),
                   "rss_spread": float(np.ptp(rss[-1])) if rss[-1] else float("nan"),
                   **{f"p{q}": float(np.percentile(lat, q)) if len(lat) else float("nan")
                      for q in (50, 95, 99)},
                   "max": float(np.max(lat)) if len(lat) else float("nan")}
            rows.append(row)
            say(f"minute {row['minute']:2d}: {row['frames']} frames, p50 {row['p50']:.2f} ms, "
                f"p95 {row['p95']:.2f}, p99 {row['p99']:.2f}, max {row['max']:.1f}, missed "
                f"{row['missed']:.2f}%, server RSS {row['rss'] / 2**20:.1f} MiB (samples "
                f"{len(rss[-1])}, spread {row['rss_spread'] / 2**10:.0f} KiB)"
                + (f"; errors: {errors[:2]}" if errors else ""))
    finally:
        await asyncio.gather(*(g.close() for g in games), return_exceptions=True)


def sample_rss(pids: list[int], rss: list[list[float]], stop: threading.Event) -> None:
    procs = [psutil.Process(p) for p in pids]
    while not stop.wait(5.0):
        if rss:
            rss[-1].append(float(sum(p.memory_info().rss for p in procs)))


def render(rows: list[dict[str, Any]], growth: float, args: argparse.Namespace,
           cpu: str) -> str:
    lines = [f"Soak (`python bench/soak.py --minutes {args.minutes} --clients {args.clients} "
             f"--objects {args.objects} --transport {args.transport}"
             + (f" --workers {args.workers}" if args.workers else "") + "`, "
             f"{cpu}, commit {git_commit()}): {args.clients} clients of {args.objects} objects "
             f"at 60 fps, every light moving every frame, for {args.minutes} minutes. Server "
             f"RSS growth after the first minute (warm-up): **{growth:+.2f}%** (limit "
             f"{GROWTH_OK:g}%).", "",
             "| minute | frames | p50 ms | p95 ms | p99 ms | max ms | missed % | server RSS MiB "
             "| RSS spread KiB |",
             "|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        lines.append(f"| {r['minute']} | {r['frames']} | {r['p50']:.2f} | {r['p95']:.2f} | "
                     f"{r['p99']:.2f} | {r['max']:.1f} | {r['missed']:.2f} | "
                     f"{r['rss'] / 2**20:.1f} | {r['rss_spread'] / 2**10:.0f} |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--minutes", type=int, default=10, help="minutes to run (10)")
    p.add_argument("--clients", type=int, default=8, help="60 fps clients (8)")
    p.add_argument("--objects", type=parse_count, default=1000,
                   help="objects per client's city, lights a tenth (1k)")
    p.add_argument("--transport", choices=("http", "ws"), default="http")
    p.add_argument("--workers", type=int, default=0,
                   help="server processes behind HAProxy; 0 (default): one, no balancer")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", default=None, help="also write the table (markdown) to this file")
    args = p.parse_args(argv)
    if args.minutes < 2:
        p.error("--minutes >= 2: the first minute is warm-up")
    args.window = 60.0
    m = machine()
    cpu = f"{m['cpu']}, {m['nproc']} CPUs"
    say(f"soak: {args.clients} clients x {args.minutes} min on {cpu}")
    server = start_server({}, args.workers)
    rows: list[dict[str, Any]] = []
    rss: list[list[float]] = []
    stop = threading.Event()
    sampler = threading.Thread(target=sample_rss, args=(server.pids(), rss, stop), daemon=True)
    sampler.start()
    try:
        asyncio.run(soak(server.port, args, rows, rss))
    finally:
        stop.set()
        server.stop()
    growth = 100.0 * (rows[-1]["rss"] / rows[1]["rss"] - 1.0)
    say(f"server RSS growth after warm-up: {growth:+.2f}% (limit {GROWTH_OK:g}%)")
    table = render(rows, growth, args, cpu)
    print(table)
    if args.out:
        with open(args.out, "w") as f:
            f.write(table)
    return 0 if growth < GROWTH_OK else 1


if __name__ == "__main__":
    sys.exit(main())
