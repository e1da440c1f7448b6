"""A sun of angle > 0 seen along rays that escape the scene: its glint in mirrors and water (analytic).

A SUN of angular diameter ``angle`` is a disc at infinity of radiance
``L_sun = color S / (pi sin^2(angle / 2))`` (Cycles' normalisation: a facing surface receives S;
docs/lights-and-materials.md, "Sun"), the radiance behind next-event estimation's weight
``color S Omega / (pi sin^2(angle / 2))`` and density ``1 / Omega``, ``Omega = 2 pi (1 - cos(angle / 2))``.  Cycles' rays see it where they
escape within its cone (``distant_light_intersect``); STPM's did not until 2026-12-06 (a review
measured a water plane's glint at 0.34 against Cycles' 9.93).  An orthographic camera looking
straight down at a plane sees, in a perfect mirror, the single direction +Z: the whole image is the
sun's radiance times the mirror's reflectance where +Z lies within the sun's cone, else black.

* chrome (Metallic 1, Roughness 0, base colour F0): every pixel ``F0 L_sun`` exactly
  (at normal incidence the metal's Fresnel is its base colour); the sun tilted 2 degrees (inside its
  2.5-degree half angle): the same; tilted 3 degrees: 0; a sun of angle 0 is never seen;
* water (IOR 1.33, Roughness 0): the reflection is drawn with some probability and the refraction
  escapes downward; the image's mean converges to ``F(0) L_sun``,
  ``F(0) = ((n - 1) / (n + 1))^2``;
* camera rays see the sun only with Blender's Object > Visibility > Camera (off by default, as in
  Cycles 5.0: measured with bpy, a camera looking into a 10-degree sun of strength 3 sees black;
  with the flag, Cycles shows 125.71 = S / (pi sin^2(5 deg)) to float precision).

Each of these failed before the sun could be seen (every pixel 0).
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from scenes import make_scene, ortho_camera_down, plane_mesh
from stpm_core.motion import MotionTransform
from stpm_core.render import render
from stpm_core.scene import Light, Material
from stpm_core.settings import RenderSettings

ANGLE = math.radians(5.0)
S = 3.0
COLOR = np.array([1.0, 0.9, 0.8])
L_SUN = COLOR * S / (math.pi * math.sin(0.5 * ANGLE) ** 2)        # W m^-2 sr^-1


def _rot_x(a):
    c, s = math.cos(a), math.sin(a)
    M = np.eye(4)
    M[1:3, 1:3] = [[c, -s], [s, c]]
    return M


def _sun(tilt_deg: float = 0.0, angle: float = ANGLE, **kw) -> Light:
    """A SUN overhead (its +Z toward the sun), tilted about X by tilt_deg."""
    return Light(type="SUN", power=S, angle=angle, color=COLOR,
                 transform=MotionTransform.static(_rot_x(math.radians(tilt_deg))), **kw)


def _plane_render(material, sun, resolution=(8, 8), samples=4, seed=1):
    scene = make_scene([plane_mesh(10.0)], [material], ortho_camera_down(), [sun], resolution=resolution)
    res = render(scene, RenderSettings(samples=samples, seed=seed, photons_caustic=0, photons_global=0))
    return np.asarray(res.passes["Combined"][..., :3], np.float64).reshape(-1, 3)


@pytest.mark.parametrize("tilt, inside", [(0.0, True), (2.0, True), (3.0, False)])
def test_a_mirror_shows_the_sun_with_its_radiance(tilt, inside):
    F0 = np.array([0.9, 0.8, 0.7])
    px = _plane_render(Material.mirror(tuple(F0)), _sun(tilt))
    want = F0 * L_SUN if inside else np.zeros(3)
    np.testing.assert_allclose(px, np.broadcast_to(want, px.shape), rtol=1e-5, atol=1e-9)


def test_a_sun_of_angle_zero_is_never_seen():
    px = _plane_render(Material.mirror((0.9, 0.9, 0.9)), _sun(0.0, angle=0.0))
    assert np.all(px == 0.0)


def test_water_reflects_the_sun_with_its_fresnel_reflectance():
    n = 1.33
    F = ((n - 1.0) / (n + 1.0)) ** 2
    px = _plane_render(Material.glass(n), _sun(0.0), resolution=(24, 24), samples=16)
    want = F * L_SUN
    mean, se = px.mean(axis=0), px.std(axis=0) / math.sqrt(px.shape[0])
    assert np.all(np.abs(mean - want) < 4.0 * se + 1e-6 * want), (mean, se, want)
    assert np.all(se < 0.1 * want)                  # enough reflections drawn for the test to mean something


@pytest.mark.parametrize("visible", [False, True])
def test_camera_rays_see_the_sun_only_with_visible_camera(visible):
    # an orthographic camera looking straight up into the sun (every ray along +Z): Cycles' default
    # (visible_camera off) shows nothing
    cam = ortho_camera_down()
    cam.transform = MotionTransform.static(_rot_x(math.pi))
    scene = make_scene([plane_mesh(2.0, z=-1.0)], [Material.diffuse()], cam, [_sun(0.0)], resolution=(6, 6),
                       metadata={"light_visible_camera": [visible]})
    res = render(scene, RenderSettings(samples=2, seed=0, photons_caustic=0, photons_global=0))
    px = np.asarray(res.passes["Combined"][..., :3], np.float64).reshape(-1, 3)
    want = L_SUN if visible else np.zeros(3)
    np.testing.assert_allclose(px, np.broadcast_to(want, px.shape), rtol=1e-5, atol=1e-9)
