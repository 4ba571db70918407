"""Scheduler and schedule(): run the stages of DESIGN section 2 on the fast path.

Takes the stores (scene.py) and cameras; returns a Frame (frame.py). Stages, each timed in
stats["seconds"]: cameras (frustum.py), visibility (frustum.py), pack (priority.py), grid
(its shape), order (visible objects by cell), prep (their records), pairs (Affects and P
per light), shadows (ranking and tiers, shadows.py), casters (culling volumes and caster
lists), group (pairs by object), objects (top-K and fade per object), output; pairs.py
describes the light-major pipeline.
The per-object state (slots, weights, last frame's selection) lives in the object store's
``state`` so it follows ids through set_/remove_ calls; the slot ids and states are the last
(read-only) frame's light_ids and fade_state. A frame computes the new state into other
arrays and swaps it in only when everything succeeded.
"""

from __future__ import annotations

import time
from typing import Any

import numba as nb
import numpy as np

from .frame import Frame, empty_frame, freeze
from .frustum import CameraFrames, cascade_splits, lights_visible, objects_visible
from .pairs import (
    GROUP_PARTS,
    RUN_SPLIT,
    grid_casters,
    grid_shape,
    group_pairs,
    light_bounds,
    light_order,
    light_pass,
    object_pass,
    visible_objects,
    visible_order,
)
from .priority import MODEL_CONTRIBUTION, MODEL_THESIS, pack_lights
from .scene import DIRECTIONAL, Camera, Config, SceneAPI
from .shadows import culling_volumes, rank_shadow_lights, sweep_casters

# Below this many (competing light, visible object) pairs a grid costs more than it saves.
BRUTE_FORCE_PAIRS = 1 << 15
# Grid cell edge over the median light radius (measured on the city bench, see RESULTS.md).
CELL_PER_RADIUS = 1.0


# Per-object state: slot ids and states are the frame's own (read-only) light_ids and
# fade_state outputs; the float64 weights and last frame's selection are kept apart.
_STATE = (("slot_light", np.int32, -1), ("slot_weight", np.float64, 0.0),
          ("slot_state", np.uint8, 0), ("selected", np.int32, -1))
_KEPT = (("slot_weight", np.float64), ("selected", np.int32))


