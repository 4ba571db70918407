"""Core benchmark: frame time of lightsched.Scheduler on seeded cities, per kind of frame.

    python bench/core.py                      # every scenario at (10k, 1k), (100k, 10k); full at (1M, 100k)
    python bench/core.py --sizes 10k:1k --frames 50 --scenarios full,static
    python bench/core.py --quick              # the ~1-2 minute cut (make bench-quick)
    python bench/core.py --write              # also writes the tables into bench/RESULTS.md

For each size (N objects, L lights): a ``lightsched.scenes.city`` with K = 8, default Config
(fade on), the sun and about 1% of the other lights casting shadows (``--no-shadows``: none).
Each scenario (``--scenarios``) says what changes between frames; the change is applied
before ``s.frame(...)`` and not timed, only ``s.frame(...)`` is:

- ``full``: every light moves every frame (``update_lights`` with every id); the objects and
  the camera stay, so their visibility and grid are kept (the cell edge, set by the lights,
  permitting);
- ``all``: as ``full``, and the camera moves as in ``camera``: visibility, the grid and the
  object records are built again, every stage runs;
- ``static``: nothing changes (no update call, the same camera objects, dt = 1/60);
- ``lights10``: a fixed seeded 10% of the point and spot lights move (``update_lights`` with
  those rows only, positions from ``move_lights`` on the subset); ``lights1`` the same with
  1%;
- ``camera``: only the camera moves, 0.5 m per frame on a horizontal orbit round the city
  centre, looking at it;
- ``objects1``: a fixed seeded 1% of the objects move (``update_objects`` with those rows
  only), each round a horizontal 2 m circle at 3 m/s; ``objects10`` the same with 10%.

Per size, the scenarios run interleaved run by run (a new Scheduler per run and scenario),
so their ratios come from the same minutes. A run steps warm-up frames first (not timed; they
include numba compilation): at least STEADY_WARMUP (90) for every scenario in motion, so
that the candidate lists' lights, all anchored at the first frame, have left their spheres
and walked again at their steady rate (earlier frames flatter the frame by ~10%), and 20
for ``static``, so that the fades started by the first frames (0.25 s = 15 frames) are
over. Scenarios other than ``full`` and ``all`` run only at N <= ``--incremental-up-to``
(default 100k). Reported per scenario:
median of the run medians, their spread, p10..p90 of frame time, the median of each stage of
``frame.stats["seconds"]``, the last frame's ``stats["plan"]``, and issue 6's target.

The shadow stage (``--shadow-budgets 4,16``): per size (N <= ``--incremental-up-to``), the
city with the sun and 5% of the other lights shadowed, run with shadow_budget S = 4 and 16,
and the same city with no shadowed light, interleaved run by run so the ratios come from the
same minutes (every light moving). Reported: the shadow stages (``shadows``: ranking and
tiers; ``casters``: culling volumes and caster lists), their share of the no-shadow frame,
and the frame-time difference.

Then a small city runs through both ``lightsched.reference.Scheduler`` (the float64 oracle)
and ``lightsched.Scheduler`` on the same frames: median times, their ratio, and the number
of (frame, object) rows whose light_ids differ (0 expected; DESIGN section 4 allows
near-ties only).

``--json PATH`` dumps the scenario results (``bench/history.py`` reads it). The script uses
only the public API (Scheduler, Config, set_/update_lights, set_/update_objects, frame) and
``lightsched.scenes``, so it also runs against older checkouts of the package.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import re
import shlex
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
from common import (
    fmt_count,
    git_commit,
    machine,
    markers,
    parse_count,
    parse_sizes,
    say,
    write_results,
)

import lightsched
from lightsched import Config
from lightsched.scene import DIRECTIONAL
from lightsched.scenes import DT, city, move_lights

BEGIN, END = markers("core.py")

# What changes between frames, per scenario (in the order of the default --scenarios).
SCENARIOS = {
    "full": "every light moves",
    "all": "every light and the camera move",
    "static": "nothing changes",
    "lights10": "10% of the point/spot lights move",
    "lights1": "1% of the point/spot lights move",
    "camera": "only the camera moves (0.5 m per frame)",
    "objects1": "1% of the objects move",
    "objects10": "10% of the objects move",
}
DEFAULT_SCENARIOS = ",".join(SCENARIOS)
DEFAULT_SIZES = "10k:1k,100k:10k,1M:100k"
QUICK_SIZES, QUICK_SCENARIOS = "10k:1k,100k:10k", "full,static,lights10"
INCREMENTAL_WARMUP = 20  # > fade_in / fade_out (0.25 s = 15 frames at 60 fps)
# Frames before a scene in motion is timed: the candidate lists are made at the first frame,
# every light anchored at once, and the lights (3 m/s, radii 5..30 m) leave their widened
# spheres over the next ~20-120 frames; before that they walk far fewer than they will
# for good. A 400-frame `full` (100k, 10k) sequence took 6.14 ms over frames 3-23 and 7.65
# over frames 100-400 (pairs 0.46 -> 1.00 ms; SKIN 0.1; bench/RESULTS.md, issue 6 targets).
STEADY_WARMUP = 90
LIGHT_FRACTIONS = {"lights10": 0.10, "lights1": 0.01}
OBJECT_FRACTIONS = {"objects1": 0.01, "objects10": 0.10}
CAMERA_STEP = 0.5  # metres per frame along the orbit
OBJECT_CIRCLE, OBJECT_SPEED = 2.0, 3.0  # metres, metres per second

# Scenarios whose every frame is full (they run at every size, warm up for --warmup only).
FULL = ("full", "all")

# Issue 6's targets, ms, on a 2-core machine: (scenario, N, L) -> ms. Its "full dynamic
# frame" is held against both full scenarios.
TARGETS = {
    **{(name, n, l): ms for name in FULL for n, l, ms in
       ((10_000, 1_000, 0.5), (100_000, 10_000, 4.0), (1_000_000, 100_000, 60.0))},
    ("static", 100_000, 10_000): 0.2,
    ("lights10", 100_000, 10_000): 1.5,
}


def make_scene(n: int, l: int, seed: int, shadows: bool, fraction: float = 0.01,
               object_ids: str = "random") -> Any:
    # object_ids is passed only when asked for: older checkouts' city() has no such argument.
    ids = {} if object_ids == "random" else {"object_ids": object_ids}
    return city(n, l, seed=seed, shadow_fraction=fraction if shadows else 0.0,
                sun_shadows=shadows, **ids)


def add_object_ids(p: argparse.ArgumentParser) -> None:
    p.add_argument("--object-ids", choices=("random", "spatial"), default="random",
                   help="the city's object ids: random (default) or ascending in Z order over "
                        "the ground, as a game that spawns its world section by section")


def stage_names(seconds: list[dict[str, float]]) -> list[str]:
    names: list[str] = []
    for d in seconds:
        names.extend(k for k in d if k not in names)
    return names


def parse_scenarios(text: str) -> list[str]:
    names = [t.strip() for t in text.split(",") if t.strip()]
    bad = [t for t in names if t not in SCENARIOS]
    if bad or not names:
        raise argparse.ArgumentTypeError(f"unknown scenario(s) {', '.join(bad) or text!r}; "
                                         f"known: {DEFAULT_SCENARIOS}")
    return list(dict.fromkeys(names))


class Motion:
    """What changes between frames in one scenario. ``step(s, i)`` applies frame ``i``'s
    changes to Scheduler ``s`` (nothing at frame 0: the scene as loaded) and returns the
    cameras of that frame. Every change is a function of the frame index, not an
    integration, and the subsets are chosen once per scene (seeded), so every run and every
    checkout sees the same frames."""

    def __init__(self, name: str, scene: Any, seed: int) -> None:
        self.name, self.scene = name, scene
        self.cameras = list(scene.cameras)
        self.warmup_min = INCREMENTAL_WARMUP if name == "static" else STEADY_WARMUP
        lights, objects = scene.lights, scene.objects
        if name in LIGHT_FRACTIONS:
            rng = np.random.default_rng([seed, 610])
            movable = np.flatnonzero(np.asarray(lights["type"]) != DIRECTIONAL)
            k = min(movable.size, max(1, round(LIGHT_FRACTIONS[name] * movable.size)))
            rows = np.sort(rng.choice(movable, size=k, replace=False))
            self.sub = {key: np.asarray(v)[rows] for key, v in lights.items()}
        elif name in OBJECT_FRACTIONS:
            rng = np.random.default_rng([seed, 601])
            n = int(np.asarray(objects["id"]).size)
            rows = np.sort(rng.choice(n, size=min(n, max(1, round(OBJECT_FRACTIONS[name] * n))),
                                      replace=False))
            self.oid = np.asarray(objects["id"])[rows]
            self.lo = np.asarray(objects["bounds_min"], dtype=np.float64)[rows]
            self.hi = np.asarray(objects["bounds_max"], dtype=np.float64)[rows]
            golden = math.pi * (3.0 - math.sqrt(5.0))
            self.phase = np.mod(self.oid.astype(np.int64) * golden, 2.0 * math.pi)
        if name in ("camera", "all"):
            self.orbit = []
            for cam in self.cameras:
                p = np.asarray(cam.position, dtype=np.float64)
                r = max(math.hypot(p[0], p[2]), 1.0)
                self.orbit.append((r, math.atan2(p[2], p[0]), float(p[1])))
        self.changed = 0  # rows sent by the last step

    def step(self, s: Any, i: int) -> list[Any]:
        self.changed = 0
        if i == 0 or self.name == "static":
            return self.cameras
        if self.name in FULL:
            lights = self.scene.lights
            s.update_lights(id=lights["id"], position=move_lights(lights, i))
            self.changed = int(np.asarray(lights["id"]).size)
            if self.name == "all":
                return self.orbit_cameras(i)
        elif self.name in LIGHT_FRACTIONS:
            s.update_lights(id=self.sub["id"], position=move_lights(self.sub, i))
            self.changed = int(self.sub["id"].size)
        elif self.name in OBJECT_FRACTIONS:
            angle = self.phase + (OBJECT_SPEED / OBJECT_CIRCLE) * i * DT
            d = np.zeros((self.oid.size, 3))
            d[:, 0] = OBJECT_CIRCLE * (np.cos(angle) - np.cos(self.phase))
            d[:, 2] = OBJECT_CIRCLE * (np.sin(angle) - np.sin(self.phase))
            s.update_objects(id=self.oid, bounds_min=self.lo + d, bounds_max=self.hi + d)
            self.changed = int(self.oid.size)
        elif self.name == "camera":
            return self.orbit_cameras(i)
        return self.cameras

    def orbit_cameras(self, i: int) -> list[Any]:
        cams = []
        for cam, (r, a0, y) in zip(self.cameras, self.orbit, strict=True):
            a = a0 + i * CAMERA_STEP / r
            pos = np.array([r * math.cos(a), y, r * math.sin(a)])
            # Looking at the city centre (the origin), as the scene's camera does.
            cams.append(dataclasses.replace(cam, position=pos, forward=-pos))
        return cams


def run_sequence(cls: type, scene: Any, config: Config, frames: int, skip: int,
                 keep_ids: bool = False, progress: bool = False,
                 motion: Motion | None = None) -> dict[str, Any]:
    """Steps ``skip + frames`` frames of ``motion`` (default: every light moving); times the
    last ``frames``."""
    if motion is None:
        motion = Motion("full", scene, 0)
    s = cls(config)
    s.set_lights(**scene.lights)
    s.set_objects(**scene.objects)
    times: list[float] = []
    seconds: list[dict[str, float]] = []
    ids: list[np.ndarray] = []
    warm: list[float] = []
    f = None
    for i in range(skip + frames):
        cameras = motion.step(s, i)
        t0 = time.perf_counter()
        f = s.frame(cameras, dt=DT)
        t = time.perf_counter() - t0
        if progress:
            say(f"     frame {i}: {t * 1e3:.1f} ms")
        if i < skip:
            warm.append(t)
            continue
        times.append(t)
        stats = getattr(f, "stats", None) or {}
        seconds.append(dict(stats.get("seconds", {}) or {}))
        if keep_ids:
            ids.append(np.asarray(f.light_ids).copy())
    assert f is not None
    stats = getattr(f, "stats", None) or {}
    vis = np.asarray(f.visible)
    count = np.asarray(getattr(f, "count", np.zeros(vis.size)))
    return {
        "times": np.asarray(times),
        "warm": warm,
        "seconds": seconds,
        "ids": ids,
        "plan": {str(k): str(v) for k, v in (stats.get("plan", {}) or {}).items()},
        "visible_objects": int(vis.sum()),
        "visible_lights": int(np.asarray(getattr(f, "visible_lights", ())).size),
        "mean_set": float(count[vis].mean()) if vis.any() else 0.0,
        "shadow_lights": int(np.asarray(getattr(f, "shadow_lights", ())).size),
        "casters": int(np.asarray(getattr(f, "caster_ids", ())).size),
    }


def summarize(runs: list[dict[str, Any]], n: int, l: int, scenario: str, warmup: int
              ) -> dict[str, Any]:
    """One scenario at one size over its runs: the median of the runs' medians (the machines
    are noisy), their spread, p10..p90 over every timed frame, and stage medians."""
    run_ms = [float(np.median(x["times"])) * 1e3 for x in runs]
    r = dict(runs[-1])
    r["times"] = np.concatenate([x["times"] for x in runs])
    r["seconds"] = [d for x in runs for d in x["seconds"]]
    ms = r["times"] * 1e3
    r.update(scenario=scenario, n=n, l=l, warmup=warmup, frames=int(runs[0]["times"].size),
             runs=len(runs), run_ms=run_ms, median=float(np.median(run_ms)),
             run_lo=min(run_ms), run_hi=max(run_ms), p10=float(np.percentile(ms, 10)),
             p90=float(np.percentile(ms, 90)), target=TARGETS.get((scenario, n, l)))
    r["stages"] = {k: float(np.median([d.get(k, 0.0) for d in r["seconds"]])) * 1e3
                   for k in stage_names(r["seconds"])}
    return r


def status(r: dict[str, Any]) -> str:
    if r.get("target") is None:
        return "-"
    return "met" if r["median"] <= r["target"] else "not met"


def shorten(text: str, width: int) -> str:
    return text if not width or len(text) <= width else text[:width - 3].rstrip() + "..."


def plan_text(plan: dict[str, str], width: int = 0, part: int = 0) -> str:
    """The plan's values joined; with ``part``, each without its parentheses and cut to
    ``part`` characters, then the whole cut to ``width``."""
    values = [str(v) for v in plan.values()]
    if part:
        values = [shorten(re.sub(r"\s*\([^()]*\)", "", v).strip(), part) for v in values]
    return shorten("; ".join(values), width) or "-"


def prime(args: argparse.Namespace) -> None:
    """Runs a small city through every scenario, untimed, so that numba compiles (or loads
    from its cache) every kernel any of them reaches before anything is timed: some are
    first called frames after the first (a fade ending, a partial update), which warm-up
    frames alone do not always cover on a cold cache."""
    n = min(min(n for n, _ in args.sizes), 10_000)
    l = min(min(l for _, l in args.sizes), 1_000)
    t0 = time.perf_counter()
    scene = make_scene(n, l, args.seed, not args.no_shadows, object_ids=args.object_ids)
    for name in dict.fromkeys(["full", *args.scenarios]):
        run_sequence(lightsched.Scheduler, scene, Config(max_lights=args.max_lights), 5,
                     INCREMENTAL_WARMUP, motion=Motion(name, scene, args.seed))
    say(f"primed (numba compilation and cache loads) on ({fmt_count(n)}, {fmt_count(l)}) in "
        f"{time.perf_counter() - t0:.1f} s")


def bench_size(n: int, l: int, scenarios: list[str], args: argparse.Namespace
               ) -> list[dict[str, Any]]:
    say(f"\n== N={fmt_count(n)} objects, L={fmt_count(l)} lights, K={args.max_lights}")
    t0 = time.perf_counter()
    scene = make_scene(n, l, args.seed, not args.no_shadows, object_ids=args.object_ids)
    say(f"   scene built in {time.perf_counter() - t0:.2f} s "
        f"({int(scene.lights['shadows'].sum())} shadowed lights)")
    motions = {name: Motion(name, scene, args.seed) for name in scenarios}
    warmups = {name: max(args.warmup, m.warmup_min) for name, m in motions.items()}
    say(f"   scenarios {', '.join(scenarios)}, interleaved: {args.runs} runs of "
        + ", ".join(sorted({f'{w}' for w in warmups.values()}, key=int))
        + f" warm-up frames, then {args.frames} timed frames ...")
    got: dict[str, list[dict[str, Any]]] = {name: [] for name in scenarios}
    for run in range(args.runs):
        for name in scenarios:
            got[name].append(run_sequence(lightsched.Scheduler, scene,
                                          Config(max_lights=args.max_lights), args.frames,
                                          warmups[name], motion=motions[name]))
        say(f"   run {run + 1}: " + ", ".join(
            f"{k} {np.median(v[-1]['times']) * 1e3:.2f} ms" for k, v in got.items()))
    out = []
    for name in scenarios:
        r = summarize(got[name], n, l, name, warmups[name])
        out.append(r)
        target = "" if r["target"] is None else \
            f"; target {r['target']:g} ms: {status(r)}"
        say(f"   {name} ({SCENARIOS[name]}, {motions[name].changed} rows sent per frame): "
            f"median {r['median']:.2f} ms (runs {r['run_lo']:.2f}..{r['run_hi']:.2f}), "
            f"p10..p90 {r['p10']:.2f}..{r['p90']:.2f} ms{target}")
        if name in FULL:
            warm = ", ".join(f"{w * 1e3:.0f}" for w in r["warm"])
            say(f"     warm-up frames (ms): {warm}")
            for k, v in r["stages"].items():
                say(f"     {k:<20} {v:9.3f} ms")
            say(f"     last frame: {r['visible_objects']} visible objects, {r['visible_lights']} "
                f"visible lights, mean set {r['mean_set']:.2f}, {r['shadow_lights']} shadowed "
                f"lights, {r['casters']} casters")
        else:
            top = sorted(r["stages"].items(), key=lambda kv: -kv[1])[:4]
            if top:
                say("     top stages: " + ", ".join(f"{k} {v:.3f} ms" for k, v in top))
        if r["plan"] and name not in FULL and out[0]["scenario"] == "full" \
                and r["plan"] == out[0]["plan"]:
            say("     plan: as full")
        elif r["plan"]:
            say("     plan: " + ", ".join(f"{k}={v}" for k, v in r["plan"].items()))
    return out


SHADOW_FRACTION = 0.05  # enough shadowed lights that S = 16 fills at (10k, 1k)


def bench_shadow_stage(n: int, l: int, budgets: list[int], args: argparse.Namespace
                       ) -> dict[str, Any]:
    say(f"\n== shadow stage: N={fmt_count(n)}, L={fmt_count(l)}, S in {budgets}")
    plain = make_scene(n, l, args.seed, False, object_ids=args.object_ids)
    shadowed = make_scene(n, l, args.seed, True, SHADOW_FRACTION, args.object_ids)
    cases = [("none", plain, Config(max_lights=args.max_lights))]
    cases += [(f"S={b}", shadowed, Config(max_lights=args.max_lights, shadow_budget=b))
              for b in budgets]
    got: dict[str, list[dict[str, Any]]] = {name: [] for name, _, _ in cases}
    for run in range(args.runs):
        for name, scene, cfg in cases:
            got[name].append(run_sequence(lightsched.Scheduler, scene, cfg, args.frames,
                                          args.warmup))
        say(f"   run {run + 1}: " + ", ".join(
            f"{k} {np.median(v[-1]['times']) * 1e3:.2f} ms" for k, v in got.items()))
    out: dict[str, Any] = {"n": n, "l": l, "rows": []}
    base = float(np.median([np.median(x["times"]) for x in got["none"]])) * 1e3
    for name, _, _ in cases[1:]:
        runs = got[name]
        frame = float(np.median([np.median(x["times"]) for x in runs])) * 1e3
        stage = {k: float(np.median([d.get(k, 0.0) for x in runs for d in x["seconds"]])) * 1e3
                 for k in ("shadows", "casters")}
        row = {"case": name, "shadow_lights": runs[-1]["shadow_lights"],
               "caster_count": runs[-1]["casters"], "frame": frame, "base": base,
               "shadows_ms": stage["shadows"], "casters_ms": stage["casters"],
               "stage": stage["shadows"] + stage["casters"]}
        row["share"] = row["stage"] / base
        row["added"] = (frame - base) / base
        out["rows"].append(row)
        say(f"   {name}: {row['shadow_lights']} shadow lights, {row['caster_count']} casters; "
            f"shadows {stage['shadows']:.2f} ms + casters {stage['casters']:.2f} ms = "
            f"{row['stage']:.2f} ms ({100 * row['share']:.1f}% of the {base:.2f} ms frame "
            f"without shadows); frame {frame:.2f} ms ({100 * row['added']:+.1f}%)")
    return out


def bench_compare(n: int, l: int, args: argparse.Namespace) -> dict[str, Any] | None:
    say(f"\n== oracle vs fast: N={fmt_count(n)}, L={fmt_count(l)}, {args.compare_frames} frames")
    try:
        from lightsched.reference import Scheduler as RefScheduler
    except ImportError as e:
        say(f"   skipped: lightsched.reference is not available ({e})")
        return None
    scene = make_scene(n, l, args.seed, not args.no_shadows, object_ids=args.object_ids)
    config = Config(max_lights=args.max_lights)
    frames = args.compare_frames
    say("   oracle ...")
    ref = run_sequence(RefScheduler, scene, config, frames, 0, keep_ids=True,
                       progress=True)
    say("   fast ...")
    fast = run_sequence(lightsched.Scheduler, scene, config, frames, 0, keep_ids=True)
    rows = sum(int(np.any(a != b, axis=1).sum()) if a.shape == b.shape else a.shape[0]
               for a, b in zip(ref["ids"], fast["ids"], strict=True))
    # Frame 0 pays numba compilation on a cold start; medians use frames after the first.
    ref_ms = float(np.median(ref["times"][1:] if frames > 1 else ref["times"])) * 1e3
    fast_ms = float(np.median(fast["times"][1:] if frames > 1 else fast["times"])) * 1e3
    ratio = ref_ms / fast_ms if fast_ms > 0 else float("inf")
    say(f"   oracle {ref_ms:.1f} ms/frame, fast {fast_ms:.3f} ms/frame, "
        f"oracle/fast = {ratio:.3g}")
    say(f"   light_ids mismatches: {rows} rows of {frames * n} (frames x objects)")
    return {"n": n, "l": l, "frames": frames, "ref_ms": ref_ms, "fast_ms": fast_ms,
            "ratio": ratio, "mismatches": rows, "rows": frames * n}


def size_label(n: int, l: int) -> str:
    return f"({fmt_count(n)}, {fmt_count(l)})"


def render(results: list[dict[str, Any]], shadow: list[dict[str, Any]],
           compare: dict[str, Any] | None, args: argparse.Namespace) -> str:
    m = machine()
    cmd = "python bench/core.py" + ("" if len(sys.argv) < 2 else " " + shlex.join(sys.argv[1:]))
    shadows = "none" if args.no_shadows else "the sun and ~1% of the other lights"
    upto = fmt_count(args.incremental_up_to)
    ids = "" if args.object_ids == "random" else f", object_ids={args.object_ids!r}"
    out = [BEGIN, "", f"Generated {time.strftime('%Y-%m-%d %H:%M %Z')} by `{cmd}` at commit "
           f"`{git_commit()}`.", "",
           f"Machine: {m['cpu']}, {m['nproc']} CPUs ({m['numba_threads']} numba threads), "
           f"{m['os']}; Python {m['python']}, numpy {m['numpy']}, numba {m['numba']}; load "
           f"average (1 min) {args.load[0]:.2f} at the start, {args.load[-1]:.2f} at the end.",
           "",
           f"Scenes: `lightsched.scenes.city(N, L, seed={args.seed}{ids})` (10% spots, one sun; "
           f"shadowed: {shadows}), one camera (fov_y 60 degrees, 16:9, 1080 px); "
           f"K = {args.max_lights}, default Config (fade on, exact precision, shadow_budget 4). "
           "Only `Scheduler.frame` is timed; the scene change before it is not. Per size the "
           f"scenarios run interleaved: {args.runs} runs (a new Scheduler each) of "
           f"{args.frames} frames after {max(args.warmup, STEADY_WARMUP)} warm-up frames "
           f"({max(args.warmup, INCREMENTAL_WARMUP)} for `static`): the candidate lists, all "
           "made at the first frame, have had their lights leave and walk again at the rate "
           "they will for good, and the first frames' fades are over; \"median\" is the "
           "median of the runs' medians, stage times are medians over all timed frames.", "",
           "Scenarios: `full` every light moves every frame (`update_lights` with every id; "
           "the objects and the camera stay, so their visibility and grid are kept); `all` "
           "every light moves and the camera moves as in `camera` (every stage runs); "
           "`static` nothing changes (no update, the same cameras, dt = 1/60); `lights10` a "
           "fixed seeded 10% of the point/spot lights move (`update_lights` with those rows "
           "only), `lights1` 1% of them; `camera` only the camera moves, 0.5 m per frame "
           "on an orbit round the city centre, looking at it; `objects1` a fixed seeded 1% "
           "of the objects move on "
           f"2 m circles (`update_objects` with those rows only), `objects10` 10% of them. "
           "Scenarios other than `full` and `all` "
           f"run at N <= {upto} only. Targets are issue 6's (2-core machine); \"plan\" is the "
           "last frame's `stats[\"plan\"]` values.", "",
           "| scenario | N | L | median ms | run medians ms | p10..p90 ms | target ms | status "
           "| plan (last frame) |",
           "|---|---|---|---|---|---|---|---|---|"]
    # Plan entries every row shares are said once below the table, not in every row.
    common = dict(results[0]["plan"]) if len(results) > 1 else {}
    for r in results[1:]:
        common = {k: v for k, v in common.items() if r["plan"].get(k) == v}
    for r in results:
        target = "-" if r["target"] is None else f"{r['target']:g}"
        own = {k: v for k, v in r["plan"].items() if k not in common}
        plan = plan_text(own, 200, 48).replace("|", "\\|")
        out.append(f"| {r['scenario']} | {fmt_count(r['n'])} | {fmt_count(r['l'])} | "
                   f"{r['median']:.2f} | {r['run_lo']:.2f}..{r['run_hi']:.2f} | "
                   f"{r['p10']:.2f}..{r['p90']:.2f} | {target} | {status(r)} | {plan} |")
    out.append("")
    if common:
        out += ["Plan entries of every row above: " + "; ".join(
            f"{k}: {shorten(v, 160)}" for k, v in common.items()).replace("|", "\\|"), ""]
    full = [r for r in results if r["scenario"] in FULL]
    if full:
        stages = stage_names([r["stages"] for r in full])
        head = ["N", "L", "median ms", "run medians ms", "p10..p90 ms",
                *[f"{s} ms" for s in stages], "visible obj", "mean set"]
        out += ["Stages of the full frames (`full`: every light moving; `all`: and the camera):",
                "", "| scenario | " + " | ".join(head) + " |", "|" + "---|" * (len(head) + 1)]
        for r in full:
            cells = [r["scenario"], fmt_count(r["n"]), fmt_count(r["l"]), f"{r['median']:.2f}",
                     f"{r['run_lo']:.2f}..{r['run_hi']:.2f}", f"{r['p10']:.2f}..{r['p90']:.2f}",
                     *[f"{r['stages'].get(s, 0.0):.2f}" for s in stages],
                     str(r["visible_objects"]), f"{r['mean_set']:.2f}"]
            out.append("| " + " | ".join(cells) + " |")

        def vs(r: dict[str, Any]) -> str:
            t = "" if r["target"] is None else f" (target {r['target']:g} ms, {status(r)})"
            return f"{r['median']:.2f} ms at {size_label(r['n'], r['l'])}{t}"

        def takes(name: str) -> str:
            return "; ".join(vs(r) for r in full if r["scenario"] == name)

        out += ["", "**Answer (core frame time):** a full dynamic frame (exact precision, "
                "K = 8, fade on) takes, with every light moving, " + takes("full")
                + (", and with the camera moving too (only the grid of the objects kept), " + takes("all")
                   if any(r["scenario"] == "all" for r in full) else "") + ".", ""]
    inc = incremental_answer(results)
    if inc:
        out += [inc, ""]
    if shadow:
        out += ["Shadow stage: the same city with the sun and "
                f"{100 * SHADOW_FRACTION:.0f}% of the other lights shadowed, at shadow_budget "
                "S, against that city with no shadowed light, interleaved run by run "
                "(every light moving; medians as above). `shadows` ranks lights and picks "
                "tiers; `casters` builds "
                "the culling volumes and caster lists. \"share\" is the shadow stages over "
                "the no-shadow frame; \"frame +\" the frame-time difference.", "",
                "| N | L | S | shadow lights | casters | shadows ms | casters ms | stage ms | "
                "frame without shadows ms | frame ms | share | frame + |",
                "|---|---|---|---|---|---|---|---|---|---|---|---|"]
        for sh in shadow:
            for r in sh["rows"]:
                out.append(f"| {fmt_count(sh['n'])} | {fmt_count(sh['l'])} | {r['case'][2:]} | "
                           f"{r['shadow_lights']} | {r['caster_count']} | {r['shadows_ms']:.2f} | "
                           f"{r['casters_ms']:.2f} | "
                           f"{r['stage']:.2f} | {r['base']:.2f} | {r['frame']:.2f} | "
                           f"{100 * r['share']:.1f}% | {100 * r['added']:+.1f}% |")
        out.append("")
    if compare is not None:
        out += ["Oracle (`lightsched.reference.Scheduler`) against the fast path on the same "
                f"{compare['frames']} frames (medians over frames after the first):", "",
                "| N | L | oracle ms | fast ms | oracle/fast | light_ids mismatches |",
                "|---|---|---|---|---|---|",
                f"| {fmt_count(compare['n'])} | {fmt_count(compare['l'])} | "
                f"{compare['ref_ms']:.1f} | {compare['fast_ms']:.3f} | {compare['ratio']:.3g} | "
                f"{compare['mismatches']} of {compare['rows']} rows |", ""]
    out.append(END)
    return "\n".join(out) + "\n"


def incremental_answer(results: list[dict[str, Any]]) -> str:
    """The "**Answer (incremental frames):**" line: the scenarios other than full at
    (100k, 10k), or else at the largest size that ran them."""
    inc = [r for r in results if r["scenario"] not in FULL]
    if not inc:
        return ""
    sizes = {(r["n"], r["l"]) for r in inc}
    n, l = (100_000, 10_000) if (100_000, 10_000) in sizes else max(sizes)
    words = {"static": "nothing moved", "lights10": "10% of the lights moved",
             "lights1": "1% of the lights moved",
             "camera": "only the camera moved", "objects1": "1% of the objects moved",
             "objects10": "10% of the objects moved"}
    parts = []
    for r in inc:
        if (r["n"], r["l"]) != (n, l):
            continue
        t = "no target" if r["target"] is None else f"target {r['target']:g} ms, {status(r)}"
        parts.append(f"{words[r['scenario']]} {r['median']:.2f} ms ({t})")
    full = [r for r in results if r["scenario"] == "full" and (r["n"], r["l"]) == (n, l)]
    scale = f"; a full frame takes {full[0]['median']:.2f} ms there" if full else ""
    return (f"**Answer (incremental frames):** at {size_label(n, l)}: " + "; ".join(parts)
            + scale + ".")


def dump_json(path: str, results: list[dict[str, Any]], load: list[float]) -> None:
    keys = ("scenario", "n", "l", "median", "run_ms", "run_lo", "run_hi", "p10", "p90",
            "target", "warmup", "frames", "runs", "stages", "plan", "visible_objects",
            "visible_lights", "mean_set", "shadow_lights", "casters")
    doc = {"lightsched": str(Path(lightsched.__file__).resolve().parent),
           "version": getattr(lightsched, "__version__", "?"), "bench_commit": git_commit(),
           "machine": machine(), "argv": sys.argv[1:], "load": load,
           "results": [{k: r.get(k) for k in keys} | {"status": status(r),
                                                       "times_ms": (r["times"] * 1e3).tolist()}
                       for r in results]}
    Path(path).write_text(json.dumps(doc, indent=1) + "\n")
    say(f"\nwrote {path}")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--sizes", type=parse_sizes, default=None,
                   help=f"comma-separated N:L pairs (default {DEFAULT_SIZES})")
    p.add_argument("--scenarios", type=parse_scenarios, default=None,
                   help=f"comma-separated scenarios (default {DEFAULT_SCENARIOS})")
    p.add_argument("--incremental-up-to", type=parse_count, default=parse_count("100k"),
                   help="run scenarios other than full, and the shadow stage, only at sizes "
                        "with N up to this (default 100k)")
    p.add_argument("--frames", type=int, default=20, help="timed frames per run (default 20)")
    p.add_argument("--warmup", type=int, default=3,
                   help=f"warm-up frames (default 3; scenarios in motion use at least "
                        f"{STEADY_WARMUP}, static {INCREMENTAL_WARMUP})")
    p.add_argument("--runs", type=int, default=3,
                   help="runs per size and scenario, each with a new Scheduler (default 3)")
    p.add_argument("--max-lights", type=int, default=8, help="K (default 8)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--no-shadows", action="store_true", help="no light casts shadows")
    add_object_ids(p)
    p.add_argument("--shadow-budgets", type=str, default="4,16",
                   help="shadow budgets S of the shadow-stage table, or 'none' (default 4,16)")
    p.add_argument("--compare", type=str, default="1000:100",
                   help="N:L of the oracle comparison, or 'none' (default 1000:100)")
    p.add_argument("--compare-frames", type=int, default=10,
                   help="frames of the oracle comparison (default 10)")
    p.add_argument("--no-prime", action="store_true",
                   help="skip the untimed priming run through every scenario on a small city")
    p.add_argument("--json", type=str, default=None, metavar="PATH",
                   help="also dump the scenario results as JSON")
    p.add_argument("--write", action="store_true", help="write the tables into bench/RESULTS.md")
    p.add_argument("--quick", action="store_true",
                   help=f"a cut for make bench-quick: {QUICK_SIZES}, scenarios {QUICK_SCENARIOS}, "
                        "1 run of 5 frames, S = 4, oracle comparison at 500:50")
    args = p.parse_args(argv)
    if args.quick:
        args.frames, args.runs, args.shadow_budgets, args.compare = 5, 1, "4", "500:50"
        args.compare_frames = 4
        args.sizes = args.sizes or parse_sizes(QUICK_SIZES)
        args.scenarios = args.scenarios or parse_scenarios(QUICK_SCENARIOS)
    args.sizes = args.sizes or parse_sizes(DEFAULT_SIZES)
    args.scenarios = args.scenarios or parse_scenarios(DEFAULT_SCENARIOS)
    if args.frames < 1 or args.warmup < 1 or args.compare_frames < 1 or args.runs < 1:
        p.error("--frames, --warmup, --runs and --compare-frames must be >= 1")

    m = machine()
    args.load = [os.getloadavg()[0]]
    say(f"lightsched {getattr(lightsched, '__version__', '?')} from "
        f"{Path(lightsched.__file__).resolve().parent} (bench at {git_commit()}); {m['cpu']}, "
        f"{m['nproc']} CPUs, numba {m['numba']} ({m['numba_threads']} threads)")
    upto = args.incremental_up_to
    cut = [f"{fmt_count(n)}:{fmt_count(l)}" for n, l in args.sizes if n > upto]
    if cut and any(s not in FULL for s in args.scenarios):
        say(f"note: scenarios other than full and all, and the shadow stage run only at N <= "
            f"{fmt_count(upto)} (--incremental-up-to); at {', '.join(cut)} only those run")
    if not args.no_prime:
        prime(args)
    results: list[dict[str, Any]] = []
    for n, l in args.sizes:
        scen = [s for s in args.scenarios if s in FULL or n <= upto]
        if scen:
            results += bench_size(n, l, scen, args)
    shadow = []
    if args.shadow_budgets.strip().lower() != "none":
        budgets = [int(b) for b in args.shadow_budgets.split(",")]
        shadow = [bench_shadow_stage(n, l, budgets, args) for n, l in args.sizes if n <= upto]
    compare = None
    if args.compare.strip().lower() != "none":
        (cn, cl), = parse_sizes(args.compare)
        compare = bench_compare(cn, cl, args)
    if results:
        say("\n== summary (median ms; target)")
        for r in results:
            t = "" if r["target"] is None else f"target {r['target']:g}: {status(r)}"
            say(f"   {r['scenario']:<9} {size_label(r['n'], r['l']):<12} {r['median']:9.3f}  {t:<20}"
                f"   [{plan_text(r['plan'], 110, 32)}]")
        inc = incremental_answer(results)
        if inc:
            say("   " + inc.replace("**", ""))
    args.load.append(os.getloadavg()[0])
    say(f"load average (1 min) {args.load[0]:.2f} at the start, {args.load[1]:.2f} at the end "
        f"({m['nproc']} CPUs; above about 1, other jobs were running and figures are "
        "pessimistic)")
    if args.json:
        dump_json(args.json, results, args.load)
    if args.write:
        write_results(render(results, shadow, compare, args), BEGIN, END)
    return 0


if __name__ == "__main__":
    sys.exit(main())
