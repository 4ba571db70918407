"""Hand-computed checks of the oracle (lightsched.reference, DESIGN section 2)."""

from __future__ import annotations

import math

import numpy as np
import pytest

import lightsched.reference as ref
from lightsched import Camera, Config

# Camera at the origin looking down +z; 90 degree field of view, square.
CAM = Camera(position=(0.0, 0.0, 0.0), forward=(0.0, 0.0, 1.0), up=(0.0, 1.0, 0.0),
             fov_y=math.pi / 2, aspect=1.0, near=0.1, far=100.0)
R0R0 = 0.1 * 0.1


def box(centre, half):
    c = np.asarray(centre, dtype=float)
    h = np.asarray(half, dtype=float)
    return c - h, c + h


def objects(*boxes, ids=None, **extra):
    ids = list(range(len(boxes))) if ids is None else ids
    lo = np.array([b[0] for b in boxes], dtype=float).reshape(-1, 3)
    hi = np.array([b[1] for b in boxes], dtype=float).reshape(-1, 3)
    return dict(id=ids, bounds_min=lo, bounds_max=hi, **extra)


def slots(frame, row):
    n = int(frame.count[row])
    return frame.light_ids[row, :n].tolist()


# ----------------------------------------------------------------------- priority


def test_point_light_contribution_by_hand():
    # Box [1,3]x[-1,1]x[9,11], light at (0,0,10): d2 = 1, q = 1/16, w = 255/256,
    # e2 = 12, g = min(1, 4*16/12) = 1, P = 2 w^2 / (1 + r0^2) + 0.5.
    f = ref.schedule(dict(id=[4], position=[[0, 0, 10]], radius=[4.0], intensity=[2.0],
                          priority=[0.5]),
                     objects(((1, -1, 9), (3, 1, 11))), [CAM])
    expected = 2 * (255 / 256) ** 2 / (1 + R0R0) + 0.5
    assert f.visible.tolist() == [True]
    assert f.count.tolist() == [1] and f.candidates.tolist() == [1]
    assert f.light_ids[0, 0] == 4 and f.light_index[0, 0] == 0
    assert f.priority[0, 0] == np.float32(expected)
    assert f.fade_weight[0, 0] == 1.0 and f.fade_state[0, 0] == 2
    assert f.light_ids[0, 1:].tolist() == [-1] * 7
    assert f.light_index[0, 1:].tolist() == [-1] * 7
    assert f.priority[0, 1:].tolist() == [0.0] * 7
    assert f.slot_shadow.tolist() == [[-1] * 8]
    assert f.stats["counts"] == {"visible_objects": 1, "visible_lights": 1, "pairs": 1,
                                 "tiles_moved": 0, "texels_rendered": 0}
    assert f.stats["plan"] == {"all": "reference"}


def test_size_factor_g_below_one():
    # Light r = 1.5 at (0.5, 0, 10): d2 = 0.25, q = 1/9, w = 80/81, g = 4*2.25/12 = 0.75.
    f = ref.schedule(dict(id=[0], position=[[0.5, 0, 10]], radius=[1.5]),
                     objects(((1, -1, 9), (3, 1, 11))), [CAM])
    expected = (80 / 81) ** 2 * 0.75 / (0.25 + R0R0)
    assert f.priority[0, 0] == pytest.approx(expected, rel=1e-6)


def test_out_of_range_and_boundary():
    # d2 = 1 = r*r affects (w = 0, P = p_user); r slightly smaller does not.
    lights = dict(id=[0, 1], position=[[0, 0, 10], [0, 0, 10]], radius=[1.0, 0.999],
                  priority=[3.0, 0.0])
    f = ref.schedule(lights, objects(((1, -1, 9), (3, 1, 11))), [CAM])
    assert slots(f, 0) == [0]
    assert f.priority[0, 0] == 3.0


