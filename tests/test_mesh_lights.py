"""Emissive meshes as lights: next-event estimation and photon emission from
surfaces with ``Material.emission`` (stpm_core.lights.MeshLight)."""
from __future__ import annotations

import numpy as np
import pytest

from scenes import make_scene, moving, ortho_camera_down, plane_mesh, translate
from stpm_core.bsdf import MaterialTable
from stpm_core.lights import LightSet
from stpm_core.motion import MotionTransform
from stpm_core.render import render
from stpm_core.scene import Material
from stpm_core.settings import RenderSettings
from stpm_core.shutter import Shutter


def rect_irradiance(L: float, a: float, b: float, h: float) -> float:
    """Irradiance W/m^2 under the centre of an a x b Lambertian rectangle of radiance L, parallel at height h.

    E = L pi F with F the differential-area-to-rectangle form factor, summed over
    the four a/2 x b/2 quarters that meet above the point (each seen from under
    its corner): F_corner = 1/(2 pi) [X / sqrt(1+X^2) atan(Y / sqrt(1+X^2))
    + Y / sqrt(1+Y^2) atan(X / sqrt(1+Y^2))], X = (a/2)/h, Y = (b/2)/h.
    """
    X, Y = 0.5 * a / h, 0.5 * b / h
    sx, sy = np.sqrt(1 + X * X), np.sqrt(1 + Y * Y)
    F_corner = (X / sx * np.arctan(Y / sx) + Y / sy * np.arctan(X / sy)) / (2 * np.pi)
    return L * np.pi * 4 * F_corner


def _quad_scene(h=1.0, a=0.6, b=0.4, Le=(2.0, 1.0, 0.5), rho=0.5, transform=None, flip=False,
                shutter=None, res=(8, 8), ortho_scale=0.02):
    """Diffuse floor (rho) at z = 0, emissive a x b quad at height h, ortho camera looking down
    from below the quad (the quad is behind the camera, so it only lights the floor)."""
    quad = plane_mesh(a, b, z=0.0, material=1, flip=flip, name="emitter")
    quad_tr = transform if transform is not None else translate(0, 0, h)
    mats = [Material.diffuse((rho, rho, rho)), Material.emitter(Le)]
    cam = ortho_camera_down(height=0.5 * h, ortho_scale=ortho_scale)
    return make_scene([plane_mesh(20.0), (quad, quad_tr)], mats, cam, [], resolution=res,
                      shutter=shutter)


@pytest.mark.parametrize("flip", [False, True])
def test_emissive_quad_lights_a_diffuse_floor_like_the_form_factor(flip):
    """Pixel radiance under the quad = rho / pi * E_rect within 1 % (both quad orientations emit)."""
    Le, rho, h, a, b = np.array([2.0, 1.0, 0.5]), 0.5, 1.0, 0.6, 0.4
    scene = _quad_scene(h, a, b, Le, rho, flip=flip)
    res = render(scene, RenderSettings(samples=256, photons_caustic=0, photons_global=0, seed=3))
    img = res.passes["Combined"][..., :3].reshape(-1, 3).mean(axis=0)
    expect = rho / np.pi * rect_irradiance(1.0, a, b, h) * Le
    assert np.allclose(img, expect, rtol=0.01), (img, expect)
    # All of it is Direct light (the floor does not emit; the camera does not see the quad)
    assert np.allclose(res.passes["Emit"], 0.0)
    assert np.allclose(res.passes["Direct"][..., :3].reshape(-1, 3).mean(0), img, rtol=1e-5)


def test_sample_direct_matches_form_factor_irradiance():
    """E = mean(weight * cos) from LightSet.sample_direct at a point under the quad (no renderer)."""
    h, a, b = 0.7, 1.0, 0.5
    scene = _quad_scene(h, a, b, Le=(1.0, 1.0, 1.0))
    ls = LightSet(scene)
    assert len(ls) == 1 and ls.lights[0].type == "MESH"
    n = 200_000
    rng = np.random.default_rng(0)
    p = np.zeros((n, 3))
    wi, dist, w = ls.sample_direct(0, p, np.zeros(n), rng.random((n, 2)))
    E = np.mean(w[:, 0] * np.maximum(wi[:, 2], 0.0))
    assert E == pytest.approx(rect_irradiance(1.0, a, b, h), rel=0.01)
    assert np.allclose(dist, np.linalg.norm(p + dist[:, None] * wi - p, axis=1))
    assert np.allclose((p + dist[:, None] * wi)[:, 2], h)      # the samples lie on the quad


