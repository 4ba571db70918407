"""Shared test helpers: fast path vs oracle frame comparison (DESIGN section 4), a twin
runner that drives both schedulers through the same calls, and small scene builders.

``assert_frames_match`` is strict everywhere except where DESIGN section 4 allows slack:
priorities 1e-6 relative, fade weights 1e-6 absolute, cascade splits 1e-12 relative, the
residual 1e-5 relative to its a (rows whose slots hold the same lights), and
the order (and the K cut) of two lights of one object whose oracle P differ by less than
``tie_rel`` relative. ``tie_rel=0`` is the exact mode of the 2^-16 m grid: identical ids,
order and states, and (``bitwise``, implied by tie_rel=0) bit-identical floats.
"""

from __future__ import annotations

import copy
import math
import os
from typing import Any

import numpy as np
from hypothesis import HealthCheck, settings

import lightsched as ls
import lightsched.reference as ref
from lightsched.frame import FRAME_ARRAYS
from lightsched.grid import BoxSource
from lightsched.scene import DIRECTIONAL, FADING_OUT
from lightsched.tuning import Tuning

# --------------------------------------------------------------------------- hypothesis

PROFILE = "lightsched"
BASE_EXAMPLES = int(os.environ.get("LIGHTSCHED_EXAMPLES", "100"))


def register_profile() -> None:
    """The fixed profile of this suite (registered and loaded by conftest.py).

    LIGHTSCHED_EXAMPLES scales every test's example count (default 100); tests size their
    own share with ``examples(scale)``."""
    settings.register_profile(
        PROFILE, max_examples=BASE_EXAMPLES, deadline=None, print_blob=True,
        suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large,
                               HealthCheck.large_base_example])
    settings.load_profile(PROFILE)


def examples(scale: float) -> settings:
    """settings with max_examples = scale * LIGHTSCHED_EXAMPLES (at least 1)."""
    return settings(max_examples=max(1, int(round(BASE_EXAMPLES * scale))), deadline=None,
                    print_blob=True,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large,
                                           HealthCheck.large_base_example])


# --------------------------------------------------------------------------- comparison

FLOAT_FIELDS = ("priority", "fade_weight")
ROW_FIELDS = ("light_ids", "light_index", "priority", "fade_weight", "fade_state")
EXACT_FIELDS = ("object_id", "visible", "count", "candidates", "directional_lights",
                "visible_lights", "slot_shadow", "shadow_lights", "shadow_tier",
                "caster_offsets", "caster_ids", "caster_masks", "shadow_views", "shadow_dirty",
                "shadow_static_dirty", "shadow_update", "shadow_rect", "camera_ids")


class OracleP:
    """The oracle's float64 P of (object row, light id), recomputed from the reference
    scheduler's stores with the reference's own functions (frame outputs are float32, too
    coarse to judge a 1e-9 near-tie)."""

    def __init__(self, oracle: ref.Scheduler, cameras: list[Any]) -> None:
        self.cfg = oracle.config
        self.lights = {lt.id: lt for lt in ref._read_lights(oracle.lights)}
        self.objects = ref._read_objects(oracle.objects)
        self.cams = [ref.CameraFrame(c) for c in ls.scene.validate_cameras(cameras)]

    def __call__(self, row: int, lid: int) -> float | None:
        lt = self.lights.get(int(lid))
        if lt is None:
            return None
        ob = self.objects[row]
        if lt.type == DIRECTIONAL:
            return lt.intensity + lt.p_user
        d2 = ref.affects_geometry(lt, ob)
        if d2 is None:
            return None
        if self.cfg.model == "contribution":
            return ref.contribution_priority(lt, ob, d2)
        return ref.thesis_priority(lt, ob, self.cams, self.cfg)


def _close(a: float, b: float, rel: float, atol: float) -> bool:
    return abs(a - b) <= rel * max(abs(a), abs(b)) + atol


