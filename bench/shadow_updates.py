"""Shadow views re-rendered per frame (issue 52): the point and spot views a renderer that
draws exactly shadow_update renders, against redrawing every shadowed view every frame; the
texels it re-renders; the longest a dirty view waited; and the shadow stages' share of the
frame (shadows, casters, views). Budgets 0, 8 and 32, caster_culling "camera" and
"light", the camera still and moving, on three scenes:

- city: a city with 5% of its point and spot lights shadowed, every light circling and
  1% of the objects moving each frame;
- stadium: 8 shadowed floodlights (spots) over a pitch, 1% of the objects (players)
  moving;
- static: the city with every object static but 0.2% movers and the lights still.

    python bench/shadow_updates.py                 # the table, markdown
    python bench/shadow_updates.py --frames 20 --objects 20000
    python bench/shadow_updates.py --cost          # the stages' share at (100k, 10k), S = 16
"""

from __future__ import annotations

import argparse
import math
import sys
import time

import numpy as np
from common import machine

import lightsched as ls
from lightsched.scenes import CityScene, city, move_lights, stadium

DIRECTIONAL = 2


def scenes(n_objects: int) -> dict[str, tuple[CityScene, float, bool]]:
    """name -> (scene, share of objects moving per frame, lights move)."""
    c = city(n_objects, n_objects // 10, seed=1, spot_fraction=0.3, shadow_fraction=0.05,
             sun_shadows=True)
    st = stadium(3000, seed=1)
    quiet = city(n_objects, n_objects // 10, seed=2, spot_fraction=0.3, shadow_fraction=0.05)
    quiet.objects["static"] = np.ones(quiet.n_objects, np.bool_)
    return {"city": (c, 0.01, True), "stadium": (st, 0.01, False),
            "static": (quiet, 0.002, False)}


def orbit(cam: ls.Camera, t: int, moving: bool) -> ls.Camera:
    """The scene's camera, turned about the vertical (0.01 rad a frame, round the scene's
    centre) when moving."""
    if not moving:
        return cam
    a = 0.01 * t
    c, s = math.cos(a), math.sin(a)
    p = np.asarray(cam.position, np.float64)
    f = np.asarray(cam.forward, np.float64)
    rot = np.array([[c, 0, -s], [0, 1, 0], [s, 0, c]])
    return ls.Camera(position=rot @ p, forward=rot @ f, up=cam.up, fov_y=cam.fov_y,
                     aspect=cam.aspect, near=cam.near, far=cam.far, id=cam.id)


class Movers:
    """A Scheduler on ``scene`` (``s``) and the boxes it was given, some of which move."""

    def __init__(self, scene: CityScene, config: ls.Config) -> None:
        self.s = ls.Scheduler(config)
        self.s.set_lights(**scene.lights)
        self.s.set_objects(**scene.objects)
        self.rng = np.random.default_rng(0)
        self.lo = np.array(scene.objects["bounds_min"], np.float64)
        self.hi = np.array(scene.objects["bounds_max"], np.float64)
        self.ids = scene.objects["id"]

    def move(self, n: int, step: float | None) -> None:
        """Moves n objects chosen at random by ``step`` on each axis, or by a normal step
        of 0.1 m (None)."""
        rows = self.rng.choice(self.ids.size, n, replace=False)
        d = self.rng.normal(0, 0.1, (n, 3)) if step is None else step
        self.lo[rows] += d
        self.hi[rows] += d
        self.s.update_objects(id=self.ids[rows], bounds_min=self.lo[rows],
                              bounds_max=self.hi[rows])


def run(scene: CityScene, movers: float, lights_move: bool, budget: int, culling: str,
        moving: bool, frames: int, warmup: int) -> dict[str, float]:
    mv = Movers(scene, ls.Config(shadow_budget=16, shadow_update_budget=budget,
                                 caster_culling=culling))
    s = mv.s
    n_move = max(1, int(movers * mv.ids.size))
    local_type = scene.lights["type"]
    type_of = dict(zip(scene.lights["id"].tolist(), local_type.tolist(), strict=True))
    drawn = every = texels = texels_every = 0
    waited: dict[tuple[int, int], int] = {}
    worst = 0
    share, views_ms = [], []
    for t in range(warmup + frames):
        if t:
            mv.move(n_move, None)
            if lights_move:
                s.update_lights(id=scene.lights["id"], position=move_lights(scene.lights, t))
        t0 = time.perf_counter()
        f = s.frame([orbit(c, t, moving) for c in scene.cameras])
        total = time.perf_counter() - t0
        if t < warmup:
            continue  # the first frames draw every view, as fast as the budget lets them
        sec = f.stats["seconds"]
        share.append(sum(sec.get(k, 0.0) for k in ("shadows", "casters", "views")) / total)
        views_ms.append(sec.get("views", 0.0) * 1e3)
        for j, lid in enumerate(f.shadow_lights.tolist()):
            if type_of[lid] == DIRECTIONAL:
                continue
            views, upd, dirty = (int(f.shadow_views[j]), int(f.shadow_update[j]),
                                 int(f.shadow_dirty[j]))
            tier2 = int(f.shadow_tier[j]) ** 2
            every += bin(views).count("1")
            texels_every += bin(views).count("1") * tier2
            drawn += bin(upd).count("1")
            texels += bin(upd).count("1") * tier2
            for bit in range(6):
                key = (lid, bit)
                if dirty >> bit & 1 and not upd >> bit & 1:
                    waited[key] = waited.get(key, 0) + 1
                    worst = max(worst, waited[key])
                else:
                    waited[key] = 0
    return {"drawn": drawn / frames, "every": every / frames,
            "texels": texels / frames / 1e6, "texels_every": texels_every / frames / 1e6,
            "worst_wait": worst, "share": float(np.median(share)),
            "views_ms": float(np.median(views_ms))}


def cost(frames: int, moving: bool) -> None:
    """The shadow stages' share of a frame at (100k, 10k), S = 16: the city with 5% of its
    point and spot lights and its sun shadowed, every light circling (full frames), or
    still with 0.1% of the objects moving (incremental frames)."""
    sc = city(100_000, 10_000, seed=1, spot_fraction=0.3, shadow_fraction=0.05,
              sun_shadows=True)
    for culling in ("camera", "light"):
        mv = Movers(sc, ls.Config(shadow_budget=16, caster_culling=culling))
        s = mv.s
        rows_ms: dict[str, list[float]] = {"shadows": [], "casters": [], "views": [],
                                           "total": []}
        for t in range(frames + 3):
            if moving:
                s.update_lights(id=sc.lights["id"], position=move_lights(sc.lights, t + 1))
            else:
                mv.move(100, 0.05)
            f = s.frame(sc.cameras)
            if t >= 3:
                for k in rows_ms:
                    rows_ms[k].append(f.stats["seconds"].get(k, 0.0) * 1e3)
        med = {k: float(np.median(v)) for k, v in rows_ms.items()}
        stages = med["shadows"] + med["casters"] + med["views"]
        print(f"| {'lights moving' if moving else '0.1% objects moving'} | {culling} | "
              f"{med['total']:.1f} | {med['shadows']:.2f} | {med['casters']:.2f} | "
              f"{med['views']:.2f} | {100 * stages / med['total']:.0f}% |", flush=True)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=30)
    ap.add_argument("--warmup", type=int, default=15,
                    help="frames before measuring (the first draws every view)")
    ap.add_argument("--objects", type=int, default=20_000)
    ap.add_argument("--scenes", default="city,stadium,static")
    ap.add_argument("--cost", action="store_true", help="the stages' share at (100k, 10k)")
    args = ap.parse_args()
    m = machine()
    if args.cost:
        print(f"{m['cpu']}: (100k, 10k), S = 16, medians of {args.frames} frames\n")
        print("| frames | culling | frame ms | shadows ms | casters ms | views ms | "
              "shadow stages' share |")
        print("|---|---|---|---|---|---|---|")
        for moving in (True, False):
            cost(args.frames, moving)
        return 0
    print(f"{m['cpu']}, {args.frames} frames after {args.warmup}, {args.objects} city "
          "objects, S = 16, default atlas 8192\n")
    print("| scene | culling | camera | B | point/spot views drawn / frame | every frame | "
          "ratio | Mtexels drawn / frame | every frame | longest wait (frames) | "
          "shadow stages' share | views stage ms |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    all_scenes = scenes(args.objects)
    for name in args.scenes.split(","):
        scene, movers, lights_move = all_scenes[name]
        for culling in ("camera", "light"):
            for moving in (False, True):
                for budget in (0, 8, 32):
                    r = run(scene, movers, lights_move, budget, culling, moving, args.frames,
                            args.warmup)
                    ratio = r["every"] / r["drawn"] if r["drawn"] else math.inf
                    print(f"| {name} | {culling} | {'moving' if moving else 'still'} | "
                          f"{budget} | {r['drawn']:.1f} | {r['every']:.1f} | {ratio:.1f}x | "
                          f"{r['texels']:.1f} | {r['texels_every']:.1f} | "
                          f"{r['worst_wait']} | {100 * r['share']:.0f}% | "
                          f"{r['views_ms']:.2f} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
