"""Depth of field: the thin lens of ``Camera.aperture_radius`` (docs/camera.md, "Depth of field").

* analytic: a half-plane emitter's edge rendered at depth z with the lens focused at z_f is
  blurred by a disc of radius c = A |1/z - 1/z_f| (lens / sensor) N_fit pixels (the pinhole's
  image plane, Cycles' model); the line spread function of a uniform disc of radius c has
  variance c^2 / 4 above the pinhole's (pixel filter and box of the finite difference), so c is
  measured from the rendered edge's profile; an edge on the focus plane stays as sharp as the
  pinhole's;
* the aperture map is uniform on the disc / polygon and inside it, the lens uniforms are
  stratified per pixel, rays of one film point meet on the focus plane (perspective, ortho,
  moving camera: the lens moves with it);
* the scene file keeps the lens (version 5) and refuses bad values with a clear error.

Cycles' images: tests/test_cycles_dof.py.  On main (no thin lens) every test here fails: the
Camera has no lens fields.
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from scenes import make_scene, persp_camera, plane_mesh, translate
from stpm_core.camera import generate_rays
from stpm_core.kernels import paths as K
from stpm_core.motion import MotionTransform
from stpm_core.render import render
from stpm_core.scene import Camera, Material, SceneError, validate_scene
from stpm_core.scenefile import load_scene, save_scene, scene_to_arrays
from stpm_core.settings import RenderSettings

LENS, SENSOR, W, H = 100.0, 36.0, 96, 24


def _edge_scene(z: float, A: float, zf: float):
    """An emissive half plane x > 0 at depth z before a 100 mm camera looking down -Z; black world."""
    cam = dataclasses.replace(persp_camera((0, 0, z), (0, 0, 0), lens=LENS), sensor_fit="HORIZONTAL",
                              aperture_radius=A, focus_distance=zf)
    mat = Material(base_color=np.zeros(3), emission=np.ones(3))
    return make_scene([(plane_mesh(4.0, 4.0), translate(2.0, 0, 0))], [mat], cam, resolution=(W, H))


def _lsf_variance(z: float, A: float, zf: float) -> float:
    """Variance (px^2) of the rendered edge's line spread function (the profile's finite difference)."""
    res = render(_edge_scene(z, A, zf), RenderSettings(samples=64, seed=3, photons_global=0, photons_caustic=0))
    profile = np.asarray(res.passes["Combined"])[..., :3].mean(axis=(0, 2))
    lsf = np.diff(profile)
    x = np.arange(lsf.size)
    m = (lsf * x).sum() / lsf.sum()
    return float((lsf * (x - m) ** 2).sum() / lsf.sum())


@pytest.mark.parametrize("z, zf", [(1.5, 3.0), (3.0, 1.5)])
def test_rendered_edge_blurs_by_the_thin_lens_circle_of_confusion(z, zf):
    A = LENS * 1e-3 / (2 * 1.4)                                   # f/1.4
    c_want = A * abs(1 / z - 1 / zf) * (LENS / SENSOR) * W        # 3.17 px
    var_pinhole = _lsf_variance(z, 0.0, zf)
    c = 2.0 * math.sqrt(_lsf_variance(z, A, zf) - var_pinhole)
    print(f"z {z} z_f {zf}: circle of confusion {c:.3f} px, thin lens {c_want:.3f} px")
    assert c == pytest.approx(c_want, rel=0.04)


def test_edge_on_the_focus_plane_stays_sharp():
    A = LENS * 1e-3 / (2 * 1.4)
    assert _lsf_variance(1.5, A, 1.5) == pytest.approx(_lsf_variance(1.5, 0.0, 1.5), rel=0.02, abs=0.01)


def _uv_grid(n: int = 200) -> np.ndarray:
    u = (np.arange(n) + 0.5) / n
    return np.stack(np.meshgrid(u, u), -1).reshape(-1, 2)


def test_aperture_disc_is_uniform():
    p = np.array([K.aperture_point(u, v, 0, 0.0, 1.0) for u, v in _uv_grid()])
    r2 = (p ** 2).sum(1)
    assert r2.max() <= 1.0 + 1e-12
    assert r2.mean() == pytest.approx(0.5, abs=2e-3)                     # uniform on the unit disc
    assert np.mean(r2 < 0.25) == pytest.approx(0.25, abs=5e-3)
    assert np.abs(p.mean(0)).max() < 2e-3


@pytest.mark.parametrize("n, rot, ratio", [(5, math.radians(25), 1.0), (6, 0.3, 1.0), (3, -1.0, 2.0)])
def test_aperture_polygon_is_uniform_inside_the_rotated_ngon(n, rot, ratio):
    p = np.array([K.aperture_point(u, v, n, rot, ratio) for u, v in _uv_grid()])
    p[:, 0] *= ratio                                                      # undo the anamorphic squeeze
    mids = rot + 2 * np.pi * np.arange(n) / n                             # edge midpoints' directions
    h = p @ np.stack([np.cos(mids), np.sin(mids)])                        # (N, n) distances along them
    apothem = math.cos(math.pi / n)
    assert h.max() <= apothem + 1e-9                                      # inside the polygon
    assert np.mean(h.max(1) < 0.5 * apothem) == pytest.approx(0.25, abs=5e-3)   # uniform in area
    # every edge reached: the polygon (not a disc inside it)
    assert np.all(h.max(0) > apothem - 0.02)
    assert np.abs(p.mean(0)).max() < 3e-3


def test_lens_uniforms_put_one_sample_in_each_cell_per_pixel():
    rng = np.random.default_rng(1)
    P, S = 7, 16
    uv = np.empty((P * S, 2))
    K.lens_tile(S, rng.random((P, S)), rng.random((P, S, 2)), uv)
    cells = (np.floor(uv[:, 0] * 4) + 4 * np.floor(uv[:, 1] * 4)).reshape(P, S)
    assert all(sorted(c) == list(range(16)) for c in cells)
    assert not np.all(cells == cells[0])                                  # permuted per pixel


def _lens_camera(**kw) -> Camera:
    base = dict(type="PERSP", lens=50.0, aperture_radius=0.2, focus_distance=3.0, aperture_blades=6,
                aperture_rotation=0.4, aperture_ratio=1.3, clip_start=0.1)
    base.update(kw)
    M = np.eye(4)
    M[:3, 3] = (0.3, -0.2, 5.0)
    return Camera(transform=MotionTransform.static(M), **base)


@pytest.mark.parametrize("ctype", ["PERSP", "ORTHO"])
def test_rays_of_one_film_point_meet_on_the_focus_plane(ctype):
    cam = _lens_camera(type=ctype, ortho_scale=2.0)
    n = 64
    px, py = np.full(n, 37.3), np.full(n, 11.8)
    uv = np.random.default_rng(2).random((n, 2))
    o, d = generate_rays(cam, (64, 48), px, py, np.zeros(n), lens_uv=uv)
    o0, d0 = generate_rays(cam, (64, 48), px[:1], py[:1], np.zeros(1))        # the pinhole ray
    # Focus plane z = 5 - 3 (the camera looks down -Z from z = 5)
    t = (2.0 - o[:, 2]) / d[:, 2]
    hit = o + t[:, None] * d
    t0 = (2.0 - o0[0, 2]) / d0[0, 2]
    np.testing.assert_allclose(hit, np.broadcast_to(o0[0] + t0 * d0[0], hit.shape), atol=1e-9)
    # The origins spread over the aperture: in the lens plane (ortho: the near plane), within the radius
    lens_z = 5.0 if ctype == "PERSP" else 5.0 - 0.1
    np.testing.assert_allclose(o[:, 2], lens_z, atol=1e-9)
    if ctype == "PERSP":
        r = np.hypot(o[:, 0] - 0.3, o[:, 1] + 0.2)
        assert r.max() <= 0.2 + 1e-12 and r.max() > 0.1


def test_a_moving_camera_carries_its_lens():
    M0, M1 = np.eye(4), np.eye(4)
    M1[:3, :3] = [[0, -1, 0], [1, 0, 0], [0, 0, 1]]                       # turned 90 degrees about Z
    M1[:3, 3] = (2.0, 0.0, 0.0)
    cam = _lens_camera(aperture_blades=0, aperture_ratio=1.0)
    cam = dataclasses.replace(cam, transform=MotionTransform(np.array([0.0, 1.0]), np.stack([M0, M1])))
    n = 200
    uv = np.random.default_rng(3).random((n, 2))
    times = np.where(np.arange(n) % 2 == 0, 0.0, 1.0)
    o, d = generate_rays(cam, (32, 32), np.full(n, 16.0), np.full(n, 16.0), times, lens_uv=uv)
    for t, M in ((0.0, M0), (1.0, M1)):
        sel = times == t
        local = (o[sel] - M[:3, 3]) @ M[:3, :3]                          # lens points in camera space
        np.testing.assert_allclose(local[:, 2], 0.0, atol=1e-12)
        assert np.hypot(local[:, 0], local[:, 1]).max() <= 0.2 + 1e-12
        # the same uniforms give the same camera-space lens points at both poses
    l0 = (o[times == 0.0] - M0[:3, 3]) @ M0[:3, :3]
    l1 = (o[times == 1.0] - M1[:3, 3]) @ M1[:3, :3]
    o_static = generate_rays(dataclasses.replace(cam, transform=MotionTransform.static(M0)), (32, 32),
                              np.full(n, 16.0), np.full(n, 16.0), np.zeros(n), lens_uv=uv)[0]
    np.testing.assert_allclose(l0, (o_static[times == 0.0] - M0[:3, 3]) @ M0[:3, :3], atol=1e-12)
    np.testing.assert_allclose(l1, (o_static[times == 1.0] - M0[:3, 3]) @ M0[:3, :3], atol=1e-12)


def test_scene_file_keeps_the_lens(tmp_path):
    scene = _edge_scene(2.0, 0.05, 1.5)
    scene.camera = dataclasses.replace(scene.camera, aperture_blades=7, aperture_rotation=0.25, aperture_ratio=0.8)
    assert scene_to_arrays(scene)[0]["version"] == 5
    back = load_scene(save_scene(scene, tmp_path / "lens.stpm"))
    for k in ("aperture_radius", "focus_distance", "aperture_blades", "aperture_rotation", "aperture_ratio"):
        assert getattr(back.camera, k) == getattr(scene.camera, k), k
    pinhole = _edge_scene(2.0, 0.0, 1.5)
    header = scene_to_arrays(pinhole)[0]
    assert header["version"] == 2 and "aperture_radius" not in header["camera"]


@pytest.mark.parametrize("field, value, words", [
    ("aperture_radius", -0.1, "camera.aperture_radius must be a number in [0"),
    ("aperture_radius", float("nan"), "camera.aperture_radius"),
    ("focus_distance", 0.0, "camera.focus_distance must be a positive"),
    ("aperture_blades", 2.5, "camera.aperture_blades must be an integer"),
    ("aperture_blades", -1, "camera.aperture_blades must be an integer"),
    ("aperture_ratio", 0.0, "camera.aperture_ratio must be a number in [0.001"),
    ("aperture_rotation", float("inf"), "camera.aperture_rotation must be a finite angle"),
])
def test_bad_lens_values_are_clear_errors(field, value, words):
    scene = _edge_scene(2.0, 0.05, 1.5)
    scene.camera = dataclasses.replace(scene.camera, **{field: value})
    with pytest.raises(SceneError, match=None) as e:
        validate_scene(scene)
    assert words in str(e.value), str(e.value)