def _row_text(f: ls.Frame, o: int) -> str:
    n = int(f.count[o])
    return (f"ids={f.light_ids[o, :n].tolist()} P={f.priority[o, :n].tolist()} "
            f"w={f.fade_weight[o, :n].tolist()} st={f.fade_state[o, :n].tolist()} "
            f"idx={f.light_index[o, :n].tolist()}")


def assert_frames_match(fast: ls.Frame, oracle: ls.Frame, rel: float = 1e-6,
                        tie_rel: float = 1e-9, p_atol: float = 1e-12, w_atol: float = 1e-6,
                        bitwise: bool | None = None, oracle_p: OracleP | None = None,
                        what: str = "") -> int:
    """DESIGN section 4. Returns how many object rows differed only by near-ties.

    Near-ties (tie_rel > 0): in a row whose light ids differ, every position where they
    differ must hold two lights (neither fading out) whose oracle P are within tie_rel
    relative, every light only one side has must be paired with one only the other side
    has whose P is within tie_rel (a swap at the K cut), with equal state and weight, and
    lights both sides have must agree in P, weight, state and index. P is the oracle's
    float64 P when ``oracle_p`` is given, else the float32 outputs (then one float32 ulp of
    slack is added, as rounding can split a near-tie by one ulp).
    """
    if bitwise is None:
        bitwise = tie_rel == 0
    tag = f"{what}: " if what else ""
    for name, dtype in FRAME_ARRAYS.items():
        a, b = getattr(fast, name), getattr(oracle, name)
        assert a.dtype == np.dtype(dtype), f"{tag}fast {name} dtype {a.dtype}, want {dtype}"
        assert b.dtype == np.dtype(dtype), f"{tag}oracle {name} dtype {b.dtype}, want {dtype}"
        assert a.shape == b.shape, f"{tag}{name} shape fast {a.shape} oracle {b.shape}"
    for name in EXACT_FIELDS:
        a, b = getattr(fast, name), getattr(oracle, name)
        if not np.array_equal(a, b):
            bad = np.flatnonzero((a != b).reshape(a.shape[0], -1).any(axis=1)) if a.ndim else []
            raise AssertionError(f"{tag}{name} differs (first rows {list(bad[:5])}):\n"
                                 f"fast   {a[:20]!r}\noracle {b[:20]!r}")
    cs_f, cs_o = fast.cascade_splits, oracle.cascade_splits
    if bitwise:
        assert np.array_equal(cs_f, cs_o), f"{tag}cascade_splits {cs_f} vs {cs_o}"
    else:
        assert np.allclose(cs_f, cs_o, rtol=1e-12, atol=0.0), f"{tag}cascade_splits {cs_f} vs {cs_o}"

    same_ids = np.all(fast.light_ids == oracle.light_ids, axis=1)
    rows = np.flatnonzero(same_ids)
    _compare_same_rows(fast, oracle, rows, rel, p_atol, w_atol, bitwise, tag)
    assert_residual_close(fast, oracle, rows, tag)
    tied = 0
    for o in np.flatnonzero(~same_ids):
        msg = (f"{tag}object id {int(fast.object_id[o])} (row {o}) differs:\n"
               f"  fast   {_row_text(fast, o)}\n  oracle {_row_text(oracle, o)}")
        if tie_rel <= 0:
            raise AssertionError(msg + "\n  (exact mode: no near-ties allowed)")
        _check_tie_row(fast, oracle, int(o), rel, tie_rel, p_atol, w_atol, oracle_p, msg)
        tied += 1
    return tied


RESIDUAL_REL = 1e-5  # DESIGN section 4: residual within 1e-5 relative to max(|a|, 1e-30)


