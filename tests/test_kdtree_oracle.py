"""The compiled kd-tree (``photons/kdtree.py``) against a brute-force numpy oracle.

Every query of :meth:`FlatTree.lookup` (STANDARD, TEMPORAL, KD4D; box and cone), :meth:`FlatTree.knn_radius`
and :meth:`FlatTree.range_sum` is recomputed here by sorting *all* photons by the same float64 squared
distance (from the float32 coordinates, summed in the same order), so radii, time windows and counts must
be equal bit for bit, and the sums of power equal to float64 rounding (the oracle sums in another order).
Inputs: random photons on planes and in a cloud, queries on and off them; and degenerate maps: exact
duplicates, every photon at one point, as many candidates as photons, one leaf, an empty map (through
:class:`PhotonMap`).  Where exact ties make the neighbour set arbitrary, the tied photons are identical
(same power, direction and time), so every valid choice gives the same sums.
"""
from __future__ import annotations

import numpy as np
import pytest

from stpm_core.photons.estimators import PhotonMap
from stpm_core.photons.record import make_records
from stpm_core.shutter import Shutter

kdtree = pytest.importorskip("stpm_core.photons.kdtree")
if not kdtree.AVAILABLE:
    pytest.skip("numba look-ups unavailable", allow_module_level=True)

S = 0.7                     # KD4D's time scale (m per shutter) in these tests
RTOL = 1e-12                # sums: float64 in another order


