"""Shadow terminator: Cycles' smooth-surface offset of shadow rays and its shading offset.

The compiled kernels (``kernels.paths.smooth_surface_heights``, ``terminator_rows``,
``terminator_origin``, ``shading_offset_factor``) against the numpy oracle
``tests/oracles/terminator_numpy.py``; the lift's purpose on a sphere's triangles; the per-object
settings through the scene file; and renders: a smooth low-poly sphere under a hard point light
changes with ``shadow_terminator_geometry_offset``, a flat one does not.  The comparison with
Cycles is ``tests/test_cycles_terminator.py``; docs/rendering.md, "Shadow terminator".
"""
from __future__ import annotations

import numpy as np
import pytest

from oracles import terminator_numpy as oracle
from scenes import make_scene, persp_camera, point_light, sphere_mesh
from stpm_core.kernels import paths as K
from stpm_core.render import render
from stpm_core.scene import Material, SceneError, validate_scene
from stpm_core.scenefile import load_scene, save_scene
from stpm_core.settings import RenderSettings


def _unit(a):
    return a / np.linalg.norm(a, axis=-1, keepdims=True)


def _triangles(rng, n):
    """n triangles near the unit sphere (corners radial, jittered) with radial unit normals bent a
    little: (V (n, 3, 3), N (n, 3, 3))."""
    c = _unit(rng.normal(size=(n, 1, 3)))
    V = _unit(c + 0.35 * rng.normal(size=(n, 3, 3))) * (1.0 + 0.02 * rng.normal(size=(n, 3, 1)))
    N = _unit(V + 0.1 * rng.normal(size=(n, 3, 3)))
    return V, N


def _mesh_arrays(V, N):
    """The kernels' mesh arrays of separate triangles V, N (n, 3, 3): vertices (3n, 3) float32,
    triangles (n, 3) int32, corner normals (n, 3, 3) float32."""
    n = V.shape[0]
    return (V.reshape(-1, 3).astype(np.float32), np.arange(3 * n, dtype=np.int32).reshape(n, 3),
            N.astype(np.float32))


def _bary(rng, n):
    u, v = rng.random(n), rng.random(n)
    out = u + v > 1
    u[out], v[out] = 1 - u[out], 1 - v[out]
    return u, v