def assert_residual_close(fast: ls.Frame, oracle: ls.Frame, rows: np.ndarray | None = None,
                          tag: str = "") -> None:
    """residual of the ``rows`` (every row when None) within DESIGN section 4's tolerance:
    each component within 1e-5 of max(|a|, 1e-30), a the oracle's. Rows whose slots differ
    by a near-tie are left out by the caller: their residuals hold different lights."""
    a = fast.residual if rows is None else fast.residual[rows]
    b = oracle.residual if rows is None else oracle.residual[rows]
    a, b = a.astype(np.float64), b.astype(np.float64)
    scale = np.maximum(np.abs(b[:, :1]), 1e-30)
    bad = ~(np.abs(a - b) <= RESIDUAL_REL * scale)
    if bad.any():
        i = int(np.flatnonzero(bad.any(axis=1))[0])
        o = i if rows is None else int(rows[i])
        raise AssertionError(f"{tag}residual differs at object id {fast.object_id[o]}:\n"
                             f"  fast   {fast.residual[o]!r}\n  oracle {oracle.residual[o]!r}\n"
                             f"  fast   {_row_text(fast, o)}\n  oracle {_row_text(oracle, o)}")


def _compare_same_rows(fast, oracle, rows, rel, p_atol, w_atol, bitwise, tag):
    for name in ("light_index", "fade_state"):
        a, b = getattr(fast, name)[rows], getattr(oracle, name)[rows]
        if not np.array_equal(a, b):
            o = rows[np.flatnonzero((a != b).any(axis=1))[0]]
            raise AssertionError(f"{tag}{name} differs at object id {fast.object_id[o]}:\n"
                                 f"  fast   {_row_text(fast, o)}\n  oracle {_row_text(oracle, o)}")
    pf = fast.priority[rows].astype(np.float64)
    po = oracle.priority[rows].astype(np.float64)
    wf = fast.fade_weight[rows].astype(np.float64)
    wo = oracle.fade_weight[rows].astype(np.float64)
    if bitwise:
        bad_p = pf.view(np.int64) != po.view(np.int64)
        bad_w = wf.view(np.int64) != wo.view(np.int64)
    else:
        bad_p = ~(np.abs(pf - po) <= rel * np.maximum(np.abs(pf), np.abs(po)) + p_atol)
        bad_w = ~(np.abs(wf - wo) <= w_atol)
    for name, bad in (("priority", bad_p), ("fade_weight", bad_w)):
        if bad.any():
            o = rows[np.flatnonzero(bad.any(axis=1))[0]]
            raise AssertionError(f"{tag}{name} differs at object id {fast.object_id[o]}:\n"
                                 f"  fast   {_row_text(fast, o)}\n  oracle {_row_text(oracle, o)}")


