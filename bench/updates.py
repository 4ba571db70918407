"""The scene updates a game sends before each frame, timed: bench/core.py times the frame only.

    python bench/updates.py                                   # 1k:100, 10k:1k, 100k:10k
    python bench/updates.py --base 467c8bc                    # against a commit's core
    python bench/updates.py --sizes 100k:10k --scenarios full --calls 400

Per size and scenario, the calls bench/core.py's motion makes between frames (``full``:
``update_lights`` with every light's new position, in the scene's id order, which is not
the store's row order; ``lights10``/``lights1``: the same for a fixed 10% or 1% of the
point and spot lights; ``objects1``/``objects10``: ``update_objects`` with the bounds of a
fixed 1% or 10% of the objects), made on a Scheduler holding the scene, with no frame
between them (a frame is what clears the stores' touched rows; they are cleared here after
each call instead, so that every call is the first since a frame, as in a game). Each
call's arguments are made before it is timed. With ``--base``, that commit's core (its
``lightsched/`` extracted as bench/paired.py does) gets the same calls on a Scheduler of its
own in the same process, the calls alternating (A B, then B A), so the slow minutes of this
noisy box hit both alike; reported: each side's median and the median of the per-call
differences with their quartiles. The update path runs no numba kernel, so no side compiles.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
from common import fmt_count, git_commit, machine, parse_sizes, say
from core import Motion, make_scene
from history import extract, resolve
from paired import load_package

import lightsched

SCENARIOS = ("full", "lights10", "lights1", "objects1", "objects10")


class _Recorder:
    """Stands in for a Scheduler in Motion.step: keeps the update call it is given."""

    def __init__(self) -> None:
        self.call: tuple[str, dict[str, Any]] | None = None

    def update_lights(self, **fields: Any) -> None:
        self.call = ("update_lights", fields)

    def update_objects(self, **fields: Any) -> None:
        self.call = ("update_objects", fields)


def calls(scene: Any, scenario: str, count: int, seed: int) -> list[tuple[str, dict[str, Any]]]:
    """The update calls of frames 1..count of ``scenario`` (bench/core.py's Motion)."""
    motion, rec, out = Motion(scenario, scene, seed), _Recorder(), []
    for i in range(1, count + 1):
        rec.call = None
        motion.step(rec, i)
        assert rec.call is not None, f"{scenario} makes no update call"
        out.append(rec.call)
    return out


def time_calls(packages: dict[str, Any], scene: Any, made: list[tuple[str, dict[str, Any]]]
               ) -> dict[str, np.ndarray]:
    """Per side, each call's seconds; sides alternate call by call."""
    sides = {}
    for side, pkg in packages.items():
        s = pkg.Scheduler(pkg.Config(max_lights=8))
        s.set_lights(**scene.lights)
        s.set_objects(**scene.objects)
        sides[side] = s
    times: dict[str, list[float]] = {side: [] for side in sides}
    order = list(sides)
    for i, (op, fields) in enumerate(made):
        for side in (order if i % 2 == 0 else order[::-1]):
            s = sides[side]
            # A new dict each time: an update pops the ids from its keyword arguments.
            given = dict(fields)
            t0 = time.perf_counter()
            getattr(s, op)(**given)
            times[side].append(time.perf_counter() - t0)
            s.lights.touched = ()
            s.objects.touched = ()
    return {side: np.array(t) for side, t in times.items()}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--base", default=None,
                   help="also time this commit's core, calls alternated with the working tree's")
    p.add_argument("--sizes", default="1k:100,10k:1k,100k:10k",
                   help="N:L pairs (default 1k:100,10k:1k,100k:10k)")
    p.add_argument("--scenarios", default=",".join(SCENARIOS),
                   help=f"motions (default {','.join(SCENARIOS)})")
    p.add_argument("--calls", type=int, default=300, help="timed calls per side (default 300)")
    p.add_argument("--warmup", type=int, default=20, help="untimed calls first (default 20)")
    p.add_argument("--seed", type=int, default=0)
    args = p.parse_args(argv)
    scenarios = [x for x in args.scenarios.split(",") if x]
    bad = [x for x in scenarios if x not in SCENARIOS]
    if bad:
        p.error(f"unknown scenario(s) {', '.join(bad)}; one of {', '.join(SCENARIOS)}")
    m = machine()
    say(f"lightsched from {Path(lightsched.__file__).parent} (working tree at {git_commit()}); "
        f"{m['cpu']}, {m['nproc']} CPUs")
    with tempfile.TemporaryDirectory() as tmp:
        packages: dict[str, Any] = {"new": lightsched}
        if args.base:
            base = resolve(args.base)
            packages["base"] = load_package(extract(base, Path(tmp)), "lightsched_base",
                                            fresh=False)
            say(f"base: {base['sha'][:7]}")
        head = "| N | L | scenario | rows a call | " + (
            "base us | working tree us | difference us (quartiles) |" if args.base
            else "us (p10..p90) |")
        say(head)
        say("|---" * (head.count("|") - 1) + "|")
        for n, l in parse_sizes(args.sizes):
            scene = make_scene(n, l, args.seed, True)
            for scenario in scenarios:
                made = calls(scene, scenario, args.warmup + args.calls, args.seed)
                times = time_calls(packages, scene, made)
                t = {side: v[args.warmup:] * 1e6 for side, v in times.items()}
                rows = int(np.asarray(made[0][1]["id"]).size)
                cells = [fmt_count(n), fmt_count(l), scenario, str(rows)]
                if args.base:
                    d = t["new"] - t["base"]
                    cells += [f"{np.median(t['base']):.1f}", f"{np.median(t['new']):.1f}",
                              f"{np.median(d):+.1f} ({np.percentile(d, 25):+.1f}.."
                              f"{np.percentile(d, 75):+.1f})"]
                else:
                    cells.append(f"{np.median(t['new']):.1f} ({np.percentile(t['new'], 10):.1f}.."
                                 f"{np.percentile(t['new'], 90):.1f})")
                say("| " + " | ".join(cells) + " |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
