"""Direct lighting, emission, specular chains and the render API against analytic answers.

All renders are tiny (<= 24x24 pixels) with no photon maps (photons = 0), so
Indirect and Caustic are zero and Direct is known in closed form.
"""
from __future__ import annotations

import numpy as np
import pytest

from scenes import look_at, make_scene, ortho_camera_down, plane_mesh, point_light, translate
from stpm_core.bsdf import MaterialTable, bsdf_sample
from stpm_core.errors import RenderCancelled
from stpm_core.motion import MotionTransform
from stpm_core.render import PASSES, render
from stpm_core.scene import Camera, Light, Material
from stpm_core.settings import RenderSettings

RHO = 0.5


def _settings(**kw):
    base = dict(samples=16, photons_global=0, photons_caustic=0, seed=3, filter_width=0.0)
    base.update(kw)
    return RenderSettings(**base)


def _pixel_world_xy(scene, sub=4):
    """World (x, y) of sub x sub points in every pixel of an ortho camera looking down: (H, W, sub*sub, 2)."""
    W, H = scene.resolution
    cam = scene.camera
    cx, cy = cam.transform.at(0.5)[:2, 3]
    pix = cam.ortho_scale / max(W, H)
    s = (np.arange(sub) + 0.5) / sub
    ix = np.arange(W)[None, :, None, None] + s[None, None, None, :]
    iy = np.arange(H)[:, None, None, None] + s[None, None, :, None]
    x = cx + (ix - 0.5 * W) * pix + 0 * iy
    y = cy + (0.5 * H - iy) * pix + 0 * ix
    return np.stack([x.reshape(H, W, -1), y.reshape(H, W, -1)], -1)


def _diffuse_plane_scene(lights, *, center=(0.0, 0.0), scale=1.0, res=(16, 16)):
    return make_scene([plane_mesh(40.0)], [Material.diffuse((RHO, RHO, RHO))],
                      ortho_camera_down(height=5.0, ortho_scale=scale, center=center), lights, resolution=res)


def _check_zero_photon_passes(p):
    for name in ("Indirect", "Caustic", "Emit"):
        assert np.all(p[name] == 0), name
    np.testing.assert_allclose(p["Combined"][..., :3], p["Direct"], rtol=1e-6)
    assert np.all(p["Combined"][..., 3] == 1)


# ---------------------------------------------------------------------------
# Lights over a diffuse plane: L = rho / pi * E
# ---------------------------------------------------------------------------
def test_point_light_over_diffuse_plane():
    h, P = 2.0, 300.0
    scene = _diffuse_plane_scene([point_light((0.0, 0.0, h), P)], center=(1.0, 0.5), scale=1.0)
    p = render(scene, _settings(samples=4)).passes
    # Analytic: L = rho/pi * I cos(theta) / r^2 with I = P / (4 pi), cos = h / r, averaged over each pixel
    xy = _pixel_world_xy(scene, sub=8)
    r2 = xy[..., 0] ** 2 + xy[..., 1] ** 2 + h * h
    want = (RHO / np.pi * P / (4 * np.pi) * h / r2 ** 1.5).mean(-1)
    np.testing.assert_allclose(p["Direct"][..., 1], want, rtol=0.01)
    _check_zero_photon_passes(p)
    # Depth = distance from the camera along its axis (camera at z = 5); Normal = +Z
    np.testing.assert_allclose(p["Depth"][..., 0], 5.0, rtol=1e-5)
    np.testing.assert_allclose(p["Normal"], np.broadcast_to([0, 0, 1], p["Normal"].shape), atol=1e-6)


def test_sun_over_diffuse_plane_with_default_filter():
    S, theta = 3.0, np.radians(35.0)
    # The sun's +Z axis points toward the sun: rotate the identity about X by theta
    R = np.eye(4)
    R[1:3, 1:3] = [[np.cos(theta), -np.sin(theta)], [np.sin(theta), np.cos(theta)]]
    sun = Light(type="SUN", power=S, transform=MotionTransform.static(R), color=np.array([1.0, 0.5, 0.25]))
    scene = _diffuse_plane_scene([sun])
    p = render(scene, _settings(samples=4, filter_width=1.5)).passes
    want = RHO / np.pi * S * np.cos(theta) * np.array([1.0, 0.5, 0.25])
    np.testing.assert_allclose(p["Direct"], np.broadcast_to(want, p["Direct"].shape), rtol=1e-5)
    _check_zero_photon_passes(p)


