"""Degenerate and extreme light / camera inputs: a light inside (or at the centre of)
its photon target, emission above the float32-safe limit, AREA lights under a
mirroring scale, and inputs that would silently render black."""
import numpy as np
import pytest

from oracles import lights_numpy
from scenes import look_at, make_scene, ortho_camera_down, plane_mesh, point_light, sphere_mesh, translate
from stpm_core.errors import SceneError
from stpm_core.lights import LightSet
from stpm_core.motion import MotionTransform
from stpm_core.render import render
from stpm_core.scene import MAX_EMISSION, Camera, Light, Material, scene_warnings, validate_scene
from stpm_core.settings import RenderSettings

MATS = [Material.diffuse((0.8, 0.8, 0.8)), Material.glass(1.5)]


def _scaled(M, s):
    M = np.array(M, float)
    M[:3, :3] = M[:3, :3] @ np.diag(s)
    return M


def _bulb(light_pos, power=300.0):
    """A point light in a glass sphere (radius 0.5, centre (0, 0, 1)) over a diffuse floor."""
    return make_scene([plane_mesh(6.0), (sphere_mesh(0.5, 10, 20, material=1), translate(0, 0, 1.0))], MATS,
                      ortho_camera_down(5.0, 4.0), [point_light(light_pos, power)], resolution=(48, 32))


# ----------------------------------------------------------------------------
# 1. Emission point at the centre of the target sphere
# ----------------------------------------------------------------------------
def test_emit_toward_from_the_target_centre_covers_the_sphere_of_directions():
    """Light exactly at the target's centre: unit directions, isotropic, photons sum to the light's flux."""
    ls = LightSet(_bulb((0.0, 0.0, 1.0)))
    n = 40_000
    o, d, P = ls.emit_toward(0, n, np.full(n, 0.5), np.random.default_rng(3), np.array([0.0, 0.0, 1.0]), 0.6)
    assert np.allclose(np.linalg.norm(d, axis=1), 1.0, atol=1e-12)
    assert np.allclose(o, [0.0, 0.0, 1.0])
    # Uniform over the sphere: mean direction ~ 0 (3 sigma = 3 / sqrt(3 n) = 0.009), half go down
    assert np.all(np.abs(d.mean(axis=0)) < 0.01)
    assert abs(np.mean(d[:, 2] < 0) - 0.5) < 0.01
    # Power: I * 4 pi / n per photon, so the sum is the flux (as emit())
    assert np.allclose(P.sum(axis=0), ls.flux(0), rtol=1e-12)


def test_sphere_light_sampled_from_its_own_centre_gives_unit_directions():
    l = point_light((0.0, 0.0, 1.0), 100.0, radius=0.2)
    ls = LightSet(make_scene([plane_mesh(2.0)], MATS[:1], ortho_camera_down(), [l]))
    n = 1000
    p = np.broadcast_to([0.0, 0.0, 1.0], (n, 3))
    wi, dist, w = ls.sample_direct(0, p, np.full(n, 0.5), np.random.default_rng(0).random((n, 2)))
    assert np.allclose(np.linalg.norm(wi, axis=1), 1.0)
    assert np.allclose(dist, 0.2)                       # the far side of the sphere, from its centre
    # Inside the sphere every direction sees radiance L = I / (pi r^2): weight = L 4 pi
    assert np.allclose(w, ls.intensity(0) / (np.pi * 0.04) * 4.0 * np.pi)


def test_point_light_at_the_centre_of_a_glass_sphere_casts_the_caustic():
    """The bulb: the caustic under a light at the exact centre matches a light 1e-6 off centre."""
    caustic = {}
    for key, pos, seed in (("centre", (0.0, 0.0, 1.0), 1), ("off", (0.0, 0.0, 1.0 + 1e-6), 2)):
        r = render(_bulb(pos), RenderSettings(samples=2, photons_caustic=20000, photons_global=0, k_nearest=16,
                                              seed=seed, filter_width=0.0))
        assert r.stats["photons_caustic"] > 5000, key          # the plan keeps caustics on, photons land
        caustic[key] = float(np.mean(r.passes["Caustic"][..., :3]))
    assert caustic["off"] > 1.0
    assert abs(caustic["centre"] / caustic["off"] - 1.0) < 0.04, caustic


