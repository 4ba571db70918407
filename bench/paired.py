"""Paired A/B of the core in one process: the working tree's lightsched against a commit's.

    python bench/paired.py --base HEAD~1                          # full and lights10 at 100k
    python bench/paired.py --base fdf791a --sizes 1M:100k --scenarios all --frames 10
    python bench/paired.py --base 41b6ba6 --new 8008441 --first base    # two commits
    python bench/paired.py --base 41b6ba6 --sizes 10k:1k --isolate 8     # a process a side
    python bench/paired.py --base 41b6ba6 --no-shadows --config residual=false  # like for like

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

``--isolate ROUNDS`` runs each side alone in a child process instead (loaded from numba's
cache, as the service runs), ROUNDS times per size and scenario, the sides alternating; a
round's two medians make one paired difference. Nothing of one side can touch the other's
frames there (the in-process A/A artifact below cannot happen), at the price of the spread
between processes: one commit's median at (10k, 1k) moved between 1.0 and 2.3 ms from one
process to the next (bench/RESULTS.md, issue 48), so take 8 rounds or more.

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
measures the code the service and bench/core.py run (a child process a side compiles it
first and writes its cache); ``--base HEAD --cached base`` measures the difference.
"""

from __future__ import annotations

import argparse
import dataclasses
import importlib.util
import json
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
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


def side_config(pkg: Any, config: dict[str, Any]) -> Any:
    """The side's Config: K = 8 and the fields of ``config`` its Config has (a base from
    before a field was added runs without it)."""
    fields = dataclasses.fields(pkg.Config)
    return pkg.Config(max_lights=8, **{k: v for k, v in config.items()
                                       if any(f.name == k for f in fields)})


def parse_config(items: list[str]) -> dict[str, Any]:
    """--config NAME=VALUE items as Config fields (VALUE read as JSON: false, 0.5, "x")."""
    out = {}
    for item in items:
        name, _, value = item.partition("=")
        out[name] = json.loads(value)
    return out


def run_frames(packages: dict[str, Any], n: int, l: int, scenario: str, frames: int,
               warmup: int, seed: int, object_ids: str = "random", shadows: bool = True,
               config: dict[str, Any] | None = None
               ) -> dict[str, tuple[list[float], list[dict[str, float]]]]:
    """Each side's Scheduler on the same scene and motion, their frames alternated (A B,
    then B A, ...); per side the timed frames' seconds and stage seconds. ``shadows``:
    the city's shadowed lights (False: none); ``config``: Config fields (side_config)."""
    scene = make_scene(n, l, seed, shadows, object_ids=object_ids)
    sides = {}
    for side, pkg in packages.items():
        s = pkg.Scheduler(side_config(pkg, config or {}))
        s.set_lights(**scene.lights)
        s.set_objects(**scene.objects)
        sides[side] = (s, Motion(scenario, scene, seed))
    warmup = max(warmup, next(iter(sides.values()))[1].warmup_min)
    out: dict[str, tuple[list[float], list[dict[str, float]]]] = {
        side: ([], []) for side in sides}
    for i in range(warmup + frames):
        for side in (list(sides)[::-1] if i % 2 else list(sides)):
            s, motion = sides[side]
            # Cameras as mappings: each package checks its own Camera class.
            cams = [dataclasses.asdict(c) for c in motion.step(s, i)]
            t0 = time.perf_counter()
            f = s.frame(cams, dt=DT)
            t = time.perf_counter() - t0
            if i >= warmup:
                out[side][0].append(t)
                out[side][1].append(dict(f.stats["seconds"]))
    return out


def stage_medians(stages: list[dict[str, float]], scale: float = 1e3) -> dict[str, float]:
    """Each stage's median over frames (seconds) or rounds (ms, ``scale`` 1), in ms."""
    return {k: float(np.median([x.get(k, 0.0) for x in stages])) * scale for k in stages[0]}


def summary(new: list[float], base: list[float], stages: dict[str, dict[str, float]],
            **about: Any) -> dict[str, Any]:
    """The medians of paired samples (frames, or isolated rounds) and of their
    differences (new - base), in ms."""
    d = np.array(new) - np.array(base)
    return {**about, "new_ms": float(np.median(new)) * 1e3,
            "base_ms": float(np.median(base)) * 1e3,
            "diff_ms": float(np.median(d)) * 1e3,
            "diff_mean_ms": float(np.mean(d)) * 1e3,
            "diff_q_ms": [float(np.percentile(d, 25)) * 1e3, float(np.percentile(d, 75)) * 1e3],
            "stages": stages}