def test_spot_light_inside_its_cone():
    h, P = 2.0, 500.0
    spot = Light(type="SPOT", power=P, transform=MotionTransform.static(translate(0, 0, h)),
                 spot_size=np.radians(120.0), spot_blend=0.0, radius=0.0)
    scene = _diffuse_plane_scene([spot], center=(0.5, -0.3), scale=1.0)
    p = render(scene, _settings(samples=4)).passes
    xy = _pixel_world_xy(scene, sub=8)
    r2 = xy[..., 0] ** 2 + xy[..., 1] ** 2 + h * h
    want = (RHO / np.pi * P / (4 * np.pi) * h / r2 ** 1.5).mean(-1)
    np.testing.assert_allclose(p["Direct"][..., 0], want, rtol=0.01)


def test_spot_light_is_dark_outside_its_cone():
    spot = Light(type="SPOT", power=500.0, transform=MotionTransform.static(translate(0, 0, 1.0)),
                 spot_size=np.radians(30.0), spot_blend=0.0)
    scene = _diffuse_plane_scene([spot], center=(3.0, 0.0), scale=1.0, res=(8, 8))
    assert np.all(render(scene, _settings(samples=2)).passes["Direct"] == 0)


def test_small_disk_area_light():
    """Irradiance from a Lambertian disk, integrated numerically over the disk (independent of the sampler)."""
    h, a, P = 1.0, 0.1, 50.0
    area = Light(type="AREA", shape="DISK", size=2 * a, power=P, transform=MotionTransform.static(translate(0, 0, h)))
    scene = _diffuse_plane_scene([area], center=(0.15, 0.0), scale=0.5, res=(8, 8))
    p = render(scene, _settings(samples=256)).passes
    L = P / (np.pi * np.pi * a * a)          # radiance of a Lambertian emitter of power P and area pi a^2
    # Quadrature over the disk: polar grid, E = int L cos_p cos_l / d^2 dA
    rr = (np.arange(40) + 0.5) / 40 * a
    ph = (np.arange(80) + 0.5) / 80 * 2 * np.pi
    R_, PH = np.meshgrid(rr, ph)
    qx, qy = (R_ * np.cos(PH)).ravel(), (R_ * np.sin(PH)).ravel()
    dA = (R_ * (a / 40) * (2 * np.pi / 80)).ravel()
    xy = _pixel_world_xy(scene, sub=3)
    dx = xy[..., 0:1] - qx
    dy = xy[..., 1:2] - qy
    d2 = dx * dx + dy * dy + h * h
    E = (L * (h * h / d2 ** 2) * dA).sum(-1).mean(-1)
    want = RHO / np.pi * E
    # Block average over all 64 pixels (noise well below 0.3 %), and per pixel within 2 %
    assert p["Direct"][..., 0].mean() == pytest.approx(want.mean(), rel=0.01)
    np.testing.assert_allclose(p["Direct"][..., 0], want, rtol=0.02)


# ---------------------------------------------------------------------------
# Emission and the world
# ---------------------------------------------------------------------------
def test_emission_and_world_are_exact_in_emit():
    Le, world = np.array([0.3, 0.6, 0.9]), np.array([0.1, 0.2, 0.05])
    # A half plane x < 0 seen from above; the other half of the view sees the world
    half = plane_mesh(4.0)
    half.vertices = half.vertices.copy()
    half.vertices[:, 0] = np.where(half.vertices[:, 0] > 0, 0.0, -4.0)
    scene = make_scene([half], [Material.emitter(Le)], ortho_camera_down(ortho_scale=2.0), world=world,
                       resolution=(8, 4))
    p = render(scene, _settings(samples=4)).passes
    np.testing.assert_allclose(p["Emit"][:, :4], np.broadcast_to(Le, (4, 4, 3)), rtol=1e-6)
    np.testing.assert_allclose(p["Emit"][:, 4:], np.broadcast_to(world, (4, 4, 3)), rtol=1e-6)
    np.testing.assert_allclose(p["Combined"][..., :3], p["Emit"], rtol=1e-6)
    assert np.all(p["Depth"][:, 4:] >= 1e9) and np.all(p["Depth"][:, :4] < 10)


