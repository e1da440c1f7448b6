"""KD4D's automatic time scale (stpm_core/photons/timescale.py): s = sqrt(2) v_max, floored when static."""
from __future__ import annotations

import numpy as np

from scenes import box_mesh, make_scene, moving, ortho_camera_down, plane_mesh, point_light, translate
from stpm_core.motion import MotionTransform
from stpm_core.photons.timescale import STATIC_FRACTION, auto_time_scale, max_motion_speed
from stpm_core.scene import Light, Material
from stpm_core.shutter import Shutter


def _scene(objects, lights):
    mats = [Material.diffuse((0.8, 0.8, 0.8))]
    return make_scene(objects, mats, ortho_camera_down(), lights, shutter=Shutter(1.0, 2.0))


def _rot_y(angle):
    c, s = np.cos(angle), np.sin(angle)
    M = np.eye(4)
    M[0, 0], M[0, 2], M[2, 0], M[2, 2] = c, s, -s, c
    return M


def _sun(transform):
    return Light(type="SUN", power=3.0, transform=transform, name="sun")


def test_moving_box_sets_the_scale():
    sc = _scene([plane_mesh(4.0), (box_mesh((0, 0, 0), (0.2, 0.2, 0.2)), moving((0, 0, 0), (1.5, 0, 0)))],
                [point_light((0, 0, 2), 100.0)])
    assert np.isclose(max_motion_speed(sc), 1.5, rtol=1e-9)
    assert np.isclose(auto_time_scale(sc), np.sqrt(2) * 1.5, rtol=1e-9)


def test_static_scene_uses_the_floor():
    sc = _scene([plane_mesh(4.0)], [point_light((0, 0, 2), 100.0)])
    lo, hi = sc.bounds()
    assert max_motion_speed(sc) == 0.0
    assert np.isclose(auto_time_scale(sc), STATIC_FRACTION * np.linalg.norm(hi - lo))


def test_translating_sun_does_not_count():
    """A SUN's position moves no photon: only its direction does."""
    slide = MotionTransform(times=np.array([0.0, 1.0]), matrices=np.stack([translate(0, 0, 5), translate(500, 0, 5)]))
    sc = _scene([plane_mesh(4.0)], [_sun(slide)])
    assert max_motion_speed(sc) == 0.0


def test_turning_sun_counts_its_angular_speed_times_the_scene_radius():
    turn = MotionTransform(times=np.array([0.0, 1.0]), matrices=np.stack([_rot_y(0.0), _rot_y(0.2)]))
    sc = _scene([plane_mesh(4.0)], [_sun(turn)])
    lo, hi = sc.bounds()
    radius = 0.5 * np.linalg.norm(hi - lo)
    assert np.isclose(max_motion_speed(sc), 0.2 * radius, rtol=1e-3)


def test_sun_with_a_zero_direction_at_some_time_does_not_count():
    """Z scaled to 0 at one key: the sun has no direction there and emits nothing; no bogus speed."""
    flat = np.eye(4)
    flat[2, 2] = 0.0
    turn = MotionTransform(times=np.array([0.0, 1.0]), matrices=np.stack([np.eye(4), flat]))
    sc = _scene([plane_mesh(4.0)], [_sun(turn)])
    assert max_motion_speed(sc) == 0.0
