"""Bounce budgets per kind with Cycles' names and defaults: ``diffuse_bounces`` (4) and
``transparent_max_bounces`` (8) beside ``glossy_bounces`` / ``transmission_bounces``.

Diffuse bounces are counted as Cycles counts them (docs/rendering.md, "Bounce budgets"): a camera
vertex reading a photon map makes one, each bounce of the photon off a DIFFUSE lobe another, but
not one at the photon's first hit (light straight from the light there: next-event estimation in
Cycles).  So

* ``diffuse_bounces = 0`` is direct light only: no photon map, no caustic either (Cycles: the
  camera path must bounce off the diffuse receiver to find a caustic; measured with bpy 5.0.1, a
  mirror caustic is 0 at 0 diffuse bounces and 0.39 at 1);
* in a closed diffuse sphere of albedo rho around a point light, Indirect / Direct is
  rho + rho^2 + ... + rho^N with N = diffuse_bounces (the truncated geometric series), and the
  global map's stored power P (rho + ... + rho^N);
* light that reached a diffuse surface through a mirror needs a diffuse bounce there, so its
  interreflection needs 2 (L S D D E: the caustic map at 1, the global map's photons at 2).

Transparent bounces: see also tests/test_transparency.py (sheets over a lit floor).
"""
from __future__ import annotations

import numpy as np
import pytest

from scenes import box_mesh, look_at, make_scene, ortho_camera_down, persp_camera, plane_mesh, point_light, \
    sphere_mesh, translate
from stpm_core.errors import SettingsError
from stpm_core.lights import LightSet
from stpm_core.motion import MotionTransform
from stpm_core.photons import build_photon_maps
from stpm_core.plan import make_plan
from stpm_core.raycast import make_caster
from stpm_core.render import render
from stpm_core.scene import Light, Material
from stpm_core.settings import RenderSettings
from stpm_core.transparency import TRANSPARENT_MAX_BOUNCES

P = 100.0
RHO = 0.5


# ----------------------------------------------------------------------------
# Settings
# ----------------------------------------------------------------------------
def test_defaults_are_cycles():
    s = RenderSettings()
    assert (s.diffuse_bounces, s.glossy_bounces, s.transmission_bounces, s.transparent_max_bounces) == (4, 4, 12, 8)
    assert TRANSPARENT_MAX_BOUNCES == s.transparent_max_bounces
    names = [spec.name for spec in RenderSettings.SPECS]
    assert names.index("max_depth") < names.index("diffuse_bounces") < names.index("glossy_bounces") \
        < names.index("transmission_bounces") < names.index("transparent_max_bounces")


@pytest.mark.parametrize("name", ["diffuse_bounces", "transparent_max_bounces"])
@pytest.mark.parametrize("bad", [-1, 1025, 2.0, "4", True, None])
def test_bad_bounce_counts_are_refused_naming_the_setting(name, bad):
    with pytest.raises(SettingsError, match=rf"^{name} must be an integer in \[0, 1024\], got "):
        RenderSettings(**{name: bad})
    with pytest.raises(SettingsError, match=rf"^{name} must be an integer"):
        RenderSettings.from_dict({name: bad})


@pytest.mark.parametrize("name", ["diffuse_bounces", "transparent_max_bounces"])
def test_bounce_counts_take_the_whole_range(name):
    for v in (0, 1, 1024, np.int64(7)):
        assert getattr(RenderSettings(**{name: v}), name) == int(v)


# ----------------------------------------------------------------------------
# A closed diffuse sphere around a point light: the truncated geometric series
# ----------------------------------------------------------------------------
def _furnace(rho: float = RHO):
    """A closed sphere (radius 2, facing inward) of albedo rho around a point light of P W; a
    camera inside looks at the wall."""
    inner = sphere_mesh(2.0, n_theta=32, n_phi=64, material=0)
    inner.triangles = inner.triangles[:, ::-1].copy()
    inner.normals = -inner.normals
    cam = persp_camera((0.0, 0.0, 0.3), (1.0, 0.2, -0.1), lens=12.0)
    return make_scene([inner], [Material.diffuse((rho, rho, rho))], cam, [point_light((0, 0, 0), P)],
                      resolution=(16, 12))