# ---------------------------------------------------------------------------
# A specular chain: mirror -> diffuse wall
# ---------------------------------------------------------------------------
def test_mirror_reflects_the_lit_wall_times_its_reflectance():
    S, a = 2.0, np.radians(25.0)
    sun_dir = np.array([-np.cos(a), 0.0, np.sin(a)])          # toward the sun
    sun = Light(type="SUN", power=S, transform=MotionTransform.static(look_at(sun_dir, (0, 0, 0))))
    wall = plane_mesh(20.0, material=0)                         # diffuse wall at x = 3 facing -x
    wall_M = translate(3, 0, 0) @ np.array([[0, 0, -1, 0], [0, 1, 0, 0], [1, 0, 0, 0], [0, 0, 0, 1.0]])
    mirror = plane_mesh(1.0, material=1)                        # 45 degree mirror through the origin, normal (1,0,1)/sqrt2
    c, s = np.cos(np.pi / 4), np.sin(np.pi / 4)
    mirror_M = np.array([[c, 0, s, 0], [0, 1, 0, 0], [-s, 0, c, 0], [0, 0, 0, 1.0]])
    mats = [Material.diffuse((RHO, RHO, RHO)), Material.mirror((0.9, 0.7, 0.5))]
    res = (8, 8)
    scene = make_scene([(wall, wall_M), (mirror, mirror_M)], mats, ortho_camera_down(ortho_scale=0.4),
                       [sun], resolution=res)
    seen = render(scene, _settings(samples=4)).passes
    # The wall seen directly, by a camera looking along +x
    direct_cam = Camera(type="ORTHO", ortho_scale=0.4, clip_start=0.01, clip_end=100,
                        transform=MotionTransform.static(look_at((1, 0, 0), (3, 0, 0))))
    scene2 = make_scene([(wall, wall_M)], mats, direct_cam, [sun], resolution=res)
    straight = render(scene2, _settings(samples=4)).passes["Direct"]
    wall_L = RHO / np.pi * S * np.cos(a)                         # cos between wall normal -x and sun_dir
    np.testing.assert_allclose(straight, wall_L, rtol=1e-5)
    # The mirror's reflectance at 45 degrees, from the BSDF itself
    n = np.array([[s, 0.0, c]])
    _, F, is_delta = bsdf_sample(MaterialTable(mats), np.array([1]), np.array([[0.0, 0.0, 1.0]]), n, n,
                                 np.full((1, 3), 0.5))
    assert is_delta[0]
    np.testing.assert_allclose(seen["Direct"], straight * F[0], rtol=1e-4)
    assert np.all(seen["Emit"] == 0)


# ---------------------------------------------------------------------------
# Render API: determinism, passes, cancel, progress
# ---------------------------------------------------------------------------
def _noisy_scene():
    area = Light(type="AREA", size=1.0, power=100.0, transform=MotionTransform.static(translate(0, 0, 1.0)))
    mats = [Material.diffuse((0.6, 0.5, 0.4)), Material.emitter((0.2, 0.1, 0.0))]
    glow = plane_mesh(0.3, z=0.2, material=1)
    return make_scene([plane_mesh(10.0), glow], mats, ortho_camera_down(ortho_scale=2.0), [area],
                      world=(0.05, 0.05, 0.1), resolution=(12, 10))


def test_same_seed_is_bit_identical_and_other_seeds_differ():
    scene = _noisy_scene()
    a = render(scene, _settings(samples=4, seed=7, filter_width=1.5)).passes
    b = render(scene, _settings(samples=4, seed=7, filter_width=1.5)).passes
    c = render(scene, _settings(samples=4, seed=8, filter_width=1.5)).passes
    serial = render(scene, _settings(samples=4, seed=7, filter_width=1.5, threads=1)).passes
    threaded = render(scene, _settings(samples=4, seed=7, filter_width=1.5, threads=3)).passes
    for name, _, _ in PASSES:
        assert a[name].tobytes() == b[name].tobytes(), name
        assert serial[name].tobytes() == threaded[name].tobytes() == a[name].tobytes(), name
    assert not np.array_equal(a["Direct"], c["Direct"])


