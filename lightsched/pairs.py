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
from .select import (
    F_NEW_P,
    F_NEW_W,
    F_OLD_P,
    F_OLD_W,
    F_ROWS,
    I_ID,
    I_NEW_ID,
    I_NEW_ROW,
    I_NEW_ST,
    I_OLD_ID,
    I_OLD_ROW,
    I_OLD_ST,
    I_PREV_SEL,
    I_ROWS,
    topk_insert,
)

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
def build_grid(hot, rows, origin, inv_h, dims):
    """Cell lists (CSR) of the lights in ``rows``; returns (cell_start, cell_sphere,
    cell_code, big_rows).

    An entry is 20 bytes, so scanning a cell streams little memory: cell_sphere [M, 4]
    float32 holds the light's centre relative to the grid origin and its radius grown so
    that the float32 test "d2 <= r*r" can only err towards passing (the exact float64 test
    of priority.pair decides); cell_code [M] int32 is row * 8 + bits, bit a set when this
    cell is the light's first along axis a.
    """
    n_l = hot.shape[0]
    light_cells = np.zeros((n_l, 6), np.int32)
    ncell = dims[0] * dims[1] * dims[2]
    counts = np.zeros(ncell + 1, np.int64)
    is_big = np.zeros(rows.shape[0], np.bool_)
    n_big = 0
    reach = 0.0  # largest |coordinate - origin| a float32 test will see
    for a in range(3):
        reach = max(reach, dims[a] / inv_h)
    for t in range(rows.shape[0]):
        j = rows[t]
        r = hot[j, 3]
        covered = 1
        for a in range(3):
            p = hot[j, a]
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
        for a in range(3):
            reach = max(reach, abs(hot[j, a] - origin[a]) + r)
        for x in range(light_cells[j, 0], light_cells[j, 3] + 1):
            for y in range(light_cells[j, 1], light_cells[j, 4] + 1):
                for z in range(light_cells[j, 2], light_cells[j, 5] + 1):
                    counts[(x * dims[1] + y) * dims[2] + z + 1] += 1
    for c in range(ncell):
        counts[c + 1] += counts[c]
    # Each float32 coordinate is off by at most 2^-24 of its magnitude (<= reach), twice
    # per axis (light and box) plus the subtraction: grow r by 4 * 2^-23 * reach per axis.
    grow = 4.0 * 2.0**-23 * reach * math.sqrt(3.0)
    cell_sphere = np.empty((counts[ncell], 4), np.float32)
    cell_code = np.empty(counts[ncell], np.int32)
    fill = counts[:ncell].copy()
    big_rows = np.empty(n_big, np.int32)
    b = 0
    for t in range(rows.shape[0]):
        j = rows[t]
        if is_big[t]:
            big_rows[b] = j
            b += 1
            continue
        r32 = np.float32((hot[j, 3] + grow) * (1.0 + 1e-5))
        for x in range(light_cells[j, 0], light_cells[j, 3] + 1):
            for y in range(light_cells[j, 1], light_cells[j, 4] + 1):
                for z in range(light_cells[j, 2], light_cells[j, 5] + 1):
                    c = (x * dims[1] + y) * dims[2] + z
                    e = fill[c]
                    fill[c] += 1
                    for a in range(3):
                        cell_sphere[e, a] = np.float32(hot[j, a] - origin[a])
                    cell_sphere[e, 3] = r32
                    cell_code[e] = (j * 8 + (x == light_cells[j, 0]) * 1
                                    + (y == light_cells[j, 1]) * 2 + (z == light_cells[j, 2]) * 4)
    return counts, cell_sphere, cell_code, big_rows


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
def _consider(rec, e, lf, ids, box, geo, sf, si, nbest, cand, cfg):
    """One light record against the current object: Affects, P, hysteresis key, top-K
    insert, and this frame's P / row for the object's old slot of that light. geo = (c0,
    c1, c2, big_r, e2); cfg = (model, w_obj, w_int, h, h_abs). Returns (nbest, cand)."""
    hit, p = pair(rec, e, lf, box, geo, cfg[0], cfg[1], cfg[2])
    if not hit:
        return nbest, cand
    j = np.int64(rec[e, 5]) >> 5
    lid = np.int64(ids[j])  # a 4-byte array stays in cache; lf rows would not
    key = p
    for m in range(sf.shape[1]):
        if si[I_PREV_SEL, m] == lid:
            key = p + cfg[3] * abs(p) + cfg[4]
        if si[I_OLD_ID, m] == lid:
            sf[F_OLD_P, m] = p
            si[I_OLD_ROW, m] = j
    return topk_insert(sf, si, nbest, key, lid, p, j), cand + 1