def test_moving_emissive_quad_lights_the_floor_where_it_is_at_each_time():
    """A quad sliding from x = -X to x = +X: renders at t = 0 and t = 1 see it above each end."""
    h, a, b, X = 0.5, 0.4, 0.4, 0.5
    tr = moving((-X, 0, h), (X, 0, h))
    scene = _quad_scene(h, a, b, Le=(1.0, 1.0, 1.0), transform=tr, shutter=Shutter(1.0, 1.0))
    # Camera over x = -X: at t = 0 the quad is right above (irradiance at its centre);
    # at t = 1 it is 2X away (far weaker)
    scene.camera = ortho_camera_down(height=0.5 * h, ortho_scale=0.02, center=(-X, 0.0))
    from stpm_core.integrator import trace_image
    from stpm_core.raycast import make_caster
    st = RenderSettings(samples=128, photons_caustic=0, photons_global=0, seed=1)
    E0 = rect_irradiance(1.0, a, b, h)
    for t, expect in ((0.0, E0), (1.0, None)):
        passes, _ = trace_image(scene, st, make_caster(scene), LightSet(scene), None, time_override=t)
        v = passes["Combined"][..., 0].mean()
        if expect is None:
            # At t = 1: the quad is centred 2X = 1.0 away in x; irradiance by direct integration
            n = 400
            g = (np.arange(n) + 0.5) / n
            xs, ys = X - a / 2 + a * g, -b / 2 + b * g
            XX, YY = np.meshgrid(xs, ys)
            r2 = (XX + X) ** 2 + YY ** 2 + h * h
            expect = np.sum(h * h / (r2 * r2)) * (a / n) * (b / n)
        assert v == pytest.approx(0.5 / np.pi * expect, rel=0.02), (t, v, 0.5 / np.pi * expect)


def test_photons_from_a_mesh_light_carry_its_flux():
    """emit(): sum of photon power = 2 pi Le A (both sides); emit_toward(): aimed photons deliver
    the irradiance sample_direct predicts on a small disc."""
    h, a, b = 1.0, 0.6, 0.4
    Le = np.array([2.0, 1.0, 0.5])
    scene = _quad_scene(h, a, b, Le=Le)
    ls = LightSet(scene)
    li = 0
    assert np.allclose(ls.flux(li), 2 * np.pi * Le * a * b, rtol=1e-6)
    assert ls.power[li] == pytest.approx(np.mean(2 * np.pi * Le * a * b), rel=1e-6)
    rng = np.random.default_rng(5)
    n = 400_000
    o, d, Phi = ls.emit(li, n, np.zeros(n), rng)
    assert np.allclose(Phi.sum(0), ls.flux(li), rtol=1e-9)                # equal powers: exact
    assert np.allclose(ls.flux(li), 2 * np.pi * Le * a * b, rtol=1e-6)   # float32 vertices
    assert np.allclose(o[:, 2], h) and np.all(np.abs(o[:, 0]) <= a / 2 + 1e-12)
    assert abs(np.mean(d[:, 2] > 0) - 0.5) < 0.01                        # both sides
    # Flux through a small disc of radius r on the floor under the centre (facing up):
    # photons going down that cross it, against E * pi r^2
    r = 0.3
    for emit in ("emit", "emit_toward"):
        if emit == "emit":
            o, d, Phi = ls.emit(li, n, np.zeros(n), rng)
        else:
            o, d, Phi = ls.emit_toward(li, n, np.zeros(n), rng, np.zeros(3), r)
        down = d[:, 2] < 0
        s = -o[down, 2] / d[down, 2]
        x = o[down] + s[:, None] * d[down]
        inside = np.hypot(x[:, 0], x[:, 1]) < r
        got = Phi[down][inside].sum(0)
        # Irradiance varies slowly over the disc: average it with sample_direct
        m = 20_000
        pts = np.zeros((m, 3))
        rr, th = r * np.sqrt(rng.random(m)), 2 * np.pi * rng.random(m)
        pts[:, 0], pts[:, 1] = rr * np.cos(th), rr * np.sin(th)
        wi, _, w = ls.sample_direct(li, pts, np.zeros(m), rng.random((m, 2)))
        E = np.mean(w * np.maximum(wi[:, 2], 0)[:, None], axis=0)
        assert np.allclose(got, E * np.pi * r * r, rtol=0.03), (emit, got, E * np.pi * r * r)


