"""Fast paths of the embree caster (fused first static part, time-slice boxes of moving
instances): the same bits as the plain paths, and safe bounds."""
from __future__ import annotations

import numpy as np
import pytest

from test_raycast import fused_scene, random_rays, soup, trs

from stpm_core.motion import MotionTransform
from stpm_core.raycast import Hits
from stpm_core.raycast.build import embree_available, make_caster
from stpm_core.raycast.geometry import TMIN_REL, tmin_of
from stpm_core.scene import Instance, Material, Scene


def _fused_ok() -> bool:
    if not embree_available():
        return False
    from stpm_core.raycast.embree_backend import FUSED_AVAILABLE
    return FUSED_AVAILABLE


needs_fused = pytest.mark.skipif(not _fused_ok(), reason="embreex or numba not installed")

FIELDS = ("t", "instance", "prim", "u", "v", "position", "ng", "ns", "material")


def assert_same_hits(a: Hits, b: Hits) -> None:
    """Every field equal bit for bit (NaN positions of misses included), same dtypes."""
    for f in FIELDS:
        x, y = getattr(a, f), getattr(b, f)
        assert x.dtype == y.dtype, f
        np.testing.assert_array_equal(x, y, err_msg=f)


def assert_close_hits(a: Hits, b: Hits) -> None:
    """Fused against the numpy path (same float64 formulas, other operation order): the same
    hits, triangles and miss values, floats to rounding."""
    for f in FIELDS:
        x, y = getattr(a, f), getattr(b, f)
        assert x.dtype == y.dtype, f
        if x.dtype.kind == "f":
            np.testing.assert_allclose(x, y, rtol=1e-12, atol=1e-12, err_msg=f)   # NaN / inf where the other has
        else:
            np.testing.assert_array_equal(x, y, err_msg=f)


def static_scene(rng) -> Scene:
    """Two static soups (one smooth-free, transformed): the caster has the static part only."""
    return Scene(meshes=[soup(rng, 150), soup(rng, 60, spread=0.6)],
                 instances=[Instance(0), Instance(1, MotionTransform.static(trs((0.2, 0.1, -0.3), 0.7)))],
                 materials=[Material(), Material()])


@needs_fused
@pytest.mark.parametrize("which", ["static", "mixed"])
def test_fused_first_part_gives_the_plain_paths_bits(which):
    """Static-only (one kernel pass writes every field) and mixed scenes: the fused caster,
    with and without tmax, equals the numpy path of the embree backend (to rounding), misses
    included; occlusion exactly."""
    rng = np.random.default_rng(5)
    scene = static_scene(rng) if which == "static" else fused_scene(rng)
    fused, plain = make_caster(scene, "embree"), make_caster(scene, "embree", fused=False)
    assert (len(fused.parts) == 1) == (which == "static")
    o, d, t = random_rays(rng, 5000)
    tmax = rng.uniform(0.05, 1.5, 5000)
    for tm in (None, tmax):
        hf, hp = fused.intersect(o, d, t, tm), plain.intersect(o, d, t, tm)
        assert 500 < hf.hit.sum() < 4900                     # hits and misses both present
        assert_close_hits(hf, hp)
        miss = ~hf.hit
        assert np.all(np.isinf(hf.t[miss])) and np.all(hf.instance[miss] == -1) and np.all(hf.material[miss] == -1)
        assert np.all(np.isnan(hf.position[miss])) and np.all(hf.ng[miss] == 0)
    np.testing.assert_array_equal(fused.occluded(o, d, t, tmax), plain.occluded(o, d, t, tmax))


