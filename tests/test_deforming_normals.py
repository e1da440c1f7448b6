"""Shading normals of deforming meshes (issue 14 item 5): per vertex step, like positions.

Cycles' motion blur stores a deforming mesh's vertex positions *and* normals per motion step
(``ATTR_STD_MOTION_VERTEX_NORMAL``) and shades a smooth mesh smooth at every time; STPM shaded
every deforming mesh flat (``ns = ng``).  ``Mesh.normals`` may now be (K, F, 3, 3), one set of
corner normals per vertex step: a hit's shading normal is the corner normals linear in time
between the steps around the ray's time (clamped outside), then blended with the barycentrics,
mapped by the normal matrix at that time and normalised.

* :func:`test_hit_normal_is_the_time_interpolated_corner_normal` -- a waving heightfield with its
  analytic normals per step, a rotating and a static instance, every backend: the hit's ``ns``
  against that rule written out here (and it is not the face normal: the old code fails);
* :func:`test_terminator_rows_interpolate_positions_and_normals` -- the shadow terminator's
  heights (``kernels.paths.terminator_rows``) of a two-step mesh at fraction a against the numpy
  oracle fed the interpolated corners and normals, and the smooth deforming object gets its cutoff;
* validation and the scene file (version 4).
"""
from __future__ import annotations

import numpy as np
import pytest

from oracles import terminator_numpy as oracle
from stpm_core.errors import SceneError
from stpm_core.kernels import paths as K
from stpm_core.motion import MotionTransform
from stpm_core.raycast import make_caster
from stpm_core.raycast.build import numba_available
from stpm_core.scene import Instance, Material, Mesh, Scene, validate_scene
from test_raycast import heightfield, trs

TIMES = np.array([0.0, 0.3, 0.7, 1.0])


def _height(x, y, t):
    return 0.3 * np.sin(3 * x + 4 * t) * np.cos(2 * y - 3 * t)


def _normal(x, y, t):
    """Unit normal (n, 3) of z = _height(x, y, t): (-dz/dx, -dz/dy, 1) normalised."""
    hx = 0.9 * np.cos(3 * x + 4 * t) * np.cos(2 * y - 3 * t)
    hy = -0.6 * np.sin(3 * x + 4 * t) * np.sin(2 * y - 3 * t)
    n = np.stack([-hx, -hy, np.ones_like(x)], -1)
    return n / np.linalg.norm(n, axis=-1, keepdims=True)


def _wave(n: int = 12) -> Mesh:
    """The heightfield with per-step corner normals (K, F, 3, 3): the analytic normal at each
    corner's vertex at each step's time."""
    mesh = heightfield(n, TIMES, _height)
    V = np.asarray(mesh.vertices, np.float64)
    F = np.asarray(mesh.triangles)
    mesh.normals = np.stack([_normal(V[k, :, 0], V[k, :, 1], t)[F] for k, t in enumerate(TIMES)]).astype(np.float32)
    return mesh


def _expected_ns(mesh: Mesh, prim, u, v, t, M3) -> np.ndarray:
    """The rule: corner normals linear in time between the steps around t, barycentric blend,
    object -> world by the inverse transpose of M3 (n, 3, 3), normalised."""
    N = np.asarray(mesh.normals, np.float64)
    i = np.clip(np.searchsorted(TIMES, t, side="right") - 1, 0, len(TIMES) - 2)
    a = np.clip((t - TIMES[i]) / (TIMES[i + 1] - TIMES[i]), 0, 1)[:, None, None]
    C = (1 - a) * N[i, prim] + a * N[i + 1, prim]                       # (n, 3, 3) corners at t
    n_obj = (1 - u - v)[:, None] * C[:, 0] + u[:, None] * C[:, 1] + v[:, None] * C[:, 2]
    n_w = np.einsum("nji,nj->ni", np.linalg.inv(M3), n_obj)           # inverse transpose
    return n_w / np.linalg.norm(n_w, axis=1, keepdims=True)


BACKENDS = ["numpy", "embree"] + (["numba"] if numba_available() else [])


