"""Shadowed lights (DESIGN section 2, "Shadowed lights" and "slot_shadow"): the ranking
with its hysteresis, the resolution tiers, the "skip" rule's live lights, and per object
slot which shadow map it samples.

Takes which lights are candidates (visible, shadows = true, affecting a visible object:
walk.affects_any) and last frame's shadowed lights with their tiers; returns this frame's
shadow lights in rank order with their tiers. slot_shadow's rule (``pick_slot_shadows``)
is inlined into objects.object_pass. The casters of the shadow lights are casters.py's.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numba as nb
import numpy as np

from .frustum import CameraFrames
from .priority import Packed, berka_eccentricity
from .scene import DIRECTIONAL, SPOT, Config, LightStore
from .select import F_NEW_W, I_NEW_ROW
from .walk import affects_any

if TYPE_CHECKING:
    from .grid import Grid


@dataclass(slots=True)
class ShadowSet:
    """The shadows stage's output: the shadow lights' ``rows`` in rank order, their ids
    and ``tier``s; ``candidates``: how many lights competed; ``shadow_of_row``: per light
    row its index in the shadow lights or -1; ``live``: per light row whether it may light
    an object (visible, and with unshadowed = "skip" not a shadowed light left without a
    map); ``directional``: the ids of the live directional lights applied outside the
    slots, ranked by i + p_user (ties: lower id); ``settled``: the shadowed set equals last
    frame's (then the next frame's ranking gives the same order; after a change it may
    not, as a light that just joined ranks with the hysteresis bonus one frame later)."""

    rows: np.ndarray
    ids: np.ndarray
    tier: np.ndarray
    candidates: int
    shadow_of_row: np.ndarray
    live: np.ndarray
    directional: np.ndarray
    settled: bool
    # The tiers before the atlas lowered them (the tier hysteresis' memory) and each
    # shadow light's importance without the hysteresis bonus (the update budget's order).
    ranked_tier: np.ndarray
    importance: np.ndarray

    def reselect(self, old: ShadowSet) -> np.ndarray:
        """Per light row whether its objects select again since ``old`` (last frame's
        set): it became live or stopped being, or its shadow map changed."""
        changed = self.live != old.live
        if self.shadow_of_row is not old.shadow_of_row:
            changed |= self.shadow_of_row != old.shadow_of_row
        return changed

    @property
    def how(self) -> str:
        return (f"{self.rows.size} of {self.candidates} candidates shadowed (ranking, tiers, "
                "slot_shadow)" if self.candidates
                else "skipped: no visible shadowed light affects a visible object")


NO_SHADOWS = (np.zeros(0, np.int32), np.zeros(0, np.int64))


def choose_shadows(last: ShadowSet | None, lights: LightStore, frames: CameraFrames,
                   visible: np.ndarray, packed: Packed, grid: Grid, config: Config
                   ) -> ShadowSet:
    """The shadows stage: the candidates (visible lights with shadows = true that affect a
    visible object of ``grid``) ranked against last frame's shadow lights (``last``, the
    hysteresis' memory), and what follows from them: the live lights and the directional
    lights outside the slots. ``visible``: the lights' visibility."""
    candidate = visible & lights.shadows
    rows, tier = np.zeros(0, np.int32), np.zeros(0, np.uint16)
    ranked, importance = tier, np.zeros(0)
    if candidate.any():
        cand_rows = np.flatnonzero(candidate).astype(np.int32)
        candidate[cand_rows] = affects_any(packed.rows, cand_rows, grid.index, grid.records)
        prev_ids, prev_tiers = NO_SHADOWS if last is None else (
            last.ids, last.ranked_tier.astype(np.int64))
        rows, ranked, importance = rank_shadow_lights(
            lights, frames, candidate, prev_ids, prev_tiers, config.shadow_budget,
            config.hysteresis, config.hysteresis_abs, config.c1)
        tier = ranked
        if config.shadow_atlas_size and rows.size:
            views = view_counts(lights.type[rows])
            kept, fitted = fit_atlas(views.tolist(), ranked.tolist(), config.shadow_atlas_size)
            rows, ranked, importance = rows[:kept], ranked[:kept], importance[:kept]
            tier = np.array(fitted, np.uint16)
    none_before = last is not None and last.rows.size == 0
    if none_before and rows.size == 0 and last.shadow_of_row.size == len(lights):
        shadow_of_row = last.shadow_of_row  # (every row -1, as last frame's)
    else:
        shadow_of_row = np.full(len(lights), -1, np.int8)
        shadow_of_row[rows] = np.arange(rows.size)
    live = visible.copy()
    if config.unshadowed == "skip":
        # A shadowed light without a shadow map affects nothing (it would leak through
        # walls): its pairs stay cached but do not compete.
        live &= ~(lights.shadows & (shadow_of_row < 0))
    dir_all = packed.dir_all
    dir_rows = dir_all[live[dir_all]] if not config.directional_in_slots else \
        np.zeros(0, np.int64)
    if dir_rows.size > 1:
        dir_p = lights.intensity[dir_rows] + lights.priority[dir_rows]
        dir_rows = dir_rows[np.lexsort((lights.id[dir_rows], -dir_p))]
    ids = lights.id[rows]
    # (At most shadow_budget <= 127 ids: Python's sort, not numpy's calls.)
    settled = (rows.size == 0 if none_before else
               sorted([] if last is None else last.ids.tolist()) == sorted(ids.tolist()))
    return ShadowSet(rows, ids, tier, int(np.count_nonzero(candidate)), shadow_of_row, live,
                     lights.id[dir_rows].astype(np.int32), settled, ranked, importance)


