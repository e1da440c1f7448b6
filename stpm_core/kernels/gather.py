"""Final gathering of the global photon map (numba kernels; docs/photon-mapping.md, "Final gathering").

At the camera's first diffuse vertex x (every vertex where the photon maps are read) the Indirect
pass is ``rho_d(x) / G * sum_j L_g(y_j)`` over G gather rays cosine-sampled about x's shading
normal (pdf cos / pi, so f_d |cos| / pdf = rho_d).  At a gather hit y the ray reads ONE
precomputed irradiance (Christensen 1999): the nearest cache point in space-time on the same
instance with a normal within ``GATHER_NORMAL_COS``, and adds ``rho_d(y) / pi * E(y)``
(``paths.photon_add``); through y's delta and rough lobes it goes on (``paths.specular_step``).

* :func:`gather_rays` -- the G rays of each queried vertex (origin, direction, time, parent
  sample, weight);
* :func:`cache_tree`, :func:`cache_lookup` -- the nearest cache point per gather hit (a balanced
  kd-tree over the cache points in (x, y, z, s t), searched nearer child first within a bound).

The cache itself (points, normals, instances, times, irradiance) is built by
:mod:`stpm_core.photons.gather`.
"""
from __future__ import annotations

import numpy as np

from ..numba_probe import njit
from .sampling import cosine_hemisphere, offset_origin, to_world

__all__ = ["gather_rays", "cache_tree", "tree_size", "cache_lookup", "LEAF"]

_JIT = dict(cache=True, nogil=True, fastmath=False, error_model="numpy")


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


LEAF = 8                                # cache points per kd-tree leaf (at most)


@njit(**_JIT)
def cache_tree(X, T, s, perm, axis, split):
    """Build a balanced kd-tree over the N cache points in (x, y, z, s t); returns the node count.

    perm (N,) is reordered so node v's points are perm[lo_v:hi_v] (the root holds all; a node's
    two children its two halves around mid = (lo + hi) // 2, in heap order 2 v + 1, 2 v + 2);
    axis (M,) int64 and split (M,) the split axis and coordinate of each inner node (axis -1: a
    leaf of at most LEAF points).  M = 2^(depth + 1) - 1 with 2^depth leaves (the caller sizes them
    with :func:`tree_size`).  Each split sorts the node's points along its widest axis.
    """
    N = perm.shape[0]
    M = axis.shape[0]
    stack_v = np.empty(128, np.int64)
    stack_lo = np.empty(128, np.int64)
    stack_hi = np.empty(128, np.int64)
    top = 0
    stack_v[0], stack_lo[0], stack_hi[0] = 0, 0, N
    top = 1
    while top > 0:
        top -= 1
        v, lo, hi = stack_v[top], stack_lo[top], stack_hi[top]
        if hi - lo <= LEAF or 2 * v + 2 >= M:
            axis[v] = -1
            continue
        # the widest axis of the node's points
        best_a, best_w = 0, -1.0
        for a in range(4):
            mn, mx = np.inf, -np.inf
            for q in range(lo, hi):
                i = perm[q]
                c = s * T[i] if a == 3 else X[i, a]      # coordinate a in (x, y, z, s t)
                mn = min(mn, c)
                mx = max(mx, c)
            if mx - mn > best_w:
                best_a, best_w = a, mx - mn
        key = np.empty(hi - lo)
        for q in range(lo, hi):
            i = perm[q]
            key[q - lo] = s * T[i] if best_a == 3 else X[i, best_a]
        order = np.argsort(key, kind="mergesort")
        seg = perm[lo:hi].copy()
        for q in range(hi - lo):
            perm[lo + q] = seg[order[q]]
        mid = (lo + hi) // 2
        axis[v] = best_a
        split[v] = key[order[mid - lo]]
        stack_v[top], stack_lo[top], stack_hi[top] = 2 * v + 1, lo, mid
        stack_v[top + 1], stack_lo[top + 1], stack_hi[top + 1] = 2 * v + 2, mid, hi
        top += 2
    return M