def test_spot_cone_hit_miss_and_partial():
    spot = dict(type=[1], position=[[0, 0, 20]], radius=[10.0], direction=[[1, 0, 0]])
    # On the axis: n = 5 > R = sqrt(3), a = 5 >= sqrt(25 - 3): c = 1, s = 1.
    # d2 = 16, q = 0.16, w = 0.9744, g = 1.
    f = ref.schedule(dict(id=[0], **spot), objects(box((5, 0, 20), (1, 1, 1))), [CAM])
    assert slots(f, 0) == [0]
    assert f.priority[0, 0] == pytest.approx(0.9744 ** 2 / (16 + R0R0), rel=1e-6)
    # Behind the apex and beside it (a = 0 < cos(o) sqrt(22) - R sin(o)): within range,
    # but outside the cone.
    f = ref.schedule(dict(id=[0], **spot),
                     objects(box((-5, 0, 20), (1, 1, 1)), box((0, 5, 20), (1, 1, 1))), [CAM])
    assert f.visible.tolist() == [True, True]
    assert f.count.tolist() == [0, 0] and f.candidates.tolist() == [0, 0]
    # A point box at (4, 3, 0) from the apex: c = a/n = 0.8; inner 0, outer pi/3:
    # s = ((0.8 - 0.5) / (1 - 0.5))^2 = 0.36; d2 = 25, q = 0.25, w = 0.9375, e2 = 0: g = 1.
    part = dict(spot, outer_angle=[math.pi / 3], inner_angle=[0.0])
    f = ref.schedule(dict(id=[0], **part), objects(box((4, 3, 20), (0, 0, 0))), [CAM])
    assert f.priority[0, 0] == pytest.approx(0.9375 ** 2 / (25 + R0R0) * 0.36, rel=1e-6)
    # inner == outer: s is a step; at c = 0.8 >= cos(pi/3) it is 1.
    hard = dict(spot, outer_angle=[math.pi / 3], inner_angle=[math.pi / 3])
    f = ref.schedule(dict(id=[0], **hard), objects(box((4, 3, 20), (0, 0, 0))), [CAM])
    assert f.priority[0, 0] == pytest.approx(0.9375 ** 2 / (25 + R0R0), rel=1e-6)


def test_masks():
    lights = dict(id=[0, 1], position=[[0, 0, 10], [0, 0, 10]], radius=[4.0, 4.0],
                  mask=[0b01, 0b10], intensity=[1.0, 2.0])
    b = ((1, -1, 9), (3, 1, 11))
    f = ref.schedule(lights, objects(b, b, b, ids=[0, 1, 2], mask=[0b10, 0b11, 0b100]), [CAM])
    assert slots(f, 0) == [1]
    assert slots(f, 1) == [1, 0]  # higher intensity first
    assert slots(f, 2) == []
    assert f.candidates.tolist() == [1, 2, 0]
    assert f.stats["counts"]["pairs"] == 3


def test_invisible_object_and_light():
    lights = dict(id=[0, 1], position=[[0, 0, -10], [0, 0, 10]], radius=[4.0, 4.0])
    # Object 0 is behind the camera, object 1 in front.
    f = ref.schedule(lights, objects(box((0, 0, -10), (1, 1, 1)), box((0, 0, 10), (1, 1, 1))),
                     [CAM])
    assert f.visible.tolist() == [False, True]
    assert f.count.tolist() == [0, 1]
    assert f.candidates.tolist() == [0, 1]
    assert f.light_ids[0].tolist() == [-1] * 8
    assert f.visible_lights.tolist() == [1]
    assert f.stats["counts"]["visible_objects"] == 1
    assert f.stats["counts"]["visible_lights"] == 1
    # A ball touching the view from behind the near plane counts as visible.
    f = ref.schedule(dict(id=[0], position=[[0, 0, -1]], radius=[1.2]),
                     objects(box((0, 0, 10), (1, 1, 1))), [CAM])
    assert f.visible_lights.tolist() == [0]


def test_k_cut_candidates_and_rows():
    # Three lights at distances 1, 2, 3 from a point object; ids given out of order.
    lights = dict(id=[30, 10, 20], position=[[0, 0, 11], [0, 0, 12], [0, 0, 13]],
                  radius=[10.0, 10.0, 10.0])
    f = ref.schedule(lights, objects(box((0, 0, 10), (0, 0, 0))), [CAM],
                     Config(max_lights=2))
    assert f.candidates.tolist() == [3]
    assert f.count.tolist() == [2]
    assert f.light_ids[0].tolist() == [30, 10]
    assert f.light_index[0].tolist() == [2, 0]  # rows in ascending id: 10, 20, 30
    q = 1 / 100
    assert f.priority[0, 0] == np.float32((1 - q * q) ** 2 / (1 + R0R0))
    assert f.stats["counts"]["pairs"] == 3


