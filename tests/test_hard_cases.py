"""Hard cases: degenerate time, extreme scales, degenerate geometry and photons, odd light and glass, bad numbers.

Every render must give finite, non-negative passes bounded by what the scene
can emit, and the right answer where one is known.  Scenes are tiny core
scenes built with tests/scenes.py.
"""
from __future__ import annotations

import numpy as np
import pytest

from scenes import (box_mesh, make_scene, moving, ortho_camera_down, persp_camera, plane_mesh, point_light,
                    sphere_mesh, translate)
from stpm_core.errors import SceneError, SettingsError, StpmError
from stpm_core.motion import MotionTransform
from stpm_core.photons.estimators import PhotonMap
from stpm_core.photons.record import make_records
from stpm_core.render import render
from stpm_core.scene import Camera, Material, Mesh, World, validate_scene
from stpm_core.settings import RenderSettings
from stpm_core.shutter import Shutter

OPEN = Shutter(0.75, 1.25)
WHITE, GLASS, EMIT = 0, 1, 2
MATS = [Material.diffuse((0.8, 0.8, 0.8), name="white"), Material.glass(1.5),
        Material.emitter((2.0, 2.0, 2.0), name="lamp")]


def _settings(**kw):
    s = dict(samples=4, photons_caustic=4000, photons_global=4000, k_nearest=16, seed=1, filter_width=0.0)
    s.update(kw)
    return RenderSettings(**s)


def check(result, bound: float = 1e3):
    """Every pass finite, colour passes non-negative and below ``bound``; returns the passes."""
    for name, a in result.passes.items():
        assert np.all(np.isfinite(a)), name
        if name not in ("Normal", "Depth"):
            assert a.min() >= 0.0, name
            assert a.max() <= bound, (name, float(a.max()))
    return result.passes


def glass_scene(sphere_tr=None, *, shutter=OPEN, res=(16, 12), mats=MATS, light_power=300.0, scale=1.0,
                offset=(0.0, 0.0, 0.0)):
    """Glass sphere over a floor and a diffuse box, ortho camera from above; scaled and offset as a whole."""
    def T(M):
        S = np.diag([scale, scale, scale, 1.0])
        return translate(*offset) @ S @ M
    sphere_tr = translate(0, 0, 1) if sphere_tr is None else sphere_tr
    sph = sphere_mesh(0.5, 10, 20, material=GLASS, name="ball")
    if isinstance(sphere_tr, MotionTransform):
        sphere_tr = MotionTransform(sphere_tr.times, np.stack([T(M) for M in sphere_tr.matrices]))
    else:
        sphere_tr = T(sphere_tr)
    cam = Camera(type="ORTHO", transform=MotionTransform.static(T(translate(0, 0, 5))), ortho_scale=4.0 * scale,
                 clip_start=0.01 * scale, clip_end=100.0 * scale)
    light = point_light(tuple(T(translate(0.3, 0.2, 3))[:3, 3]), light_power * scale * scale, radius=0.0)
    return make_scene([(plane_mesh(6.0, name="floor"), T(np.eye(4))), (sph, sphere_tr),
                       (box_mesh((0.8, 0.2, 0), (1.4, 0.8, 0.6), name="crate"), T(np.eye(4)))],
                      mats, cam, [light], shutter=shutter, resolution=res)


# ----------------------------------------------------------------------------
# Time
# ----------------------------------------------------------------------------
def _caustic_power(scene, n=60_000) -> float:
    """Total power (W, red) stored in the caustic map: the light the glass delivers to the floor."""
    from stpm_core.lights import LightSet
    from stpm_core.photons import build_photon_maps
    from stpm_core.raycast import make_caster
    maps = build_photon_maps(scene, _settings(photons_caustic=n, photons_global=0), make_caster(scene), LightSet(scene))
    return float(maps.maps["caustic"].power[:, 0].sum())


