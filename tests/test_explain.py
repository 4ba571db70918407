"""Scheduler.explain (DESIGN section 7): a hand-made scene for each reason, run on the fast
Scheduler and the oracle alike, and the fast path against the oracle on random sequences,
explained right after each frame and again after the scene has changed since."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest
from helpers import Twin, camera, examples
from hypothesis import event, given
from hypothesis import strategies as st
from test_equivalence import run_sequence, scenes

import lightsched as ls
import lightsched.reference as ref
from lightsched.fields import EXPLAIN_FIELDS, REASONS
from lightsched.scene import DIRECTIONAL, POINT, SPOT

SCHEDULERS = pytest.mark.parametrize("make", [ls.Scheduler, ref.Scheduler],
                                     ids=["fast", "oracle"])
CAM = camera()  # at the origin, looking along +z, 90 degrees, far 100
SEEN = ([-1.0, -1.0, 9.0], [1.0, 1.0, 11.0])  # object 1, in view
BEHIND = ([-1.0, -1.0, -11.0], [1.0, 1.0, -9.0])  # object 2, behind the camera


def lights(*rows: dict[str, Any]) -> dict[str, Any]:
    """set_lights keywords from rows {id, position, ...} (point lights of radius 5 by
    default)."""
    defaults = {"type": POINT, "position": (0.0, 0.0, 0.0), "radius": 5.0, "intensity": 10.0,
                "mask": 1, "shadows": False, "direction": (0.0, -1.0, 0.0), "outer_angle": 0.5}
    rows = tuple({**defaults, **r} for r in rows)
    return {k: np.array([r[k] for r in rows]) for k in rows[0]}


def scheduler(make: Any, light_rows: list[dict[str, Any]], **config: Any) -> Any:
    s = make(ls.Config(**config))
    s.set_lights(**lights(*light_rows))
    s.set_objects(id=np.array([1, 2]), bounds_min=np.array([SEEN[0], BEHIND[0]]),
                  bounds_max=np.array([SEEN[1], BEHIND[1]]), mask=np.array([1, 1]))
    return s


def reasons(e: ls.Explanation) -> dict[int, str]:
    return dict(zip(e.light_id.tolist(), e.reason, strict=True))


NEAR = {"id": 10, "position": (0.0, 0.0, 7.0)}  # 2 m in front of object 1


@SCHEDULERS
def test_each_reason_of_a_light_that_does_not_light_the_object(make):
    s = scheduler(make, [
        NEAR,
        {"id": 11, "position": (0.0, 0.0, 7.0), "mask": 2},
        {"id": 12, "position": (25.0, 0.0, 40.0)},
        {"id": 13, "type": SPOT, "position": (0.0, 3.0, 10.0), "direction": (0.0, 1.0, 0.0)},
        {"id": 14, "type": DIRECTIONAL},
        {"id": 15, "position": (0.0, 0.0, -50.0)},
    ])
    s.frame([CAM])
    e = s.explain(1)
    assert reasons(e) == {10: "selected", 11: "masked", 12: "out_of_range",
                          13: "outside_cone", 14: "directional"}
    i = e.light_id.tolist().index(10)
    assert e.d2[i] == 4.0 and e.slot[i] == 0 and e.fade_state[i] == ls.scene.ON
    assert e.fade_weight[i] == 1.0 and e.selection_priority[i] == e.priority[i]
    assert math.isnan(e.d2[e.light_id.tolist().index(14)])
    assert reasons(s.explain(2)) == dict.fromkeys([10, 11, 12, 13, 14], "object_not_visible")


@SCHEDULERS
def test_removed_and_light_not_visible_rows_are_the_slots_held_when_the_frame_began(make):
    s = scheduler(make, [NEAR, {"id": 20, "position": (0.0, 0.0, 8.0)}])
    s.frame([CAM])
    s.remove_lights(id=[10])
    s.update_lights(id=[20], position=[[0.0, 0.0, -50.0]])
    s.frame([CAM])
    e = s.explain(1)
    assert reasons(e) == {10: "removed", 20: "light_not_visible"}
    assert (e.slot == -1).all() and np.isnan(e.priority).all()


@SCHEDULERS
def test_unshadowed_skip(make):
    s = scheduler(make, [NEAR, {"id": 30, "position": (0.0, 0.0, 8.0), "shadows": True}],
                  unshadowed="skip", shadow_budget=0)
    s.frame([CAM])
    assert reasons(s.explain(1)) == {10: "selected", 30: "unshadowed_skip"}


@SCHEDULERS
def test_below_k_waiting_and_fading_out_with_one_slot(make):
    weak = {"id": 40, "position": (0.0, 0.0, 7.0), "intensity": 1.0}
    s = scheduler(make, [NEAR, weak], max_lights=1, fade_in=0.5, fade_out=0.5)
    s.frame([CAM])
    assert reasons(s.explain(1)) == {10: "selected", 40: "below_k"}
    s.update_lights(id=[40], intensity=[1000.0])
    s.frame([CAM], dt=0.1)
    e = s.explain(1)
    # 40 is selected now, but 10 fades out in the only slot: 40 waits (K is a hard limit).
    assert reasons(e) == {10: "fading_out", 40: "waiting"}
    i = e.light_id.tolist().index(10)
    assert e.fade_state[i] == ls.scene.FADING_OUT and e.fade_weight[i] == pytest.approx(0.8)
    # 10 was selected last frame: its key had the hysteresis bonus.
    assert e.selection_priority[i] == pytest.approx(e.priority[i] * 1.1)


@SCHEDULERS
def test_explains_the_last_frame_after_the_scene_changed(make):
    s = scheduler(make, [NEAR])
    s.frame([CAM])
    s.remove_objects(id=[1])
    s.set_lights(**lights({"id": 50, "position": (0.0, 0.0, 7.0)}))
    e = s.explain(1)
    assert reasons(e) == {10: "selected"} and e.frame_index == 0


@SCHEDULERS
def test_an_unknown_object_or_no_frame_is_a_validation_error_naming_object_id(make):
    s = scheduler(make, [NEAR])
    with pytest.raises(ls.ValidationError) as no_frame:
        s.explain(1)
    s.frame([CAM])
    with pytest.raises(ls.ValidationError) as unknown:
        s.explain(3)
    with pytest.raises(ls.ValidationError) as not_an_id:
        s.explain("1")
    assert {no_frame.value.field, unknown.value.field, not_an_id.value.field} == {"object_id"}


def test_the_reasons_are_design_s_in_its_order():
    assert REASONS == ("removed", "object_not_visible", "light_not_visible", "masked",
                       "unshadowed_skip", "out_of_range", "outside_cone", "directional",
                       "selected", "waiting", "fading_out", "below_k")
    assert [f.name for f in EXPLAIN_FIELDS] == [
        "light_id", "priority", "selection_priority", "d2", "slot", "fade_weight",
        "fade_state", "reason"]


def assert_explanations_match(t: Twin, what: str) -> int:
    """Every object's explanation, fast against oracle: reasons, slots and states exactly,
    P as the frames compare priorities; the number of rows compared."""
    rows = 0
    for oid in [o.id for o in t.ref._explained["objects"]]:
        a, b = t.fast.explain(oid), t.ref.explain(oid)
        tag = f"{what}, object {oid}:\nfast\n{a}\noracle\n{b}"
        assert a.frame_index == b.frame_index, tag
        assert a.light_id.tolist() == b.light_id.tolist(), tag
        assert a.reason == b.reason, tag
        assert a.slot.tolist() == b.slot.tolist(), tag
        assert a.fade_state.tolist() == b.fade_state.tolist(), tag
        for name, rel, atol in (("priority", 1e-6, 1e-12), ("selection_priority", 1e-6, 1e-12),
                                ("d2", 1e-12, 0.0), ("fade_weight", 0.0, 1e-6)):
            x, y = getattr(a, name), getattr(b, name)
            assert np.array_equal(np.isnan(x), np.isnan(y)), (name, tag)
            ok = ~np.isnan(x)
            assert np.allclose(x[ok], y[ok], rtol=rel, atol=atol), (name, tag)
        rows += a.light_id.size
        for reason in set(a.reason):
            event(f"reason {reason}")
    return rows


@examples(1.0)
@given(sc=scenes(), data=st.data())
def test_explain_matches_oracle_on_random_sequences(sc, data, tuning):
    def check(t: Twin, what: str) -> None:
        # After a frame whose near-ties let the two part, their states may differ.
        if t.compared == t.frames and not t.diverged:
            assert_explanations_match(t, what)

    run_sequence(sc, data, tuning, (2, 6), check)


def test_keeping_the_record_still_lets_frames_take_their_output_arrays_back():
    """explain's record of the last frame references the outputs of the frame before it;
    the next frame drops it before its objects stage, which then reuses those arrays (two
    sets of output arrays alternate in a steady scene, buffers.SpareOutputs)."""
    from lightsched.scenes import city, move_lights

    sc = city(500, 40, seed=0)
    s = ls.Scheduler()
    s.set_lights(**sc.lights)
    s.set_objects(**sc.objects)
    addresses = []
    for i in range(6):
        s.update_lights(id=sc.lights["id"], position=move_lights(sc.lights, i + 1))
        addresses.append(s.frame(sc.cameras).light_ids.__array_interface__["data"][0])
    assert addresses[2:] == addresses[:2] * 2


@SCHEDULERS
def test_a_frame_undone_by_its_transaction_leaves_explain_on_the_frame_before(make):
    s = scheduler(make, [NEAR])
    s.frame([CAM])
    with pytest.raises(RuntimeError), s.transaction():
        s.remove_lights(id=[10])
        s.frame([CAM])
        raise RuntimeError("the request failed after its frame")
    e = s.explain(1)
    assert e.frame_index == 0 and reasons(e) == {10: "selected"}