def test_exact_tie_goes_to_lower_id():
    # Mirror positions: bit-identical P.
    lights = dict(id=[7, 3], position=[[1, 0, 10], [-1, 0, 10]], radius=[4.0, 4.0])
    f = ref.schedule(lights, objects(box((0, 0, 10), (0, 0, 0))), [CAM], Config(max_lights=1))
    assert f.candidates.tolist() == [2]
    assert f.light_ids[0].tolist() == [3] and f.light_index[0].tolist() == [0]
    f = ref.schedule(lights, objects(box((0, 0, 10), (0, 0, 0))), [CAM])
    assert f.light_ids[0, :2].tolist() == [3, 7]
    assert f.priority[0, 0] == f.priority[0, 1]


# ----------------------------------------------------------------------- frames


def _p_user_scene(config, priorities, positions=None):
    """Lights of intensity 0 near a point object: P = p_user exactly."""
    n = len(priorities)
    s = ref.Scheduler(config)
    s.set_lights(id=list(range(1, n + 1)), intensity=[0.0] * n, priority=priorities,
                 position=positions if positions is not None else [[0, 0, 11]] * n,
                 radius=[4.0] * n)
    s.set_objects(**objects(box((0, 0, 10), (0, 0, 0))))
    return s


def test_hysteresis_keeps_incumbent_within_ten_percent():
    s = _p_user_scene(Config(max_lights=1, fade_in=0, fade_out=0), [1.0, 0.9])
    f = s.frame([CAM], dt=0.1)
    assert f.light_ids[0, 0] == 1
    s.update_lights(id=[2], priority=[1.05])  # below 1 + 0.1*1
    f = s.frame([CAM], dt=0.1)
    assert f.light_ids[0, 0] == 1
    assert f.priority[0, 0] == 1.0  # the output P carries no hysteresis
    s.update_lights(id=[2], priority=[1.15])
    f = s.frame([CAM], dt=0.1)
    assert f.light_ids[0].tolist() == [2]
    assert f.fade_state[0, 0] == 2 and f.fade_weight[0, 0] == 1.0
    # Now 2 is the incumbent: 1 needs more than 1.15 * 1.1.
    s.update_lights(id=[1], priority=[1.25])
    assert s.frame([CAM], dt=0.1).light_ids[0, 0] == 2
    # hysteresis_abs adds on top.
    s2 = _p_user_scene(Config(max_lights=1, hysteresis=0.0, hysteresis_abs=0.5), [1.0, 0.9])
    s2.frame([CAM], dt=0.1)
    s2.update_lights(id=[2], priority=[1.4])
    assert s2.frame([CAM], dt=0.1, cut=True).light_ids[0, 0] == 1  # cut keeps hysteresis


def test_fade_sequence_replace_with_k_hard_limit():
    # K = 2, dt = 0.1, fades 0.25 s: steps of 0.4.
    far = [0, 0, 50]
    s = _p_user_scene(Config(max_lights=2), [1.0, 2.0, 3.0],
                      positions=[[0, 0, 11], far, far])
    f = s.frame([CAM], dt=0.1)
    assert slots(f, 0) == [1] and f.fade_weight[0, 0] == 1.0 and f.fade_state[0, 0] == 2
    s.update_lights(id=[2, 3], position=[[0, 0, 12], [0, 0, 12]])
    # Frame 1: 1 loses selection (key 1.1 < 2), fades out; 3 takes the free slot; 2 waits.
    f = s.frame([CAM], dt=0.1)
    assert f.candidates[0] == 3
    assert slots(f, 0) == [3, 1]
    assert f.fade_state[0, :2].tolist() == [1, 3]
    assert f.fade_weight[0, :2].tolist() == pytest.approx([0.4, 0.6])
    assert f.priority[0, :2].tolist() == [3.0, 1.0]
    # Frame 2.
    f = s.frame([CAM], dt=0.1)
    assert slots(f, 0) == [3, 1]
    assert f.fade_weight[0, :2].tolist() == pytest.approx([0.8, 0.2])
    assert f.fade_state[0, :2].tolist() == [1, 3]
    # Frame 3: 1 is freed (0.2 - 0.4 <= 0), 3 is on, 2 takes the slot.
    f = s.frame([CAM], dt=0.1)
    assert slots(f, 0) == [3, 2]
    assert f.fade_state[0, :2].tolist() == [2, 1]
    assert f.fade_weight[0, :2].tolist() == pytest.approx([1.0, 0.4])
    assert f.fade_weight[0, 0] == 1.0
    f = s.frame([CAM], dt=0.1)
    assert f.fade_weight[0, :2].tolist() == pytest.approx([1.0, 0.8])
    f = s.frame([CAM], dt=0.1)
    assert f.fade_weight[0, :2].tolist() == [1.0, 1.0]
    assert f.fade_state[0, :2].tolist() == [2, 2]


