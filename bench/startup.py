"""First frames of a new process: what numba's compile and cache load cost a client, with
and without lightsched.warmup.

    python bench/startup.py --runs 3                 # numba's cache as it is (filled)
    python bench/startup.py --runs 1 --cold          # an empty cache: minutes per case
    python bench/startup.py --runs 3 --where core    # the embedded API only

Each case is a fresh process (a new Python, the kernels not yet in it), alternating "no
warm-up" and "warm-up" run by run. ``core``: a Scheduler on city(N, N/10) takes its first
frames (every light moving), after ``warm_up()`` or not. ``service``: ``lightsched serve``
(``--no-warm-up`` or not) in a process of its own; the seconds until its port answers
/healthz, then the Python client's first frames of a new session of the same city (the
first carries the scene). ``--cold`` gives each process an empty NUMBA_CACHE_DIR of its
own, as on a machine's first start. A frame that fails (the client's default 60 s
timeout) is printed as such.
"""

from __future__ import annotations

import argparse
import json
import os
import socket
import subprocess
import sys
import tempfile
import time
from typing import Any

from common import fmt_count, git_commit, say

CORE = """
import json, sys, time
from lightsched import Config, Scheduler
from lightsched.scenes import city, move_lights
from lightsched.warmup import warm_up
n, frames, warm = int(sys.argv[1]), int(sys.argv[2]), sys.argv[3] == "1"
w = warm_up().seconds if warm else None
sc = city(n, n // 10, seed=0)
s = Scheduler(Config())
s.set_lights(**sc.lights)
s.set_objects(**sc.objects)
ms = []
for i in range(frames):
    t = time.perf_counter()
    s.update_lights(id=sc.lights["id"], position=move_lights(sc.lights, i + 1))
    s.frame(sc.cameras, dt=1 / 60)
    ms.append((time.perf_counter() - t) * 1e3)
print(json.dumps({"warm_up_s": w, "frames_ms": ms}))
"""


def core_case(n: int, frames: int, warm: bool, env: dict[str, str]) -> dict[str, Any]:
    out = subprocess.run([sys.executable, "-c", CORE, str(n), str(frames), str(int(warm))],
                         capture_output=True, text=True, env=env, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def service_case(n: int, frames: int, warm: bool, env: dict[str, str]) -> dict[str, Any]:
    from lightsched_client import Client

    from lightsched.scenes import city, move_lights

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    t0 = time.perf_counter()
    proc = subprocess.Popen([sys.executable, "-m", "lightsched", "serve", "--port", str(port),
                             "--no-demo", "--log-level", "warning"]
                            + ([] if warm else ["--no-warm-up"]),
                            stdout=subprocess.DEVNULL, env=env)
    try:
        with Client(f"http://127.0.0.1:{port}") as c:
            while True:
                try:
                    c.health()
                    break
                except OSError:
                    if proc.poll() is not None:
                        raise RuntimeError("the server exited") from None
                    time.sleep(0.02)
            up = time.perf_counter() - t0
            sc = city(n, n // 10, seed=0)
            session = c.session()
            session.set_lights(**sc.lights)
            session.set_objects(**sc.objects)
            ms: list[float | str] = []
            for i in range(frames):
                t = time.perf_counter()
                if i:
                    session.update_lights(id=sc.lights["id"],
                                          position=move_lights(sc.lights, i))
                try:
                    session.frame(sc.cameras, dt=1 / 60)
                except Exception as e:  # noqa: BLE001 - the failure is the measurement
                    ms.append(f"failed after {time.perf_counter() - t:.1f} s "
                              f"({type(e).__name__})")
                    break
                ms.append((time.perf_counter() - t) * 1e3)
        return {"port_open_s": up, "frames_ms": ms}
    finally:
        proc.terminate()
        proc.wait()


def _fmt_frames(ms: list[Any]) -> str:
    return ", ".join(m if isinstance(m, str) else f"{m:.1f}" for m in ms)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--objects", type=int, default=1000, help="N of city(N, N/10)")
    ap.add_argument("--frames", type=int, default=4, help="frames per case")
    ap.add_argument("--runs", type=int, default=3, help="processes per case")
    ap.add_argument("--where", choices=("core", "service", "both"), default="both")
    ap.add_argument("--cold", action="store_true",
                    help="an empty numba cache per process (a machine's first start)")
    args = ap.parse_args(argv)
    say(f"bench/startup.py at {git_commit()}: city({fmt_count(args.objects)}, "
        f"{fmt_count(args.objects // 10)}), {args.frames} frames, numba cache "
        + ("empty per process" if args.cold else "as it is"))
    where = ("core", "service") if args.where == "both" else (args.where,)
    for run in range(args.runs):
        for kind in where:
            for warm in (False, True):
                with tempfile.TemporaryDirectory(prefix="lightsched-numba-") as cache:
                    env = dict(os.environ)
                    if args.cold:
                        env["NUMBA_CACHE_DIR"] = cache
                    if kind == "core":
                        r = core_case(args.objects, args.frames, warm, env)
                        head = ("warm_up " + (f"{r['warm_up_s']:.2f} s" if warm else "no"))
                    else:
                        r = service_case(args.objects, args.frames, warm, env)
                        head = (("serve" if warm else "serve --no-warm-up")
                                + f", port open after {r['port_open_s']:.2f} s")
                say(f"run {run + 1} {kind:<7} {head}; frames ms: {_fmt_frames(r['frames_ms'])}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
