"""The residual (DESIGN section 2, "Residual"): one light and one object per light type,
worked out by hand from DESIGN's formulas, in both the oracle and the fast path; the fade
handing a light between its slot and the residual; the rules that leave lights out; and
Config.residual off. (tests/test_equivalence.py compares it with the oracle on random
multi-frame scenes.)"""

from __future__ import annotations

import math

import numpy as np
import pytest

import lightsched as ls
import lightsched.reference as ref
from tests.helpers import camera

R0 = 0.1
CAM = camera(position=(0.0, 0.0, -10.0))


@pytest.fixture(params=["fast", "oracle"])
def sched_cls(request):
    return ls.Scheduler if request.param == "fast" else ref.Scheduler


def _lights(**fields):
    return {"id": np.asarray(fields.pop("id"), np.int32),
            **{k: np.asarray(v, float if k != "type" else np.uint8) if k != "shadows"
               else np.asarray(v, bool) for k, v in fields.items()}}


def _box(lo, hi):
    return {"id": np.array([7], np.int32), "bounds_min": np.array([lo], float),
            "bounds_max": np.array([hi], float)}


def _frame(sched_cls, config, lights, objects, dt=0.0, cut=True):
    s = sched_cls(config)
    s.set_lights(**lights)
    s.set_objects(**objects)
    return s, s.frame([CAM], dt=dt, cut=cut)


def _point_e(i, r, dc2):
    q = dc2 / (r * r)
    w = max(0.0, 1 - q * q)
    return i * w * w / (dc2 + R0 * R0)


def _close(got, want):
    got = np.asarray(got, np.float64)
    want = np.asarray(want, np.float64)
    assert np.all(np.abs(got - want) <= 1e-6 * max(abs(want[0]), 1e-30)), (got, want)


def test_point_light_past_k_from_the_box_centre(sched_cls):
    """K = 1: the near light holds the slot at weight 1 (no residual), the far one is
    wholly in the residual, measured from the box centre with dc2 = max(v . v, R*R)."""
    lights = _lights(id=[1, 2], position=[[0.0, 0.0, 1.5], [0.0, 0.0, 4.0]],
                     radius=[10.0, 10.0], intensity=[5.0, 3.0])
    # A box [-1, 1]^3: R = sqrt(3); the far light's v = (0, 0, 4), v . v = 16 > R*R.
    _, f = _frame(sched_cls, ls.Config(max_lights=1), lights, _box([-1, -1, -1], [1, 1, 1]))
    assert f.light_ids.tolist() == [[1]] and f.fade_weight.tolist() == [[1.0]]
    e = _point_e(3.0, 10.0, 16.0)
    _close(f.residual[0], [e, 0.0, 0.0, e])
    # The near light inside the box's bounding sphere: dc2 = R*R = 3, not v . v = 2.25.
    lights["intensity"] = np.array([1.0, 50.0])
    _, f = _frame(sched_cls, ls.Config(max_lights=1), lights, _box([-1, -1, -1], [1, 1, 1]))
    assert f.light_ids.tolist() == [[2]]
    e = _point_e(1.0, 10.0, 3.0)
    _close(f.residual[0], [e, 0.0, 0.0, e])


def test_spot_light_in_the_residual_carries_its_spot_factor(sched_cls):
    """A spot at the origin along +z and a point (zero-extent) object off its axis, in the
    ramp between the inner and outer cones: s = ((c - cos o)/(cos i - cos o))^2 with c the
    cosine of the angle to the axis; u points from the object to the light."""
    outer, inner = math.pi / 4, math.pi / 8
    lights = _lights(id=[3, 4], type=[0, 1], position=[[1.0, 0.0, 2.5], [0.0, 0.0, 0.0]],
                     radius=[10.0, 10.0], intensity=[5.0, 2.0],
                     direction=[[0.0, 0.0, 1.0], [0.0, 0.0, 1.0]], outer_angle=[0.5, outer],
                     inner_angle=[0.4, inner])
    _, f = _frame(sched_cls, ls.Config(max_lights=1), lights, _box([1, 0, 2], [1, 0, 2]))
    assert f.light_ids.tolist() == [[3]]
    c = 2 / math.sqrt(5)
    s = ((c - math.cos(outer)) / (math.cos(inner) - math.cos(outer))) ** 2
    assert 0 < s < 1
    e = _point_e(2.0, 10.0, 5.0) * s
    _close(f.residual[0], [e, -e / math.sqrt(5), 0.0, -2 * e / math.sqrt(5)])


