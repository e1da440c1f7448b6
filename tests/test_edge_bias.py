"""The disc estimate's boundary bias at a surface's edge, and its correction (kdtree._edge_scale).

A k-nearest estimate divides the photons' power by the whole disc pi r^2; where the query's surface
ends inside the disc (a wall beside a window opening, a table's rim) part of the disc holds no
surface and the estimate reads the covered fraction of the irradiance: at a distance d from a
straight edge, f(d / r) = 1 - (acos(d / r) - (d / r) sqrt(1 - (d / r)^2)) / pi (0.5 at the edge).
The global map's look-ups divide by the covered fraction their photons show (docs/photon-mapping.md,
"Edges and corners", "Boundary correction").  Synthetic maps of a plane z = 0 at 1 W/m^2 (x in
[0, 2]: the edge at x = 0), queries at d in [0, 3 r], k 100; the same map read with the correction
on and off (``PhotonMap.edge``).  Measured 2026-12-07 (3 maps, 30 k queries each; before -> after,
mean read / 1 W/m^2), d / r in [0.3, 0.5), [0.5, 0.7), [0.7, 0.85), [0.85, 1): STANDARD 0.737,
0.850, 0.929, 0.981 -> 0.982, 0.975, 0.954, 0.984; TEMPORAL 0.748, 0.856, 0.938, 0.989 -> 0.994,
0.988, 0.971, 0.992; the interior (no edge within 0.5 m) 1.0016x / 1.0009x (docs/photon-mapping.md,
"Boundary correction at a convex edge").  Without the correction (``EDGE_CORRECTION`` False, i.e.
main before it) test_edge_reads_the_surfaces_irradiance fails in all four cases.
"""
from __future__ import annotations

import numpy as np
import pytest

from stpm_core.photons import kdtree
from stpm_core.photons.estimators import CONE_K, PhotonMap
from stpm_core.photons.record import make_records
from stpm_core.shutter import Shutter

pytestmark = pytest.mark.skipif(not kdtree.AVAILABLE, reason="the correction is in the compiled look-ups")

BOX = Shutter(1.0, 2.0)
K = 100
DENSITY = 5_000.0          # photons / m^2: r about 0.08 m at k 100
L = 12.0                   # the edge's length (m)


def _covered(x):
    x = np.clip(x, -1.0, 1.0)
    return 1.0 - (np.arccos(x) - x * np.sqrt(1.0 - x * x)) / np.pi


def plane_map(rng, *, width=2.0, step=None, edge=True):
    """A plane z = 0, x in [0, width], y in [0, L], 1 W/m^2 (step = (x_s, ratio): ratio W/m^2 for
    x < x_s), photons from above, their normals stored."""
    n = rng.poisson(DENSITY * width * L)
    pos = np.column_stack([rng.uniform(0, width, n), rng.uniform(0, L, n), np.zeros(n)])
    if step is not None:
        pos = pos[(pos[:, 0] >= step[0]) | (rng.random(n) < step[1])]
        n = pos.shape[0]
    wi = rng.normal(size=(n, 3))
    wi /= np.linalg.norm(wi, axis=1, keepdims=True)
    wi[:, 2] = np.abs(wi[:, 2])
    ng = np.tile([0.0, 0.0, 1.0], (n, 1))
    rec = make_records(pos, wi, np.full((n, 3), 1.0 / DENSITY), BOX.sample(rng.random(n)), ng=ng)
    return PhotonMap(rec, BOX, time_scale=0.2, edge=edge)


def read(m, x, estimator, *, edge, kernel="BOX", seed=0):
    """(E (n,), r (n,)) at queries (x, y, 0), y in [0.5, L - 0.5], the same queries for both settings."""
    rng = np.random.default_rng(seed)
    n = x.shape[0]
    q = np.column_stack([x, rng.uniform(0.5, L - 0.5, n), np.zeros(n)])
    ns = np.tile([0.0, 0.0, 1.0], (n, 1))
    m.edge = edge
    E, r, *_ = m.estimate(q, ns, rng.random(n), estimator=estimator, k=K, ng=ns, support=True, kernel=kernel)
    return E[:, 0], r


def test_cut_fraction_matches_the_disc_segment():
    d = np.linspace(0.0, 1.0, 201)
    got = np.array([kdtree._cut_fraction(x, 0.0) for x in d])
    assert np.abs(got - _covered(d)).max() < 1e-3
    # the cone kernel's weighted fraction against a Monte Carlo of the disc
    rng = np.random.default_rng(0)
    rho, th = np.sqrt(rng.random(400_000)), rng.random(400_000) * 2 * np.pi
    w = 1.0 - rho / 1.1
    for x in (0.0, 0.3, 0.7):
        mc = w[rho * np.cos(th) <= x].sum() / w.sum()
        assert abs(kdtree._cut_fraction(x, 1.0 / 1.1) - mc) < 3e-3, x


