"""Quality: run time against error (DESIGN section 4), the priority policies compared, popping.

    python bench/quality.py            # ~15 minutes on a 2-core machine
    python bench/quality.py --quick    # smaller scenes, fewer frames (about a minute)
    python bench/quality.py --write    # also bench/RESULTS.md and bench/plots/quality_*.png
    python bench/quality.py --quick --residual-only   # issue 53's part alone (no --write)

The three errors of DESIGN section 4, as computed here (functions below, each with the
details in its docstring):

- set error (``set_error``): the share of visible objects whose light set (the ids in their
  slots, as a set, fading-out slots included) differs from the oracle's
  (``lightsched.reference.Scheduler``, same Config) on the same frame. The oracle is ~150x
  slower than the fast path, so this runs on a small copy of each scene for a few frames.
- captured lighting (``captured_lighting``): at ``SAMPLES_PER_FACE`` seeded points on each
  of the 6 faces of every visible object's box (24 points, face normals), Lambert lighting
  of DESIGN's contribution model (``light_at_points``), summed over the object's slots
  weighted by fade_weight, over the sum of the K best lights for that object (the K lights
  with the largest lighting summed over its points, among every light that affects it).
  Directional lights are left out of both sides: with directional_in_slots false they take
  no slot and the renderer applies every one of them to every object, so they are the same
  in both terms and would only pull the ratio towards 1. Also reported, against every
  affecting light instead of the best K ("of all"): what a renderer with unlimited lights
  would show; it is the error that trades against K.
- popping (``popping``): per object visible on this and the previous frame, the lighting
  of this frame's slots and weights minus that of last frame's slots and weights, both
  evaluated with this frame's light and object positions (motion itself is not counted);
  the sum of absolute values over objects and frames, over the total lighting of those
  objects and frames (a per-frame share; the tables give it per second, x 60). Also
  reported, "in steps": the same sum over only the one-frame changes larger than
  POP_STEP = 10 % of the object's best-K lighting, and "pops": how many such steps per 1000
  object-seconds. Why: the absolute sum is blind to how fast a change happens (a light
  fading in over 15 frames adds E/15 fifteen times, the same E as a one-frame switch), and
  a 0.25 s fade moves an object's lighting by at most 1/15 of one light's share per frame,
  below the step size, so what fade removes shows in the steps, not in the sum.

Issue 53 adds the residual (DESIGN section 2, "Residual") and section 4's lighting error
and abrupt pops, at the same sample points and normals, for no fade / fade / fade +
hysteresis, each with the residual off and on, K = 2, 4, 8, in city, stadium and dungeon-22
(``residual_study``; details in the docstrings):

- lighting error (``lighting_error``): sum |D - A| / sum A over every measured (frame,
  object, point). A: every light that affects the object (this module's Affects test, the
  unshadowed rule ignored) and every directional light whose mask it shares, unweighted.
  D: the slots' lights times their fade weights, plus the frame's residual at the point's
  normal (``residual_at``: max(0, a/4 + (b . n)/2)) when on, plus the frame's
  directional_lights. Directional lights are in both (section 4 says so), unlike above.
- abrupt pops (``abrupt_pops``): a point pops on a frame when |(D_t - D_t-1) - (A_t -
  A_t-1)| > POP_SHARE * max(A_t, A_t-1), each frame's lighting at its own positions; counted
  per object-frame (an object visible on both frames pops when any of its points does), per
  1000 such object-seconds at dt = 1/60. Where A = 0 on both frames the threshold is 0 and
  any change of D pops; the report says how many pops are of that kind.
- summed popping: ``popping`` above, with the residual of each side's weights (rebuilt in
  numpy from DESIGN, ``residual_terms`` and ``residual_vectors``, and checked against the
  frame's) added to both sides when the run has it on.
- the residual's cost: paired frame times (on - off, same frame, same lockstep timing pass)
  per scene and K, and a (100k, 10k) city frame at K = 4 measured by
  bench/residual_cost.py's child; the issue's conditions at K = 4 judged from the figures
  (``done_when``), and ``bench/plots/quality_residual.png``.

The affecting lights of every object are found here in numpy by DESIGN's Affects test
(``affecting_pairs``; range, spot cone, masks, visible lights; checked against the fast
path's ``candidates`` count each frame), not taken from the oracle.

Scenes and sequences (dt 1/60 s, the camera orbiting the vertical axis through the origin
at ``ORBIT`` rad/s): ``lightsched.scenes.city`` with every light moving
(``lightsched.scenes.move_lights``, 3 m/s round 3 m circles), and the selection-heavy
``lightsched.scenes.stadium`` (hundreds of floodlights reach every object on the pitch; a
local ``stadium_fallback`` if that generator is missing) with the floodlights fixed and the
players and props running round 5 m circles. The set error uses a small copy of each
(the oracle is slow); lighting metrics in the stadium use a seeded subset of objects.

Reported per scene: the knobs (precision, grid cell, K, hysteresis, model, fade) with frame
time and the errors, and the Pareto fronts; the four policies (nearest, brightest, thesis,
contribution) on captured lighting; popping for fade off/on x hysteresis 0/0.1.
"""

from __future__ import annotations

import argparse
import contextlib
import math
import os
import shlex
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from common import PLOTS, git_commit, machine, markers, say, write_results
from tqdm import tqdm

import lightsched
import lightsched.reference as ref
from lightsched import Camera, Config
from lightsched.scene import DIRECTIONAL, POINT, SPOT, SceneAPI
from lightsched.scenes import DT, CityScene, city, move_lights
from lightsched.tuning import Tuning

BEGIN, END = markers("quality.py")

SAMPLES_PER_FACE = 4  # on a jittered 2x2 grid per face: 24 points per object
R0 = ref.R0  # metres: the falloff's softening distance of DESIGN's contribution model
POP_STEP = 0.10  # a one-frame change above this share of the object's best-K lighting is a pop
ORBIT = 0.1  # rad/s: the camera's orbit round the vertical axis through the origin
UNITY_ATTEN = 25.0  # brightest policy: attenuation 1 / (1 + 25 d^2 / r^2)


# =========================================================================== geometry


