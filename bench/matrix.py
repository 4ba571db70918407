"""The kernel matrix (issue 49): scenes x sizes x targets, with ns per pair and per object.

    python bench/matrix.py                                        # everything, 3 rounds
    python bench/matrix.py --scenes dense --sizes 10k:1k --targets native,avx2 --rounds 5
    python bench/matrix.py --scenes city,dense --sizes 100k:10k    # the stadium at 100k
                                                                   # takes seconds a frame

Scenes (lightsched.scenes), every point and spot light moving every frame, K = 8, the
default Config (contribution model, fade and hysteresis on):
- city: ``city(N, L)``, sparse (about 4 lights reach an object), the lights at 3 m/s as in
  bench/core.py's ``full``;
- dense: ``dense(N, L)``, about 33 competing lights an object, the lights at 1 m a frame;
- stadium: ``stadium(N)``, 1,000 floodlights at every size (each covers the pitch: at
  10,000 a (100k, 10k) stadium held 250M pairs and ran out of 24 GiB), at 3 m/s.

Targets: ``native`` (what numba sees on this host), and forced through numba's CPU
variables (lightsched.simd.FORCED_TARGETS): ``avx2`` (Haswell's features, no AVX-512: the
measurement of the AVX2 path on an AVX-512 host) and ``x86-64`` (SSE2, no AVX). Each
target runs in processes of its own with a numba cache of its own (bench/.cache/matrix/);
a first process per target compiles, then every round runs each target once, the order
turned round from one round to the next, and the medians over rounds are reported. Times
compare within one run only (paired, interleaved; the machine's speed drifts between runs).

Per row: the frame's median, the candidate lists' and the object pass's stage medians
(``stats["seconds"]``), the pairs (``stats["counts"]["pairs"]``), ns per pair and ns per
object (the frame over them), and the frame against the native target's.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from typing import Any

import numpy as np
from common import (
    HERE,
    SCENE_SPEED,
    SCENES,
    STADIUM_LIGHTS,
    fmt_count,
    git_commit,
    machine,
    make_scene,
    parse_sizes,
    say,
)

from lightsched import Config, Scheduler
from lightsched.scenes import DT, move_lights
from lightsched.simd import FORCED_TARGETS

TARGETS = ("native", *FORCED_TARGETS)
CACHE = HERE / ".cache" / "matrix"


def run_case(scene: str, n: int, l: int, frames: int, warmup: int, seed: int) -> dict[str, Any]:
    """One scene's frames in this process: the medians of the timed ones."""
    sc = make_scene(scene, n, l, seed)
    s = Scheduler(Config(max_lights=8))
    s.set_lights(**sc.lights)
    s.set_objects(**sc.objects)
    times, seconds, pairs = [], [], []
    for i in range(warmup + frames):
        if i:
            s.update_lights(id=sc.lights["id"],
                            position=move_lights(sc.lights, i, speed=SCENE_SPEED[scene]))
        t0 = time.perf_counter()
        f = s.frame(sc.cameras, dt=DT)
        t = time.perf_counter() - t0
        if i >= warmup:
            times.append(t)
            seconds.append(f.stats["seconds"])
            pairs.append(f.stats["counts"]["pairs"])
    return {"frame_ms": float(np.median(times)) * 1e3,
            "lists_ms": float(np.median([x.get("lists", 0.0) for x in seconds])) * 1e3,
            "objects_ms": float(np.median([x.get("objects", 0.0) for x in seconds])) * 1e3,
            "pairs": int(np.median(pairs))}


def child(args: argparse.Namespace) -> int:
    from lightsched.simd import PACKING, target_features

    for scene in args.scenes:
        for n, l in args.sizes:
            r = run_case(scene, n, l, args.frames, args.warmup, args.seed)
            print(json.dumps({"scene": scene, "n": n, "l": l, **r}), flush=True)
    print(json.dumps({"packing": PACKING, "avx512": "+avx512f" in target_features()}))
    return 0


