"""Light-object pairs: a uniform grid (or brute force) and the fused object pass.

Takes the packed lights (priority.py layout), the rows of the lights that compete for slots,
and the object store; finds for every visible object the lights that affect it (DESIGN
section 2, "Affects"; the test itself lives in priority.pair) without materialising pairs:
the object pass walks the grid cells an object overlaps, computes P, keeps the top K with
hysteresis (select.py) and steps the fade machine (fade.py), all in one parallel loop over
objects. Each object writes only its own rows, so the output does not depend on the thread
count or on the order in which threads run.

The grid stores each point/spot light in every cell its bounding cube overlaps (widened by
a relative 1e-9 so rounding never drops a pair); an object visits the cells of its box and
takes a light only in the first cell both share, so no pair is seen twice. Lights that would
cover too many cells, and directional lights in slots, go to a short list every object
tests (the "global" lights).
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from .fade import fade_object
from .priority import pair
from .select import hysteresis_key, topk_insert

MAX_CELLS = 1 << 21          # bounds grid memory whatever the scene's extent
MAX_CELLS_PER_LIGHT = 512    # a light covering more is tested against every object
CHUNK = 256                  # objects per parallel work item (scratch is per chunk)


@nb.njit(cache=True, nogil=True, inline="always")
def _cell(x, origin, inv_h, dim):
    v = (x - origin) * inv_h
    if not v > 0.0:
        return 0
    if v >= dim - 1:
        return dim - 1
    return int(v)


@nb.njit(cache=True, nogil=True)
def build_grid(lf, rows, origin, inv_h, dims):
    """Cell lists (CSR) of the lights in ``rows``; returns (cell_start, cell_lights,
    light_cells [L, 6] (first and last cell per axis, by light row), big_rows)."""
    n_l = lf.shape[0]
    light_cells = np.zeros((n_l, 6), np.int32)
    ncell = dims[0] * dims[1] * dims[2]
    counts = np.zeros(ncell + 1, np.int64)
    is_big = np.zeros(rows.shape[0], np.bool_)
    n_big = 0
    for t in range(rows.shape[0]):
        j = rows[t]
        r = lf[j, 3]
        covered = 1
        for a in range(3):
            p = lf[j, a]
            slack = r * 1e-9 + abs(p) * 1e-15
            c0 = _cell(p - r - slack, origin[a], inv_h, dims[a])
            c1 = _cell(p + r + slack, origin[a], inv_h, dims[a])
            light_cells[j, a] = c0
            light_cells[j, 3 + a] = c1
            covered *= c1 - c0 + 1
        if covered > MAX_CELLS_PER_LIGHT:
            is_big[t] = True
            n_big += 1
            continue
        for x in range(light_cells[j, 0], light_cells[j, 3] + 1):
            for y in range(light_cells[j, 1], light_cells[j, 4] + 1):
                for z in range(light_cells[j, 2], light_cells[j, 5] + 1):
                    counts[(x * dims[1] + y) * dims[2] + z + 1] += 1
    for c in range(ncell):
        counts[c + 1] += counts[c]
    cell_lights = np.empty(counts[ncell], np.int32)
    fill = counts[:ncell].copy()
    big_rows = np.empty(n_big, np.int32)
    b = 0
    for t in range(rows.shape[0]):
        j = rows[t]
        if is_big[t]:
            big_rows[b] = j
            b += 1
            continue
        for x in range(light_cells[j, 0], light_cells[j, 3] + 1):
            for y in range(light_cells[j, 1], light_cells[j, 4] + 1):
                for z in range(light_cells[j, 2], light_cells[j, 5] + 1):
                    c = (x * dims[1] + y) * dims[2] + z
                    cell_lights[fill[c]] = j
                    fill[c] += 1
    return counts, cell_lights, light_cells, big_rows


def grid_shape(lo: np.ndarray, hi: np.ndarray, cell: float) -> tuple[np.ndarray, float, np.ndarray]:
    """(origin, 1/h, dims) for a box, cell edge ``cell`` grown until at most MAX_CELLS."""
    extent = np.maximum(hi - lo, 0.0)
    h = max(cell, float(extent.max()) / MAX_CELLS ** (1 / 3) * 1.0001, 1e-300)
    while True:
        dims = np.maximum(np.ceil(extent / h), 1).astype(np.int64)
        if int(np.prod(dims)) <= MAX_CELLS:
            break
        h *= 1.25
    return lo.astype(np.float64), 1.0 / h, dims


@nb.njit(cache=True, nogil=True, inline="always")
def _push(buf, n, j):
    if n == buf.shape[0]:
        grown = np.empty(2 * n, np.int32)
        grown[:n] = buf
        buf = grown
    buf[n] = j
    return buf, n + 1


@nb.njit(cache=True, nogil=True)
def _gather(lo, hi, grid, buf):
    """Rows of the grid lights whose cells meet the box, each once; returns (buf, n)."""
    g_f, dims, cell_start, cell_lights, light_cells = grid
    n = 0
    x0 = _cell(lo[0], g_f[0], g_f[3], dims[0])
    y0 = _cell(lo[1], g_f[1], g_f[3], dims[1])
    z0 = _cell(lo[2], g_f[2], g_f[3], dims[2])
    x1 = _cell(hi[0], g_f[0], g_f[3], dims[0])
    y1 = _cell(hi[1], g_f[1], g_f[3], dims[1])
    z1 = _cell(hi[2], g_f[2], g_f[3], dims[2])
    for x in range(x0, x1 + 1):
        for y in range(y0, y1 + 1):
            base = (x * dims[1] + y) * dims[2]
            for z in range(z0, z1 + 1):
                c = base + z
                for e in range(cell_start[c], cell_start[c + 1]):
                    j = cell_lights[e]
                    # Take the pair only in the first cell shared by light and object.
                    if (x == max(light_cells[j, 0], x0) and y == max(light_cells[j, 1], y0)
                            and z == max(light_cells[j, 2], z0)):
                        buf, n = _push(buf, n, j)
    return buf, n


@nb.njit(cache=True, nogil=True, parallel=True)
def object_pass(objs, lights, grid, glob, state_in, state_out, out, params):
    """For every object: affecting lights, P, top-K with hysteresis, fade, output rows.

    objs = (bounds_min, bounds_max, mask, visible, reset); lights = (light_f, light_i);
    grid = (origin + 1/h [4], dims, cell_start, cell_lights, light_cells) with dims all 0 for
    no grid; glob = rows every object tests; state_in/state_out = (slot ids, slot weights
    f64, slot states, selected ids) [N, K]; out = (light_ids, light_index, priority f32,
    fade_weight f32, fade_state, count, candidates); params = (model, w_obj, w_int, h, h_abs, dt/fade_in,
    dt/fade_out, fade_in, fade_out).
    """
    lo_all, hi_all, omask, visible, reset = objs
    lf, li = lights
    s_id, s_w, s_st, s_sel = state_in
    n_id, n_w, n_st, n_sel = state_out
    o_ids, o_index, o_prio, o_w, o_st, o_count, o_cand = out
    model = int(params[0])
    w_obj = params[1]
    w_int = params[2]
    h = params[3]
    h_abs = params[4]
    rates = (params[5], params[6], params[7], params[8])
    use_grid = grid[1][0] > 0
    n_obj = lo_all.shape[0]
    k = s_id.shape[1]
    n_chunks = (n_obj + CHUNK - 1) // CHUNK
    for ch in nb.prange(n_chunks):
        best_key = np.empty(k)
        best_id = np.empty(k, np.int64)
        best_p = np.empty(k)
        best_row = np.empty(k, np.int64)
        old_p = np.empty(k)
        old_row = np.empty(k, np.int64)
        new_id = np.empty(k, np.int64)
        new_w = np.empty(k)
        new_st = np.empty(k, np.uint8)
        new_p = np.empty(k)
        new_row = np.empty(k, np.int64)
        has_slot = np.empty(k, np.bool_)
        taken = np.empty(k, np.bool_)
        buf = np.empty(64, np.int32)
        for o in range(ch * CHUNK, min(n_obj, (ch + 1) * CHUNK)):
            cnt = 0
            nbest = 0
            cand = 0
            if visible[o]:
                lo = lo_all[o]
                hi = hi_all[o]
                c0 = (lo[0] + hi[0]) / 2
                c1 = (lo[1] + hi[1]) / 2
                c2 = (lo[2] + hi[2]) / 2
                e0 = hi[0] - lo[0]
                e1 = hi[1] - lo[1]
                e2_ = hi[2] - lo[2]
                e2 = e0 * e0 + e1 * e1 + e2_ * e2_
                big_r = math.sqrt(e2) / 2
                om = np.int64(omask[o])
                old_id = s_id[o]
                for m in range(k):
                    old_row[m] = -1
                n = 0
                if use_grid:
                    buf, n = _gather(lo, hi, grid, buf)
                for t in range(n + glob.shape[0]):
                    j = buf[t] if t < n else glob[t - n]
                    if li[j, 0] & om == 0:
                        continue
                    hit, p = pair(lf, j, lo, hi, c0, c1, c2, big_r, e2, model, w_obj, w_int)
                    if not hit:
                        continue
                    cand += 1
                    lid = li[j, 1]
                    for m in range(k):
                        if old_id[m] < 0:
                            break
                        if old_id[m] == lid:
                            old_p[m] = p
                            old_row[m] = j
                    key = hysteresis_key(p, lid, s_sel[o], h, h_abs)
                    nbest = topk_insert(best_key, best_id, best_p, best_row, nbest, key, lid,
                                        p, j)
                cnt = fade_object((best_id, best_p, best_row), nbest,
                                  (s_id[o], s_w[o], s_st[o]), old_p, old_row, reset[o],
                                  rates, (new_id, new_w, new_st, new_p, new_row),
                                  (has_slot, taken))
            for m in range(k):
                if m < cnt:
                    n_id[o, m] = new_id[m]
                    n_w[o, m] = new_w[m]
                    n_st[o, m] = new_st[m]
                    o_ids[o, m] = new_id[m]
                    o_index[o, m] = new_row[m]
                    o_prio[o, m] = np.float32(new_p[m])
                    o_w[o, m] = np.float32(new_w[m])
                    o_st[o, m] = new_st[m]
                else:
                    n_id[o, m] = -1
                    n_w[o, m] = 0.0
                    n_st[o, m] = 0
                    o_ids[o, m] = -1
                    o_index[o, m] = -1
                    o_prio[o, m] = 0.0
                    o_w[o, m] = 0.0
                    o_st[o, m] = 0
                n_sel[o, m] = best_id[m] if m < nbest else -1
            o_count[o] = cnt
            o_cand[o] = cand
