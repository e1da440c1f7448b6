"""The look-up's glossy sums (``kdtree.FlatTree.lookup(..., glossy=...)``) against a brute-force oracle.

Random photons on a plane (directions on both sides, random powers and times, about half flagged
delta-only), queries with the closure of a rough coated plastic or a rough metal: the glossy sum
must be the sum of f_c(wo, wi_p) Phi_p over the photons the estimate itself kept (the k - 1 nearest
on the query's side; TEMPORAL's window) whose flag is set, f_c = ``kernels.bsdf.bsdf_eval_cont``
evaluated per photon here; the power sum must not change.  The records' flag survives packing
(``record.delta_only``).
"""
from __future__ import annotations

import numpy as np
import pytest

from stpm_core.kernels.bsdf import bsdf_eval_cont, ggx_albedo_tables
from stpm_core.kernels.closure import pack_materials
from stpm_core.photons import kdtree
from stpm_core.photons.record import delta_only, make_records, oct_decode
from stpm_core.scene import Material

pytestmark = pytest.mark.skipif(not kdtree.AVAILABLE, reason="compiled look-ups unavailable")


def _map(rng, N=3000):
    pos = np.zeros((N, 3))
    pos[:, :2] = rng.uniform(-1.0, 1.0, (N, 2))
    wi = rng.normal(size=(N, 3))
    wi /= np.linalg.norm(wi, axis=1, keepdims=True)
    power = rng.uniform(0.5, 1.5, (N, 3))
    t = rng.uniform(0.0, 1.0, N)
    flag = rng.uniform(size=N) < 0.5
    rec = make_records(pos, wi, power, t, delta_only=flag)
    return rec, flag


def test_records_keep_the_delta_only_flag():
    rng = np.random.default_rng(1)
    rec, flag = _map(rng)
    assert np.array_equal(delta_only(rec), flag)
    wi = oct_decode(rec["wi_oct"]).astype(float)
    again = oct_decode(make_records(np.zeros((len(rec), 3)), wi, np.ones((len(rec), 3)), np.zeros(len(rec)))["wi_oct"])
    assert np.max(np.abs(wi - again)) < 1e-4


def _packed(rec) -> np.ndarray:
    """(N, 8) float32 records as the tree holds them: wi, the delta-only flag, power."""
    packed = np.zeros((len(rec), 8), np.float32)
    packed[:, :3] = oct_decode(rec["wi_oct"])
    packed[:, 3] = delta_only(rec)
    packed[:, 4:7] = rec["power"]
    return packed


@pytest.mark.parametrize("mode", [kdtree.MODE_STANDARD, kdtree.MODE_TEMPORAL])
@pytest.mark.parametrize("mat", [Material(base_color=np.full(3, 0.4), roughness=0.6, specular=1.0),
                                 Material(base_color=np.array([0.9, 0.6, 0.4]), metallic=1.0, roughness=0.5)])
def test_glossy_sums_match_the_oracle(mode, mat):
    rng = np.random.default_rng(7)
    rec, flag = _map(rng)
    packed = _packed(rec)
    tree = kdtree.FlatTree(rec["position"], rec["time"], packed, dims=3, s=1.0)
    n, k = 40, 30
    kq = 90 if mode == kdtree.MODE_TEMPORAL else k
    q = np.zeros((n, 4))
    q[:, :2] = rng.uniform(-0.8, 0.8, (n, 2))
    q[:, 3] = rng.uniform(0.1, 0.9, n)
    ns = np.tile([0.0, 0.0, 1.0], (n, 1))
    wo = rng.normal(size=(n, 3))
    wo[:, 2] = np.abs(wo[:, 2]) + 0.2
    wo /= np.linalg.norm(wo, axis=1, keepdims=True)
    C = pack_materials([mat])
    E, E_avg = ggx_albedo_tables()
    gC = np.ascontiguousarray(np.repeat(C[:1], n, axis=0))
    gW = np.concatenate([wo, ns, ns], axis=1)
    phi0, r0, tau0 = tree.lookup(mode, q, ns, kq, k, False, 1.1, 1)
    phi, r, tau, g = tree.lookup(mode, q, ns, kq, k, False, 1.1, 1, (gC, gW, E, E_avg, 1.0))
    np.testing.assert_array_equal(phi, phi0)
    np.testing.assert_array_equal(r, r0)
    # oracle: the kept photons by brute force (float64 distances from the float32 records, as the search)
    P = rec["position"].astype(np.float64)
    T = rec["time"].astype(np.float64)
    W = packed[:, :3].astype(np.float64)
    for i in range(n):
        d2 = ((P - q[i, :3]) ** 2).sum(axis=1)
        inner = np.argsort(d2, kind="stable")[:kq - 1]
        if mode == kdtree.MODE_TEMPORAL:
            dt = np.abs(T[inner] - q[i, 3])
            inner = inner[dt < tau[i]]
        inner = inner[W[inner] @ ns[i] > 0.0]
        want_phi = packed[inner, 4:7].astype(np.float64).sum(axis=0)
        np.testing.assert_allclose(phi[i], want_phi, rtol=1e-5)
        want = np.zeros(3)
        for j in inner[flag[inner]]:
            f0, f1, f2, _ = bsdf_eval_cont(C, 0, E, E_avg, tuple(wo[i]), tuple(W[j]), tuple(ns[i]), tuple(ns[i]), False)
            want += np.array([f0, f1, f2]) * packed[j, 4:7]
        np.testing.assert_allclose(g[i], want, rtol=1e-5, atol=1e-12)
    assert g.sum() > 0.0