def test_passes_shapes_and_sum():
    scene = _noisy_scene()
    res = render(scene, _settings(samples=4, filter_width=1.5))
    W, H = scene.resolution
    for name, ch, _ in PASSES:
        assert res.passes[name].shape == (H, W, ch) and res.passes[name].dtype == np.float32
    p = res.passes
    total = p["Emit"] + p["Direct"] + p["Indirect"] + p["Caustic"]
    np.testing.assert_allclose(p["Combined"][..., :3], total, rtol=1e-5, atol=1e-7)
    assert p["Emit"].max() > 0 and p["Direct"].max() > 0
    st = res.stats
    for key in ("wall_s", "export_s", "photon_trace_s", "photon_map_build_s", "render_s", "estimator",
                "method", "samples", "resolution", "seed", "rays_cast"):
        assert key in st
    assert st["rays_cast"] >= W * H * 4 and st["resolution"] == [W, H]


def test_cancel_raises_and_progress_reaches_one():
    scene = _noisy_scene()
    with pytest.raises(RenderCancelled):
        render(scene, _settings(samples=2), cancel=lambda: True)
    seen = []
    render(scene, _settings(samples=2), progress=lambda f, m: seen.append(f))
    assert seen[-1] == 1.0 and all(b >= a for a, b in zip(seen, seen[1:]))


# ---------------------------------------------------------------------------
# Photon maps plugged in: a mirror's caustic on a wall
# ---------------------------------------------------------------------------
def _mirror_caustic_scene(res=(8, 8)):
    """A vertical sun hits a 45 degree mirror; the reflected beam lands square on a wall at x = 3.

    Camera at x = 1 looks along +x at the middle of the beam.  The wall is parallel to the
    sunlight (Direct = 0) and its caustic irradiance is R(45 deg) * S.
    """
    S = 2.0
    sun = Light(type="SUN", power=S, transform=MotionTransform.static(np.eye(4)))  # toward the sun = +Z
    wall = plane_mesh(20.0, material=0)
    wall_M = translate(3, 0, 0) @ np.array([[0, 0, -1, 0], [0, 1, 0, 0], [1, 0, 0, 0], [0, 0, 0, 1.0]])
    mirror = plane_mesh(1.0, material=1)
    c, s = np.cos(np.pi / 4), np.sin(np.pi / 4)
    mirror_M = np.array([[c, 0, s, 0], [0, 1, 0, 0], [-s, 0, c, 0], [0, 0, 0, 1.0]])
    mats = [Material.diffuse((RHO, RHO, RHO)), Material.mirror((0.9, 0.7, 0.5))]
    cam = Camera(type="ORTHO", ortho_scale=0.3, clip_start=0.01, clip_end=100,
                 transform=MotionTransform.static(look_at((1, 0, 0), (3, 0, 0))))
    return make_scene([(wall, wall_M), (mirror, mirror_M)], mats, cam, [sun], resolution=res), S, mats


def test_mirror_caustic_from_the_caustic_map():
    scene, S, mats = _mirror_caustic_scene()
    st = _settings(samples=4, photons_caustic=60_000, photons_global=0, k_nearest=50, estimator="STANDARD")
    res = render(scene, st)
    p = res.passes
    n = np.array([[np.sin(np.pi / 4), 0.0, np.cos(np.pi / 4)]])
    _, F, _ = bsdf_sample(MaterialTable(mats), np.array([1]), np.array([[0.0, 0.0, 1.0]]), n, n, np.full((1, 3), 0.5))
    want = RHO / np.pi * S * F[0]
    # k-nearest estimates overestimate by about k / (k - 1); the block mean is well inside 4 %
    np.testing.assert_allclose(p["Caustic"].mean(axis=(0, 1)), want, rtol=0.04)
    assert np.all(p["Direct"] == 0) and np.all(p["Indirect"] == 0)
    np.testing.assert_allclose(p["Combined"][..., :3], p["Caustic"], rtol=1e-6)
    assert res.stats["photons_caustic"] > 0 and res.stats["photon_lookups"] > 0