# ----------------------------------------------------------------------------
# 2. Emission limit
# ----------------------------------------------------------------------------
def test_light_power_limit_both_sides():
    sc = _bulb((0.3, 0.2, 3.0), power=MAX_EMISSION)
    validate_scene(sc)                                            # at the limit: accepted ...
    r = render(sc, RenderSettings(samples=2, photons_caustic=4000, photons_global=4000, k_nearest=16, seed=1))
    for name, a in r.passes.items():                              # ... and renders finite
        assert np.all(np.isfinite(a)), name
    assert float(np.mean(r.passes["Combined"][..., :3])) > 1e26
    sc.lights[0].power = 1.01 * MAX_EMISSION
    with pytest.raises(SceneError, match=r"lights\[0\] \('light'\)\.power is 1\.01e\+30 W"):
        validate_scene(sc)
    with pytest.raises(SceneError):
        render(sc, RenderSettings(samples=1))
    # The limit is on power times colour: a large colour multiplier counts
    sc.lights[0].power = 0.5 * MAX_EMISSION
    sc.lights[0].color = np.array([1.0, 3.0, 1.0])
    with pytest.raises(SceneError, match=r"power \* max\(color\) is 1\.5e\+30"):
        validate_scene(sc)
    sc.lights[0].color = np.array([1.0, 2.0, 1.0])
    validate_scene(sc)


@pytest.mark.parametrize("typ", ["SUN", "AREA", "SPOT"])
def test_power_limit_applies_to_every_light_type(typ):
    l = Light(type=typ, power=MAX_EMISSION, transform=MotionTransform.static(translate(0, 0, 3)), name="big")
    sc = make_scene([plane_mesh(2.0)], MATS[:1], ortho_camera_down(), [l])
    validate_scene(sc)
    l.power = 2 * MAX_EMISSION
    with pytest.raises(SceneError, match="'big'.*2e\\+30"):
        validate_scene(sc)


def test_emission_and_world_limits_both_sides():
    mats = [Material.diffuse(), Material.emitter((0.0, MAX_EMISSION, 0.0), name="hot")]
    sc = make_scene([plane_mesh(2.0), (plane_mesh(0.5, material=1), translate(0, 0, 1))], mats,
                    ortho_camera_down(), [], world=(1.0, 1.0, 1.0))
    sc.world.strength = MAX_EMISSION
    validate_scene(sc)
    r = render(sc, RenderSettings(samples=1, photons_caustic=0, photons_global=2000, k_nearest=8, seed=1))
    for name, a in r.passes.items():
        assert np.all(np.isfinite(a)), name
    mats[1].emission = np.array([0.0, 1.5 * MAX_EMISSION, 0.0])
    with pytest.raises(SceneError, match=r"materials\[1\] \('hot'\)\.emission is 1\.5e\+30"):
        validate_scene(sc)
    mats[1].emission = np.array([0.0, MAX_EMISSION, 0.0])
    sc.world.strength = 1e300
    with pytest.raises(SceneError, match=r"world\.strength is 1e\+300"):
        validate_scene(sc)
    sc.world.strength = 0.5 * MAX_EMISSION
    sc.world.color = np.array([3.0, 0.0, 0.0])
    with pytest.raises(SceneError, match=r"world\.color \* strength is 1\.5e\+30"):
        validate_scene(sc)


# ----------------------------------------------------------------------------
# 3. AREA orientation under a mirroring scale follows -Z, as SPOT and SUN do
# ----------------------------------------------------------------------------
BASE = look_at((0.3, 0.2, 3.0), (0.3, 0.2, 0.0))
LIT = [(1, 1, 1), (-1, 1, 1), (1, -1, 1), (-1, -1, 1), (1, 1, 3)]
DARK = [(1, 1, -1), (-1, 1, -1), (1, -1, -1)]


def _irradiance_below(typ, s, n=64):
    """Irradiance at (0.3, 0.2, 0) on an upward surface from a light at height 3 (midpoint grid: exact symmetry)."""
    l = Light(type=typ, transform=MotionTransform.static(_scaled(BASE, s)), power=300.0, size=1.0)
    ls = LightSet(make_scene([plane_mesh(6.0)], MATS[:1], ortho_camera_down(), [l]))
    g = (np.arange(n) + 0.5) / n
    u = np.stack(np.meshgrid(g, g, indexing="ij"), axis=-1).reshape(-1, 2)
    p = np.broadcast_to([0.3, 0.2, 0.0], (u.shape[0], 3))
    wi, _, w = ls.sample_direct(0, p, np.full(u.shape[0], 0.5), u)
    return float(np.mean(w[:, 0] * np.maximum(wi[:, 2], 0.0))), ls


