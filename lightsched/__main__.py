"""Command line: ``python -m lightsched demo | serve | warm-up`` (also the ``lightsched``
console script).

The only module of the package that prints. ``serve`` runs the HTTP service
(lightsched_server, imported only then: the core has no web imports). ``demo`` builds the demo city
(``lightsched.scenes.demo_scene``), steps it with moving lights and prints what each frame
returned, summarised, and where the time went (``frame.stats["seconds"]``). ``warm-up``
compiles every kernel into numba's cache (``lightsched.warmup``), as a build step of a
deployment would, so that no first frame pays for it.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Sequence
from typing import Any

import numpy as np

from .scene import Config
from .scenes import DT, city_sequence, demo_scene


def _scheduler_class(reference: bool) -> Any:
    if reference:
        from .reference import Scheduler as RefScheduler

        return RefScheduler
    from .scheduler import Scheduler

    return Scheduler


def _row(label: str, values: Sequence[float], fmt: str = "{:.1f}") -> str:
    v = np.asarray(values, dtype=np.float64)
    if v.size == 0:
        return f"  {label:<34} -"
    return (f"  {label:<34} mean {fmt.format(v.mean()):>9}   min {fmt.format(v.min()):>9}"
            f"   max {fmt.format(v.max()):>9}")


def run_demo(args: argparse.Namespace) -> int:
    scene = demo_scene(args.seed, n_objects=args.objects, n_lights=args.lights)
    cls = _scheduler_class(args.reference)
    config = Config(max_lights=args.max_lights)
    s = cls(config)
    s.set_lights(**scene.lights)
    s.set_objects(**scene.objects)
    lt = np.bincount(scene.lights["type"], minlength=3)
    impl = "lightsched.reference.Scheduler" if args.reference else "lightsched.Scheduler"
    print(f"LightSched demo: {scene.n_objects} objects, {scene.n_lights} lights "
          f"({lt[0]} point, {lt[1]} spot, {lt[2]} directional, "
          f"{int(scene.lights['shadows'].sum())} shadowed) on a {scene.side:.0f} m square, "
          f"seed {args.seed}")
    print(f"{impl}, K={config.max_lights}, {args.frames} frames at dt={DT:.4f} s, "
          f"lights circling at 3 m/s")

    visible_o: list[int] = []
    visible_l: list[int] = []
    set_size: list[float] = []
    changed: list[int] = []
    fading: list[int] = []
    shadowed: list[int] = []
    casters: list[int] = []
    wall: list[float] = []
    seconds: list[dict[str, float]] = []
    plan: dict[str, Any] = {}
    prev: np.ndarray | None = None
    for i, upd in city_sequence(scene, args.frames):
        if upd:
            s.update_lights(**upd)
        t0 = time.perf_counter()
        f = s.frame(scene.cameras, dt=DT)
        wall.append(time.perf_counter() - t0)
        vis = np.asarray(f.visible)
        visible_o.append(int(vis.sum()))
        visible_l.append(int(np.asarray(f.visible_lights).size))
        set_size.append(float(np.asarray(f.count)[vis].mean()) if vis.any() else 0.0)
        ids = np.asarray(f.light_ids)
        if prev is not None:
            changed.append(int(np.any(ids != prev, axis=1).sum()))
        prev = ids.copy()
        st = np.asarray(f.fade_state)
        fading.append(int(((st == 1) | (st == 3)).sum()))
        shadowed.append(int(np.asarray(f.shadow_lights).size))
        casters.append(int(np.asarray(f.caster_ids).size))
        stats = f.stats or {}
        seconds.append(dict(stats.get("seconds", {}) or {}))
        plan = stats.get("plan", plan) or plan
        if args.verbose:
            print(f"  frame {i:4d}: {visible_o[-1]} objects, {visible_l[-1]} lights visible, "
                  f"{changed[-1] if changed else 0} sets changed, {fading[-1]} slots fading, "
                  f"{wall[-1] * 1e3:.2f} ms")

    print("\nper frame (over all frames; 'changed' over frames after the first):")
    print(_row("visible objects", visible_o, "{:.0f}"))
    print(_row("visible lights", visible_l, "{:.0f}"))
    print(_row("mean set size (visible objects)", set_size, "{:.2f}"))
    print(_row("sets changed", changed, "{:.1f}"))
    print(_row("slots fading (in or out)", fading, "{:.1f}"))
    print(_row("shadowed lights", shadowed, "{:.1f}"))
    print(_row("shadow casters listed", casters, "{:.0f}"))

    later = seconds[1:] if len(seconds) > 1 else seconds
    stages: list[str] = []
    for d in later:
        stages.extend(k for k in d if k not in stages)
    print("\nmilliseconds per frame, median over frames after the first:")
    for name in stages:
        ms = np.median([d.get(name, 0.0) for d in later]) * 1e3
        print(f"  {name:<20} {ms:9.3f}")
    if not stages:
        print("  (no per-stage times in frame.stats['seconds'])")
    elif len(stages) > 1 and "total" not in stages:
        total = np.median([sum(d.values()) for d in later]) * 1e3
        print(f"  {'sum of stages':<20} {total:9.3f}")
    wall_later = wall[1:] if len(wall) > 1 else wall
    first = f"first frame {wall[0] * 1e3:.1f} ms"
    if not args.reference:
        first += ", includes numba compilation on a cold cache"
    print(f"  {'frame() wall time':<20} {np.median(wall_later) * 1e3:9.3f}   ({first})")
    if plan:
        print("plan of the last frame: " + ", ".join(f"{k}={v}" for k, v in plan.items()))
    return 0


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="lightsched",
                                description="Per-object light selection for real-time renderers.")
    sub = p.add_subparsers(dest="command", required=True)
    d = sub.add_parser("demo", help="step a demo city with moving lights and print a summary")
    d.add_argument("--frames", type=int, default=120, help="frames to step (default 120)")
    d.add_argument("--objects", type=int, default=3000, help="objects (default 3000)")
    d.add_argument("--lights", type=int, default=300, help="lights (default 300)")
    d.add_argument("--seed", type=int, default=0, help="scene seed (default 0)")
    d.add_argument("--max-lights", type=int, default=8, help="K, lights per object (default 8)")
    d.add_argument("--reference", action="store_true",
                   help="run the float64 oracle lightsched.reference.Scheduler (slow)")
    d.add_argument("-v", "--verbose", action="store_true", help="print a line per frame")
    d.set_defaults(func=run_demo)
    sv = sub.add_parser(
        "serve", help="run the HTTP/msgpack service (needs the server extra)",
        description="Serve the LightSched API (/v1, WebSocket streams, /docs, /metrics, "
                    "/healthz). Limits and API keys come from LIGHTSCHED_* environment "
                    "variables: LIGHTSCHED_API_KEYS (comma-separated) or LIGHTSCHED_API_KEYS_FILE "
                    "(one per line) turn on 'Authorization: Bearer <key>'; "
                    "LIGHTSCHED_MAX_BODY_BYTES, _MAX_LIGHTS, _MAX_OBJECTS, _MAX_SESSIONS, "
                    "_SESSION_TTL (seconds idle) and _MAX_PENDING_FRAMES set the limits; "
                    "LIGHTSCHED_CORS_ORIGINS (comma-separated) lets pages of those origins "
                    "call the service, and LIGHTSCHED_TICKET_TTL sets the stream tickets' "
                    "lifetime in seconds.")
    sv.add_argument("--host", default="127.0.0.1", help="interface to bind (default 127.0.0.1)")
    sv.add_argument("--port", type=int, default=8080, help="TCP port (default 8080)")
    sv.add_argument("--no-demo", action="store_true",
                    help="do not preload the demo session (id 'demo')")
    sv.add_argument("--log-level", default="info", help="uvicorn log level (default info)")
    sv.add_argument("--no-warm-up", action="store_true",
                    help="accept requests at once, without first loading (or, on a machine's "
                         "first start, compiling) every kernel; the first frames then pay it")
    sv.set_defaults(func=run_serve)
    w = sub.add_parser(
        "warm-up", help="compile every kernel into numba's cache (a deployment's build step)",
        description="Steps a small city through every frame path for each K and precision, "
                    "so that numba compiles every kernel signature into its cache (a few "
                    "minutes on a machine's first run; well under a second once cached). "
                    "`serve` does the same before it accepts requests.")
    w.add_argument("--max-lights", type=int, nargs="+", default=None,
                   help="the K values to prepare (default: every compiled variant)")
    w.add_argument("--precision", nargs="+", choices=("exact", "fast"),
                   default=["exact", "fast"], help="precisions to prepare (default both)")
    w.set_defaults(func=run_warm_up)
    return p


def run_warm_up(args: argparse.Namespace) -> int:
    from .warmup import warm_up

    print("LightSched: preparing kernels (compiling them takes a few minutes on a machine's "
          "first run)", flush=True)
    print(warm_up(args.max_lights, tuple(args.precision)).summary(), flush=True)
    return 0


def run_serve(args: argparse.Namespace) -> int:
    try:
        from lightsched_server import serve
    except ImportError as e:
        print(f"lightsched serve needs the server extra (pip install 'lightsched[server]'): {e}",
              file=sys.stderr)
        return 2
    serve(args.host, args.port, demo=not args.no_demo, log_level=args.log_level,
          warm_up=not args.no_warm_up)
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if getattr(args, "frames", 1) < 1:
        print("lightsched: --frames must be >= 1", file=sys.stderr)
        return 2
    return int(args.func(args))


if __name__ == "__main__":
    sys.exit(main())
