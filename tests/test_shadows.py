"""Shadowed lights by hand (DESIGN section 2, "Shadowed lights", "slot_shadow"): ranking with
hysteresis, directional lights first, resolution tiers with their hysteresis, and the
per-slot shadow map index. Both schedulers; test_equivalence.py compares them at random."""

import math

import numpy as np
import pytest

import lightsched as ls
import lightsched.reference as ref

SCHEDULERS = pytest.mark.parametrize("cls", [ls.Scheduler, ref.Scheduler], ids=["fast", "oracle"])
FOV = 1.0
CAM = ls.Camera(position=[0, 0, 0], forward=[0, 0, 1], up=[0, 1, 0], fov_y=FOV, aspect=1.0,
                near=0.1, far=1000.0, height_px=1080.0)


def point_lights(ids, z, radius=1.0, priority=0.0, intensity=0.0, shadows=True):
    n = len(ids)
    return dict(id=ids, position=[[0.0, 0.0, z]] * n, radius=[radius] * n,
                intensity=[intensity] * n, priority=np.broadcast_to(priority, n).tolist(),
                shadows=np.broadcast_to(shadows, n).tolist())


def box_at(z, half=0.5):
    return dict(id=[0], bounds_min=[[-half, -half, z - half]], bounds_max=[[half, half, z + half]])


def distance_for(s_px, radius=1.0):
    """Camera distance at which a light of this radius projects to s_px pixels."""
    return 1080.0 * radius / (s_px * math.tan(FOV / 2))


@SCHEDULERS
def test_tier_follows_projected_size_with_hysteresis(cls):
    s = cls(ls.Config(hysteresis=0.1))
    s.set_objects(**box_at(distance_for(395.0)))
    s.set_lights(**point_lights([7], distance_for(395.0)))
    f = s.frame([CAM])
    assert f.shadow_lights.tolist() == [7] and f.shadow_tier.tolist() == [512]
    # The box holds the light: it meets all six cube-face pyramids.
    assert f.caster_offsets.tolist() == [0, 1] and f.caster_ids.tolist() == [0]
    assert f.caster_masks.tolist() == [0b111111]

    def move(s_px):
        z = distance_for(s_px)
        s.update_lights(id=[7], position=[[0.0, 0.0, z]])
        s.update_objects(id=[0], bounds_min=[[-0.5, -0.5, z - 0.5]],
                         bounds_max=[[0.5, 0.5, z + 0.5]])
        return s.frame([CAM]).shadow_tier.tolist()

    assert move(540.0) == [512]     # would be 1024, but 540 <= 512 * 1.1
    assert move(600.0) == [1024]    # left the band
    assert move(480.0) == [1024]    # 480 >= 1024 / 2.2
    assert move(100.0) == [256]     # below the band, and the 256 floor
    assert move(9000.0) == [2048]   # camera inside the light: s = 1080 / t_y = 1977 px


@SCHEDULERS
def test_ranking_hysteresis_and_directional_first(cls):
    s = cls(ls.Config(shadow_budget=2, hysteresis=0.1))
    s.set_objects(**box_at(20.0, half=3.0))
    # Intensity 0: importance is p_user alone, so the ranking is set by hand.
    lights = point_lights([1, 2, 3], 20.0, priority=[1.0, 0.5, 0.2])
    sun = dict(id=[9], type=[2], direction=[[0.0, -1.0, 0.0]], intensity=[0.0],
               priority=[-5.0], shadows=[True])
    s.set_lights(**{k: list(lights[k]) + list(sun.get(k, [0.0] if k != "position" else
                                                       [[0.0, 0.0, 0.0]]))
                    for k in lights}, type=[0, 0, 0, 2],
                 direction=[[0, 0, 1]] * 3 + [[0, -1, 0]])
    f = s.frame([CAM])
    assert f.shadow_lights.tolist() == [9, 1]        # directional first, whatever its key
    assert f.shadow_tier[0] == 4096
    s.update_lights(id=[2], priority=[1.05])          # 1.05 < 1.0 * 1.1: the incumbent stays
    assert s.frame([CAM]).shadow_lights.tolist() == [9, 1]
    s.update_lights(id=[2], priority=[1.2])
    assert s.frame([CAM]).shadow_lights.tolist() == [9, 2]
    s.update_lights(id=[1, 2], priority=[0.3, 0.3])   # equal keys... 2 is the incumbent
    assert s.frame([CAM]).shadow_lights.tolist() == [9, 2]


@SCHEDULERS
def test_only_lights_affecting_a_visible_object_are_candidates(cls):
    s = cls(ls.Config())
    s.set_objects(**box_at(20.0))
    s.set_lights(**point_lights([1, 2], 20.0))
    s.update_lights(id=[2], position=[[8.0, 0.0, 20.0]])  # in view, reaches nothing visible
    f = s.frame([CAM])
    assert f.shadow_lights.tolist() == [1]
    assert f.visible_lights.tolist() == [1, 2]


@SCHEDULERS
def test_slot_shadow_caps_by_weight_then_output_order(cls):
    cfg = ls.Config(max_lights=4, max_shadowed_per_object=2, fade_in=1.0, fade_out=1.0)
    s = cls(cfg)
    s.set_objects(**box_at(20.0, half=2.0))
    # Four lights on the box; 1, 2 and 4 cast shadows; P grows with intensity.
    s.set_lights(id=[1, 2, 3, 4], position=[[0.0, 0.0, 20.0]] * 4, radius=[5.0] * 4,
                 intensity=[4.0, 3.0, 2.0, 1.0], shadows=[True, True, False, True])
    f = s.frame([CAM])
    assert f.light_ids[0].tolist() == [1, 2, 3, 4]
    index = {lid: k for k, lid in enumerate(f.shadow_lights.tolist())}
    # All at weight 1: the first two shadowed slots in output order.
    assert f.slot_shadow[0].tolist() == [index[1], index[2], -1, -1]
    # Light 1 leaves range: it is freed at once; 4 is the second shadowed slot now.
    s.update_lights(id=[1], position=[[0.0, 0.0, 200.0]])
    f = s.frame([CAM], dt=0.5)
    index = {lid: k for k, lid in enumerate(f.shadow_lights.tolist())}
    assert f.light_ids[0].tolist()[:3] == [2, 3, 4]
    assert f.slot_shadow[0].tolist() == [index[2], -1, index[4], -1]


@SCHEDULERS
def test_no_shadow_maps_when_nothing_casts(cls):
    s = cls(ls.Config(shadow_budget=4))
    s.set_objects(**box_at(20.0))
    s.set_lights(**point_lights([1], 20.0, shadows=False))
    f = s.frame([CAM])
    assert f.shadow_lights.size == 0 and f.shadow_tier.dtype == np.uint16
    assert (f.slot_shadow == -1).all() and f.caster_offsets.tolist() == [0]
    if cls is ls.Scheduler:
        assert f.stats["plan"]["shadows"].startswith("skipped")
        assert f.stats["plan"]["casters"].startswith("skipped")
