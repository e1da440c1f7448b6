"""Final gathering of the global photon map (numba kernels; docs/photon-mapping.md, "Final gathering").

At the camera's first diffuse vertex x (every vertex where the photon maps are read) the Indirect
pass is ``rho_d(x) / G * sum_j L_g(y_j)`` over G gather rays cosine-sampled about x's shading
normal (pdf cos / pi, so f_d |cos| / pdf = rho_d).  At a gather hit y the ray reads ONE
precomputed irradiance (Christensen 1999): the nearest cache point in space-time on the same
instance with a normal within ``GATHER_NORMAL_COS``, and adds ``rho_d(y) / pi * E(y)``
(``paths.photon_add``); through y's delta and rough lobes it goes on (``paths.specular_step``).

* :func:`gather_rays` -- the G rays of each queried vertex (origin, direction, time, parent
  sample, weight);
* :func:`cache_lookup` -- the nearest cache point per gather hit (a uniform grid over the cache
  points, cells searched ring by ring until no nearer point can remain).

The cache itself (points, normals, instances, times, irradiance) is built by
:mod:`stpm_core.photons.gather`.
"""
from __future__ import annotations

import numpy as np

from ..numba_probe import njit
from .sampling import cosine_hemisphere, offset_origin, to_world

__all__ = ["gather_rays", "cache_lookup", "GRID_BITS"]

_JIT = dict(cache=True, nogil=True, fastmath=False, error_model="numpy")

GRID_BITS = 21                          # bits per axis of a cell key (cells 0 .. 2^21 - 1)


@njit(**_JIT)
def gather_rays(rows, live, P, NG, rho, n_q, t_q, idx, use_idx, beta, use_beta, G, U, EPS, guard_fraction,
                o, d, t, parent, w, guard):
    """The G gather rays of each queried row; returns how many were made.

    Query j (of n = live.shape[0]) is hit row r = rows[live[j]] of P, NG (m, 3), with diffuse
    albedo rho[live[j]] (k, 3) and the shading normal n_q[j] (n, 3) turned toward the camera ray
    (``paths.photon_albedo``), time t_q[j]; its sample is idx[r] (r when not use_idx), its
    throughput beta[r] (1 when not use_beta).  Ray s of query j uses U[j G + s] (n G, 2): its
    first uniform stratified as (s + U0) / G, then ``cosine_hemisphere`` about n_q[j].  Directions
    below the geometric surface (on the other side of NG turned to n_q) are dropped (their
    radiance would come through the surface).  Out, per ray: origin o offset by EPS[j] (scene
    units) along NG, direction d, time t, the sample parent, weight w = beta * rho / G (3,) and
    the self-intersection guard guard_fraction * EPS[j].
    """
    n_go = 0
    inv_g = 1.0 / G
    for j in range(live.shape[0]):
        k = live[j]
        r = rows[k]
        i = idx[r] if use_idx else r
        ns = (n_q[j, 0], n_q[j, 1], n_q[j, 2])
        g = (NG[r, 0], NG[r, 1], NG[r, 2])
        if g[0] * ns[0] + g[1] * ns[1] + g[2] * ns[2] < 0.0:
            g = (-g[0], -g[1], -g[2])
        if use_beta:
            b0, b1, b2 = beta[r, 0], beta[r, 1], beta[r, 2]
        else:
            b0, b1, b2 = 1.0, 1.0, 1.0
        w0, w1, w2 = b0 * rho[k, 0] * inv_g, b1 * rho[k, 1] * inv_g, b2 * rho[k, 2] * inv_g
        e = EPS[j]
        for s in range(G):
            u0 = (s + U[j * G + s, 0]) * inv_g
            wi = to_world(cosine_hemisphere(u0, U[j * G + s, 1]), ns)
            if wi[0] * g[0] + wi[1] * g[1] + wi[2] * g[2] <= 0.0:
                continue
            o[n_go, 0], o[n_go, 1], o[n_go, 2] = offset_origin((P[r, 0], P[r, 1], P[r, 2]), g, e, wi)
            d[n_go, 0], d[n_go, 1], d[n_go, 2] = wi[0], wi[1], wi[2]
            t[n_go] = t_q[j]
            parent[n_go] = i
            w[n_go, 0], w[n_go, 1], w[n_go, 2] = w0, w1, w2
            guard[n_go] = guard_fraction * e
            n_go += 1
    return n_go


