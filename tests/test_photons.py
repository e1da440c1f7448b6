"""Photon tracing end to end: traced maps against analytic answers.

Scenes (all tiny, exact):

* mirror caustic: a point light of P W at (0, 0, 1) under a 1 x 1 perfect
  mirror at z = 2 facing down; the floor z = 0 sees the light's virtual image
  at (0, 0, 3) through the mirror's aperture, so inside the caustic the
  irradiance at x is I (3 - z) / |x - L'|^3 with I = P / (4 pi);
* moving receiver: the same caustic falling on a diffuse box that slides
  through it;
* furnace: a point light at the centre of a closed diffuse sphere of albedo
  rho: every bounce keeps rho of the flux, so stored global-map power is
  P rho / (1 - rho) and, over the surface, irradiance is uniform.
"""
from __future__ import annotations

import numpy as np
import pytest

from scenes import box_mesh, make_scene, moving, ortho_camera_down, plane_mesh, point_light, sphere_mesh, translate
from stpm_core.bsdf import MaterialTable
from stpm_core.lights import LightSet
from stpm_core.photons import BYTES_PER_PHOTON, build_photon_maps
from stpm_core.photons.record import NO_NORMAL, decode_normal_codes, make_records, normal_codes, oct_decode, oct_encode
from stpm_core.photons.trace import trace_photon_paths
from stpm_core.raycast import make_caster
from stpm_core.scene import Material
from stpm_core.settings import RenderSettings
from stpm_core.shutter import Shutter

P = 100.0          # light power (W)
Z_LIGHT, Z_MIRROR = 1.0, 2.0
Z_VIRTUAL = 2 * Z_MIRROR - Z_LIGHT
I = P / (4 * np.pi)  # point-light intensity (W/sr)


def caustic_irradiance(p: np.ndarray) -> np.ndarray:
    """Analytic caustic irradiance (n,) W/m^2 of the virtual source at points p (n, 3) facing +z."""
    d = np.linalg.norm(p - np.array([0.0, 0.0, Z_VIRTUAL]), axis=1)
    return I * (Z_VIRTUAL - p[:, 2]) / d ** 3


def mirror_scene(mirror=None, box=None):
    """Floor + down-facing mirror (+ optional moving box); box shutter over one frame."""
    mats = [Material.diffuse((0.8, 0.8, 0.8)), Material.mirror()]
    objs = [plane_mesh(10.0, z=0.0, material=0, name="floor"),
            (plane_mesh(1.0, z=0.0, material=1, flip=True, name="mirror"),
             mirror if mirror is not None else translate(0, 0, Z_MIRROR))]
    if box is not None:
        objs.append(box)
    return make_scene(objs, mats, ortho_camera_down(), [point_light((0, 0, Z_LIGHT), P)],
                      shutter=Shutter(1.0, 2.0))


def trace(scene, **settings):
    st = RenderSettings(**settings)
    return build_photon_maps(scene, st, make_caster(scene), LightSet(scene))


UP = np.array([0.0, 0.0, 1.0])


# ----------------------------------------------------------------------------
# Record
# ----------------------------------------------------------------------------
def test_record_is_36_bytes_and_round_trips():
    rng = np.random.default_rng(0)
    w = rng.normal(size=(10000, 3))
    w /= np.linalg.norm(w, axis=1, keepdims=True)
    w[:6] = np.vstack([np.eye(3), -np.eye(3)])  # the axes and the folded poles
    back = oct_decode(oct_encode(w)).astype(np.float64)
    assert np.allclose(np.linalg.norm(back, axis=1), 1.0, atol=1e-6)
    back /= np.linalg.norm(back, axis=1, keepdims=True)
    angle = np.arcsin(np.minimum(np.linalg.norm(np.cross(back, w), axis=1), 1.0))
    assert BYTES_PER_PHOTON == 36
    assert angle.max() < 1e-4 and np.all(np.sum(back * w, axis=1) > 0)
    rec = make_records(rng.random((5, 3)), w[:5], rng.random((5, 3)), rng.random(5))
    assert rec.itemsize == 36 and rec.nbytes == 180
    assert (rec["ng_oct"] == NO_NORMAL).all() and (normal_codes(rec) == 0.0).all()      # no normal stored