def _same_instant(a_scene, b_scene):
    """Camera-side passes equal; the caustic carries the same power (photon maps traced separately)."""
    a, b = check(render(a_scene, _settings())), check(render(b_scene, _settings()))
    for name in ("Direct", "Emit", "Depth", "Normal"):          # same camera paths, same geometry
        np.testing.assert_allclose(a[name], b[name], rtol=1e-3, atol=1e-4, err_msg=name)
    assert _caustic_power(a_scene) == pytest.approx(_caustic_power(b_scene), rel=0.02)


def test_zero_length_shutter_renders_the_frame_instant():
    """A closed shutter shows the scene at its one instant (u = 0.5): the moving sphere at its midpoint."""
    _same_instant(glass_scene(moving((-0.5, 0, 1), (0.5, 0, 1)), shutter=Shutter(1.0, 1.0)),
                  glass_scene(translate(0, 0, 1), shutter=Shutter(1.0, 1.0)))


def test_zero_length_shutter_aims_caustic_photons_at_the_instant():
    """With the shutter closed, a moving glass sphere is aimed at where it is, not at its unused path."""
    from stpm_core.bsdf import MaterialTable
    from stpm_core.photons.trace import specular_targets
    moving_scene = glass_scene(moving((-0.5, 0, 1), (0.5, 0, 1)), shutter=Shutter(1.0, 1.0))
    still_scene = glass_scene(translate(0, 0, 1), shutter=Shutter(1.0, 1.0))
    (i0, c0, r0), = specular_targets(moving_scene, MaterialTable(moving_scene.materials))
    (i1, c1, r1), = specular_targets(still_scene, MaterialTable(still_scene.materials))
    np.testing.assert_allclose(c0, c1, atol=1e-9)
    assert r0 == pytest.approx(r1)


def test_micro_shutter_equals_the_instant():
    """1e-6 frames of shutter: the sphere (1 unit per frame) travels 1e-6 units; the image is the instant's."""
    micro = glass_scene(moving((-0.5e-6, 0, 1), (0.5e-6, 0, 1)), shutter=Shutter(1.0, 1.0 + 1e-6))
    assert render(micro, _settings(samples=1, photons_caustic=0, photons_global=0)).plan["motion_blur"]
    _same_instant(micro, glass_scene(translate(0, 0, 1), shutter=Shutter(1.0, 1.0)))


def test_motion_of_100_times_the_object_size():
    """An emitting cube 0.05 wide crossing 5 units (100x its size) during the shutter.

    Each image point on its path is covered 1 % of the time; the image integral of
    Emit equals L * (top face area) exactly in expectation (radiance averaged over time).
    """
    a, D, L = 0.05, 5.0, 2.0
    cube = box_mesh((-a / 2, -a / 2, 0), (a / 2, a / 2, a), material=EMIT, name="bullet")
    cam = ortho_camera_down(3.0, ortho_scale=6.0)
    W, H = 30, 3                                   # pixels 0.2 wide, the view 6 x 0.6
    scene = make_scene([(cube, moving((-D / 2, 0, 0), (D / 2, 0, 0)))], MATS, cam, [], shutter=OPEN, resolution=(W, H))
    res = render(scene, _settings(samples=1024, photons_caustic=0, photons_global=0))
    p = check(res, bound=L * 1.0001)
    pix_area = (6.0 / W) * (6.0 / W)
    total = float(p["Emit"][..., 0].sum()) * pix_area
    assert abs(total / (L * a * a) - 1) < 0.35      # ~85 sample hits: 3 sigma
    assert float(p["Emit"][..., 0].max()) < 0.2 * L  # smeared thin: never the cube's full radiance