@needs_fused
def test_guard_rays32_is_tmin_of_then_rays32():
    """The fused guard kernel gives tmin_of's guard and rays32's float32 rays bit for bit
    (zero and NaN directions included)."""
    from stpm_core.raycast import embree_kernels as K
    rng = np.random.default_rng(2)
    n = 2000
    o = rng.normal(0, 50, (n, 3))
    d = rng.normal(0, 1, (n, 3)) * rng.uniform(1e-3, 1e3, (n, 1))
    d[:5] = 0.0
    d[5:8, 1] = np.nan
    tmax = rng.uniform(0, 100, n)
    tmax[:100] = np.inf
    scale, centre = 37.5, rng.normal(0, 10, 3)
    for tm, has in ((tmax, True), (np.zeros(1), False)):
        tmin = np.empty(n)
        o32, d32, far = np.empty((n, 3), np.float32), np.empty((n, 3), np.float32), np.empty(n, np.float32)
        K.guard_rays32(o, d, tm, has, np.array([TMIN_REL * scale]), centre, tmin, o32, d32, far)
        ref_tmin = tmin_of(d, scale)
        np.testing.assert_array_equal(tmin, ref_tmin)
        per_ray = rng.uniform(0.0, TMIN_REL * scale, n)                 # each ray its own guard
        tmin2 = np.empty(n)
        K.guard_rays32(o, d, tm, has, per_ray, centre, tmin2, np.empty_like(o32), np.empty_like(d32), np.empty_like(far))
        np.testing.assert_array_equal(tmin2, tmin_of(d, scale, per_ray))
        r_o, r_d, r_far = np.empty_like(o32), np.empty_like(d32), np.empty_like(far)
        K.rays32(o, d, ref_tmin, tmax if has else np.full(n, np.inf), centre, r_o, r_d, r_far)
        for a, b in ((o32, r_o), (d32, r_d), (far, r_far)):
            np.testing.assert_array_equal(a, b)


def moving_group_scene(rng) -> Scene:
    """A static soup and four fast moving, turning, stretching instances of one soup (a group)."""
    mesh = soup(rng, 50, spread=0.4, size=0.2)
    inst = [Instance(0)]
    for k in range(4):
        p = rng.uniform(-1.5, 1.5, 3)
        inst.append(Instance(1, MotionTransform(np.array([0.0, 0.35, 1.0]), np.stack([
            trs(p, rng.uniform(0, 6), rng.uniform(0.6, 1.4, 3)),
            trs(p + rng.normal(0, 0.8, 3), rng.uniform(0, 6), rng.uniform(0.6, 1.4, 3)),
            trs(p + rng.normal(0, 0.8, 3), rng.uniform(0, 6), rng.uniform(0.6, 1.4, 3))]))))
    return Scene(meshes=[soup(rng, 100), mesh], instances=inst, materials=[Material(), Material()])


@needs_fused
def test_time_slice_boxes_hold_the_moving_mesh():
    """Every vertex of every moving instance and every corner of its object box (the extreme
    points), at 20000 random times, lies in the slice box of its time."""
    from stpm_core.raycast.embree_backend import RigidGroup
    rng = np.random.default_rng(11)
    scene = moving_group_scene(rng)
    g = [p for p in make_caster(scene, "embree").parts if isinstance(p, RigidGroup)][0]
    s_lo, s_hi = g._slices
    L = s_lo.shape[1]
    V = np.asarray(scene.meshes[1].vertices, np.float64)
    a, b = V.min(0), V.max(0)
    V = np.concatenate([V, [[x, y, z] for x in (a[0], b[0]) for y in (a[1], b[1]) for z in (a[2], b[2])]])
    ts = np.concatenate([rng.uniform(0, 1, 20000), np.linspace(0, 1, 33), [0.35]])
    for j, i in enumerate(g.instances):
        M = scene.instances[i].transform.at(ts)
        P = np.einsum("kij,vj->kvi", M[:, :3, :3], V) + M[:, None, :3, 3]          # (times, V, 3)
        sl = np.minimum((ts * L).astype(int), L - 1)
        assert np.all(P >= s_lo[j, sl][:, None]) and np.all(P <= s_hi[j, sl][:, None])
        # ... and the slices are much tighter than the whole swept box
        assert np.mean(np.prod(s_hi[j] - s_lo[j], axis=1)) < 0.6 * np.prod(g.hi[j] - g.lo[j])


