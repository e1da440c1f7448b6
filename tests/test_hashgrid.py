"""The hash grid's fixed-region look-ups (``photons/hashgrid.py``) answer exactly as the kd-tree's.

Every case runs the same queries through ``FlatTree.range_sum`` (the kd-tree) and
``HashGrid.range_sum`` and asks for the same photon sets: equal counts, and equal sums of
integer-valued powers (exact in float64 whatever the order of the additions, so set for set:
compared bit for bit); the cone-weighted sums to 1e-12 relative (only the order of the float64
additions differs).  Inputs: random maps (a cloud and planes), photons on one plane and on cell
boundaries, all in one cell, an empty map, radius 0, huge and infinite radii, queries outside
the photons' box, time windows reaching past the shutter ends, cells much finer and much coarser
than the regions; balls in 3D and 4D and cylinders, box and cone kernels.
"""
from __future__ import annotations

import numpy as np
import pytest

from stpm_core.photons import hashgrid, kdtree
from stpm_core.photons.estimators import PhotonMap
from stpm_core.photons.record import make_records
from stpm_core.shutter import Shutter

pytestmark = pytest.mark.skipif(not hashgrid.AVAILABLE, reason="numba unavailable")

BOX = Shutter(1.0, 1.5)
S = 0.8                                  # time scale (m per shutter)


def _map(pos, rng, times=None):
    """A PhotonMap over pos (N, 3) with integer powers (1 .. 2^20) and random sides and times."""
    N = pos.shape[0]
    wi = rng.normal(size=(N, 3))
    wi /= np.maximum(np.linalg.norm(wi, axis=1, keepdims=True), 1e-12)
    power = rng.integers(1, 1 << 20, (N, 3)).astype(np.float64)
    t = rng.random(N) if times is None else times
    return PhotonMap(make_records(pos, wi, power, t), BOX, time_scale=S)


def _queries(rng, n, lo=-1.0, hi=1.0, r=(0.02, 0.3)):
    q = np.zeros((n, 4))
    q[:, :3] = rng.uniform(lo, hi, (n, 3))
    q[:, 3] = S * rng.random(n)
    ns = rng.normal(size=(n, 3)).astype(np.float32)
    rad = rng.uniform(*r, n)
    return q, ns, rad


def _compare(m, q, ns, rad, half, *, dims, cone, h):
    """Both look-ups on the same queries; the same sets (counts, exact integer sums)."""
    tree = m.flat_tree(dims)
    grid = hashgrid.HashGrid(m.records["position"], m.records["time"], m._packed, s=m.time_scale, h=h)
    Phi_t, cnt_t = tree.range_sum(q, ns, rad, half, cone, 1.1, 1)
    Phi_g, cnt_g = grid.range_sum(q, ns, rad, half, cone, 1.1, 1, dims=dims)
    assert np.array_equal(cnt_g, cnt_t)
    if cone:
        assert np.allclose(Phi_g, Phi_t, rtol=1e-12, atol=0.0)
    else:
        assert np.array_equal(Phi_g, Phi_t)            # integer powers: exact sums, the same set
    return cnt_t


SHAPES = [(3, None, False), (3, None, True), (4, None, False), (4, None, True), (4, "cyl", False),
          (4, "cyl", True)]


