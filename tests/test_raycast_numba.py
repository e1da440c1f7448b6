"""The numba ray-casting backend against the exact numpy oracle, analytic answers
and its own BVH invariants; backend selection ('auto', STPM_RAYCAST_BACKEND);
a full render through numba equals the numpy backend's render."""
from __future__ import annotations

import numpy as np
import pytest

from scenes import make_scene, moving, persp_camera, plane_mesh, point_light, sphere_mesh
from stpm_core.errors import StpmError
from stpm_core.motion import MotionTransform
from stpm_core.raycast import make_caster
from stpm_core.raycast.build import BACKEND_ENV, numba_available
from stpm_core.scene import Instance, Material, Scene
from test_raycast import (assert_degenerate_triangles_are_passed_over, degenerate_triangles_scene, heightfield,
                          many_moving_instances, random_rays, random_scene, soup, trs, waving_heightfield_rays)

pytestmark = pytest.mark.skipif(not numba_available(), reason="numba not installed")


def mixed_scene(seed: int, offset=np.zeros(3)) -> Scene:
    """Static + two moving (one rotating, one stretched) + deforming (static and moving
    transforms, large deformation so swept boxes matter) instances."""
    scene = random_scene(np.random.default_rng(seed), offset=offset, deform_amp=0.2)
    times = np.linspace(0, 1, 3)
    scene.meshes.append(heightfield(12, times, lambda x, y, t: 0.4 * np.sin(3 * x + 5 * t) * y))
    o = np.asarray(offset, float)
    scene.instances.append(Instance(3, MotionTransform(np.array([0.0, 1.0]),
                                                       np.stack([trs(o + (0, 0, -1)), trs(o + (0.3, 0, -1), 0.7)]))))
    return scene


def assert_same_hits(hb, hr, d, rtol=1e-9):
    """numba hits hb equal numpy oracle hits hr: same rays hit, t to rtol, same instance and
    triangle except exact-t ties (shared edges), same shading data where the triangle is the same."""
    np.testing.assert_array_equal(hb.hit, hr.hit)
    h = hr.hit
    np.testing.assert_allclose(hb.t[h], hr.t[h], rtol=rtol)
    same = h & (hb.instance == hr.instance) & (hb.prim == hr.prim)
    tie = h & ~same
    np.testing.assert_allclose(hb.t[tie], hr.t[tie], rtol=rtol)       # a different triangle only at a tie
    assert tie.sum() <= max(2, 0.002 * h.sum())
    np.testing.assert_allclose(hb.position[h], hr.position[h], atol=1e-9 * np.abs(hr.position[h]).max())
    for f, tol in (("u", 1e-9), ("v", 1e-9), ("ng", 1e-9), ("ns", 1e-9)):
        np.testing.assert_allclose(getattr(hb, f)[same], getattr(hr, f)[same], atol=tol)
    np.testing.assert_array_equal(hb.material[same], hr.material[same])
    for x in (hb, hr):
        assert np.all(x.instance[~x.hit] == -1) and np.all(np.isinf(x.t[~x.hit]))


# ---------------------------------------------------------------- oracle agreement
def test_numba_matches_numpy_on_random_scenes():
    """Random rays over random static + moving + deforming scenes: the exact same answers."""
    for seed in (1, 2):
        scene = mixed_scene(seed)
        rng = np.random.default_rng(100 + seed)
        o, d, t = random_rays(rng, 2000)
        nb, ref = make_caster(scene, "numba"), make_caster(scene, "numpy")
        assert nb.backend == "numba"
        assert {type(p).__name__ for p in nb.parts} == {"StaticPart", "NumbaPart"}
        hb, hr = nb.intersect(o, d, t), ref.intersect(o, d, t)
        assert hr.hit.mean() > 0.4                                   # the test means something
        assert len(set(hr.instance[hr.hit])) == len(scene.instances)  # every kind of part is hit
        assert_same_hits(hb, hr, d)


def test_deforming_mesh_exact_at_each_ray_time():
    """A waving heightfield: every hit lies on the surface at the ray's own time (analytic
    z = h(x, y, t) interpolated on the triangle), and matches the oracle."""
    mesh, scene, o, d, t = waving_heightfield_rays(0.1)
    hb = make_caster(scene, "numba").intersect(o, d, t)
    assert hb.hit.all()
    # Barycentric point of the triangle at the ray time == the hit position
    from stpm_core.raycast.geometry import triangles_at
    P = triangles_at(mesh, hb.prim.astype(np.int64), t)
    x = (1 - hb.u - hb.v)[:, None] * P[:, 0] + hb.u[:, None] * P[:, 1] + hb.v[:, None] * P[:, 2]
    np.testing.assert_allclose(hb.position, x, atol=1e-12)
    assert_same_hits(hb, make_caster(scene, "numpy").intersect(o, d, t), d)