def test_glossy_sums_of_some_rows_in_place_equal_a_look_up_of_those_rows():
    # FlatTree.lookup(rows=, out=) with glossy sums (PhotonMap._search_sliced: one time slice's
    # queries): each row reads its own closure and hit rows (gC, gW of the whole batch) and writes
    # its sums in place, bit for bit a look-up of the gathered rows; other rows untouched
    rng = np.random.default_rng(9)
    rec, _ = _map(rng)
    tree = kdtree.FlatTree(rec["position"], rec["time"], _packed(rec), dims=3, s=1.0)
    n = 60
    q = np.zeros((n, 4))
    q[:, :2] = rng.uniform(-0.8, 0.8, (n, 2))
    q[:, 3] = rng.uniform(0.1, 0.9, n)
    ns = np.tile([0.0, 0.0, 1.0], (n, 1)).astype(np.float32)
    wo = rng.normal(size=(n, 3))
    wo[:, 2] = np.abs(wo[:, 2]) + 0.2
    wo /= np.linalg.norm(wo, axis=1, keepdims=True)
    C = pack_materials([Material(base_color=np.full(3, 0.4), roughness=0.6, specular=1.0),
                        Material(base_color=np.array([0.9, 0.6, 0.4]), metallic=1.0, roughness=0.5)])
    E, E_avg = ggx_albedo_tables()
    gC = np.ascontiguousarray(C[rng.integers(0, 2, n)])          # two materials, mixed over the rows
    gW = np.concatenate([wo, ns, ns], axis=1)
    rows = rng.choice(n, 25, replace=False)
    out = tuple(np.full(shape, 5.0) for shape in ((n, 3), n, n, (n, 3)))
    got = tree.lookup(kdtree.MODE_TEMPORAL, q, ns, 90, 30, False, 1.1, 1, (gC, gW, E, E_avg, 1.0), rows=rows, out=out)
    want = tree.lookup(kdtree.MODE_TEMPORAL, q[rows], ns[rows], 90, 30, False, 1.1, 1,
                       (gC[rows], gW[rows], E, E_avg, 1.0))
    others = np.setdiff1d(np.arange(n), rows)
    for a, b, c in zip(got, want, out):
        assert a is c and np.array_equal(a[rows], b) and np.all(a[others] == 5.0)
    assert want[3].sum() > 0.0


@pytest.mark.parametrize("cone", [False, True])
@pytest.mark.parametrize("cyl", [False, True])
def test_range_glossy_sums_match_the_oracle(cone, cyl):
    """The progressive method's fixed regions (``FlatTree.range_sum(..., glossy=...)``, 4D tree): the
    glossy sum is the sum of w f_c(wo, wi_p) Phi_p over the photons inside the region on the query's
    side (w the cone's weight) whose flag is set; the power sums and counts do not change."""
    rng = np.random.default_rng(11)
    rec, flag = _map(rng)
    packed = _packed(rec)
    s = 0.7
    tree = kdtree.FlatTree(rec["position"], rec["time"], packed, dims=4, s=s)
    n = 40
    q = np.zeros((n, 4))
    q[:, :2] = rng.uniform(-0.8, 0.8, (n, 2))
    q[:, 3] = s * rng.uniform(0.1, 0.9, n)
    ns = np.tile([0.0, 0.0, 1.0], (n, 1))
    rad = rng.uniform(0.1, 0.25, n)
    half = rng.uniform(0.05, 0.3, n) if cyl else None
    wo = rng.normal(size=(n, 3))
    wo[:, 2] = np.abs(wo[:, 2]) + 0.2
    wo /= np.linalg.norm(wo, axis=1, keepdims=True)
    C = pack_materials([Material(base_color=np.full(3, 0.4), roughness=0.6, specular=1.0)])
    E, E_avg = ggx_albedo_tables()
    gC = np.ascontiguousarray(np.repeat(C[:1], n, axis=0))
    gW = np.concatenate([wo, ns, ns], axis=1)
    phi0, cnt0 = tree.range_sum(q, ns, rad, half, cone, 1.1, 1)
    phi, cnt, g = tree.range_sum(q, ns, rad, half, cone, 1.1, 1, (gC, gW, E, E_avg, 1.0))
    np.testing.assert_array_equal(phi, phi0)
    np.testing.assert_array_equal(cnt, cnt0)
    # oracle: the photons inside by brute force (float64 distances from the float32 records, as the search)
    P = rec["position"].astype(np.float64)
    T = s * rec["time"].astype(np.float64)
    W = packed[:, :3].astype(np.float64)
    for i in range(n):
        d2 = ((P - q[i, :3]) ** 2).sum(axis=1)
        if cyl:
            inside = (d2 < rad[i] ** 2) & (np.abs(T - q[i, 3]) <= half[i])
        else:
            d2 = d2 + (T - q[i, 3]) ** 2
            inside = d2 < rad[i] ** 2
        j_in = np.flatnonzero(inside & (W @ ns[i] > 0.0) & flag)
        w = 1.0 - np.sqrt(d2[j_in]) / (1.1 * rad[i]) if cone else np.ones(j_in.size)
        want = np.zeros(3)
        for wj, j in zip(w, j_in):
            f0, f1, f2, _ = bsdf_eval_cont(C, 0, E, E_avg, tuple(wo[i]), tuple(W[j]), tuple(ns[i]), tuple(ns[i]), False)
            want += wj * np.array([f0, f1, f2]) * packed[j, 4:7]
        np.testing.assert_allclose(g[i], want, rtol=1e-5, atol=1e-12)
    assert g.sum() > 0.0