def test_fade_sequence_k1_waits_for_the_slot():
    s = _p_user_scene(Config(max_lights=1), [1.0, 2.0], positions=[[0, 0, 11], [0, 0, 50]])
    s.frame([CAM], dt=0.1)
    s.update_lights(id=[2], position=[[0, 0, 12]])
    weights = []
    for _ in range(5):
        f = s.frame([CAM], dt=0.1)
        weights.append((int(f.light_ids[0, 0]), float(f.fade_weight[0, 0]),
                        int(f.fade_state[0, 0])))
    assert [w[0] for w in weights] == [1, 1, 2, 2, 2]
    assert [w[2] for w in weights] == [3, 3, 1, 1, 2]
    assert [w[1] for w in weights] == pytest.approx([0.6, 0.2, 0.4, 0.8, 1.0])


def test_cut_and_new_objects_start_on():
    far = [0, 0, 50]
    s = _p_user_scene(Config(max_lights=2), [1.0, 2.0, 3.0],
                      positions=[[0, 0, 11], far, far])
    s.frame([CAM], dt=0.1)
    s.update_lights(id=[2, 3], position=[[0, 0, 12], [0, 0, 12]])
    f = s.frame([CAM], dt=0.1, cut=True)
    assert slots(f, 0) == [3, 2]
    assert f.fade_weight[0, :2].tolist() == [1.0, 1.0]
    assert f.fade_state[0, :2].tolist() == [2, 2]
    # An object removed and set again is new: no fade.
    s.update_lights(id=[1], priority=[5.0])
    s.remove_objects(id=[0])
    s.set_objects(**objects(box((0, 0, 10), (0, 0, 0))))
    f = s.frame([CAM], dt=0.1)
    assert slots(f, 0) == [1, 3]
    assert f.fade_weight[0, :2].tolist() == [1.0, 1.0]


def test_invisible_last_frame_starts_on_and_removed_light_frees_slot():
    s = _p_user_scene(Config(max_lights=2), [1.0, 2.0])
    s.frame([CAM], dt=0.1)
    away = Camera(position=(0, 0, 0), forward=(0, 0, -1), up=(0, 1, 0), fov_y=1.0,
                  aspect=1.0, near=0.1, far=100.0)
    f = s.frame([away], dt=0.1)
    assert f.visible.tolist() == [False] and f.count.tolist() == [0]
    s.update_lights(id=[1], priority=[9.0])
    f = s.frame([CAM], dt=0.1)
    assert slots(f, 0) == [1, 2] and f.fade_weight[0, :2].tolist() == [1.0, 1.0]
    # A removed light no longer affects: its slot is freed at once, no fade out.
    s.remove_lights(id=[1])
    f = s.frame([CAM], dt=0.1)
    assert slots(f, 0) == [2] and f.fade_state[0, 0] == 2
    assert f.light_index[0, 0] == 0


def test_zero_dt_keeps_new_light_at_zero_weight():
    s = _p_user_scene(Config(max_lights=2), [1.0, 2.0], positions=[[0, 0, 11], [0, 0, 50]])
    s.frame([CAM], dt=0.1)
    s.update_lights(id=[2], position=[[0, 0, 12]])
    f = s.frame([CAM], dt=0.0)
    assert slots(f, 0) == [2, 1]
    assert f.fade_state[0, :2].tolist() == [1, 2]
    assert f.fade_weight[0, :2].tolist() == [0.0, 1.0]


# ----------------------------------------------------------------------- directional