def test_area_light_orientation_follows_minus_z_under_mirroring_like_spot_and_sun():
    E_area = {s: _irradiance_below("AREA", s)[0] for s in LIT + DARK}
    ref = E_area[(1, 1, 1)]
    # Square of side 1 at height h = 3 over the point, radiance L = P / (pi A): four corner form factors,
    # E = 4 (L / 2) [2 a / s atan(a / s)], half side a = 0.5, s = sqrt(a^2 + h^2)
    a, sq = 0.5, np.sqrt(0.25 + 9.0)
    assert ref == pytest.approx(4.0 * 0.5 * (300.0 / np.pi) * 2.0 * a / sq * np.arctan(a / sq), rel=1e-3)
    for s in LIT[1:4]:
        assert E_area[s] == pytest.approx(ref, rel=1e-9), s
    # A Z scale other than +-1 changes nothing (only the X, Y scales multiply the size)
    assert E_area[(1, 1, 3)] == pytest.approx(ref, rel=1e-9)
    for s in DARK:
        assert E_area[s] == 0.0, s
    # SPOT and SUN give the same lit / unlit answer for every scale
    for typ in ("SPOT", "SUN"):
        for s in LIT:
            assert _irradiance_below(typ, s, 4)[0] > 0.0, (typ, s)
        for s in DARK:
            assert _irradiance_below(typ, s, 4)[0] == 0.0, (typ, s)


@pytest.mark.parametrize("s", [(1, 1, 1), (-1, 1, 1), (1, 1, -1)])
def test_area_light_photons_and_visibility_follow_its_emitting_side(s):
    """emit() photons leave on the -Z side; intersect() sees the light only from that side."""
    _, ls = _irradiance_below("AREA", s, 2)
    down = s[2] > 0                           # -Z column points down unless Z is mirrored
    _, d, P = ls.emit(0, 2000, np.full(2000, 0.5), np.random.default_rng(0))
    assert np.all(d[:, 2] < 0) if down else np.all(d[:, 2] > 0)
    o = np.array([[0.3, 0.2, 0.0], [0.3, 0.2, 6.0]])         # below and above the light
    dirs = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, -1.0]])
    t, L = lights_numpy.intersect(ls, o, dirs, np.full(2, 0.5))
    seen = np.isfinite(t)
    assert seen.tolist() == ([True, False] if down else [False, True])
    assert np.allclose(L[seen], 300.0 / np.pi)                # L = P / (pi A), A = 1


# ----------------------------------------------------------------------------
# 4. Inputs that would render black without a word
# ----------------------------------------------------------------------------
def _one_light_scene(light, camera=None):
    return make_scene([plane_mesh(6.0)], MATS[:1], camera or ortho_camera_down(5.0, 4.0), [light], resolution=(16, 8))


def test_area_light_of_zero_size_is_warned_about():
    l = Light(type="AREA", transform=MotionTransform.static(BASE), power=300.0, size=0.0, name="panel")
    w = scene_warnings(_one_light_scene(l))
    assert len(w) == 1 and "'panel'" in w[0] and "zero area" in w[0]
    l.size, l.shape, l.size_y = 1.0, "RECTANGLE", 0.0
    assert "zero area" in scene_warnings(_one_light_scene(l))[0]
    l.size_y = 1e-9                                       # tiny but emitting: no warning
    assert scene_warnings(_one_light_scene(l)) == []
    l.shape, l.size = "SQUARE", 1.0
    l.transform = MotionTransform.static(_scaled(BASE, (1, 0, 1)))
    assert "zero X or Y scale" in scene_warnings(_one_light_scene(l))[0]


@pytest.mark.parametrize("typ", ["SPOT", "SUN", "AREA"])
def test_light_with_zero_scale_transform_is_warned_about(typ):
    for s in ((0, 0, 0), (1, 1, 0)):
        l = Light(type=typ, transform=MotionTransform.static(_scaled(BASE, s)), power=300.0, name="lamp")
        w = scene_warnings(_one_light_scene(l))
        assert len(w) == 1 and "'lamp'" in w[0] and "emits nothing" in w[0], (s, w)
    # Mirrored or merely scaled: a valid light, no warning; POINT ignores its axes
    for s in ((1, 1, -1), (-1, 1, 1), (1e-6, 1e-6, 1e-6)):
        l = Light(type=typ, transform=MotionTransform.static(_scaled(BASE, s)), power=300.0)
        assert scene_warnings(_one_light_scene(l)) == [], s
    l = Light(type="POINT", transform=MotionTransform.static(_scaled(BASE, (0, 0, 0))), power=300.0)
    assert scene_warnings(_one_light_scene(l)) == []


def test_light_whose_scale_crosses_zero_in_the_shutter_is_warned_about():
    """Keys (1, 1, 1) and (1, 1, -1): the interpolated Z scale is 0 halfway."""
    tr = MotionTransform(np.array([0.0, 1.0]), np.stack([BASE, _scaled(BASE, (1, 1, -1))]))
    l = Light(type="SPOT", transform=tr, power=300.0, name="flip")
    assert "zero Z scale" in scene_warnings(_one_light_scene(l))[0]


