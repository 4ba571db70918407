"""Scaling: time per frame and per stage of lightsched.Scheduler over N objects and L lights.

    python bench/scaling.py            # N 1k..1M with L = N/10, L 100..100k at N = 100k
    python bench/scaling.py --quick    # up to 100k objects, fewer frames
    python bench/scaling.py --write    # also bench/RESULTS.md and bench/plots/scaling.png

Scenes are ``lightsched.scenes.city(N, L, seed=0)`` with the sun and 1 % of the other
lights shadowed (as bench/core.py), K = 8, default Config, every light moving every frame.
Three sweeps: the diagonal (L = N/10), N at fixed L = 10k, and L at fixed N = 100k. Each
point runs ``--runs`` schedulers of a few frames after warm-up; reported are the median of
the run medians, the spread of run medians, and the median of every stage.
"""

from __future__ import annotations

import argparse
import shlex
import sys
import time
from typing import Any

import numpy as np
from common import PLOTS, fmt_count, git_commit, machine, markers, say, write_results
from core import make_scene, run_sequence, stage_names
from tqdm import tqdm

from lightsched import Config, Scheduler
from lightsched.scenes import dungeon22, large_world, split_screen, stadium

BEGIN, END = markers("scaling.py")

FULL = {
    "diagonal (L = N/10)": [(1_000, 100), (10_000, 1_000), (100_000, 10_000), (1_000_000, 100_000)],
    "N at L = 10k": [(1_000, 10_000), (10_000, 10_000), (100_000, 10_000), (1_000_000, 10_000)],
    "L at N = 100k": [(100_000, 100), (100_000, 1_000), (100_000, 10_000), (100_000, 100_000)],
}
QUICK = {
    "diagonal (L = N/10)": [(1_000, 100), (10_000, 1_000), (100_000, 10_000)],
    "N at L = 10k": [(10_000, 10_000), (100_000, 10_000)],
    "L at N = 100k": [(100_000, 1_000), (100_000, 10_000)],
}


def frames_for(n: int, l: int, quick: bool) -> int:
    """Timed frames per run: fewer where a frame is long."""
    work = n + 10 * l
    base = 3 if quick else 8
    return max(2, base if work >= 1_000_000 else 2 * base if work >= 100_000 else 4 * base)


def measure(n: int, l: int, args: argparse.Namespace, cache: dict) -> dict[str, Any]:
    if (n, l) in cache:
        return cache[(n, l)]
    scene = make_scene(n, l, 0, True)
    frames = frames_for(n, l, args.quick)
    runs = [run_sequence(Scheduler, scene, Config(max_lights=8), frames, 2)
            for _ in range(args.runs)]
    run_ms = [float(np.median(r["times"])) * 1e3 for r in runs]
    seconds = [d for r in runs for d in r["seconds"]]
    out = {"n": n, "l": l, "frames": frames, "median": float(np.median(run_ms)),
           "lo": min(run_ms), "hi": max(run_ms),
           "stages": {k: float(np.median([d.get(k, 0.0) for d in seconds])) * 1e3
                      for k in stage_names(seconds)},
           "visible": runs[-1]["visible_objects"], "mean_set": runs[-1]["mean_set"]}
    cache[(n, l)] = out
    return out