def test_stored_normals_round_trip_on_the_side_of_wi():
    # record.ng_oct (turned to wi's side) -> normal_codes (12 bits an axis, one float32) -> decoded
    rng = np.random.default_rng(1)
    n = rng.normal(size=(10000, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    n[:6] = np.vstack([np.eye(3), -np.eye(3)])
    wi = rng.normal(size=n.shape)
    wi /= np.linalg.norm(wi, axis=1, keepdims=True)
    rec = make_records(np.zeros_like(n), wi, np.ones_like(n), np.zeros(len(n)), ng=n)
    code = normal_codes(rec)
    assert code.dtype == np.float32 and (code >= 1.0).all() and (code < 2.0 ** 24).all()
    back = decode_normal_codes(code)
    side = np.where(np.sum(n * wi, axis=1) < 0.0, -1.0, 1.0)[:, None]
    assert np.sum(back * wi, axis=1).min() >= -1e-3                           # on the side of wi
    assert np.degrees(np.arccos(np.minimum(np.sum(back * side * n, axis=1), 1.0))).max() < 0.1
    assert np.array_equal(decode_normal_codes(normal_codes(make_records(
        np.zeros((1, 3)), [[0.0, 0.0, 1.0]], np.ones((1, 3)), [0.0], ng=[[0.0, 0.0, -1.0]]))), [[0.0, 0.0, 1.0]])


# ----------------------------------------------------------------------------
# Mirror caustic: virtual source
# ----------------------------------------------------------------------------
def _caustic_points(rng, n, lo, hi):
    p = np.column_stack([rng.uniform(lo, hi, (n, 2)), np.zeros(n)])
    return p


@pytest.mark.parametrize("estimator", ["STANDARD", "TEMPORAL", "KD4D"])
def test_static_mirror_caustic_matches_virtual_source(estimator):
    scene = mirror_scene()
    maps = trace(scene, photons_caustic=150_000, photons_global=0, estimator=estimator)
    assert maps.stats["photons_caustic"] > 50_000 and maps.stats["photons_global"] == 0
    # records are stored relative to the scene's centre (float32 precision far from the origin)
    lo, hi = scene.bounds()
    np.testing.assert_allclose(maps.maps["caustic"].origin, 0.5 * (lo + hi))
    np.testing.assert_allclose(maps.maps["caustic"].position[:, 2] + maps.maps["caustic"].origin[2], 0.0, atol=1e-5)
    rng = np.random.default_rng(1)
    # 3 x 3 blocks of the caustic, 0.2 away from its edges at +-1.5
    edges = np.linspace(-1.3, 1.3, 4)
    for bx in range(3):
        for by in range(3):
            p = np.column_stack([rng.uniform(edges[bx], edges[bx + 1], 600),
                                 rng.uniform(edges[by], edges[by + 1], 600), np.zeros(600)])
            E = maps.estimate("caustic", p, np.tile(UP, (600, 1)), rng.random(600))[:, 0]
            assert abs(E.mean() / caustic_irradiance(p).mean() - 1) < 0.03, (bx, by)


@pytest.mark.parametrize("estimator", ["TEMPORAL", "KD4D"])
def test_moving_mirror_caustic_matches_virtual_source(estimator):
    # The mirror slides in its own plane: the virtual source stays put, the aperture
    # (and so the caustic) moves: at time t the caustic spans x in 3 (m(t) -+ 0.5).
    m0, m1 = -0.25, 0.25
    scene = mirror_scene(mirror=moving((m0, 0, Z_MIRROR), (m1, 0, Z_MIRROR)))
    maps = trace(scene, photons_caustic=200_000, photons_global=0, estimator=estimator)
    rng = np.random.default_rng(2)
    n = 20000
    t = rng.random(n)
    m = m0 + (m1 - m0) * t
    p = np.column_stack([rng.uniform(-2.1, 2.1, n), rng.uniform(-1.3, 1.3, n), np.zeros(n)])
    margin = 0.25
    lit = np.abs(p[:, 0] - 3 * m) < 1.5 - margin
    # Part-time lit region only (|x| > 0.75: lit for part of the shutter): STANDARD is wrong here
    part = lit & (np.abs(p[:, 0]) > 0.75 + margin)
    for sel in (lit, part):
        E = maps.estimate("caustic", p[sel], np.tile(UP, (sel.sum(), 1)), t[sel])[:, 0]
        assert abs(E.mean() / caustic_irradiance(p[sel]).mean() - 1) < 0.03
    E_std = maps.estimate("caustic", p[part], np.tile(UP, (part.sum(), 1)), t[part], estimator="STANDARD")[:, 0]
    assert E_std.mean() / caustic_irradiance(p[part]).mean() < 0.85


# ----------------------------------------------------------------------------
# Moving receiver: a box sliding through the static caustic
# ----------------------------------------------------------------------------
BOX_H, BOX_HALF = 0.3, 0.5


def _box_top_points(rng, n, margin=0.1):
    """Points on the moving box top (n, 3) at times (n,), lit at their time, away from edges."""
    out = []
    half_caustic = 0.5 * (Z_VIRTUAL - BOX_H) / (Z_VIRTUAL - Z_MIRROR)  # caustic half-width on the top plane
    while sum(len(o) for o in out) < n:
        t = rng.random(4 * n)
        xi = rng.uniform(-BOX_HALF + margin, BOX_HALF - margin, (4 * n, 2))
        x = -1.0 + 2.0 * t + xi[:, 0]
        ok = np.abs(x) < half_caustic - margin
        out.append(np.column_stack([x, xi[:, 1], np.full(4 * n, BOX_H), t])[ok])
    q = np.concatenate(out)[:n]
    return q[:, :3], q[:, 3]


def test_moving_receiver_time_dependent_estimates_are_right_standard_is_dark():
    box = (box_mesh(lo=(-BOX_HALF, -BOX_HALF, 0.0), hi=(BOX_HALF, BOX_HALF, BOX_H), material=0, name="box"),
           moving((-1.0, 0, 0), (1.0, 0, 0)))
    maps = trace(mirror_scene(box=box), photons_caustic=300_000, photons_global=0)
    rng = np.random.default_rng(3)
    p, t = _box_top_points(rng, 6000)
    ns = np.tile(UP, (len(p), 1))
    E_true = caustic_irradiance(p).mean()
    err = {}
    for name, kw in [("TEMPORAL", {}), ("KD4D", {"estimator": "KD4D"}), ("STANDARD", {"estimator": "STANDARD"}),
                     ("TEMPORAL_1.5", {"temporal_alpha": 1.5})]:
        err[name] = maps.estimate("caustic", p, ns, t, **kw)[:, 0].mean() / E_true - 1
    assert abs(err["TEMPORAL"]) < 0.05, err
    assert abs(err["KD4D"]) < 0.05, err
    assert err["STANDARD"] < -0.25, err           # present for about half the shutter: about half as bright
    assert abs(err["TEMPORAL_1.5"]) > 2 * abs(err["TEMPORAL"]) and err["TEMPORAL_1.5"] < -0.04, err


# ----------------------------------------------------------------------------
# Energy: closed diffuse sphere (furnace)
# ----------------------------------------------------------------------------
def _sphere_furnace(rho):
    mats = [Material.diffuse((rho, rho, rho))]
    mesh = sphere_mesh(1.0, n_theta=32, n_phi=64, material=0)
    return make_scene([mesh], mats, ortho_camera_down(), [point_light((0, 0, 0), P)]), mesh


def _area_uniform_points(mesh, rng, n):
    v = np.asarray(mesh.vertices, float)[np.asarray(mesh.triangles)]
    a = 0.5 * np.linalg.norm(np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]), axis=1)
    f = rng.choice(len(a), size=n, p=a / a.sum())
    u = rng.random((n, 2))
    flip = u.sum(1) > 1
    u[flip] = 1 - u[flip]
    p = v[f, 0] + u[:, :1] * (v[f, 1] - v[f, 0]) + u[:, 1:] * (v[f, 2] - v[f, 0])
    return p, a.sum()