def test_camera_that_cannot_form_rays_is_an_error():
    light = point_light((0.0, 0.0, 3.0), 300.0)
    M = look_at((0.0, -5.0, 3.0), (0.0, 0.0, 0.0))
    for s in ((1, 1, 0), (0, 1, 1), (0, 0, 0)):
        cam = Camera(type="PERSP", transform=MotionTransform.static(_scaled(M, s)), clip_start=0.01, clip_end=100)
        with pytest.raises(SceneError, match="camera.transform cannot form rays"):
            validate_scene(_one_light_scene(light, cam))
    # Collapsed axes (Y parallel to X)
    C = np.array(M)
    C[:3, 1] = C[:3, 0]
    cam = Camera(type="PERSP", transform=MotionTransform.static(C), clip_start=0.01, clip_end=100)
    with pytest.raises(SceneError, match="camera.transform"):
        validate_scene(_one_light_scene(light, cam))
    # Any non-zero scale, mirrored or not, is fine (the camera ignores scale)
    for s in ((2, 2, 2), (1, 1, -1), (1e-6, 1e-6, 1e-6)):
        cam = Camera(type="PERSP", transform=MotionTransform.static(_scaled(M, s)), clip_start=0.01, clip_end=100)
        validate_scene(_one_light_scene(light, cam))


@pytest.mark.parametrize("typ,s", [("SPOT", (0, 0, 0)), ("SUN", (0, 0, 0)), ("SUN", (1, 1, 0)),
                                   ("AREA", (1, 1, 0)), ("AREA", (0, 0, 0))])
def test_light_without_direction_emits_nothing_along_unit_directions(typ, s):
    """Zero Z scale (or zero area): flux 0, photons of zero power along unit directions, no direct light."""
    l = Light(type=typ, transform=MotionTransform.static(_scaled(BASE, s)), power=300.0)
    ls = LightSet(_one_light_scene(l))
    assert np.all(ls.flux(0) == 0.0) and ls.power[0] == 0.0
    n = 500
    times = np.full(n, 0.5)
    for o, d, P in (ls.emit(0, n, times, np.random.default_rng(1)),
                    ls.emit_toward(0, n, times, np.random.default_rng(1), np.zeros(3), 1.0)):
        assert np.all(np.isfinite(o)) and np.all(P == 0.0)
        assert np.allclose(np.linalg.norm(d, axis=1), 1.0)
    p = np.broadcast_to([0.3, 0.2, 0.0], (n, 3))
    wi, _, w = ls.sample_direct(0, p, times, np.random.default_rng(2).random((n, 2)))
    assert np.all(w == 0.0) and np.allclose(np.linalg.norm(wi, axis=1), 1.0)


def test_world_entry_aims_photons_at_a_sphere_from_outside_the_scene():
    """LightSet's WORLD entry: emit_toward lines cross the target sphere, start outside the scene's sphere,
    carry 4 pi * pi rho^2 * L in all, and follow per-photon (moving) centres."""
    L = np.array([0.5, 0.25, 1.0])
    sc = make_scene([plane_mesh(6.0)], MATS[:1], ortho_camera_down(), [], world=L)
    ls = LightSet(sc)
    assert [l.type for l in ls.lights] == ["WORLD"]
    n, rho = 20_000, 0.4
    c = np.array([1.0, -0.5, 0.7])
    centers = c + np.linspace(0.0, 1.0, n)[:, None] * np.array([0.5, 0.0, 0.0])      # a moving target
    o, d, P = ls.emit_toward(0, n, np.linspace(0, 1, n), np.random.default_rng(4), centers, rho)
    assert np.allclose(np.linalg.norm(d, axis=1), 1.0)
    oc = centers - o
    miss = np.linalg.norm(oc - np.sum(oc * d, axis=1)[:, None] * d, axis=1)      # line-to-centre distance
    assert np.all(miss <= rho + 1e-9) and np.all(np.sum(oc * d, axis=1) > 0)
    assert np.all(np.linalg.norm(o - ls._scene_center, axis=1) >= ls._scene_radius - 1e-9)
    assert np.allclose(P.sum(axis=0), 4 * np.pi * np.pi * rho ** 2 * L)
    # Lines through the sphere cover its cross-section uniformly: the disc perpendicular to d
    # through the centre is hit within rho / sqrt(2) by half of them
    assert abs(np.mean(miss < rho / np.sqrt(2)) - 0.5) < 0.02


def test_render_reports_lights_that_emit_nothing():
    l = Light(type="AREA", transform=MotionTransform.static(BASE), power=300.0, size=0.0, name="panel")
    r = render(_one_light_scene(l), RenderSettings(samples=1, photons_caustic=0, photons_global=0))
    assert any("'panel'" in w and "zero area" in w for w in r.warnings)