def named_scenes(quick: bool) -> dict[str, Any]:
    """The harness's named scenes (lightsched.scenes), each with the Config it recommends."""
    n = 10_000 if quick else 100_000
    return {"dungeon-22 (K = 4)": dungeon22(seed=0),
            "stadium (1,000 floodlights)": stadium(seed=0),
            f"large-world ({fmt_count(n)}, 1e7 m out)": large_world(n, n // 10, seed=0),
            f"split-screen ({fmt_count(n)}, 4 cameras)": split_screen(n, n // 10, seed=0)}


def measure_named(args: argparse.Namespace) -> list[dict[str, Any]]:
    out = []
    for name, scene in tqdm(named_scenes(args.quick).items(), desc="scenes", file=sys.stderr):
        config = scene.config or Config()
        n = len(scene.objects["id"])
        frames = frames_for(n, len(scene.lights["id"]), args.quick)
        runs = [run_sequence(Scheduler, scene, config, frames, 2) for _ in range(args.runs)]
        run_ms = [float(np.median(r["times"])) * 1e3 for r in runs]
        out.append({"name": name, "n": n, "l": len(scene.lights["id"]), "k": config.max_lights,
                    "median": float(np.median(run_ms)), "lo": min(run_ms), "hi": max(run_ms),
                    "visible": runs[-1]["visible_objects"], "mean_set": runs[-1]["mean_set"]})
        say(f"{name:<34} {out[-1]['median']:8.2f} ms (runs {out[-1]['lo']:.2f}..{out[-1]['hi']:.2f})")
    return out


def render(results: dict[str, list[dict[str, Any]]], args: argparse.Namespace,
           named: list[dict[str, Any]]) -> str:
    m = machine()
    cmd = "python bench/scaling.py" + ("" if len(sys.argv) < 2 else " " + shlex.join(sys.argv[1:]))
    out = [BEGIN, "", "## Scaling (`bench/scaling.py`)", "",
           f"Generated {time.strftime('%Y-%m-%d %H:%M %Z')} by `{cmd}` at commit `{git_commit()}`; "
           f"{m['cpu']}, {m['nproc']} CPUs ({m['numba_threads']} numba threads).", "",
           "City scenes (`city(N, L, seed=0)`, sun + 1 % shadowed, K = 8, fade on, every light "
           f"moving); {args.runs} runs per point; median of run medians, with the spread of run "
           "medians; stage columns are medians over all timed frames. Plot: "
           "`bench/plots/scaling.png`.", ""]
    stages = stage_names([r["stages"] for rows in results.values() for r in rows])
    stages = [s for s in stages if s != "total"]
    head = ["sweep", "N", "L", "frame ms", "run medians", *stages, "visible", "mean set"]
    out += ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for sweep, rows in results.items():
        for r in rows:
            out.append("| " + " | ".join([
                sweep, fmt_count(r["n"]), fmt_count(r["l"]), f"{r['median']:.2f}",
                f"{r['lo']:.2f}..{r['hi']:.2f}", *[f"{r['stages'].get(s, 0.0):.2f}" for s in stages],
                str(r["visible"]), f"{r['mean_set']:.2f}"]) + " |")
    diag = results.get("diagonal (L = N/10)", [])
    if len(diag) >= 2:
        a, b = diag[0], diag[-1]
        slope = np.log(b["median"] / a["median"]) / np.log(b["n"] / a["n"])
        out += ["", f"**Answer (scaling):** along the diagonal (L = N/10) the frame time grows as "
                f"N^{slope:.2f} from {fmt_count(a['n'])} to {fmt_count(b['n'])} objects (1.0 is "
                f"linear): {a['median']:.2f} ms to {b['median']:.1f} ms."]
    out += ["", "The named scenes of `lightsched.scenes` (each with its recommended Config, lights "
            "moving every frame):", "", "| scene | N | L | K | frame ms | run medians | visible | "
            "mean set |", "|---|---|---|---|---|---|---|---|"]
    for r in named:
        out.append(f"| {r['name']} | {r['n']} | {r['l']} | {r['k']} | {r['median']:.2f} | "
                   f"{r['lo']:.2f}..{r['hi']:.2f} | {r['visible']} | {r['mean_set']:.2f} |")
    out += ["", END]
    return "\n".join(out) + "\n"


def plot(results: dict[str, list[dict[str, Any]]]) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    for sweep, rows in results.items():
        key = "l" if sweep.startswith("L ") else "n"
        ax = axes[1] if key == "l" else axes[0]
        ax.errorbar([r[key] for r in rows], [r["median"] for r in rows],
                    yerr=[[r["median"] - r["lo"] for r in rows], [r["hi"] - r["median"] for r in rows]],
                    marker="o", capsize=3, label=sweep)
    for ax, label in zip(axes, ("objects N", "lights L"), strict=True):
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel(label)
        ax.set_ylabel("frame ms (median)")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend()
    fig.suptitle("lightsched.Scheduler frame time, city scenes, 2 cores")
    fig.tight_layout()
    PLOTS.mkdir(exist_ok=True)
    fig.savefig(PLOTS / "scaling.png", dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--quick", action="store_true", help="up to 100k objects, fewer frames")
    p.add_argument("--runs", type=int, default=None, help="schedulers per point (3; quick 2)")
    p.add_argument("--write", action="store_true", help="write RESULTS.md and the plot")
    args = p.parse_args(argv)
    args.runs = args.runs or (2 if args.quick else 3)
    plan = QUICK if args.quick else FULL
    cache: dict = {}
    results: dict[str, list[dict[str, Any]]] = {k: [] for k in plan}
    points = [(sweep, n, l) for sweep, sizes in plan.items() for n, l in sizes]
    for sweep, n, l in tqdm(points, desc="scaling", file=sys.stderr):
        r = measure(n, l, args, cache)
        results[sweep].append(r)
        say(f"{sweep:<20} N={fmt_count(n):>5} L={fmt_count(l):>5}: {r['median']:8.2f} ms "
            f"(runs {r['lo']:.2f}..{r['hi']:.2f})")
    named = measure_named(args)
    if args.write:
        write_results(render(results, args, named), BEGIN, END)
        plot(results)
        say(f"wrote bench/RESULTS.md and {PLOTS / 'scaling.png'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
