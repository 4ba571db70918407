"""Scheduler and schedule(): run the stages of DESIGN section 2 on the fast path.

Takes the stores (scene.py) and cameras; returns a Frame (frame.py). Stages, each timed in
stats["seconds"]: cameras (frustum.py), visibility (frustum.py), pack (priority.py), grid
(pairs.py), objects (pairs.object_pass: Affects, priority, top-K, fade fused), output.
The per-object state (slots, weights, last frame's selection) lives in the object store's
``state`` so it follows ids through set_/remove_ calls; a frame computes the new state into
fresh arrays and swaps it in only when everything succeeded.
"""

from __future__ import annotations

import time
from typing import Any

import numba as nb
import numpy as np

from .frame import Frame, empty_frame
from .frustum import CameraFrames, cascade_splits, lights_visible, objects_visible
from .pairs import build_grid, cell_order, grid_shape, object_pass
from .priority import MODEL_CONTRIBUTION, MODEL_THESIS, pack_lights
from .scene import DIRECTIONAL, Camera, Config, SceneAPI

# Below this many (competing light, visible object) pairs a grid costs more than it saves.
BRUTE_FORCE_PAIRS = 1 << 15


@nb.njit(cache=True, nogil=True)
def _visible_bounds(lo, hi, visible):
    b = np.empty(6)
    b[:3] = np.inf
    b[3:] = -np.inf
    for o in range(lo.shape[0]):
        if visible[o]:
            for a in range(3):
                b[a] = min(b[a], lo[o, a])
                b[3 + a] = max(b[3 + a], hi[o, a])
    return b


_STATE = (("slot_light", np.int32, -1), ("slot_weight", np.float64, 0.0),
          ("slot_state", np.uint8, 0), ("selected", np.int32, -1))