# ----------------------------------------------------------------------------
# Scale and position
# ----------------------------------------------------------------------------
# Enough caustic photons and camera samples that the estimate's noise sits below the tolerances:
# at 4 samples per pixel the Caustic pass's image mean moves +-35 % from seed to seed (a few pixels
# see the focus), at 64 +-6 %; rounding at 1e5 from the origin changes a few random paths, so the
# comparison must not hinge on them.
SCALE_SETTINGS = dict(photons_caustic=40_000, k_nearest=50, samples=64)
# The caustic through the glass sphere 1e5 from the origin is brighter by a measured +4 to +10 %
# (5 seeds; +0.6 % at 1e4, +1.8 % at 3e4): the secondary-ray offset OFFSET_POS x |p| (1 cm there)
# moves each refraction's continuation, and the excess follows OFFSET_POS (+16 % at 3e-7, +1.7 %
# at 3e-8; docs/raycast.md, "Known limits").  Direct and Emit stay within 0.2 %.
FAR_CAUSTIC_TOL = 0.12


@pytest.fixture(scope="module")
def reference_scale_render():
    return check(render(glass_scene(moving((-0.3, 0, 1), (0.3, 0, 1))), _settings(**SCALE_SETTINGS)))


@pytest.mark.parametrize("scale,offset", [(1e-3, (0, 0, 0)), (1e4, (0, 0, 0)),
                                          (1.0, (1e5, -1e5, 1e5))],
                         ids=["scale_1e-3", "scale_1e4", "translate_1e5"])
def test_scaled_and_translated_scene_matches(reference_scale_render, scale, offset):
    """Scaling the scene (light power by scale^2) or moving it far away changes no pixel beyond noise."""
    ref = reference_scale_render
    sc = glass_scene(moving((-0.3, 0, 1), (0.3, 0, 1)), scale=scale, offset=offset)
    out = check(render(sc, _settings(**SCALE_SETTINGS)))
    for name in ("Direct", "Caustic", "Emit"):
        diff = np.abs(out[name] - ref[name])
        level = max(ref[name].mean(), 1e-3)
        if offset == (0, 0, 0):
            # same seeds, same random paths: pixels agree up to a few flipped samples
            assert diff.mean() <= 0.02 * level, (name, float(diff.mean()), float(ref[name].mean()))
        else:
            # 1e5 from the origin, float rounding reroutes some random paths: no pass may be
            # biased (float32 world photon positions made the caustic 7 % off), pixels at noise level
            tol = FAR_CAUSTIC_TOL if name == "Caustic" else 0.02
            assert abs(out[name].mean() - ref[name].mean()) <= tol * level, (name, float(out[name].mean()),
                                                                              float(ref[name].mean()))
            assert diff.mean() <= max(0.10, tol) * level, (name, float(diff.mean()), float(ref[name].mean()))
    np.testing.assert_allclose(out["Depth"][ref["Depth"] < 1e9] / scale, ref["Depth"][ref["Depth"] < 1e9], rtol=1e-3)


# ----------------------------------------------------------------------------
# Degenerate geometry
# ----------------------------------------------------------------------------
def test_zero_area_and_sliver_triangles():
    """A floor made of good triangles plus zero-area ones (repeated, collinear) and 1e-9-wide slivers."""
    floor = plane_mesh(6.0)
    V = np.asarray(floor.vertices, np.float64)
    extra_v = np.array([[0, 0, 0.5], [1, 0, 0.5], [2, 0, 0.5],             # collinear
                        [0, 0, 0.7], [1, 1e-9, 0.7], [2, 0, 0.7]])          # sliver
    V2 = np.vstack([V, extra_v]).astype(np.float32)
    tri = np.vstack([floor.triangles, [[4, 5, 6], [4, 4, 4], [0, 0, 1], [7, 8, 9]]]).astype(np.int32)
    mesh = Mesh(vertices=V2, triangles=tri, material_ids=np.zeros(len(tri), np.int32), name="bad")
    scene = make_scene([mesh, (sphere_mesh(0.5, 8, 16, material=GLASS), translate(0, 0, 1.5))], MATS,
                       ortho_camera_down(5.0, 4.0), [point_light((0, 0, 3), 200.0)], resolution=(16, 16))
    p = check(render(scene, _settings()))
    # the floor away from the sphere's shadow gets the analytic direct light rho/pi * I cos / d^2
    Dz = p["Direct"][0, 0, 0]
    x, y = -2 + 0.125, 2 - 0.125                    # centre of the top-left pixel
    d2 = x * x + y * y + 9.0
    expect = 0.8 / np.pi * (200.0 / (4 * np.pi)) * 3.0 / d2 ** 1.5
    assert Dz == pytest.approx(expect, rel=0.02)


