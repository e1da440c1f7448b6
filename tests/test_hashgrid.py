"""The bounded cell table (``photons/hashgrid.py``, ``CellTable``) and the progressive pilot's
regions read from it: values kept up to the limit, held keys keep their values, and each query
gets the region ``Pilot.region_at`` computes at its grid cell's centre.
"""
from __future__ import annotations

import numpy as np
import pytest

from stpm_core.photons import hashgrid
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
