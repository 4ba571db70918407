"""Frame by frame: one scheduler's frame times, stages and page faults, alone in a process.

    python bench/frames.py --sizes 1M:100k --scenarios all --frames 12
    python bench/frames.py --base 8c430cf --sizes 1M:100k --scenarios all   # a commit's core

Medians hide a stage that is slow on every other frame; this lists each frame: its time,
the stages of ``stats["seconds"]`` asked for, and the page faults the process took while
it ran (minor faults from getrusage, and 2 MB transparent huge pages from /proc/vmstat,
which count the whole machine). A steady scene should fault nothing: a fault per frame
means an array allocated per frame that the allocator maps afresh (over glibc's mmap
threshold, 32 MB at most). ``--base`` runs a commit's ``lightsched/`` instead of the
working tree's (extracted as bench/paired.py does), so before and after run in separate
processes, each alone.
"""

from __future__ import annotations

import argparse
import dataclasses
import resource
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
from common import fmt_count, git_commit, parse_sizes, say
from core import DT, Motion, add_object_ids, make_scene, parse_scenarios
from history import extract, resolve
from paired import load_package

import lightsched


def thp_faults() -> int:
    """Huge pages faulted in on the machine so far (0 where /proc/vmstat has no count)."""
    try:
        with open("/proc/vmstat") as f:
            for line in f:
                if line.startswith("thp_fault_alloc "):
                    return int(line.split()[1])
    except OSError:
        pass
    return 0


def frames(pkg: Any, n: int, l: int, scenario: str, count: int, warmup: int, seed: int,
           stages: list[str], object_ids: str = "random") -> list[dict[str, float]]:
    """Per timed frame: ms, minor faults, huge-page faults and the stages' ms."""
    scene = make_scene(n, l, seed, True, object_ids=object_ids)
    s = pkg.Scheduler(pkg.Config(max_lights=8))
    s.set_lights(**scene.lights)
    s.set_objects(**scene.objects)
    motion = Motion(scenario, scene, seed)
    rows = []
    for i in range(max(warmup, motion.warmup_min) + count):
        cams = [dataclasses.asdict(c) for c in motion.step(s, i)]
        minor0, thp0 = resource.getrusage(resource.RUSAGE_SELF).ru_minflt, thp_faults()
        t0 = time.perf_counter()
        f = s.frame(cams, dt=DT)
        t = time.perf_counter() - t0
        row = {"frame": i, "ms": t * 1e3,
               "minor": resource.getrusage(resource.RUSAGE_SELF).ru_minflt - minor0,
               "thp": thp_faults() - thp0}
        row.update({k: f.stats["seconds"].get(k, 0.0) * 1e3 for k in stages})
        rows.append(row)
    return rows[-count:]


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--base", default=None,
                   help="run this commit's lightsched/ instead of the working tree's")
    p.add_argument("--sizes", default="1M:100k", help="N:L pairs (default 1M:100k)")
    p.add_argument("--scenarios", default="all", help="bench/core.py scenarios (default all)")
    p.add_argument("--frames", type=int, default=12, help="timed frames (default 12)")
    p.add_argument("--warmup", type=int, default=3,
                   help="untimed frames first (at least the scenario's own warm-up)")
    p.add_argument("--stages", default="grid,pairs,lists,objects",
                   help="stats['seconds'] stages to list (default grid,pairs,lists,objects)")
    p.add_argument("--seed", type=int, default=0)
    add_object_ids(p)
    p.add_argument("--workdir", default=None,
                   help="where to extract --base (kept, with its numba cache)")
    args = p.parse_args(argv)
    stages = [x for x in args.stages.split(",") if x]
    with tempfile.TemporaryDirectory() as tmp:
        if args.base:
            base = resolve(args.base)
            # Its numba cache kept, as the working tree's is: each run alone in a process
            # loads its kernels the same way.
            pkg = load_package(extract(base, Path(args.workdir) if args.workdir else Path(tmp)),
                               "lightsched_base", fresh=False)
            what = f"{base['sha'][:7]}'s core"
        else:
            pkg, what = lightsched, f"working tree {git_commit()}"
        for n, l in parse_sizes(args.sizes):
            for scenario in parse_scenarios(args.scenarios):
                rows = frames(pkg, n, l, scenario, args.frames, args.warmup, args.seed, stages,
                              args.object_ids)
                say(f"{what}, ({fmt_count(n)}, {fmt_count(l)}) {scenario}:")
                say("| frame | ms | minor faults | 2 MB faults | "
                    + " | ".join(f"{k} ms" for k in stages) + " |")
                say("|---" * (4 + len(stages)) + "|")
                for r in rows + [{"frame": "median", **{k: float(np.median([x[k] for x in rows]))
                                                        for k in rows[0] if k != "frame"}}]:
                    say(f"| {r['frame']} | {r['ms']:.1f} | {r['minor']:.0f} | {r['thp']:.0f} | "
                        + " | ".join(f"{r[k]:.1f}" for k in stages) + " |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
