"""Environment-image worlds (stpm_core/world_light.py, stpm_core/kernels/environment.py).

Analytic answers, with numpy oracles written here independently of the kernels:

* the sampling density integrates to 1 and the density of a drawn direction is the density
  the kernel reports for it; a histogram of drawn directions follows the image;
* a plane under an image with a small bright patch receives the cosine-weighted integral of the
  image (within 1 %), the patch casting a sharp shadow;
* with a box filter and Closest interpolation a background pixel is the texel under the camera
  ray (to float32 rounding), turned by the mapping;
* world photons carry the image's flux: through a plane from above, pi R^2-disc geometry gives
  the plane the same power as the cosine-weighted integral.
"""
from __future__ import annotations

import numpy as np
import pytest

from scenes import make_scene, ortho_camera_down, plane_mesh, persp_camera
from stpm_core.kernels.environment import env_lookup_batch, env_pdf_batch, env_sample_batch
from stpm_core.lights import LightSet
from stpm_core.motion import MotionTransform
from stpm_core.raycast import make_caster
from stpm_core.render import render
from stpm_core.scene import Material, World, sphere_mean
from stpm_core.settings import RenderSettings
from stpm_core.world_light import environment_arrays

ID = np.eye(4)[None].copy()


def _direction(u, v):
    """Cycles' equirectangular (u, v) -> unit direction (oracle: the inverse of the kernels' map)."""
    theta, phi = np.pi * (1.0 - v), np.pi - 2.0 * np.pi * u
    return np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], axis=-1)


def _rot_z(a):
    c, s = np.cos(a), np.sin(a)
    M = np.eye(4)
    M[:2, :2] = [[c, -s], [s, c]]
    return M


def sky_with_sun(H=64, W=128, sun_uv=(0.3, 0.78), sun_texels=2, sky=0.2, sun=400.0):
    """A dim sky gradient plus a bright square patch of sun_texels^2 texels at sun_uv."""
    v = (np.arange(H) + 0.5) / H
    img = np.empty((H, W, 3), np.float32)
    img[...] = (sky * (0.5 + v))[:, None, None] * np.array([0.8, 0.9, 1.0], np.float32)
    img[v < 0.5] = 0.05
    j, i = int(sun_uv[1] * H), int(sun_uv[0] * W)
    img[j:j + sun_texels, i:i + sun_texels] = sun
    return img


def image_irradiance(img, n=(0.0, 0.0, 1.0), k=8):
    """Oracle: E = sum over texels of L cos+ dOmega (Closest: constant per texel), each texel split
    into k x k sub-cells for the cosine and solid angle."""
    H, W = img.shape[:2]
    us = (np.arange(W * k) + 0.5) / (W * k)
    vs = (np.arange(H * k) + 0.5) / (H * k)
    U, V = np.meshgrid(us, vs)
    d = _direction(U, V)
    dOmega = (2 * np.pi / (W * k)) * (np.pi / (H * k)) * np.sin(np.pi * V)
    cos = np.maximum(d @ np.asarray(n, float), 0.0)
    L = img[(V * H).astype(int), (U * W).astype(int)].astype(np.float64)
    return (L * (cos * dOmega)[..., None]).sum(axis=(0, 1))


def _settings(**kw):
    d = dict(samples=16, photons_caustic=0, photons_global=0, effects="MANUAL", caustics=False, indirect=False,
             seed=3, filter_width=0.0)
    d.update(kw)
    return RenderSettings(**d)


def _image_scene(img, objects, camera, mapping=None, interpolation="CLOSEST", resolution=(16, 16), materials=None):
    sc = make_scene(objects, materials or [Material.diffuse((1.0, 1.0, 1.0))], camera, resolution=resolution)
    sc.world = World(color=np.ones(3), strength=1.0, image=img, interpolation=interpolation,
                     mapping=mapping or MotionTransform.static())
    return sc


def test_sphere_mean_is_the_solid_angle_average():
    img = sky_with_sun()
    k = 4
    H, W = img.shape[:2]
    V = (np.arange(H * k) + 0.5) / (H * k)
    w = np.sin(np.pi * V)
    rowmean = img.astype(np.float64).mean(axis=1)[(V * H).astype(int)]
    want = (w[:, None] * rowmean).sum(axis=0) / w.sum()
    np.testing.assert_allclose(sphere_mean(img), want, rtol=2e-3)


