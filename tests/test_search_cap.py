"""Bounded k-nearest searches (``estimators.SEARCH_CAP``, ``kdtree._lookup``'s cap2).

A capped search never looks beyond r_max: where the kq-th neighbour lies within r_max the look-up
is the unbounded one; elsewhere it sums every photon strictly within r_max over the r_max region
(TEMPORAL: no time selection, the window is the whole slice).  Checked here against a brute-force
numpy oracle (every photon sorted by the kernels' float64 squared distance), through
``PhotonMap.estimate`` against sum / (pi min(r_k, r_max)^2), the cap switched off (bit for bit the
unbounded search), and on a rendered caustic against the unbounded render (block Z-test).
"""
from __future__ import annotations

import numpy as np
import pytest

from stpm_core.photons import estimators
from stpm_core.photons.estimators import PhotonMap
from stpm_core.photons.record import make_records
from stpm_core.shutter import Shutter
from test_kdtree_oracle import S, assert_sums, d2_all, photon_arrays, query_arrays, side_sum

kdtree = pytest.importorskip("stpm_core.photons.kdtree")
if not kdtree.AVAILABLE:
    pytest.skip("numba look-ups unavailable", allow_module_level=True)


def oracle_capped(pos, t, packed, q, ns, mode, kq, k, cone, cone_k, s, cap, ng=None, plane=np.inf):
    """(phi (n, 3), r (n,), tau (n,)) of the capped look-up, by sorting every photon per query; ng (n, 3)
    and plane: only photons with |(x_p - x_q) . ng| <= plane rho count (the tangent slab, rho the
    radius r, KD4D's spatial section sqrt(r^2 - (s dt)^2) at the photon's time)."""
    D = 4 if mode == kdtree.MODE_KD4D else 3
    n = len(q)
    phi, r, tau = np.zeros((n, 3)), np.zeros(n), np.full(n, np.inf)
    for i in range(n):
        d2 = d2_all(pos, t, q[i], D, s)
        order = np.argsort(d2, kind="stable")
        if d2[order[kq - 1]] < cap * cap:                    # the kq-th strictly within r_max: unbounded
            r[i] = np.sqrt(d2[order[kq - 1]])
            inner = order[:kq - 1]
            if mode == kdtree.MODE_TEMPORAL:
                dt = np.abs(t[inner].astype(np.float64) - q[i, 3])
                o = np.argsort(dt, kind="stable")
                tau[i] = dt[o[k - 1]]
                inner = inner[o[:k - 1]]
        else:                                                # capped: all photons strictly within r_max
            r[i] = cap
            inner = np.nonzero(d2 < cap * cap)[0]
        if ng is not None:
            h = (pos[inner].astype(np.float64) - q[i, :3]) @ ng[i].astype(np.float64)
            rho2 = np.full(len(inner), r[i] * r[i] if np.isfinite(cap) and r[i] == cap else 0.0)
            if not (np.isfinite(cap) and r[i] == cap):
                rho2[:] = d2[order[kq - 1]]
            if mode == kdtree.MODE_KD4D:
                rho2 = np.maximum(rho2 - (s * t[inner].astype(np.float64) - q[i, 3]) ** 2, 0.0)
            inner = inner[h * h <= plane * plane * rho2]
        w = 1.0 - np.sqrt(d2[inner]) / (cone_k * max(r[i], 1e-300)) if cone else np.ones(len(inner))
        phi[i] = side_sum(packed, inner, ns[i], w)
    return phi, r, tau