def test_directional_lights_ordering_and_in_slots():
    lights = dict(id=[5, 1, 3, 8], type=[2, 2, 2, 0], direction=[[0, -1, 0]] * 4,
                  position=[[0, 0, 0], [0, 0, 0], [0, 0, 0], [0, 0, 11]],
                  radius=[1.0, 1.0, 1.0, 4.0], intensity=[1.0, 2.0, 0.5, 0.0],
                  priority=[1.0, 0.0, 0.5, 0.0], mask=[1, 1, 2, 1])
    obj = objects(box((0, 0, 10), (0, 0, 0)), mask=[1])
    f = ref.schedule(lights, obj, [CAM])
    # P: 5 -> 2, 1 -> 2 (tie, lower id first), 3 -> 1; masks do not matter here.
    assert f.directional_lights.tolist() == [1, 5, 3]
    assert slots(f, 0) == [8] and f.candidates.tolist() == [1]
    assert f.visible_lights.tolist() == [1, 3, 5, 8]
    f = ref.schedule(lights, obj, [CAM], Config(directional_in_slots=True))
    assert f.directional_lights.tolist() == []
    assert slots(f, 0) == [1, 5, 8]  # light 3 is masked out
    assert f.priority[0, :3].tolist() == [2.0, 2.0, 0.0]
    assert f.candidates.tolist() == [3]


def test_unshadowed_skip():
    lights = dict(id=[0, 1, 2], type=[0, 0, 2], position=[[0, 0, 11]] * 3,
                  radius=[4.0] * 3, direction=[[0, -1, 0]] * 3, shadows=[True, False, True])
    obj = objects(box((0, 0, 10), (0, 0, 0)))
    f = ref.schedule(lights, obj, [CAM])
    assert sorted(slots(f, 0)) == [0, 1] and f.directional_lights.tolist() == [2]
    # Both shadowed lights get a map (directional first): "skip" removes nothing.
    f = ref.schedule(lights, obj, [CAM], Config(unshadowed="skip"))
    assert f.shadow_lights.tolist() == [2, 0] and f.shadow_tier[0] == 4096
    assert sorted(slots(f, 0)) == [0, 1] and f.directional_lights.tolist() == [2]
    # One map: the sun keeps it, the shadowed point light affects nothing.
    f = ref.schedule(lights, obj, [CAM], Config(unshadowed="skip", shadow_budget=1))
    assert f.shadow_lights.tolist() == [2]
    assert slots(f, 0) == [1] and f.directional_lights.tolist() == [2]
    # No maps: both shadowed lights are dropped.
    f = ref.schedule(lights, obj, [CAM], Config(unshadowed="skip", shadow_budget=0))
    assert slots(f, 0) == [1] and f.directional_lights.tolist() == []
    assert f.visible_lights.tolist() == [0, 1, 2]
    assert f.shadow_lights.tolist() == [] and f.caster_offsets.tolist() == [0]


# ----------------------------------------------------------------------- thesis


def test_thesis_light_straight_ahead_and_off_axis():
    cfg = Config(model="thesis")
    obj = objects(box((0, 0, 12), (1, 1, 1)))
    # Straight ahead: theta = 0, f = 1; d_viewer = 10, d_object = 2, i = 1:
    # P = 1 - 0.01*10 - 0.1*2 + 0.1*1 = 0.8.
    f = ref.schedule(dict(id=[0], position=[[0, 0, 10]], radius=[2.0]), obj, [CAM], cfg)
    assert f.priority[0, 0] == pytest.approx(0.8, rel=1e-6)
    # Camera inside the light: f = 1 whatever the angle.
    f = ref.schedule(dict(id=[0], position=[[0, 0, 10]], radius=[12.0]), obj, [CAM], cfg)
    assert f.priority[0, 0] == pytest.approx(0.8, rel=1e-6)
    # Off axis at 45 degrees: light (1.5, 0, 1.5), r = 1, box touching it.
    d = math.sqrt(4.5)
    alpha = math.asin(1 / d)
    ecc = math.exp(-(math.pi / 4 - alpha) / 0.25)
    c = (2.5, 0.0, 2.5)
    d_obj = math.sqrt(2)
    f = ref.schedule(dict(id=[0], position=[[1.5, 0, 1.5]], radius=[1.0], priority=[2.0]),
                     objects(box(c, (0.5, 0.5, 0.5))), [CAM], cfg)
    assert f.priority[0, 0] == pytest.approx(ecc - 0.01 * d - 0.1 * d_obj + 0.1 + 2.0,
                                             rel=1e-6)
    # The focus moves the focal ray: with focus.x such that g points at the light, f = 1.
    # r = f x up = (-1, 0, 0) here, so focus.x = -1 aims at +x; aspect 1, t_x = 1.
    aim = Camera(position=(0, 0, 0), forward=(0, 0, 1), up=(0, 1, 0), fov_y=math.pi / 2,
                 aspect=1.0, near=0.1, far=100.0, focus=(-1.0, 0.0))
    f = ref.schedule(dict(id=[0], position=[[1.5, 0, 1.5]], radius=[1.0], priority=[2.0]),
                     objects(box(c, (0.5, 0.5, 0.5))), [aim], cfg)
    assert f.priority[0, 0] == pytest.approx(1 - 0.01 * d - 0.1 * d_obj + 0.1 + 2.0, rel=1e-6)
    # Two cameras: the max over cameras.
    f = ref.schedule(dict(id=[0], position=[[1.5, 0, 1.5]], radius=[1.0], priority=[2.0]),
                     objects(box(c, (0.5, 0.5, 0.5))), [CAM, dict(vars(aim), id=1)], cfg)
    assert f.priority[0, 0] == pytest.approx(1 - 0.01 * d - 0.1 * d_obj + 0.1 + 2.0, rel=1e-6)


