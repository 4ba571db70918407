"""Lights walking the grid of objects (grid.py): the light pass, the "affects any" test of
the shadow ranking's candidates and the caster search of point and spot lights.

A light walks the columns of cells that can hold the centre of an object it reaches (its
sphere widened by the largest object half-extent, cut column by column), each column one
contiguous run of objects; the exact range test (d2 <= r*r) filters, then the rest of
Affects and P (priority.record_pair_p); a point light under the contribution model takes
its run eight records a step in vector code (simd.py), the same arithmetic lane by lane.
``light_pass`` writes each light's pairs into its own segment of the pair buffers, sized
beforehand by ``light_bounds``, so the result does not depend on the thread count. The
light is fixed in the inner loop: its type and data stay in registers, and the objects it
meets are neighbours in memory.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, NamedTuple

import numba as nb
import numpy as np

from .frustum import SERIAL_LIGHTS
from .grid import _axis_cells, _cell
from .jit import PRANGE_ONLY
from .priority import (
    MODEL_CONTRIBUTION,
    PackedLights,
    PairParams,
    box_d2,
    record_geometry,
    record_pair_p,
    spot_cone,
)
from .scene import DIRECTIONAL, POINT, SPOT
from .simd import point_priority, point_run, prefetch_row, spot_priority

if TYPE_CHECKING:
    from .buffers import Buffers
    from .grid import Grid


class LightPairs(NamedTuple):
    """Pairs light by light: light ``rows[t]``'s (object row, P) at ``obj`` and ``p``
    [offsets[t] : offsets[t] + count[t]] (light_pass)."""

    rows: np.ndarray
    offsets: np.ndarray
    count: np.ndarray
    obj: np.ndarray
    p: np.ndarray


def walk_lights(lights: PackedLights, rows: np.ndarray, grid: Grid,
                params: PairParams, buffers: Buffers, name: str) -> LightPairs:
    """Affects and P of the lights ``rows`` (packed ``lights``) against the objects of
    ``grid`` (light_bounds, light_pass), into the scratch buffers ``name``_obj and _p."""
    offsets = light_bounds(lights[0], rows, grid.index, grid.records.box.shape[0])
    pair_obj = buffers.scratch(name + "_obj", int(offsets[-1]), np.int32)
    pair_p = buffers.scratch(name + "_p", int(offsets[-1]), np.float64)
    count = light_pass(lights, rows, grid.index, grid.records, offsets, pair_obj, pair_p,
                       params)
    return LightPairs(rows, offsets, count, pair_obj, pair_p)

LIGHT_CHUNK = 64             # lights per parallel work item of the light pass


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _light_cells(hot, j, g_f, dims, ext):
    """The clamped range of the cells that can hold the centre of an object light j
    reaches: its bounding cube widened by the largest object half-extent (and a relative
    1e-9 so rounding never drops a pair); empty (x1 < x0) if that misses the grid."""
    x0, x1, mx = _axis_cells(hot[j, 0], hot[j, 3] + ext[0], g_f[0], g_f[3], dims[0])
    y0, y1, my = _axis_cells(hot[j, 1], hot[j, 3] + ext[1], g_f[1], g_f[4], dims[1])
    z0, z1, mz = _axis_cells(hot[j, 2], hot[j, 3] + ext[2], g_f[2], g_f[5], dims[2])
    if mx or my or mz:
        return (1, 0, 0, 0, 0, 0)
    return (x0, y0, z0, x1, y1, z1)


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _slab_d2(p, cell, origin, h, dim, ext_a):
    """Squared distance along one axis from p to the centres' slab of a cell row, widened
    by the largest object half-extent; the clamped border cells reach to infinity and a
    relative 1e-9 margin absorbs rounding."""
    eps = h * 1e-9 + abs(origin) * 1e-15
    lo = -np.inf if cell == 0 else origin + cell * h - eps - ext_a
    hi = np.inf if cell == dim - 1 else origin + (cell + 1) * h + eps + ext_a
    d = max(lo - p, 0.0, p - hi)
    return d * d


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _reach2(hot, j):
    """Squared radius of light j's sphere widened by a relative 1e-9 (and 1e-15 of its
    coordinates), so the cell walk's rounding never drops an object the exact test keeps."""
    r = hot[j, 3]
    big_r = r + r * 1e-9 + (abs(hot[j, 0]) + abs(hot[j, 1]) + abs(hot[j, 2])) * 1e-15
    return big_r * big_r


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _column_run(hot, j, c, x, y, dxx, rr, g_f, dims, cell_start, ext):
    """Positions [v0, v1) of the objects centred in the column (x, y) of light j's cell
    range c that its widened sphere (squared radius rr; dxx its x slab distance) can reach:
    the cube is cut to the sphere column by column, empty when the sphere misses the
    column's slab, else trimmed to its chord along z."""
    dd = dxx + _slab_d2(hot[j, 1], y, g_f[1], 1.0 / g_f[4], dims[1], ext[1])
    if dd > rr:
        return 0, 0
    zr = math.sqrt(rr - dd) * (1.0 + 1e-9) + ext[2]
    z0 = max(c[2], _cell(hot[j, 2] - zr, g_f[2], g_f[5], dims[2]))
    z1 = min(c[5], _cell(hot[j, 2] + zr, g_f[2], g_f[5], dims[2]))
    if z1 < z0:
        return 0, 0
    base = (x * dims[1] + y) * dims[2]
    return cell_start[base + z0], cell_start[base + z1 + 1]


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def light_runs(hot, j, g_f, dims, cell_start, ext, runs):
    """The grid walk (DESIGN section 8, the object grid): the runs of grid positions
    [runs[i, 0], runs[i, 1]) holding the objects centred in the cells that point or spot
    light j's sphere can reach, column by column (_column_run), empty columns left out.
    The one walk of the light pass, affects_any and casters.grid_casters; the objects
    larger than a cell (big_pos) are not in any run.

    hot: packed light rows (priority.pack); j: the light's row; g_f, dims, cell_start,
    ext: the grid's GridIndex fields; runs: int64 [R, 2] scratch. Returns (number of runs,
    runs, regrown when short)."""
    c = _light_cells(hot, j, g_f, dims, ext)
    columns = max(c[3] - c[0] + 1, 0) * max(c[4] - c[1] + 1, 0)
    if columns > runs.shape[0]:
        runs = np.empty((columns, 2), np.int64)
    rr = _reach2(hot, j)
    m = 0
    for x in range(c[0], c[3] + 1):
        dxx = _slab_d2(hot[j, 0], x, g_f[0], 1.0 / g_f[3], dims[0], ext[0])
        if dxx > rr:
            continue
        for y in range(c[1], c[4] + 1):
            v0, v1 = _column_run(hot, j, c, x, y, dxx, rr, g_f, dims, cell_start, ext)
            if v1 > v0:
                runs[m, 0] = v0
                runs[m, 1] = v1
                m += 1
    return m, runs


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _light_bound(hot, j, g_f, dims, cell_start, ext, n_big, n_vis):
    if (np.int64(hot[j, 5]) >> 3) & 3 == DIRECTIONAL:
        return n_vis
    c = _light_cells(hot, j, g_f, dims, ext)
    total = n_big
    # The whole cube, not the sphere cut: a looser bound is cheaper to count.
    for x in range(c[0], c[3] + 1):
        for y in range(c[1], c[4] + 1):
            base = (x * dims[1] + y) * dims[2]
            total += cell_start[base + c[5] + 1] - cell_start[base + c[2]]
    return total