@nb.njit(cache=True, nogil=True, inline="always")
def _scan_grid(om, hot, lf, ids, box, geo, sf, si, nbest, cand, cfg, grid):
    """Walks the grid cells the box overlaps; a pair is taken only in the first cell light
    and object share: along each axis that cell is the object's first or the light's first
    (the entry's bits). A conservative float32 sphere-box test filters before the exact
    pair. Returns (nbest, cand)."""
    g_f, dims, cell_start, cell_sphere, cell_code = grid
    x0 = _cell(box[0], g_f[0], g_f[3], dims[0])
    y0 = _cell(box[1], g_f[1], g_f[3], dims[1])
    z0 = _cell(box[2], g_f[2], g_f[3], dims[2])
    x1 = _cell(box[3], g_f[0], g_f[3], dims[0])
    y1 = _cell(box[4], g_f[1], g_f[3], dims[1])
    z1 = _cell(box[5], g_f[2], g_f[3], dims[2])
    lo0 = np.float32(box[0] - g_f[0])
    lo1 = np.float32(box[1] - g_f[1])
    lo2 = np.float32(box[2] - g_f[2])
    hi0 = np.float32(box[3] - g_f[0])
    hi1 = np.float32(box[4] - g_f[1])
    hi2 = np.float32(box[5] - g_f[2])
    zero = np.float32(0.0)
    for x in range(x0, x1 + 1):
        need = 0 if x == x0 else 1
        for y in range(y0, y1 + 1):
            need_y = need | (0 if y == y0 else 2)
            base = (x * dims[1] + y) * dims[2]
            for z in range(z0, z1 + 1):
                need_z = need_y | (0 if z == z0 else 4)
                for e in range(cell_start[base + z], cell_start[base + z + 1]):
                    code = cell_code[e]
                    if code & need_z != need_z:
                        continue
                    q0 = cell_sphere[e, 0]
                    q1 = cell_sphere[e, 1]
                    q2 = cell_sphere[e, 2]
                    r = cell_sphere[e, 3]
                    dx = max(lo0 - q0, zero, q0 - hi0)
                    dy = max(lo1 - q1, zero, q1 - hi1)
                    dz = max(lo2 - q2, zero, q2 - hi2)
                    if dx * dx + dy * dy + dz * dz > r * r:
                        continue
                    j = code >> 3
                    if np.int64(hot[j, 4]) & om == 0:
                        continue
                    nbest, cand = _consider(hot, j, lf, ids, box, geo, sf, si, nbest, cand,
                                            cfg)
    return nbest, cand


@nb.njit(cache=True, nogil=True)
def cell_order(lo, hi, visible, g_f, dims):
    """Objects in grid-cell order of their centres (a counting sort): neighbours then share
    lights in cache. Invisible objects go last. Returns int64[N]."""
    n = lo.shape[0]
    ncell = dims[0] * dims[1] * dims[2]
    key = np.empty(n, np.int64)
    counts = np.zeros(ncell + 2, np.int64)
    for o in range(n):
        if visible[o]:
            x = _cell((lo[o, 0] + hi[o, 0]) / 2, g_f[0], g_f[3], dims[0])
            y = _cell((lo[o, 1] + hi[o, 1]) / 2, g_f[1], g_f[3], dims[1])
            z = _cell((lo[o, 2] + hi[o, 2]) / 2, g_f[2], g_f[3], dims[2])
            key[o] = (x * dims[1] + y) * dims[2] + z
        else:
            key[o] = ncell
        counts[key[o] + 1] += 1
    for c in range(ncell + 1):
        counts[c + 1] += counts[c]
    order = np.empty(n, np.int64)
    for o in range(n):
        order[counts[key[o]]] = o
        counts[key[o]] += 1
    return order


