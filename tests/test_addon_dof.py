"""Blender's depth of field (``camera.data.dof``) -> the core Camera's thin lens, property by property.

Each value set here differs from Blender's default, so a property the exporter skipped fails its
assertion (on main, before depth of field: no lens fields at all and a "not supported" warning).
"""
from __future__ import annotations

import math

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from test_addon_scenes import add_camera, add_mesh, export_now, fresh, linear_keys  # noqa: E402


def _dof_camera(**dof):
    cam = add_camera(location=(0.5, -4.0, 1.0), rotation=(math.radians(80), 0, math.radians(10)), lens=85.0)
    cam.data.dof.use_dof = True
    for k, v in dof.items():
        setattr(cam.data.dof, k, v)
    return cam


def test_every_dof_property_reaches_the_camera():
    fresh()
    add_mesh("cube")
    _dof_camera(focus_distance=3.25, aperture_fstop=1.7, aperture_blades=6,
                aperture_rotation=math.radians(20), aperture_ratio=1.6)
    out, warnings = export_now()
    c = out.camera
    # Cycles: radius = lens [mm] * 1e-3 / (2 fstop) scene units
    assert c.aperture_radius == pytest.approx(85.0e-3 / (2 * 1.7), rel=1e-6)
    assert c.focus_distance == pytest.approx(3.25, rel=1e-6)
    assert c.aperture_blades == 6
    assert c.aperture_rotation == pytest.approx(math.radians(20), rel=1e-6)
    assert c.aperture_ratio == pytest.approx(1.6, rel=1e-6)
    assert not any("depth of field" in w for w in warnings), warnings
    # Orthographic: radius 1 / (2 fstop), as Cycles
    bpy.context.scene.camera.data.type = "ORTHO"
    assert export_now()[0].camera.aperture_radius == pytest.approx(1 / (2 * 1.7), rel=1e-6)
    # use_dof off: a pinhole
    bpy.context.scene.camera.data.dof.use_dof = False
    assert export_now()[0].camera.aperture_radius == 0.0


def test_focus_object_is_projected_on_the_view_axis():
    fresh()
    target = add_mesh("cube", "Target", location=(1.0, 2.0, 0.3))
    cam = _dof_camera(focus_distance=99.0, focus_object=target)
    out, _ = export_now()
    M = np.array(cam.matrix_world)
    z = M[:3, 2] / np.linalg.norm(M[:3, 2])
    want = abs(np.dot(z, M[:3, 3] - np.array([1.0, 2.0, 0.3])))
    assert out.camera.focus_distance == pytest.approx(want, rel=1e-6)
    assert abs(want - np.linalg.norm(M[:3, 3] - np.array([1.0, 2.0, 0.3]))) > 0.05     # projected, not the distance


def test_focus_moving_during_the_shutter_warns_and_takes_the_frame():
    scene = fresh()
    add_mesh("cube")
    cam = _dof_camera()
    for f, d in ((0, 2.0), (2, 4.0)):
        cam.data.dof.focus_distance = d
        cam.data.dof.keyframe_insert("focus_distance", frame=f)
    linear_keys(cam.data)
    scene.render.use_motion_blur, scene.render.motion_blur_shutter = True, 1.0
    scene.frame_set(1)
    out, warnings = export_now()
    assert out.camera.focus_distance == pytest.approx(3.0, rel=1e-5)
    assert any("focus distance changes during the shutter" in w for w in warnings), warnings