def test_sampling_density_is_normalised_and_matches_the_draws():
    img = sky_with_sun()
    env = environment_arrays(World(color=np.ones(3), image=img))
    M = _rot_z(0.7)[None].copy()
    # the density integrates to 1 over the sphere (a fine grid of directions)
    k = 6
    H, W = img.shape[:2]
    U, V = np.meshgrid((np.arange(W * k) + 0.5) / (W * k), (np.arange(H * k) + 0.5) / (H * k))
    d = np.ascontiguousarray((_direction(U, V).reshape(-1, 3)) @ M[0, :3, :3].T)
    dOmega = (2 * np.pi / (W * k)) * (np.pi / (H * k)) * np.sin(np.pi * V.reshape(-1))
    u = np.random.default_rng(0).random((200_000, 2))
    dout, pdf, again = np.empty((u.shape[0], 3)), np.empty(u.shape[0]), np.empty(u.shape[0])
    env_sample_batch(env, M, u, dout, pdf, again)
    np.testing.assert_allclose(np.linalg.norm(dout, axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose(pdf, again, rtol=1e-9)
    # Monte Carlo: E[L / pdf] over the sphere = integral of L (the image's mean times 4 pi)
    L = np.empty((u.shape[0], 3))
    env_lookup_batch(env, M, dout, L)
    est = (L / pdf[:, None]).mean(axis=0)
    np.testing.assert_allclose(est, 4 * np.pi * sphere_mean(img), rtol=0.01)
    # the density itself integrates to 1 (a midpoint sum over a grid 6x finer than the image's)
    pd_grid = np.empty(d.shape[0])
    env_pdf_batch(env, M, d, pd_grid)
    assert (pd_grid * dOmega).sum() == pytest.approx(1.0, rel=1e-3)


def test_plane_under_an_image_gets_its_cosine_integral():
    img = sky_with_sun()
    want = image_irradiance(img)
    scene = _image_scene(img, [plane_mesh(4.0)], ortho_camera_down(2.0, 1.0))
    r = render(scene, _settings(samples=64))
    direct = r.passes["Direct"].reshape(-1, 3).mean(axis=0)
    # radiance of a white diffuse plane = E / pi
    np.testing.assert_allclose(direct, want / np.pi, rtol=0.01)


def test_a_sun_patch_casts_a_sharp_shadow():
    """A box on a plane under a bright sun patch: the shadow is dark, its edge a few pixels wide."""
    from scenes import box_mesh
    img = sky_with_sun(sky=0.05, sun=4000.0, sun_uv=(0.5, 0.75))     # sun in the -x direction, 45 deg up
    scene = _image_scene(img, [plane_mesh(8.0), box_mesh((-0.25, -0.25, 0.0), (0.25, 0.25, 0.5))],
                         ortho_camera_down(3.0, 3.0), resolution=(48, 48))
    r = render(scene, _settings(samples=32))
    D = r.passes["Direct"][..., 0]
    depth = r.passes["Depth"][..., 0]
    floor = np.abs(depth - 3.0) < 1e-6
    lit = floor & (np.abs(np.arange(48) - 24)[None, :] > 14)
    # the sun at u = 0.5 points along +x (phi = 0): the shadow falls on -x, beyond the box
    iy, ix = np.mgrid[0:48, 0:48]
    x = (ix + 0.5) / 48 * 3.0 - 1.5
    y = 1.5 - (iy + 0.5) / 48 * 3.0
    shadow = floor & (x < -0.35) & (x > -0.6) & (np.abs(y) < 0.15)
    assert shadow.sum() > 10
    assert D[shadow].mean() < 0.25 * D[lit].mean()


def test_background_pixel_is_the_texel_under_the_ray():
    """Box filter, Closest: a pixel whose whole footprint looks up one texel is that texel (float32
    rounding), with the image turned by the mapping; pixels across a texel edge lie between texels."""
    rng = np.random.default_rng(4)
    img = rng.random((8, 16, 3)).astype(np.float32) + 0.1
    M = _rot_z(0.4)
    far = plane_mesh(0.001, z=-500.0)                  # something to render; never in view
    cam = persp_camera((0, 0, 0), (1, 0.3, 0.2), lens=12.0)
    W, H = 24, 16
    scene = _image_scene(img, [far], cam, mapping=MotionTransform.static(M), resolution=(W, H))
    got = render(scene, _settings(samples=4)).passes["Emit"]
    from stpm_core.camera import generate_rays

    def texels(px, py):
        d = generate_rays(scene.camera, (W, H), px.ravel(), py.ravel(), np.zeros(px.size))[1]
        m = d @ M[:3, :3]                                         # world -> map: M^T d
        u = (np.pi - np.arctan2(m[:, 1], m[:, 0])) / (2 * np.pi)
        v = 1 - np.arccos(np.clip(m[:, 2], -1, 1)) / np.pi
        return (np.minimum((v * 8).astype(int), 7) * 16 + (u * 16).astype(int) % 16).reshape(H, W)

    X, Y = np.meshgrid(np.arange(W, dtype=float), np.arange(H, dtype=float))
    corners = [texels(X + a, Y + b) for a in (0.0, 0.999) for b in (0.0, 0.999)]
    one = np.all([c == corners[0] for c in corners], axis=0)
    assert one.sum() > 0.5 * W * H
    want = img.reshape(-1, 3)[corners[0]]
    np.testing.assert_allclose(got[one], want[one], rtol=1e-6)
    lo = np.min([img.reshape(-1, 3)[c] for c in corners], axis=0)
    hi = np.max([img.reshape(-1, 3)[c] for c in corners], axis=0)
    assert np.all(got >= lo - 1e-6) and np.all(got <= hi + 1e-6)


def test_world_photons_carry_the_image_flux_onto_a_plane():
    img = sky_with_sun()
    scene = _image_scene(img, [plane_mesh(2.0)], ortho_camera_down(2.0, 1.0))
    lights = LightSet(scene)
    li = [l.type for l in lights.lights].index("WORLD")
    n = 400_000
    o, d, P = lights.emit(li, n, np.zeros(1), np.random.default_rng(5))
    caster = make_caster(scene)
    hits = caster.intersect(o, d, np.zeros(n), np.full(n, np.inf))
    down = (hits.t < np.inf) & (d[:, 2] < 0)            # onto the plane's upper side
    power = P[down].sum(axis=0)
    want = image_irradiance(img) * 4.0                   # E * area of the 2 x 2 plane
    np.testing.assert_allclose(power, want, rtol=0.03)


def test_camera_rays_see_the_camera_image_and_light_comes_from_the_image():
    """A Light Path "Is Camera Ray" world (World.camera_image): the background shows the camera
    image, a mirror shows the lighting image, and a diffuse plane is lit by the lighting image."""
    from stpm_core.scene import Material
    light_img = np.full((8, 16, 3), 0.5, np.float32)
    cam_img = np.full((8, 16, 3), 0.1, np.float32)
    cam_img[..., 2] = 0.9
    cam = persp_camera((0, -3, 1.0), (0, 0, 0.5), lens=20.0)
    plane = plane_mesh(2.0, material=0)
    mirror = plane_mesh(0.6, material=1)
    mirror.vertices = (np.asarray(mirror.vertices, float) @ np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]]).T
                       + [0.0, 0.5, 0.7]).astype(np.float32)        # upright, facing the camera (-y)
    mirror.triangles = mirror.triangles[:, ::-1].copy()
    sc = _image_scene(light_img, [plane, mirror], cam, materials=[Material.diffuse((1, 1, 1)), Material.mirror()],
                      resolution=(48, 32))
    sc.world.camera_image = cam_img
    r = render(sc, _settings(samples=64))
    depth = r.passes["Depth"][..., 0]
    emit, direct = r.passes["Emit"], r.passes["Direct"]
    bg = depth >= depth.max() - 1e-6
    np.testing.assert_allclose(emit[bg], np.broadcast_to([0.1, 0.1, 0.9], emit[bg].shape), rtol=1e-6)
    # the mirror reflects the sky above the camera: the lighting image
    pure = np.all(np.abs(emit - 0.5) < 1e-6, axis=-1)       # (its edge pixels also hold background)
    assert pure.sum() > 8 and not pure[bg].any()
    # the plane (radiance = E / pi = L for white under a uniform half-sphere of L) sees 0.5
    floor = (~bg) & (direct[..., 0] > 0)
    inner = floor.copy()                                           # pixels wholly on the floor
    inner[1:-1, 1:-1] = np.all([floor[1 + a:31 + a, 1 + b:47 + b] for a in (-1, 0, 1) for b in (-1, 0, 1)], axis=0)
    inner[[0, -1]] = False
    inner[:, [0, -1]] = False
    floor = inner
    rows = np.nonzero(floor.any(axis=1))[0]
    near = floor & (np.arange(32) >= rows.max() - 3)[:, None]  # the front of the floor: the mirror hides little sky
    assert near.sum() > 30
    assert direct[near].mean() == pytest.approx(0.5, rel=0.03)


