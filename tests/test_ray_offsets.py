"""Secondary-ray origin offsets are local to the object hit (raycast.geometry.instance_offsets).

Before, every offset was 1e-5 x the whole scene's diagonal: one far object (1 m box 100 km away)
pushed shadow-ray origins 1 m off the floor, above a slab 1 m up, and the slab's shadow vanished.
"""
from __future__ import annotations

import numpy as np

from scenes import box_mesh, make_scene, moving, ortho_camera_down, plane_mesh, point_light, translate
from stpm_core.raycast.geometry import OFFSET_POS, OFFSET_REL, instance_offsets, offset_lengths
from stpm_core.render import render
from stpm_core.scene import Material
from stpm_core.settings import RenderSettings

MATS = [Material.diffuse((0.8, 0.8, 0.8))]


def _slab_scene(extra=()):
    """A 1 x 1 m slab 1 m above a 6 m floor, under a point light at z = 3; ortho view from z = 5."""
    objs = [plane_mesh(6.0), box_mesh((-0.5, -0.5, 1.0), (0.5, 0.5, 1.2))] + list(extra)
    return make_scene(objs, MATS, ortho_camera_down(5.0, 4.0), [point_light((0, 0, 3.0), 300.0)], resolution=(32, 24))


def _floor_direct(scene):
    r = render(scene, RenderSettings(samples=2, photons_caustic=0, photons_global=0, effects="MANUAL",
                                     caustics=False, indirect=False, seed=3, filter_width=0.0))
    floor = np.abs(r.passes["Depth"][..., 0] - 5.0) < 1e-3
    return r.passes["Direct"][..., 0], floor


def test_a_far_object_leaves_shadows_alone():
    near, floor = _floor_direct(_slab_scene())
    far, floor_far = _floor_direct(_slab_scene([(box_mesh((0, 0, 0), (1, 1, 1)), translate(1e5, 0, 0))]))
    # The static geometry is baked in float32 about the scene's centre, now 50 km away: edges of
    # the slab may move by a pixel; everything else must not change
    both = floor & floor_far
    assert (floor != floor_far).sum() <= 2
    shadow = both & (near == 0.0)
    assert shadow.sum() > 20                               # the slab's shadow on the floor
    assert np.all(far[shadow] == 0.0)                      # still there with a box 100 km away
    assert abs(far[both].mean() / near[both].mean() - 1.0) < 5e-3
    # (before the offsets were local: 1 m offsets, min floor Direct 0.32, mean +20 %)


def test_offsets_follow_the_object_not_its_motion_or_the_scene():
    slide = moving((0, 0, 0), (1e4, 0, 0))             # a 1 m box sliding 10 km
    scene = _slab_scene([(box_mesh((0, 0, 0), (1, 1, 1)), slide)])
    off = instance_offsets(scene)
    assert np.isclose(off[0], OFFSET_REL * np.sqrt(6.0 ** 2 + 6.0 ** 2))           # floor: its own diagonal
    assert np.isclose(off[2], OFFSET_REL * np.sqrt(3.0))                            # box: 1 m cube, motion ignored
    p = np.array([[0.0, 0.0, 0.0], [2e3, -5.0, 1.0]])
    e = offset_lengths(off, np.array([2, 2]), p)
    np.testing.assert_allclose(e, off[2] + OFFSET_POS * np.array([0.0, 2e3]))      # + float32 resolution at p


def test_a_far_object_leaves_the_shadow_of_a_thin_sheet_near_the_floor():
    """The guard of secondary rays is local too.  A one-quad sheet 8 cm above the floor, lit from low
    (light at x = 3 m, z = 0.5 m), throws its shadow beside itself; the floor's shadow rays meet the
    sheet about 0.5 m from their origin.  With a box 1000 km away the old global guard (1e-6 x the
    diagonal: 1 m) skipped it and the shadow was gone."""
    def scene(extra=()):
        objs = [plane_mesh(6.0), (plane_mesh(1.0), translate(0.0, 0.0, 0.08))] + list(extra)
        return make_scene(objs, MATS, ortho_camera_down(5.0, 4.0), [point_light((3.0, 0.0, 0.5), 300.0)],
                          resolution=(32, 24))
    near, floor = _floor_direct(scene())
    far, _ = _floor_direct(scene([(box_mesh((0, 0, 0), (1, 1, 1)), translate(1e6, 0, 0))]))
    shadow = floor & (near == 0.0)
    assert shadow.sum() > 20                               # the sheet's shadow, beside it on the floor
    assert np.mean(far[shadow] == 0.0) > 0.95