# ----------------------------------------------------------------------------
# Degenerate photon maps
# ----------------------------------------------------------------------------
UP = np.array([[0.0, 0.0, 1.0]])


def _map(pos, t, Phi=1.0, shutter=OPEN):
    n = len(t)
    return PhotonMap(make_records(np.asarray(pos, float), np.repeat(UP, n, 0), np.full((n, 3), Phi), np.asarray(t, float)),
                     shutter, time_scale=1.0)


@pytest.mark.parametrize("estimator", ["STANDARD", "TEMPORAL", "KD4D"])
def test_coincident_photons_give_the_known_disc_estimate(estimator):
    """N photons at one point and one time, queried at distance d: E = (k-1) Phi / (pi d^2) (STANDARD).

    At the cluster itself the estimate is a point mass; it must stay finite and non-negative.
    """
    N, Phi, d, k = 200, 0.01, 0.1, 20
    m = _map(np.zeros((N, 3)), np.full(N, 0.5), Phi)
    p = np.array([[d, 0.0, 0.0], [0.0, 0.0, 0.0]])
    E = m.estimate(p, np.repeat(UP, 2, 0), np.full(2, 0.5), estimator=estimator, k=k)
    assert np.all(np.isfinite(E)) and np.all(E >= 0)
    # all photons share one time: every estimator is STANDARD here
    assert E[0, 0] == pytest.approx((k - 1) * Phi / (np.pi * d * d), rel=1e-6)


@pytest.mark.parametrize("estimator", ["STANDARD", "TEMPORAL", "KD4D"])
def test_k_larger_than_the_photon_count_and_empty_maps(estimator):
    rng = np.random.default_rng(4)
    m = _map(rng.uniform(-1, 1, (7, 3)) * [1, 1, 0], rng.random(7))
    E = m.estimate(np.zeros((5, 3)), np.repeat(UP, 5, 0), rng.random(5), estimator=estimator, k=1000)
    assert E.shape == (5, 3) and np.all(np.isfinite(E)) and np.all(E >= 0)
    empty = _map(np.zeros((0, 3)), np.zeros(0))
    assert np.all(empty.estimate(np.zeros((3, 3)), np.repeat(UP, 3, 0), np.zeros(3), estimator=estimator, k=5) == 0)
    one = _map(np.zeros((1, 3)), np.zeros(1))
    assert np.all(one.estimate(np.zeros((3, 3)), np.repeat(UP, 3, 0), np.zeros(3), estimator=estimator, k=5) == 0)


def test_render_with_k_beyond_the_photons_and_with_no_photons():
    scene = glass_scene(moving((-0.3, 0, 1), (0.3, 0, 1)))
    check(render(scene, _settings(photons_caustic=30, photons_global=30, k_nearest=100_000)))
    res = render(scene, _settings(photons_caustic=0, photons_global=0))
    p = check(res)
    assert res.stats["photons_caustic"] == 0 and float(p["Caustic"].max()) == 0.0


# ----------------------------------------------------------------------------
# Lights and glass
# ----------------------------------------------------------------------------
def test_light_inside_a_closed_object_lights_nothing_outside():
    crate = box_mesh((-0.5, -0.5, 0.2), (0.5, 0.5, 1.2), name="crate")
    scene = make_scene([plane_mesh(6.0), crate, (sphere_mesh(0.3, 8, 16, material=GLASS), translate(1.5, 0, 0.5))],
                       MATS, persp_camera((0, -5, 3), (0, 0, 0.5)), [point_light((0, 0, 0.7), 500.0)],
                       resolution=(16, 12))
    res = render(scene, _settings())
    p = check(res)
    assert not res.plan["caustics"] and not res.plan["indirect"]
    for name in ("Direct", "Caustic", "Indirect", "Combined"):
        assert float(p[name][..., :3].max()) == 0.0, name