def test_an_hdri_sun_makes_the_caustic_of_the_equivalent_sun_lamp():
    """A black HDRI with one small bright patch and a SUN lamp of the same irradiance, direction
    and angular size: a glass sphere over a floor gets the same caustic power from both (world
    photons are drawn from the image and aimed at the sphere like the sun's)."""
    from scenes import look_at, sphere_mesh
    from stpm_core.lights import LightSet
    from stpm_core.photons.maps import build_photon_maps
    from stpm_core.scene import Light, Material
    H, W = 128, 256
    img = np.zeros((H, W, 3), np.float32)
    j, i = 95, 64                                          # v = 0.744: 44 degrees up; u = 0.25: phi = pi/2 (+y)
    img[j:j + 2, i:i + 2] = 1.0e4
    floor = plane_mesh(6.0, material=0)
    ball = sphere_mesh(0.5, 32, 64, material=1)
    ball.vertices = (np.asarray(ball.vertices) + np.float32([0, 0, 1.0])).astype(np.float32)
    mats = [Material.diffuse((0.5, 0.5, 0.5)), Material.glass(1.5)]
    world_scene = _image_scene(img, [floor, ball], ortho_camera_down(3.0, 3.0), interpolation="CLOSEST",
                               materials=mats)
    # the patch as a sun: direction its centre, strength its irradiance across the beam
    k = 8
    U, V = np.meshgrid((i + (np.arange(2 * k) + 0.5) / k) / W, (j + (np.arange(2 * k) + 0.5) / k) / H)
    d = _direction(U, V).reshape(-1, 3)
    dOmega = (2 * np.pi / (W * k)) * (np.pi / (H * k)) * np.sin(np.pi * V.reshape(-1))
    axis = (d * dOmega[:, None]).sum(0)
    axis /= np.linalg.norm(axis)
    strength = float((1.0e4 * dOmega * (d @ axis)).sum())
    angle = 2.0 * np.sqrt(dOmega.sum() / np.pi)            # the disc of the same solid angle
    sun_scene = make_scene([floor, ball], mats, ortho_camera_down(3.0, 3.0),
                           [Light(type="SUN", power=strength, angle=angle,
                                  transform=MotionTransform.static(look_at(axis * 10, (0, 0, 0))))])
    s = RenderSettings(photons_caustic=300_000, photons_global=0, seed=1)
    power = []
    for sc in (world_scene, sun_scene):
        maps = build_photon_maps(sc, s, make_caster(sc), LightSet(sc))
        rec = maps.maps["caustic"]
        on_floor = np.abs(rec.position[:, 2] + rec.origin[2]) < 1e-3            # positions are relative to origin
        power.append(float(rec.power.astype(float)[on_floor].sum()))
    print(f"caustic power on the floor: HDRI sun {power[0]:.4g} W, sun lamp {power[1]:.4g} W")
    assert power[1] > 0
    assert power[0] == pytest.approx(power[1], rel=0.03), power


