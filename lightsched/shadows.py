"""Shadowed lights: ranking, resolution tiers and slot_shadow (DESIGN section 2, "Shadowed
lights" and "slot_shadow"). Caster lists are not built yet (issue 3).
slot_shadow's rule (pick_slot_shadows) is inlined into pairs.object_pass.

Takes the packed lights and cameras, which lights are candidates (visible, shadows = true,
affecting a visible object: pairs.py counts that) and last frame's shadowed lights with
their tiers; returns this frame's shadow lights in rank order with their tiers, and per
object slot which shadow map it samples.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from .frustum import CameraFrames
from .priority import berka_eccentricity
from .scene import DIRECTIONAL, LightStore
from .select import F_NEW_W, I_NEW_ROW

MIN_TIER, MAX_TIER = 256, 4096


@nb.njit(cache=True, nogil=True, parallel=True, error_model="numpy")
def _importance(rows, position, radius, intensity, prio, cams, c1):
    """(importance, s_max) per light row: s = height_px r / (max(d_viewer, r) t_y),
    importance = i min(1, s/height_px)^2 f + p_user (f: Berka's eccentricity), each the max
    over cameras."""
    cam_p, basis, tan_xy, focus, height = cams
    imp = np.empty(rows.shape[0])
    s_max = np.empty(rows.shape[0])
    for t in nb.prange(rows.shape[0]):
        j = rows[t]
        r = radius[j]
        best = -np.inf
        big_s = 0.0
        for c in range(cam_p.shape[0]):
            v0 = position[j, 0] - cam_p[c, 0]
            v1 = position[j, 1] - cam_p[c, 1]
            v2 = position[j, 2] - cam_p[c, 2]
            d_viewer = math.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
            s = height[c] * r / (max(d_viewer, r) * tan_xy[c, 1])
            m = min(1.0, s / height[c])
            f = berka_eccentricity(v0, v1, v2, d_viewer, r, basis[c], tan_xy[c], focus[c], c1)
            best = max(best, intensity[j] * m * m * f + prio[j])
            big_s = max(big_s, s)
        imp[t] = best
        s_max[t] = big_s
    return imp, s_max


def rank_shadow_lights(lights: LightStore, frames: CameraFrames, candidate: np.ndarray,
                       prev_ids: np.ndarray, prev_tiers: np.ndarray, budget: int, h: float,
                       h_abs: float, c1: float) -> tuple[np.ndarray, np.ndarray]:
    """(rows of the shadow lights in rank order, their tiers) for the candidate rows.

    Directional candidates rank first, among themselves by i + p_user; the others by
    importance. A light shadowed last frame competes with key + h|key| + h_abs; ties go to
    the lower id (row). Tier = clamp(2^ceil(log2 s_max), 256, 4096), kept at last frame's T
    while s_max stays in [T/(2(1+h)), T(1+h)]; directional lights 4096.
    """
    rows = np.flatnonzero(candidate)
    is_dir = lights.type[rows] == DIRECTIONAL
    key = np.empty(rows.size)
    s_max = np.zeros(rows.size)
    key[is_dir] = lights.intensity[rows[is_dir]] + lights.priority[rows[is_dir]]
    other = rows[~is_dir]
    if other.size:
        cams = (frames.position, frames.basis, frames.tan_xy, frames.focus, frames.height_px)
        key[~is_dir], s_max[~is_dir] = _importance(other, lights.position, lights.radius,
                                                   lights.intensity, lights.priority, cams, c1)
    ids = lights.id[rows]
    if prev_ids.size:
        prev_sorted = np.sort(prev_ids)
        at = np.minimum(np.searchsorted(prev_sorted, ids), prev_sorted.size - 1)
        before = prev_sorted[at] == ids
        key[before] = key[before] + h * np.abs(key[before]) + h_abs
    order = np.lexsort((rows, -key, ~is_dir))[:budget]
    chosen = rows[order]
    # At most S (<= 127) lights: plain Python, exact 2^ceil(log2 s) by frexp.
    prev = dict(zip(prev_ids.tolist(), prev_tiers.tolist(), strict=True))
    tier = np.empty(chosen.size, np.uint16)
    for t, (lid, directional, s) in enumerate(zip(lights.id[chosen].tolist(),
                                                   is_dir[order].tolist(),
                                                   s_max[order].tolist(), strict=True)):
        if directional:
            tier[t] = MAX_TIER
            continue
        mant, expo = math.frexp(s)
        value = int(min(max(math.ldexp(1.0, expo - 1 if mant == 0.5 else expo), MIN_TIER),
                        MAX_TIER))
        if lid in prev and prev[lid] / (2 * (1 + h)) <= s <= prev[lid] * (1 + h):
            value = prev[lid]
        tier[t] = value
    return chosen.astype(np.int32), tier


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def pick_slot_shadows(sf, si, cnt, shadow_of_row, max_per_object, out, o):
    """slot_shadow of one object: for at most max_per_object of its slots whose light has a
    shadow map, chosen by fade weight descending, then output order, the index of that map
    in shadow_lights; -1 elsewhere. Fading-out slots count: the shader still samples them.
    Reads the object's new slots (F_NEW_W, I_NEW_ROW of select.py, in output order) and
    writes row o of out [N, K], which the caller has filled with -1; inlined into
    pairs.object_pass."""
    for _ in range(max_per_object):
        best = -1
        for m in range(cnt):
            if out[o, m] >= 0 or shadow_of_row[si[I_NEW_ROW, m]] < 0:
                continue
            if best < 0 or sf[F_NEW_W, m] > sf[F_NEW_W, best]:
                best = m
        if best < 0:
            break
        out[o, best] = shadow_of_row[si[I_NEW_ROW, best]]