@pytest.mark.parametrize("seed,dup", [(1, 1), (2, 3)])
def test_capped_lookups_equal_brute_force(seed, dup):
    rng = np.random.default_rng(seed)
    N = 3000
    pos, t, packed = photon_arrays(rng, N, dup=dup)
    q, ns = query_arrays(rng, 200, pos)
    trees = {3: kdtree.FlatTree(pos, t, packed, dims=3, s=S), 4: kdtree.FlatTree(pos, t, packed, dims=4, s=S)}
    for mode, kq, k in ((kdtree.MODE_STANDARD, 50, 50), (kdtree.MODE_TEMPORAL, 75, 50), (kdtree.MODE_KD4D, 50, 50)):
        qq = q.copy()
        if mode == kdtree.MODE_KD4D:
            qq[:, 3] *= S
        tree = trees[4 if mode == kdtree.MODE_KD4D else 3]
        r_unb = tree.lookup(mode, qq, ns, kq, k, False, 1.1, 1)[1]
        for cap in np.percentile(r_unb, [5, 50, 95]):       # mostly capped .. mostly not
            for cone in (False, True):
                phi, r, tau = tree.lookup(mode, qq, ns, kq, k, cone, 1.1, 1, cap=float(cap))
                phi_o, r_o, tau_o = oracle_capped(pos, t, packed, qq, ns, mode, kq, k, cone, 1.1, S, float(cap))
                assert np.array_equal(r, r_o), (mode, cap, cone)
                if mode == kdtree.MODE_TEMPORAL:
                    assert np.array_equal(tau, tau_o), (mode, cap, cone)
                assert_sums(phi, phi_o)
                capped = r >= cap
                assert 0 < capped.sum() < len(r) or cap != np.percentile(r_unb, 50)


def test_capped_lookups_in_the_tangent_slab_equal_brute_force():
    # the two per-query rules together: a capped query's slab reaches a fraction of r_max, not of a
    # k-th neighbour it never found (docs/photon-mapping.md, "Bounded searches", "Tangent slab")
    rng = np.random.default_rng(7)
    pos, t, packed = photon_arrays(rng, 3000)
    q, ns = query_arrays(rng, 200, pos)
    ng = rng.normal(size=(len(q), 3))
    ng = (ng / np.linalg.norm(ng, axis=1, keepdims=True)).astype(np.float32)
    trees = {3: kdtree.FlatTree(pos, t, packed, dims=3, s=S), 4: kdtree.FlatTree(pos, t, packed, dims=4, s=S)}
    for mode, kq, k in ((kdtree.MODE_STANDARD, 50, 50), (kdtree.MODE_TEMPORAL, 75, 50), (kdtree.MODE_KD4D, 50, 50)):
        qq = q.copy()
        if mode == kdtree.MODE_KD4D:
            qq[:, 3] *= S
        tree = trees[4 if mode == kdtree.MODE_KD4D else 3]
        cap = float(np.median(tree.lookup(mode, qq, ns, kq, k, False, 1.1, 1)[1]))
        phi, r, _ = tree.lookup(mode, qq, ns, kq, k, False, 1.1, 1, cap=cap, ng=ng, plane=0.3)
        phi_o, r_o, _ = oracle_capped(pos, t, packed, qq, ns, mode, kq, k, False, 1.1, S, cap, ng=ng, plane=0.3)
        assert np.array_equal(r, r_o), mode
        assert_sums(phi, phi_o)
        # the slab drops photons in capped and uncapped queries alike
        phi_all = tree.lookup(mode, qq, ns, kq, k, False, 1.1, 1, cap=cap)[0]
        for sel in (r >= cap, r < cap):
            assert phi[sel].sum() < 0.8 * phi_all[sel].sum(), (mode, sel.sum())


def test_capped_lookups_split_over_threads_equal_one_thread():
    # a capped query leaves no warm start for the next: each range starts its own, same answers
    rng = np.random.default_rng(5)
    pos, t, packed = photon_arrays(rng, 20_000)
    q, ns = query_arrays(rng, 9000, pos)
    tree = kdtree.FlatTree(pos, t, packed, dims=3, s=S)
    cap = float(np.median(tree.lookup(kdtree.MODE_TEMPORAL, q, ns, 75, 50, False, 1.1, 1)[1]))
    one = tree.lookup(kdtree.MODE_TEMPORAL, q, ns, 75, 50, True, 1.1, 1, cap=cap)
    two = tree.lookup(kdtree.MODE_TEMPORAL, q, ns, 75, 50, True, 1.1, 2, cap=cap)
    assert np.array_equal(one[1], two[1]) and np.array_equal(one[2], two[2])
    assert_sums(one[0], two[0])