def _check_tie_row(fast, oracle, o, rel, tie_rel, p_atol, w_atol, oracle_p, msg):
    n = int(oracle.count[o])  # counts were compared exactly already
    f_ids = [int(x) for x in fast.light_ids[o, :n]]
    o_ids = [int(x) for x in oracle.light_ids[o, :n]]
    f_slot = {lid: j for j, lid in enumerate(f_ids)}
    o_slot = {lid: j for j, lid in enumerate(o_ids)}
    assert len(f_slot) == n and len(o_slot) == n, msg + "\n  repeated light id in a row"

    def p_of(lid: int) -> float:
        if oracle_p is not None:
            p = oracle_p(o, lid)
            assert p is not None, msg + f"\n  light {lid} does not affect the object per the oracle"
            return p
        if lid in o_slot:
            return float(oracle.priority[o, o_slot[lid]])
        return float(fast.priority[o, f_slot[lid]])

    def tied(a: int, b: int) -> bool:
        pa, pb = p_of(a), p_of(b)
        slack = 0.0 if oracle_p is not None else float(np.spacing(np.float32(max(abs(pa), abs(pb)))))
        return abs(pa - pb) <= tie_rel * max(abs(pa), abs(pb)) + slack

    def same_slot(a_frame, ja, b_frame, jb, label):
        wa, wb = float(a_frame.fade_weight[o, ja]), float(b_frame.fade_weight[o, jb])
        assert abs(wa - wb) <= w_atol, msg + f"\n  {label}: weights {wa} vs {wb}"
        sa, sb = int(a_frame.fade_state[o, ja]), int(b_frame.fade_state[o, jb])
        assert sa == sb, msg + f"\n  {label}: states {sa} vs {sb}"

    # Lights on both sides: same P, weight, state and light_index.
    for lid in set(f_ids) & set(o_ids):
        jf, jo = f_slot[lid], o_slot[lid]
        a, b = float(fast.priority[o, jf]), float(oracle.priority[o, jo])
        assert _close(a, b, rel, p_atol), msg + f"\n  light {lid}: P {a} vs {b}"
        same_slot(fast, jf, oracle, jo, f"light {lid}")
        assert fast.light_index[o, jf] == oracle.light_index[o, jo], msg + f"\n  light {lid} index"
    # Swaps at the K cut: pair the lights only one side has, by P.
    only_f = sorted(set(f_ids) - set(o_ids), key=lambda x: (-p_of(x), x))
    only_o = sorted(set(o_ids) - set(f_ids), key=lambda x: (-p_of(x), x))
    assert len(only_f) == len(only_o), msg
    for a, b in zip(only_f, only_o, strict=True):
        assert tied(a, b), (msg + f"\n  fast has {a} (P {p_of(a)!r}), oracle {b} "
                            f"(P {p_of(b)!r}): not a near-tie")
        same_slot(fast, f_slot[a], oracle, o_slot[b], f"swap {a}/{b}")
        ja, jb = f_slot[a], o_slot[b]
        assert _close(float(fast.priority[o, ja]), float(np.float32(p_of(a))), rel, p_atol), msg
        assert _close(float(oracle.priority[o, jb]), float(np.float32(p_of(b))), rel, p_atol), msg
    # Order: every position that differs holds two near-tied lights, neither fading out.
    for j in range(n):
        a, b = f_ids[j], o_ids[j]
        if a == b:
            continue
        assert fast.fade_state[o, j] != FADING_OUT and oracle.fade_state[o, j] != FADING_OUT, (
            msg + f"\n  slot {j}: fading-out slots ordered differently")
        assert tied(a, b), msg + f"\n  slot {j}: {a} (P {p_of(a)!r}) vs {b} (P {p_of(b)!r}): not a near-tie"