def test_zero_power_lights_give_black_and_trace_nothing():
    scene = glass_scene(moving((-0.3, 0, 1), (0.3, 0, 1)), light_power=0.0)
    res = render(scene, _settings())
    p = check(res)
    assert float(p["Combined"][..., :3].max()) == 0.0
    assert res.stats["photons_caustic"] == 0 and res.stats["photons_global"] == 0
    assert not any(res.plan[k] for k in ("caustics", "indirect", "time_dependent"))


def test_ior_one_glass_is_invisible():
    """An index-matched sphere bends nothing: Direct + Caustic equals the direct light without it."""
    mats = [MATS[0], Material.glass(1.0), MATS[2]]
    with_ball = render(glass_scene(mats=mats, res=(12, 12)), _settings(photons_caustic=60_000, k_nearest=30))
    without = make_scene([plane_mesh(6.0), box_mesh((0.8, 0.2, 0), (1.4, 0.8, 0.6))], mats,
                         ortho_camera_down(5.0, 4.0), [point_light((0.3, 0.2, 3), 300.0)], resolution=(12, 12))
    ref = check(render(without, _settings()))
    p = check(with_ball)
    seen = p["Direct"] + p["Caustic"]
    assert seen[..., 0].mean() == pytest.approx(ref["Direct"][..., 0].mean(), rel=0.05)
    # camera rays pass straight through (Fresnel 0): outside the sphere's shadow the floor looks the same
    far = np.abs(p["Caustic"][..., 0]) == 0
    np.testing.assert_allclose(p["Direct"][far], ref["Direct"][far], rtol=1e-4)


def test_total_internal_reflection_loops_stay_bounded():
    """A diamond-like cube (IOR 2.4) over an emitting floor: chains end at max_depth, radiance <= the emitter's."""
    mats = [MATS[0], Material.glass(2.4), Material.emitter((1.0, 1.0, 1.0))]
    cube = box_mesh((-0.5, -0.5, 0.2), (0.5, 0.5, 1.2), material=GLASS)
    floor = plane_mesh(6.0, material=EMIT)
    scene = make_scene([floor, cube], mats, persp_camera((1.5, -2, 2.5), (0, 0, 0.7)), [],
                       world=(0.5, 0.5, 0.5), resolution=(16, 12))
    for depth in (1, 8, 64):
        p = check(render(scene, _settings(max_depth=depth, photons_caustic=0, photons_global=0)), bound=1.0 + 1e-5)
        assert float(p["Combined"][..., :3].max()) > 0.4


def test_grazing_rays():
    """Camera and light skimming a large floor: finite, and never brighter than the light allows."""
    h = 1e-3
    light = point_light((0, 50, h * 10), 100.0)
    scene = make_scene([plane_mesh(1000.0)], MATS, persp_camera((0, 0, h), (0, 100, 0)), [light],
                       resolution=(16, 12))
    p = check(render(scene, _settings()))
    I = 100.0 / (4 * np.pi)
    assert float(p["Direct"].max()) <= 0.8 / np.pi * I / (10 * h) ** 2


