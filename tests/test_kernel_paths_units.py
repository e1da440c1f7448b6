"""The compiled tracer kernels (stpm_core.kernels.paths) against the numpy tracer they replaced.

The kernels' driver (``integrator.trace_image``) and the numpy oracle
(``oracles.integrator_numpy.trace_image_numpy``) draw the same random numbers,
so they must agree to float rounding, pass by pass: here on an ortho camera, a
box and a wide filter, two threads, a moving camera, ``time_override`` and
photon maps (tests/test_kernel_paths.py covers every light and lobe).  Also the
camera-sample kernel against the numpy camera samples, and the one clear error
when the kernels cannot run.
"""
from __future__ import annotations

import numpy as np
import pytest

from scenes import (box_mesh, look_at, make_scene, moving, ortho_camera_down, persp_camera, plane_mesh, point_light,
                    sphere_mesh, translate)
from oracles.integrator_numpy import camera_samples, trace_image_numpy
from stpm_core import kernels
from stpm_core.film import BH_INVERSE_CDF, PASSES, Film
from stpm_core.integrator import trace_image
from stpm_core.kernels import paths as K
from stpm_core.lights import LightSet
from stpm_core.motion import MotionTransform
from stpm_core.photons import build_photon_maps
from stpm_core.raycast import make_caster
from stpm_core.render import render
from stpm_core.scene import Light, Material
from stpm_core.settings import RenderSettings
from stpm_core.shutter import Shutter


def _both(scene, settings, monkeypatch=None, time_override=None):
    """(kernels, numpy oracle) passes of the same trace (the same photon maps for both)."""
    caster, lights = make_caster(scene), LightSet(scene)
    maps = None
    if settings.photons_caustic or settings.photons_global:
        maps = build_photon_maps(scene, settings, caster, lights)
    a, _ = trace_image(scene, settings, caster, lights, maps, time_override=time_override)
    b, _ = trace_image_numpy(scene, settings, caster, lights, maps, time_override=time_override)
    return a, b


def _assert_close(a, b):
    for name, _, _ in PASSES:
        x, y = a[name].astype(np.float64), b[name].astype(np.float64)
        scale = max(np.abs(y).max(), 1e-30)
        assert np.allclose(x, y, rtol=2e-5, atol=2e-6 * scale), (name, np.abs(x - y).max(), scale)


def _spot(pos, target, power):
    return Light(type="SPOT", power=power, transform=MotionTransform.static(look_at(pos, target)),
                 radius=0.0, spot_size=0.9, spot_blend=0.3)


def _area(pos, size, power):
    M = translate(*pos)
    return Light(type="AREA", power=power, transform=MotionTransform.static(M), size=size)


def _scene(materials, lights, camera=None, shutter=None, world=(0.05, 0.06, 0.07), metadata=None):
    objs = [plane_mesh(8.0),
            (sphere_mesh(0.5, 8, 16, material=1), moving((-0.6, 0, 0.5), (0.4, 0.1, 0.6))),
            (box_mesh((-0.3, -0.3, 0), (0.3, 0.3, 0.4), material=2), translate(0.9, 0.6, 0.0)),
            (box_mesh((-0.15, -0.15, 0), (0.15, 0.15, 0.1), material=3), translate(-1.0, 1.0, 1.2))]
    return make_scene(objs, materials, camera or persp_camera((0.5, -4, 2.5), (0, 0, 0.4)), lights,
                      world=world, resolution=(37, 29), shutter=shutter or Shutter(1.0, 1.5), metadata=metadata)


_SMOOTH = [Material.diffuse((0.7, 0.6, 0.5)), Material.glass(1.5),
           Material(base_color=np.array([0.3, 0.5, 0.6]), specular=0.5, roughness=0.0),
           Material.emitter((4.0, 3.0, 2.0))]
_LIGHTS = [point_light((1, -1, 3), 300.0), _spot((-1.5, -1.0, 3.0), (0, 0, 0), 500.0)]


def test_kernels_match_numpy_point_and_spot_lights(monkeypatch):
    """Point + spot lights (sampled in the kernel), a mesh light, glass chains, motion, world: same image."""
    st = RenderSettings(samples=5, photons_caustic=0, photons_global=0, seed=11, threads=1, max_depth=6)
    a, b = _both(_scene(_SMOOTH, _LIGHTS), st, monkeypatch)
    _assert_close(a, b)
    assert a["Direct"].max() > 0 and a["Emit"].max() > 0