def test_directional_light_in_slots_goes_to_the_residual(sched_cls):
    """With directional_in_slots a sun competes: past K its irradiance i goes to the
    residual along u = -direction. Applied outside the slots, it is not in the residual."""
    lights = _lights(id=[1, 2], type=[0, 2], position=[[0.0, 0.0, 1.0], [0.0, 0.0, 0.0]],
                     radius=[10.0, 1.0], intensity=[10.0, 0.5],
                     direction=[[0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])
    box = _box([0, 0, 0], [0, 0, 0])
    _, f = _frame(sched_cls, ls.Config(max_lights=1, directional_in_slots=True), lights, box)
    assert f.light_ids.tolist() == [[1]] and f.candidates.tolist() == [2]
    _close(f.residual[0], [0.5, 0.0, 0.5, 0.0])
    _, f = _frame(sched_cls, ls.Config(max_lights=1), lights, box)
    assert f.directional_lights.tolist() == [2]
    assert f.residual.tolist() == [[0.0, 0.0, 0.0, 0.0]]


def test_fade_hands_light_between_slot_and_residual(sched_cls):
    """A fading-out slot's light is in the residual by 1 - w; a selected light waiting for
    a free slot wholly; summed in ascending light id."""
    a = dict(id=[1], position=[[0.0, 0.0, 2.0]], radius=[10.0], intensity=[1.0])
    cfg = ls.Config(max_lights=1, fade_in=0.25, fade_out=0.25, hysteresis=0.0)
    box = _box([0, 0, 0], [0, 0, 0])
    s, f = _frame(sched_cls, cfg, _lights(**a), box)
    assert f.residual.tolist() == [[0.0, 0.0, 0.0, 0.0]]
    s.set_lights(**_lights(id=[1, 2], position=[[0.0, 0.0, 2.0], [0.0, 3.0, 0.0]],
                           radius=[10.0, 10.0], intensity=[1.0, 50.0]))
    f = s.frame([CAM], dt=0.1)
    assert f.light_ids.tolist() == [[1]] and f.fade_state.tolist() == [[3]]
    rho = 1 - (1 - 0.1 / 0.25)
    e1, e2 = _point_e(1.0, 10.0, 4.0), _point_e(50.0, 10.0, 9.0)
    t1 = rho * e1
    _close(f.residual[0], [t1 + e2, 0.0, e2, t1])


def test_skip_leaves_shadowed_lights_out(sched_cls):
    """With unshadowed = "skip" a light with shadows = true has no part in the residual,
    even as one of the frame's shadow lights; with "light" it has."""
    lights = _lights(id=[1, 2], position=[[0.0, 0.0, 1.0], [0.0, 0.0, 3.0]],
                     radius=[10.0, 10.0], intensity=[10.0, 1.0], shadows=[False, True])
    box = _box([0, 0, 0], [0, 0, 0])
    e = _point_e(1.0, 10.0, 9.0)
    _, f = _frame(sched_cls, ls.Config(max_lights=1), lights, box)
    _close(f.residual[0], [e, 0.0, 0.0, e])
    _, f = _frame(sched_cls, ls.Config(max_lights=1, unshadowed="skip"), lights, box)
    assert f.shadow_lights.tolist() == [2] and f.candidates.tolist() == [2]
    assert f.residual.tolist() == [[0.0, 0.0, 0.0, 0.0]]


def test_residual_off_and_invisible_objects_are_zero(sched_cls):
    lights = _lights(id=[1, 2], position=[[0.0, 0.0, 1.0], [0.0, 0.0, 3.0]],
                     radius=[10.0, 10.0], intensity=[10.0, 1.0])
    objects = {"id": np.array([7, 8], np.int32),
               "bounds_min": np.array([[0.0, 0.0, 0.0], [0.0, 0.0, -20.0]]),
               "bounds_max": np.array([[0.0, 0.0, 0.0], [0.0, 0.0, -19.0]])}
    _, f = _frame(sched_cls, ls.Config(max_lights=1), lights, objects)
    assert f.visible.tolist() == [True, False]
    assert f.residual[0, 0] > 0 and f.residual[1].tolist() == [0.0] * 4
    s, f = _frame(sched_cls, ls.Config(max_lights=1, residual=False), lights, objects)
    assert f.residual.dtype == np.float32 and f.residual.shape == (2, 4)
    assert not f.residual.any()
    s.update_lights(id=[2], position=[[0.0, 1.0, 3.0]])
    assert not s.frame([CAM], dt=0.1).residual.any()


def test_residual_switched_off_and_on_between_frames(sched_cls):
    """Off, every frame's residual is zero (the fast path's frames share one read-only
    array of zeros, which the pass never writes); switched on again, the lit object's
    residual comes back, and the frames made while it was off still read zero."""
    lights = _lights(id=[1, 2], position=[[0.0, 0.0, 1.0], [0.0, 0.0, 3.0]],
                     radius=[10.0, 10.0], intensity=[10.0, 1.0])
    s, f = _frame(sched_cls, ls.Config(max_lights=1), lights, _box([0, 0, 0], [0, 0, 0]))
    assert f.residual[0, 0] > 0
    off_frames = []
    for i, on in enumerate((True, False, False, False, True, True, True, False, True)):
        s.config = ls.Config(max_lights=1, residual=on)
        s.update_lights(id=[2], position=[[0.0, 0.1 * i, 3.0]])
        f = s.frame([CAM], dt=0.1)
        assert (f.residual[0, 0] > 0) == on
        assert not f.residual[0, 1:].any() or on
        if not on:
            off_frames.append(f)
        del f
    assert all(not g.residual.any() for g in off_frames)
