"""The world lights the scene (stpm_core/world_light.py): constant radiance L from every direction.

Analytic answers: an unoccluded diffuse surface of albedo rho under L has irradiance pi L and
radiance rho L; world photons through a closed receiver carry 4 pi * pi R^2 * L in all, and the
ones landing on a plane of area A from one side carry pi L A.
"""
from __future__ import annotations

import numpy as np
import pytest

from oracles.emission_numpy import world_emit
from scenes import box_mesh, make_scene, ortho_camera_down, plane_mesh, sphere_mesh
from stpm_core.lights import LightSet
from stpm_core.plan import make_plan
from stpm_core.raycast import make_caster
from stpm_core.render import render
from stpm_core.scene import Material
from stpm_core.settings import RenderSettings
from stpm_core.world_light import WorldLight

L_WORLD = np.array([0.5, 0.25, 1.0])


def _settings(**kw):
    d = dict(samples=8, photons_caustic=0, photons_global=0, effects="MANUAL", caustics=False, indirect=False,
             seed=2, filter_width=0.0)
    d.update(kw)
    return RenderSettings(**d)


def test_diffuse_plane_under_the_world_has_radiance_rho_L():
    """Only the upper hemisphere sees the plane: E = pi L, radiance rho L, noise-free with cosine sampling."""
    scene = make_scene([plane_mesh(4.0)], [Material.diffuse((0.8, 0.8, 0.8))], ortho_camera_down(2.0, 1.0),
                       world=L_WORLD, resolution=(16, 16))
    r = render(scene, _settings())
    direct = r.passes["Direct"].reshape(-1, 3)
    np.testing.assert_allclose(direct, np.broadcast_to(0.8 * L_WORLD, direct.shape), rtol=1e-6)
    assert not any("no lights" in w for w in r.warnings)


def test_convex_sphere_sees_only_the_world():
    """Every point of a convex sphere sees half the world, unoccluded: radiance rho L everywhere."""
    scene = make_scene([sphere_mesh(0.5, 16, 32)], [Material.diffuse((0.6, 0.6, 0.6))], ortho_camera_down(3.0, 1.2),
                       world=L_WORLD, resolution=(24, 24))
    r = render(scene, _settings())
    depth = r.passes["Depth"][..., 0]
    inside = depth < 2.8                       # sphere pixels fully covered (centre region)
    vals = r.passes["Direct"][inside]
    assert inside.sum() > 100
    np.testing.assert_allclose(vals.mean(axis=0), 0.6 * L_WORLD, rtol=0.01)


def test_box_on_a_plane_shadows_the_world():
    """Floor next to a box sees less sky than floor far away (ambient occlusion), never more, never < 0."""
    scene = make_scene([plane_mesh(12.0), box_mesh((-0.3, -0.3, 0.0), (0.3, 0.3, 1.0))],
                       [Material.diffuse((0.8, 0.8, 0.8))], ortho_camera_down(3.0, 6.0), world=(1.0, 1.0, 1.0),
                       resolution=(48, 48))
    r = render(scene, _settings(samples=16))
    D = r.passes["Direct"][..., 0]
    floor = np.abs(r.passes["Depth"][..., 0] - 3.0) < 1e-6
    iy, ix = np.mgrid[0:48, 0:48]
    dist = np.hypot(ix + 0.5 - 24, iy + 0.5 - 24) * (6.0 / 48)          # metres from the box's axis
    near, far = floor & (dist < 0.6), floor & (dist > 2.8)
    assert near.sum() > 10 and far.sum() > 100
    assert np.all(D >= 0)
    # 2.8 m from a 1 m tall box it hides at most 1 - cos^2 of 20 deg of the cosine-weighted sky, x its
    # 0.6 m width over a 2 pi 2.8 m circle: under 1 %
    assert D[far].mean() == pytest.approx(0.8, rel=0.02)
    assert D[near].mean() < 0.85 * D[far].mean()


def test_world_photons_carry_the_flux_through_the_scene_sphere():
    w = WorldLight(L_WORLD, center=(0, 0, 0), radius=2.0)
    np.testing.assert_allclose(w.flux(), 4 * np.pi * np.pi * 4.0 * L_WORLD)
    rng = np.random.default_rng(1)
    o, d, Phi = world_emit(w, 200_000, rng)
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0)
    np.testing.assert_allclose(Phi.sum(axis=0), w.flux())
    assert np.all(np.linalg.norm(o, axis=1) >= 2.0 * 2.0 - 1e-9)   # every photon starts outside the sphere
    # Photons crossing the plane z = 0 inside |x|, |y| < 0.5 from above: pi L A (A = 1 m^2)
    t = -o[:, 2] / np.where(d[:, 2] == 0, np.inf, d[:, 2])
    x = o + t[:, None] * d
    down = (d[:, 2] < 0) & (np.abs(x[:, 0]) < 0.5) & (np.abs(x[:, 1]) < 0.5)
    np.testing.assert_allclose(Phi[down].sum(axis=0), np.pi * L_WORLD * 1.0, rtol=0.03)


def test_world_in_lightset_and_plan():
    mats = [Material.diffuse((0.8, 0.8, 0.8)), Material.mirror()]
    scene = make_scene([plane_mesh(4.0), box_mesh((-0.3, -0.3, 0.5), (0.3, 0.3, 0.8), material=1),
                        box_mesh((1.0, 1.0, 0.0), (1.4, 1.4, 0.4))], mats, ortho_camera_down(3.0, 2.0),
                       world=(0.2, 0.2, 0.2), resolution=(16, 16))
    lights = LightSet(scene)
    assert [l.type for l in lights.lights] == ["WORLD"]
    plan = make_plan(scene, RenderSettings(), caster=make_caster(scene), lights=lights)
    assert "world" in plan["details"]["lights"]
    assert plan["indirect"] and plan["caustics"]         # sky bounces between floor and box; the mirror focuses it
    dark = make_scene([plane_mesh(4.0)], mats, ortho_camera_down(3.0, 2.0), resolution=(16, 16))
    assert [l.type for l in LightSet(dark).lights] == []


def test_world_indirect_light_reaches_under_a_roof():
    """A floor under a diffuse roof gets world light only by bounces: the Indirect pass, when asked for."""
    scene = make_scene([plane_mesh(8.0), box_mesh((-1.0, -1.0, 0.6), (1.0, 1.0, 0.7))],
                       [Material.diffuse((0.8, 0.8, 0.8))], ortho_camera_down(0.3, 0.6), world=(1.0, 1.0, 1.0),
                       resolution=(8, 8))
    # the camera sits under the roof (z = 0.3), looking down at the floor
    r_off = render(scene, _settings())
    r_on = render(scene, _settings(photons_global=100_000, indirect=True))
    assert r_off.passes["Indirect"].max() == 0.0
    ind = r_on.passes["Indirect"][..., 0]
    assert np.all(np.isfinite(ind)) and ind.min() >= 0.0 and ind.mean() > 0.05
    # direct light there comes in sideways only, under a 2 x 2 m roof 0.6 m up: well below 0.8
    assert r_on.passes["Direct"][..., 0].mean() < 0.5