def target_env(target: str) -> dict[str, str]:
    env = dict(os.environ, NUMBA_CACHE_DIR=str(CACHE / target))
    if target in FORCED_TARGETS:
        env["NUMBA_CPU_NAME"], env["NUMBA_CPU_FEATURES"] = FORCED_TARGETS[target]
    return env


def start_target(target: str, rest: list[str], frames: int | None = None) -> subprocess.Popen:
    """A child running every case on ``target`` (``frames``: a short run that compiles)."""
    more = [] if frames is None else ["--frames", str(frames), "--warmup", "2"]
    return subprocess.Popen([sys.executable, __file__, *rest, *more, "--child"],
                            env=target_env(target), stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)


def results(target: str, child: subprocess.Popen) -> list[dict[str, Any]]:
    """The child's lines: one per case, then its packing."""
    out, err = child.communicate()
    if child.returncode != 0:
        raise SystemExit(f"target {target}: {err[-3000:]}")
    return [json.loads(line) for line in out.splitlines() if line.startswith("{")]


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--scenes", type=lambda t: t.split(","), default=list(SCENES))
    p.add_argument("--sizes", type=parse_sizes, default=parse_sizes("10k:1k,100k:10k"))
    p.add_argument("--targets", type=lambda t: t.split(","), default=list(TARGETS))
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--frames", type=int, default=30, help="timed frames a case (default 30)")
    p.add_argument("--warmup", type=int, default=90,
                   help="frames first (default 90: the candidate lists reach their steady "
                        "state, bench/core.py's STEADY_WARMUP)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    bad = [x for x in args.scenes if x not in SCENES] + [
        x for x in args.targets if x not in TARGETS]
    if bad:
        p.error(f"unknown scene or target {bad}; scenes {SCENES}, targets {TARGETS}")
    if args.child:
        return child(args)
    rest = list(sys.argv[1:] if argv is None else argv)
    m = machine()
    say(f"{m['cpu']}, {m['nproc']} CPUs ({m['numba_threads']} numba threads), {git_commit()}; "
        f"{args.rounds} rounds of {args.frames} frames after {args.warmup}")
    # Each target's kernels compiled into its cache, the targets side by side (a compile
    # takes one core).
    packing = {}
    for at in range(0, len(args.targets), os.cpu_count() or 1):
        started = {t: start_target(t, rest, frames=2)
                   for t in args.targets[at:at + (os.cpu_count() or 1)]}
        packing.update({t: results(t, child)[-1] for t, child in started.items()})
    rows: dict[tuple[str, int, int, str], list[dict[str, Any]]] = {}
    for r in range(args.rounds):
        for target in (args.targets if r % 2 == 0 else args.targets[::-1]):
            for case in results(target, start_target(target, rest))[:-1]:
                rows.setdefault((case["scene"], case["n"], case["l"], target), []).append(case)
    say("| scene | N, L | target (packing) | frame ms | lists ms | objects ms | pairs "
        "| ns / pair | ns / object | frame / native |")
    say("|---|---|---|---|---|---|---|---|---|---|")
    for scene in args.scenes:
        for n, l in args.sizes:
            med = {t: {k: float(np.median([c[k] for c in rows[(scene, n, l, t)]]))
                       for k in ("frame_ms", "lists_ms", "objects_ms", "pairs")}
                   for t in args.targets}
            for t in args.targets:
                x = med[t]
                ratio = (f"{x['frame_ms'] / med['native']['frame_ms']:.2f}"
                         if "native" in med else "")
                shown = STADIUM_LIGHTS if scene == "stadium" else l
                say(f"| {scene} | {fmt_count(n)}, {fmt_count(shown)} | {t} "
                    f"({packing[t]['packing']}) | {x['frame_ms']:.2f} | {x['lists_ms']:.2f} "
                    f"| {x['objects_ms']:.2f} | {int(x['pairs'])} "
                    f"| {x['frame_ms'] * 1e6 / max(x['pairs'], 1):.1f} "
                    f"| {x['frame_ms'] * 1e6 / n:.0f} | {ratio} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