def test_kernels_match_numpy_other_lights_rough_materials_transparent_film(monkeypatch):
    """Area / soft point / sun lights (sampled by LightSet), rough lobes (f from bsdf_eval), alpha = coverage."""
    mats = [Material(base_color=np.array([0.6, 0.6, 0.6]), specular=0.5, roughness=0.4), Material.glass(1.4),
            Material(base_color=np.array([0.8, 0.7, 0.3]), metallic=1.0, roughness=0.3),
            Material.emitter((2.0, 2.0, 2.0))]
    sun = Light(type="SUN", power=2.0, transform=MotionTransform.static(look_at((1, -2, 4), (0, 0, 0))), angle=0.1)
    lights = [_area((0.5, 0.0, 2.5), 0.8, 200.0), point_light((-1, -1, 2.5), 150.0, radius=0.2), sun]
    st = RenderSettings(samples=4, photons_caustic=0, photons_global=0, seed=5, threads=2, filter_width=2.3)
    a, b = _both(_scene(mats, lights, world=(0.0, 0.0, 0.0), metadata={"film_transparent": True}), st, monkeypatch)
    _assert_close(a, b)
    assert 0.0 < a["Combined"][..., 3].min() or a["Combined"][..., 3].max() <= 1.0


def test_kernels_match_numpy_ortho_box_filter_with_photons(monkeypatch):
    """Ortho camera, box filter, caustic and global photon maps (PhotonMaps.estimate on the same points)."""
    st = RenderSettings(samples=3, photons_caustic=4000, photons_global=4000, seed=2, threads=1, filter_width=0.0)
    sc = _scene(_SMOOTH, _LIGHTS[:1], camera=ortho_camera_down(6.0, 4.0), shutter=Shutter(1.0, 1.0))
    a, b = _both(sc, st, monkeypatch)
    _assert_close(a, b)
    assert a["Indirect"].max() > 0


@pytest.mark.parametrize("radius", [0.0, 1.5, 2.3])
def test_camera_tile_equals_camera_samples(radius):
    """camera_tile reproduces camera_samples bit for bit from the same uniforms (spp with leftovers
    too), the film positions placed by the filter's inverse CDF."""
    for spp in (1, 5, 16):
        x0, y0, tw, th = 3, 7, 6, 4
        gy, gx = np.mgrid[y0:y0 + th, x0:x0 + tw]
        px, py, xi = camera_samples(gx.ravel(), gy.ravel(), spp, Shutter(1.0, 1.5), np.random.default_rng(spp),
                                    filter_width=radius)
        rng = np.random.default_rng(spp)
        P = tw * th
        jit, perm_u, time_u = rng.random((P, spp, 2)), rng.random((P, spp)), rng.random((P, spp))
        out = [np.empty(P * spp) for _ in range(3)]
        K.camera_tile(x0, y0, tw, th, spp, jit, perm_u, time_u, True, radius, BH_INVERSE_CDF, *out)
        for x, y in zip((px, py, xi), out):
            assert np.array_equal(x, y)


def test_tile_sums_matrix_with_derived_combined_equals_add_samples():
    """Combined derived from its parts (and alpha from the sample count) sums like the full matrix."""
    rng = np.random.default_rng(4)
    W, H, spp = 19, 13, 6
    fa, fb = Film(W, H, 1.5), Film(W, H, 1.5)
    gy, gx = np.mgrid[0:H, 0:W]
    n = gx.size * spp
    V = rng.random((n, 20))
    V[:, 17:20] = 0.0                                      # Caustic all zero
    V[:, 0:3] = V[:, 8:11] + V[:, 11:14] + V[:, 14:17]      # Combined = Emit + Direct + Indirect (+ Caustic)
    V[:, 3] = 1.0
    vals, c0 = {}, 0
    for name, c, _ in PASSES:
        vals[name] = V[:, c0:c0 + c]
        c0 += c
    fa.add_samples(np.repeat(gx.ravel(), spp), np.repeat(gy.ravel(), spp), vals)
    fb.add_window(fb.tile_sums_matrix(0, 0, W, H, V, combined_is_sum=True, alpha_one=True,
                                      zero=("Caustic",), scan=False))
    A, B = fa.resolve(), fb.resolve()
    for name in A:
        assert np.allclose(A[name], B[name], rtol=2e-6, atol=1e-6), name