class Scheduler(SceneAPI):
    """Stateful fast-path scheduler (DESIGN section 7)."""

    def __init__(self, config: Config | None = None) -> None:
        super().__init__(config)
        k = self.config.max_lights
        for name, dtype, fill in _STATE:
            self.objects.add_state(name, (k,), dtype, fill)
        self.objects.add_state("was_visible", (), np.bool_, False)
        self._buffers: dict[str, np.ndarray] = {}
        self._spare_state: tuple[np.ndarray, ...] | None = None
        # Last frame's shadow lights (ids) and their tiers, for the two hystereses.
        self._shadow_prev = (np.zeros(0, np.int32), np.zeros(0, np.int64))

    def _scratch(self, name: str, size: int, dtype: Any) -> np.ndarray:
        """A reusable buffer of at least ``size`` elements (grown by half when short), so a
        steady scene allocates no pair memory per frame."""
        buf = self._buffers.get(name)
        if buf is None or buf.size < size:
            buf = np.empty(max(size, int(1.5 * (0 if buf is None else buf.size))), dtype)
            self._buffers[name] = buf
        return buf

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
        vis_o, b = objects_visible(objs.bounds_min, objs.bounds_max, frames.plane_n,
                                   frames.plane_p)
        t = _lap(seconds, "visibility", t)

        hot, lf = pack_lights(lights, frames, cfg.w_ecc, cfg.w_dist, cfg.c1)
        is_dir = lights.type == DIRECTIONAL
        # Pairs are found for every visible light: the shadow ranking needs to know which
        # shadowed lights affect a visible object before "skip" removes the others.
        compete = vis_l & (~is_dir if not cfg.directional_in_slots else True)
        t = _lap(seconds, "pack", t)

        rows = np.flatnonzero(compete).astype(np.int32)
        point_rows = rows[~is_dir[rows]]
        n_vis = int(np.count_nonzero(vis_o))
        if n_vis == 0:
            b = np.zeros(6)
        if rows.size == 0 or n_vis == 0:
            plan["pairs"] = "none: no competing light or no visible object"
        if point_rows.size * n_vis <= BRUTE_FORCE_PAIRS:
            # One cell holding every visible object: each light tests them all.
            g_f, dims = grid_shape(b[:3], b[3:], 2.0 * max(float(np.max(b[3:] - b[:3])), 1.0))
            plan.setdefault("pairs", f"brute force ({rows.size} lights x {n_vis} objects)")
        else:
            radii = lights.radius[point_rows]
            median = float(np.partition(radii, radii.size // 2)[radii.size // 2])
            g_f, dims = grid_shape(b[:3], b[3:], CELL_PER_RADIUS * median)
        t = _lap(seconds, "grid", t)
        vis_rows, pos_of, cell_start = visible_order(objs.bounds_min, objs.bounds_max, vis_o,
                                             g_f, dims)
        t = _lap(seconds, "order", t)
        nv = vis_rows.size
        ncell = int(dims[0] * dims[1] * dims[2])
        n_small = int(cell_start[ncell])
        vis = (self._scratch("vis_box", nv * 8, np.float64)[:nv * 8].reshape(nv, 8), vis_rows)
        ext = visible_objects(objs.bounds_min, objs.bounds_max, objs.mask, pos_of, n_small,
                              vis[0])
        big_pos = np.arange(n_small, nv, dtype=np.int32)
        grid = (g_f, dims, cell_start, ext, big_pos)
        if "pairs" not in plan:
            plan["pairs"] = (f"grid of visible objects ({dims[0]}x{dims[1]}x{dims[2]} cells of "
                             f"{1 / g_f[3]:.3g} m, z {RUN_SPLIT}x finer, {big_pos.size} objects "
                             f"larger than a cell tested directly), walked by {rows.size} lights")
        t = _lap(seconds, "prep", t)

        model = MODEL_CONTRIBUTION if cfg.model == "contribution" else MODEL_THESIS
        rows = light_order(hot, rows, g_f, dims)
        offsets = light_bounds(hot, rows, grid, n_vis)
        pair_obj = self._scratch("pair_obj", int(offsets[-1]), np.int32)
        pair_p = self._scratch("pair_p", int(offsets[-1]), np.float64)
        count = light_pass((hot, lf), rows, grid, vis, offsets,
                           pair_obj, pair_p, np.array([model, cfg.w_obj, cfg.w_int]))
        t = _lap(seconds, "pairs", t)

        # Shadowed lights (DESIGN section 2): candidates affect a visible object.
        candidate = vis_l & lights.shadows
        shadow_rows, shadow_tier = np.zeros(0, np.int32), np.zeros(0, np.uint16)
        if candidate.any():
            affects = np.zeros(len(lights), bool)
            affects[rows] = count > 0
            sun = is_dir & candidate & ~compete
            if sun.any():
                seen = np.bitwise_or.reduce(objs.mask[vis_o]) if n_vis else np.uint32(0)
                affects[sun] = (lights.mask[sun] & seen) != 0
            candidate &= affects
            shadow_rows, shadow_tier = rank_shadow_lights(
                lights, frames, candidate, self._shadow_prev[0], self._shadow_prev[1],
                cfg.shadow_budget, cfg.hysteresis, cfg.hysteresis_abs, cfg.c1)
        shadow_of_row = np.full(len(lights), -1, np.int8)
        shadow_of_row[shadow_rows] = np.arange(shadow_rows.size)
        live = vis_l.copy()
        if cfg.unshadowed == "skip":
            # A shadowed light without a shadow map affects nothing (it would leak
            # through walls): its pairs are dropped before grouping.
            live &= ~(lights.shadows & (shadow_of_row < 0))
            count[~live[rows]] = 0
        dir_rows = np.flatnonzero(live & is_dir) if not cfg.directional_in_slots else \
            np.zeros(0, np.int64)
        dir_p = lights.intensity[dir_rows] + lights.priority[dir_rows]
        directional = lights.id[dir_rows[np.lexsort((lights.id[dir_rows], -dir_p))]]
        t = _lap(seconds, "shadows", t)
        casters, plan["casters"] = self._casters(frames, splits, shadow_rows, (hot, lf), grid,
                                                 vis, vis_o)
        t = _lap(seconds, "casters", t)
        n, n_pairs = len(objs), int(count.sum())
        lists = (self._scratch("start", n + 1, np.int64)[:n + 1],
                 self._scratch("obj_pairs", 2 * n_pairs, np.float64)[:2 * n_pairs]
                 .reshape(n_pairs, 2))
        hist = self._scratch("hist", GROUP_PARTS * (n + 1), np.int64)
        group_pairs(rows, offsets, count, pair_obj, pair_p,
                    (hist[:GROUP_PARTS * (n + 1)].reshape(GROUP_PARTS, n + 1),) + lists)
        t = _lap(seconds, "group", t)

        reset = objs.is_new | ~objs.get("was_visible")
        if self.frame_index == 0 or cut:
            reset = np.ones(n, np.bool_)
        state_in = tuple(objs.get(name) for name, _, _ in _STATE)
        state_out = self._spare_state
        if state_out is None or state_out[0].shape != (n, k):
            state_out = tuple(np.empty((n, k), dtype) for _, dtype in _KEPT)
        out = (np.empty((n, k), np.int32), np.empty((n, k), np.int32),
               np.empty((n, k), np.float32), np.empty((n, k), np.float32),
               np.empty((n, k), np.uint8), np.empty(n, np.int32), np.empty(n, np.int32),
               np.empty((n, k), np.int8))
        params = np.array([cfg.hysteresis, cfg.hysteresis_abs, _rate(dt, cfg.fade_in),
                           _rate(dt, cfg.fade_out), cfg.fade_in, cfg.fade_out])
        object_pass((vis_o, reset), lists, lights.id, state_in, state_out, out, params,
                    (shadow_of_row, cfg.max_shadowed_per_object))
        t = _lap(seconds, "objects", t)

        for (name, _), arr in zip(_KEPT, state_out, strict=True):
            objs.put(name, arr)
        objs.put("slot_light", out[0])
        objs.put("slot_state", out[4])
        objs.put("was_visible", vis_o)
        self._spare_state = (state_in[1], state_in[3])  # next frame writes over these
        frame = empty_frame(
            objs.id, k, cfg.cascades, visible=vis_o.copy(), count=out[5], candidates=out[6],
            light_ids=out[0], light_index=out[1], priority=out[2], fade_weight=out[3],
            fade_state=out[4], directional_lights=directional.astype(np.int32),
            visible_lights=lights.id[vis_l], cascade_splits=splits, slot_shadow=out[7],
            shadow_lights=lights.id[shadow_rows], shadow_tier=shadow_tier,
            caster_offsets=casters[0], caster_ids=casters[1], caster_masks=casters[2])
        freeze(frame)
        self._shadow_prev = (lights.id[shadow_rows], shadow_tier.astype(np.int64))
        plan["visibility"] = f"frustum planes, {len(cameras)} camera(s)"
        plan["priority"] = cfg.model + " (exact float64)"
        if cfg.precision == "fast":
            plan["priority"] += "; precision 'fast' not built yet, ran exact"
        plan["fade"] = "fused with selection in the object pass"
        plan["shadows"] = (f"{shadow_rows.size} of {int(candidate.sum())} candidates shadowed "
                           "(ranking, tiers, slot_shadow)"
                           if candidate.any() else "skipped: no visible shadowed light "
                           "affects a visible object")
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
                "pairs": n_pairs,
                "pair_bound": int(offsets[-1]),
                "slots": int(frame.count.sum()),
                "shadow_lights": int(shadow_rows.size),
                "casters": int(casters[1].size),
                "threads": nb.get_num_threads(),
            },
            "seconds": seconds,
        }
        return frame


    def _casters(self, frames: CameraFrames, splits: np.ndarray, shadow_rows: np.ndarray,
                 lights_packed: tuple[np.ndarray, np.ndarray], grid: tuple, vis: tuple,
                 vis_o: np.ndarray) -> tuple[tuple[np.ndarray, ...], str]:
        """(caster_offsets, caster_ids, caster_masks) of the shadow lights in rank order, and
        the plan: directional lights scan every object against their cascade sweeps; point
        and spot lights walk the light pass's grid of visible objects, then a grid of the
        same kind over the invisible casting objects that meet their spheres' bounding box
        (objects need not be visible to cast)."""
        lights, objs = self.lights, self.objects
        n_s = shadow_rows.size
        if n_s == 0:
            empty = (np.zeros(1, np.int64), np.zeros(0, np.int32), np.zeros(0, np.uint32))
            return empty, "skipped: no shadow lights"
        vn, vq, vm, shared = culling_volumes(lights, shadow_rows, frames, splits,
                                     self.config.cascade_overlap)
        lo, hi, casts = objs.bounds_min, objs.bounds_max, objs.casts_shadows
        found: list[tuple[np.ndarray, np.ndarray]] = [None] * n_s  # type: ignore[list-item]
        is_dir = lights.type[shadow_rows] == DIRECTIONAL
        plan = []
        sun = np.flatnonzero(is_dir)
        if sun.size:
            bits = sweep_casters(lo, hi, casts, objs.mask,
                                 lights.mask[shadow_rows[sun]].astype(np.int64),
                                 (vn[sun], vq[sun], vm[sun], shared[sun]))
            for i, t in enumerate(sun):
                rows = np.flatnonzero(bits[i])
                found[t] = (rows, bits[i][rows])
            plan.append(f"{sun.size} directional: every object against "
                        f"{vm.shape[1]} cascade sweeps")
        local = np.flatnonzero(~is_dir)
        if local.size:
            rows_l = shadow_rows[local].astype(np.int64)
            vols = (vn[local], vq[local], vm[local], shared[local])
            parts = [self._grid_casters(lights_packed, rows_l, grid, vis, vols)]
            # The invisible casting objects, as a subset with its own grid over the box of
            # the lights' spheres; a grid position maps back to its row through ``hidden``.
            hidden = np.flatnonzero(casts & ~vis_o)
            radius = lights.radius[rows_l]
            reach = lights.position[rows_l]
            r_lo = (reach - radius[:, None]).min(0)
            r_hi = (reach + radius[:, None]).max(0)
            near = (hi[hidden] >= r_lo).all(1) & (lo[hidden] <= r_hi).all(1)
            hidden = hidden[near]
            g_f, dims = grid_shape(r_lo, r_hi, CELL_PER_RADIUS * float(np.median(radius)))
            h_lo, h_hi = lo[hidden], hi[hidden]
            h_pos_rows, h_pos, h_start = visible_order(h_lo, h_hi, np.ones(hidden.size, bool),
                                                       g_f, dims)
            nh = h_pos_rows.size
            if nh:
                n_small = int(h_start[int(dims[0] * dims[1] * dims[2])])
                h_box = np.empty((nh, 8))
                ext = visible_objects(h_lo, h_hi, objs.mask[hidden], h_pos, n_small, h_box)
                h_grid = (g_f, dims, h_start, ext, np.arange(n_small, nh, dtype=np.int32))
                parts.append(self._grid_casters(lights_packed, rows_l, h_grid,
                                                (h_box, hidden[h_pos_rows]), vols))
            for i, t in enumerate(local):
                rows = np.concatenate([p[0][i] for p in parts])
                masks = np.concatenate([p[1][i] for p in parts])
                order = np.argsort(rows, kind="stable")
                found[t] = (rows[order], masks[order])
            plan.append(f"{local.size} point/spot: the grid of visible objects, then a grid of "
                        f"{nh} invisible casting objects near them")
        counts = np.array([f[0].size for f in found], np.int64)
        offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
        ids = objs.id[np.concatenate([f[0] for f in found])].astype(np.int32)
        masks = np.concatenate([f[1] for f in found]).astype(np.uint32)
        return (offsets, ids, masks), "; ".join(plan)

    def _grid_casters(self, lights_packed: tuple[np.ndarray, np.ndarray], rows: np.ndarray,
                      grid: tuple, recs: tuple, vols: tuple
                      ) -> tuple[list[np.ndarray], list[np.ndarray]]:
        """Per light of ``rows``, (object rows, masks) of its casters in one grid."""
        offsets = light_bounds(lights_packed[0], rows, grid, recs[0].shape[0])
        out = (np.empty(int(offsets[-1]), np.int64), np.empty(int(offsets[-1]), np.uint32))
        count = grid_casters(lights_packed, rows, grid, recs, self.objects.casts_shadows, vols,
                             offsets, out)
        ends = offsets[:-1] + count
        return ([out[0][a:b] for a, b in zip(offsets[:-1], ends, strict=True)],
                [out[1][a:b] for a, b in zip(offsets[:-1], ends, strict=True)])


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
