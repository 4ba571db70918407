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
