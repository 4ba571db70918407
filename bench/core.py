"""Core benchmark: frame time of lightsched.Scheduler on seeded cities with moving lights.

    python bench/core.py                      # (10k, 1k) and (100k, 10k), 20 timed frames
    python bench/core.py --sizes 10k:1k --frames 50
    python bench/core.py --write              # also writes the tables into bench/RESULTS.md

For each size (N objects, L lights): a ``lightsched.scenes.city`` with K = 8, default Config
(fade on), the sun and about 1% of the other lights casting shadows (``--no-shadows``: none).
Every frame moves every light (``update_lights`` with new positions, not timed); only
``s.frame(...)`` is timed. A few warm-up frames run first (they include numba compilation).
Reported: median and p10..p90 of frame time, and the median of each stage of
``frame.stats["seconds"]``.

The shadow stage (``--shadow-budgets 4,16``): per size, the city with the sun and 5% of
the other lights shadowed, run with shadow_budget S = 4 and 16, and the same city with no
shadowed light, interleaved run by run so the ratios come from the same minutes. Reported:
the shadow stages (``shadows``: ranking and tiers; ``casters``: culling volumes and caster
lists), their share of the no-shadow frame, and the frame-time difference.

Then a small city runs through both ``lightsched.reference.Scheduler`` (the float64 oracle)
and ``lightsched.Scheduler`` on the same frames: median times, their ratio, and the number
of (frame, object) rows whose light_ids differ (0 expected; DESIGN section 4 allows
near-ties only).
"""

from __future__ import annotations

import argparse
import shlex
import sys
import time
from typing import Any

import numpy as np
from common import (
    fmt_count,
    git_commit,
    machine,
    markers,
    parse_sizes,
    say,
    write_results,
)

import lightsched
from lightsched import Config
from lightsched.scenes import DT, city, move_lights

BEGIN, END = markers("core.py")


def make_scene(n: int, l: int, seed: int, shadows: bool, fraction: float = 0.01) -> Any:
    return city(n, l, seed=seed, shadow_fraction=fraction if shadows else 0.0,
                sun_shadows=shadows)


def stage_names(seconds: list[dict[str, float]]) -> list[str]:
    names: list[str] = []
    for d in seconds:
        names.extend(k for k in d if k not in names)
    return names


def run_sequence(cls: type, scene: Any, config: Config, frames: int, skip: int,
                 keep_ids: bool = False, progress: bool = False) -> dict[str, Any]:
    """Steps ``skip + frames`` frames, lights moving every frame; times the last ``frames``."""
    s = cls(config)
    s.set_lights(**scene.lights)
    s.set_objects(**scene.objects)
    times: list[float] = []
    seconds: list[dict[str, float]] = []
    ids: list[np.ndarray] = []
    warm: list[float] = []
    f = None
    for i in range(skip + frames):
        if i > 0:
            s.update_lights(id=scene.lights["id"], position=move_lights(scene.lights, i))
        t0 = time.perf_counter()
        f = s.frame(scene.cameras, dt=DT)
        t = time.perf_counter() - t0
        if progress:
            say(f"     frame {i}: {t * 1e3:.1f} ms")
        if i < skip:
            warm.append(t)
            continue
        times.append(t)
        seconds.append(dict((f.stats or {}).get("seconds", {}) or {}))
        if keep_ids:
            ids.append(np.asarray(f.light_ids).copy())
    assert f is not None
    vis = np.asarray(f.visible)
    return {
        "times": np.asarray(times),
        "warm": warm,
        "seconds": seconds,
        "ids": ids,
        "plan": dict((f.stats or {}).get("plan", {}) or {}),
        "visible_objects": int(vis.sum()),
        "visible_lights": int(np.asarray(f.visible_lights).size),
        "mean_set": float(np.asarray(f.count)[vis].mean()) if vis.any() else 0.0,
        "shadow_lights": int(np.asarray(f.shadow_lights).size),
        "casters": int(np.asarray(f.caster_ids).size),
    }