def assert_frame_sane(f: ls.Frame, k: int, what: str = "") -> None:
    """No NaN/Inf, empty slots empty, weights and states in range, rows in output order."""
    tag = f"{what}: " if what else ""
    n = f.object_id.size
    assert f.light_ids.shape == (n, k), tag + "light_ids shape"
    assert np.all(np.isfinite(f.priority)), tag + "non-finite priority"
    assert np.all(np.isfinite(f.fade_weight)), tag + "non-finite fade_weight"
    assert np.all(np.isfinite(f.cascade_splits)), tag + "non-finite cascade_splits"
    assert np.all(np.diff(f.object_id.astype(np.int64)) > 0), tag + "object rows not ascending"
    assert np.all(np.diff(f.visible_lights.astype(np.int64)) > 0), tag + "visible_lights not ascending"
    cnt = f.count
    assert np.all((cnt >= 0) & (cnt <= k)), tag + "count out of range"
    assert np.all(cnt <= f.candidates), tag + "count > candidates"
    assert np.all(cnt[~f.visible] == 0) and np.all(f.candidates[~f.visible] == 0), tag + "invisible lit"
    assert f.residual.shape == (n, 4), tag + "residual shape"
    assert np.all(np.isfinite(f.residual)), tag + "non-finite residual"
    assert np.all(f.residual[~f.visible] == 0), tag + "invisible residual"
    assert np.all(f.residual[:, 0] >= 0), tag + "negative residual a"
    slot = np.arange(k)[None, :]
    empty = slot >= cnt[:, None]
    assert np.all(f.light_ids[empty] == -1) and np.all(f.light_index[empty] == -1), tag + "empty ids"
    assert np.all(f.priority[empty] == 0) and np.all(f.fade_weight[empty] == 0), tag + "empty floats"
    assert np.all(f.fade_state[empty] == 0), tag + "empty states"
    full = ~empty
    assert np.all(f.light_ids[full] >= 0) and np.all(f.light_index[full] >= 0), tag + "full ids"
    w = f.fade_weight[full]
    st = f.fade_state[full]
    assert np.all((w >= 0) & (w <= 1)), tag + "weight out of [0, 1]"
    assert np.all((st >= 1) & (st <= 3)), tag + "state out of 1..3"
    assert np.all(w[st == 2] == 1) and np.all(w[st == 1] < 1), tag + "on iff weight 1"
    # Output order: not fading out by P desc (ties lower id), then fading out by weight desc.
    for o in np.flatnonzero(cnt > 1):
        c = int(cnt[o])
        keys = [(int(f.fade_state[o, j]) == FADING_OUT,
                 -float(f.fade_weight[o, j]) if f.fade_state[o, j] == FADING_OUT
                 else -float(f.priority[o, j]), int(f.light_ids[o, j])) for j in range(c)]
        # float32 rounding may merge two P; only demand a weakly sorted key sequence.
        for a, b in zip(keys, keys[1:], strict=False):
            assert a[:2] <= b[:2], tag + f"object {f.object_id[o]} slots out of order: {keys}"
        assert len({x[2] for x in keys}) == c, tag + "repeated light in a row"


# --------------------------------------------------------------------------- twin runner


class Twin:
    """A fast Scheduler and an oracle Scheduler driven through the same calls.

    Every set_/update_/remove_ call goes to both (with private copies of the arrays) and
    must succeed or fail alike. ``frame`` steps both and compares them; after a frame that
    differed only by near-ties their states may legitimately part, so later frames are
    then only checked for sanity (``diverged`` says so). ``compared`` counts the frames
    that were compared (the one that found the near-ties included), ``frames`` all of
    them: a test of a sequence asserts that most were. ``tuning``: the fast scheduler's
    (lightsched.tuning.Tuning; None, the default one)."""

    def __init__(self, config: ls.Config | None = None, tie_rel: float = 1e-9,
                 bitwise: bool | None = None, tuning: Tuning | None = None) -> None:
        self.config = config or ls.Config()
        self.fast = ls.Scheduler(self.config, tuning)
        self.ref = ref.Scheduler(self.config)
        self.tie_rel = tie_rel
        self.bitwise = bitwise
        self.diverged = False
        self.tied_rows = 0
        self.frames = 0
        self.compared = 0
        self.plans: list[str] = []

    def _call(self, method: str, **kw: Any) -> None:
        errs = []
        for s in (self.fast, self.ref):
            try:
                getattr(s, method)(**copy.deepcopy(kw))
                errs.append(None)
            except ls.ValidationError as e:
                errs.append((e.field, e.index))
        assert errs[0] == errs[1], f"{method}: fast {errs[0]} vs oracle {errs[1]}"
        if errs[0] is not None:
            raise AssertionError(f"{method} rejected a test input: {errs[0]}")

    def set_lights(self, **kw: Any) -> None:
        self._call("set_lights", **kw)

    def set_objects(self, **kw: Any) -> None:
        self._call("set_objects", **kw)

    def update_lights(self, **kw: Any) -> None:
        self._call("update_lights", **kw)

    def update_objects(self, **kw: Any) -> None:
        self._call("update_objects", **kw)

    def remove_lights(self, id: Any) -> None:  # noqa: A002
        self._call("remove_lights", id=id)

    def remove_objects(self, id: Any) -> None:  # noqa: A002
        self._call("remove_objects", id=id)

    def frame(self, cameras: Any, dt: float = 1 / 60, cut: bool = False,
              plan: str | None = None) -> tuple[ls.Frame, ls.Frame]:
        """Steps both; compares (unless diverged); ``plan``: expected prefix of the fast
        frame's stats["plan"]["pairs"]."""
        what = f"frame {self.frames}"
        ff = self.fast.frame(cameras, dt=dt, cut=cut)
        fo = self.ref.frame(cameras, dt=dt, cut=cut)
        self.frames += 1
        k = self.config.max_lights
        assert_frame_sane(ff, k, "fast " + what)
        assert_frame_sane(fo, k, "oracle " + what)
        pairs_plan = ff.stats["plan"]["pairs"]
        self.plans.append(pairs_plan)
        if plan is not None:
            assert pairs_plan.startswith(plan), f"{what}: plan {pairs_plan!r}, want {plan!r}"
        if not self.diverged:
            t = assert_frames_match(ff, fo, tie_rel=self.tie_rel, bitwise=self.bitwise,
                                    oracle_p=OracleP(self.ref, cameras), what=what)
            self.compared += 1
            if t:
                self.tied_rows += t
                self.diverged = True
                _event("near-tie rows: later frames only sanity-checked")
        return ff, fo