def test_furnace_first_hits_carry_exactly_the_emitted_power():
    scene, _ = _sphere_furnace(0.5)
    lights = LightSet(scene)
    rng = np.random.default_rng(5)
    t = rng.random(20_000)
    o, d, Phi = lights.emit(0, 20_000, t, rng)
    rec = trace_photon_paths(make_caster(scene), MaterialTable(scene.materials), o, d, Phi, t, rng,
                             mode="global", max_depth=0, inst_offset=np.full(len(scene.instances), 1e-6), min_nondelta=0)
    assert len(rec) == 20_000                                   # closed: every photon lands
    assert np.allclose(rec["power"].astype(float).sum(0), P, rtol=1e-5)


@pytest.mark.parametrize("rho", [0.5])
def test_furnace_global_map_converges_to_interreflection(rho):
    scene, mesh = _sphere_furnace(rho)
    maps = trace(scene, photons_global=60_000, photons_caustic=0, max_depth=40, diffuse_bounces=1024)
    # Stored power: every bounce keeps rho -> P (rho + rho^2 + ...) = P rho / (1 - rho) (with no
    # diffuse bounce budget; Cycles' default 4 truncates the series: tests/test_bounces.py)
    Phi = maps.maps["global"].power.astype(float).sum(0)
    assert np.allclose(Phi, P * rho / (1 - rho), rtol=0.02)
    # Irradiance: uniform over the sphere; the mean over area-uniform points is flux / area
    rng = np.random.default_rng(4)
    p, area = _area_uniform_points(mesh, rng, 4000)
    ns = -p / np.linalg.norm(p, axis=1, keepdims=True)
    for est in ("STANDARD", "TEMPORAL", "KD4D"):
        E = maps.estimate("global", p, ns, rng.random(len(p)), estimator=est)[:, 0]
        assert abs(E.mean() / (P * rho / (1 - rho) / area) - 1) < 0.02, est