class Scheduler(SceneAPI):
    """Stateful fast-path scheduler (DESIGN section 7)."""

    def __init__(self, config: Config | None = None) -> None:
        super().__init__(config)
        k = self.config.max_lights
        for name, dtype, fill in _STATE:
            self.objects.add_state(name, (k,), dtype, fill)
        self.objects.add_state("was_visible", (), np.bool_, False)

    def _frame(self, cameras: list[Camera], dt: float, cut: bool) -> Frame:
        cfg = self.config
        lights, objs = self.lights, self.objects
        k = cfg.max_lights
        seconds: dict[str, float] = {}
        plan: dict[str, str] = {}
        t = time.perf_counter()

        frames = CameraFrames(cameras)
        splits = cascade_splits(cameras, cfg.cascades, cfg.shadow_distance)
        t = _lap(seconds, "cameras", t)

        vis_l = lights_visible(lights.type, lights.position, lights.radius, frames.plane_n,
                               frames.plane_p)
        vis_o = objects_visible(objs.bounds_min, objs.bounds_max, frames.plane_n,
                                frames.plane_p)
        t = _lap(seconds, "visibility", t)

        hot, lf = pack_lights(lights, frames, cfg.w_ecc, cfg.w_dist, cfg.c1)
        is_dir = lights.type == DIRECTIONAL
        # Shadow stage not built yet: shadow_lights is empty, so "skip" drops every
        # light that may cast shadows (DESIGN section 2, Affects).
        removed = lights.shadows if cfg.unshadowed == "skip" else np.zeros(len(lights), bool)
        live = vis_l & ~removed
        compete = live & (~is_dir if not cfg.directional_in_slots else True)
        dir_rows = np.flatnonzero(live & is_dir) if not cfg.directional_in_slots else \
            np.zeros(0, np.int64)
        dir_p = lights.intensity[dir_rows] + lights.priority[dir_rows]
        directional = lights.id[dir_rows[np.lexsort((lights.id[dir_rows], -dir_p))]]
        t = _lap(seconds, "pack", t)

        grid_rows = np.flatnonzero(compete & ~is_dir).astype(np.int32)
        glob_rows = np.flatnonzero(compete & is_dir).astype(np.int32)
        n_vis = int(np.count_nonzero(vis_o))
        no_grid = (np.zeros(4), np.zeros(3, np.int64), np.zeros(1, np.int64),
                   np.zeros((0, 4), np.float32), np.zeros(0, np.int32))
        grid = no_grid
        order = np.arange(len(objs), dtype=np.int64)
        if grid_rows.size == 0 or n_vis == 0:
            plan["pairs"] = "none: no competing light or no visible object"
        elif grid_rows.size * n_vis <= BRUTE_FORCE_PAIRS:
            plan["pairs"] = f"brute force ({grid_rows.size} lights x {n_vis} objects)"
            glob_rows = np.concatenate([grid_rows, glob_rows])
        else:
            b = _visible_bounds(objs.bounds_min, objs.bounds_max, vis_o)
            cell = float(np.median(lights.radius[grid_rows]))
            origin, inv_h, dims = grid_shape(b[:3], b[3:], cell)
            start, cell_sphere, cell_code, big = build_grid(hot, grid_rows, origin, inv_h, dims)
            grid = (np.append(origin, inv_h), dims, start, cell_sphere, cell_code)
            glob_rows = np.concatenate([big, glob_rows])
            plan["pairs"] = (f"grid ({dims[0]}x{dims[1]}x{dims[2]} cells of "
                             f"{1 / inv_h:.3g} m, {cell_code.size} entries, "
                             f"{big.size} lights too big for it)")
            order = cell_order(objs.bounds_min, objs.bounds_max, vis_o, grid[0], dims)
        t = _lap(seconds, "grid", t)

        reset = objs.is_new | ~objs.get("was_visible")
        if self.frame_index == 0 or cut:
            reset = np.ones(len(objs), np.bool_)
        n = len(objs)
        state_in = tuple(objs.get(name) for name, _, _ in _STATE)
        state_out = tuple(np.empty((n, k), dtype) for _, dtype, _ in _STATE)
        out = (np.empty((n, k), np.int32), np.empty((n, k), np.int32),
               np.empty((n, k), np.float32), np.empty((n, k), np.float32),
               np.empty((n, k), np.uint8), np.empty(n, np.int32), np.empty(n, np.int32))
        model = MODEL_CONTRIBUTION if cfg.model == "contribution" else MODEL_THESIS
        params = np.array([model, cfg.w_obj, cfg.w_int, cfg.hysteresis, cfg.hysteresis_abs,
                           _rate(dt, cfg.fade_in), _rate(dt, cfg.fade_out), cfg.fade_in,
                           cfg.fade_out])
        object_pass((objs.bounds_min, objs.bounds_max, objs.mask, vis_o, reset, order),
                    (hot, lf, lights.id), grid,
                    glob_rows, state_in, state_out, out, params)
        t = _lap(seconds, "objects", t)

        for (name, _, _), arr in zip(_STATE, state_out, strict=True):
            objs.put(name, arr)
        objs.put("was_visible", vis_o)
        frame = empty_frame(objs.id, k, len(cameras), cfg.cascades)
        (frame.light_ids, frame.light_index, frame.priority, frame.fade_weight,
         frame.fade_state, frame.count, frame.candidates) = out
        frame.visible = vis_o.copy()
        frame.directional_lights = directional.astype(np.int32)
        frame.visible_lights = lights.id[vis_l]
        frame.cascade_splits = splits
        has_shadowed = bool(np.any(lights.shadows & vis_l))
        plan["visibility"] = f"frustum planes, {len(cameras)} camera(s)"
        plan["priority"] = cfg.model + " (exact float64)"
        if cfg.precision == "fast":
            plan["priority"] += "; precision 'fast' not built yet, ran exact"
        plan["fade"] = "fused into the object pass"
        plan["shadows"] = ("skipped: shadow stage not built yet" if has_shadowed
                           else "skipped: no visible shadowed light")
        t = _lap(seconds, "output", t)
        seconds["total"] = sum(seconds.values())
        frame.stats = {
            "plan": plan,
            "counts": {
                "objects": n,
                "visible_objects": n_vis,
                "lights": len(lights),
                "visible_lights": int(np.count_nonzero(vis_l)),
                "competing_lights": int(np.count_nonzero(compete)),
                "pairs": int(frame.candidates.sum()),
                "slots": int(frame.count.sum()),
                "threads": nb.get_num_threads(),
            },
            "seconds": seconds,
        }
        return frame


def _rate(dt: float, fade_time: float) -> float:
    return dt / fade_time if fade_time > 0.0 else 1.0


def _lap(seconds: dict[str, float], stage: str, t: float) -> float:
    now = time.perf_counter()
    seconds[stage] = now - t
    return now


def schedule(lights: dict[str, Any], objects: dict[str, Any], cameras: Any,
             config: Config | None = None) -> Frame:
    """Stateless one frame (DESIGN section 7): every object starts with its selected lights
    on, as on a scheduler's first frame."""
    s = Scheduler(config)
    s.set_lights(**lights)
    s.set_objects(**objects)
    return s.frame(cameras, dt=0.0, cut=True)