@pytest.mark.parametrize("kernel", ["BOX", "CONE"])
@pytest.mark.parametrize("estimator", ["STANDARD", "TEMPORAL"])
def test_edge_reads_the_surfaces_irradiance(estimator, kernel):
    rng = np.random.default_rng(5)
    m = plane_map(rng)
    # d in units of the interior's median radius (binning by each query's own r would select
    # the small radii, i.e. the high estimates, into the far bins)
    r_int = np.median(read(m, np.full(500, 1.0), estimator, edge=False, kernel=kernel)[1])
    x = np.random.default_rng(1).uniform(0.0, 1.2 * r_int, 20_000)
    E0, r = read(m, x, estimator, edge=False, kernel=kernel)
    E1, _ = read(m, x, estimator, edge=True, kernel=kernel)
    d = x / r_int
    for lo, hi in ((0.3, 0.5), (0.5, 0.7), (0.7, 0.85), (0.85, 1.0)):
        s = (d >= lo) & (d < hi)
        assert s.sum() > 1500
        # uncorrected: the covered fraction (what main read); corrected: within 5 %
        inv_k = 1.0 / CONE_K if kernel == "CONE" else 0.0
        cov = np.mean([kdtree._cut_fraction(min(v, 1.0), inv_k) for v in x[s] / r[s]])
        assert abs(E0[s].mean() / cov - 1.0) < 0.03
        assert abs(E1[s].mean() - 1.0) < 0.05, (lo, E0[s].mean(), E1[s].mean())
    s = d < 0.3                                   # nearer: at most 2x (the edge at the query)
    assert 0.95 < E1[s].mean() < 1.05


@pytest.mark.parametrize("estimator", ["STANDARD", "TEMPORAL"])
def test_interior_is_unchanged(estimator):
    rng = np.random.default_rng(6)
    m = plane_map(rng)
    x = np.random.default_rng(2).uniform(0.5, 1.5, 20_000)
    E0, _ = read(m, x, estimator, edge=False)
    E1, _ = read(m, x, estimator, edge=True)
    # measured 1.0009-1.0016x (about 3 % of the queries, each by a few %)
    assert abs(E1.mean() / E0.mean() - 1.0) < 0.005
    assert np.mean(E1 != E0) < 0.1


@pytest.mark.parametrize("estimator", ["STANDARD", "TEMPORAL"])
def test_a_density_step_is_not_an_edge(estimator):
    # a caustic-like step on a whole plane: 1 W/m^2 for x >= 2, 0.25 below; queries within 2 r of it.
    # The photons go on beyond the step (sparser), so the strip inside the support line is short of
    # photons and the correction stays off; measured (2026-12-07) at most 1.020x (STANDARD, bright side
    # 0.2-0.5 r from the step), 1.010x TEMPORAL.  Without that strip test (EDGE_ACCEPT 0) this test
    # fails: STANDARD 1.036x in the bin 0.2-0.5 r.
    rng = np.random.default_rng(7)
    m = plane_map(rng, width=4.0, step=(2.0, 0.25))
    x = 2.0 + np.random.default_rng(3).uniform(-0.16, 0.16, 20_000)
    E0, r = read(m, x, estimator, edge=False)
    E1, _ = read(m, x, estimator, edge=True)
    d = (x - 2.0) / r
    for lo, hi in ((-1.0, -0.2), (-0.2, 0.2), (0.2, 0.5), (0.5, 1.0)):
        s = (d >= lo) & (d < hi)
        assert E1[s].mean() / E0[s].mean() < 1.03, (lo, E1[s].mean() / E0[s].mean())


def test_off_by_default_and_for_the_caustic_map():
    from stpm_core.photons import maps
    assert maps.EDGE_MAPS == ("global",)
    rng = np.random.default_rng(8)
    m = plane_map(rng, edge=False)
    x = np.random.default_rng(4).uniform(0.0, 0.1, 2000)
    E0, _ = read(m, x, "TEMPORAL", edge=False)
    E1, _ = read(m, x, "TEMPORAL", edge=False)
    assert np.array_equal(E0, E1)
    assert E0.mean() < 0.85                        # the boundary bias itself


@pytest.mark.parametrize("estimator", ["STANDARD", "TEMPORAL", "KD4D"])
def test_the_corner_leak_stays_closed(estimator):
    # tests/test_corner_leak.py's map (a concave corner, the open notch's sunlit face behind A) with
    # the correction on: B's photons lie in front of A's plane (EDGE_FRONT: no correction), the
    # notch's are dropped by the normal test; measured 1.056 / 1.003 / 1.044 with and without it
    from test_corner_leak import E_WALL, corner_map
    rng = np.random.default_rng(3)
    m = corner_map(rng)
    n = 400
    q = np.column_stack([rng.uniform(0.02, 0.1, n), np.zeros(n), rng.uniform(0.5, 1.5, n)])
    ns = np.tile([0.0, 1.0, 0.0], (n, 1))
    t = rng.random(n)
    m.edge = False
    E0 = m.estimate(q, ns, t, estimator=estimator, k=100, ng=ns)[:, 0]
    m.edge = True
    E1 = m.estimate(q, ns, t, estimator=estimator, k=100, ng=ns)[:, 0]
    assert abs(E1.mean() / E_WALL - 1.0) < 0.1
    assert abs(E1.mean() / E0.mean() - 1.0) < 0.01