@needs_fused
def test_time_slice_boxes_change_no_hit():
    """Casting with the slice boxes and without them (whole swept boxes): the same bits, and
    agreement with the numpy oracle; rays at times outside [0, 1] use the whole boxes."""
    from stpm_core.raycast.embree_backend import RigidGroup
    rng = np.random.default_rng(12)
    scene = moving_group_scene(rng)
    sliced = make_caster(scene, "embree")
    whole = make_caster(scene, "embree")
    for g in (p for p in whole.parts if isinstance(p, RigidGroup)):
        J = g.lo.shape[0]
        g._slices = (np.empty((J, 0, 3)), np.empty((J, 0, 3)))
    o, d, t = random_rays(rng, 6000)
    t[:200] = rng.uniform(-0.3, 1.3, 200)
    hs, hw = sliced.intersect(o, d, t), whole.intersect(o, d, t)
    assert (hs.instance >= 1).sum() > 300                    # the moving instances are hit
    assert_same_hits(hs, hw)
    ref = make_caster(scene, "numpy").intersect(o, d, t)
    np.testing.assert_array_equal(hs.instance, ref.instance)
    np.testing.assert_allclose(hs.t[hs.hit], ref.t[hs.hit], rtol=1e-9)
    tmax = rng.uniform(0.1, 2.0, 6000)
    np.testing.assert_array_equal(sliced.occluded(o, d, t, tmax), whole.occluded(o, d, t, tmax))


@needs_fused
def test_group_merge_kernel_gives_cast_all_bits(monkeypatch):
    """RigidGroup.cast_into (refinement and nearest pair in group_finish) against cast_all and the
    caster's numpy merge: the same bits, for random rays and for grazing rays leaving the moving
    floor of a one-member group (refined hits inside the guard: the block's numpy re-cast)."""
    from stpm_core.raycast import embree_kernels as K
    from stpm_core.raycast.embree_backend import RigidGroup
    rng = np.random.default_rng(21)
    results = []
    finish = K.group_finish
    monkeypatch.setattr(K, "group_finish", lambda *a: results.append(finish(*a)) or results[-1])
    # Scene 1: four moving instances of one mesh (ties between pairs possible), random rays
    scene = moving_group_scene(rng)
    o, d, t = random_rays(rng, 6000)
    cases = [(scene, o, d, t)]
    # Scene 2: a moving floor (z = 0.05 t) with walls; rays leave the floor at grazing angles
    V = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0],
                  [-1.2, 1.2, -0.1], [1.2, 1.2, -0.1], [1.2, 1.2, 0.5], [-1.2, 1.2, 0.5]], np.float32)
    F = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]], np.int32)
    from stpm_core.scene import Mesh
    mesh = Mesh(vertices=V, triangles=F, material_ids=np.array([0, 0, 1, 1], np.int32))
    floor = Scene(meshes=[soup(rng, 20, spread=0.2, size=0.05), mesh],
                  instances=[Instance(0, MotionTransform.static(trs((0, 0, -3)))),
                             Instance(1, MotionTransform(np.array([0.0, 1.0]),
                                                         np.stack([trs((0, 0, 0)), trs((0, 0, 0.05))])))],
                  materials=[Material(), Material()])
    n = 3000
    tg = rng.uniform(0, 1, n)
    og = np.column_stack([rng.uniform(-0.9, 0.9, (n, 2)), 0.05 * tg])
    az, el = rng.uniform(0, 2 * np.pi, n), rng.uniform(1e-5, 5e-3, n)
    dg = np.column_stack([np.cos(az) * np.cos(el), np.sin(az) * np.cos(el), np.sin(el)])
    cases.append((floor, og, dg, tg))
    for sc, o, d, t in cases:
        merged = make_caster(sc, "embree")
        plain = make_caster(sc, "embree")
        groups = [p for p in plain.parts if isinstance(p, RigidGroup)]
        assert groups and all(g.cast_into is not None for g in groups)
        for g in groups:
            g.cast_into = None                               # the caster falls back to cast_all
        results.clear()
        hm, hp = merged.intersect(o, d, t), plain.intersect(o, d, t)
        assert_same_hits(hm, hp)
        if sc is floor:
            assert results and not all(results)              # blocks handed to the numpy re-cast
            assert hm.hit.sum() > 500 and np.all(hm.material[hm.hit] == 1)    # the wall, never the floor
        else:
            assert results and all(results)                  # the kernel merged every block
            assert (hm.instance >= 1).sum() > 300
