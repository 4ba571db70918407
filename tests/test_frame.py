"""Frames are read-only snapshots: a kept frame never changes when later frames run (the fast
scheduler keeps a frame's light_ids and fade_state as its next frame's slot state)."""

import numpy as np
import pytest

import lightsched as ls
import lightsched.reference as ref
from lightsched import scenes


@pytest.mark.parametrize("cls", [ls.Scheduler, ref.Scheduler], ids=["fast", "oracle"])
def test_frames_are_read_only_snapshots(cls):
    sc = scenes.city(400, 60, seed=3)
    s = cls(ls.Config(max_lights=4))
    s.set_lights(**sc.lights)
    s.set_objects(**sc.objects)
    first = s.frame(sc.cameras)
    kept = {name: arr.copy() for name, arr in first.arrays().items()}
    for name, arr in first.arrays().items():
        assert not arr.flags.writeable, name
    with pytest.raises(ValueError):
        first.light_ids[0, 0] = 123
    for i in range(1, 4):
        s.update_lights(id=sc.lights["id"], position=scenes.move_lights(sc.lights, i))
        s.frame(sc.cameras, dt=0.1)
    for name, arr in first.arrays().items():
        np.testing.assert_array_equal(arr, kept[name], err_msg=name)


def test_frame_fields_are_the_one_field_list():
    """lightsched.fields lists the arrays once; the Frame dataclass, FRAME_ARRAYS and
    PER_OBJECT (the object pass's order, which the scheduler relies on) follow it."""
    import dataclasses

    from lightsched.fields import FIELDS, FRAME_FIELDS, PER_OBJECT_NAMES
    from lightsched.frame import FRAME_ARRAYS, PER_OBJECT, empty_frame

    names = [f.name for f in FIELDS]
    assert list(FRAME_FIELDS) == names
    assert [f.name for f in dataclasses.fields(ls.Frame)] == names + ["stats"]
    assert list(FRAME_ARRAYS) == names
    assert FRAME_ARRAYS == {f.name: f.dtype for f in FIELDS}
    assert list(PER_OBJECT) == ["visible", "light_ids", "light_index", "priority",
                                "fade_weight", "fade_state", "count", "candidates",
                                "slot_shadow", "residual"]
    assert sorted(PER_OBJECT) == sorted(PER_OBJECT_NAMES)
    assert PER_OBJECT["light_ids"] == (np.int32, "NK", -1)
    assert PER_OBJECT["visible"] == (np.bool_, "N", False)
    assert PER_OBJECT["slot_shadow"] == (np.int8, "NK", -1)
    assert PER_OBJECT["residual"] == (np.float32, "N4", 0.0)
    f = empty_frame(np.array([4, 9, 12], np.int32), k=3, cascades=2)
    shapes = {"object_id": (3,), "visible": (3,), "count": (3,), "candidates": (3,),
              "cascade_splits": (0, 3), "caster_offsets": (1,), "residual": (3, 4),
              "shadow_rect": (0, 6, 3)}
    for field in FIELDS:
        a = getattr(f, field.name)
        assert a.dtype == np.dtype(field.dtype), field.name
        want = shapes.get(field.name, (3, 3) if field.shape == ("N", "K") else (0,))
        assert a.shape == want, field.name
        if field.per_object:
            assert (a == field.empty).all(), field.name
