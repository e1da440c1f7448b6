"""The densities behind multiple importance sampling of lights (kernels.lights.light_pdf, mesh_light_pdf).

Camera paths that go on through a rough lobe and reach a light weigh it against next-event
estimation with the power heuristic, which needs the density p_l with which next-event estimation
draws that direction (docs/rendering.md, "Multiple importance sampling").  Checked here:

* p_l integrates to 1 over the directions that reach the light (uniform directions, a light hit by
  ``seen_light``), for every shape the samplers treat apart;
* one light: what a ray from p hits (``seen_light``), what next-event estimation at p samples and
  its density describe the same shape and radiance (soft falloff: the disc facing p, as Cycles;
  until 2026-12-06 rays hit the sphere, whose wider silhouette (solid angle x (1 + x^2), x = r / d)
  only the camera paths' lobes reached: a bias of +1.8 % on rough metal and fireflies);
* the sampler's own weights agree with it: weight = L / p_l (area lights: L = color P / (pi A));
* the kernel's p_l equals the numpy oracle's (``lights_numpy.nee_pdf``: the rectangle's solid angle
  from two triangles' (Van Oosterom and Strackee), not from the spherical-rectangle code);
* unbiased: a near-mirror floor under an area light, a sphere light and an emissive panel renders
  the same image with and without the weighing (Z-test over seeds) and with a lower variance.
"""
from __future__ import annotations

import numpy as np
import pytest

from oracles import lights_numpy
from scenes import box_mesh, make_scene, persp_camera, plane_mesh, translate
from stpm_core.kernels.light_params import kernel_light, light_poses
from stpm_core.kernels.lights import light_pdf_batch, sample_pdf_batch, seen_batch
from stpm_core.lights import LightSet
from stpm_core.motion import MotionTransform
from stpm_core.render import render
from stpm_core.scene import Light, Material
from stpm_core.settings import RenderSettings
from stpm_core.shutter import Shutter


def _rot_x(a):
    c, s = np.cos(a), np.sin(a)
    M = np.eye(4)
    M[1:3, 1:3] = [[c, -s], [s, c]]
    return M


def _lights(*lights, objects=None, materials=None):
    mats = materials or [Material.diffuse((0.5, 0.5, 0.5))]
    scene = make_scene(objects or [plane_mesh(6.0)], mats, persp_camera((0, -4, 2), (0, 0, 0)), list(lights),
                       shutter=Shutter(1.0, 1.0))
    return LightSet(scene)


AREA = {
    "rectangle": dict(shape="RECTANGLE", size=1.2, size_y=0.5),
    "disk": dict(shape="DISK", size=0.9),
    "ellipse": dict(shape="ELLIPSE", size=1.1, size_y=0.4),
}


def _uniform_dirs(n, rng):
    v = rng.normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


@pytest.mark.parametrize("case", ["rectangle", "disk", "ellipse", "sphere", "soft", "sun"])
def test_light_density_integrates_to_one_over_the_light(case):
    M = translate(0.2, -0.1, 1.3) @ _rot_x(0.5)
    if case in AREA:
        light = Light(type="AREA", power=100.0, transform=MotionTransform.static(M), **AREA[case])
    elif case == "sun":
        # a 30-degree disc at infinity: escaping rays (t_scene = inf) inside its cone see it
        light = Light(type="SUN", power=3.0, angle=np.radians(30.0), transform=MotionTransform.static(M))
    else:
        light = Light(type="POINT", power=100.0, radius=0.4, use_soft_falloff=case == "soft",
                      transform=MotionTransform.static(M))
    ls = _lights(light)
    prm = kernel_light(ls, 0)[0]
    poses = light_poses(ls, 0, np.zeros(1))
    rng = np.random.default_rng(1)
    n = 400_000
    for p in ([0.0, 0.0, 0.0], [0.9, 0.4, 0.6]):
        P = np.tile(p, (n, 1))
        wi = _uniform_dirs(n, rng)
        pdf = np.empty(n)
        light_pdf_batch(prm, poses, P, wi, pdf)
        L = np.empty((n, 3))
        seen_batch(prm, poses, P, wi, np.full(n, np.inf), False, L)
        hit = L[:, 0] > 0                    # soft falloff: the disc through the centre facing p
        if case in ("soft", "sun"):
            # the shape a ray from p hits is the shape next-event estimation samples from p
            assert np.array_equal(hit, pdf > 0), (p, int(np.sum(hit != (pdf > 0))))
        assert hit.sum() > 1000
        est = 4.0 * np.pi * np.where(hit, pdf, 0.0)
        mean, se = est.mean(), est.std() / np.sqrt(n)
        assert abs(mean - 1.0) < max(4.0 * se, 0.01), (case, p, mean, se)


