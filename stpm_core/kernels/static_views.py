"""Static views: which path segments see the same point at every instant (numba kernel;
docs/photon-mapping.md, "Static views read the shutter's average").

* :func:`static_segments` -- per ray segment o -> hit: the hit lies on a static instance, the
  segment comes near no moving instance at any instant of the shutter, and (optionally) the path
  before it was such a chain too.

The regions of the moving instances (their boxes over the shutter and the capsules holding them at
every instant) come from ``integrator.static_view_setup``; the numpy form of the same test is the
oracle ``tests/oracles/static_view_numpy.py``.
"""
from __future__ import annotations

import numpy as np

from ..numba_probe import njit

__all__ = ["static_segments"]

_JIT = dict(cache=True, nogil=True, fastmath=False, error_model="numpy")


@njit(**_JIT)
def _segments_distance(px, py, pz, dx, dy, dz, qx, qy, qz, ex, ey, ez):
    """Distance between the segments p + s d and q + u e, s, u in [0, 1] (Ericson, Real-Time
    Collision Detection, 5.1.9: the closest points' parameters clamped to the segments)."""
    rx, ry, rz = px - qx, py - qy, pz - qz
    a = dx * dx + dy * dy + dz * dz
    e = ex * ex + ey * ey + ez * ez
    f = rx * ex + ry * ey + rz * ez
    c = dx * rx + dy * ry + dz * rz
    b = dx * ex + dy * ey + dz * ez
    den = a * e - b * b
    s = 0.0
    if den > 1e-30 * max(a * e, 1e-300):
        s = min(max((b * f - c * e) / den, 0.0), 1.0)
    if e > 0.0:
        u = (b * s + f) / e
        if u < 0.0:
            s = min(max(-c / max(a, 1e-300), 0.0), 1.0)
        elif u > 1.0:
            s = min(max((b - c) / max(a, 1e-300), 0.0), 1.0)
        # with s clamped, u follows again
        u = min(max((b * s + f) / e, 0.0), 1.0)
    else:
        u = 0.0
        s = min(max(-c / max(a, 1e-300), 0.0), 1.0)
    wx = px + s * dx - (qx + u * ex)
    wy = py + s * dy - (qy + u * ey)
    wz = pz + s * dz - (qz + u * ez)
    return np.sqrt(wx * wx + wy * wy + wz * wz)


@njit(**_JIT)
def static_segments(o, position, instance, chain, use_chain, static, lo, hi, ca, cb, cr, out):
    """out[i] = 1 where segment i, from o[i] (o (m, 3), or (1, 3): one origin for all) to its hit
    position[i] (m, 3) on instance[i] (m,) int32 (-1: a miss), is a static view: chain[i] != 0 (the
    path before the segment is one; only with use_chain), static[instance] (n_instances,) uint8 and
    the segment comes near no moving instance at any instant.  Near: it crosses one of the moving
    instances' boxes over the shutter (lo, hi (M, 3)) and comes within cr[j] of one of the capsules'
    axes ca[j] -> cb[j] (K, 3).  Returns how many rows are static views."""
    m = position.shape[0]
    n_box, n_cap = lo.shape[0], ca.shape[0]
    one = o.shape[0] == 1
    count = 0
    for i in range(m):
        out[i] = 0
        j = instance[i]
        if j < 0 or static[j] == 0 or (use_chain and chain[i] == 0):
            continue
        k = 0 if one else i
        ox, oy, oz = o[k, 0], o[k, 1], o[k, 2]
        sx, sy, sz = position[i, 0] - ox, position[i, 1] - oy, position[i, 2] - oz
        # -- the segment against each moving instance's box over the shutter (slabs) ---------------
        near = False
        for b in range(n_box):
            t0, t1 = -np.inf, np.inf
            for ax in range(3):
                sa = sx if ax == 0 else (sy if ax == 1 else sz)
                oa = ox if ax == 0 else (oy if ax == 1 else oz)
                inv = 1.0 / (1e-300 if sa == 0.0 else sa)       # axis-parallel: huge, never nan
                u0, u1 = (lo[b, ax] - oa) * inv, (hi[b, ax] - oa) * inv
                t0 = max(t0, min(u0, u1))
                t1 = min(t1, max(u0, u1))
            if t1 >= max(t0, 0.0) and t0 <= 1.0:
                near = True
                break
        # -- ... and, where it crosses one, against the capsules ----------------------------------
        if near:
            near = False
            for c in range(n_cap):
                if _segments_distance(ox, oy, oz, sx, sy, sz, ca[c, 0], ca[c, 1], ca[c, 2],
                                      cb[c, 0] - ca[c, 0], cb[c, 1] - ca[c, 1], cb[c, 2] - ca[c, 2]) <= cr[c]:
                    near = True
                    break
        if not near:
            out[i] = 1
            count += 1
    return count
