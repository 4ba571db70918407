"""The residual's cost (issue 53): two Schedulers on one city, residual on and off, full
frames with every light moving, interleaved and paired in one process per numba target
(native, and the AVX2 path forced as bench/clients.py forces it), both targets in one run.

    python bench/residual_cost.py
    python bench/residual_cost.py --frames 40
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time

import numpy as np
from common import machine

from clients import server_env

SIZES = ((10_000, 1_000), (100_000, 10_000))
KS = (4, 8)
WARMUP = 3


def child(n: int, n_lights: int, k: int, frames: int) -> None:
    """One target's run: prints the medians of each side and of the paired differences."""
    import lightsched as ls
    from lightsched.scenes import city, move_lights

    sc = city(n, n_lights, seed=0)
    schedulers = {}
    for on in (True, False):
        s = ls.Scheduler(ls.Config(max_lights=k, residual=on))
        s.set_lights(**sc.lights)
        s.set_objects(**sc.objects)
        s.frame(sc.cameras, dt=1 / 60)
        schedulers[on] = s
    ms: dict[bool, list[float]] = {True: [], False: []}
    for t in range(frames + WARMUP):
        position = move_lights(sc.lights, t + 1)
        for on in ((True, False) if t % 2 else (False, True)):
            s = schedulers[on]
            s.update_lights(id=sc.lights["id"], position=position)
            t0 = time.perf_counter()
            s.frame(sc.cameras, dt=1 / 60)
            if t >= WARMUP:
                ms[on].append((time.perf_counter() - t0) * 1e3)
    on, off = np.array(ms[True]), np.array(ms[False])
    print(json.dumps({"on": float(np.median(on)), "off": float(np.median(off)),
                      "diff": float(np.median(on - off))}))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=20)
    ap.add_argument("--child", nargs=4, type=int, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        child(*args.child)
        return 0
    print(f"{machine()['cpu']}: residual on against off, paired, {args.frames} frames")
    for n, n_lights in SIZES:
        for k in KS:
            for target in ("native", "avx2"):
                cmd = [sys.executable, __file__, "--child", str(n), str(n_lights), str(k),
                       str(args.frames)]
                done = subprocess.run(cmd, env=server_env(target), capture_output=True,
                                      text=True, check=True)
                r = json.loads(done.stdout.strip().splitlines()[-1])
                print(f"({n // 1000}k, {n_lights // 1000}k) K = {k} {target}: off {r['off']:.2f} ms, "
                      f"on {r['on']:.2f} ms, paired {r['diff']:+.2f} ms "
                      f"({100 * r['diff'] / r['off']:+.0f}%)", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