@nb.njit(cache=True, nogil=True, parallel=PRANGE_ONLY, error_model="numpy")
def light_bounds(hot, rows, grid, n_vis):
    """Offsets [len(rows) + 1] of each light's segment in the pair buffers: the prefix sum
    of an upper bound of the pairs it can emit (objects centred in the cells of its
    widened cube plus the big objects; every visible object for a directional light).
    hot: PackedLights.hot; grid: GridIndex; n_vis: the grid's object count. Parallel from
    SERIAL_LIGHTS lights. rows: int32 light rows, in grid order. DESIGN section 2,
    "Affects" (the pairs it bounds); section 5 (a segment per light: the pairs do not
    depend on the thread count)."""
    g_f, dims, cell_start, ext, big_pos = grid
    n_big = big_pos.shape[0]
    out = np.zeros(rows.shape[0], np.int64)
    if rows.shape[0] < SERIAL_LIGHTS:
        for t in range(rows.shape[0]):
            out[t] = _light_bound(hot, rows[t], g_f, dims, cell_start, ext, n_big, n_vis)
    else:
        # (The grid unpacked out of the loop, as in light_pass.)
        for t in nb.prange(rows.shape[0]):
            out[t] = _light_bound(hot, rows[t], g_f, dims, cell_start, ext, n_big, n_vis)
    offsets = np.zeros(rows.shape[0] + 1, np.int64)
    for t in range(rows.shape[0]):
        offsets[t + 1] = offsets[t] + out[t]
    return offsets


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _exact_pair(hot, lf, j, lm, typ, v, d2, vis_box, vis_bits, vis_rows, pair_obj, pair_p, n,
                model, w_obj, w_int):
    """The rest of the exact float64 Affects test of light j (mask lm) and visible object
    v once d2 <= r*r holds (the mask, then record_pair_p); on a hit appends (object row, P) at n.
    Returns the new n. The record arrays come one by one, not as the ``vis`` tuple: a tuple
    of arrays unpacked once per pair kept their reference counting in the loop (measured
    +27% on the light pass)."""
    if np.int64(vis_bits[v, 6]) & lm == 0:
        return n
    hit, p = record_pair_p(hot, lf, j, typ, v, d2, vis_box, model, w_obj, w_int)
    if hit:
        pair_obj[n] = vis_rows[v]
        pair_p[n] = p
        n += 1
    return n