def test_skip_uniforms_leaves_the_stream_where_drawing_would():
    """skip_uniforms(rng, n) == rng.random(n) for every number that follows (the skipped blocks of
    instant shutters and point lights keep the rest of the image's random numbers in place)."""
    from stpm_core.sampling import rng_for, skip_uniforms
    a, b = rng_for(9, 1, 2), rng_for(9, 1, 2)
    a.random(3), b.random(3)
    a.random((700, 2))
    skip_uniforms(b, 1400)
    assert np.array_equal(a.random(11), b.random(11))


def test_kernels_match_numpy_moving_camera_and_lights_time_override():
    """A moving camera (one pose per sample) and moving point / spot lights; time_override too."""
    cam = persp_camera((0.5, -4, 2.5), (0, 0, 0.4))
    M0 = cam.transform.matrices[0]
    cam.transform = MotionTransform(np.array([0.0, 1.0]), np.stack([M0, translate(0.3, 0.2, 0.1) @ M0]))
    pl = point_light((1, -1, 3), 300.0)
    pl.transform = moving((1, -1, 3), (0.5, -0.5, 3.2))
    sp = _spot((-1.5, -1.0, 3.0), (0, 0, 0), 500.0)
    sp.transform = MotionTransform(np.array([0.0, 1.0]), np.stack([sp.transform.matrices[0],
                                                                   translate(0.4, 0, 0) @ sp.transform.matrices[0]]))
    sc = _scene(_SMOOTH, [pl, sp], camera=cam)
    st = RenderSettings(samples=3, photons_caustic=0, photons_global=0, seed=4, threads=1)
    for t in (None, 0.3):
        a, b = _both(sc, st, time_override=t)
        _assert_close(a, b)
        assert a["Direct"].max() > 0


def test_without_numba_a_render_stops_with_one_line(monkeypatch):
    """numba unavailable (as with STPM_NO_NUMBA=1): one StpmError line naming the cause, no slow path."""
    st = RenderSettings(samples=2, photons_caustic=0, photons_global=0, seed=3, threads=1)
    sc = _scene(_SMOOTH, _LIGHTS[:1])
    monkeypatch.setattr(kernels, "AVAILABLE", False)
    monkeypatch.setattr(kernels, "IMPORT_ERROR", "disabled by STPM_NO_NUMBA")
    monkeypatch.setattr(kernels, "_CHECKED", False)
    with pytest.raises(kernels.KernelsUnavailable, match="need numba.*STPM_NO_NUMBA") as err:
        render(sc, st)
    assert "\n" not in str(err.value)


def test_a_kernel_that_fails_to_compile_gives_one_line(monkeypatch):
    """A numba error inside a render (a kernel that cannot compile or load here) is reported as one
    KernelsUnavailable line naming numba's error, not a traceback."""
    from numba.core.errors import TypingError

    from stpm_core import integrator
    st = RenderSettings(samples=2, photons_caustic=0, photons_global=0, seed=3, threads=1)
    sc = _scene(_SMOOTH, _LIGHTS[:1])

    def broken(*a, **k):
        raise TypingError("No implementation of function Function(<built-in function abs>) found\nmore")

    monkeypatch.setattr(integrator._K, "classify_hits", broken)
    with pytest.raises(kernels.KernelsUnavailable, match="TypingError: No implementation") as err:
        render(sc, st)
    assert "\n" not in str(err.value) and "more" not in str(err.value)


def test_cli_without_numba_exits_with_one_error_line(tmp_path):
    """STPM_NO_NUMBA=1 (or numba missing): `stpm render` exits 1 with one `stpm: error:` line naming numba."""
    import os
    import subprocess
    import sys

    from stpm_core.scenefile import save_scene
    path = save_scene(_scene(_SMOOTH, _LIGHTS[:1]), tmp_path / "tiny.stpm")
    env = dict(os.environ, STPM_NO_NUMBA="1")
    r = subprocess.run([sys.executable, "-m", "stpm_core.cli", "render", str(path), "--output",
                        str(tmp_path / "out.exr"), "--samples", "1"], env=env, capture_output=True, text=True)
    assert r.returncode == 1, r.stderr
    lines = [ln for ln in r.stderr.splitlines() if ln.startswith("stpm: error:")]
    assert lines == ["stpm: error: the compiled kernels need numba, which is unavailable here "
                     "(disabled by STPM_NO_NUMBA)"], r.stderr
    assert "Traceback" not in r.stderr and not (tmp_path / "out.exr").exists()