def bench_size(n: int, l: int, args: argparse.Namespace) -> dict[str, Any]:
    say(f"\n== N={fmt_count(n)} objects, L={fmt_count(l)} lights, K={args.max_lights}")
    t0 = time.perf_counter()
    scene = make_scene(n, l, args.seed, not args.no_shadows)
    say(f"   scene built in {time.perf_counter() - t0:.2f} s "
        f"({int(scene.lights['shadows'].sum())} shadowed lights)")
    say(f"   {args.runs} runs of {args.warmup} warm-up frames, then {args.frames} timed "
        "frames ...")
    runs = []
    for _ in range(args.runs):
        runs.append(run_sequence(lightsched.Scheduler, scene,
                                 Config(max_lights=args.max_lights), args.frames, args.warmup))
        say(f"     run median {np.median(runs[-1]['times']) * 1e3:.2f} ms")
    run_ms = [float(np.median(x["times"])) * 1e3 for x in runs]
    r = dict(runs[-1])
    r["times"] = np.concatenate([x["times"] for x in runs])
    r["seconds"] = [d for x in runs for d in x["seconds"]]
    ms = r["times"] * 1e3
    # The machines are noisy: the figure is the median of the runs' medians, with their
    # spread beside it, and p10..p90 over every timed frame.
    r.update(n=n, l=l, median=float(np.median(run_ms)), run_lo=min(run_ms),
             run_hi=max(run_ms), p10=float(np.percentile(ms, 10)),
             p90=float(np.percentile(ms, 90)))
    r["stages"] = {k: float(np.median([d.get(k, 0.0) for d in r["seconds"]])) * 1e3
                   for k in stage_names(r["seconds"])}
    warm = ", ".join(f"{w * 1e3:.0f}" for w in r["warm"])
    say(f"   warm-up frames (ms): {warm}")
    say(f"   frame: median of run medians {r['median']:.2f} ms (runs {r['run_lo']:.2f}.."
        f"{r['run_hi']:.2f}), p10..p90 {r['p10']:.2f}..{r['p90']:.2f} ms")
    for k, v in r["stages"].items():
        say(f"     {k:<20} {v:9.3f} ms")
    say(f"   last frame: {r['visible_objects']} visible objects, {r['visible_lights']} visible "
        f"lights, mean set {r['mean_set']:.2f}, {r['shadow_lights']} shadowed lights, "
        f"{r['casters']} casters")
    if r["plan"]:
        say("   plan: " + ", ".join(f"{k}={v}" for k, v in r["plan"].items()))
    return r


SHADOW_FRACTION = 0.05  # enough shadowed lights that S = 16 fills at (10k, 1k)


def bench_shadow_stage(n: int, l: int, budgets: list[int], args: argparse.Namespace
                       ) -> dict[str, Any]:
    say(f"\n== shadow stage: N={fmt_count(n)}, L={fmt_count(l)}, S in {budgets}")
    plain = make_scene(n, l, args.seed, False)
    shadowed = make_scene(n, l, args.seed, True, SHADOW_FRACTION)
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
    scene = make_scene(n, l, args.seed, not args.no_shadows)
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


