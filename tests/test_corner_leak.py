"""A wall's look-ups near an open outer corner read no sunlit face behind the wall (a leak, fixed).

Two 0.1 m thick box walls meeting at the inner corner with the outer corner's 0.1 x 0.1 m notch
open (how review/make_interior5.py's kitchen is built): the sun outside lights the notch, and
the notch's face that continues the other wall's plane (here x = 0, y in [-0.1, 0]) stores bright
photons that arrived from the notch, i.e. from the room side of the wall A (y = 0, facing +y).
They pass A's side test and lie within the tangent slab's back tolerance (PLANE_FRACTION r =
0.5 r, r of the order of 0.3-1 m in a dim room), so a query on A near the corner adds them.  In
the kitchen (Sun alone) that read 2.4-3.7x Cycles at the corner, 0.80-1.13x with the notch
filled (docs/photon-mapping.md, "Tangent slab", "Open outer corners").  No constant of the slab
removes it (the notch is 0.1 m deep whatever r is); a photon record held no normal to reject a
face perpendicular to the query's.  Fixed by the photon normals (2026-12-07): each record carries its
surface's geometric normal (record.ng_oct), and a photon behind the query's plane counts only if that
normal is within acos(NORMAL_COS) = 80 deg of the query's (kdtree._facing; docs "Photon normals").

Synthetic map: A and B (x = 0, facing +x) at 1 W/m^2 each, the notch face at 20 W/m^2; queries
on A 0.02-0.1 m from the corner (TEMPORAL, k 100: r about 0.08 m).  Measured before the
fix (2026-12-07): mean 6.03x A's irradiance (STANDARD 3.55x); PLANE_FRONT 0.5: 5.97x; PLANE_FRACTION
0.1: 2.11x; the same map without the notch's photons: 1.00x (STANDARD 1.06x).  With the photon
normals: TEMPORAL 1.003x, STANDARD 1.056x, KD4D 1.044x (the maps without normals still read 6.03x,
3.55x, 4.72x: test_the_leak_without_stored_normals).
"""
from __future__ import annotations

import numpy as np
import pytest

from stpm_core.photons.estimators import PhotonMap
from stpm_core.photons.record import make_records
from stpm_core.shutter import Shutter

BOX = Shutter(1.0, 2.0)
E_WALL, E_NOTCH, NOTCH = 1.0, 20.0, 0.1       # W/m^2, W/m^2, m


def _hemisphere(rng, n, axis, sign):
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    d[:, axis] = sign * np.abs(d[:, axis])
    return d


def corner_map(rng, density=5_000.0, *, no_normals=False, backend="auto"):
    """(map): A (y = 0, x in [0, 2]), B (x = 0, y in [0, 2]) and the notch face (x = 0, y in
    [-NOTCH, 0], photons from -x and +y: from the other notch face at y = 0), z in [0, 2]."""
    nA = int(density * 4.0)
    nN = int(density * NOTCH * 2.0)
    A = np.column_stack([rng.uniform(0, 2, nA), np.zeros(nA), rng.uniform(0, 2, nA)])
    B = np.column_stack([np.zeros(nA), rng.uniform(0, 2, nA), rng.uniform(0, 2, nA)])
    N = np.column_stack([np.zeros(nN), rng.uniform(-NOTCH, 0, nN), rng.uniform(0, 2, nN)])
    wN = _hemisphere(rng, nN, 0, -1.0)
    wN[:, 1] = np.abs(wN[:, 1])
    pos = np.vstack([A, B, N])
    wi = np.vstack([_hemisphere(rng, nA, 1, 1.0), _hemisphere(rng, nA, 0, 1.0), wN])
    # the surfaces' geometric normals as the tracer stores them (record.make_records turns them to wi's side)
    ng = np.repeat([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [1.0, 0.0, 0.0]], [nA, nA, nN], axis=0)
    power = np.concatenate([np.full(2 * nA, E_WALL / density), np.full(nN, E_NOTCH / density)])
    t = BOX.sample(rng.random(pos.shape[0]))
    return PhotonMap(make_records(pos, wi, np.repeat(power[:, None], 3, 1), t, ng=None if no_normals else ng),
                     BOX, time_scale=0.2, backend=backend)


@pytest.mark.parametrize("backend", ["numba", "scipy"])
@pytest.mark.parametrize("estimator", ["STANDARD", "TEMPORAL", "KD4D"])
def test_wall_near_an_open_outer_corner_reads_no_notch_photons(estimator, backend):
    rng = np.random.default_rng(3)
    m = corner_map(rng, backend=backend)
    n = 400
    q = np.column_stack([rng.uniform(0.02, 0.1, n), np.zeros(n), rng.uniform(0.5, 1.5, n)])
    ns = np.tile([0.0, 1.0, 0.0], (n, 1))
    E = m.estimate(q, ns, rng.random(n), estimator=estimator, k=100, ng=ns)[:, 0]
    assert abs(E.mean() / E_WALL - 1.0) < 0.1, E.mean() / E_WALL


def test_the_leak_without_stored_normals():
    # the same map without normals (records made without ng: every photon passes the normal test)
    # still reads the notch: what the test above would read without the fix
    rng = np.random.default_rng(3)
    m = corner_map(rng, no_normals=True)
    n = 400
    q = np.column_stack([rng.uniform(0.02, 0.1, n), np.zeros(n), rng.uniform(0.5, 1.5, n)])
    ns = np.tile([0.0, 1.0, 0.0], (n, 1))
    E = m.estimate(q, ns, rng.random(n), estimator="TEMPORAL", k=100, ng=ns)[:, 0]
    assert E.mean() > 3.0 * E_WALL, E.mean() / E_WALL
