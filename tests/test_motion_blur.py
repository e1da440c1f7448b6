"""Motion blur: camera-sample times spread over the shutter, against analytic time averages.

Pixel value = (1 / shutter) * integral over the shutter of radiance; for an
object moving at constant speed that is a coverage ramp, computed here by
direct quadrature in time and space (independent of the renderer's sampler).
"""
from __future__ import annotations

import numpy as np
import pytest

from scenes import box_mesh, look_at, make_scene, moving, ortho_camera_down, plane_mesh, translate
from stpm_core.film import blackman_harris
from stpm_core.motion import MotionTransform
from stpm_core.render import render
from stpm_core.scene import Light, Material
from stpm_core.settings import RenderSettings
from stpm_core.shutter import Shutter

W, H = 16, 2
SCALE = 2.0                      # the view spans x in [-1, 1]
PIX = SCALE / W


def _covered_fraction(x: np.ndarray, c0: float, c1: float, half: float, times=None, cdf=lambda u: u) -> np.ndarray:
    """Share of the shutter during which world x (m,) lies inside [c(t) - half, c(t) + half], c linear c0 -> c1.

    Exact: x is covered for t in [(x - half - c0) / (c1 - c0), (x + half - c0) / (c1 - c0)] (clipped to
    [0, 1]), whose shutter mass is cdf(t_b) - cdf(t_a).  With ``times`` (k,): the fraction of those instants.
    """
    if times is not None:
        c = c0 + (c1 - c0) * np.asarray(times)[:, None]
        return np.mean(np.abs(x[None, :] - c) <= half, axis=0)
    ta = np.clip((x - half - c0) / (c1 - c0), 0.0, 1.0)
    tb = np.clip((x + half - c0) / (c1 - c0), 0.0, 1.0)
    lo, hi = np.minimum(ta, tb), np.maximum(ta, tb)
    return cdf(hi) - cdf(lo)


def _pixel_average(f_of_x, filter_width: float) -> np.ndarray:
    """Pixel columns (W,) of a function of world x: box over the pixel, or the Blackman-Harris window."""
    centres = -1.0 + (np.arange(W) + 0.5) * PIX
    if filter_width == 0.0:
        s = (np.arange(200) + 0.5) / 200 - 0.5
        xs = centres[:, None] + s[None, :] * PIX
        return f_of_x(xs.ravel()).reshape(W, -1).mean(1)
    r = filter_width
    s = np.linspace(-r, r, 801)
    w = blackman_harris(s, r)
    xs = centres[:, None] + s[None, :] * PIX
    return (f_of_x(xs.ravel()).reshape(W, -1) * w).sum(1) / w.sum()


def _moving_box_scene(c0, c1, half, shutter=Shutter(1.0, 2.0)):
    """An emissive (radiance 1) slab moving along x under an ortho camera, black world."""
    slab = box_mesh((-half, -5, -0.1), (half, 5, 0.1))
    return make_scene([(slab, moving((c0, 0, 0), (c1, 0, 0)))], [Material.emitter((1.0, 1.0, 1.0))],
                      ortho_camera_down(ortho_scale=SCALE), resolution=(W, H), shutter=shutter)


@pytest.mark.parametrize("filter_width", [0.0, 1.5])
def test_moving_box_coverage_is_the_time_average(filter_width):
    c0, c1, half = -0.9, 0.5, 0.2
    scene = _moving_box_scene(c0, c1, half)
    st = RenderSettings(samples=400, photons_global=0, photons_caustic=0, filter_width=filter_width, seed=1)
    got = render(scene, st).passes["Emit"][..., 0].mean(0)        # average the two rows
    want = _pixel_average(lambda x: _covered_fraction(x, c0, c1, half), filter_width)
    # interior columns (the filter window is cut at the image border)
    sl = slice(0, W) if filter_width == 0 else slice(2, W - 2)
    np.testing.assert_allclose(got[sl], want[sl], atol=0.02)
    assert want.max() - want.min() > 0.25         # a real ramp, not a constant


def test_accumulation_averages_stills_at_stratified_instants():
    c0, c1, half, N = -0.9, 0.5, 0.2, 5
    scene = _moving_box_scene(c0, c1, half)
    st = RenderSettings(method="ACCUMULATION", accumulation_steps=N, samples=16, photons_global=0,
                        photons_caustic=0, filter_width=0.0, seed=1)
    res = render(scene, st)
    got = res.passes["Emit"][..., 0].mean(0)
    t = (np.arange(N) + 0.5) / N                   # the instants of the accumulation buffer
    want = _pixel_average(lambda x: _covered_fraction(x, c0, c1, half, t), 0.0)
    np.testing.assert_allclose(got, want, atol=0.02)
    assert res.stats["method"] == "ACCUMULATION" and res.stats["estimator"] == "STANDARD"


def test_shutter_curve_weights_time():
    """A ramp shutter curve (density 2u) weights late instants more: the box's late positions dominate."""
    c0, c1, half = -0.9, 0.5, 0.2
    scene = _moving_box_scene(c0, c1, half, shutter=Shutter(1.0, 2.0, curve=np.array([0.0, 1.0])))
    st = RenderSettings(samples=400, photons_global=0, photons_caustic=0, filter_width=0.0, seed=2)
    got = render(scene, st).passes["Emit"][..., 0].mean(0)
    want = _pixel_average(lambda x: _covered_fraction(x, c0, c1, half, cdf=lambda u: u * u), 0.0)  # density 2u
    np.testing.assert_allclose(got, want, atol=0.02)


