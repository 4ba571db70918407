"""Paired A/B of the core in one process: the working tree's lightsched against a commit's.

    python bench/paired.py --base HEAD~1                          # full and lights10 at 100k
    python bench/paired.py --base fdf791a --sizes 1M:100k --scenarios all --frames 10
    python bench/paired.py --base 41b6ba6 --new 8008441 --first base    # two commits

The base commit's ``lightsched/`` is extracted (``git archive``, as bench/history.py does)
and the working tree's copied, and both are imported under other names
(``lightsched_base``, ``lightsched_new``) without their numba caches, so both sides compile
their kernels in this process (a side that loads numba's cache runs other code: below). Both
get a Scheduler on the same scene and the same motion (bench/core.py's scenarios), and
their frames alternate (A B, then B A, ...), so the minutes when this noisy 2-core box is
slow hit both alike. Reported per (size, scenario): each side's median frame time and the
median of the per-frame differences (working tree - base) with its quartiles, and the
stages (``stats["seconds"]``) whose medians moved most. The mean of the differences is
given too: a change to work done every few frames (packing the pair cache) leaves the
median difference near 0 and shows in the mean. The two schedulers hold two copies of the
state, so each frame finds a colder cache than it would alone: the absolute times are above
bench/core.py's, the difference is what this measures.

Use it for changes of a few percent, which separate processes (bench/history.py) cannot
resolve here: their run medians spread by +-10% from one minute to the next.
A/A runs (the same commit on both sides, ``--base HEAD`` or ``--new X --base X``) are broken
since issue 48: the "new" side runs 2-3x behind in every stage whichever side goes first
(bench/RESULTS.md, issue 48); a swap of the roles (``--base B --new A`` against ``--base A``)
checks a difference instead. Earlier, its resolution from A/A runs: at (100k, 10k) one
run's median difference moved by up to ~0.5 ms with no change, its quartiles sometimes
excluding zero (bench/RESULTS.md); repeat a run before trusting a
difference of that size. Until the sides both compiled, the working tree's loaded numba's
cache and the base compiled: that alone put ~+0.5 ms on the working tree's object pass at
(100k, 10k) (A/A +0.70 ms, objects 5.23 -> 5.71; with both compiling +0.05).

Why loaded code differs: numba compiles a parallel loop's body (the "gufunc") in a library
of its own, then links a copy into the kernel's module, where LLVM optimises it again; the
cache stores that module's machine code. A process that compiles runs the first copy (the
JIT linker resolves the copy's weak symbol to the definition loaded first), a process that
loads the cache runs the copy optimised again: other code (for the object pass 2,524
instructions against 2,074), ~0.5 ms slower in a (100k, 10k) frame. ``--cached both``
measures the code the service and bench/core.py run (a child process compiles both sides
first and writes their caches); ``--base HEAD --cached base`` measures the difference.
"""

from __future__ import annotations

import argparse
import dataclasses
import importlib.util
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
from common import fmt_count, git_commit, machine, parse_sizes, say
from core import DT, Motion, add_object_ids, make_scene, parse_scenarios
from history import extract, resolve

import lightsched
from lightsched.warmup import cache_counts


def load_package(path: Path, name: str, fresh: bool = True) -> Any:
    """The package at path/lightsched imported as ``name`` (its relative imports resolve
    inside it, so the two versions do not mix). ``fresh``: its numba cache removed first,
    so that it compiles its kernels in this process (see the module's docstring)."""
    if fresh:
        shutil.rmtree(path / "lightsched" / "__pycache__", ignore_errors=True)
    spec = importlib.util.spec_from_file_location(
        name, path / "lightsched" / "__init__.py",
        submodule_search_locations=[str(path / "lightsched")])
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module


def copy_worktree(workdir: Path) -> Path:
    """The working tree's lightsched/ copied under workdir (as extract() does a commit's)."""
    dest = workdir / "worktree"
    shutil.rmtree(dest, ignore_errors=True)
    shutil.copytree(Path(lightsched.__file__).parent, dest / "lightsched",
                    ignore=shutil.ignore_patterns("__pycache__"))
    return dest


def new_side(commit: str | None, workdir: Path, copy: bool) -> Path:
    """The folder of the new side's lightsched/: the working tree's copy (``copy``: made
    now), or ``commit`` extracted in a folder of its own (so it may equal the base)."""
    if commit is None:
        return copy_worktree(workdir) if copy else workdir / "worktree"
    return extract(resolve(commit), workdir / "new")


def paired(packages: dict[str, Any], n: int, l: int, scenario: str, frames: int, warmup: int,
           seed: int, object_ids: str = "random") -> dict[str, Any]:
    """Frames of both sides alternated; per side the frame times and stage seconds."""
    scene = make_scene(n, l, seed, True, object_ids=object_ids)
    sides = {}
    for side, pkg in packages.items():
        s = pkg.Scheduler(pkg.Config(max_lights=8))
        s.set_lights(**scene.lights)
        s.set_objects(**scene.objects)
        sides[side] = (s, Motion(scenario, scene, seed))
    warmup = max(warmup, sides["new"][1].warmup_min)
    times: dict[str, list[float]] = {side: [] for side in sides}
    stages: dict[str, list[dict[str, float]]] = {side: [] for side in sides}
    for i in range(warmup + frames):
        for side in (("new", "base") if i % 2 else ("base", "new")):
            s, motion = sides[side]
            # Cameras as mappings: each package checks its own Camera class.
            cams = [dataclasses.asdict(c) for c in motion.step(s, i)]
            t0 = time.perf_counter()
            f = s.frame(cams, dt=DT)
            t = time.perf_counter() - t0
            if i >= warmup:
                times[side].append(t)
                stages[side].append(dict(f.stats["seconds"]))
    d = np.array(times["new"]) - np.array(times["base"])
    return {"n": n, "l": l, "scenario": scenario, "frames": frames,
            "new_ms": float(np.median(times["new"])) * 1e3,
            "base_ms": float(np.median(times["base"])) * 1e3,
            "diff_ms": float(np.median(d)) * 1e3,
            "diff_mean_ms": float(np.mean(d)) * 1e3,
            "diff_q_ms": [float(np.percentile(d, 25)) * 1e3, float(np.percentile(d, 75)) * 1e3],
            "stages": {side: {k: float(np.median([x.get(k, 0.0) for x in v])) * 1e3
                              for k in v[0]} for side, v in stages.items()}}