@njit(**_JIT)
def _cell(x, lo, h):
    """Cell index of coordinate x on an axis starting at lo with cells of side h (clipped to the key's range)."""
    c = int(np.floor((x - lo) / h))
    return min(max(c, 0), (1 << GRID_BITS) - 1)


@njit(**_JIT)
def cache_lookup(rows, live, P, NG, D, T, inst, cells, starts, cpos, ctime, cnorm, cinst, cE, lo, h, s, cos_min,
                 max_ring, out):
    """Irradiance (n, 3) W/m^2 of the nearest cache point of each gather hit, into out; returns misses.

    Query j is hit row r = rows[live[j]]: point P[r], geometric normal NG[r] turned toward the
    arriving ray (against D[r]), time T[r], instance inst[r].  Candidates: cache points with the
    same instance and a normal cnorm (N, 3) whose cosine with it is at least cos_min; the nearest
    in space-time, distance^2 = |x - x_c|^2 + (s (t - t_c))^2 (s: KD4D's time scale, scene units
    per shutter).  out[j] = cE (N, 3) of that point, 0 where none lies within max_ring cells.

    The grid: cells of side h from lo (3,); cells (C,) int64 the sorted keys of the occupied
    cells (x | y << 21 | z << 42), starts (C + 1,) the first row of each in cpos / ctime / cnorm /
    cinst / cE (the cache points sorted by cell).  Rings of cells at Chebyshev distance R = 0, 1,
    ... around the query's cell are searched in turn; after ring R every point not yet seen lies
    at least R h away in space, so the search stops once the best distance^2 is <= (R h)^2.
    """
    misses = 0
    nb = 1 << GRID_BITS
    for j in range(live.shape[0]):
        r = rows[live[j]]
        p0, p1, p2 = P[r, 0], P[r, 1], P[r, 2]
        g0, g1, g2 = NG[r, 0], NG[r, 1], NG[r, 2]
        if g0 * D[r, 0] + g1 * D[r, 1] + g2 * D[r, 2] > 0.0:
            g0, g1, g2 = -g0, -g1, -g2
        tq = T[r]
        iq = inst[r]
        cx, cy, cz = _cell(p0, lo[0], h), _cell(p1, lo[1], h), _cell(p2, lo[2], h)
        best = np.inf
        bi = -1
        for R in range(max_ring + 1):
            for dz in range(-R, R + 1):
                z = cz + dz
                if z < 0 or z >= nb:
                    continue
                for dy in range(-R, R + 1):
                    y = cy + dy
                    if y < 0 or y >= nb:
                        continue
                    inner = abs(dz) < R and abs(dy) < R
                    dx = -R
                    while dx <= R:
                        x = cx + dx
                        if x >= 0 and x < nb:
                            key = np.int64(x) | (np.int64(y) << GRID_BITS) | (np.int64(z) << (2 * GRID_BITS))
                            c = np.searchsorted(cells, key)
                            if c < cells.shape[0] and cells[c] == key:
                                for q in range(starts[c], starts[c + 1]):
                                    if cinst[q] != iq:
                                        continue
                                    if cnorm[q, 0] * g0 + cnorm[q, 1] * g1 + cnorm[q, 2] * g2 < cos_min:
                                        continue
                                    e0, e1, e2 = cpos[q, 0] - p0, cpos[q, 1] - p1, cpos[q, 2] - p2
                                    et = s * (ctime[q] - tq)
                                    d2 = e0 * e0 + e1 * e1 + e2 * e2 + et * et
                                    if d2 < best:
                                        best = d2
                                        bi = q
                        # inside the shell only its two faces along x are new
                        dx = dx + (2 * R if (inner and dx == -R and R > 0) else 1)
            if bi >= 0 and best <= (R * h) * (R * h):
                break
        if bi < 0:
            out[j, 0], out[j, 1], out[j, 2] = 0.0, 0.0, 0.0
            misses += 1
        else:
            out[j, 0], out[j, 1], out[j, 2] = cE[bi, 0], cE[bi, 1], cE[bi, 2]
    return misses
