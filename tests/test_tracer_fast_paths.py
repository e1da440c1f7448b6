"""The tracer's fast paths agree with the general code they shortcut, and
renders stay deterministic (same seed -> bit-identical, whatever the threads)."""
from __future__ import annotations

import numpy as np
import pytest

from scenes import box_mesh, make_scene, moving, persp_camera, plane_mesh, point_light, sphere_mesh, translate
from stpm_core.film import PASSES, Film
from stpm_core.render import render
from stpm_core.scene import Material
from stpm_core.settings import RenderSettings
from stpm_core.shutter import Shutter


def test_film_tile_sums_equal_add_samples():
    """Film.tile_sums (per-pixel sums of a tile's layout, compiled) and the numpy oracle's sums give the
    same image as the general add_samples by pixel index."""
    from oracles.integrator_numpy import tile_sums_numpy
    rng = np.random.default_rng(0)
    W, H, spp = 23, 17, 5
    fa, fb, fc = Film(W, H, 1.5), Film(W, H, 1.5), Film(W, H, 1.5)
    for (x0, y0, tw, th) in [(0, 0, 8, 8), (8, 0, 15, 8), (0, 8, 23, 9)]:
        gy, gx = np.mgrid[y0:y0 + th, x0:x0 + tw]
        n = gx.size * spp
        vals = {name: rng.random((n, c)) for name, c, _ in PASSES}
        vals["Caustic"][:] = 0.0                      # an all-zero pass is skipped by tile_sums
        fa.add_samples(np.repeat(gx.ravel(), spp), np.repeat(gy.ravel(), spp), vals)
        fb.add_window(fb.tile_sums(x0, y0, tw, th, vals))
        fc.add_window(tile_sums_numpy(fc, x0, y0, tw, th, vals))
    A, B, C = fa.resolve(), fb.resolve(), fc.resolve()
    for name in A:
        assert np.allclose(A[name], B[name], rtol=2e-6, atol=1e-6), name
        assert np.allclose(C[name], B[name], rtol=2e-6, atol=1e-6), name


def test_static_camera_and_light_poses_match_the_per_time_path():
    """Broadcast poses of static cameras / lights equal the general per-time evaluation."""
    from oracles.integrator_numpy import generate_rays
    from stpm_core.lights import LightSet
    from stpm_core.motion import MotionTransform
    cam = persp_camera((1, -5, 2), (0, 0, 0.5))
    cam_moving = persp_camera((1, -5, 2), (0, 0, 0.5))
    M = cam.transform.matrices[0]
    cam_moving.transform = MotionTransform(np.array([0.0, 1.0]), np.stack([M, M]))   # not static
    rng = np.random.default_rng(2)
    px, py, t = rng.random(100) * 32, rng.random(100) * 24, rng.random(100)
    o1, d1 = generate_rays(cam, (32, 24), px, py, t)
    o2, d2 = generate_rays(cam_moving, (32, 24), px, py, t)
    assert np.allclose(o1, o2, atol=1e-12) and np.allclose(d1, d2, atol=1e-12)
    scene = make_scene([plane_mesh(4.0)], [Material.diffuse()], cam, [point_light((0, 0, 2), 100.0)])
    ls = LightSet(scene)
    p = rng.normal(size=(100, 3))
    a = ls.sample_direct(0, p, t, rng.random((100, 2)))
    scene.lights[0].transform = MotionTransform(np.array([0.0, 1.0]), np.stack([scene.lights[0].transform.matrices[0]] * 2))
    b = LightSet(scene).sample_direct(0, p, t, rng.random((100, 2)))
    for x, y in zip(a, b):
        assert np.allclose(x, y)


def test_renders_are_bit_identical_for_a_seed_whatever_the_thread_count(monkeypatch):
    from stpm_core import integrator
    monkeypatch.setattr(integrator, "BATCH_SAMPLES", 256)     # 8 x 8-pixel tiles: 30 tiles, 2 threads
    mats = [Material.diffuse((0.7, 0.7, 0.7)), Material.glass(1.5), Material.emitter((3.0, 3.0, 3.0))]
    objs = [plane_mesh(10.0), (sphere_mesh(0.5, 8, 16, material=1), moving((-0.5, 0, 0.5), (0.5, 0, 0.5))),
            (box_mesh((-0.2, -0.2, 0), (0.2, 0.2, 0.1), material=2), translate(1.0, 1.0, 1.5))]
    scene = make_scene(objs, mats, persp_camera((0, -4, 2), (0, 0, 0.5)), [point_light((1, -1, 3), 300.0)],
                       resolution=(48, 40), shutter=Shutter(1.0, 1.5))
    st = RenderSettings(samples=4, photons_caustic=0, photons_global=0, seed=7)
    a = render(scene, st.replace(threads=1)).passes
    b = render(scene, st.replace(threads=2)).passes
    c = render(scene, st.replace(threads=2)).passes
    for name in a:
        assert np.array_equal(a[name], b[name]) and np.array_equal(b[name], c[name]), name
    # The emissive box lights the floor (mesh light) and is seen by the camera
    assert a["Direct"][..., :3].max() > 0 and a["Emit"][..., :3].max() > 0
