"""Shadowed lights: ranking, resolution tiers and slot_shadow (DESIGN section 2, "Shadowed
lights" and "slot_shadow"). Caster lists are not built yet (issue 3).

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
from .scene import DIRECTIONAL

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


def rank_shadow_lights(lights: object, frames: CameraFrames, candidate: np.ndarray,
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
    before = np.isin(ids, prev_ids)
    key[before] = key[before] + h * np.abs(key[before]) + h_abs
    order = np.lexsort((rows, -key, ~is_dir))[:budget]
    chosen, s_max, is_dir = rows[order], s_max[order], is_dir[order]
    mant, expo = np.frexp(np.where(is_dir, 1.0, s_max))
    tier = np.clip(np.ldexp(1.0, np.where(mant == 0.5, expo - 1, expo)), MIN_TIER, MAX_TIER)
    prev = dict(zip(prev_ids.tolist(), prev_tiers.tolist(), strict=True))
    for t, lid in enumerate(lights.id[chosen].tolist()):
        if is_dir[t]:
            tier[t] = MAX_TIER
        elif lid in prev and prev[lid] / (2 * (1 + h)) <= s_max[t] <= prev[lid] * (1 + h):
            tier[t] = prev[lid]
    return chosen.astype(np.int32), tier.astype(np.uint16)


@nb.njit(cache=True, nogil=True, parallel=True, error_model="numpy")
def slot_shadow(light_index, weight, count, shadow_of_row, max_per_object):
    """slot_shadow [N, K] int8: for at most max_per_object of an object's slots whose light
    has a shadow map, chosen by fade weight descending, then output order, the index of
    that map in shadow_lights; -1 elsewhere. Fading-out slots count: the shader still
    samples them."""
    n, k = light_index.shape
    out = np.full((n, k), -1, np.int8)
    for o in nb.prange(n):
        for _ in range(max_per_object):
            best = -1
            for m in range(count[o]):
                if out[o, m] >= 0 or shadow_of_row[light_index[o, m]] < 0:
                    continue
                if best < 0 or weight[o, m] > weight[o, best]:
                    best = m
            if best < 0:
                break
            out[o, best] = shadow_of_row[light_index[o, best]]
    return out