def render(results: list[dict[str, Any]], shadow: list[dict[str, Any]],
           compare: dict[str, Any] | None, args: argparse.Namespace) -> str:
    m = machine()
    cmd = "python bench/core.py" + ("" if len(sys.argv) < 2 else " " + shlex.join(sys.argv[1:]))
    shadows = "none" if args.no_shadows else "the sun and ~1% of the other lights"
    out = [BEGIN, "", f"Generated {time.strftime('%Y-%m-%d %H:%M %Z')} by `{cmd}` at commit "
           f"`{git_commit()}`.", "",
           f"Machine: {m['cpu']}, {m['nproc']} CPUs ({m['numba_threads']} numba threads), "
           f"{m['os']}; Python {m['python']}, numpy {m['numpy']}, numba {m['numba']}.", "",
           f"Scenes: `lightsched.scenes.city(N, L, seed={args.seed})` (10% spots, one sun; "
           f"shadowed: {shadows}), one camera (fov_y 60 degrees, 16:9, 1080 px); "
           f"K = {args.max_lights}, default Config (fade on, exact precision). Every light "
           f"moves every frame; only `Scheduler.frame` is timed: {args.runs} runs (a new "
           f"Scheduler each) of {args.frames} frames after {args.warmup} warm-up frames; "
           "\"median\" is the median of the runs' medians, stage times are medians over all "
           "timed frames.", ""]
    stages = stage_names([r["stages"] for r in results])
    head = ["N", "L", "median ms", "run medians ms", "p10..p90 ms", *[f"{s} ms" for s in stages],
            "visible obj", "mean set"]
    out.append("| " + " | ".join(head) + " |")
    out.append("|" + "---|" * len(head))
    for r in results:
        cells = [fmt_count(r["n"]), fmt_count(r["l"]), f"{r['median']:.2f}",
                 f"{r['run_lo']:.2f}..{r['run_hi']:.2f}", f"{r['p10']:.2f}..{r['p90']:.2f}",
                 *[f"{r['stages'].get(s, 0.0):.2f}" for s in stages],
                 str(r["visible_objects"]), f"{r['mean_set']:.2f}"]
        out.append("| " + " | ".join(cells) + " |")
    out += ["", "**Answer (core frame time):** a full dynamic frame (every light moving, exact "
            "precision, K = 8, fade on) takes " + "; ".join(
                f"{r['median']:.2f} ms at ({fmt_count(r['n'])}, {fmt_count(r['l'])})"
                for r in results) + ".", ""]
    if shadow:
        out += ["Shadow stage: the same city with the sun and "
                f"{100 * SHADOW_FRACTION:.0f}% of the other lights shadowed, at shadow_budget "
                "S, against that city with no shadowed light, interleaved run by run "
                "(medians as above). `shadows` ranks lights and picks tiers; `casters` builds "
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


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--sizes", type=parse_sizes, default=parse_sizes("10k:1k,100k:10k"),
                   help="comma-separated N:L pairs (default 10k:1k,100k:10k)")
    p.add_argument("--frames", type=int, default=20, help="timed frames per size (default 20)")
    p.add_argument("--warmup", type=int, default=3, help="warm-up frames (default 3)")
    p.add_argument("--runs", type=int, default=3,
                   help="runs per size, each with a new Scheduler (default 3)")
    p.add_argument("--max-lights", type=int, default=8, help="K (default 8)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--no-shadows", action="store_true", help="no light casts shadows")
    p.add_argument("--shadow-budgets", type=str, default="4,16",
                   help="shadow budgets S of the shadow-stage table, or 'none' (default 4,16)")
    p.add_argument("--compare", type=str, default="1000:100",
                   help="N:L of the oracle comparison, or 'none' (default 1000:100)")
    p.add_argument("--compare-frames", type=int, default=10,
                   help="frames of the oracle comparison (default 10)")
    p.add_argument("--write", action="store_true", help="write the tables into bench/RESULTS.md")
    p.add_argument("--quick", action="store_true",
                   help="a cut for make bench-quick: 10k:1k and 100k:10k, 1 run of 5 frames, S = 4, "
                        "oracle comparison at 500:50")
    args = p.parse_args(argv)
    if args.quick:
        args.frames, args.runs, args.shadow_budgets, args.compare = 5, 1, "4", "500:50"
        args.compare_frames = 4
    if args.frames < 1 or args.warmup < 1 or args.compare_frames < 1 or args.runs < 1:
        p.error("--frames, --warmup, --runs and --compare-frames must be >= 1")

    m = machine()
    say(f"lightsched {lightsched.__version__} at {git_commit()}; {m['cpu']}, {m['nproc']} CPUs, "
        f"numba {m['numba']} ({m['numba_threads']} threads)")
    results = [bench_size(n, l, args) for n, l in args.sizes]
    shadow = []
    if args.shadow_budgets.strip().lower() != "none":
        budgets = [int(b) for b in args.shadow_budgets.split(",")]
        shadow = [bench_shadow_stage(n, l, budgets, args) for n, l in args.sizes]
    compare = None
    if args.compare.strip().lower() != "none":
        (cn, cl), = parse_sizes(args.compare)
        compare = bench_compare(cn, cl, args)
    if args.write:
        write_results(render(results, shadow, compare, args), BEGIN, END)
    return 0


if __name__ == "__main__":
    sys.exit(main())