@nb.njit(cache=True, nogil=True, parallel=PRANGE_ONLY, error_model="numpy")
def light_pass(lights, rows, grid, vis, offsets, pair_obj, pair_p, params):
    """For each light in ``rows`` (parallel), its pairs with the grid's objects (DESIGN
    section 2, "Affects" and "Priority"; section 8, the object grid): pair_obj / pair_p
    [offsets[t] : offsets[t] + count[t]] = (object row, P).

    lights: PackedLights; rows: light rows, in grid order (grid.light_order); grid:
    GridIndex; vis: the grid's Records; offsets: light_bounds; pair_obj int32, pair_p
    float64: the pair buffers; params: PairParams. Returns count per light."""
    model = params.model
    w_obj = params.w_obj
    w_int = params.w_int
    # Unpacked once: a tuple of arrays unpacked in the loop (once a light, in a helper)
    # keeps its reference counting there, atomic operations on counts both threads share.
    hot, lf = lights
    g_f, dims, cell_start, ext, big_pos = grid
    vis_box, vis_bits, vis_rows = vis
    n_vis = vis_box.shape[0]
    count = np.zeros(rows.shape[0], np.int64)
    n_chunks = (rows.shape[0] + LIGHT_CHUNK - 1) // LIGHT_CHUNK
    for ch in nb.prange(n_chunks):
        keep = (np.empty(256, np.int32), np.empty(256))
        runs = np.empty((64, 2), np.int64)
        for t in range(ch * LIGHT_CHUNK, min(rows.shape[0], (ch + 1) * LIGHT_CHUNK)):
            if t + 1 < rows.shape[0]:
                prefetch_row(hot, rows[t + 1])
            # Light rows[t]'s pairs into its segment of pair_obj / pair_p; ``keep`` is the
            # filter scratch of _run_pairs (regrown there when short).
            j = rows[t]
            lm = np.int64(hot[j, 4])
            typ = (np.int64(hot[j, 5]) >> 3) & 3
            n = offsets[t]
            # The end of the light's segment: simd's whole stores may fill it up to there.
            end = offsets[t + 1]
            if typ == DIRECTIONAL:
                p = hot[j, 6] + hot[j, 7]
                for v in range(n_vis):
                    if np.int64(vis_bits[v, 6]) & lm != 0:
                        pair_obj[n] = vis_rows[v]
                        pair_p[n] = p
                        n += 1
                count[t] = n - offsets[t]
                continue
            m, runs = light_runs(hot, j, g_f, dims, cell_start, ext, runs)
            for i in range(m):
                n, keep = _run_pairs(runs[i, 0], runs[i, 1], hot, lf, j, lm, typ, vis_box,
                                     vis_bits, vis_rows, pair_obj, pair_p, n, end, keep, model,
                                     w_obj, w_int)
            if vis_box.itemsize == 8:
                # Float64 records: the walk left (position, d2) of the hits (simd.point_run).
                if typ == POINT and model == MODEL_CONTRIBUTION:
                    point_priority(vis_box, vis_rows, _point_light(hot, j), pair_obj, pair_p,
                                   offsets[t], n, end)
                elif typ == SPOT and model == MODEL_CONTRIBUTION:
                    spot = (lf[j, 0], lf[j, 1], lf[j, 2], lf[j, 3], lf[j, 4], lf[j, 5])
                    n = spot_priority(vis_box, vis_rows, _point_light(hot, j), spot, pair_obj,
                                      pair_p, offsets[t], n, end)
                else:
                    n = _finish_hits(hot, lf, j, typ, offsets[t], n, vis_box, vis_rows,
                                     pair_obj, pair_p, model, w_obj, w_int)
            r = hot[j, 3]
            rr_exact = r * r
            for b in range(big_pos.shape[0]):
                v = big_pos[b]
                d2 = box_d2(vis_box, v, hot[j, 0], hot[j, 1], hot[j, 2])
                if d2 <= rr_exact:
                    n = _exact_pair(hot, lf, j, lm, typ, v, d2, vis_box, vis_bits, vis_rows,
                                    pair_obj, pair_p, n, model, w_obj, w_int)
            count[t] = n - offsets[t]
    return count


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _point_light(hot, j):
    """Light j as simd.point_run, point_priority and spot_priority take it."""
    return hot[j, 0], hot[j, 1], hot[j, 2], hot[j, 3], hot[j, 4], hot[j, 6], hot[j, 7]


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _finish_hits(hot, lf, j, typ, n0, n1, vis_box, vis_rows, pair_obj, pair_p, model, w_obj,
                 w_int):
    """The hits simd.point_run left at n0..n1-1, (position, d2), through the rest of
    Affects and P (record_pair_p: the spot cone, the thesis model), kept ones compacted in place
    as (object row, P). Returns the new end."""
    m = n0
    for i in range(n0, n1):
        v = pair_obj[i]
        hit, p = record_pair_p(hot, lf, j, typ, v, pair_p[i], vis_box, model, w_obj, w_int)
        if hit:
            pair_obj[m] = vis_rows[v]
            pair_p[m] = p
            m += 1
    return m


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _run_pairs(v0, v1, hot, lf, j, lm, typ, vis_box, vis_bits, vis_rows, pair_obj, pair_p, n,
               end, keep, model, w_obj, w_int):
    """The pairs of light j with the objects at positions v0..v1-1, appended at n (its
    segment of the pair buffers ends at ``end``). Float64
    records go eight at a time through simd.point_run (the range test and the mask), which
    appends (position, d2) of the hits; light_pass finishes them after the walk. Float32
    records ("fast") take the scalar loop: the range test (exact, DESIGN's d2 <= r*r)
    compacts the survivors and their d2 into ``keep`` without branching (a test that fails
    at random would mispredict); the rest of Affects and P run on survivors only. Returns
    (new n, keep, regrown when short)."""
    hits_end = point_run(vis_box, vis_rows, v0, v1, _point_light(hot, j), pair_obj, pair_p, n,
                         end)
    if hits_end >= 0:
        return hits_end, keep
    p0 = hot[j, 0]
    p1 = hot[j, 1]
    p2 = hot[j, 2]
    r = hot[j, 3]
    rr_exact = r * r
    if v1 - v0 > keep[0].shape[0]:
        keep = (np.empty(2 * (v1 - v0), np.int32), np.empty(2 * (v1 - v0)))
    kept, kept_d2 = keep
    m = 0
    for v in range(v0, v1):
        d2 = box_d2(vis_box, v, p0, p1, p2)
        kept[m] = v
        kept_d2[m] = d2
        m += d2 <= rr_exact
    for i in range(m):
        n = _exact_pair(hot, lf, j, lm, typ, kept[i], kept_d2[i], vis_box, vis_bits, vis_rows,
                        pair_obj, pair_p, n, model, w_obj, w_int)
    return n, keep