def _plane_map(rng, N, *, bounded, spot=True):
    """A map on the floor z = 0: uniform photons over 4 x 4 m plus (spot) a dense caustic spot of
    radius 0.1 m at the origin holding 95 % of them; all from above, equal power, times uniform."""
    n_spot = int(0.95 * N) if spot else 0
    u = rng.random(n_spot)
    a = rng.uniform(0, 2 * np.pi, n_spot)
    xy = np.concatenate([0.1 * np.sqrt(u)[:, None] * np.stack([np.cos(a), np.sin(a)], -1),
                         rng.uniform(-2, 2, (N - n_spot, 2))])
    pos = np.zeros((N, 3))
    pos[:, :2] = xy
    rec = make_records(pos, np.tile([0.0, 0.0, 1.0], (N, 1)), np.full((N, 3), 1e-4), rng.random(N))
    return PhotonMap(rec, Shutter(1.0, 2.0), time_scale=1.0, bounded=bounded)


def test_bounded_estimate_is_the_sum_within_min_rk_rmax_over_its_area():
    # PhotonMap.estimate (STANDARD): E = sum of the k - 1 inner photons / (pi r_k^2) where r_k < r_max,
    # else every photon within r_max / (pi r_max^2); r_max from the map's own photons
    rng = np.random.default_rng(7)
    m = _plane_map(rng, 20_000, bounded=True)
    pos = m.position                                         # (the records' float32 positions)
    k = 50
    p = np.zeros((400, 3))
    u, a = rng.random(200), rng.uniform(0, 2 * np.pi, 200)
    spot = 0.08 * np.sqrt(u)[:, None] * np.stack([np.cos(a), np.sin(a)], -1)      # inside the spot
    p[:, :2] = np.concatenate([spot, rng.uniform(-2, 2, (200, 2))])
    up = np.tile([0.0, 0.0, 1.0], (400, 1))
    E = m.estimate(p, up, np.full(400, 0.5), estimator="STANDARD", k=k)
    cap = m.search_cap(m.flat_tree(3), k)
    assert np.isfinite(cap)
    expect = np.zeros(400)
    phi = float(m.power[0, 0])                               # (1e-4 rounded to float32)
    d2 = ((pos[None, :, :] - p[:, None, :]) ** 2).sum(-1)
    for i in range(400):
        d = np.sort(d2[i])
        if d[k - 1] < cap * cap:
            expect[i] = (k - 1) * phi / (np.pi * d[k - 1])
        else:
            expect[i] = np.count_nonzero(d2[i] < cap * cap) * phi / (np.pi * cap * cap)
    np.testing.assert_allclose(E[:, 0], expect, rtol=1e-9)
    # the cap is where the map is thin: the spot's queries are never capped, most of the floor's are
    n_cap = m.stats["capped_count"]
    assert 150 < n_cap <= 200, n_cap
    # its value: SEARCH_CAP_FACTOR x a percentile of the photons' own k-th radii (95 % of them in the spot)
    r_spot = 0.1 * np.sqrt(k / (0.95 * 20_000))
    assert 0.5 * estimators.SEARCH_CAP_FACTOR * r_spot < cap < 2.0 * estimators.SEARCH_CAP_FACTOR * r_spot