def test_accumulation_with_photon_maps_matches_photon_method_on_a_static_scene():
    """With nothing moving, every still sees the same scene: ACCUMULATION and PHOTON agree."""
    scene, S, mats = _mirror_caustic_scene(res=(4, 4))
    common = dict(samples=2, photons_caustic=20_000, k_nearest=30)
    a = render(scene, _settings(method="ACCUMULATION", accumulation_steps=2, **common)).passes["Caustic"].mean()
    b = render(scene, _settings(method="PHOTON", estimator="STANDARD", **common)).passes["Caustic"].mean()
    assert a == pytest.approx(b, rel=0.05)


def test_lights_are_invisible_to_the_camera_but_seen_in_a_mirror():
    """As in Cycles (visible_camera off, visible_glossy on): looking up at a square area light (faces -Z)
    and a point light of radius r shows nothing; a mirror below them shows R * color P / (pi A) and
    R * P / (4 pi) / (pi r^2)."""
    P, size, r = 40.0, 1.0, 0.1
    area = Light(type="AREA", shape="SQUARE", size=size, power=P, color=np.array([1.0, 0.5, 0.25]),
                 transform=MotionTransform.static(translate(-0.5, 0, 3.0)))
    ball = Light(type="POINT", power=P, radius=r, transform=MotionTransform.static(translate(0.75, 0.0, 3.0)))
    up = Camera(type="ORTHO", ortho_scale=4.0, clip_start=0.01, clip_end=100,
                transform=MotionTransform.static(look_at((0, 0, 0), (0, 0, 5), up=(0, 1, 0))))
    assert np.all(render(make_scene([], [], up, [area, ball], resolution=(16, 16)), _settings(samples=4))
                  .passes["Emit"] == 0)
    # A horizontal mirror under the lights, seen from above
    mats = [Material.mirror((0.9, 0.8, 0.7))]
    scene = make_scene([plane_mesh(10.0)], mats, ortho_camera_down(height=6.0, ortho_scale=4.0), [area, ball],
                       resolution=(16, 16))
    e = render(scene, _settings(samples=64)).passes["Emit"]
    z = np.array([[0.0, 0.0, 1.0]])
    _, F, _ = bsdf_sample(MaterialTable(mats), np.array([0]), z, z, z, np.full((1, 3), 0.5))
    want_area = np.array([1.0, 0.5, 0.25]) * P / (np.pi * size * size) * F[0]
    # Pixel size 0.25: the square covers 4 x 4 pixels exactly
    inside = np.all(np.isclose(e, want_area, rtol=1e-5), axis=-1)
    assert inside.sum() == 16
    # The sphere: radiance times its pixel area = R L pi r^2 (within pixel-sampling noise)
    ball_px = (e[..., 1] > 0) & ~inside
    L_ball = P / (4 * np.pi) / (np.pi * r * r)
    assert e[..., 1][ball_px].sum() * 0.25 ** 2 == pytest.approx(F[0, 1] * L_ball * np.pi * r * r, rel=0.05)


def test_light_visible_camera_flag_shows_the_light():
    P, size = 40.0, 1.0
    area = Light(type="AREA", shape="SQUARE", size=size, power=P, transform=MotionTransform.static(translate(0, 0, 3.0)))
    up = Camera(type="ORTHO", ortho_scale=4.0, clip_start=0.01, clip_end=100,
                transform=MotionTransform.static(look_at((0, 0, 0), (0, 0, 5), up=(0, 1, 0))))
    scene = make_scene([], [], up, [area], resolution=(8, 8), metadata={"light_visible_camera": [True]})
    e = render(scene, _settings(samples=4)).passes["Emit"]
    np.testing.assert_allclose(e[3:5, 3:5], P / (np.pi * size * size), rtol=1e-6)  # 0.5 m pixels
    assert np.all(e[:3] == 0) and np.all(e[5:] == 0)


def test_stats_are_json_ready():
    import json
    scene, _, _ = _mirror_caustic_scene(res=(4, 4))
    res = render(scene, _settings(samples=1, photons_caustic=2000))
    back = json.loads(json.dumps(res.stats))
    assert back["photons_caustic"] == res.stats["photons_caustic"] > 0 and back["method"] == "PHOTON"