def test_many_moving_instances_agree():
    """40 moving instances of one mesh (shared BVH, culled through the caster's part BVH)."""
    rng = np.random.default_rng(17)
    scene = many_moving_instances(rng)
    o, d, t = random_rays(rng, 2000)
    nb = make_caster(scene, "numba")
    assert len({id(p.tris) for p in nb.parts}) == 1                  # one object-space BVH for the mesh
    hb, hr = nb.intersect(o, d, t), make_caster(scene, "numpy").intersect(o, d, t)
    assert hr.hit.sum() > 200
    assert_same_hits(hb, hr, d)


# ---------------------------------------------------------------- tmax, occlusion
def test_tmax_and_occluded():
    rng = np.random.default_rng(2)
    scene = mixed_scene(4)
    nb, ref = make_caster(scene, "numba"), make_caster(scene, "numpy")
    o, d, t = random_rays(rng, 1500)
    full = nb.intersect(o, d, t)
    h = full.hit
    # tmax just past / just before the nearest hit
    past = nb.intersect(o[h], d[h], t[h], full.t[h] * (1 + 1e-9))
    before = nb.intersect(o[h], d[h], t[h], full.t[h] * (1 - 1e-9))
    assert past.hit.all() and not before.hit.any()
    np.testing.assert_array_equal(past.t, full.t[h])
    assert not nb.occluded(o[h], d[h], t[h], full.t[h]).any()        # t < tmax is strict
    assert nb.occluded(o[h], d[h], t[h], full.t[h] * (1 + 1e-9)).all()
    # Random tmax: occluded == (nearest hit < tmax) == the oracle's answer
    tmax = rng.uniform(0.0, 2.0, len(o))
    blocked = nb.occluded(o, d, t, tmax)
    np.testing.assert_array_equal(blocked, full.t < tmax)
    np.testing.assert_array_equal(blocked, ref.occluded(o, d, t, tmax))
    ht = nb.intersect(o, d, t, tmax)
    np.testing.assert_array_equal(ht.hit, blocked)
    assert blocked.sum() > 100 and (~blocked).sum() > 100
    # Read-only and float32 inputs give the same answers (converted for the kernels)
    ro = [x.copy() for x in (o, d, t, tmax)]
    for x in ro:
        x.setflags(write=False)
    np.testing.assert_array_equal(nb.occluded(*ro), blocked)
    np.testing.assert_array_equal(nb.intersect(*ro).t, ht.t)
    o32, d32 = o.astype(np.float32), d.astype(np.float32)
    np.testing.assert_array_equal(nb.intersect(o32, d32, t).t, ref.intersect(o32, d32, t).t)


def test_translated_1e5_scene_gives_the_same_hits():
    """1e5 units from the origin: float64 all the way, same answers as the oracle there
    and (up to the offset's rounding) as the untranslated scene."""
    offset = np.array([1e5, -1e5, 1e5])
    rng = np.random.default_rng(11)
    o, d, t = random_rays(rng, 2000)
    scene_a, scene_b = mixed_scene(5), mixed_scene(5, offset=offset)
    ha = make_caster(scene_a, "numba").intersect(o, d, t)
    hb = make_caster(scene_b, "numba").intersect(o + offset, d, t)
    assert_same_hits(hb, make_caster(scene_b, "numpy").intersect(o + offset, d, t), d)
    assert ha.hit.sum() > 1000
    np.testing.assert_array_equal(ha.hit, hb.hit)
    np.testing.assert_allclose(ha.t[ha.hit], hb.t[ha.hit], rtol=1e-6)
    same = ha.hit & (ha.prim == hb.prim) & (ha.instance == hb.instance)
    assert same.sum() >= ha.hit.sum() - 3
    np.testing.assert_allclose(hb.position[same] - offset, ha.position[same], atol=1e-6)


def test_degenerate_triangles_do_not_crash_or_nan():
    scene = degenerate_triangles_scene()
    caster = make_caster(scene, "numba")
    rng = assert_degenerate_triangles_are_passed_over(caster, scene)
    # Axis-parallel rays (zero direction components) along and beside the degenerate ones
    d2 = np.tile([1.0, 0, 0], (500, 1))
    o2 = np.column_stack([np.full(500, -3.0), rng.uniform(-1, 1, 500), rng.choice([0.0, 0.5, 0.25], 500)])
    np.testing.assert_array_equal(caster.intersect(o2, d2, 0.5).hit,
                                  make_caster(scene, "numpy").intersect(o2, d2, 0.5).hit)