# ----------------------------------------------------------------------------
# Degenerate inputs
# ----------------------------------------------------------------------------
def test_empty_maps_and_dark_lights_give_zero():
    scene = mirror_scene()
    scene.lights[0].power = 0.0
    maps = trace(scene, photons_caustic=1000, photons_global=1000)
    assert not maps.has("caustic") and not maps.has("global")
    p = np.zeros((5, 3))
    for est in ("STANDARD", "TEMPORAL", "KD4D"):
        assert np.all(maps.estimate("global", p, np.tile(UP, (5, 1)), np.zeros(5), estimator=est) == 0)
    assert maps.stats["photons_caustic"] == 0 and maps.stats["bytes_per_photon"] == 36


def test_time_override_stills_reduce_to_standard():
    scene = mirror_scene(mirror=moving((-0.25, 0, Z_MIRROR), (0.25, 0, Z_MIRROR)))
    maps = trace(scene, photons_caustic=40_000, photons_global=0)
    still = build_photon_maps(scene, RenderSettings(photons_caustic=40_000, photons_global=0),
                              make_caster(scene), LightSet(scene), time_override=0.0)
    assert np.all(still.maps["caustic"].time == 0.0)
    # At t = 0 the mirror is at x = -0.25: the caustic spans x in [-2.25, 0.75]
    p = np.array([[-1.2, 0.0, 0.0], [1.4, 0.0, 0.0]])
    E = still.estimate("caustic", p, np.tile(UP, (2, 1)), np.zeros(2))[:, 0]
    assert abs(E[0] / caustic_irradiance(p[:1])[0] - 1) < 0.2 and E[1] < 0.05 * E[0]  # x = 1.4 is dark at t = 0
    assert maps.maps["caustic"].time.std() > 0.2               # whole-shutter map: times spread


def test_photon_batches_on_threads_give_the_same_records():
    """Batches are traced on worker threads and taken in batch order: the caustic and global
    records do not depend on the thread count (several batches per map)."""
    from stpm_core.photons.trace import BATCH, trace_caustic_map, trace_global_map
    scene = mirror_scene(mirror=moving((-0.25, 0, Z_MIRROR), (0.25, 0, Z_MIRROR)))
    caster, lights, table = make_caster(scene), LightSet(scene), MaterialTable(scene.materials)
    n = 2 * BATCH + 1000
    got = {}
    for threads in (1, 2):
        st = RenderSettings(photons_caustic=n, photons_global=n, threads=threads, seed=3)
        seen = []
        rc, ic = trace_caustic_map(scene, st, caster, lights, table, progress=lambda f, m: seen.append(f))
        rg, ig = trace_global_map(scene, st, caster, lights, table)
        got[threads] = (rc, rg)
        assert ic["photons_emitted_caustic"] == n and ig["photons_emitted_global"] == n
        assert seen == sorted(seen) and seen[-1] == pytest.approx(1.0) and len(seen) == 3
    for a, b in zip(got[1], got[2]):
        assert a.size > 1000 and a.tobytes() == b.tobytes()