@njit(**_JIT)
def tree_size(N):
    """Nodes M of :func:`cache_tree`'s heap for N points: leaves of at most LEAF points."""
    leaves = 1
    while leaves * LEAF < N:
        leaves *= 2
    return 2 * leaves - 1


@njit(**_JIT)
def cache_lookup(rows, live, P, NG, D, T, inst, perm, axis, split, cpos, ctime, cnorm, cinst, cE, s, cos_min,
                 r2_max, out):
    """Irradiance (n, 3) W/m^2 of the nearest cache point of each gather hit, into out; returns misses.

    Query j is hit row r = rows[live[j]]: point P[r], geometric normal NG[r] turned toward the
    arriving ray (against D[r]), time T[r], instance inst[r].  Candidates: cache points with the
    same instance and a normal cnorm (N, 3) whose cosine with it is at least cos_min; the nearest
    in space-time, distance^2 = |x - x_c|^2 + (s (t - t_c))^2 (s: KD4D's time scale, scene units
    per shutter), searched on the kd-tree (perm, axis, split) of :func:`cache_tree` nearer child
    first, a far child only while its splitting plane is nearer than the best so far.  out[j] =
    cE (N, 3) of that point, 0 where none lies within distance^2 r2_max.
    """
    misses = 0
    N = perm.shape[0]
    M = axis.shape[0]
    stack_v = np.empty(256, np.int64)
    stack_d = np.empty(256)
    stack_lo = np.empty(256, np.int64)
    stack_hi = np.empty(256, np.int64)
    q = np.empty(4)
    for j in range(live.shape[0]):
        r = rows[live[j]]
        q[0], q[1], q[2], q[3] = P[r, 0], P[r, 1], P[r, 2], s * T[r]
        g0, g1, g2 = NG[r, 0], NG[r, 1], NG[r, 2]
        if g0 * D[r, 0] + g1 * D[r, 1] + g2 * D[r, 2] > 0.0:
            g0, g1, g2 = -g0, -g1, -g2
        iq = inst[r]
        best = r2_max
        bi = -1
        stack_v[0], stack_d[0], stack_lo[0], stack_hi[0] = 0, 0.0, 0, N
        top = 1
        while top > 0:
            top -= 1
            if stack_d[top] >= best:
                continue
            v, lo, hi = stack_v[top], stack_lo[top], stack_hi[top]
            while v < M and axis[v] >= 0:
                # descend toward q, keep the far side for later
                mid = (lo + hi) // 2
                dlt = q[axis[v]] - split[v]
                if dlt < 0.0:
                    near, nlo, nhi, far, flo, fhi = 2 * v + 1, lo, mid, 2 * v + 2, mid, hi
                else:
                    near, nlo, nhi, far, flo, fhi = 2 * v + 2, mid, hi, 2 * v + 1, lo, mid
                if dlt * dlt < best and top < 256:
                    stack_v[top], stack_d[top], stack_lo[top], stack_hi[top] = far, dlt * dlt, flo, fhi
                    top += 1
                v, lo, hi = near, nlo, nhi
            for k in range(lo, hi):
                c = perm[k]
                if cinst[c] != iq:
                    continue
                if cnorm[c, 0] * g0 + cnorm[c, 1] * g1 + cnorm[c, 2] * g2 < cos_min:
                    continue
                e0, e1, e2 = cpos[c, 0] - q[0], cpos[c, 1] - q[1], cpos[c, 2] - q[2]
                et = s * ctime[c] - q[3]
                d2 = e0 * e0 + e1 * e1 + e2 * e2 + et * et
                if d2 < best:
                    best = d2
                    bi = c
        if bi < 0:
            out[j, 0], out[j, 1], out[j, 2] = 0.0, 0.0, 0.0
            misses += 1
        else:
            out[j, 0], out[j, 1], out[j, 2] = cE[bi, 0], cE[bi, 1], cE[bi, 2]
    return misses