# ----------------------------------------------------------------------- cascades


def test_cascade_splits():
    cam = Camera(position=(0, 0, 0), forward=(0, 0, 1), up=(0, 1, 0), fov_y=1.0, aspect=1.5,
                 near=1.0, far=1000.0)
    short = Camera(position=(0, 0, 0), forward=(0, 0, 1), up=(0, 1, 0), fov_y=1.0,
                   aspect=1.5, near=1.0, far=100.0, id=1)
    hidden = objects(box((0, 0, -10), (1, 1, 1)))  # behind both cameras
    f = ref.schedule(dict(id=[]), hidden, [cam, short])
    assert f.cascade_splits.shape == (2, 5) and f.cascade_splits.dtype == np.float64
    # D = 150: z_i = 0.5 * 150^(i/4) + 0.5 * (1 + 149 i / 4).
    expected = [1.0,
                0.5 * 150 ** 0.25 + 19.125,
                0.5 * math.sqrt(150) + 37.75,
                0.5 * 150 ** 0.75 + 56.375,
                150.0]
    assert f.cascade_splits[0].tolist() == pytest.approx(expected, rel=1e-12)
    assert f.cascade_splits[0, 0] == 1.0 and f.cascade_splits[0, 4] == 150.0
    # far = 100 < shadow_distance: D = 100.
    assert f.cascade_splits[1].tolist() == pytest.approx(
        [1.0, 0.5 * 100 ** 0.25 + 0.5 * (1 + 99 / 4), 0.5 * 10 + 0.5 * (1 + 49.5),
         0.5 * 100 ** 0.75 + 0.5 * (1 + 74.25), 100.0], rel=1e-12)
    f = ref.schedule(dict(id=[]), hidden, [cam], Config(cascades=2))
    assert f.cascade_splits.shape == (1, 3)


def test_no_lights():
    f = ref.schedule(dict(id=[]), objects(box((0, 0, 10), (1, 1, 1))), [CAM],
                     Config(max_lights=3))
    assert f.light_ids.tolist() == [[-1, -1, -1]] and f.visible.tolist() == [True]
    assert f.directional_lights.dtype == np.int32 and f.visible_lights.size == 0
    assert f.stats["counts"] == {"visible_objects": 1, "visible_lights": 0, "pairs": 0,
                                 "tiles_moved": 0, "texels_rendered": 0}


def test_empty_scene_and_shapes():
    f = ref.schedule(dict(id=[]), dict(id=[], bounds_min=np.zeros((0, 3)),
                                       bounds_max=np.zeros((0, 3))), [CAM],
                     Config(max_lights=3))
    assert f.light_ids.shape == (0, 3)
    assert f.directional_lights.dtype == np.int32 and f.visible_lights.size == 0
    assert f.stats["counts"] == {"visible_objects": 0, "visible_lights": 0, "pairs": 0,
                                 "tiles_moved": 0, "texels_rendered": 0}
