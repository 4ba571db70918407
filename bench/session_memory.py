"""How much memory a session costs a worker: M sessions of a city of N objects (N/10 lights)
in one real ``lightsched serve``, each set and stepped once; the worker's RSS before and
after, per session.

    python bench/session_memory.py                    # 1k objects: 100 sessions; 40: 1000
    python bench/session_memory.py --sizes 10k --sessions 20
"""

from __future__ import annotations

import argparse
import sys

import psutil
from common import fmt_count, machine, parse_count, say
from lightsched_client import Client
from lightsched_server.cluster import Cluster

import lightsched as ls
from lightsched.scenes import city


def measure(n: int, m: int) -> tuple[float, float, float]:
    """(KiB per session, RSS before MiB, after MiB) for m sessions of n objects."""
    scene = city(n, max(1, n // 10), seed=0)
    with Cluster(1, warm_up=False, env={"LIGHTSCHED_MAX_SESSIONS": str(m + 1)}) as c, \
            Client(c.worker_url(0)) as client:
        proc = psutil.Process(c.workers[0].pid)

        def one() -> None:
            s = client.session(ls.Config())
            s.set_lights(**scene.lights)
            s.set_objects(**scene.objects)
            s.frame(scene.cameras)

        one()  # the kernels and the first frame's buffers: not a session's cost
        base = proc.memory_info().rss
        for _ in range(m):
            one()
        full = proc.memory_info().rss
    return (full - base) / m / 1024, base / 2**20, full / 2**20


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--sizes", default="40,1k", help="object counts (default 40,1k)")
    p.add_argument("--sessions", default="1000,100", help="sessions per size (1000,100)")
    args = p.parse_args(argv)
    sizes = [parse_count(x) for x in args.sizes.split(",")]
    counts = [int(x) for x in args.sessions.split(",")]
    mach = machine()
    say(f"{mach['cpu']}, {mach['nproc']} CPUs")
    for n, m in zip(sizes, counts, strict=True):
        kib, before, after = measure(n, m)
        say(f"{m} sessions of {fmt_count(n)} objects, {max(1, n // 10)} lights: {kib:.0f} KiB "
            f"each (worker RSS {before:.0f} -> {after:.0f} MiB)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