@pytest.mark.parametrize("dims,shape,cone", SHAPES)
@pytest.mark.parametrize("h", [0.003, 0.1, 5.0])
def test_random_maps_match_the_tree(dims, shape, cone, h):
    rng = np.random.default_rng(dims + 10 * cone + 100 * (shape == "cyl") + int(1000 * h))
    N = 6000
    pos = rng.uniform(-1, 1, (N, 3))
    pos[: N // 3, 2] = 0.0                                # a plane
    pos[N // 3: N // 2, 0] = 0.5                          # another, across the first
    m = _map(pos, rng)
    q, ns, rad = _queries(rng, 300)
    q[:100, 2] = 0.0
    half = rng.uniform(0.0, 0.5, 300) if shape == "cyl" else None
    cnt = _compare(m, q, ns, rad, half, dims=dims, cone=cone, h=h)
    assert cnt.sum() > 0


@pytest.mark.parametrize("dims,shape,cone", SHAPES)
def test_adversarial_inputs_match_the_tree(dims, shape, cone):
    rng = np.random.default_rng(7 + dims + 10 * cone + 100 * (shape == "cyl"))
    n = 200
    h = 0.125
    # photons on one plane, on a lattice of cell boundaries (multiples of h from the minimum)
    g = np.arange(-8, 9) * h
    X, Y = np.meshgrid(g, g, indexing="ij")
    pos = np.column_stack([X.ravel(), Y.ravel(), np.zeros(X.size)])
    pos = np.concatenate([pos, pos, pos])                 # coincident photons, different times
    times = np.concatenate([np.zeros(X.size), np.ones(X.size), rng.random(X.size)])   # shutter ends
    m = _map(pos, rng, times)
    q, ns, rad = _queries(rng, n)
    q[:, 2] = 0.0
    q[: n // 4, :2] = np.round(q[: n // 4, :2] / h) * h  # queries on photons
    rad[: n // 4] = h                                       # ... reaching exactly the next ones
    q[: n // 2, 3] = S * np.where(rng.random(n // 2) < 0.5, 0.0, 1.0)   # at the shutter ends
    half = np.where(rng.random(n) < 0.5, 0.3, 0.0) if shape == "cyl" else None
    _compare(m, q, ns, rad, half, dims=dims, cone=cone, h=h)
    # radius 0, huge and infinite radii, queries far outside the photons' box
    rad0 = rad.copy()
    rad0[:50], rad0[50:100], rad0[100:150] = 0.0, 1e6, np.inf
    q2 = q.copy()
    q2[150:, :3] += 50.0
    cnt = _compare(m, q2, ns, rad0, half if half is None else np.where(rng.random(n) < 0.5, np.inf, 0.2),
                   dims=dims, cone=cone, h=h)
    assert (cnt[:50] == 0).all() and (cnt[150:] == 0).all()
    if shape is None:
        assert (cnt[50:150] == m.n).all()


@pytest.mark.parametrize("dims,shape", [(3, None), (4, None), (4, "cyl")])
def test_one_cell_and_empty_maps(dims, shape):
    rng = np.random.default_rng(3)
    # all photons in one cell (h much larger than their cloud)
    m = _map(rng.uniform(0.0, 1e-3, (500, 3)), rng)
    q, ns, rad = _queries(rng, 100, -2e-3, 3e-3, (1e-4, 2e-3))
    half = rng.uniform(0.0, 0.3, 100) if shape == "cyl" else None
    grid = hashgrid.HashGrid(m.records["position"], m.records["time"], m._packed, s=S, h=10.0)
    assert grid.cells == 1
    _compare(m, q, ns, rad, half, dims=dims, cone=False, h=10.0)
    # an empty map: zeros
    empty = hashgrid.HashGrid(np.zeros((0, 3), np.float32), np.zeros(0, np.float32), np.zeros((0, 8), np.float32),
                              s=S, h=0.1)
    Phi, cnt = empty.range_sum(q, ns, rad, half, False, 1.1, 1, dims=dims)
    assert not Phi.any() and not cnt.any()


def test_memory_is_bounded_by_the_photons():
    """Cells far finer than the photons' spacing: the table still holds at most 4 N slots."""
    rng = np.random.default_rng(5)
    N = 3000
    pos = rng.uniform(-100.0, 100.0, (N, 3))
    m = _map(pos, rng)
    grid = hashgrid.HashGrid(m.records["position"], m.records["time"], m._packed, s=S, h=1e-9)
    assert grid.cells == N and grid.slots <= 4 * N
    assert grid.h >= 200.0 / (1 << 21)                      # cell indices fit 21 bits
    q, ns, rad = _queries(rng, 100, -100, 100, (1.0, 20.0))
    _compare(m, q, ns, rad, None, dims=3, cone=False, h=1e-9)


def test_cell_size_is_the_median_radius():
    assert hashgrid.cell_size(np.array([0.1, 0.2, np.inf, 0.0, 0.3]), 10.0) == pytest.approx(0.2)
    assert hashgrid.cell_size(np.array([0.0, np.inf]), 10.0) == pytest.approx(10.0 / (1 << 20))


@pytest.mark.parametrize("estimator", ["STANDARD", "TEMPORAL", "KD4D"])
@pytest.mark.parametrize("kernel", ["BOX", "CONE"])
def test_a_progressive_pass_estimates_the_same_on_grid_and_tree(estimator, kernel, monkeypatch):
    """``ProgressiveMaps.estimate`` with its regions read on the hash grid equals the kd-tree's, whole
    shutter and a stratum (the photon counts it reports too)."""
    import stpm_core.photons.progressive as pp
    from stpm_core.photons.maps import PhotonMaps

    def maps(N, seed):
        rng = np.random.default_rng(seed)
        pos = rng.uniform(-0.5, 0.5, (N, 3))
        pos[: 2 * N // 3, 2] = 0.0
        m = _map(pos, rng)
        empty = PhotonMap(m.records[:0], m.shutter, time_scale=m.time_scale)
        return PhotonMaps({"caustic": m, "global": empty}, estimator=estimator, k=20, kernel=kernel,
                          temporal_alpha=0, time_scale=m.time_scale)

    pilot = pp.Pilot(maps(3000, 1), {"caustic": 1.0, "global": 1.0}, estimator, S, 0.0)
    rng = np.random.default_rng(2)
    n = 500
    p = np.column_stack([rng.uniform(-0.6, 0.6, (n, 2)), np.where(rng.random(n) < 0.7, 0.0, 0.2)])
    ns = np.tile([0.0, 0.0, 1.0], (n, 1))
    t = rng.random(n)
    for stratum in (None, (0.25, 0.5, 0.25)):
        tq = t if stratum is None else 0.25 + 0.25 * t
        out = {}
        for lookup in ("kdtree", "hashgrid"):
            monkeypatch.setattr(pp, "RANGE_LOOKUP", lookup)
            pm = pp.ProgressiveMaps(maps(20_000, 3), pilot, pass_index=3, alpha=0.4, kernel=kernel, stratum=stratum)
            out[lookup] = (pm.estimate("caustic", p, ns, tq), pm.stats["caustic_photons_per_estimate"])
        assert out["kdtree"][1] == out["hashgrid"][1] > 0
        assert np.allclose(out["hashgrid"][0], out["kdtree"][0], rtol=1e-12, atol=0.0)
        assert out["kdtree"][0].any()


def test_cell_table_keeps_values_up_to_its_limit():
    table = hashgrid.CellTable(100)
    keys = np.arange(0, 3000, 7, dtype=np.int64) << 20       # many colliding low bits
    table.put(keys[:60], keys[:60] * 0.5, keys[:60] * 0.25)
    table.put(keys[30:90], np.full(60, -1.0), np.full(60, -1.0))    # held keys keep their values
    have, r, tau = table.get(keys)
    assert table.count == 90 and have[:90].all() and not have[90:].any()
    assert np.array_equal(r[:60], keys[:60] * 0.5) and np.array_equal(tau[:60], keys[:60] * 0.25)
    assert np.array_equal(r[60:90], np.full(30, -1.0))
    table.put(keys[90:], keys[90:] * 1.0, keys[90:] * 1.0)            # fills to the limit, then stops
    assert table.count == 100 and table.get(keys)[0].sum() == 100
    assert np.array_equal(table.keys(), np.sort(table.keys())) and table.tkey.size == 256


@pytest.mark.parametrize("estimator", ["STANDARD", "TEMPORAL", "KD4D"])
def test_pilot_regions_read_from_the_table_are_those_at_the_cell_centres(estimator):
    """``Pilot.initial_size`` (regions kept per grid cell in a CellTable) gives each query the region
    ``region_at`` computes at its cell's centre, whether the cell was seen before or not."""
    import stpm_core.photons.progressive as pp
    from stpm_core.photons.maps import PhotonMaps
    rng = np.random.default_rng(9)
    pos = rng.uniform(-0.5, 0.5, (4000, 3))
    pos[:3000, 2] = 0.0
    m = _map(pos, rng)
    empty = PhotonMap(m.records[:0], m.shutter, time_scale=S)
    pilot = pp.Pilot(PhotonMaps({"caustic": m, "global": empty}, estimator=estimator, k=20, kernel="BOX",
                                temporal_alpha=0, time_scale=S), {"caustic": 1.3, "global": 1.0}, estimator, S, 0.0)
    ns = np.tile(np.float32([0, 0, 1]), (400, 1))
    for _ in range(3):                                       # new cells, then mostly seen ones
        q = np.column_stack([rng.uniform(-0.3, 0.3, (400, 2)), np.zeros(400), S * rng.random(400)])
        r, tau = pilot.initial_size("caustic", q, ns)
        g = pilot._grids["caustic"]
        cells = np.floor((q[:, :3] - g["lo"]) / g["h"])
        qc = np.empty((400, 4))
        qc[:, :3] = g["lo"] + (cells + 0.5) * g["h"]
        nt = g["nt"]
        qc[:, 3] = S * (np.floor(q[:, 3] / S * nt).clip(0, nt - 1) + 0.5) / nt if nt > 1 else S * 0.5
        r0, tau0 = pilot.region_at("caustic", qc)
        assert np.array_equal(r, r0) and (tau is None) == (tau0 is None)
        assert tau is None or np.array_equal(tau, tau0)