def test_the_cosine_fraction_follows_the_image_power_and_stays_unbiased():
    """Next-event estimation's cosine fraction depends on the normal (``kernels.environment.nee_cos``,
    ``world_light.nee_cos_table``): small where the image's power (the sun patch) is above the
    surface, large where it is below; the sampler reports the density ``world_nee_pdf`` gives, and
    E[L cos / p] is the cosine-weighted integral of the image for any normal (the oracle)."""
    from stpm_core.kernels.environment import nee_cos
    from stpm_core.kernels.lights import _sample_env, world_nee_pdf
    from stpm_core.world_light import NEE_COS_RANGE
    img = sky_with_sun()
    img_k, func, marg, cond, par, portals = environment_arrays(World(color=np.ones(3), image=img))
    M = np.eye(4)
    lo, hi = NEE_COS_RANGE
    assert nee_cos(par, M, (0.0, 0.0, 1.0)) < lo + 0.1 * (hi - lo)        # the sun above a floor
    assert nee_cos(par, M, (0.0, 0.0, -1.0)) > hi - 0.1 * (hi - lo)       # below a ceiling
    assert nee_cos(par, M, (0.0, 0.0, 0.0)) == par[3]                     # no normal: the fixed fraction
    rng = np.random.default_rng(5)
    for n in ((0.0, 0.0, 1.0), (1.0, 0.0, 0.0), (0.0, -0.6, 0.8)):
        u = rng.random((60_000, 2))
        est = np.zeros(3)
        for k in range(u.shape[0]):
            r = _sample_env(img_k, func, marg, cond, par, M, n, u[k, 0], u[k, 1])
            wi = (r[0], r[1], r[2])
            if k < 200:
                assert r[7] == pytest.approx(world_nee_pdf(func, par, portals, M, (0.0, 0.0, 0.0), n, wi), rel=1e-12)
            est += np.array(r[4:7]) * max(wi[0] * n[0] + wi[1] * n[1] + wi[2] * n[2], 0.0)
        np.testing.assert_allclose(est / u.shape[0], image_irradiance(img, n), rtol=0.02)