def photon_arrays(rng, N, *, dup=1, one_point=False):
    """Positions (N, 3) float32, times (N,) float32, packed rows (N, 8) float32 (wi, 0, Phi, 0).

    dup > 1: every photon repeated dup times (exact copies); one_point: all at one place and time."""
    n0 = -(-N // dup)
    kind = rng.integers(0, 3, n0)
    pos = rng.uniform(-1.0, 1.0, (n0, 3))
    pos[kind == 0, 2] = 0.0                                   # a floor
    pos[kind == 1, 0] = 0.25                                  # a wall
    t = rng.random(n0)
    wi = rng.normal(size=(n0, 3))
    wi /= np.linalg.norm(wi, axis=1, keepdims=True)
    phi = rng.uniform(0.1, 2.0, (n0, 3))
    if one_point:
        pos[:] = (0.1, -0.2, 0.3)
        t[:] = 0.4
        wi[:] = (0.0, 0.0, 1.0)
        phi[:] = (1.0, 0.5, 0.25)
    rep = lambda a: np.repeat(a, dup, axis=0)[:N]
    packed = np.zeros((N, 8), np.float32)
    packed[:, :3] = rep(wi)
    packed[:, 4:7] = rep(phi)
    return rep(pos).astype(np.float32), rep(t).astype(np.float32), packed


def query_arrays(rng, n, pos):
    """Queries (n, 4) float64 (x, y, z, t): half near photons, half anywhere; normals (n, 3) float32."""
    q = np.empty((n, 4))
    near = pos[rng.integers(0, len(pos), n)].astype(np.float64) + rng.normal(0.0, 0.05, (n, 3))
    q[:, :3] = np.where(rng.random((n, 1)) < 0.5, near, rng.uniform(-1.3, 1.3, (n, 3)))
    q[:, 3] = rng.random(n)
    ns = rng.normal(size=(n, 3))
    ns /= np.linalg.norm(ns, axis=1, keepdims=True)
    return q, ns.astype(np.float32)


def d2_all(pos, t, q, D, s):
    """Squared distances (N,) float64 from every photon to query q (4,), as the kernels compute them."""
    e0 = pos[:, 0].astype(np.float64) - q[0]
    e1 = pos[:, 1].astype(np.float64) - q[1]
    e2 = pos[:, 2].astype(np.float64) - q[2]
    d2 = e0 * e0 + e1 * e1 + e2 * e2
    if D == 4:
        e3 = s * t.astype(np.float64) - q[3]
        d2 = d2 + e3 * e3
    return d2


def side_sum(packed, idx, n, w):
    """sum over idx of w Phi on the n side (3,) float64."""
    P = packed[idx]
    on = (P[:, 0] * n[0] + P[:, 1] * n[1] + P[:, 2] * n[2]) > 0.0
    return (w[on, None] * P[on, 4:7].astype(np.float64)).sum(axis=0)


def oracle_lookup(pos, t, packed, q, ns, mode, kq, k, cone, cone_k, s):
    """(phi (n, 3), r (n,), tau (n,)) by sorting every photon, per query."""
    D = 4 if mode == kdtree.MODE_KD4D else 3
    n = len(q)
    phi, r, tau = np.zeros((n, 3)), np.zeros(n), np.zeros(n)
    for i in range(n):
        qi = q[i].copy()
        if mode == kdtree.MODE_KD4D:
            qi[3] = q[i, 3]                                  # (already s t)
        d2 = d2_all(pos, t, qi, D, s)
        order = np.argsort(d2, kind="stable")
        r[i] = np.sqrt(d2[order[kq - 1]])
        inner = order[:kq - 1]
        if mode == kdtree.MODE_TEMPORAL:
            dt = np.abs(t[inner].astype(np.float64) - q[i, 3])
            o = np.argsort(dt, kind="stable")
            tau[i] = dt[o[k - 1]]
            inner = inner[o[:k - 1]]
        w = 1.0 - np.sqrt(d2[inner]) / (cone_k * max(r[i], 1e-300)) if cone else np.ones(len(inner))
        phi[i] = side_sum(packed, inner, ns[i], w)
    return phi, r, tau


def assert_sums(a, b):
    np.testing.assert_allclose(a, b, rtol=RTOL, atol=1e-300)


CASES = [  # (name, N, dup, one_point, seed)
    ("random", 3000, 1, False, 1),
    ("duplicates", 3000, 3, False, 2),
    ("one point", 200, 1, True, 3),
    ("one leaf", 20, 1, False, 4),
]


@pytest.mark.parametrize("name,N,dup,one_point,seed", CASES, ids=[c[0] for c in CASES])
def test_knn_lookups_equal_brute_force(name, N, dup, one_point, seed):
    rng = np.random.default_rng(seed)
    pos, t, packed = photon_arrays(rng, N, dup=dup, one_point=one_point)
    q, ns = query_arrays(rng, 150, pos)
    trees = {3: kdtree.FlatTree(pos, t, packed, dims=3, s=S), 4: kdtree.FlatTree(pos, t, packed, dims=4, s=S)}
    for mode, kq, k in ((kdtree.MODE_STANDARD, 7, 7), (kdtree.MODE_STANDARD, min(100, N), min(100, N)),
                        (kdtree.MODE_TEMPORAL, min(150, N), min(100, N - 1)), (kdtree.MODE_TEMPORAL, min(24, N), min(16, N - 1)),
                        (kdtree.MODE_TEMPORAL, N, N - 1),          # every photon a candidate
                        (kdtree.MODE_KD4D, min(50, N), min(50, N)), (kdtree.MODE_STANDARD, N, N)):
        qq = q.copy()
        if mode == kdtree.MODE_KD4D:
            qq[:, 3] *= S
        tree = trees[4 if mode == kdtree.MODE_KD4D else 3]
        for cone in (False, True):
            phi, r, tau = tree.lookup(mode, qq, ns, kq, k, cone, 1.1, 1)
            phi_o, r_o, tau_o = oracle_lookup(pos, t, packed, qq, ns, mode, kq, k, cone, 1.1, S)
            assert np.array_equal(r, r_o), (mode, kq, cone)
            if mode == kdtree.MODE_TEMPORAL:
                assert np.array_equal(tau, tau_o), (mode, kq, k, cone)
            assert_sums(phi, phi_o)


def test_knn_lookups_split_over_threads_equal_one_thread():
    # a batch split over workers gives each range its own warm start: the same answers
    rng = np.random.default_rng(5)
    pos, t, packed = photon_arrays(rng, 20_000)
    q, ns = query_arrays(rng, 9000, pos)
    tree = kdtree.FlatTree(pos, t, packed, dims=3, s=S)
    one = tree.lookup(kdtree.MODE_TEMPORAL, q, ns, 75, 50, True, 1.1, 1)
    two = tree.lookup(kdtree.MODE_TEMPORAL, q, ns, 75, 50, True, 1.1, 2)
    assert np.array_equal(one[1], two[1]) and np.array_equal(one[2], two[2])
    assert_sums(one[0], two[0])


def test_knn_lookups_of_some_rows_into_given_arrays_equal_a_look_up_of_those_rows():
    # FlatTree.lookup(rows=, out=) (PhotonMap._search_sliced: one time slice's queries of a batch): the
    # rows' answers written in place, bit for bit those of a look-up of the gathered rows (what the
    # slices did until 2026-12-07); every other row of out untouched
    rng = np.random.default_rng(6)
    pos, t, packed = photon_arrays(rng, 20_000)
    n = 3000
    q, ns = query_arrays(rng, n, pos)
    ng = ns[rng.permutation(n)]
    tree = kdtree.FlatTree(pos, t, packed, dims=3, s=S)
    rows = rng.choice(n, 1100, replace=False)                # (any order: the look-up sorts them)
    others = np.setdiff1d(np.arange(n), rows)
    for mode, kq, k in ((kdtree.MODE_STANDARD, 40, 40), (kdtree.MODE_TEMPORAL, 75, 50)):
        cap = float(np.median(tree.lookup(mode, q, ns, kq, k, False, 1.1, 1)[1]))   # about half capped
        for cone in (False, True):
            out = (np.full((n, 3), 7.0), np.full(n, 7.0), np.full(n, 7.0))
            got = tree.lookup(mode, q, ns, kq, k, cone, 1.1, 1, cap=cap, ng=ng, plane=0.5, rows=rows, out=out)
            assert all(a is b for a, b in zip(got, out))
            ref = tree.lookup(mode, q[rows], ns[rows], kq, k, cone, 1.1, 1, cap=cap, ng=ng[rows], plane=0.5)
            for a, b in zip(got, ref):
                assert np.array_equal(a[rows], b), (mode, cone)
                assert np.all(a[others] == 7.0)
            assert 0.2 < np.mean(ref[1] >= cap) < 0.8


def test_morton_order_is_the_stable_sort_of_z_curve_codes():
    # kdtree.morton_order (compiled) against numpy: codes of the rows' first D columns quantised to
    # 2^10 cells over the rows' own bounding box, sorted stably (ties: many queries in one cell)
    rng = np.random.default_rng(8)

    def reference(sub, D):
        lo = sub.min(axis=0)
        v = np.clip(((sub - lo) * (1024.0 / np.maximum(sub.max(axis=0) - lo, 1e-30))).astype(np.int64), 0, 1023)
        code = np.zeros(len(sub), np.int64)
        for b in range(10):
            for a in range(D):
                code |= ((v[:, a] >> b) & 1) << (D * b + a)
        return np.argsort(code, kind="stable")

    for n in (1, 2, 85, 5000):
        q = rng.random((n, 4)) * [3.0, 1.0, 1e-3, 1.0]
        q[: n // 2, :3] = np.round(q[: n // 2, :3], 2)          # repeated cells
        for D in (3, 4):
            assert np.array_equal(kdtree.morton_order(q, D), reference(q, D))
            rows = rng.permutation(n)[: max(1, n // 3)]
            assert np.array_equal(kdtree.morton_order(q, D, rows), rows[reference(q[rows], D)])
    assert kdtree.morton_order(np.zeros((0, 4)), 3).shape == (0,)


@pytest.mark.parametrize("name,N,dup,one_point,seed", CASES, ids=[c[0] for c in CASES])
def test_knn_radius_equals_brute_force(name, N, dup, one_point, seed):
    rng = np.random.default_rng(10 + seed)
    pos, t, packed = photon_arrays(rng, N, dup=dup, one_point=one_point)
    q, _ = query_arrays(rng, 150, pos)
    for dims in (3, 4):
        tree = kdtree.FlatTree(pos, t, packed, dims=dims, s=S)
        qq = q.copy()
        qq[:, 3] *= S
        for kq, cap in ((min(17, N), np.inf), (min(17, N), 0.3), (N, np.inf)):
            r = tree.knn_radius(qq, kq, cap, 1)
            for i in range(len(qq)):
                d2 = np.sort(d2_all(pos, t, qq[i], dims, S))
                want = np.sqrt(d2[kq - 1]) if d2[kq - 1] < cap * cap else cap
                assert r[i] == want, (dims, kq, cap, i)


@pytest.mark.parametrize("name,N,dup,one_point,seed", CASES, ids=[c[0] for c in CASES])
def test_range_sums_equal_brute_force(name, N, dup, one_point, seed):
    rng = np.random.default_rng(20 + seed)
    pos, t, packed = photon_arrays(rng, N, dup=dup, one_point=one_point)
    q, ns = query_arrays(rng, 150, pos)
    q[:, 3] *= S
    rad = rng.uniform(0.0, 0.4, len(q))
    rad[:5] = (0.0, 1e-9, 10.0, np.inf, 0.2)
    half = rng.uniform(0.0, 0.3, len(q))
    for dims, cyl in ((3, False), (4, False), (4, True)):
        tree = kdtree.FlatTree(pos, t, packed, dims=dims, s=S)
        for cone in (False, True):
            phi, cnt = tree.range_sum(q, ns, rad, half if cyl else None, cone, 1.1, 1)
            for i in range(len(q)):
                if cyl:
                    e = pos.astype(np.float64) - q[i, :3]
                    d2 = e[:, 0] * e[:, 0] + e[:, 1] * e[:, 1] + e[:, 2] * e[:, 2]
                    inside = (d2 < rad[i] ** 2) & ~(np.abs(S * t.astype(np.float64) - q[i, 3]) > half[i])
                else:
                    d2 = d2_all(pos, t, q[i], dims, S)
                    inside = d2 < rad[i] ** 2
                idx = np.flatnonzero(inside)
                w = 1.0 - np.sqrt(d2[idx]) / (1.1 * max(rad[i], 1e-300)) if cone else np.ones(len(idx))
                assert cnt[i] == len(idx), (dims, cyl, i)
                assert_sums(phi[i], side_sum(packed, idx, ns[i], w))


def test_photon_map_degenerate_sizes():
    # through PhotonMap: an empty map reads 0; k larger than the map is clamped to the map (the same
    # estimate as k = N); a map of one point and one time reads the same with every estimator
    rng = np.random.default_rng(3)
    shutter = Shutter(1.0, 2.0)
    p = rng.uniform(-0.5, 0.5, (40, 3))
    ns = np.tile([0.0, 0.0, 1.0], (40, 1))
    t = rng.random(40)
    empty = PhotonMap(make_records(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0)), shutter,
                      time_scale=S)
    for est in ("STANDARD", "TEMPORAL", "KD4D"):
        assert np.array_equal(empty.estimate(p, ns, t, estimator=est, k=50), np.zeros((40, 3)))
    pos, tt, packed = photon_arrays(rng, 60)
    m = PhotonMap(make_records(pos, packed[:, :3], packed[:, 4:7], tt), shutter, time_scale=S)
    for est in ("STANDARD", "TEMPORAL", "KD4D"):
        big = m.estimate(p, ns, t, estimator=est, k=1000)
        assert np.all(np.isfinite(big)) and big.sum() > 0
        assert np.array_equal(big, m.estimate(p, ns, t, estimator=est, k=60))
    pos, tt, packed = photon_arrays(rng, 50, one_point=True)
    m = PhotonMap(make_records(pos, packed[:, :3], packed[:, 4:7], tt), shutter, time_scale=S)
    E = [m.estimate(p, ns, t, estimator=est, k=10) for est in ("STANDARD", "TEMPORAL", "KD4D")]
    assert np.array_equal(E[0], E[1]) and np.array_equal(E[0], E[2])      # one time: a timeless map
    r2 = ((p - pos[0].astype(np.float64)) ** 2).sum(axis=1)
    np.testing.assert_allclose(E[0][:, 0], 9 * 1.0 / (np.pi * r2), rtol=1e-6)   # k - 1 = 9 photons of 1 W


def test_searches_for_more_photons_than_the_tree_holds_are_refused():
    # the search would otherwise read kq photons that are not there (out of bounds): callers clamp k
    rng = np.random.default_rng(9)
    pos, t, packed = photon_arrays(rng, 40)
    q, ns = query_arrays(rng, 5, pos)
    tree = kdtree.FlatTree(pos, t, packed, dims=3, s=S)
    for mode, kq, k in ((kdtree.MODE_STANDARD, 41, 41), (kdtree.MODE_TEMPORAL, 41, 20), (kdtree.MODE_TEMPORAL, 20, 20),
                        (kdtree.MODE_STANDARD, 0, 0)):
        with pytest.raises(ValueError):
            tree.lookup(mode, q, ns, kq, k, False, 1.1, 1)
    with pytest.raises(ValueError):
        tree.knn_radius(q, 41, np.inf, 1)
    assert np.all(np.isfinite(tree.lookup(kdtree.MODE_TEMPORAL, q, ns, 40, 39, False, 1.1, 1)[1]))