def test_warm_up_compiles_kernels_that_answer_correctly():
    """warm_up() runs the kernels on two stacked triangles; the kernels it loads then
    give the analytic hit."""
    from stpm_core.raycast.numba_backend import TriangleBVH, warm_up
    assert warm_up() >= 0
    corners = np.array([[[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 0, 1], [1, 0, 1], [0, 1, 1]]], float)[None]
    o, d = np.array([[0.2, 0.3, -1.0], [0.2, 0.3, 2.0]]), np.array([[0.0, 0.0, 2.0], [0.0, 0.0, -1.0]])
    t, prim, u, v = TriangleBVH(corners).cast(o, d, np.zeros(2), np.full(2, np.inf), np.zeros(2, np.int64),
                                               np.zeros(2))
    np.testing.assert_allclose(t, [0.5, 1.0])
    np.testing.assert_array_equal(prim, [0, 1])
    np.testing.assert_allclose(np.column_stack([u, v]), [[0.2, 0.3], [0.2, 0.3]])


# ---------------------------------------------------------------- BVH invariants
def test_bvh_invariants():
    """Every primitive in exactly one leaf; leaf boxes hold their boxes; parents hold children."""
    from stpm_core.raycast.bvh_build import LEAF_MAX, build_bvh
    rng = np.random.default_rng(9)
    c = np.vstack([rng.normal(0, 1, (3000, 3)), np.zeros((40, 3))])   # 40 identical centroids too
    lo, hi = c - rng.uniform(0, 0.1, c.shape), c + rng.uniform(0, 0.1, c.shape)
    b = build_bvh(lo, hi)
    leaf = b.child < 0
    assert np.all(b.count[leaf] <= LEAF_MAX) and np.all(b.count[leaf] >= 1)
    seen = np.concatenate([b.order[s:s + n] for s, n in zip(b.start[leaf], b.count[leaf])])
    np.testing.assert_array_equal(np.sort(seen), np.arange(len(c)))
    for k in np.flatnonzero(leaf):
        p = b.order[b.start[k]:b.start[k] + b.count[k]]
        assert np.all(lo[p] >= b.lo[k]) and np.all(hi[p] <= b.hi[k])
    inner = np.flatnonzero(~leaf)
    for kid in (b.child[inner], b.child[inner] + 1):
        assert np.all(b.lo[kid] >= b.lo[inner]) and np.all(b.hi[kid] <= b.hi[inner])
    assert b.depth < 40


# ---------------------------------------------------------------- backend selection
def test_auto_order_and_environment_override(monkeypatch):
    from stpm_core.raycast import build
    scene = Scene(meshes=[soup(np.random.default_rng(0), 5)], instances=[Instance(0)],
                  materials=[Material(), Material()])
    monkeypatch.delenv(BACKEND_ENV, raising=False)
    monkeypatch.setattr(build, "embree_available", lambda: False)
    assert make_caster(scene, "auto").backend == "numba"
    monkeypatch.setattr(build, "numba_available", lambda: False)
    assert make_caster(scene, "auto").backend == "numpy"
    with pytest.raises(StpmError):
        make_caster(scene, "numba")
    monkeypatch.undo()
    monkeypatch.setenv(BACKEND_ENV, "numba")
    assert make_caster(scene).backend == "numba"
    assert make_caster(scene, "numpy").backend == "numpy"                 # explicit choice wins
    monkeypatch.setenv(BACKEND_ENV, "optix")
    with pytest.raises(StpmError):
        make_caster(scene)


# ---------------------------------------------------------------- full render
def test_render_with_numba_equals_render_with_numpy(monkeypatch):
    """render() (which asks for 'auto') through STPM_RAYCAST_BACKEND: same image either way."""
    from stpm_core.render import render
    from stpm_core.settings import RenderSettings
    scene = make_scene([plane_mesh(10.0),
                        (sphere_mesh(0.6, 12, 24), moving((-0.4, 0, 0.6), (0.4, 0.2, 0.7))),
                        (sphere_mesh(0.4, 8, 16, material=1), MotionTransform.static(trs((0.9, -0.8, 0.4))))],
                       [Material.diffuse((0.6, 0.6, 0.6)), Material.mirror()],
                       persp_camera((0, -5, 3), (0, 0, 0.4)), [point_light((1, -1, 4), 300.0)],
                       resolution=(20, 16))
    settings = RenderSettings(samples=4, photons_global=2000, photons_caustic=1000, seed=5, filter_width=0.0)
    images, backends = {}, {}
    for backend in ("numpy", "numba"):
        monkeypatch.setenv(BACKEND_ENV, backend)
        out = render(scene, settings)
        images[backend] = out.passes
        backends[backend] = make_caster(scene).backend
    assert backends == {"numpy": "numpy", "numba": "numba"}
    a, b = images["numpy"], images["numba"]
    assert a["Direct"].max() > 0 and a["Direct"].std() > 0            # a real image
    assert a["Caustic"].max() > 0 and a["Indirect"].max() > 0        # photon paths went through the caster too
    for name in a:
        np.testing.assert_allclose(b[name], a[name], rtol=1e-5, atol=1e-6, err_msg=name)