@pytest.mark.parametrize("estimator", ["STANDARD", "TEMPORAL", "KD4D"])
def test_caps_are_found_at_map_build_not_in_the_first_look_up(monkeypatch, estimator):
    # PhotonMap.build finds every search cap its look-ups will use (each TEMPORAL time slice's too):
    # map building, not look-up time.  Then no look-up searches for one, and the estimates are
    # those of a map whose caps were found lazily, bit for bit
    rng = np.random.default_rng(12)
    built = _plane_map(np.random.default_rng(4), 30_000, bounded=True)
    lazy = PhotonMap(built.records, Shutter(1.0, 2.0), time_scale=1.0, bounded=True)
    built.build(estimator, k=50)
    caps = dict(built._caps)
    n_trees = estimators.temporal_slices(built.n, 50) if estimator == "TEMPORAL" else 1
    assert len(caps) == n_trees and (n_trees >= 2 or estimator != "TEMPORAL")
    p = np.zeros((300, 3))
    p[:, :2] = rng.uniform(-2, 2, (300, 2))
    up = np.tile([0.0, 0.0, 1.0], (300, 1))
    t = rng.random(300)
    searched = []
    knn_radius = kdtree.FlatTree.knn_radius
    monkeypatch.setattr(kdtree.FlatTree, "knn_radius", lambda *a, **kw: searched.append(1) or knn_radius(*a, **kw))
    E = built.estimate(p, up, t, estimator=estimator, k=50)
    assert not searched and built._caps == caps
    E_lazy = lazy.estimate(p, up, t, estimator=estimator, k=50)
    assert len(searched) == n_trees                          # (the lazy map searched for its caps)
    assert sorted(lazy._caps.values()) == sorted(caps.values())
    assert np.array_equal(E, E_lazy)
    assert built.stats["capped_count"] == lazy.stats["capped_count"] > 0


@pytest.mark.parametrize("estimator", ["STANDARD", "TEMPORAL", "KD4D"])
def test_cap_off_is_the_unbounded_search_bit_for_bit(monkeypatch, estimator):
    rng = np.random.default_rng(11)
    rec_rng = np.random.default_rng(3)
    bounded = _plane_map(rec_rng, 30_000, bounded=True)
    plain = PhotonMap(bounded.records, Shutter(1.0, 2.0), time_scale=1.0, bounded=False)
    p = np.zeros((3000, 3))
    p[:, :2] = rng.uniform(-2, 2, (3000, 2))
    up = np.tile([0.0, 0.0, 1.0], (3000, 1))
    t = rng.random(3000)
    ref = plain.estimate(p, up, t, estimator=estimator, k=50, support=True)
    monkeypatch.setattr(estimators, "SEARCH_CAP", False)
    off = bounded.estimate(p, up, t, estimator=estimator, k=50, support=True)
    for a, b in zip(ref, off):
        assert np.array_equal(a, b)
    assert bounded.stats["capped_count"] == 0
    # and on: the same map's floor queries are capped, so the test above can see a difference
    monkeypatch.setattr(estimators, "SEARCH_CAP", True)
    on = bounded.estimate(p, up, t, estimator=estimator, k=50, support=True)
    assert bounded.stats["capped_count"] > 1000
    assert not np.array_equal(ref[1], on[1])