def test_shadow_of_a_moving_occluder():
    """A slab above the camera passes between a 45 degree sun and a diffuse floor: the floor's
    radiance is rho/pi * S cos(45) times the fraction of the shutter it is not in shadow."""
    rho, S, hz, half, thick = 0.5, 2.0, 3.0, 0.25, 0.1
    c0, c1 = -4.5, -3.0                                      # slab centre moves along x at z = hz
    sun_dir = np.array([-1.0, 0.0, 1.0]) / np.sqrt(2)        # toward the sun: the shadow lands hz further +x
    sun = Light(type="SUN", power=S, transform=MotionTransform.static(look_at(sun_dir, (0, 0, 0))))
    slab = box_mesh((-half, -20, -thick / 2), (half, 20, thick / 2))
    scene = make_scene([plane_mesh(40.0), (slab, moving((c0, 0, hz), (c1, 0, hz)))],
                       [Material.diffuse((rho, rho, rho))],
                       ortho_camera_down(height=2.0, ortho_scale=SCALE, center=(-0.5 + 0.0, 0.0)),
                       [sun], resolution=(W, H), shutter=Shutter(1.0, 1.5))
    st = RenderSettings(samples=400, photons_global=0, photons_caustic=0, filter_width=0.0, seed=4)
    got = render(scene, st).passes["Direct"][..., 0].mean(0)
    L0 = rho / np.pi * S * np.cos(np.pi / 4)
    # A slab point (x, z) shadows floor x + z: the shadow is centred at c + hz, half-width half + thick / 2.
    # The view spans x in [-1.5, 0.5]: shift the helper's [-1, 1] columns by -0.5
    shadow = lambda x: _covered_fraction(x - 0.5, c0 + hz, c1 + hz, half + thick / 2)
    want = L0 * (1.0 - _pixel_average(shadow, 0.0))
    np.testing.assert_allclose(got, want, atol=0.02 * L0)
    assert want.min() < 0.7 * L0 and want.max() == pytest.approx(L0)


def test_moving_camera_blurs_a_static_slab():
    """The camera slides +x by 1.4 over the shutter: a static slab moves -1.4 across the view."""
    half = 0.2
    slab = box_mesh((-half, -5, -0.1), (half, 5, 0.1))
    cam = ortho_camera_down(ortho_scale=SCALE)
    cam.transform = moving((0.9, 0, 5.0), (-0.5, 0, 5.0))   # the view centre goes from x = 0.9 to -0.5
    scene = make_scene([slab], [Material.emitter((1.0, 1.0, 1.0))], cam, resolution=(W, H),
                       shutter=Shutter(1.0, 2.0))
    st = RenderSettings(samples=400, photons_global=0, photons_caustic=0, filter_width=0.0, seed=5)
    got = render(scene, st).passes["Emit"][..., 0].mean(0)
    # In view coordinates the slab centre is at -(camera x): from -0.9 to 0.5
    want = _pixel_average(lambda x: _covered_fraction(x, -0.9, 0.5, half), 0.0)
    np.testing.assert_allclose(got, want, atol=0.02)


# ---------------------------------------------------------------------------
# Photon maps with motion: a receiver moving through a static caustic
# ---------------------------------------------------------------------------
def test_moving_receiver_in_a_static_caustic():
    """A vertical sun, a 45 degree mirror and a wall that recedes from x = 3 to x = 4 along the
    reflected beam: the wall's caustic irradiance is R S at every instant, so its radiance is
    rho / pi * R * S.  Time-less photons (STANDARD) spread over the swept slab and come out far too
    dark; TEMPORAL and the accumulation baseline get it right."""
    from stpm_core.bsdf import MaterialTable, bsdf_sample
    from stpm_core.scene import Camera

    rho, S = 0.5, 2.0
    sun = Light(type="SUN", power=S, transform=MotionTransform.static(np.eye(4)))
    R90 = np.array([[0, 0, -1, 0], [0, 1, 0, 0], [1, 0, 0, 0], [0, 0, 0, 1.0]])   # plane normal +Z -> -X
    wall_T = MotionTransform(times=np.array([0.0, 1.0]),
                             matrices=np.stack([translate(3, 0, 0) @ R90, translate(4, 0, 0) @ R90]))
    c = np.cos(np.pi / 4)
    mirror_M = np.array([[c, 0, c, 0], [0, 1, 0, 0], [-c, 0, c, 0], [0, 0, 0, 1.0]])
    mats = [Material.diffuse((rho, rho, rho)), Material.mirror((0.9, 0.7, 0.5))]
    cam = Camera(type="ORTHO", ortho_scale=0.3, clip_start=0.01, clip_end=100,
                 transform=MotionTransform.static(look_at((1, 0, 0), (3, 0, 0))))
    scene = make_scene([(plane_mesh(20.0), wall_T), (plane_mesh(1.0, material=1), mirror_M)], mats, cam, [sun],
                       resolution=(8, 8), shutter=Shutter(1.0, 2.0))
    n = np.array([[c, 0.0, c]])
    _, F, _ = bsdf_sample(MaterialTable(mats), np.array([1]), np.array([[0.0, 0.0, 1.0]]), n, n, np.full((1, 3), 0.5))
    want = rho / np.pi * S * F[0]

    def caustic(**kw):
        st = RenderSettings(samples=4, photons_caustic=40_000, photons_global=0, k_nearest=30, filter_width=0.0,
                            seed=1, **kw)
        return render(scene, st).passes["Caustic"].mean(axis=(0, 1))

    assert np.all(caustic(estimator="STANDARD") < 0.3 * want)
    np.testing.assert_allclose(caustic(estimator="TEMPORAL"), want, rtol=0.10)
    np.testing.assert_allclose(caustic(method="ACCUMULATION", accumulation_steps=4), want, rtol=0.05)