@pytest.mark.parametrize("backend", BACKENDS)
def test_hit_normal_is_the_time_interpolated_corner_normal(backend):
    mesh = _wave()
    spin = MotionTransform(np.array([0.0, 1.0]), np.stack([trs((4, 0, 0), 0.0), trs((4.5, 0, 0), 0.8, (1, 1.5, 1))]))
    scene = Scene(meshes=[mesh], instances=[Instance(0), Instance(0, spin)], materials=[Material()])
    validate_scene(scene)
    rng = np.random.default_rng(11)
    n = 1500
    xy = rng.uniform(-0.8, 0.8, (n, 2))
    t = rng.uniform(0, 1, n)
    second = np.arange(n) % 2 == 1                       # odd rays aim at the moving instance
    target = np.column_stack([xy, np.zeros(n)])
    M = np.stack([spin.at(np.array([ti]))[0] if s else np.eye(4) for ti, s in zip(t, second)])
    target = np.einsum("nij,nj->ni", M[:, :3, :3], target) + M[:, :3, 3]
    o = target + np.array([0.1, -0.2, 3.0])
    d = target - o
    hits = make_caster(scene, backend).intersect(o, d, t)
    assert hits.hit.mean() > 0.95
    h = np.flatnonzero(hits.hit)
    M3 = M[h, :3, :3]
    assert np.array_equal(hits.instance[h], second[h].astype(int))
    want = _expected_ns(mesh, hits.prim[h].astype(int), hits.u[h], hits.v[h], t[h], M3)
    np.testing.assert_allclose(hits.ns[h], want, atol=1e-5)      # float32 normals
    # ... which is not the face normal (the old code's ns = ng): the test can fail
    assert np.median(np.linalg.norm(hits.ns[h] - hits.ng[h], axis=1)) > 0.02
    # ... nor the normals of one step held over the shutter
    wrong = _expected_ns(mesh, hits.prim[h].astype(int), hits.u[h], hits.v[h], np.zeros(h.size), M3)
    assert np.median(np.linalg.norm(hits.ns[h] - wrong, axis=1)) > 0.1


def test_normals_at_matches_vertices_at_timing():
    """Mesh.normals_at is linear between steps and clamped outside, as Mesh.vertices_at."""
    mesh = _wave(4)
    N = np.asarray(mesh.normals, np.float64)
    np.testing.assert_allclose(mesh.normals_at(0.5), 0.5 * N[1] + 0.5 * N[2], atol=1e-7)
    np.testing.assert_allclose(mesh.normals_at(-1.0), N[0])
    np.testing.assert_allclose(mesh.normals_at(2.0), N[-1])
    rigid = Mesh(vertices=np.asarray(mesh.vertices)[0], triangles=mesh.triangles, material_ids=mesh.material_ids,
                 normals=N[0].astype(np.float32))
    assert rigid.normals_at(0.7) is rigid.normal_keys[0] or np.array_equal(rigid.normals_at(0.7), N[0])