def view_counts(types: np.ndarray) -> np.ndarray:
    """Views per light of ``types``: a point light's six cube faces, a spot light's one, and
    0 for a directional light, whose cascades are not in the atlas (DESIGN "Shadow views")."""
    return np.where(types == DIRECTIONAL, 0, np.where(types == SPOT, 1, 6))


def fit_atlas(views: list[int], tiers: list[int], atlas: int) -> tuple[int, list[int]]:
    """DESIGN section 2, "Atlas", the fit rule: the point and spot shadow lights fit iff
    sum views * tier^2 <= atlas^2. ``views``, ``tiers``: per shadow light in shadow_lights
    order. Returns how many lights stay (the longest prefix that fits at 256: the others
    leave shadow_lights this frame) and their tiers after the last light above 256 dropped
    one tier at a time until the rest fit. Python ints: at most 127 lights."""
    room = atlas * atlas
    floor = MIN_TIER * MIN_TIER
    kept, used = len(views), 0
    for j, v in enumerate(views):
        used += v * floor
        if used > room:
            kept = j
            break
    out = list(tiers[:kept])
    area = sum(views[j] * out[j] * out[j] for j in range(kept))
    last = kept - 1
    while area > room:
        # The last light above 256 drops first; once it is at 256, the one before it.
        while not (views[last] and out[last] > MIN_TIER):
            last -= 1
        area -= views[last] * (out[last] * out[last] - (out[last] // 2) ** 2)
        out[last] //= 2
    return kept, out

MIN_TIER, MAX_TIER = 256, 4096


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _importance(j, position, radius, intensity, prio, cams, c1):
    """(importance, s_max) of point or spot light row j: s = height_px r / (max(d_viewer,
    r) t_y), importance = i min(1, s/height_px)^2 f + p_user (f: Berka's eccentricity),
    each the max over cameras (DESIGN section 2, "Shadowed lights")."""
    cam_p, basis, tan_xy, focus, height = cams
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
    return best, big_s


@nb.njit(cache=True, nogil=True, error_model="numpy")
def _rank(candidate, light, cams, prev, params):
    """rank_shadow_lights' work in one call on the calling thread: a frame has a few dozen
    candidates, too few to pay for the ~20 numpy calls this replaced (their per-call
    overhead) or for a parallel launch. light = (type, id, intensity, priority, position,
    radius); prev = (last frame's ids, their tiers); params = (budget, h, h_abs, c1).
    Returns (rows, tiers, importance without the hysteresis bonus)."""
    typ, ids, intensity, prio, position, radius = light
    budget, h, h_abs, c1 = int(params[0]), params[1], params[2], params[3]
    rows = np.flatnonzero(candidate)
    m = rows.shape[0]
    neg_key = np.empty(m)
    plain = np.empty(m)  # the key without the hysteresis bonus
    s_max = np.zeros(m)
    was = np.full(m, -1, np.int64)  # last frame's tier, or -1
    prev_at = np.argsort(prev[0])
    prev_sorted = prev[0][prev_at]
    for t in range(m):
        j = rows[t]
        if typ[j] == DIRECTIONAL:
            key = intensity[j] + prio[j]
        else:
            key, s_max[t] = _importance(j, position, radius, intensity, prio, cams, c1)
        plain[t] = key
        at = np.searchsorted(prev_sorted, ids[j])
        if at < prev_sorted.shape[0] and prev_sorted[at] == ids[j]:
            key = key + h * abs(key) + h_abs
            was[t] = prev[1][prev_at[at]]
        neg_key[t] = -key
    # Directional lights first, then key descending; a stable sort over ascending rows
    # breaks ties by the lower row.
    by_key = np.argsort(neg_key, kind="mergesort")
    order = np.empty(m, np.int64)
    n_dir = 0
    for t in range(m):
        n_dir += typ[rows[t]] == DIRECTIONAL
    head, tail = 0, n_dir
    for t in by_key:
        if typ[rows[t]] == DIRECTIONAL:
            order[head] = t
            head += 1
        else:
            order[tail] = t
            tail += 1
    n_out = min(budget, m)
    chosen = np.empty(n_out, np.int32)
    tier = np.empty(n_out, np.uint16)
    importance = np.empty(n_out)
    for q in range(n_out):
        t = order[q]
        chosen[q] = rows[t]
        importance[q] = plain[t]
        if typ[rows[t]] == DIRECTIONAL:
            tier[q] = MAX_TIER
            continue
        s = s_max[t]
        mant, expo = math.frexp(s)  # exact 2^ceil(log2 s)
        value = min(max(math.ldexp(1.0, expo - 1 if mant == 0.5 else expo), MIN_TIER),
                    MAX_TIER)
        if was[t] >= 0 and was[t] / (2 * (1 + h)) <= s <= was[t] * (1 + h):
            value = was[t]
        tier[q] = value
    return chosen, tier, importance


def rank_shadow_lights(lights: LightStore, frames: CameraFrames, candidate: np.ndarray,
                       prev_ids: np.ndarray, prev_tiers: np.ndarray, budget: int, h: float,
                       h_abs: float, c1: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(rows of the shadow lights in rank order, their tiers, their importance without the
    hysteresis bonus) for the candidate rows.

    Directional candidates rank first, among themselves by i + p_user; the others by
    importance. A light shadowed last frame competes with key + h|key| + h_abs; ties go to
    the lower id (row). Tier = clamp(2^ceil(log2 s_max), 256, 4096), kept at last frame's T
    while s_max stays in [T/(2(1+h)), T(1+h)]; directional lights 4096.
    """
    return _rank(candidate, (lights.type, lights.id, lights.intensity, lights.priority,
                             lights.position, lights.radius),
                 (frames.position, frames.basis, frames.tan_xy, frames.focus, frames.height_px),
                 (prev_ids, prev_tiers), np.array([budget, h, h_abs, c1], np.float64))


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def pick_slot_shadows(sf, si, cnt, shadow_of_row, max_per_object, out, o):
    """slot_shadow of one object: for at most max_per_object of its slots whose light has a
    shadow map, chosen by fade weight descending, then output order, the index of that map
    in shadow_lights; -1 elsewhere. Fading-out slots count: the shader still samples them.
    Reads the object's new slots (F_NEW_W, I_NEW_ROW of select.py, in output order) and
    writes row o of out [N, K], which the caller has filled with -1; inlined into
    objects.object_pass. sf, si: the object's scratch (select.py); cnt: its occupied
    slots; shadow_of_row: int8 [L] (ShadowSet's); max_per_object:
    Config.max_shadowed_per_object; out: int8 slot_shadow. DESIGN section 2,
    "slot_shadow[o, k]"."""
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