def test_smooth_surface_heights_match_numpy_oracle():
    rng = np.random.default_rng(5)
    n = 400
    V, N = _triangles(rng, n)
    N[:40] *= -1.0                                     # inward normals: the back height matters
    u, v = _bary(rng, n)
    Vs, T, Ns = _mesh_arrays(V, N)
    V, N = Vs.astype(float)[T], Ns.astype(float)          # the oracle sees the float32 values
    got = np.array([K.smooth_surface_heights(Vs, T, Ns, i, u[i], v[i])[:2] for i in range(n)])
    lift_f, nn = oracle.smooth_surface_offset(V, N, u, v, np.ones(n, bool))
    lift_b, _ = oracle.smooth_surface_offset(V, N, u, v, np.zeros(n, bool))
    np.testing.assert_allclose(got[:, 0, None] * nn, lift_f, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(got[:, 1, None] * nn, lift_b, rtol=1e-12, atol=1e-14)
    assert np.all(got[:, 0] >= 0.0) and np.all(got[:, 1] <= 0.0)
    assert np.mean(got[:, 0] > 0) > 0.5                # most points of a convex patch are lifted


def test_terminator_origin_matches_numpy_oracle():
    """Rows through ``terminator_rows`` (object space, a rotation and a uniform scale 1.7 to world)
    and ``terminator_origin`` against the oracle in world space, for light directions across the
    terminator (both sides of the face, both sides of ns, rays from either side)."""
    rng = np.random.default_rng(8)
    n = 600
    Vo, No = _triangles(rng, n)
    Vs, T, Ns = _mesh_arrays(Vo, No)
    Vo, No = Vs.astype(float)[T], Ns.astype(float)
    u, v = _bary(rng, n)
    R = np.linalg.qr(rng.normal(size=(3, 3)))[0]
    M = 1.7 * R
    t = np.array([0.3, -2.0, 1.0])
    Vw = Vo @ M.T + t
    Nw = No @ R.T
    w = np.stack([1 - u - v, u, v], 1)
    p = np.einsum("nk,nki->ni", w, Vw)
    ng = _unit(np.cross(Vw[:, 1] - Vw[:, 0], Vw[:, 2] - Vw[:, 0]))
    ns = _unit(np.einsum("nk,nki->ni", w, Nw))
    # light directions near the terminator: ns tilted by up to about +-30 degrees past 90
    tang = _unit(np.cross(ns, rng.normal(size=(n, 3))))
    ang = rng.uniform(np.radians(60), np.radians(120), n)
    wi = _unit(np.cos(ang)[:, None] * ns + np.sin(ang)[:, None] * tang)
    d = _unit(-ng + 0.5 * rng.normal(size=(n, 3)))
    d[:100] *= -1.0                                     # some rays arrive from behind the face
    for cut in (0.1, 0.35):
        TERM = np.zeros((n, 7))
        rows = np.arange(n, dtype=np.int64)
        K.terminator_rows(rows, np.arange(n, dtype=np.int32), Vs[None].copy(), T, Ns[None].copy(), np.zeros(n, np.int64),
                          np.zeros(n), M[None].copy(), u, v, cut, 1.0, TERM)
        got = np.array([K.terminator_origin(TERM, r, tuple(p[r]), tuple(ns[r]), tuple(ng[r]), tuple(d[r]),
                                            tuple(wi[r])) for r in range(n)])
        want = oracle.shadow_ray_origin(p, ns, ng, d, wi, Vw, Nw, u, v, cut)
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)
        moved = np.linalg.norm(got - p, axis=1) > 0
        assert 0.1 < moved.mean() < 0.95, moved.mean()  # the ramp: some lifted, some not


def test_lift_moves_sphere_points_toward_the_sphere():
    """On a UV sphere's triangles (corners on the sphere, radial normals) the front lift brings the
    flat triangle's points closer to the sphere they approximate: what lets shadow rays near the
    terminator clear the neighbouring triangles (Hanika 2021)."""
    m = sphere_mesh(1.0, 8, 16)
    V = np.asarray(m.vertices, float)[m.triangles]
    N = np.asarray(m.normals, float)
    rng = np.random.default_rng(2)
    u, v = _bary(rng, len(V))
    lift, _ = oracle.smooth_surface_offset(V, N, u, v, np.ones(len(V), bool))
    w = np.stack([1 - u - v, u, v], 1)
    P = np.einsum("nk,nki->ni", w, V)
    gap0 = 1.0 - np.linalg.norm(P, axis=1)
    gap1 = np.abs(1.0 - np.linalg.norm(P + lift, axis=1))
    inner = np.min(w, axis=1) > 0.05
    assert np.all(gap1[inner] < gap0[inner]), (gap0[inner].max(), gap1[inner].max())
    assert np.median(gap1[inner] / gap0[inner]) < 0.5


@pytest.mark.parametrize("s", [0.0, 0.3, 0.8])
def test_shading_offset_factor_matches_numpy_oracle(s):
    rng = np.random.default_rng(11)
    n = 300
    ns = _unit(rng.normal(size=(n, 3)))
    ng = _unit(ns + 0.2 * rng.normal(size=(n, 3)))
    d = _unit(rng.normal(size=(n, 3)))
    wi = _unit(rng.normal(size=(n, 3)))
    fm = 1.0 / (1.0 - 0.5 * s)
    got = np.array([K.shading_offset_factor(fm, tuple(ns[r]), tuple(ng[r]), tuple(d[r]), tuple(wi[r]))
                    for r in range(n)])
    np.testing.assert_allclose(got, oracle.shading_offset_factor(s, ns, ng, d, wi), rtol=1e-12, atol=1e-15)
    if s == 0.0:                                       # (next-event estimation skips it at m = 1)
        np.testing.assert_allclose(got, 1.0, rtol=1e-12)