def _pdf_samples(ls, li, p, times, rng):
    k = kernel_light(ls, li)
    poses = light_poses(ls, li, times)
    S = np.empty((p.shape[0], 8))
    u = rng.random((p.shape[0], 2))
    sample_pdf_batch(k[0], poses, *k[2:], p, times, u, np.zeros_like(p), S)
    return S, u


@pytest.mark.parametrize("case", ["rectangle", "disk", "sphere", "soft", "mesh", "moving rectangle", "sun"])
def test_sampler_density_matches_its_weights_and_the_oracle(case):
    rng = np.random.default_rng(2)
    M = translate(0.1, 0.2, 1.5) @ _rot_x(0.3)
    objects, mats = None, None
    if case == "mesh":
        objects = [plane_mesh(6.0), (box_mesh((-0.3, -0.2, 1.2), (0.4, 0.3, 1.5), material=1), translate(0, 0, 0))]
        mats = [Material.diffuse((0.5, 0.5, 0.5)), Material.emitter((3.0, 2.0, 1.0))]
        ls = _lights(objects=objects, materials=mats)
    elif case == "moving rectangle":
        tr = MotionTransform(np.array([0.0, 1.0]), np.stack([M, translate(0.8, 0.0, 1.2) @ _rot_x(-0.2)]))
        ls = _lights(Light(type="AREA", power=80.0, transform=tr, **AREA["rectangle"]))
    elif case in AREA:
        ls = _lights(Light(type="AREA", power=80.0, transform=MotionTransform.static(M), **AREA[case]))
    elif case == "sun":
        ls = _lights(Light(type="SUN", power=80.0, angle=np.radians(5.0), transform=MotionTransform.static(M)))
    else:
        ls = _lights(Light(type="POINT", power=80.0, radius=0.3, use_soft_falloff=case == "soft",
                           transform=MotionTransform.static(M)))
    li = len(ls.lights) - 1
    n = 3000
    p = rng.uniform(-2.0, 2.0, (n, 3)) * [1, 1, 0.5]
    times = rng.random(n)
    S, u = _pdf_samples(ls, li, p, times, rng)
    wi, dist, w, pdf = S[:, 0:3], S[:, 3], S[:, 4:7], S[:, 7]
    front = w[:, 0] > 0
    assert front.sum() > n // 4
    # the weight is the radiance over the density: w p_l = L
    light = ls.lights[li]
    if light.type == "AREA":
        A = ls._area_shape(li, times)[3]
        L = np.asarray(light.color, float)[0] * light.power / (np.pi * A)
    elif light.type == "MESH":
        L = np.asarray(light.Le)[lights_numpy.mesh_triangle_of_sample(ls, li, u), 0]
    elif light.type == "SUN":
        L = np.asarray(light.color, float)[0] * light.power / (np.pi * np.sin(0.5 * light.angle) ** 2)   # Cycles' radiance
    else:
        L = np.asarray(light.color, float)[0] * light.power / (4 * np.pi) / (np.pi * 0.3 ** 2)
    np.testing.assert_allclose(w[front, 0] * pdf[front], np.broadcast_to(L, (n,))[front], rtol=1e-9)
    # the oracle's density, from the geometry alone
    j = x = None
    if light.type == "MESH":
        j, x = lights_numpy.mesh_triangle_of_sample(ls, li, u), p + dist[:, None] * wi
    ref = lights_numpy.nee_pdf(ls, li, p, wi, times, x=x, j=j)
    np.testing.assert_allclose(pdf[front], ref[front], rtol=1e-7)