def paired(packages: dict[str, Any], n: int, l: int, scenario: str,
           args: argparse.Namespace) -> dict[str, Any]:
    """Both sides in this process, frame by frame."""
    out = run_frames(packages, n, l, scenario, args.frames, args.warmup, args.seed,
                     args.object_ids, not args.no_shadows, parse_config(args.config))
    return summary(out["new"][0], out["base"][0],
                   {side: stage_medians(st) for side, (_, st) in out.items()},
                   n=n, l=l, scenario=scenario)


def isolated(rest: list[str], workdir: Path, rounds: int, n: int, l: int, scenario: str
             ) -> dict[str, Any]:
    """Each side alone in a child process that loads it from numba's cache, ``rounds``
    times, the sides alternating (A B, then B A, ...): per round each side's median frame,
    paired by round. No state of one side can touch the other's frames here."""
    medians: dict[str, list[float]] = {"new": [], "base": []}
    stages: dict[str, list[dict[str, float]]] = {"new": [], "base": []}
    for r in range(rounds):
        for side in (("base", "new") if r % 2 else ("new", "base")):
            child = subprocess.run(
                [sys.executable, __file__, *rest, "--workdir", str(workdir), "--child", side,
                 "--sizes", f"{n}:{l}", "--scenarios", scenario],
                capture_output=True, text=True)
            if child.returncode != 0:
                raise SystemExit(f"{side} side, round {r}: {child.stderr[-3000:]}")
            got = json.loads(child.stdout.strip().splitlines()[-1])
            medians[side].append(got["frame_ms"] / 1e3)
            stages[side].append(got["stages"])
    return summary(medians["new"], medians["base"],
                   {side: stage_medians(v, scale=1.0) for side, v in stages.items()},
                   n=n, l=l, scenario=scenario)


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
                        "service does (a child process a side compiles it first, writing its "
                        "cache); the others compile in this process (default none; the "
                        "module docstring says why the two differ)")
    p.add_argument("--first", choices=["new", "base"], default="new",
                   help="the side imported, compiled and given its Scheduler first (default "
                        "new): swapping it shows what the order alone does")
    p.add_argument("--isolate", type=int, default=0, metavar="ROUNDS",
                   help="run each side alone in a process of its own, ROUNDS times per "
                        "size and scenario, the sides alternating; the kernels load from "
                        "numba's cache (implies --cached both)")
    p.add_argument("--no-shadows", action="store_true",
                   help="the city without shadowed lights (default: 1%% of the point and spot "
                        "lights and the sun shadowed)")
    p.add_argument("--config", action="append", default=[], metavar="NAME=VALUE",
                   help="a Config field for both sides, VALUE as JSON (residual=false); a "
                        "side whose Config has no such field runs without it")
    p.add_argument("--prime", action="store_true", help=argparse.SUPPRESS)
    p.add_argument("--child", choices=["new", "base"], help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.isolate:
        args.cached = "both"
    base = resolve(args.base)
    rest = list(sys.argv[1:] if argv is None else argv)
    with tempfile.TemporaryDirectory() as tmp:
        workdir = Path(args.workdir) if args.workdir else Path(tmp)
        cached = {"new": args.cached in ("new", "both"), "base": args.cached in ("base", "both")}
        if args.prime:
            return prime(args, base, workdir)
        if args.child:
            return child(args, base, workdir)
        paths = {"new": new_side(args.new, workdir, copy=True), "base": extract(base, workdir)}
        for side in (s for s in ("new", "base") if cached[s]):
            # A child compiles the side and writes its cache, one side a process: a cache
            # written with both sides in one process referred to the other side's module.
            subprocess.run([sys.executable, __file__, *rest, "--prime", "--child", side,
                            "--workdir", str(workdir)], check=True)
        if args.isolate:
            return report(args, base, lambda n, l, scenario: isolated(
                rest, workdir, args.isolate, n, l, scenario), {})
        order = ("new", "base") if args.first == "new" else ("base", "new")
        packages = {side: load_package(paths[side], "lightsched_" + side, fresh=not cached[side])
                    for side in order}
        return report(args, base, lambda n, l, scenario: paired(
            packages, n, l, scenario, args), packages)


def side_package(args: argparse.Namespace, base: dict[str, str], workdir: Path, fresh: bool
                 ) -> Any:
    """The package of side ``args.child``, from the folder the parent made."""
    path = new_side(args.new, workdir, copy=False) if args.child == "new" else extract(
        base, workdir)
    return load_package(path, "lightsched_" + args.child, fresh=fresh)


def prime(args: argparse.Namespace, base: dict[str, str], workdir: Path) -> int:
    """Compiles side ``args.child`` alone and writes its numba cache: every kernel and
    signature the timed frames will call (some arrays turn read-only, a signature of their
    own, after the first frames), and every path's (its lightsched.warmup, where it has
    one: the timed frames may take paths the primed ones did not; a compile in a timed
    frame cost one run +0.3 s)."""
    pkg = side_package(args, base, workdir, fresh=True)
    for n, l in parse_sizes(args.sizes):
        for scenario in parse_scenarios(args.scenarios):
            run_frames({args.child: pkg}, n, l, scenario, 3, args.warmup, args.seed,
                       args.object_ids, not args.no_shadows, parse_config(args.config))
    if importlib.util.find_spec(pkg.__name__ + ".warmup") is not None:
        importlib.import_module(pkg.__name__ + ".warmup").warm_up()
    return 0


def child(args: argparse.Namespace, base: dict[str, str], workdir: Path) -> int:
    """One side alone, loaded from the cache the prime wrote: its median frame and stage
    medians as one line of JSON (for ``isolated``)."""
    pkg = side_package(args, base, workdir, fresh=False)
    (n, l), = parse_sizes(args.sizes)
    (scenario,) = parse_scenarios(args.scenarios)
    times, stages = run_frames({args.child: pkg}, n, l, scenario, args.frames, args.warmup,
                               args.seed, args.object_ids, not args.no_shadows,
                               parse_config(args.config))[args.child]
    print(json.dumps({"frame_ms": float(np.median(times)) * 1e3,
                      "stages": stage_medians(stages)}))
    return 0


def report(args: argparse.Namespace, base: dict[str, str],
           measure: Callable[[int, int, str], dict[str, Any]], packages: dict[str, Any]
           ) -> int:
    """The table: per size and scenario, ``measure``'s medians and differences."""
    m = machine()
    new = git_commit() if args.new is None else resolve(args.new)["sha"][:7]
    how = (f"each side alone in a process, {args.isolate} rounds of {args.frames} frames"
           if args.isolate else f"both sides in one process, first side: {args.first}")
    say(f"{m['cpu']}, {m['nproc']} CPUs ({m['numba_threads']} numba threads); new side "
        f"{new} against base {base['sha'][:7]} ({base['subject'][:60]}...); object "
        f"ids {args.object_ids}; kernels loaded from numba's cache: {args.cached}; {how}; "
        f"shadowed lights: {'none' if args.no_shadows else 'yes'}; Config fields: "
        f"{', '.join(args.config) or 'none'} (K = 8)")
    say("| N | L | scenario | base ms | working tree ms | difference ms (quartiles) "
        "| mean difference ms | stages that moved most (base -> working tree, ms) |")
    say("|---|---|---|---|---|---|---|---|")
    for n, l in parse_sizes(args.sizes):
        for scenario in parse_scenarios(args.scenarios):
            r = measure(n, l, scenario)
            q = r["diff_q_ms"]
            say(f"| {fmt_count(n)} | {fmt_count(l)} | {scenario} | {r['base_ms']:.2f} "
                f"| {r['new_ms']:.2f} | {r['diff_ms']:+.2f} ({q[0]:+.2f}..{q[1]:+.2f}) "
                f"| {r['diff_mean_ms']:+.2f} | {stage_moves(r)} |")
    if packages:
        say("numba kernels (signatures) loaded from the cache / compiled here: " + ", ".join(
            f"{side} {loaded} / {compiled}" for side, (loaded, compiled) in
            ((side, cache_counts(pkg)) for side, pkg in packages.items())))
    return 0


if __name__ == "__main__":
    sys.exit(main())