@nb.njit(cache=True, nogil=True, parallel=PRANGE_ONLY, error_model="numpy")
def affects_any(lights, rows, grid, vis):
    """Per light of ``rows`` (parallel): whether it affects at least one object of the grid
    (DESIGN section 2, "Affects": mask, range, cone), stopping at the first hit. lights:
    PackedLights; grid: GridIndex; vis: the grid's Records. An incremental frame
    asks this of its shadowed lights, the shadow ranking's candidates, instead of walking
    every light."""
    hot, lf = lights
    g_f, dims, cell_start, ext, big_pos = grid
    vis_box, vis_bits = vis[0], vis[1]
    out = np.zeros(rows.shape[0], np.bool_)
    for t in nb.prange(rows.shape[0]):
        j = rows[t]
        lm = np.int64(hot[j, 4])
        typ = (np.int64(hot[j, 5]) >> 3) & 3
        hit = False
        if typ == DIRECTIONAL:
            for v in range(vis_box.shape[0]):
                if np.int64(vis_bits[v, 6]) & lm != 0:
                    hit = True
                    break
            out[t] = hit
            continue
        m, runs = light_runs(hot, j, g_f, dims, cell_start, ext, np.empty((16, 2), np.int64))
        for i in range(m):
            for v in range(runs[i, 0], runs[i, 1]):
                if _affects(hot, lf, j, lm, typ, v, vis_box, vis_bits):
                    hit = True
                    break
            if hit:
                break
        for b in range(big_pos.shape[0]):
            if hit:
                break
            hit = _affects(hot, lf, j, lm, typ, big_pos[b], vis_box, vis_bits)
        out[t] = hit
    return out


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _affects(hot, lf, j, lm, typ, v, vis_box, vis_bits):
    """DESIGN "Affects" of point or spot light j (mask lm) and visible object v."""
    if np.int64(vis_bits[v, 6]) & lm == 0:
        return False
    r = hot[j, 3]
    d2 = box_d2(vis_box, v, hot[j, 0], hot[j, 1], hot[j, 2])
    if not d2 <= r * r:
        return False
    if typ != SPOT:
        return True
    return spot_cone(hot, lf, j, record_geometry(vis_box, v), False)[0]