@pytest.mark.parametrize("case", ["point soft", "spot soft", "point sphere", "point soft, inside", "sun"])
def test_rays_hit_the_shape_next_event_estimation_samples(case):
    """From points p around the light: every direction next-event estimation draws hits the light's
    shape with the radiance the sample carries (seen = weight x p_l), and uniform directions hit it
    exactly where p_l > 0 (soft falloff: the disc facing p; the sphere: its cone; a sun of angle > 0:
    its cone, for rays that escape)."""
    rng = np.random.default_rng(5)
    M = translate(0.1, 0.2, 1.5) @ _rot_x(0.4)
    kw = dict(radius=0.3, use_soft_falloff="soft" in case, transform=MotionTransform.static(M))
    if case.startswith("spot"):
        light = Light(type="SPOT", power=120.0, spot_size=1.6, spot_blend=0.3, **kw)
    elif case == "sun":
        light = Light(type="SUN", power=3.0, angle=np.radians(40.0), transform=kw["transform"])
    else:
        light = Light(type="POINT", power=80.0, **kw)
    ls = _lights(light)
    n = 20_000
    if case.endswith("inside"):              # closer to the centre than the radius
        v = _uniform_dirs(n, rng)
        p = M[:3, 3] + v * rng.uniform(0.02, 0.29, (n, 1))
    else:
        p = rng.uniform(-2.0, 2.0, (n, 3)) * [1, 1, 0.5]
    times = np.zeros(n)
    S, _ = _pdf_samples(ls, 0, p, times, rng)
    wi, w, pdf = np.ascontiguousarray(S[:, 0:3]), S[:, 4:7], S[:, 7]      # (C arrays: one compiled kernel)
    prm, poses = kernel_light(ls, 0)[0], light_poses(ls, 0, np.zeros(1))
    L = np.empty((n, 3))
    seen_batch(prm, poses, p, wi, np.full(n, np.inf), False, L)
    lit = w[:, 0] > 0
    assert lit.sum() > n // 4
    if "sphere" in case:
        # directions at the cone's rim may round off the sphere: all but a few hit it
        ok = lit & (L[:, 0] > 0)
        assert ok.sum() > 0.999 * lit.sum(), (int(ok.sum()), int(lit.sum()))
    else:
        ok = lit
    np.testing.assert_allclose(L[ok], w[ok] * pdf[ok, None], rtol=1e-9)
    np.testing.assert_allclose(L[ok], lights_numpy.seen_lights_numpy(ls, p[ok], wi[ok], times[ok],
                                                                     np.full(int(ok.sum()), np.inf)), rtol=1e-9)
    if "sphere" in case:
        return                               # (the sphere's density is 1 / Omega in every direction)
    # uniform directions: a ray hits the disc exactly where next-event estimation can draw it
    u = _uniform_dirs(n, rng)
    pdf_u = np.empty(n)
    light_pdf_batch(prm, poses, p, u, pdf_u)
    seen_batch(prm, poses, p, u, np.full(n, np.inf), False, L)
    hit = L[:, 0] > 0
    sel = np.ones(n, bool)
    if case.startswith("spot"):              # outside its cone a spot is black: nothing to see
        axis = -M[:3, 2] / np.linalg.norm(M[:3, 2])
        sel = lights_numpy.spot_attenuation(light, -u @ axis) > 0
    assert np.array_equal(hit[sel], pdf_u[sel] > 0), int(np.sum(hit[sel] != (pdf_u[sel] > 0)))
    assert hit[sel].sum() > 50