def _series(rho: float, n: int) -> float:
    return sum(rho ** k for k in range(1, n + 1))


@pytest.mark.parametrize("n", [0, 1, 2, 4])
def test_global_map_power_is_the_truncated_series(n):
    """Stored global power: P (rho + ... + rho^N).  A photon's first bounce is not counted (light
    from the light: next-event estimation's in Cycles), so N = 1 keeps rho P (photons stored at
    their second hit) and N = 0 nothing."""
    scene = _furnace()
    maps = build_photon_maps(scene, RenderSettings(photons_global=40_000, photons_caustic=0, max_depth=40,
                                                   diffuse_bounces=n), make_caster(scene), LightSet(scene))
    stored = maps.maps["global"].power.astype(float).sum(0) if maps.has("global") else np.zeros(3)
    np.testing.assert_allclose(stored, P * _series(RHO, n), rtol=0.02)


def test_indirect_over_direct_follows_the_diffuse_budget():
    """Rendered: Indirect / Direct = rho + ... + rho^N on the sphere's wall (uniform irradiance; the
    point light at the centre lights every point at normal incidence), 0 at N = 0 with Direct
    unchanged; N = 1 -> 0.5, N = 4 -> 0.9375 (rho = 0.5).  Measured over seeds 0-2: within 1.3 % of
    the series at both N (the density estimate's noise on the wall the camera sees)."""
    scene = _furnace()
    base = dict(samples=4, photons_global=200_000, photons_caustic=0, k_nearest=100, max_depth=40, seed=2,
                effects="MANUAL", caustics=False, indirect=True, filter_width=0.0)
    direct, ratio = {}, {}
    for n in (0, 1, 4):
        r = render(scene, RenderSettings(diffuse_bounces=n, **base))
        direct[n] = r.passes["Direct"][..., :3].astype(float)
        ratio[n] = r.passes["Indirect"][..., :3].astype(float).mean() / direct[n].mean()
        if n == 0:
            assert not r.plan["indirect"] and not r.plan["caustics"], r.plan["reasons"]
            assert any("diffuse_bounces = 0" in line for line in r.plan["reasons"])
    print({n: round(v, 4) for n, v in ratio.items()})
    assert ratio[0] == 0.0
    assert np.array_equal(direct[0], direct[1]) and np.array_equal(direct[1], direct[4])
    for n in (1, 4):
        assert ratio[n] == pytest.approx(_series(RHO, n), rel=0.04), (n, ratio[n])


# ----------------------------------------------------------------------------
# Caustics: one diffuse bounce in Cycles' count
# ----------------------------------------------------------------------------
def _mirror_caustic_scene():
    """A point light 1 m above a diffuse floor under a 1 x 1 m mirror facing down at 2 m; an
    orthographic camera at 1.5 m (below the mirror) sees the floor inside the caustic."""
    mats = [Material.diffuse((0.8, 0.8, 0.8)), Material.mirror()]
    objs = [plane_mesh(10.0, material=0, name="floor"),
            (plane_mesh(1.0, material=1, flip=True, name="mirror"), translate(0, 0, 2.0))]
    cam = ortho_camera_down(1.5, 2.0)
    return make_scene(objs, mats, cam, [point_light((0, 0, 1.0), P)], resolution=(8, 8))