def face_samples(lo: np.ndarray, hi: np.ndarray, per_face: int = SAMPLES_PER_FACE,
                 seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Sample points on the 6 faces of each box [lo, hi] (N, 3), and their normals.

    Faces in the order +x, -x, +y, -y, +z, -z, ``per_face`` points each, at seeded
    positions (u, v) in [0, 1]^2 that every box shares (a jittered grid when ``per_face``
    is a square, else uniform). Returns points (N, 6 * per_face, 3) and outward unit
    normals (6 * per_face, 3).
    """
    lo = np.asarray(lo, np.float64).reshape(-1, 3)
    hi = np.asarray(hi, np.float64).reshape(-1, 3)
    rng = np.random.default_rng(seed)
    side = int(round(math.sqrt(per_face)))
    uv = []
    for _ in range(6):
        if side * side == per_face:
            cells = np.stack(np.meshgrid(np.arange(side), np.arange(side), indexing="ij"),
                             -1).reshape(-1, 2)
            uv.append((cells + rng.uniform(0.0, 1.0, (per_face, 2))) / side)
        else:
            uv.append(rng.uniform(0.0, 1.0, (per_face, 2)))
    m = 6 * per_face
    points = np.empty((lo.shape[0], m, 3))
    normals = np.zeros((m, 3))
    ext = hi - lo
    for face in range(6):
        axis, neg = divmod(face, 2)
        others = [a for a in range(3) if a != axis]
        sl = slice(face * per_face, (face + 1) * per_face)
        points[:, sl, axis] = (lo if neg else hi)[:, None, axis]
        for j, a in enumerate(others):
            points[:, sl, a] = lo[:, None, a] + uv[face][None, :, j] * ext[:, None, a]
        normals[sl, axis] = -1.0 if neg else 1.0
    return points, normals


def light_at_points(lights: Any, rows: np.ndarray, x: np.ndarray, n: np.ndarray) -> np.ndarray:
    """Lambert lighting of light row ``rows[i]`` at points ``x[i]`` (P, M, 3) with unit
    normals ``n`` (M, 3) or (P, M, 3): (P, M).

    DESIGN section 4 ("captured lighting") with the falloff of section 2's contribution
    model, evaluated at the point instead of the box: with v = p - x, d2 = v . v,
    q = d2 / r^2, w = max(0, 1 - q^2), the lighting is intensity * max(0, n . v / |v|)
    * w^2 / (d2 + r0^2), times for spots s = clamp((c - cos o) / (cos inner - cos o), 0, 1)^2
    (a step at cos o when inner = outer) with c = (x - p) . axis / |v| the cosine of the
    point's angle from the axis. Directional: intensity * max(0, n . -direction). A point
    at the light's position gets 0. ``lights`` is a store with DESIGN's light fields in rows
    (``SceneAPI.lights``).
    """
    rows = np.asarray(rows, np.int64)
    x = np.asarray(x, np.float64)
    nn = np.broadcast_to(np.asarray(n, np.float64), x.shape)
    ltype = lights.type[rows]
    p = lights.position[rows][:, None, :]
    v = p - x
    d2 = v[..., 0] * v[..., 0] + v[..., 1] * v[..., 1] + v[..., 2] * v[..., 2]
    r2 = (lights.radius[rows] ** 2)[:, None]
    q = d2 / r2
    w = np.maximum(0.0, 1.0 - q * q)
    dist = np.sqrt(d2)
    safe = np.where(dist > 0.0, dist, 1.0)
    cos_n = np.where(dist > 0.0, (nn * v).sum(-1) / safe, 0.0)
    out = lights.intensity[rows][:, None] * np.maximum(0.0, cos_n) * w * w / (d2 + R0 * R0)
    spot = ltype == SPOT
    if spot.any():
        axis = lights.direction[rows[spot]][:, None, :]
        c = np.where(dist[spot] > 0.0, -(v[spot] * axis).sum(-1) / safe[spot], 1.0)
        outer = lights.outer_angle[rows[spot]]
        inner = lights.inner_angle[rows[spot]]
        cos_o, cos_i = np.cos(outer)[:, None], np.cos(inner)[:, None]
        step = ((inner == outer)[:, None] | (cos_i == cos_o))
        ramp = np.clip((c - cos_o) / np.where(step, 1.0, cos_i - cos_o), 0.0, 1.0) ** 2
        out[spot] *= np.where(step, (c >= cos_o).astype(np.float64), ramp)
    sun = ltype == DIRECTIONAL
    if sun.any():
        d = lights.direction[rows[sun]][:, None, :]
        out[sun] = lights.intensity[rows[sun]][:, None] * np.maximum(0.0, -(nn[sun] * d).sum(-1))
    return out


def pair_lighting_points(lights: Any, points: np.ndarray, normals: np.ndarray, obj: np.ndarray,
                         light: np.ndarray, chunk: int = 16384) -> np.ndarray:
    """Lighting of each (object row, light row) pair at each of the object's sample points
    (``face_samples``), at full weight: (P, M)."""
    obj = np.asarray(obj, np.int64)
    light = np.asarray(light, np.int64)
    out = np.empty((obj.size, points.shape[1]))
    for s in range(0, obj.size, chunk):
        o, lt = obj[s:s + chunk], light[s:s + chunk]
        out[s:s + chunk] = light_at_points(lights, lt, points[o], normals)
    return out


def pair_lighting(lights: Any, points: np.ndarray, normals: np.ndarray, obj: np.ndarray,
                  light: np.ndarray) -> np.ndarray:
    """Lighting of each (object row, light row) pair summed over the object's sample points
    (``face_samples``), at full weight: (P,)."""
    return pair_lighting_points(lights, points, normals, obj, light).sum(-1)


def affecting_pairs(lights: Any, objects: Any, obj_rows: np.ndarray, light_rows: np.ndarray,
                    chunk: int = 64) -> tuple[np.ndarray, np.ndarray]:
    """(object rows, light rows) of the pairs where light affects object (DESIGN section 2,
    "Affects"), for the given (visible) object rows and competing (visible, point or spot)
    light rows: masks intersect, d2 <= r*r with d2 the squared distance from the light to
    the box, and for spots the bounding sphere (c, R) meets the cone: n <= R or
    a >= cos(o) sqrt(n^2 - R^2) - R sin(o). Written in DESIGN's order of operations (cos and
    sin by ``math``) so it decides like the oracle. Lights go in chunks of ``chunk``
    sorted by x, each tested against the objects that meet the box of its spheres.
    Pairs come sorted by object row, then light row."""
    obj_rows = np.asarray(obj_rows, np.int64)
    light_rows = np.asarray(light_rows, np.int64)
    light_rows = light_rows[lights.type[light_rows] != DIRECTIONAL]
    if obj_rows.size == 0 or light_rows.size == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    lo, hi = objects.bounds_min[obj_rows], objects.bounds_max[obj_rows]
    omask = objects.mask[obj_rows].astype(np.int64)
    centre = (lo + hi) / 2
    ext = hi - lo
    big_r = np.sqrt(ext[:, 0] * ext[:, 0] + ext[:, 1] * ext[:, 1] + ext[:, 2] * ext[:, 2]) / 2
    light_rows = light_rows[np.argsort(lights.position[light_rows, 0], kind="stable")]
    cos_o = np.array([math.cos(float(a)) for a in lights.outer_angle])
    sin_o = np.array([math.sin(float(a)) for a in lights.outer_angle])
    out_o, out_l = [], []
    for s in range(0, light_rows.size, chunk):
        rows = light_rows[s:s + chunk]
        p = lights.position[rows]
        r = lights.radius[rows]
        reach_lo = (p - r[:, None]).min(0)
        reach_hi = (p + r[:, None]).max(0)
        near = np.flatnonzero(np.all((hi >= reach_lo) & (lo <= reach_hi), axis=1))
        if near.size == 0:
            continue
        d = [np.maximum(np.maximum(lo[near, k][:, None] - p[None, :, k], 0.0),
                        p[None, :, k] - hi[near, k][:, None]) for k in range(3)]
        d2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2]
        ok = d2 <= (r * r)[None, :]
        ok &= (omask[near][:, None] & lights.mask[rows].astype(np.int64)[None, :]) != 0
        spot = lights.type[rows] == SPOT
        if spot.any():
            ps, axis = p[spot], lights.direction[rows[spot]]
            v = [centre[near, k][:, None] - ps[None, :, k] for k in range(3)]
            n = np.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
            a = v[0] * axis[None, :, 0] + v[1] * axis[None, :, 1] + v[2] * axis[None, :, 2]
            rr = big_r[near][:, None]
            rad = n * n - rr * rr
            root = np.sqrt(np.where(rad > 0.0, rad, 0.0))
            cone = (n <= rr) | (a >= cos_o[rows[spot]][None, :] * root
                                - rr * sin_o[rows[spot]][None, :])
            ok[:, spot] &= cone
        i, j = np.nonzero(ok)
        out_o.append(obj_rows[near[i]])
        out_l.append(rows[j])
    if not out_o:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    o, lt = np.concatenate(out_o), np.concatenate(out_l)
    order = np.lexsort((lt, o))
    return o[order], lt[order]


# =========================================================================== metrics


def set_error(ids_a: np.ndarray, ids_b: np.ndarray, visible: np.ndarray) -> tuple[float, int, int]:
    """DESIGN section 4, set error: (share, differing, visible) over the visible objects,
    where an object differs when the ids in its slots (-1 = empty, ignored), taken as a set,
    differ between ``ids_a`` and ``ids_b`` ([N, K], rows in the same object order)."""
    a = np.sort(np.asarray(ids_a)[visible], axis=1)
    b = np.sort(np.asarray(ids_b)[visible], axis=1)
    n_vis = int(a.shape[0])
    if a.shape != b.shape:
        return (1.0 if n_vis else 0.0), n_vis, n_vis
    differ = int(np.count_nonzero(np.any(a != b, axis=1)))
    return (differ / n_vis if n_vis else 0.0), differ, n_vis


def captured_lighting(chosen: np.ndarray, best: np.ndarray) -> tuple[float, float, int]:
    """DESIGN section 4, captured lighting, from per-object sums: ``chosen`` the lighting the
    object's slots deliver (weighted by fade_weight), ``best`` what its best K affecting
    lights would deliver. Returns (sum of chosen / sum of best, mean of chosen / best over
    objects with best > 0, number of such objects); 1.0 when nothing is lit."""
    chosen = np.asarray(chosen, np.float64)
    best = np.asarray(best, np.float64)
    lit = best > 0.0
    total = float(best.sum())
    ratio = float(chosen.sum()) / total if total > 0.0 else 1.0
    mean = float(np.mean(chosen[lit] / best[lit])) if lit.any() else 1.0
    return ratio, mean, int(lit.sum())


def popping(now: np.ndarray, before: np.ndarray, ref: np.ndarray, step: float = POP_STEP
            ) -> tuple[float, float, int, float]:
    """DESIGN section 4, popping, for one frame: ``now`` is each object's lighting from this
    frame's slots and weights, ``before`` from last frame's slots and weights, both at this
    frame's light and object positions (so only set and weight changes count), for the
    objects visible on both frames; ``ref`` is each object's best-K lighting this frame.
    Returns (sum |now - before|, the same over the changes larger than ``step`` * ref (pops),
    the number of pops, sum of now): divide the sums by the last one, summed over frames,
    for the normalised popping."""
    now = np.asarray(now, np.float64)
    before = np.asarray(before, np.float64)
    change = np.abs(now - before)
    pop = change > step * np.asarray(ref, np.float64)
    return float(change.sum()), float(change[pop].sum()), int(pop.sum()), float(now.sum())


def group_sum(group: np.ndarray, values: np.ndarray, n: int) -> np.ndarray:
    """Rows of ``values`` (S, ...) summed by ``group`` (S,), ascending, in 0..n-1: (n, ...)."""
    out = np.zeros((n, *values.shape[1:]))
    if group.size:
        starts = np.flatnonzero(np.r_[True, group[1:] != group[:-1]])
        out[group[starts]] = np.add.reduceat(values, starts, axis=0)
    return out


class LightingTable:
    """One frame's lighting of every affecting (object, light) pair, and what a selection
    delivers. Pairs are sorted by object row then light row; ``n_obj`` object rows."""

    def __init__(self, lights: Any, points: np.ndarray, normals: np.ndarray, obj: np.ndarray,
                 light: np.ndarray, n_obj: int) -> None:
        self.lights, self.points, self.normals = lights, points, normals
        self.obj, self.light = obj, light
        self.n_obj, self.n_lights = n_obj, len(lights)
        self.ep = pair_lighting_points(lights, points, normals, obj, light)  # (P, M)
        self.e = self.ep.sum(-1)
        self.key = obj * self.n_lights + light
        # Per object: its pairs by lighting descending (ties: lower light row), and ranks.
        order = np.lexsort((light, -self.e, obj))
        self._by_e = order
        start = np.searchsorted(obj[order], obj[order], side="left")
        self._rank = np.arange(order.size) - start
        self.missing = 0  # looked-up pairs that are not affecting pairs (computed directly)

    def all_lights(self) -> np.ndarray:
        """Per object row: the lighting of every affecting light together."""
        return np.bincount(self.obj, self.e, minlength=self.n_obj)

    def all_lights_points(self, rows: np.ndarray) -> np.ndarray:
        """Per object row of ``rows`` (ascending) and sample point: the lighting of every
        affecting point and spot light together, (len(rows), M)."""
        return group_sum(np.searchsorted(rows, self.obj), self.ep, rows.size)

    def best(self, k: int) -> np.ndarray:
        """Per object row: the lighting of its best ``k`` affecting lights."""
        keep = self._rank < k
        idx = self._by_e[keep]
        return np.bincount(self.obj[idx], self.e[idx], minlength=self.n_obj)

    def find(self, obj: np.ndarray, light: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Positions of (object row, light row) pairs among the affecting pairs, and whether
        each was found (positions of pairs not found are meaningless)."""
        key = np.asarray(obj, np.int64) * self.n_lights + np.asarray(light, np.int64)
        if self.key.size == 0:
            return np.zeros(key.size, np.int64), np.zeros(key.size, bool)
        pos = np.minimum(np.searchsorted(self.key, key), self.key.size - 1)
        return pos, self.key[pos] == key

    def lookup_points(self, obj: np.ndarray, light: np.ndarray) -> np.ndarray:
        """Lighting of (object row, light row) pairs at the object's sample points, (S, M);
        pairs that are not affecting pairs (a light that left the object's range or the
        view) are computed directly."""
        pos, found = self.find(obj, light)
        out = np.zeros((pos.size, self.points.shape[1]))
        out[found] = self.ep[pos[found]]
        if not found.all():
            miss = ~found
            self.missing += int(miss.sum())
            out[miss] = pair_lighting_points(self.lights, self.points, self.normals, obj[miss],
                                             light[miss])
        return out

    def lookup(self, obj: np.ndarray, light: np.ndarray) -> np.ndarray:
        """Lighting of (object row, light row) pairs summed over the sample points."""
        return self.lookup_points(obj, light).sum(-1)

    def selection_points(self, rows: np.ndarray, light_index: np.ndarray, weight: np.ndarray
                         ) -> tuple[np.ndarray, int]:
        """Per object row of ``rows`` and sample point: the lighting of its slots (light
        rows ``light_index[row]``, -1 empty) weighted by ``weight[row]``, (len(rows), M);
        and how many slot lights were not affecting lights of this frame (computed
        directly)."""
        li = light_index[rows]
        occupied = li >= 0
        local = np.repeat(np.arange(rows.size), occupied.sum(1))
        before = self.missing
        e = self.lookup_points(rows[local], li[occupied]) * weight[rows][occupied][:, None]
        return group_sum(local, e, rows.size), self.missing - before

    def selection(self, rows: np.ndarray, light_index: np.ndarray, weight: np.ndarray
                  ) -> tuple[np.ndarray, int]:
        """``selection_points`` summed over each object's sample points: (len(rows),)."""
        pts, miss = self.selection_points(rows, light_index, weight)
        return pts.sum(1), miss

    def top_by(self, key: np.ndarray, k: int, shape: tuple[int, int]) -> np.ndarray:
        """light_index [N, K] of the policy that takes, per object, the ``k`` affecting
        lights with the largest ``key`` (one value per pair; ties: lower light row, which is
        the lower id)."""
        order = np.lexsort((self.light, -key, self.obj))
        o = self.obj[order]
        rank = np.arange(order.size) - np.searchsorted(o, o, side="left")
        keep = rank < k
        out = np.full(shape, -1, np.int64)
        out[o[keep], rank[keep]] = self.light[order][keep]
        return out


def nearest_key(lights: Any, objects: Any, obj: np.ndarray, light: np.ndarray) -> np.ndarray:
    """Nearest-distance policy (Ogre, Bateman): minus the distance from the light to the
    object's box centre (larger is better)."""
    c = (objects.bounds_min[obj] + objects.bounds_max[obj]) / 2
    return -np.sqrt(((lights.position[light] - c) ** 2).sum(1))


def brightest_key(lights: Any, objects: Any, obj: np.ndarray, light: np.ndarray) -> np.ndarray:
    """Brightest policy (Unity built-in forward: "the brightest lights that affect the
    object"): intensity / (1 + 25 d^2 / r^2) with d the distance from the light to the
    object's box centre and r its range, the usual approximation of Unity's built-in
    attenuation curve; the spot cone is not weighed."""
    c = (objects.bounds_min[obj] + objects.bounds_max[obj]) / 2
    d2 = ((lights.position[light] - c) ** 2).sum(1)
    return lights.intensity[light] / (1.0 + UNITY_ATTEN * d2 / lights.radius[light] ** 2)


# =========================================================================== residual metrics

POP_SHARE = 0.10  # abrupt pops: a change A does not explain, above this share of A (DESIGN 4)


def sphere_spot_factor(lights: Any, rows: np.ndarray, v: np.ndarray, big_r: np.ndarray
                       ) -> np.ndarray:
    """s of DESIGN's contribution model for spot light rows ``rows`` and bounding spheres
    of radius ``big_r`` whose centres are at ``v`` (P, 3) from the light: with n = |v|,
    a = v . axis, root = sqrt(max(n^2 - R^2, 0)), c = 1 if n <= R or a >= root, else
    (a root + R sqrt(max(n^2 - a^2, 0))) / n^2; s = clamp((c - cos o)/(cos inner - cos o),
    0, 1)^2, or [c >= cos o] when inner = o or the cosines are equal."""
    axis = lights.direction[rows]
    n = np.sqrt(v[:, 0] * v[:, 0] + v[:, 1] * v[:, 1] + v[:, 2] * v[:, 2])
    a = v[:, 0] * axis[:, 0] + v[:, 1] * axis[:, 1] + v[:, 2] * axis[:, 2]
    n2 = n * n
    root = np.sqrt(np.maximum(n2 - big_r * big_r, 0.0))
    side = np.sqrt(np.maximum(n2 - a * a, 0.0))
    whole = (n <= big_r) | (a >= root) | ~(n2 > 0.0)
    c = np.where(whole, 1.0, (a * root + big_r * side) / np.where(n2 > 0.0, n2, 1.0))
    # math.cos, as the oracle: np.cos may differ in the last bit.
    cos_all_o = np.array([math.cos(float(x)) for x in lights.outer_angle])
    cos_all_i = np.array([math.cos(float(x)) for x in lights.inner_angle])
    cos_o, cos_i = cos_all_o[rows], cos_all_i[rows]
    step = (lights.inner_angle[rows] == lights.outer_angle[rows]) | (cos_i == cos_o)
    t = np.clip((c - cos_o) / np.where(step, 1.0, cos_i - cos_o), 0.0, 1.0)
    return np.where(step, (c >= cos_o).astype(np.float64), t * t)


def residual_terms(lights: Any, objects: Any, obj: np.ndarray, light: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray]:
    """(E_l, u_l) of DESIGN section 2, "Residual", for (object row, light row) pairs: the
    light over the whole object, from its box centre c. v = p - c, dc2 = max(v . v, R^2)
    with R = |hi - lo| / 2, q = dc2 / r^2, w = max(0, 1 - q^2), E = i w^2 / (dc2 + r0^2) * s
    (``sphere_spot_factor`` for spots, 1 for point lights; no g, no p_user), u = v / |v|,
    (0, 0, 0) when v . v = 0; directional: E = i, u = -direction. Returns E (P,), u (P, 3)."""
    obj = np.asarray(obj, np.int64)
    light = np.asarray(light, np.int64)
    lo, hi = objects.bounds_min[obj], objects.bounds_max[obj]
    ext = hi - lo
    big_r = np.sqrt(ext[:, 0] * ext[:, 0] + ext[:, 1] * ext[:, 1] + ext[:, 2] * ext[:, 2]) / 2
    v = lights.position[light] - (lo + hi) / 2
    vv = v[:, 0] * v[:, 0] + v[:, 1] * v[:, 1] + v[:, 2] * v[:, 2]
    dc2 = np.maximum(vv, big_r * big_r)
    r = lights.radius[light]
    q = dc2 / (r * r)
    w = np.maximum(0.0, 1.0 - q * q)
    e = lights.intensity[light] * w * w / (dc2 + R0 * R0)
    ltype = lights.type[light]
    spot = ltype == SPOT
    if spot.any():
        e[spot] *= sphere_spot_factor(lights, light[spot], -v[spot], big_r[spot])
    has_dir = vv > 0.0
    u = np.where(has_dir[:, None], v / np.where(has_dir, np.sqrt(vv), 1.0)[:, None], 0.0)
    sun = ltype == DIRECTIONAL
    e[sun] = lights.intensity[light[sun]]
    u[sun] = -lights.direction[light[sun]]
    return e, u