def _event(text: str) -> None:
    """A hypothesis statistics event when running under hypothesis (else nothing)."""
    try:
        from hypothesis import event

        event(text)
    except Exception:  # noqa: BLE001 - outside a hypothesis test
        pass


# --------------------------------------------------------------------------- scenes


def camera(position=(0.0, 0.0, 0.0), forward=(0.0, 0.0, 1.0), up=(0.0, 1.0, 0.0),
           fov_y=math.pi / 2, aspect=1.0, near=0.1, far=100.0, **kw: Any) -> ls.Camera:
    return ls.Camera(position=np.asarray(position, float), forward=np.asarray(forward, float),
                     up=np.asarray(up, float), fov_y=fov_y, aspect=aspect, near=near, far=far,
                     **kw)


def up_for(forward: Any) -> np.ndarray:
    """An up vector well away from parallel to ``forward``."""
    f = np.asarray(forward, float)
    f = f / np.linalg.norm(f)
    for cand in ((0.0, 1.0, 0.0), (1.0, 0.0, 0.0), (0.0, 0.0, 1.0)):
        c = np.array(cand)
        if abs(float(f @ c)) < 0.9:
            return c
    raise AssertionError("unreachable")


def frames_identical(a: ls.Frame, b: ls.Frame, what: str = "") -> None:
    """Bit-identical frames (every output array, dtype, shape)."""
    for name in FRAME_ARRAYS:
        x, y = getattr(a, name), getattr(b, name)
        assert x.dtype == y.dtype and x.shape == y.shape, f"{what}: {name} dtype/shape"
        if x.dtype.kind == "f":
            same = np.array_equal(x.view(np.dtype(f"i{x.itemsize}")),
                                  y.view(np.dtype(f"i{y.itemsize}")))
        else:
            same = np.array_equal(x, y)
        assert same, f"{what}: {name} differs\n{x!r}\n{y!r}"


def by_row_or_grid(lo: np.ndarray, hi: np.ndarray, grid_rows: np.ndarray, by_row: bool
                   ) -> BoxSource:
    """The boxes of a grid's positions as grid.group_boxes, casters.sweep_groups and
    frustum.objects_visible_groups read them: the objects' by row, or (as a grid's float64
    records hold them) copied into grid order, as views of one [V, 8] array."""
    if by_row:
        return BoxSource(lo, hi, grid_rows, True)
    recs = np.zeros((grid_rows.size, 8))
    recs[:, :3] = lo[grid_rows]
    recs[:, 3:6] = hi[grid_rows]
    return BoxSource(recs[:, :3], recs[:, 3:6], grid_rows, False)