def test_no_diffuse_bounce_means_no_caustic_either_as_cycles():
    scene = _mirror_caustic_scene()
    base = dict(samples=2, photons_global=20_000, photons_caustic=20_000, seed=1, effects="MANUAL",
                caustics=True, indirect=True)
    res = {n: render(scene, RenderSettings(diffuse_bounces=n, **base)) for n in (0, 1, 4)}
    for name in ("Caustic", "Indirect"):
        assert np.all(res[0].passes[name] == 0.0), name
    assert res[0].stats["photons_caustic"] == 0 and res[0].stats["photons_global"] == 0
    # one diffuse bounce (the floor's, read by the camera) is all a caustic needs: the caustic map
    # is the same at 1 and 4.  Its level: the light's mirror image 3 m above the floor,
    # rho / pi * I * 3 / d^3 at the pixels' centres (the camera sees 2 x 2 m inside the caustic)
    c = (np.arange(8) + 0.5) / 8 * 2.0 - 1.0
    x, y = np.meshgrid(c, c)
    want = 0.8 / np.pi * P / (4 * np.pi) * 3.0 / (x ** 2 + y ** 2 + 9.0) ** 1.5
    assert res[1].passes["Caustic"][..., 0].mean() == pytest.approx(want.mean(), rel=0.1)
    assert np.array_equal(res[1].passes["Caustic"], res[4].passes["Caustic"])
    assert np.array_equal(res[0].passes["Direct"], res[1].passes["Direct"])


def test_make_plan_says_why_with_no_diffuse_bounce():
    scene = _mirror_caustic_scene()
    assert make_plan(scene, RenderSettings())["caustics"]
    plan = make_plan(scene, RenderSettings(diffuse_bounces=0))
    assert not plan["caustics"] and not plan["indirect"]
    assert any(line.startswith("caustics, indirect: off (diffuse_bounces = 0") for line in plan["reasons"])


def test_light_through_a_mirror_needs_a_counted_diffuse_bounce():
    """A spot light shining up into a mirror: every photon reaches the floor through the mirror, so
    its bounce off the floor is a counted diffuse bounce (in Cycles the camera path must bounce off
    the floor to find that light, next-event estimation cannot).  What the floor sends on to a wall
    is L S D D E: 2 diffuse bounces.  At diffuse_bounces 1 the global map is empty and the caustic
    map (L S D E) full; at 2 the global map holds the wall's light."""
    spot = Light(type="SPOT", power=P, spot_size=0.5, spot_blend=0.0,
                 transform=MotionTransform.static(look_at((0, 0, 1.0), (0, 0, 2.0), up=(0, 1, 0))))
    mats = [Material.diffuse((0.8, 0.8, 0.8)), Material.mirror()]
    objs = [plane_mesh(10.0, material=0, name="floor"),
            (plane_mesh(4.0, material=1, flip=True, name="mirror"), translate(0, 0, 2.0)),
            box_mesh((1.5, -3.0, 0.0), (1.7, 3.0, 1.9), material=0, name="wall")]
    scene = make_scene(objs, mats, ortho_camera_down(), [spot], resolution=(8, 8))
    caster, lights = make_caster(scene), LightSet(scene)
    stored = {}
    for n in (1, 2):
        maps = build_photon_maps(scene, RenderSettings(photons_global=20_000, photons_caustic=20_000,
                                                       diffuse_bounces=n), caster, lights)
        stored[n] = {k: maps.maps[k].power.shape[0] for k in ("caustic", "global")}
    print(stored)
    assert stored[1]["global"] == 0
    assert stored[2]["global"] > 1000
    assert stored[1]["caustic"] == stored[2]["caustic"] > 100     # (aimed at the mirror: most miss the cone)


def test_the_photon_tracer_alone_has_no_diffuse_budget():
    """trace_photon_paths without diffuse_bounces has no budget (the tests' and the plan probe's
    direct calls); the maps' builders pass the settings' (test_global_map_power_is_the_truncated_series)."""
    import inspect
    from stpm_core.photons.trace import trace_photon_paths
    sig = inspect.signature(trace_photon_paths)
    assert sig.parameters["diffuse_bounces"].default is None
    assert sig.parameters["transparent_bounces"].default == TRANSPARENT_MAX_BOUNCES