def stage_moves(r: dict[str, Any], top: int = 3) -> str:
    new, base = r["stages"]["new"], r["stages"]["base"]
    moves = sorted(((new.get(k, 0.0) - base.get(k, 0.0), k) for k in base if k != "total"),
                   key=lambda x: -abs(x[0]))[:top]
    return ", ".join(f"{k} {base[k]:.2f} -> {new.get(k, 0.0):.2f}" for _, k in moves)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--base", required=True, help="the commit to compare the working tree with")
    p.add_argument("--new", default=None,
                   help="a commit to take the working tree's place (default: the working tree)")
    p.add_argument("--sizes", default="100k:10k", help="N:L pairs (default 100k:10k)")
    p.add_argument("--scenarios", default="full,lights10",
                   help="bench/core.py scenarios (default full,lights10)")
    p.add_argument("--frames", type=int, default=60, help="timed frames per side (default 60)")
    p.add_argument("--warmup", type=int, default=5,
                   help="untimed frames first (at least the scenario's own warm-up)")
    p.add_argument("--seed", type=int, default=0)
    add_object_ids(p)
    p.add_argument("--workdir", default=None,
                   help="where to extract the base and copy the working tree (kept, "
                        "with numba caches only under --cached; default a temporary folder)")
    p.add_argument("--cached", choices=["none", "base", "new", "both"], default="none",
                   help="the sides that run the code numba loads from its cache, as the "
                        "service does (a child process compiles them first, writing their "
                        "caches); the others compile in this process (default none; the "
                        "module docstring says why the two differ)")
    p.add_argument("--first", choices=["new", "base"], default="new",
                   help="the side imported, compiled and given its Scheduler first (default "
                        "new): swapping it shows what the order alone does")
    p.add_argument("--prime", action="store_true", help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    base = resolve(args.base)
    with tempfile.TemporaryDirectory() as tmp:
        workdir = Path(args.workdir) if args.workdir else Path(tmp)
        cached = {"new": args.cached in ("new", "both"), "base": args.cached in ("base", "both")}
        if any(cached.values()) and not args.prime:
            # The child copies and compiles both sides; the sides to load from the cache
            # are then imported from its copies, which kept their caches.
            rest = list(sys.argv[1:] if argv is None else argv)
            subprocess.run([sys.executable, __file__, *rest, "--prime", "--workdir",
                            str(workdir)], check=True)
            paths = {"new": new_side(args.new, workdir, copy=False), "base": extract(base, workdir)}
        else:
            paths = {"new": new_side(args.new, workdir, copy=True), "base": extract(base, workdir)}
        order = ("new", "base") if args.first == "new" else ("base", "new")
        packages = {side: load_package(paths[side], "lightsched_" + side,
                                       fresh=args.prime or not cached[side])
                    for side in order}
        if args.prime:
            # Every kernel and signature the timed run will call, compiled and cached (some
            # arrays turn read-only, a signature of their own, after the first frames).
            for n, l in parse_sizes(args.sizes):
                for scenario in parse_scenarios(args.scenarios):
                    paired(packages, n, l, scenario, 3, args.warmup, args.seed,
                           args.object_ids)
            # And every path's (a side's lightsched.warmup, where it has one): the timed
            # frames may take paths the primed ones did not (a compile in a timed frame
            # cost one run +0.3 s).
            for pkg in packages.values():
                if importlib.util.find_spec(pkg.__name__ + ".warmup") is not None:
                    importlib.import_module(pkg.__name__ + ".warmup").warm_up()
            return 0
        m = machine()
        new = git_commit() if args.new is None else resolve(args.new)["sha"][:7]
        say(f"{m['cpu']}, {m['nproc']} CPUs ({m['numba_threads']} numba threads); new side "
            f"{new} against base {base['sha'][:7]} ({base['subject'][:60]}...); object "
            f"ids {args.object_ids}; kernels loaded from numba's cache: {args.cached}; "
            f"first side: {args.first}")
        say("| N | L | scenario | base ms | working tree ms | difference ms (quartiles) "
            "| mean difference ms | stages that moved most (base -> working tree, ms) |")
        say("|---|---|---|---|---|---|---|---|")
        for n, l in parse_sizes(args.sizes):
            for scenario in parse_scenarios(args.scenarios):
                r = paired(packages, n, l, scenario, args.frames, args.warmup, args.seed,
                           args.object_ids)
                q = r["diff_q_ms"]
                say(f"| {fmt_count(n)} | {fmt_count(l)} | {scenario} | {r['base_ms']:.2f} "
                    f"| {r['new_ms']:.2f} | {r['diff_ms']:+.2f} ({q[0]:+.2f}..{q[1]:+.2f}) "
                    f"| {r['diff_mean_ms']:+.2f} | {stage_moves(r)} |")
        say("numba kernels (signatures) loaded from the cache / compiled here: " + ", ".join(
            f"{side} {loaded} / {compiled}" for side, (loaded, compiled) in
            ((side, cache_counts(pkg)) for side, pkg in packages.items())))
    return 0


if __name__ == "__main__":
    sys.exit(main())