def test_photon_tracer_global_map_sees_mesh_light_flux():
    """build_photon_maps through the real photon tracer: the mesh light's photons leave with its flux."""
    from stpm_core.photons.trace import trace_global_map
    from stpm_core.raycast import make_caster
    scene = _quad_scene(1.0, 0.6, 0.4, Le=(1.0, 1.0, 1.0))
    ls = LightSet(scene)
    st = RenderSettings(samples=1, photons_global=20_000, photons_caustic=0, seed=2)
    recs, info = trace_global_map(scene, st, make_caster(scene), ls, MaterialTable(scene.materials),
                                  min_nondelta=0)
    assert info["photons_emitted_global"] == 20_000
    # First hits (min_nondelta=0) on the floor: the downward half of the flux, less what
    # misses the 20 x 20 floor (view factor from the quad ~ 0.995)
    down = np.asarray(recs["power"], float).sum(0)
    assert np.allclose(down, 0.5 * ls.flux(0), rtol=0.02), (down, 0.5 * ls.flux(0))


def test_emitters_add_no_light_entry_without_emission_and_scene_lights_keep_their_indices():
    from scenes import point_light
    scene = _quad_scene()
    scene.lights = [point_light((0, 0, 3), 100.0)]
    ls = LightSet(scene)
    assert [l.type for l in ls.lights] == ["POINT", "MESH"] and ls.n_scene_lights == 1
    scene.materials[1] = Material.diffuse()
    assert [l.type for l in LightSet(scene).lights] == ["POINT"]


def test_emissive_quad_and_area_light_of_equal_radiance_light_a_room_alike():
    """Independent light models agree: an emissive quad (radiance Le, both sides) and an AREA
    light of the same rectangle and power P = pi Le A (facing down) give the same floor image."""
    from stpm_core.scene import Light
    h, a, b, Le = 0.8, 0.5, 0.3, 1.5
    scene = _quad_scene(h, a, b, Le=(Le, Le, Le), res=(6, 6), ortho_scale=1.2)
    st = RenderSettings(samples=256, photons_caustic=0, photons_global=0, seed=4)
    mesh_img = render(scene, st).passes["Combined"][..., 0]
    # The same rectangle as an AREA light (local -Z faces the floor), no emissive geometry
    scene.materials[1] = Material.diffuse((0.0, 0.0, 0.0))
    scene.instances = scene.instances[:1]
    scene.lights = [Light(type="AREA", shape="RECTANGLE", size=a, size_y=b, power=np.pi * Le * a * b,
                          transform=MotionTransform.static(translate(0, 0, h)))]
    area_img = render(scene, st).passes["Combined"][..., 0]
    assert np.allclose(mesh_img, area_img, rtol=0.08), (mesh_img, area_img)    # per pixel: noise
    assert abs(mesh_img.mean() / area_img.mean() - 1) < 0.01


def test_deforming_emitter_is_sampled_where_its_vertices_are_at_each_time():
    """A quad whose vertices rise from z = 1 to z = 2 and widen 2x: light samples at time t lie on
    the quad's shape at t, and the flux follows the area (2 pi Le A(t))."""
    from stpm_core.scene import Mesh
    quad = plane_mesh(0.5, 0.5, z=1.0, material=1)
    V0 = np.asarray(quad.vertices, np.float32)
    V1 = V0 * np.array([2.0, 2.0, 1.0], np.float32) + np.array([0, 0, 1.0], np.float32)
    deforming = Mesh(vertices=np.stack([V0, V1]), triangles=quad.triangles, material_ids=quad.material_ids,
                     vertex_times=np.array([0.0, 1.0]), name="emitter")
    scene = _quad_scene()
    scene.meshes[1] = deforming
    scene.instances[1].transform = MotionTransform.static()
    ls = LightSet(scene)
    ml = ls.lights[0]
    rng = np.random.default_rng(3)
    n = 5000
    for t in (0.0, 0.5, 1.0):
        wi, dist, w = ls.sample_direct(0, np.zeros((n, 3)), np.full(n, t), rng.random((n, 2)))
        y = dist[:, None] * wi
        half = 0.25 * (1 + t)
        assert np.allclose(y[:, 2], 1.0 + t) and np.all(np.abs(y[:, :2]) <= half + 1e-9)
        assert np.allclose(ml.flux_at(t), 2 * np.pi * (2 * half) ** 2 * np.array([2.0, 1.0, 0.5]))
        assert np.allclose(ml.transform.at(t)[:3, 3], [0, 0, 1.0 + t])      # centroid, for aiming photons