@nb.njit(cache=True, nogil=True, parallel=True)
def object_pass(objs, lights, grid, glob, state_in, state_out, out, params):
    """For every object: affecting lights, P, top-K with hysteresis, fade, output rows.

    objs = (bounds_min, bounds_max, mask, visible, reset, order), objects walked in
    ``order``; lights = (light_hot, light_f, light ids) (priority.py); grid = (origin and 1/h [4],
    dims, cell_start, cell_sphere, cell_code), dims all 0 for no grid; glob = light rows every object
    tests; state_in / state_out = (slot ids, slot weights f64, slot states, selected ids),
    each [N, K]; out = (light_ids, light_index, priority f32, fade_weight f32, fade_state,
    count, candidates); params = (model, w_obj, w_int, h, h_abs, dt/fade_in, dt/fade_out,
    fade_in, fade_out).
    """
    lo_all, hi_all, omask, visible, reset, order = objs
    hot, lf, ids = lights
    s_id, s_w, s_st, s_sel = state_in
    n_id, n_w, n_st, n_sel = state_out
    o_ids, o_index, o_prio, o_w, o_st, o_count, o_cand = out
    cfg = (int(params[0]), params[1], params[2], params[3], params[4])
    inc = params[5]
    dec = params[6]
    fade_in = params[7]
    fade_out = params[8]
    use_grid = grid[1][0] > 0
    n_obj = lo_all.shape[0]
    k = s_id.shape[1]
    n_chunks = (n_obj + CHUNK - 1) // CHUNK
    for ch in nb.prange(n_chunks):
        sf = np.empty((F_ROWS, k))
        si = np.empty((I_ROWS, k), np.int64)
        box = np.empty(6)
        for t_o in range(ch * CHUNK, min(n_obj, (ch + 1) * CHUNK)):
            o = order[t_o]
            cnt = 0
            nbest = 0
            cand = 0
            if visible[o]:
                for a in range(3):
                    box[a] = lo_all[o, a]
                    box[3 + a] = hi_all[o, a]
                c0 = (box[0] + box[3]) / 2
                c1 = (box[1] + box[4]) / 2
                c2 = (box[2] + box[5]) / 2
                ex = box[3] - box[0]
                ey = box[4] - box[1]
                ez = box[5] - box[2]
                e2 = ex * ex + ey * ey + ez * ez
                big_r = math.sqrt(e2) / 2
                om = np.int64(omask[o])
                for m in range(k):
                    si[I_OLD_ID, m] = s_id[o, m]
                    sf[F_OLD_W, m] = s_w[o, m]
                    si[I_OLD_ST, m] = s_st[o, m]
                    si[I_PREV_SEL, m] = s_sel[o, m]
                    si[I_OLD_ROW, m] = -1
                geo = (c0, c1, c2, big_r, e2)
                if use_grid:
                    nbest, cand = _scan_grid(om, hot, lf, ids, box, geo, sf, si, nbest,
                                             cand, cfg, grid)
                for t in range(glob.shape[0]):
                    j = glob[t]
                    if np.int64(hot[j, 4]) & om != 0:
                        nbest, cand = _consider(hot, j, lf, ids, box, geo, sf, si, nbest,
                                                cand, cfg)
                cnt = fade_object(sf, si, nbest, reset[o], inc, dec, fade_in, fade_out)
            for m in range(k):
                if m < cnt:
                    n_id[o, m] = si[I_NEW_ID, m]
                    n_w[o, m] = sf[F_NEW_W, m]
                    n_st[o, m] = si[I_NEW_ST, m]
                    o_ids[o, m] = si[I_NEW_ID, m]
                    o_index[o, m] = si[I_NEW_ROW, m]
                    o_prio[o, m] = np.float32(sf[F_NEW_P, m])
                    o_w[o, m] = np.float32(sf[F_NEW_W, m])
                    o_st[o, m] = si[I_NEW_ST, m]
                else:
                    n_id[o, m] = -1
                    n_w[o, m] = 0.0
                    n_st[o, m] = 0
                    o_ids[o, m] = -1
                    o_index[o, m] = -1
                    o_prio[o, m] = 0.0
                    o_w[o, m] = 0.0
                    o_st[o, m] = 0
                n_sel[o, m] = si[I_ID, m] if m < nbest else -1
            o_count[o] = cnt
            o_cand[o] = cand