def test_delta_lights_and_suns_of_angle_zero_have_no_density():
    ls = _lights(Light(type="POINT", power=10.0, radius=0.0, transform=MotionTransform.static(translate(0, 0, 2))),
                 Light(type="SUN", power=2.0, angle=0.0, transform=MotionTransform.static(np.eye(4))))
    rng = np.random.default_rng(3)
    p = rng.normal(size=(50, 3))
    for li in range(2):
        S, _ = _pdf_samples(ls, li, p, np.zeros(50), rng)
        assert np.all(np.isinf(S[:, 7]))


def _mirror_floor_scene():
    """A near-mirror metal floor (roughness 0.1) reflecting a tilted area light, a sphere light (soft
    falloff) and an emissive box (a MESH light) that moves during the shutter; black world."""
    mats = [Material(base_color=np.array([0.9, 0.9, 0.9]), metallic=1.0, roughness=0.1),
            Material.emitter((4.0, 3.0, 2.0))]
    moving_box = MotionTransform(np.array([0.0, 1.0]), np.stack([translate(0.0, 0.0, 0.0), translate(0.3, 0.0, 0.1)]))
    objects = [plane_mesh(8.0), (box_mesh((-0.2, 1.6, 0.9), (0.2, 1.8, 1.2), material=1), moving_box)]
    lights = [Light(type="AREA", power=60.0, shape="RECTANGLE", size=0.8, size_y=0.4,
                    transform=MotionTransform.static(translate(-1.0, 1.5, 1.6) @ _rot_x(-0.35))),
              Light(type="POINT", power=40.0, radius=0.15, use_soft_falloff=True,
                    transform=MotionTransform.static(translate(1.1, 1.0, 1.2)))]
    return make_scene(objects, mats, persp_camera((0, -3.0, 0.9), (0, 1.0, 0.3), lens=30), lights,
                      resolution=(32, 24), shutter=Shutter(1.0, 1.5))


def test_weighing_leaves_the_image_unbiased_and_cuts_its_noise():
    """Glossy bounces 1: the path through the floor's rough lobe and next-event estimation share each
    light (power heuristic).  Glossy bounces 0: next-event estimation alone.  Same mean image (block
    Z-test over 6 seeds), and the weighed one has far lower per-pixel variance (measured ~0.1x)."""
    scene = _mirror_floor_scene()
    imgs = {}
    for gb in (0, 1):
        imgs[gb] = np.stack([render(scene, RenderSettings(samples=16, seed=s, photons_caustic=0, photons_global=0,
                                                            max_depth=1, glossy_bounces=gb)).passes["Combined"][..., :3]
                             for s in range(6)]).astype(np.float64).mean(axis=-1)
    a, b = imgs[1], imgs[0]
    assert np.all(np.isfinite(a)) and a.min() >= 0.0
    blocks = lambda x: x.reshape(x.shape[0], 6, 4, 8, 4).mean(axis=(2, 4))      # 4 x 4 px blocks
    A, B = blocks(a), blocks(b)
    se = np.sqrt(A.var(0, ddof=1) / 6 + B.var(0, ddof=1) / 6 + (0.002 * B.mean(0)) ** 2 + 1e-12)
    z = (A.mean(0) - B.mean(0)) / se
    assert np.abs(z).max() < 5.0, np.round(z, 1)
    # the whole image's mean: next-event estimation alone through the near-mirror lobe has heavy tails
    # (its image mean varies by 20 % from seed to seed), so the tolerance is its standard error
    ma, mb = a.mean(axis=(1, 2)), b.mean(axis=(1, 2))
    z_mean = (ma.mean() - mb.mean()) / np.sqrt(ma.var(ddof=1) / 6 + mb.var(ddof=1) / 6)
    assert abs(z_mean) < 4.0, (ma.mean(), mb.mean(), z_mean)
    lit = b.mean(0) > 0.05 * b.mean(0).max()
    ratio = float(np.median(a.var(0, ddof=1)[lit] / np.maximum(b.var(0, ddof=1)[lit], 1e-12)))
    print(f"per-pixel variance, weighed / next-event estimation alone: {ratio:.3f} over {int(lit.sum())} px")
    assert ratio < 0.5, ratio
