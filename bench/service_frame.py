"""The service's own cost of a frame, in one process: no sockets, no HTTP.

    python bench/service_frame.py                        # 25 sessions of city(1000, 100)
    python bench/service_frame.py --sessions 1 --frames 2000
    python bench/service_frame.py --root /tmp/base       # another checkout's lightsched,
                                                         # server and client (A/B)

What the server's event loop does for a frame besides the HTTP or WebSocket stack: msgpack
decode of the request body, ``Service.frame`` (request checks, cameras, ``update_lights``
with every light's new position, ``Scheduler.frame`` on one numba thread as the service runs
small scenes, metrics, the response map) and msgpack encode of the answer. The sessions take
their frames in turn, as under `bench/load.py`'s clients, so each frame finds the caches as
the other sessions left them. Printed: the median and quartiles of that time per frame over
the timed frames, after as many warm-up frames (the request bodies are made outside the
timing, as a game's client makes them). bench/load.py measures the whole server under load.
"""

from __future__ import annotations

import argparse
import asyncio
import os
import sys
import time

import numpy as np


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--sessions", type=int, default=25)
    p.add_argument("--objects", type=int, default=1000, help="N; the city has N/10 lights")
    p.add_argument("--frames", type=int, default=400, help="timed frames per session")
    p.add_argument("--root", default=os.path.dirname(os.path.dirname(os.path.abspath(__file__))),
                   help="the checkout whose lightsched/, server/ and client are measured")
    args = p.parse_args(argv)
    sys.path[:0] = [args.root, os.path.join(args.root, "clients", "python")]
    import numba as nb
    from lightsched_client.client import _Changes
    from lightsched_client.wire import MSGPACK, dumps, loads

    from lightsched.scenes import city, move_lights
    from server.service import Service

    nb.set_num_threads(1)
    period = 1 / 60
    svc = Service()
    loop = asyncio.new_event_loop()
    games = []
    for g in range(args.sessions):
        scene = city(args.objects, max(1, args.objects // 10), seed=g)
        s = svc.create_session({}, None)
        ch = _Changes()
        ch.set_lights(**scene.lights)
        ch.set_objects(**scene.objects)
        body = dumps(ch._request(scene.cameras, period, False, None, False), MSGPACK)
        loop.run_until_complete(svc.frame(s.id, None, loads(body, MSGPACK)))
        games.append((s.id, scene))

    def body(i: int) -> tuple[str, bytes]:
        sid, scene = games[i % len(games)]
        ch = _Changes()
        ch.update_lights(id=scene.lights["id"],
                         position=move_lights(scene.lights, i // len(games) + 1))
        return sid, dumps(ch._request(scene.cameras, period, False, None, False), MSGPACK)

    def one(sid: str, data: bytes) -> float:
        t0 = time.perf_counter()
        doc = loop.run_until_complete(svc.frame(sid, None, loads(data, MSGPACK)))
        dumps(doc, MSGPACK)
        return time.perf_counter() - t0

    n = args.frames * len(games)
    bodies = [body(i) for i in range(2 * n)]
    for sid, data in bodies[:n]:
        one(sid, data)
    us = np.array([one(sid, data) for sid, data in bodies[n:]]) * 1e6
    q1, med, q3 = np.percentile(us, [25, 50, 75])
    print(f"{args.root}: {args.sessions} sessions of city({args.objects}, "
          f"{max(1, args.objects // 10)}), {n} timed frames: decode + Service.frame + encode "
          f"median {med:.1f} us (quartiles {q1:.1f}..{q3:.1f})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