def _sphere_scene(smooth: bool, geometry_offset: float, shading_offset: float = 0.0):
    """A 16 x 8 UV sphere (smooth or flat) lit from the side by a radius-0 point light, 48 x 48."""
    mesh = sphere_mesh(1.0, 8, 16, smooth=smooth)
    cam = persp_camera((0.0, -4.5, 0.0), (0.0, 0.0, 0.0), lens=50)
    scene = make_scene([mesh], [Material(base_color=(0.8, 0.8, 0.8), roughness=1.0, specular=0.0)], cam,
                       [point_light((-4.0, -0.5, 0.5), 800.0)], resolution=(48, 48))
    scene.instances[0].shadow_terminator_geometry_offset = geometry_offset
    scene.instances[0].shadow_terminator_shading_offset = shading_offset
    return scene


def _direct(scene):
    res = render(scene, RenderSettings(samples=4, seed=1, photons_global=0, photons_caustic=0, max_depth=1))
    return np.asarray(res.passes["Combined"][..., :3], np.float64)


def test_geometry_offset_lights_the_smooth_terminator_and_leaves_flat_meshes_alone():
    smooth_on, smooth_off = _direct(_sphere_scene(True, 0.1)), _direct(_sphere_scene(True, 0.0))
    # the offset only adds light (shadow rays that cleared the neighbouring triangles), near the
    # terminator: 13 of the 314 lit pixels brighter by more than 20 % (measured), none darker
    on, off = smooth_on.mean(axis=-1), smooth_off.mean(axis=-1)
    assert np.sum(on > 1.2 * off + 1e-3) >= 6, np.sum(on > 1.2 * off + 1e-3)
    assert np.all(on >= off - 1e-12)
    flat_on, flat_off = _direct(_sphere_scene(False, 0.1)), _direct(_sphere_scene(False, 0.0))
    np.testing.assert_array_equal(flat_on, flat_off)
    # the shading offset darkens grazing light on flat meshes too (Cycles applies it to every BSDF)
    flat_shift = _direct(_sphere_scene(False, 0.1, 0.5))
    assert flat_shift.sum() < 0.99 * flat_on.sum()


def test_settings_round_trip_through_the_scene_file_and_are_checked(tmp_path):
    scene = _sphere_scene(True, 0.25, 0.5)
    save_scene(scene, tmp_path / "s.stpm")
    back = load_scene(tmp_path / "s.stpm")
    assert back.instances[0].shadow_terminator_geometry_offset == 0.25
    assert back.instances[0].shadow_terminator_shading_offset == 0.5
    scene.instances[0].shadow_terminator_geometry_offset = -0.1
    with pytest.raises(SceneError, match="shadow_terminator_geometry_offset"):
        validate_scene(scene)


def test_band_weight_is_cycles_nee_weight_below_the_face_only():
    """``band_nee_weight``: Cycles' power-heuristic weight of next-event estimation against the diffuse
    lobe's density cos / pi, below the face only; 1 above it and for delta lights (p_l = inf)."""
    g, d = (0.0, 0.0, 1.0), (0.0, 0.0, -1.0)            # the ray arrives from above: the face looks up
    below, above = (0.6, 0.0, -0.8), (0.6, 0.0, 0.8)
    cos_s = 0.3
    p_b = cos_s / np.pi
    assert K.band_nee_weight(2.0, cos_s, g, d, above) == 1.0
    assert K.band_nee_weight(np.inf, cos_s, g, d, below) == 1.0
    assert K.band_nee_weight(p_b, cos_s, g, d, below) == pytest.approx(0.5)
    assert K.band_nee_weight(2.0, cos_s, g, d, below) == pytest.approx(4.0 / (4.0 + p_b * p_b))
    # seen from behind the face the sides swap
    assert K.band_nee_weight(p_b, cos_s, g, (0.0, 0.0, 1.0), above) == pytest.approx(0.5)