def residual_vectors(group: np.ndarray, e: np.ndarray, u: np.ndarray, rho: np.ndarray, n: int
                     ) -> np.ndarray:
    """DESIGN section 2, "Residual": per object, (a, b_x, b_y, b_z) = the sum over its
    competing lights of t = rho * E times (1, u_x, u_y, u_z), in float64, in the order of the
    pairs (ascending light id when they are sorted by light row). ``group``: each pair's
    object, as an index in 0..n-1, ascending. Returns (n, 4)."""
    t = rho * e
    return group_sum(group, np.column_stack([t, t * u[:, 0], t * u[:, 1], t * u[:, 2]]), n)


def residual_at(residual: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """What the shader adds to the diffuse irradiance (DESIGN section 2, "Residual"):
    max(0, a/4 + (b . n)/2) for each object's residual (a, b) (R, 4) at each of the sample
    normals n (M, 3): (R, M). For one light (a, b) = E (1, u) this is E times the band-0 and
    band-1 spherical-harmonic projection of max(0, n . u), clamped at 0."""
    res = np.asarray(residual, np.float64)
    nn = np.asarray(normals, np.float64)
    return np.maximum(0.0, res[:, :1] / 4 + (res[:, 1:] @ nn.T) / 2)


def directional_points(lights: Any, objects: Any, rows: np.ndarray, light_rows: np.ndarray,
                       points: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """Lighting of the directional light rows ``light_rows`` at the sample points of object
    rows ``rows``, each light only on objects whose mask it shares: (len(rows), M)."""
    out = np.zeros((rows.size, points.shape[1]))
    for lr in np.asarray(light_rows, np.int64):
        hit = (objects.mask[rows].astype(np.int64) & int(lights.mask[lr])) != 0
        if hit.any():
            out[hit] += light_at_points(lights, np.full(int(hit.sum()), lr), points[rows[hit]],
                                        normals)
    return out


def lighting_error(delivered: np.ndarray, all_lights: np.ndarray) -> tuple[float, float]:
    """DESIGN section 4, lighting error, over the sample points given: (sum |D - A|, sum A),
    D the delivered and A the all-lights lighting at each point. The error of a sequence is
    the first summed over its frames over the second summed over its frames."""
    d = np.asarray(delivered, np.float64)
    a = np.asarray(all_lights, np.float64)
    return float(np.abs(d - a).sum()), float(a.sum())


def abrupt_pops(d_now: np.ndarray, d_before: np.ndarray, a_now: np.ndarray,
                a_before: np.ndarray, share: float = POP_SHARE,
                scale: np.ndarray | None = None) -> np.ndarray:
    """DESIGN section 4, abrupt pops: True at each sample point where
    |(D_t - D_t-1) - (A_t - A_t-1)| > ``share`` * max(A_t, A_t-1), D the delivered and A the
    all-lights lighting, each frame's at that frame's positions (so a change of A that D
    follows, motion included, is not a pop; a ramp of 1/15 of A a frame is not; a one-frame
    jump of more than a tenth is). At a point unlit on both frames (A = 0) any change of D
    is a pop: DESIGN's threshold is then 0. ``scale`` (broadcast to the points) replaces
    max(A_t, A_t-1) as what ``share`` is taken of, for the report's diagnostic against the
    object's mean lighting; None is DESIGN's definition."""
    d_now, d_before = np.asarray(d_now, np.float64), np.asarray(d_before, np.float64)
    a_now, a_before = np.asarray(a_now, np.float64), np.asarray(a_before, np.float64)
    ref = np.maximum(a_now, a_before) if scale is None else scale
    return np.abs((d_now - d_before) - (a_now - a_before)) > share * ref


# =========================================================================== scenes


def camera_at(base: list[Camera], i: int, omega: float = ORBIT, dt: float = DT) -> list[Camera]:
    """The cameras of frame ``i``: ``base`` turned by omega * i * dt round the y axis."""
    a = omega * i * dt
    ca, sa = math.cos(a), math.sin(a)
    rot = np.array([[ca, 0.0, sa], [0.0, 1.0, 0.0], [-sa, 0.0, ca]])
    return [replace(c, position=rot @ np.asarray(c.position, float),
                    forward=rot @ np.asarray(c.forward, float)) for c in base]


PLAYER_SPEED = 5.0  # m/s: moving objects (stadium players) run round 5 m circles


def changes(scene: CityScene, motion: str, i: int) -> list[tuple[str, dict[str, np.ndarray]]]:
    """The scene changes of frame ``i`` (none on frame 0), as (SceneAPI method, fields).

    ``motion`` "lights": every light moves (``move_lights``: 3 m/s round 3 m circles).
    "objects": lights stay; every object with static = False moves its box the same way
    at PLAYER_SPEED round 5 m circles (the stadium's players and props). "both": the two.
    """
    if i == 0:
        return []
    if motion == "both":
        return changes(scene, "lights", i) + changes(scene, "objects", i)
    if motion == "lights":
        return [("update_lights", {"id": scene.lights["id"],
                                   "position": move_lights(scene.lights, i)})]
    static = np.asarray(scene.objects.get("static", np.zeros(scene.n_objects, bool)), bool)
    rows = np.flatnonzero(~static)
    lo, hi = scene.objects["bounds_min"][rows], scene.objects["bounds_max"][rows]
    centre = {"id": scene.objects["id"][rows], "position": (lo + hi) / 2}
    shift = move_lights(centre, i, speed=PLAYER_SPEED, circle=5.0) - centre["position"]
    return [("update_objects", {"id": centre["id"], "bounds_min": lo + shift,
                                "bounds_max": hi + shift})]


def apply_changes(s: Any, todo: list[tuple[str, dict[str, np.ndarray]]]) -> None:
    for op, fields in todo:
        getattr(s, op)(**fields)


def scene_mirror(scene: CityScene) -> SceneAPI:
    """The scene's stores without a scheduler: what the metrics read each frame."""
    mirror = SceneAPI()
    mirror.set_lights(**scene.lights)
    mirror.set_objects(**scene.objects)
    return mirror


def measured_subset(n: int, max_objects: int, seed: int) -> np.ndarray:
    """bool [n]: every object, or a seeded choice of ``max_objects`` of them."""
    subset = np.zeros(n, bool)
    if n <= max_objects:
        subset[:] = True
    else:
        subset[np.random.default_rng(seed).choice(n, max_objects, replace=False)] = True
    return subset


def lockstep(scene: CityScene, motion: str, mirror: SceneAPI, scheds: dict[tuple, Any],
             frames: int, seed: int, desc: str
             ) -> Iterator[tuple[np.ndarray, np.ndarray, list[Camera]]]:
    """Frame by frame: applies frame i's changes to the mirror and every scheduler, then
    yields (the sample points and normals of the mirror's boxes, the cameras)."""
    for i in tqdm(range(frames), desc=desc, unit="frame", file=sys.stderr, leave=False):
        todo = changes(scene, motion, i)
        for s in [mirror, *scheds.values()]:
            apply_changes(s, todo)
        points, normals = face_samples(mirror.objects.bounds_min, mirror.objects.bounds_max,
                                       seed=seed)
        yield points, normals, camera_at(scene.cameras, i)


@contextlib.contextmanager
def numba_threads(n: int) -> Iterator[None]:
    """Runs the block with ``n`` numba threads: the measurement passes (not timed) use one,
    so that a busy shared machine does not stall the parallel kernels at their barriers."""
    import numba

    old = numba.get_num_threads()
    numba.set_num_threads(min(n, old))
    try:
        yield
    finally:
        numba.set_num_threads(old)


def stadium_fallback(n_objects: int = 3000, n_lights: int = 600, seed: int = 0) -> CityScene:
    """A selection-heavy stadium, used when ``lightsched.scenes.stadium`` does not exist: a
    100 x 64 m field at the origin with half the objects on it (people and props, 0.3..0.6 m
    wide, 1.8 m tall) and half in stands round it (blocks 2..6 m, 2..25 m up); 85 % of the
    lights are floodlight spots on four corner masts (35..45 m up, range 140..180 m, outer
    angle 0.25..0.5 rad, aimed at random points of the field, intensity 50..100), the rest
    point lights over the field and stands (10..20 m up, range 30..60 m, intensity 5..30),
    and one sun. The camera is a broadcast camera 25 m up beside the field."""
    rng = np.random.default_rng(seed)
    n_field = n_objects // 2
    n_stand = n_objects - n_field
    centre = np.empty((n_objects, 3))
    half = np.empty((n_objects, 3))
    centre[:n_field, 0] = rng.uniform(-50, 50, n_field)
    centre[:n_field, 2] = rng.uniform(-32, 32, n_field)
    half[:n_field, 0] = rng.uniform(0.15, 0.3, n_field)
    half[:n_field, 2] = rng.uniform(0.15, 0.3, n_field)
    half[:n_field, 1] = 0.9
    centre[:n_field, 1] = 0.9
    ang = rng.uniform(0, 2 * math.pi, n_stand)
    dist = rng.uniform(1.15, 1.5, n_stand)
    centre[n_field:, 0] = 55 * dist * np.cos(ang)
    centre[n_field:, 2] = 37 * dist * np.sin(ang)
    centre[n_field:, 1] = rng.uniform(2, 25, n_stand)
    half[n_field:] = rng.uniform(1, 3, (n_stand, 3))
    oid = rng.permutation(2 * n_objects + 16)[:n_objects].astype(np.int32)
    objects = {"id": oid, "bounds_min": centre - half, "bounds_max": centre + half,
               "static": np.arange(n_objects) >= n_field}

    n_dir = 1
    n_spot = int(round(0.85 * (n_lights - n_dir)))
    n_point = n_lights - n_dir - n_spot
    ltype = np.concatenate([np.full(n_dir, DIRECTIONAL), np.full(n_spot, SPOT),
                            np.full(n_point, POINT)]).astype(np.uint8)
    pos = np.zeros((n_lights, 3))
    radius = np.full(n_lights, 1.0)
    direction = np.zeros((n_lights, 3))
    direction[:, 1] = -1.0
    outer = np.full(n_lights, math.pi / 4)
    intensity = np.ones(n_lights)
    direction[0] = np.array([0.4, -0.8, 0.3]) / np.linalg.norm([0.4, -0.8, 0.3])
    intensity[0] = 2.0
    s = slice(n_dir, n_dir + n_spot)
    mast = rng.integers(0, 4, n_spot)
    corner = np.stack([np.where(mast % 2 == 0, -62.0, 62.0), np.zeros(n_spot),
                       np.where(mast < 2, -44.0, 44.0)], 1)
    pos[s] = corner + rng.uniform(-3, 3, (n_spot, 3))
    pos[s, 1] = rng.uniform(35, 45, n_spot)
    target = np.stack([rng.uniform(-50, 50, n_spot), np.zeros(n_spot),
                       rng.uniform(-32, 32, n_spot)], 1)
    axis = target - pos[s]
    direction[s] = axis / np.linalg.norm(axis, axis=1)[:, None]
    radius[s] = rng.uniform(140, 180, n_spot)
    outer[s] = rng.uniform(0.25, 0.5, n_spot)
    intensity[s] = rng.uniform(50, 100, n_spot)
    p = slice(n_dir + n_spot, n_lights)
    ang = rng.uniform(0, 2 * math.pi, n_point)
    dist = rng.uniform(0, 1.4, n_point)
    pos[p, 0] = 55 * dist * np.cos(ang)
    pos[p, 2] = 37 * dist * np.sin(ang)
    pos[p, 1] = rng.uniform(10, 20, n_point)
    radius[p] = rng.uniform(30, 60, n_point)
    intensity[p] = rng.uniform(5, 30, n_point)
    lid = rng.permutation(2 * n_lights + 16)[:n_lights].astype(np.int32)
    lights = {"id": lid, "type": ltype, "position": pos, "radius": radius,
              "direction": direction, "outer_angle": outer, "intensity": intensity,
              "shadows": np.zeros(n_lights, np.bool_)}
    cam_pos = np.array([0.0, 25.0, -75.0])
    cam = Camera(position=cam_pos, forward=-cam_pos, up=np.array([0.0, 1.0, 0.0]),
                 fov_y=math.radians(50.0), aspect=16 / 9, near=0.5, far=1000.0)
    return CityScene(lights=lights, objects=objects, cameras=[cam], side=130.0, seed=seed,
                     params={"n_objects": n_objects, "n_lights": n_lights,
                             "generator": "bench/quality.py stadium_fallback"})


def stadium_scene(n_objects: int, n_lights: int, seed: int) -> tuple[CityScene, str]:
    """``lightsched.scenes.stadium`` when it exists, else ``stadium_fallback``; and a note
    saying which."""
    import lightsched.scenes as scenes

    gen = getattr(scenes, "stadium", None)
    if gen is None:
        return (stadium_fallback(n_objects, n_lights, seed),
                f"local fallback `bench/quality.py:stadium_fallback({n_objects}, {n_lights}, "
                f"seed={seed})` (lightsched.scenes.stadium did not exist)")
    return (gen(n_objects=n_objects, seed=seed, n_lights=n_lights),
            f"`lightsched.scenes.stadium({n_objects}, seed={seed}, n_lights={n_lights})`")


# =========================================================================== runs


@dataclass(frozen=True)
class Run:
    """A fast-path configuration: Config keywords and the grid cell (Tuning.cell_per_radius)."""

    name: str
    config: tuple[tuple[str, Any], ...] = ()
    cell: float = 1.0

    def make_config(self) -> Config:
        return Config(**dict(self.config))

    @property
    def key(self) -> tuple:
        return (tuple(sorted(self.make_config().to_dict().items())), self.cell)


def run(name: str, cell: float = 1.0, **kw: Any) -> Run:
    return Run(name, tuple(sorted(kw.items())), cell)


FADE_OFF = {"fade_in": 0.0, "fade_out": 0.0}
PURE = {"hysteresis": 0.0, **FADE_OFF}  # selection alone: every frame as if stateless

# (knob, value, run). The default Config appears in several knobs; it is run once.
KNOBS: list[tuple[str, str, Run]] = [
    ("precision", "exact", run("default")),
    ("precision", "fast", run("precision fast", precision="fast")),
    *[("grid cell / radius", f"{c:g}", run("default") if c == 1.0 else run(f"cell {c:g}", c))
      for c in (0.5, 1.0, 2.0, 4.0)],
    *[("K", str(k), run("default") if k == 8 else run(f"K {k}", max_lights=k))
      for k in (2, 4, 8, 16)],
    *[("hysteresis", f"{h:g}", run("default") if h == 0.1 else run(f"h {h:g}", hysteresis=h))
      for h in (0.0, 0.1, 0.3)],
    ("model", "contribution", run("default")),
    ("model", "thesis", run("thesis", model="thesis")),
    ("fade", "on (0.25 s)", run("default")),
    ("fade", "off", run("fade off", **FADE_OFF)),
]
POPPING_K = (8, 2)


def popping_runs() -> list[tuple[str, str, int, Run]]:
    """(fade, hysteresis, K, run): fade off/on x hysteresis 0/0.1 at each K of POPPING_K."""
    out = []
    for k in POPPING_K:
        kk = {} if k == 8 else {"max_lights": k}
        tag = "" if k == 8 else f"K {k}, "
        out += [("off", "0", k, run(f"{tag}fade off, h 0", **PURE, **kk)),
                ("off", "0.1", k, run(f"{tag}fade off", **FADE_OFF, **kk)),
                ("on (0.25 s)", "0", k, run(f"{tag}h 0", hysteresis=0.0, **kk)),
                ("on (0.25 s)", "0.1", k, run("default" if k == 8 else f"K {k}", **kk))]
    return out


POLICY_K = (4, 8)
POLICIES = ("nearest", "brightest", "thesis", "contribution")


def policy_runs() -> list[tuple[str, int, Run]]:
    """The two priority models as pure selections (hysteresis 0, no fade) at each K."""
    out = []
    for k in POLICY_K:
        out.append(("thesis", k, run(f"thesis K {k}, pure", model="thesis", max_lights=k, **PURE)))
        out.append(("contribution", k, run(f"contribution K {k}, pure", max_lights=k, **PURE)))
    return out


def distinct_runs(rows: list[Run]) -> dict[tuple, Run]:
    out: dict[tuple, Run] = {}
    for r in rows:
        out.setdefault(r.key, r)
    return out


@dataclass
class Acc:
    """Sums of one selection's metrics over a sequence."""

    chosen: float = 0.0
    best: float = 0.0
    all: float = 0.0
    ratios: list[np.ndarray] = field(default_factory=list)
    change: float = 0.0
    steps: float = 0.0
    pops: int = 0
    pop_objects: int = 0
    pop_total: float = 0.0
    missing: int = 0
    slots: int = 0
    prev: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None  # visible, index, weight
    differ_rows: int = 0  # rows differing from the run it must equal (grid cells)

    def add(self, table: LightingTable, rows: np.ndarray, visible: np.ndarray,
            light_index: np.ndarray, weight: np.ndarray, best: np.ndarray,
            all_l: np.ndarray) -> None:
        """One frame: ``rows`` are the measured visible object rows."""
        now, miss = table.selection(rows, light_index, weight)
        self.missing += miss
        self.slots += int((light_index[rows] >= 0).sum())
        self.chosen += float(now.sum())
        self.best += float(best[rows].sum())
        self.all += float(all_l[rows].sum())
        b = best[rows]
        self.ratios.append(now[b > 0] / b[b > 0])
        if self.prev is not None:
            pv, pli, pw = self.prev
            both = pv[rows]
            if both.any():
                before, _ = table.selection(rows[both], pli, pw)
                c, st, n_pop, t = popping(now[both], before, b[both])
                self.change += c
                self.steps += st
                self.pops += n_pop
                self.pop_objects += int(both.sum())
                self.pop_total += t
        self.prev = (visible.copy(), light_index.copy(), weight.copy())

    def result(self) -> dict[str, float]:
        ratios = np.concatenate(self.ratios) if self.ratios else np.zeros(0)
        return {"captured": self.chosen / self.best if self.best > 0 else 1.0,
                "captured_mean": float(ratios.mean()) if ratios.size else 1.0,
                "of_all": self.chosen / self.all if self.all > 0 else 1.0,
                "popping": self.change / self.pop_total if self.pop_total > 0 else 0.0,
                "steps": self.steps / self.pop_total if self.pop_total > 0 else 0.0,
                "pops": 1000 * self.pops / (self.pop_objects * DT) if self.pop_objects else 0.0,
                "missing": self.missing, "slots": self.slots, "object_frames": int(ratios.size),
                "differ_rows": self.differ_rows}


def new_scheduler(cls: type, r: Run, scene: CityScene) -> Any:
    """A scheduler of ``cls`` with the run's Config (and, a fast one, its grid cell)."""
    s = (cls(r.make_config(), Tuning(cell_per_radius=r.cell)) if cls is lightsched.Scheduler
         else cls(r.make_config()))
    s.set_lights(**scene.lights)
    s.set_objects(**scene.objects)
    return s


def metrics_pass(scene: CityScene, motion: str, runs: dict[tuple, Run], frames: int,
                 max_objects: int, seed: int, desc: str) -> dict[str, Any]:
    """Steps every run's fast Scheduler in lockstep over the animated sequence and measures
    captured lighting and popping of each, plus the nearest and brightest policies, on the
    visible objects of a fixed seeded subset of at most ``max_objects`` objects."""
    mirror = scene_mirror(scene)
    lights, objects = mirror.lights, mirror.objects
    n = len(objects)
    subset = measured_subset(n, max_objects, seed)
    scheds = {key: new_scheduler(lightsched.Scheduler, r, scene) for key, r in runs.items()}
    accs = {key: Acc() for key in runs}
    pol = {(p, k): Acc() for p in ("nearest", "brightest") for k in POLICY_K}
    ks = sorted({r.make_config().max_lights for r in runs.values()} | set(POLICY_K))
    base_of = {key: next((k2 for k2, r2 in runs.items() if r2.cell == 1.0
                          and r2.make_config() == r.make_config()), None)
               for key, r in runs.items()}
    plans: dict[tuple, dict[str, str]] = {}
    cand_mismatch = 0
    pairs_total = 0
    measured = 0
    for points, normals, cams in lockstep(scene, motion, mirror, scheds, frames, seed, desc):
        lights, objects = mirror.lights, mirror.objects
        out = {}
        for key, s in scheds.items():
            out[key] = s.frame(cams, dt=DT)
            plans[key] = dict(out[key].stats.get("plan", {}))
        f0 = next(iter(out.values()))
        visible = np.asarray(f0.visible)
        rows = np.flatnonzero(visible & subset)
        vis_l = np.searchsorted(lights.id, f0.visible_lights)
        o, lt = affecting_pairs(lights, objects, rows, vis_l)
        table = LightingTable(lights, points, normals, o, lt, n)
        pairs_total += o.size
        measured += rows.size
        counts = np.bincount(o, minlength=n)
        cand_mismatch += int(np.count_nonzero(counts[rows] != np.asarray(f0.candidates)[rows]))
        best = {k: table.best(k) for k in ks}
        all_l = table.all_lights()
        for key, f in out.items():
            k = runs[key].make_config().max_lights
            accs[key].add(table, rows, visible, np.asarray(f.light_index),
                          np.asarray(f.fade_weight, np.float64), best[k], all_l)
            base = base_of[key]
            if base is not None and base != key:
                fb = out[base]
                accs[key].differ_rows += int(np.count_nonzero(
                    np.any(f.light_ids != fb.light_ids, axis=1)
                    | np.any(f.fade_weight != fb.fade_weight, axis=1)))
        for p, keyf in (("nearest", nearest_key), ("brightest", brightest_key)):
            pkey = keyf(lights, objects, o, lt)
            for k in POLICY_K:
                li = table.top_by(pkey, k, (n, k))
                pol[(p, k)].add(table, rows, visible, li, (li >= 0).astype(np.float64),
                                best[k], all_l)
    return {"runs": {key: accs[key].result() for key in runs},
            "policies": {pk: a.result() for pk, a in pol.items()},
            "plans": plans, "candidate_mismatch": cand_mismatch,
            "pairs_per_object": pairs_total / max(measured, 1),
            "measured_objects": measured / max(frames, 1), "subset": int(subset.sum()),
            "frames": frames}


def timing_pass(scene: CityScene, motion: str, runs: dict[tuple, Run], frames: int, warmup: int,
                repeats: int, desc: str) -> dict[tuple, dict[str, float]]:
    """Scheduler.frame times of every run over the animated sequence (scene changes not
    timed): ``repeats`` passes, each with fresh schedulers stepped in lockstep, frame by frame,
    in an order rotated every frame, so every run sees the same minutes of a shared machine;
    ``warmup`` untimed frames first. Per run: the median over passes of the pass's median
    frame time ("ms"), the smallest and largest pass medians, and every timed frame in order
    ("frames_ms": the same frame of the same pass at the same index in every run, so two
    runs can be compared frame by frame)."""
    medians: dict[tuple, list[float]] = {key: [] for key in runs}
    every: dict[tuple, list[float]] = {key: [] for key in runs}
    keys = list(runs)
    bar = tqdm(total=repeats * (warmup + frames), desc=desc, unit="frame", file=sys.stderr,
               leave=False)
    for _ in range(repeats):
        scheds = {key: new_scheduler(lightsched.Scheduler, r, scene) for key, r in runs.items()}
        times: dict[tuple, list[float]] = {key: [] for key in runs}
        for i in range(warmup + frames):
            todo = changes(scene, motion, i)
            cams = camera_at(scene.cameras, i)
            for j in range(len(keys)):
                key = keys[(i + j) % len(keys)]
                s = scheds[key]
                apply_changes(s, todo)
                t0 = time.perf_counter()
                s.frame(cams, dt=DT)
                t = time.perf_counter() - t0
                if i >= warmup:
                    times[key].append(t)
            bar.update()
        for key in runs:
            medians[key].append(float(np.median(times[key])))
            every[key] += times[key]
    bar.close()
    return {key: {"ms": float(np.median(m)) * 1e3, "lo": min(m) * 1e3, "hi": max(m) * 1e3,
                  "frames_ms": np.array(every[key]) * 1e3}
            for key, m in medians.items()}


def oracle_pass(scene: CityScene, motion: str, runs: dict[tuple, Run], frames: int, desc: str
                ) -> dict[str, Any]:
    """Set error of each run's fast Scheduler against the oracle with the same Config (one
    oracle per distinct Config), in lockstep over the animated sequence. Differing objects
    are kept for the report, with both sets and the oracle-side priorities."""
    scheds = {key: new_scheduler(lightsched.Scheduler, r, scene) for key, r in runs.items()}
    oracles: dict[tuple, Any] = {}  # one oracle per distinct Config (the cell is not its)
    for r in runs.values():
        oracles.setdefault(r.key[0], new_scheduler(ref.Scheduler, r, scene))
    diff = {key: 0 for key in runs}
    vis_total = {key: 0 for key in runs}
    vis_mismatch = {key: 0 for key in runs}
    examples: list[str] = []
    oracle_ms: list[float] = []
    for i in tqdm(range(frames), desc=desc, unit="frame", file=sys.stderr, leave=False):
        todo = changes(scene, motion, i)
        for s in [*scheds.values(), *oracles.values()]:
            apply_changes(s, todo)
        cams = camera_at(scene.cameras, i)
        ref_frames = {}
        for cfg, s in oracles.items():
            t0 = time.perf_counter()
            ref_frames[cfg] = s.frame(cams, dt=DT)
            oracle_ms.append((time.perf_counter() - t0) * 1e3)
        for key, s in scheds.items():
            f = s.frame(cams, dt=DT)
            fr = ref_frames[runs[key].key[0]]
            vis = np.asarray(fr.visible)
            vis_mismatch[key] += int(np.count_nonzero(vis != np.asarray(f.visible)))
            _, d, nv = set_error(f.light_ids, fr.light_ids, vis)
            diff[key] += d
            vis_total[key] += nv
            if d and len(examples) < 8:
                bad = np.flatnonzero(vis & np.any(np.sort(f.light_ids, 1) != np.sort(fr.light_ids, 1), 1))
                for row in bad[:2]:
                    examples.append(
                        f"{runs[key].name}, frame {i}, object {int(fr.object_id[row])}: fast "
                        f"{sorted(int(x) for x in f.light_ids[row] if x >= 0)} "
                        f"oracle {sorted(int(x) for x in fr.light_ids[row] if x >= 0)} "
                        f"(oracle P {[float(x) for x in fr.priority[row][:fr.count[row]]]})")
    return {"set_error": {key: diff[key] / vis_total[key] if vis_total[key] else 0.0
                          for key in runs},
            "differ": diff, "visible": vis_total, "visibility_mismatch": vis_mismatch,
            "examples": examples, "oracle_ms": float(np.median(oracle_ms)) if oracle_ms else 0.0,
            "oracle_configs": len(oracles), "frames": frames}


# =========================================================================== residual study


RESIDUAL_K = (2, 4, 8)
FADES = ("no fade", "fade", "fade + hysteresis")
FADE_CONFIG = {"no fade": PURE, "fade": {"hysteresis": 0.0}, "fade + hysteresis": {}}


def residual_runs() -> list[tuple[str, bool, int, Run]]:
    """(fade, residual, K, run): no fade (hysteresis 0), fade (hysteresis 0) and fade +
    hysteresis (the default 0.1), each with the residual off and on, at each K of RESIDUAL_K;
    the rest of the Config is the default."""
    return [(fade, on, k, run(f"K {k}, {fade}, residual {'on' if on else 'off'}",
                              max_lights=k, residual=on, **FADE_CONFIG[fade]))
            for k in RESIDUAL_K for fade in FADES for on in (False, True)]


@dataclass
class FrameContext:
    """One frame's lighting that every run shares: the measured (visible, in the subset)
    object rows, ascending; the affecting pairs' lighting (``table``); the all-lights
    lighting at each sample point (``a_points``); the residual terms (E, u) of each affecting
    pair; and last frame's pairs with their terms at this frame's positions."""

    rows: np.ndarray
    normals: np.ndarray
    table: LightingTable
    a_points: np.ndarray  # (len(rows), M)
    e: np.ndarray  # (P,) per affecting pair, in the table's order
    u: np.ndarray  # (P, 3)
    group: np.ndarray  # (P,) each pair's object as an index into rows
    prev_group: np.ndarray  # last frame's pairs whose object is in rows: index into rows
    prev_keep: np.ndarray  # (P_prev,) bool: which of last frame's pairs those are
    prev_e: np.ndarray  # their terms at this frame's positions
    prev_u: np.ndarray
    a_prev: np.ndarray  # (N, M): last frame's a_points by object row (measured rows only)
    directional: Any  # callable: directional light rows -> (len(rows), M)
    best: dict[int, np.ndarray] = field(default_factory=dict)


@dataclass
class ResidualAcc:
    """One run's lighting error, abrupt pops and summed popping over a sequence (DESIGN
    section 4), the residual in the delivered lighting when the run's Config has it on."""

    residual: bool
    k: int
    err: float = 0.0
    all: float = 0.0
    object_frames: int = 0  # measured objects visible on this and the last frame
    pop_frames: int = 0  # of those, the ones with a point that pops
    pop_points: int = 0
    unlit_pop_frames: int = 0  # pop_frames whose popping points all have A = 0 on both frames
    mean_pop_frames: int = 0  # object-frames that pop against the object's mean A (diagnostic)
    steady_pop_frames: int = 0  # pop_frames where D held still at every popping point: A jumped
    change: float = 0.0
    total: float = 0.0
    residual_dev: float = 0.0  # max |numpy residual - frame's| / max(|a|, 1e-30)
    missing: int = 0
    d_prev: np.ndarray | None = None  # (N, M) last frame's delivered lighting by object row
    prev: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None = None

    def add(self, ctx: FrameContext, f: Any) -> None:
        """One frame of this run: ``f`` is its Scheduler.frame output."""
        rows, table = ctx.rows, ctx.table
        li = np.asarray(f.light_index, np.int64)
        w = np.asarray(f.fade_weight, np.float64)
        visible = np.asarray(f.visible)
        slots, miss = table.selection_points(rows, li, w)
        self.missing += miss
        # rho of each affecting pair: 1 - the weight of its light's slot (0 if none).
        occ = li[rows] >= 0
        pos, found = table.find(np.repeat(rows, occ.sum(1)), li[rows][occ])
        slot_w = np.zeros(table.obj.size)
        slot_w[pos[found]] = w[rows][occ][found]
        rho = 1.0 - slot_w
        frame_res = np.asarray(f.residual, np.float64)[rows]
        d = slots + ctx.directional(np.searchsorted(table.lights.id, f.directional_lights))
        if self.residual:
            d += residual_at(frame_res, ctx.normals)
            mine = residual_vectors(ctx.group, ctx.e, ctx.u, rho, rows.size)
            scale = np.maximum(np.abs(frame_res[:, :1]), 1e-30)
            if rows.size:
                self.residual_dev = max(self.residual_dev,
                                        float((np.abs(mine - frame_res) / scale).max()))
        err, a_sum = lighting_error(d, ctx.a_points)
        self.err += err
        self.all += a_sum
        if self.d_prev is None:
            self.d_prev = np.zeros((visible.size, d.shape[1]))
        if self.prev is not None:
            pv, pli, pw, prho = self.prev
            both = pv[rows]
            if both.any():
                rb = rows[both]
                before, _ = table.selection(rb, pli, pw)
                now = slots[both].sum(1)
                if self.residual:
                    now = now + residual_at(mine[both], ctx.normals).sum(1)
                    old = residual_vectors(ctx.prev_group, ctx.prev_e, ctx.prev_u,
                                           prho[ctx.prev_keep], rows.size)
                    before = before + residual_at(old[both], ctx.normals).sum(1)
                if self.k not in ctx.best:
                    ctx.best[self.k] = table.best(self.k)
                c, _, _, t = popping(now, before, ctx.best[self.k][rb])
                self.change += c
                self.total += t
                a_before = ctx.a_prev[rb]
                pops = abrupt_pops(d[both], self.d_prev[rb], ctx.a_points[both], a_before)
                lit = np.maximum(ctx.a_points[both], a_before) > 0.0
                popped = pops.any(1)
                self.object_frames += int(both.sum())
                self.pop_frames += int(popped.sum())
                self.pop_points += int(pops.sum())
                self.unlit_pop_frames += int((popped & ~(pops & lit).any(1)).sum())
                d_jump = np.abs(d[both] - self.d_prev[rb]) > POP_SHARE * np.maximum(
                    ctx.a_points[both], a_before)
                self.steady_pop_frames += int((popped & ~(pops & d_jump).any(1)).sum())
                mean_a = np.maximum(ctx.a_points[both], a_before).mean(1, keepdims=True)
                self.mean_pop_frames += int(abrupt_pops(
                    d[both], self.d_prev[rb], ctx.a_points[both], a_before,
                    scale=mean_a).any(1).sum())
        self.d_prev[rows] = d
        self.prev = (visible.copy(), li.copy(), w.copy(), rho)

    def result(self) -> dict[str, float]:
        seconds = self.object_frames * DT
        return {"error": self.err / self.all if self.all > 0 else 0.0,
                "pops": 1000 * self.pop_frames / seconds if seconds else 0.0,
                "unlit_pops": 1000 * self.unlit_pop_frames / seconds if seconds else 0.0,
                "steady_pops": 1000 * self.steady_pop_frames / seconds if seconds else 0.0,
                "mean_pops": 1000 * self.mean_pop_frames / seconds if seconds else 0.0,
                "pop_points": self.pop_points, "object_frames": self.object_frames,
                "popping": self.change / self.total if self.total > 0 else 0.0,
                "residual_dev": self.residual_dev, "missing": self.missing}


def residual_pass(scene: CityScene, motion: str, runs: dict[tuple, Run], frames: int,
                  max_objects: int, seed: int, desc: str) -> dict[str, Any]:
    """Steps every run's fast Scheduler in lockstep over the animated sequence and measures
    the lighting error, abrupt pops and summed popping of each (``ResidualAcc``) on the
    visible objects of a fixed seeded subset of at most ``max_objects`` objects."""
    mirror = scene_mirror(scene)
    n = len(mirror.objects)
    subset = measured_subset(n, max_objects, seed)
    scheds = {key: new_scheduler(lightsched.Scheduler, r, scene) for key, r in runs.items()}
    accs = {key: ResidualAcc(r.make_config().residual, r.make_config().max_lights)
            for key, r in runs.items()}
    m = 6 * SAMPLES_PER_FACE
    a_prev = np.zeros((n, m))
    prev_pairs: tuple[np.ndarray, np.ndarray] | None = None
    cand_mismatch = pairs_total = measured = 0
    sun_share = [0.0, 0.0]  # directional lighting in A, all of A
    for points, normals, cams in lockstep(scene, motion, mirror, scheds, frames, seed, desc):
        lights, objects = mirror.lights, mirror.objects
        out = {key: s.frame(cams, dt=DT) for key, s in scheds.items()}
        f0 = next(iter(out.values()))
        rows = np.flatnonzero(np.asarray(f0.visible) & subset)
        vis_l = np.searchsorted(lights.id, f0.visible_lights)
        o, lt = affecting_pairs(lights, objects, rows, vis_l)
        table = LightingTable(lights, points, normals, o, lt, n)
        pairs_total += o.size
        measured += rows.size
        counts = np.bincount(o, minlength=n)
        cand_mismatch += int(np.count_nonzero(counts[rows] != np.asarray(f0.candidates)[rows]))
        e, u = residual_terms(lights, objects, o, lt)
        cache: dict[bytes, np.ndarray] = {}

        def directional(light_rows: np.ndarray, rows: np.ndarray = rows, cache: dict = cache,
                        points: np.ndarray = points, normals: np.ndarray = normals,
                        lights: Any = lights, objects: Any = objects) -> np.ndarray:
            key = np.asarray(light_rows, np.int64).tobytes()
            if key not in cache:
                cache[key] = directional_points(lights, objects, rows, light_rows, points,
                                                normals)
            return cache[key]

        suns = np.flatnonzero(lights.type == DIRECTIONAL)
        a_dir = directional(suns)
        a_points = table.all_lights_points(rows) + a_dir
        sun_share[0] += float(a_dir.sum())
        sun_share[1] += float(a_points.sum())
        if prev_pairs is None:
            prev_keep = np.zeros(0, bool)
            po = pl = np.zeros(0, np.int64)
        else:
            po_all, pl_all = prev_pairs
            prev_keep = np.isin(po_all, rows)
            po, pl = po_all[prev_keep], pl_all[prev_keep]
        pos, found = table.find(po, pl)
        prev_e, prev_u = np.zeros(po.size), np.zeros((po.size, 3))
        prev_e[found], prev_u[found] = e[pos[found]], u[pos[found]]
        if not found.all():
            prev_e[~found], prev_u[~found] = residual_terms(lights, objects, po[~found],
                                                            pl[~found])
        ctx = FrameContext(rows, normals, table, a_points, e, u, np.searchsorted(rows, o),
                           np.searchsorted(rows, po), prev_keep, prev_e, prev_u, a_prev,
                           directional)
        for key, f in out.items():
            accs[key].add(ctx, f)
        a_prev[rows] = a_points
        prev_pairs = (o, lt)
    return {"runs": {key: a.result() for key, a in accs.items()},
            "candidate_mismatch": cand_mismatch,
            "pairs_per_object": pairs_total / max(measured, 1),
            "measured_objects": measured / max(frames, 1), "subset": int(subset.sum()),
            "sun_share": sun_share[0] / sun_share[1] if sun_share[1] > 0 else 0.0,
            "frames": frames}


def paired_cost(timing: dict[tuple, dict[str, Any]], on: Run, off: Run) -> tuple[float, float]:
    """The residual's cost from one timing pass: the median over frames of (on - off) frame
    time of the same frame (ms), and that over the off run's median, as a share."""
    t_on, t_off = timing[on.key]["frames_ms"], timing[off.key]["frames_ms"]
    diff = float(np.median(t_on - t_off))
    return diff, diff / timing[off.key]["ms"] if timing[off.key]["ms"] > 0 else 0.0


def big_frame_cost(n: int, n_lights: int, k: int, frames: int) -> dict[str, float]:
    """The residual's cost on a full city frame of (n, n_lights) at K = k: the child of
    bench/residual_cost.py (two Schedulers, residual on and off, every light moving,
    interleaved and paired) in a process of its own, on the native numba target."""
    import json
    import subprocess
    from pathlib import Path

    script = Path(__file__).resolve().parent / "residual_cost.py"
    load0 = os.getloadavg()[0]
    done = subprocess.run([sys.executable, str(script), "--child", str(n), str(n_lights), str(k),
                           str(frames)], capture_output=True, text=True, check=True)
    # The share depends on the machine's load: contention stretches the whole frame more
    # than the residual's pass, so the load goes beside the figure.
    return {**json.loads(done.stdout.strip().splitlines()[-1]), "load": (load0, os.getloadavg()[0])}


# =========================================================================== study


@dataclass
class SceneSpec:
    label: str
    big: CityScene
    small: CityScene
    note_big: str
    note_small: str
    max_objects: int  # objects the lighting metrics look at (a seeded subset beyond)
    frames: int  # of the animated sequence, for captured lighting and popping
    time_frames: int  # timed frames per run
    oracle_frames: int  # frames of the set-error comparison
    motion: str  # "lights" or "objects", see ``changes``


def pareto(points: list[tuple[float, ...]]) -> list[bool]:
    """True for the points no other point dominates (every coordinate <=, one <)."""
    out = []
    for i, p in enumerate(points):
        dominated = any(all(a <= b for a, b in zip(q, p, strict=True))
                        and any(a < b for a, b in zip(q, p, strict=True))
                        for j, q in enumerate(points) if j != i)
        out.append(not dominated)
    return out


def study(spec: SceneSpec, args: argparse.Namespace) -> dict[str, Any]:
    say(f"\n== {spec.label}: {spec.note_big}")
    knob_runs = [r for _, _, r in KNOBS]
    pop_runs = [r for _, _, _, r in popping_runs()]
    pol_runs = [r for _, _, r in policy_runs()]
    runs = distinct_runs(knob_runs + pop_runs + pol_runs)
    t0 = time.perf_counter()
    with numba_threads(1):
        metrics = metrics_pass(spec.big, spec.motion, runs, spec.frames, spec.max_objects,
                               args.seed, f"{spec.label} metrics")
    say(f"   metrics: {len(runs)} fast-path runs in lockstep, {spec.frames} frames, "
        f"{metrics['measured_objects']:.0f} measured visible objects per frame (subset of "
        f"{metrics['subset']}), {metrics['pairs_per_object']:.1f} affecting lights per object "
        f"({time.perf_counter() - t0:.1f} s)")
    if metrics["candidate_mismatch"]:
        say(f"   !! {metrics['candidate_mismatch']} (frame, object) rows where the numpy "
            "Affects count differs from the fast path's candidates")
    outside = sum(m["missing"] for m in metrics["runs"].values())
    metrics["outside"] = outside
    if outside:
        say(f"   !! {outside} slot lights are not among the numpy affecting lights of their object")
    t0 = time.perf_counter()
    timing_keys = distinct_runs(knob_runs + pop_runs)
    load0 = os.getloadavg()[0]
    timing = timing_pass(spec.big, spec.motion, timing_keys, spec.time_frames, args.warmup,
                         args.runs, f"{spec.label} timing")
    load = (load0, os.getloadavg()[0])
    say(f"   timing: {len(timing)} runs x {args.runs} x {spec.time_frames} frames "
        f"({time.perf_counter() - t0:.1f} s; 1-minute load average {load[0]:.2f} before, "
        f"{load[1]:.2f} after, {os.cpu_count()} CPUs)")
    t0 = time.perf_counter()
    oracle_keys = distinct_runs(knob_runs)
    with numba_threads(1):
        oracle = oracle_pass(spec.small, spec.motion, oracle_keys, spec.oracle_frames,
                             f"{spec.label} oracle")
    say(f"   oracle: {oracle['oracle_configs']} oracle configs x {spec.oracle_frames} frames on "
        f"{spec.note_small}, {oracle['oracle_ms']:.0f} ms per oracle frame "
        f"({time.perf_counter() - t0:.1f} s)")
    for e in oracle["examples"]:
        say(f"   !! set differs: {e}")
    vis_bad = sum(oracle["visibility_mismatch"].values())
    if vis_bad:
        say(f"   !! {vis_bad} (frame, object) rows where fast and oracle visibility differ")
    return {"spec": spec, "runs": runs, "metrics": metrics, "timing": timing, "oracle": oracle,
            "load": load}


def knob_rows(res: dict[str, Any]) -> list[dict[str, Any]]:
    rows = []
    for knob, value, r in KNOBS:
        m = res["metrics"]["runs"][r.key]
        rows.append({"knob": knob, "value": value, "run": r, "ms": res["timing"][r.key]["ms"],
                     "set_error": res["oracle"]["set_error"][r.key], **m,
                     "plan": res["metrics"]["plans"][r.key].get("priority", "")})
    # Pareto over the distinct runs: time, lighting lost against all affecting lights, popping.
    distinct = list({row["run"].key: row for row in rows}.values())
    front2 = pareto([(d["ms"], 1 - d["of_all"]) for d in distinct])
    front3 = pareto([(d["ms"], 1 - d["of_all"], d["popping"]) for d in distinct])
    mark = {d["run"].key: (a, b) for d, a, b in zip(distinct, front2, front3, strict=True)}
    for row in rows:
        row["front2"], row["front3"] = mark[row["run"].key]
    return rows


def pct(x: float, digits: int = 2) -> str:
    return f"{100 * x:.{digits}f}%"


def per_s(x: float) -> str:
    """A per-frame share of the lighting as percent of the lighting per second."""
    return f"{100 * x / DT:.3f}"


def knob_table(res: dict[str, Any]) -> list[str]:
    head = ["knob", "value", "frame ms", "set error", "captured (sum)", "captured (mean)",
            "of all lights", "popping %/s", "in steps %/s", "pops / 1000 obj-s", "front: time, lost",
            "front: + popping"]
    out = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for row in knob_rows(res):
        cells = [row["knob"], row["value"], f"{row['ms']:.2f}", pct(row["set_error"]),
                 pct(row["captured"]), pct(row["captured_mean"]), pct(row["of_all"]),
                 per_s(row["popping"]), per_s(row["steps"]), f"{row['pops']:.2f}",
                 "*" if row["front2"] else "", "*" if row["front3"] else ""]
        out.append("| " + " | ".join(cells) + " |")
    return out


def policy_rows(res: dict[str, Any]) -> list[dict[str, Any]]:
    out = []
    runs = {(p, k): r for p, k, r in policy_runs()}
    for k in POLICY_K:
        for p in POLICIES:
            m = (res["metrics"]["policies"][(p, k)] if p in ("nearest", "brightest")
                 else res["metrics"]["runs"][runs[(p, k)].key])
            out.append({"policy": p, "k": k, **m})
    return out


POLICY_NOTE = {
    "nearest": "nearest to the object's centre (Ogre, Bateman)",
    "brightest": "intensity / (1 + 25 d^2 / r^2) at the centre (Unity built-in)",
    "thesis": "Eriksson eq. 3.1, `Config(model=\"thesis\")`",
    "contribution": "`Config(model=\"contribution\")`",
}


def policy_table(res: dict[str, Any]) -> list[str]:
    head = ["K", "policy", "captured (sum)", "captured (mean)", "of all lights", "popping %/s",
            "in steps %/s", "pops / 1000 obj-s"]
    out = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for row in policy_rows(res):
        out.append(f"| {row['k']} | {POLICY_NOTE[row['policy']]} | {pct(row['captured'])} | "
                   f"{pct(row['captured_mean'])} | {pct(row['of_all'])} | "
                   f"{per_s(row['popping'])} | {per_s(row['steps'])} | {row['pops']:.2f} |")
    return out


def popping_rows(res: dict[str, Any]) -> list[dict[str, Any]]:
    out = []
    for fade, h, k, r in popping_runs():
        out.append({"fade": fade, "h": h, "k": k, "ms": res["timing"][r.key]["ms"],
                    **res["metrics"]["runs"][r.key]})
    return out


def popping_table(res: dict[str, Any]) -> list[str]:
    head = ["K", "fade", "hysteresis", "popping %/s", "in steps %/s", "pops / 1000 obj-s",
            "captured (sum)",
            "of all lights", "frame ms"]
    out = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for row in popping_rows(res):
        out.append(f"| {row['k']} | {row['fade']} | {row['h']} | {per_s(row['popping'])} | "
                   f"{per_s(row['steps'])} | {row['pops']:.2f} | {pct(row['captured'])} | "
                   f"{pct(row['of_all'])} | "
                   f"{row['ms']:.2f} |")
    return out


def print_tables(res: dict[str, Any]) -> None:
    label = res["spec"].label
    for title, lines in (("knobs", knob_table(res)), ("policies", policy_table(res)),
                         ("popping (fade x hysteresis)", popping_table(res))):
        say(f"\n   {label}: {title}")
        for line in lines:
            say("   " + line)


def answers(res: dict[str, Any]) -> dict[str, Any]:
    """The numbers the prose quotes."""
    rows = knob_rows(res)
    by = {(r["knob"], r["value"]): r for r in rows}
    exact, fast = by[("precision", "exact")], by[("precision", "fast")]
    pol = {(r["policy"], r["k"]): r for r in policy_rows(res)}
    pops = {(r["fade"], r["h"], r["k"]): r for r in popping_rows(res)}
    winner = {k: max(POLICIES, key=lambda p, k=k: pol[(p, k)]["captured"]) for k in POLICY_K}
    grid = [by[("grid cell / radius", f"{c:g}")] for c in (0.5, 1.0, 2.0, 4.0)]
    return {"exact": exact, "fast": fast, "pol": pol, "winner": winner, "pops": pops,
            "grid": grid, "fast_plan": fast["plan"]}


def prose(res: dict[str, Any]) -> list[str]:
    a = answers(res)
    label = res["spec"].label
    e, f = a["exact"], a["fast"]
    out = []
    same = abs(e["captured"] - f["captured"]) < 1e-12 and abs(e["popping"] - f["popping"]) < 1e-12
    out.append(
        f"- {label}, precision: exact {e['ms']:.2f} ms/frame, set error {pct(e['set_error'])}, "
        f"captured {pct(e['captured'])}; \"fast\" {f['ms']:.2f} ms/frame, set error "
        f"{pct(f['set_error'])}, captured {pct(f['captured'])}"
        + (" (identical lighting figures)" if same else "")
        + f". \"fast\" runs \"{a['fast_plan']}\": {100 * (f['ms'] / e['ms'] - 1):+.0f}% run "
        "time against exact in this run.")
    grid = a["grid"]
    differ = sum(g["differ_rows"] for g in grid)
    out.append(
        f"- {label}, grid cell / radius 0.5, 1, 2, 4: "
        + ", ".join(f"{g['ms']:.2f}" for g in grid)
        + f" ms/frame; set error {', '.join(pct(g['set_error']) for g in grid)}; "
        f"{differ} (frame, object) rows differ from cell 1 in light_ids or fade_weight "
        "(exact, as required).")
    for k in POLICY_K:
        pol = a["pol"]
        w = a["winner"][k]
        ranked = sorted(POLICIES, key=lambda p, k=k: -pol[(p, k)]["captured"])
        out.append(
            f"- {label}, K = {k}: {w} captures the most lighting ("
            + ", ".join(f"{p} {pct(pol[(p, k)]['captured'])}" for p in ranked)
            + " of the best K; of all affecting lights "
            + ", ".join(f"{p} {pct(pol[(p, k)]['of_all'])}" for p in ranked) + ").")
    p = a["pops"]

    def cut(x: float, y: float) -> str:
        if x <= 0:
            return "n/a (0 without either)"
        return f"{100 * (y / x - 1):+.0f}%"

    def least(p: dict, k: int, what: str) -> str:
        rows = [(v[what], f"fade {f.split(' ')[0]}, h {h}") for (f, h, kk), v in p.items() if kk == k]
        low = min(v for v, _ in rows)
        best = [name for v, name in rows if v <= low * (1 + 1e-9) + 1e-15]
        return "all four rows alike" if len(best) == len(rows) else " and ".join(best)

    for k in POPPING_K:
        off0, off1 = p[("off", "0", k)], p[("off", "0.1", k)]
        on0, on1 = p[("on (0.25 s)", "0", k)], p[("on (0.25 s)", "0.1", k)]
        out.append(
            f"- {label}, popping at K = {k}: with neither fade nor hysteresis "
            f"{per_s(off0['popping'])} % of the lighting per second changes through set and "
            f"weight changes, {per_s(off0['steps'])} %/s of it in one-frame steps above "
            f"{pct(POP_STEP, 0)} ({off0['pops']:.2f} pops per 1000 object-seconds). Summed "
            f"popping against neither: hysteresis 0.1 alone {cut(off0['popping'], off1['popping'])}, fade "
            f"alone {cut(off0['popping'], on0['popping'])}, both "
            f"{cut(off0['popping'], on1['popping'])}. Pops: hysteresis alone "
            f"{cut(off0['pops'], off1['pops'])}, fade alone {cut(off0['pops'], on0['pops'])}, "
            f"both {cut(off0['pops'], on1['pops'])}. Least summed popping: "
            f"{least(p, k, 'popping')}; fewest pops: {least(p, k, 'pops')}. Captured "
            f"lighting {pct(off0['captured'])} without either, {pct(on1['captured'])} with both.")
    return out


def plot(results: list[dict[str, Any]], path: Any) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(len(results), 2, figsize=(12, 4.8 * len(results)), squeeze=False)
    for row_axes, res in zip(axes, results, strict=True):
        rows = list({r["run"].key: r for r in knob_rows(res)}.values())
        labels = {}
        for r in knob_rows(res):
            labels.setdefault(r["run"].key, []).append(f"{r['knob']}={r['value']}")
        for ax, (ylab, yfun, front) in zip(row_axes, (
                ("lighting lost vs all affecting lights (%)", lambda r: 100 * (1 - r["of_all"]),
                 "front2"),
                ("popping (% of the lighting per second)", lambda r: 100 * r["popping"] / DT,
                 None)),
                strict=True):
            xs = np.array([r["ms"] for r in rows])
            ys = np.array([yfun(r) for r in rows])
            if front is None:
                mask = pareto([(x, y) for x, y in zip(xs, ys, strict=True)])
            else:
                mask = [r[front] for r in rows]
            mask = np.array(mask)
            ax.scatter(xs[~mask], ys[~mask], c="tab:gray", label="dominated")
            ax.scatter(xs[mask], ys[mask], c="tab:red", label="Pareto-optimal")
            order = np.argsort(xs[mask])
            ax.step(xs[mask][order], ys[mask][order], where="post", c="tab:red", lw=0.8)
            for r, x, y in zip(rows, xs, ys, strict=True):
                ax.annotate(labels[r["run"].key][-1], (x, y), fontsize=7,
                            xytext=(3, 3), textcoords="offset points")
            if ys.max() > 100 * max(ys.min(), 1e-3):
                ax.set_yscale("symlog", linthresh=0.01)
            ax.set_xlabel("Scheduler.frame median (ms)")
            ax.set_ylabel(ylab)
            ax.set_title(f"{res['spec'].label}: frame time vs {ylab.split(' (')[0]}", fontsize=10)
            ax.grid(alpha=0.3)
            ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def in_short(results: list[dict[str, Any]]) -> list[str]:
    """The three answers the section owes, one bullet each, from the figures."""
    prec, pol, pop = [], [], []
    for res in results:
        a, label = answers(res), res["spec"].label
        e, f = a["exact"], a["fast"]
        prec.append(f"{label} {e['ms']:.2f} vs {f['ms']:.2f} ms/frame, set error "
                    f"{pct(e['set_error'])} vs {pct(f['set_error'])}, captured "
                    f"{pct(e['captured'])} vs {pct(f['captured'])}")
        for k in POLICY_K:
            ranked = sorted(POLICIES, key=lambda p, k=k: -a["pol"][(p, k)]["captured"])
            pol.append(f"{label} K = {k}: " + ", ".join(
                f"{p} {pct(a['pol'][(p, k)]['captured'], 1)}" for p in ranked))
        by = {(r["knob"], r["value"]): r for r in knob_rows(res)}
        h1, h3 = by[("hysteresis", "0.1")], by[("hysteresis", "0.3")]
        for k in POPPING_K:
            p = a["pops"]
            off0, off1 = p[("off", "0", k)], p[("off", "0.1", k)]
            on0, on1 = p[("on (0.25 s)", "0", k)], p[("on (0.25 s)", "0.1", k)]
            pop.append(f"{label} K = {k}: summed popping {per_s(off0['popping'])} %/s with "
                       f"neither, {per_s(off1['popping'])} with hysteresis 0.1, "
                       f"{per_s(on0['popping'])} with fade, {per_s(on1['popping'])} with both; "
                       f"pops per 1000 object-s {off0['pops']:.1f}, {off1['pops']:.1f}, "
                       f"{on0['pops']:.1f}, {on1['pops']:.1f}")
        pop.append(f"{label} K = 8, hysteresis 0.3 instead of 0.1 (fade on): summed popping "
                   f"{per_s(h1['popping'])} -> {per_s(h3['popping'])} %/s, captured "
                   f"{pct(h1['captured'])} -> {pct(h3['captured'])}")
    winners = {answers(res)["winner"][k] for res in results for k in POLICY_K}
    return [
        "**Answer (exact vs fast precision):** \"fast\" keeps the object records in float32 "
        "relative to the first camera (the arithmetic stays float64); exact vs fast: "
        + "; ".join(prec) + ". Rounding the coordinates to float32 moves the set error and "
        "the captured lighting by the amounts shown; it does not make the frame faster, "
        "because the light pass is bound by its walk over the grid and its branches, not by "
        "the bytes of the records (bench/RESULTS.md, issue 6 notes).",
        "**Answer (policy that captures the most lighting):** "
        + (f"{winners.pop()} in every case" if len(winners) == 1
           else "it depends: " + ", ".join(sorted(winners)))
        + " (captured, of the best K: " + "; ".join(pol) + ").",
        "**Answer (fade and hysteresis against popping):** (rows: neither / hysteresis 0.1 / fade "
        "0.25 s / both): " + "; ".join(pop) + ". Hysteresis cuts the summed popping and the "
        "pops; fade removes the one-frame pops but raises the summed change (see the note "
        "below).",
    ]


def popping_note(results: list[dict[str, Any]]) -> str:
    """What the popping figures mean, with the cases where fade raised the summed popping."""
    raised = []
    for res in results:
        p = answers(res)["pops"]
        for k in POPPING_K:
            off0, on0 = p[("off", "0", k)], p[("on (0.25 s)", "0", k)]
            if off0["popping"] > 0 and on0["popping"] > off0["popping"]:
                raised.append(f"{res['spec'].label} K = {k}: x{on0['popping'] / off0['popping']:.1f}")
    text = ("Note on popping. The summed absolute change is blind to how fast a change happens: "
            "a light fading in over 15 frames changes the lighting by E/15 a frame, 15 times, "
            "the same total E as a one-frame switch; fade lowers the sum only where a set flips "
            "back before the fade completes, and shows in the steps and pops instead. It is also "
            "taken per object, so an instant swap of two lights of equal total lighting counts "
            "as almost nothing even where they light different faces.")
    if raised:
        text += (" Fade without hysteresis raised the summed popping here (" + "; ".join(raised)
                 + "). Two reasons. Weight ramps are changes too: a light that enters an "
                 "object's range starts at zero lighting (the windowed falloff), so switching it "
                 "on at once costs nothing, while fading it in adds the ramp. And with all K "
                 "slots taken, a light that lost selection keeps its slot while it fades out "
                 "and the newly selected light waits for that slot (DESIGN section 2, Fade: "
                 "\"with no free slot they wait\"), so a swap of lights E_out -> E_in becomes a "
                 "dip and a recovery (E_out + E_in summed) instead of a cross-fade "
                 "(|E_in - E_out|); the second happens only where K binds (K = 2, the stadium). "
                 "Hysteresis suppresses the swaps between nearly equal lights that fade turns into dips.")
    return text


def render(results: list[dict[str, Any]], rres: list[dict[str, Any]],
           big: dict[str, float] | None, checks: list[dict[str, Any]],
           args: argparse.Namespace) -> str:
    m = machine()
    cmd = "python bench/quality.py" + ("" if len(sys.argv) < 2 else " " + shlex.join(sys.argv[1:]))
    out = [BEGIN, "", "### Quality: time against error, policies, popping (`bench/quality.py`)", "",
           f"Generated {time.strftime('%Y-%m-%d %H:%M %Z')} by `{cmd}` at commit "
           f"`{git_commit()}`.", "",
           f"Machine: {m['cpu']}, {m['nproc']} CPUs ({m['numba_threads']} numba threads), "
           f"{m['os']}; Python {m['python']}, numpy {m['numpy']}, numba {m['numba']}.", "",
           "Method. Every scene is animated, dt = 1/60 s, the camera orbiting the vertical axis "
           f"through the origin at {ORBIT} rad/s; in the city every light moves "
           "(`lightsched.scenes.move_lights`: 3 m/s round 3 m circles); in the stadium the "
           f"floodlights stay and the players and props (static = False) run {PLAYER_SPEED:g} m/s "
           "round 5 m circles. Errors as DESIGN section 4: **set error** = share of visible "
           "objects whose light set (slot ids as a set, fading-out slots included) differs from "
           "`lightsched.reference.Scheduler` with the same Config, on a small copy of the scene; "
           "**captured** = lighting delivered by the slots (weighted by fade_weight) over that "
           f"of the best K affecting lights, at {6 * SAMPLES_PER_FACE} seeded points per object "
           f"({SAMPLES_PER_FACE} per box face on a jittered 2x2 grid, face normals): Lambert "
           "max(0, n.L) x intensity x w^2/(d2 + r0^2) with q = d2/r^2 from the point (x the "
           "spot factor of the point's angle from the axis); \"sum\" = sum over sum over all "
           "measured (frame, object) pairs, \"mean\" = mean of per-object ratios (objects with "
           "some lighting); **of all lights** = the same over every affecting light (what "
           "unlimited slots would show: the error K trades against; the Pareto fronts use "
           "1 - this); **popping** = sum over frames and objects (visible on both frames) of "
           "|lighting of this frame's slots and weights - lighting of last frame's slots and "
           "weights|, both at this frame's light and object positions, over the total "
           "lighting, given "
           "per second (the per-frame share x 60); **in steps** = the same sum over only the "
           f"one-frame changes larger than {pct(POP_STEP, 0)} of the object's best-K lighting "
           "(a 0.25 s fade moves at most 1/15 of one light per frame, below that); **pops** = "
           "the number of such steps per 1000 object-seconds. "
           "Directional lights are left out of every lighting figure (they take no slot: the "
           "renderer applies each to every object, so they are equal on both sides of each "
           "ratio). Affecting lights come from a numpy Affects test written from DESIGN "
           "section 2 (compared with the fast path's `candidates` every frame). Frame times: "
           f"`Scheduler.frame` medians: {args.runs} pass(es), each stepping fresh schedulers of "
           "every row in lockstep (the order rotated every frame, so all rows share the same "
           f"minutes of a shared machine) after {args.warmup} warm-up frame(s); the median of "
           "the pass medians. \"front\" marks rows on the Pareto front of "
           "(frame time, lighting lost against all lights) and of (time, lost, popping).", ""]
    for res in results:
        spec, met, orc = res["spec"], res["metrics"], res["oracle"]
        out += [f"#### {spec.label}", "",
                f"Timing and lighting scene: {spec.note_big}, {met['frames']} frames "
                f"({spec.time_frames} timed per run); errors measured on "
                f"{met['measured_objects']:.0f} visible objects per frame on average "
                + (f"(a seeded subset of {met['subset']} objects), " if met["subset"] < spec.big.n_objects
                   else "(all), ")
                + f"{met['pairs_per_object']:.1f} affecting lights per object. 1-minute load "
                f"average while timing: {res['load'][0]:.2f} .. {res['load'][1]:.2f} on "
                f"{os.cpu_count()} CPUs. Set-error scene: "
                f"{spec.note_small}, {orc['frames']} frames, {orc['oracle_ms']:.0f} ms per "
                "oracle frame. "
                f"Numpy Affects vs fast-path candidates: {met['candidate_mismatch']} differing "
                f"(frame, object) rows; slot lights outside the numpy affecting set: "
                f"{met['outside']}; objects whose visibility differs between fast path and "
                f"oracle: {sum(orc['visibility_mismatch'].values())}.", ""]
        if orc["examples"]:
            out += ["Fast path and oracle disagree (reported, not hidden):", ""]
            out += [f"- {e}" for e in orc["examples"]] + [""]
        out += ["Knobs (K = 8, default Config but for the knob):", ""] + knob_table(res) + [""]
        out += ["Policies (pure selection: hysteresis 0, no fade; nearest and brightest select "
                "among the same affecting lights in numpy):", ""] + policy_table(res) + [""]
        out += ["Popping, fade x hysteresis:", ""] + popping_table(res) + [""]
    out += ["#### Answers", "", "In short:", ""] + [line for answer in in_short(results)
                                                    for line in (answer, "")] + ["In detail:", ""]
    for res in results:
        out += prose(res)
    out += ["", popping_note(results), "", "Plot: `bench/plots/quality_pareto.png` (frame time "
            "against lighting lost and against popping, Pareto fronts in red).", ""]
    out += residual_section(rres, big, checks) + [END, ""]
    return "\n".join(out)


@dataclass
class ResidualSpec:
    label: str
    scene: CityScene
    note: str
    motion: str  # see ``changes``
    max_objects: int  # objects the metrics look at (a seeded subset beyond)
    frames: int
    time_frames: int


DONE_K = 4
DONE_ERROR = {"stadium": 0.05, "city": 0.005}  # issue 53: lighting error below these at K = 4
DONE_COST = 0.10  # issue 53: the residual adds at most this share to a (100k, 10k) frame
BIG = (100_000, 10_000)


def residual_specs(specs: list[SceneSpec], args: argparse.Namespace) -> list[ResidualSpec]:
    """city and stadium as in the rest of the study; dungeon-22 (``lightsched.scenes.
    dungeon22``: 22 lights, K = 4 recommended) with every object measured, its lights moving
    as the city's and its racers running as the stadium's players."""
    from lightsched.scenes import dungeon22

    out = [ResidualSpec(s.label, s.big, s.note_big, s.motion, s.max_objects, s.frames,
                        s.time_frames) for s in specs]
    frames = 20 if args.quick else 120
    out.append(ResidualSpec("dungeon-22", dungeon22(seed=args.seed),
                            f"`lightsched.scenes.dungeon22(seed={args.seed})`", "both", 10**9,
                            frames, 4 if args.quick else 20))
    return out


def residual_study(spec: ResidualSpec, args: argparse.Namespace) -> dict[str, Any]:
    say(f"\n== residual: {spec.label}: {spec.note}")
    rows = residual_runs()
    runs = distinct_runs([r for _, _, _, r in rows])
    t0 = time.perf_counter()
    with numba_threads(1):
        met = residual_pass(spec.scene, spec.motion, runs, spec.frames, spec.max_objects,
                            args.seed, f"{spec.label} residual metrics")
    say(f"   metrics: {len(runs)} runs in lockstep, {spec.frames} frames, "
        f"{met['measured_objects']:.0f} measured visible objects per frame (subset of "
        f"{met['subset']}), {met['pairs_per_object']:.1f} affecting lights per object "
        f"({time.perf_counter() - t0:.1f} s)")
    if met["candidate_mismatch"]:
        say(f"   !! {met['candidate_mismatch']} (frame, object) rows where the numpy Affects "
            "count differs from the fast path's candidates")
    t0 = time.perf_counter()
    load0 = os.getloadavg()[0]
    timing = timing_pass(spec.scene, spec.motion, runs, spec.time_frames, args.warmup,
                         args.runs, f"{spec.label} residual timing")
    load = (load0, os.getloadavg()[0])
    say(f"   timing: {len(runs)} runs x {args.runs} x {spec.time_frames} frames "
        f"({time.perf_counter() - t0:.1f} s)")
    table = {}
    for fade, on, k, r in rows:
        row = {"fade": fade, "residual": on, "k": k, "ms": timing[r.key]["ms"],
               **met["runs"][r.key]}
        if on:
            twin = next(r2 for f2, o2, k2, r2 in rows if (f2, o2, k2) == (fade, False, k))
            row["cost_ms"], row["cost"] = paired_cost(timing, r, twin)
        table[(fade, on, k)] = row
    return {"spec": spec, "metrics": met, "rows": table, "load": load}


def onoff(on: bool) -> str:
    return "on" if on else "off"


def residual_table(res: dict[str, Any]) -> list[str]:
    head = ["K", "fade", "residual", "lighting error", "of point and spot lights",
            "abrupt pops / 1000 obj-s",
            "of which unlit (A = 0)", "of which D steady", "pops against the object's mean A",
            "summed popping %/s",
            "frame ms", "residual's cost"]
    out = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    # Directional lights are the same in D and A, so |D - A| is the same without them; only
    # sum A shrinks.
    spot_point = 1.0 - res["metrics"]["sun_share"]
    for (fade, on, k), r in res["rows"].items():
        cost = f"{r['cost_ms']:+.2f} ms ({100 * r['cost']:+.0f}%)" if on else ""
        out.append(f"| {k} | {fade} | {onoff(on)} | {pct(r['error'])} | "
                   f"{pct(r['error'] / spot_point) if spot_point > 0 else '-'} | {r['pops']:.2f} | "
                   f"{r['unlit_pops']:.2f} | {r['steady_pops']:.2f} | {r['mean_pops']:.2f} | "
                   f"{per_s(r['popping'])} | "
                   f"{r['ms']:.2f} | {cost} |")
    return out


def done_when(rres: list[dict[str, Any]], big: dict[str, float] | None) -> list[dict[str, Any]]:
    """Issue 53's conditions at K = DONE_K with fade and the residual on, each judged from
    the figures, for both fade rows ("fade", hysteresis 0; "fade + hysteresis", the
    default). Each: condition, fade row, figures, passed (None: not measured)."""
    by = {r["spec"].label: r["rows"] for r in rres}
    out = []
    k = DONE_K
    for fade in ("fade", "fade + hysteresis"):
        for label, limit in DONE_ERROR.items():
            if label not in by:
                continue
            on, off = by[label][(fade, True, k)], by[label][(fade, False, k)]
            out.append({"condition": f"{label} lighting error < {pct(limit, 1)}", "fade": fade,
                        "figures": f"{pct(on['error'])} (without the residual: "
                                   f"{pct(off['error'])})",
                        "passed": on["error"] < limit})
        pops = {label: rows[(fade, True, k)]["pops"] for label, rows in by.items()}
        pops_off = {label: rows[(fade, False, k)]["pops"] for label, rows in by.items()}
        out.append({"condition": "abrupt pops 0 per 1000 object-s in every scene", "fade": fade,
                    "figures": ", ".join(f"{lb} {v:.2f}" for lb, v in pops.items())
                    + " (without the residual: "
                    + ", ".join(f"{lb} {v:.2f}" for lb, v in pops_off.items()) + ")",
                    "passed": all(v == 0 for v in pops.values())})
        mine = {label: (rows[(fade, True, k)]["popping"], rows[("no fade", True, k)]["popping"])
                for label, rows in by.items()}
        out.append({"condition": "summed popping no higher than without fade (residual on)",
                    "fade": fade,
                    "figures": ", ".join(f"{lb} {per_s(a)} vs {per_s(b)} %/s"
                                         for lb, (a, b) in mine.items()),
                    "passed": all(a <= b for a, b in mine.values())})
    if big is None:
        out.append({"condition": f"the residual adds at most {pct(DONE_COST, 0)} to a "
                                 f"({BIG[0] // 1000}k, {BIG[1] // 1000}k) frame", "fade": "default",
                    "figures": "not measured (--quick)", "passed": None})
    else:
        out.append({"condition": f"the residual adds at most {pct(DONE_COST, 0)} to a "
                                 f"({BIG[0] // 1000}k, {BIG[1] // 1000}k) frame",
                    "fade": "fade + hysteresis",
                    "figures": f"off {big['off']:.2f} ms, on {big['on']:.2f} ms, paired "
                               f"{big['diff']:+.2f} ms ({100 * big['diff'] / big['off']:+.0f}%)",
                    "passed": big["diff"] / big["off"] <= DONE_COST})
    return out


def verdict(passed: bool | None) -> str:
    return {True: "pass", False: "**fail**", None: "not measured"}[passed]


def done_table(checks: list[dict[str, Any]]) -> list[str]:
    out = [f"| condition (K = {DONE_K}, residual on) | fade row | figures | verdict |",
           "|---|---|---|---|"]
    out += [f"| {c['condition']} | {c['fade']} | {c['figures']} | {verdict(c['passed'])} |"
            for c in checks]
    return out


def done_answer(checks: list[dict[str, Any]]) -> str:
    failed = [c for c in checks if c["passed"] is False]
    unknown = [c for c in checks if c["passed"] is None]
    head = ("every condition holds" if not failed and not unknown else
            f"{len(checks) - len(failed) - len(unknown)} of {len(checks)} checks pass")
    text = f"**Answer (issue 53 done-when, K = {DONE_K}, fade, residual on):** {head}"
    if failed:
        text += "; failing: " + "; ".join(f"{c['condition']} with {c['fade']}: {c['figures']}"
                                          for c in failed)
    if unknown:
        text += "; not measured: " + "; ".join(c["condition"] for c in unknown)
    return text + "."


def residual_plot(rres: list[dict[str, Any]], path: Any) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    m = machine()
    fig, axes = plt.subplots(1, len(rres), figsize=(5.2 * len(rres), 4.6), squeeze=False)
    style = {"no fade": (":", "o"), "fade": ("--", "s"), "fade + hysteresis": ("-", "^")}
    for ax, res in zip(axes[0], rres, strict=True):
        for fade in FADES:
            for on in (False, True):
                pts = [res["rows"][(fade, on, k)] for k in RESIDUAL_K]
                ls, mk = style[fade]
                ax.plot([p["ms"] for p in pts], [100 * p["error"] for p in pts], ls=ls, marker=mk,
                        c="tab:orange" if on else "tab:blue",
                        label=f"{fade}, residual {onoff(on)}")
                if fade == "fade + hysteresis":
                    for p in pts:
                        ax.annotate(f"K={p['k']}", (p["ms"], 100 * p["error"]), fontsize=7,
                                    xytext=(3, 3), textcoords="offset points")
        ax.set_yscale("symlog", linthresh=0.01)
        ax.set_xlabel("Scheduler.frame median (ms)")
        ax.set_ylabel("lighting error sum|D - A| / sum A (%)")
        ax.set_title(res["spec"].label, fontsize=10)
        ax.grid(alpha=0.3, which="both")
    axes[0][0].legend(fontsize=7)
    fig.suptitle(f"Lighting error against frame time, K = "
                 f"{', '.join(map(str, RESIDUAL_K))}, with and without the residual "
                 f"({m['cpu']}, {m['nproc']} CPUs)", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def residual_section(rres: list[dict[str, Any]], big: dict[str, float] | None,
                     checks: list[dict[str, Any]]) -> list[str]:
    out = ["#### Residual, lighting error and abrupt pops (issue 53)", "",
           "Method (DESIGN section 4). Every run is a fast-path Scheduler with the default "
           "Config but for K, fade and residual: **no fade** = fade_in = fade_out = 0 and "
           "hysteresis 0; **fade** = 0.25 s fades, hysteresis 0; **fade + hysteresis** = the "
           "default (0.25 s, 0.1). Same sequences as above (dungeon-22: its lights move as the "
           "city's and its racers run as the stadium's players). At the "
           f"{6 * SAMPLES_PER_FACE} sample points of each measured visible object (as above: "
           f"{SAMPLES_PER_FACE} seeded points per box face, face normals, the same points "
           "every frame, moving with the box): **A** = every light that affects the object "
           "(numpy Affects, the unshadowed rule ignored) plus every directional light whose "
           "mask it shares, at full weight; **D** = the slots' lights times their fade "
           "weights, plus the frame's residual evaluated at the point's normal, max(0, a/4 + "
           "(b . n)/2), when the run has it on, plus the frame's directional_lights (outside "
           "the slots). Each light's term is the Lambert term of the windowed falloff at the "
           "point (`light_at_points`). **lighting error** = sum |D - A| / sum A over every "
           "measured (frame, object, point); \"of point and spot lights\": the same with the "
           "directional lights left out of A (they are the same in D, so only sum A changes; "
           "a diagnostic, not DESIGN's metric). **abrupt pops**: an object-frame (visible on "
           "this and the last frame) pops when at any of its points |(D_t - D_t-1) - (A_t - "
           f"A_t-1)| > {POP_SHARE:g} max(A_t, A_t-1); counted per 1000 such object-seconds at "
           "dt = 1/60 s; \"of which unlit\": the object-frames whose popping points all have "
           "A = 0 on both frames, where DESIGN's threshold is 0 and any change of D pops; "
           f"\"of which D steady\": those where D moved by at most {POP_SHARE:g} max(A_t, "
           "A_t-1) at every popping point, so the pop is A's jump (a light entering or leaving "
           "the visible lights, say), not a change the viewer sees; "
           "\"against the object's mean A\" (a diagnostic, not DESIGN's metric): the same "
           f"test with {POP_SHARE:g} x the mean over the object's points of max(A_t, A_t-1) "
           "as the threshold, so that dim points do not pop on small changes. "
           "**summed popping** = the popping above (this frame's slots and weights against "
           "last frame's, both at this frame's positions, per object summed over its points, "
           "over the delivered total), with, when the residual is on, the residual of each "
           "frame's weights added to both sides (rebuilt in numpy from DESIGN section 2 and "
           "checked against the frame's residual: largest relative difference below). "
           "**frame ms**: `Scheduler.frame` medians as above, every row of a scene in one "
           "lockstep timing pass; **residual's cost**: the median over those frames of "
           "(residual on - residual off) of the same frame, over the off row's median.", ""]
    for res in rres:
        spec, met = res["spec"], res["metrics"]
        dev = max((r["residual_dev"] for r in met["runs"].values()), default=0.0)
        missing = sum(r["missing"] for r in met["runs"].values())
        out += [f"##### {spec.label}", "",
                f"{spec.note}, {met['frames']} frames ({spec.time_frames} timed per run); "
                f"{met['measured_objects']:.0f} measured visible objects per frame "
                + (f"(a seeded subset of {met['subset']} objects)"
                   if met["subset"] < spec.scene.n_objects else "(all)")
                + f", {met['pairs_per_object']:.1f} affecting lights per object; directional "
                f"lights give {pct(met['sun_share'], 1)} of A. Numpy Affects vs fast-path "
                f"candidates: {met['candidate_mismatch']} differing (frame, object) rows; slot "
                f"lights outside the affecting set: {missing}; numpy residual vs the frame's: "
                f"largest difference {dev:.1e} of |a| (DESIGN's tolerance 1e-5). 1-minute load "
                f"average while timing: {res['load'][0]:.2f} .. {res['load'][1]:.2f}.", ""]
        out += residual_table(res) + [""]
    if big is not None:
        out += [f"The residual on a ({BIG[0] // 1000}k, {BIG[1] // 1000}k) city frame at K = "
                f"{DONE_K} (`bench/residual_cost.py`'s child: every light moving, on and off "
                f"interleaved in one process, native target): off {big['off']:.2f} ms, on "
                f"{big['on']:.2f} ms, paired difference {big['diff']:+.2f} ms "
                f"({100 * big['diff'] / big['off']:+.0f}%); 1-minute load average "
                f"{big['load'][0]:.2f} .. {big['load'][1]:.2f} on {os.cpu_count()} CPUs.", ""]
    out += ["Done when (issue 53), judged from the figures above:", ""] + done_table(checks)
    out += ["", done_answer(checks), "",
            "Plot: `bench/plots/quality_residual.png` (lighting error against frame time "
            "across K, with and without the residual, one panel per scene).", "",
            "![lighting error against frame time](plots/quality_residual.png)", ""]
    return out


def scene_specs(args: argparse.Namespace) -> list[SceneSpec]:
    """city: every visible object measured; stadium (hundreds of affecting lights per
    object): a seeded subset, fewer frames, and the oracle scene keeps all the lights (the
    generator's advice) with fewer objects."""
    seed = args.seed
    if args.quick:
        cb, cs, sb, ss = (3000, 300), (800, 80), (600, 300), (100, 300)
        c_frames = s_frames = 20
        c_obj, s_obj, c_time, s_time, c_or, s_or = 3000, 150, 4, 3, 2, 2
    else:
        cb, cs, sb, ss = (10_000, 1000), (2000, 200), (3000, 1000), (400, 1000)
        c_frames, s_frames = 120, 60
        c_obj, s_obj, c_time, s_time, c_or, s_or = 10_000, 300, 20, 10, 4, 3
    big_s, note_bs = stadium_scene(*sb, seed)
    small_s, note_ss = stadium_scene(*ss, seed)
    return [
        SceneSpec("city", city(*cb, seed=seed), city(*cs, seed=seed),
                  f"`city({cb[0]}, {cb[1]}, seed={seed})`", f"`city({cs[0]}, {cs[1]}, seed={seed})`",
                  c_obj, c_frames, c_time, c_or, "lights"),
        SceneSpec("stadium", big_s, small_s, note_bs, note_ss, s_obj, s_frames, s_time, s_or,
                  "objects"),
    ]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="smaller scenes, fewer frames")
    ap.add_argument("--write", action="store_true",
                    help="write the section into bench/RESULTS.md and the plot into bench/plots")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--residual-only", action="store_true",
                    help="only the residual study (issue 53); cannot --write")
    args = ap.parse_args(argv)
    if args.residual_only and args.write:
        ap.error("--write needs the whole study (RESULTS.md holds one section)")
    if args.quick:
        args.warmup, args.runs = 1, 1
    else:
        args.warmup, args.runs = 3, 3
    t_start = time.perf_counter()
    specs = scene_specs(args)
    results = []
    for spec in [] if args.residual_only else specs:
        res = study(spec, args)
        print_tables(res)
        results.append(res)
    rres = []
    for rspec in residual_specs(specs, args):
        res = residual_study(rspec, args)
        say(f"\n   {rspec.label}: lighting error, abrupt pops, summed popping")
        for line in residual_table(res):
            say("   " + line)
        rres.append(res)
    big = None
    if not args.quick:
        t0 = time.perf_counter()
        big = big_frame_cost(*BIG, DONE_K, 20)
        say(f"\n== residual on a ({BIG[0]}, {BIG[1]}) city frame, K = {DONE_K}: off "
            f"{big['off']:.2f} ms, on {big['on']:.2f} ms, paired {big['diff']:+.2f} ms "
            f"({time.perf_counter() - t0:.1f} s)")
    checks = done_when(rres, big)
    say("\n== answers")
    for res in results:
        for line in prose(res):
            say(line)
    say("")
    for line in done_table(checks):
        say(line)
    say(done_answer(checks))
    if args.write:
        PLOTS.mkdir(parents=True, exist_ok=True)
        path = PLOTS / "quality_pareto.png"
        plot(results, path)
        path_r = PLOTS / "quality_residual.png"
        residual_plot(rres, path_r)
        say(f"\nwrote {path} and {path_r}")
        write_results(render(results, rres, big, checks, args), BEGIN, END)
    say(f"\ntotal {time.perf_counter() - t_start:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