# ----------------------------------------------------------------------------
# NaN / inf anywhere: one clear line, nothing rendered
# ----------------------------------------------------------------------------
def _corrupt(where: str, bad: float):
    """A valid glass scene with one value replaced by ``bad`` (built lazily: some constructors refuse it)."""
    sc = glass_scene(moving((-0.3, 0, 1), (0.3, 0, 1)))
    if where == "vertices":
        sc.meshes[0].vertices = sc.meshes[0].vertices.copy()
        sc.meshes[0].vertices[1, 2] = bad
    elif where == "normals":
        sc.meshes[1].normals = sc.meshes[1].normals.copy()
        sc.meshes[1].normals[3, 1, 0] = bad
    elif where == "light_power":
        sc.lights[0].power = bad
    elif where == "light_color":
        sc.lights[0].color = np.array([1.0, bad, 1.0])
    elif where == "light_radius":
        sc.lights[0].radius = bad
    elif where == "base_color":
        sc.materials = [Material.diffuse((0.8, bad, 0.8))] + sc.materials[1:]
    elif where == "emission":
        sc.materials = sc.materials[:2] + [Material.emitter((bad, 1.0, 1.0))]
    elif where == "ior":
        sc.materials = [sc.materials[0], Material.glass(bad), sc.materials[2]]
    elif where == "roughness":
        sc.materials = [Material(roughness=bad)] + sc.materials[1:]
    elif where == "camera_lens":
        sc.camera.lens = bad
    elif where == "camera_ortho_scale":
        sc.camera.ortho_scale = bad
    elif where == "world":
        sc.world = World(color=np.array([bad, 0, 0]))
    elif where == "world_strength":
        sc.world = World(strength=bad)
    elif where == "transform":
        M = np.eye(4)
        M[0, 3] = bad
        sc.instances[0].transform = MotionTransform.static(M)
    elif where == "vertex_times":
        m = sc.meshes[0]
        v = np.asarray(m.vertices)
        m.vertices, m.vertex_times = np.stack([v, v]), np.array([0.0, bad])
    elif where == "shutter":
        sc.shutter = Shutter(1.0, bad)
    elif where == "shutter_curve":
        sc.shutter = Shutter(1.0, 1.5, curve=np.array([1.0, bad, 1.0]))
    return sc


CORRUPTIONS = ["vertices", "normals", "light_power", "light_color", "light_radius", "base_color", "emission", "ior",
               "roughness", "camera_lens", "camera_ortho_scale", "world", "world_strength", "transform",
               "vertex_times", "shutter", "shutter_curve"]


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf], ids=["nan", "inf", "-inf"])
@pytest.mark.parametrize("where", CORRUPTIONS)
def test_nan_or_inf_anywhere_is_one_clear_line(where, bad):
    calls = []
    with pytest.raises(SceneError) as info:
        scene = _corrupt(where, bad)
        validate_scene(scene)                    # the loader and the add-on's export call this
        render(scene, _settings(), progress=lambda f, m: calls.append(f))
    msg = str(info.value)
    assert "\n" not in msg and 0 < len(msg) < 200
    assert calls == []                           # nothing rendered from garbage


@pytest.mark.parametrize("field", ["temporal_alpha", "time_scale", "filter_width"])
@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_nan_or_inf_settings_are_one_clear_line(field, bad):
    with pytest.raises(SettingsError) as info:
        _settings(**{field: bad})
    assert field in str(info.value) and "\n" not in str(info.value)


def test_nan_in_a_scene_file_is_refused(tmp_path):
    """A .stpm file whose arrays hold NaN loads as SceneError (never a half-valid scene)."""
    from stpm_core.scenefile import load_scene, save_scene, scene_to_arrays  # noqa: F401
    import zipfile
    sc = glass_scene()
    path = tmp_path / "s.stpm"
    save_scene(sc, path)
    with zipfile.ZipFile(path) as z:
        names = z.namelist()
        data = {n: z.read(n) for n in names}
    target = next(n for n in names if n.endswith(".npy") and "vert" in n)
    import io
    arr = np.load(io.BytesIO(data[target]))
    arr = arr.astype(arr.dtype)
    arr.reshape(-1)[0] = np.nan
    buf = io.BytesIO()
    np.save(buf, arr)
    data[target] = buf.getvalue()
    bad = tmp_path / "bad.stpm"
    with zipfile.ZipFile(bad, "w") as z:
        for n in names:
            z.writestr(n, data[n])
    with pytest.raises(StpmError) as info:
        load_scene(bad)
    assert "NaN" in str(info.value) or "nan" in str(info.value).lower()