def test_a_bounded_caustic_render_keeps_the_caustic_and_drops_the_far_tail(monkeypatch):
    """The mirror caustic of ``test_compare.moving_caustic_scene`` (a point light's image through a
    0.6 m mirror: exactly the 1.8 m square |x|, |y| < 0.9 on the floor; a box sliding through it)
    seen from farther up, 6 x 4 m of floor, so most caustic look-ups find their neighbours a metre
    away.  TEMPORAL, 4 seeds of photons and camera, Caustic pass, cap on against off:

    * inside the square (|x|, |y| < 0.7 m) the same within noise: mean within 1 %, no 2 x 2 pixel
      block off by more than z = 4 (36 blocks, unpaired);
    * beyond it (|x| or |y| > 1.2 m), where the exact caustic is 0, the unbounded k-nearest estimate
      reads a tail of about (k - 1) Phi / (pi d^2) at a distance d from the caustic; the bounded one
      keeps less than half of it;
    * the cap bounds searches here (capped queries in the render stats).
    Measured: docs/photon-mapping.md, "Bounded searches".
    """
    from scenes import ortho_camera_down
    from stpm_core.render import render
    from stpm_core.settings import RenderSettings
    from test_compare import moving_caustic_scene
    W, H = 48, 32
    scene = moving_caustic_scene((W, H), mirror=(0.0, 0.0))
    scene.camera = ortho_camera_down(height=1.8, ortho_scale=6.0)
    base = dict(method="PHOTON", estimator="TEMPORAL", samples=16, photons_caustic=20_000, photons_global=0,
                k_nearest=30, effects="MANUAL", caustics=True, indirect=False, threads=1)
    imgs = {True: [], False: []}
    capped = []
    for seed in (1, 2, 3, 4):
        for on in (True, False):
            monkeypatch.setattr(estimators, "SEARCH_CAP", on)
            res = render(scene, RenderSettings(**{**base, "seed": seed}))
            imgs[on].append(res.passes["Caustic"][..., :3].astype(np.float64).mean(-1))
            if on:
                capped.append(res.stats["photon_stats"]["caustic_capped_count"])
    on, off = np.stack(imgs[True]), np.stack(imgs[False])
    x = -3.0 + (np.arange(W) + 0.5) * 6.0 / W
    y = 2.0 - (np.arange(H) + 0.5) * 4.0 / H
    X, Y = np.meshgrid(x, y)
    inside = (np.abs(X) < 0.7) & (np.abs(Y) < 0.7)
    beyond = (np.abs(X) > 1.2) | (np.abs(Y) > 1.2)
    assert min(capped) > 0, capped
    ratio = on[:, inside].mean() / off[:, inside].mean()
    assert abs(ratio - 1.0) < 0.01, ratio
    rows, cols = np.nonzero(inside.any(1))[0], np.nonzero(inside.any(0))[0]
    crop = lambda a: a[:, rows[0]:rows[-1] + 1, cols[0]:cols[-1] + 1]
    blocks = lambda a: a.reshape(4, a.shape[1] // 2, 2, a.shape[2] // 2, 2).mean(axis=(2, 4))
    Bon, Boff = blocks(crop(on)), blocks(crop(off))
    se = np.sqrt((Bon.var(0, ddof=1) + Boff.var(0, ddof=1)) / 4)
    z = (Bon.mean(0) - Boff.mean(0)) / np.maximum(se, 1e-3 * Boff.mean())
    assert Bon.shape[1:] == (6, 6) and np.abs(z).max() < 4.0, np.abs(z).max()
    tail_on, tail_off = on[:, beyond].mean(), off[:, beyond].mean()
    assert tail_off > 0 and tail_on < 0.5 * tail_off, (tail_on, tail_off)


def test_queries_below_the_cap_density_are_capped_and_brighter_ones_not():
    # r_max = 1.5 x the 90th percentile of the photons' own k-th radii: a query is capped where the
    # photon density is below about 1 / 1.5^2 of the level under which the map's dimmest 10 % lie
    # (docs/photon-mapping.md, "Bounded searches"; the factor was 2, a quarter, before 2026-12-07).
    # A dense floor (95 % of the photons) and two patches far from it at 1 / 1.8 and 1 / 4.5 of its
    # density: the first patch's queries read k-nearest estimates, the second's are capped.
    rng = np.random.default_rng(3)
    dense = 10_000.0                                          # photons / m^2
    parts = [(rng.uniform((-2.0, -1.0), (0.0, 1.0), (40_000, 2)))]
    for x0, ratio in ((0.3, 1.8), (1.2, 4.5)):
        n = int(dense / ratio * 0.25)
        parts.append(rng.uniform((x0, -0.25), (x0 + 0.5, 0.25), (n, 2)))
    xy = np.concatenate(parts)
    N = len(xy)
    pos = np.zeros((N, 3))
    pos[:, :2] = xy
    m = PhotonMap(make_records(pos, np.tile([0.0, 0.0, 1.0], (N, 1)), np.full((N, 3), 1e-4), rng.random(N)),
                  Shutter(1.0, 2.0), time_scale=1.0, bounded=True)
    k = 50
    for x0, lo, hi in ((0.3, 0.0, 0.1), (1.2, 0.9, 1.0)):
        q = np.zeros((200, 3))
        q[:, :2] = rng.uniform((x0 + 0.2, -0.05), (x0 + 0.3, 0.05), (200, 2))
        before = m.stats["capped_count"]
        m.estimate(q, np.tile([0.0, 0.0, 1.0], (200, 1)), np.full(200, 0.5), estimator="STANDARD", k=k)
        frac = (m.stats["capped_count"] - before) / 200
        assert lo <= frac <= hi, (x0, frac, m.search_cap(m.flat_tree(3), k))