def test_terminator_rows_interpolate_positions_and_normals():
    """Two steps of one triangle set (the second sheared and its normals turned); rows at fraction
    a of the step: the heights of the triangle and normals interpolated to a (numpy oracle)."""
    rng = np.random.default_rng(4)
    n = 300
    c = rng.normal(size=(n, 3))
    V0 = c[:, None, :] + 0.4 * rng.normal(size=(n, 3, 3))
    V1 = V0 + 0.2 * rng.normal(size=(n, 3, 3))
    fn = np.cross(V0[:, 1] - V0[:, 0], V0[:, 2] - V0[:, 0])
    fn /= np.linalg.norm(fn, axis=1, keepdims=True)
    N0 = fn[:, None, :] + 0.5 * rng.normal(size=(n, 3, 3))
    N1 = fn[:, None, :] + 0.5 * rng.normal(size=(n, 3, 3))
    N0 /= np.linalg.norm(N0, axis=2, keepdims=True)
    N1 /= np.linalg.norm(N1, axis=2, keepdims=True)
    Vs = np.stack([V0.reshape(-1, 3), V1.reshape(-1, 3)]).astype(np.float32)          # (2, 3n, 3)
    Ns = np.stack([N0, N1]).astype(np.float32)                                        # (2, n, 3, 3)
    T = np.arange(3 * n, dtype=np.int32).reshape(n, 3)
    u, v = rng.random(n), rng.random(n)
    out = u + v > 1
    u[out], v[out] = 1 - u[out], 1 - v[out]
    a = rng.random(n)
    TERM = np.zeros((n, 7))
    K.terminator_rows(np.arange(n, dtype=np.int64), np.arange(n, dtype=np.int32), Vs, T, Ns,
                      np.zeros(n, np.int64), a, np.eye(3)[None].copy(), u, v, 0.1, 1.0, TERM)
    Va = (1 - a)[:, None, None] * Vs[0].astype(float)[T] + a[:, None, None] * Vs[1].astype(float)[T]
    Na = (1 - a)[:, None, None] * Ns[0].astype(float) + a[:, None, None] * Ns[1].astype(float)
    lift_f, nn = oracle.smooth_surface_offset(Va, Na, u, v, np.ones(n, bool))
    lift_b, _ = oracle.smooth_surface_offset(Va, Na, u, v, np.zeros(n, bool))
    np.testing.assert_allclose(TERM[:, :3], nn, rtol=1e-12, atol=1e-13)
    np.testing.assert_allclose(TERM[:, 3, None] * nn, lift_f, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(TERM[:, 4, None] * nn, lift_b, rtol=1e-10, atol=1e-12)
    assert np.mean(TERM[:, 3] > 0) > 0.3
    # the step's own (a = 0) heights differ: the interpolation is not a no-op
    TERM0 = np.zeros((n, 7))
    K.terminator_rows(np.arange(n, dtype=np.int64), np.arange(n, dtype=np.int32), Vs, T, Ns,
                      np.zeros(n, np.int64), np.zeros(n), np.eye(3)[None].copy(), u, v, 0.1, 1.0, TERM0)
    assert np.abs(TERM0[:, 3] - TERM[:, 3]).max() > 1e-3


def test_smooth_deforming_objects_get_the_terminator_cutoff():
    from stpm_core.integrator import terminator_settings
    mesh = _wave(4)
    flat = heightfield(4, TIMES, _height)
    scene = Scene(meshes=[mesh, flat], instances=[Instance(0), Instance(1)], materials=[Material()])
    cut, _ = terminator_settings(scene)
    assert cut[0] == pytest.approx(0.1) and cut[1] == 0.0


def test_validation_of_per_step_normals():
    mesh = _wave(3)
    scene = Scene(meshes=[mesh], instances=[Instance(0)], materials=[Material()])
    validate_scene(scene)
    N = np.asarray(mesh.normals)
    mesh.normals = N[:3]                                   # 3 steps for 4 vertex steps
    with pytest.raises(SceneError, match=r"normals must have shape \(18, 3, 3\) or \(4, 18, 3, 3\)"):
        validate_scene(scene)
    mesh.normals = N[0]                                    # one set for every step: accepted
    validate_scene(scene)
    bad = N.copy()
    bad[2, 5, 1, 0] = np.nan
    mesh.normals = bad
    with pytest.raises(SceneError, match="normals"):
        validate_scene(scene)
    rigid = Mesh(vertices=np.asarray(mesh.vertices)[0], triangles=mesh.triangles, material_ids=mesh.material_ids,
                 normals=N)                                # per-step normals on a rigid mesh
    with pytest.raises(SceneError, match=r"normals must have shape \(18, 3, 3\), got \(4, 18, 3, 3\)"):
        validate_scene(Scene(meshes=[rigid], instances=[Instance(0)], materials=[Material()]))


def test_scene_file_keeps_per_step_normals(tmp_path):
    from stpm_core.scenefile import load_scene, save_scene, scene_to_arrays
    from scenes import persp_camera, point_light
    mesh = _wave(3)
    scene = Scene(meshes=[mesh], instances=[Instance(0)], materials=[Material()], camera=persp_camera((0, -3, 2), (0, 0, 0)),
                  lights=[point_light((0, 0, 3), 100.0)])
    assert scene_to_arrays(scene)[0]["version"] == 4
    path = tmp_path / "wave.stpm"
    save_scene(scene, path)
    back = load_scene(path)
    assert back.meshes[0].normals.shape == (4, 18, 3, 3)
    np.testing.assert_array_equal(back.meshes[0].normals, mesh.normals)
    mesh.normals = np.asarray(mesh.normals)[0]
    assert scene_to_arrays(scene)[0]["version"] == 2
