"""numba kernels fusing the numpy work around embree's ``run()`` (embree backend).

Each kernel does in one pass per ray what :mod:`.embree_backend` otherwise
does with a dozen whole-array numpy operations (temporaries, gathers), with
the same float64 operations in the same order, so results agree with the
numpy path to rounding (tests/test_raycast.py compares them):

* :func:`rays32` - re-centred float32 rays for ``run()``
  (``EmbreeMesh._rays32``); :func:`guard_rays32` - the same with the
  self-intersection guard (``tmin_of``) computed in the same pass (the
  caster's first, static part);
* :func:`static_finish` - after embree's closest-hit call on the baked
  static scene: float64 plane refinement of t, guard / tmax test, and every
  :class:`~stpm_core.raycast.Hits` field (instance, prim, material, ng, the
  corner-normal blend ns, position) written straight into the caster's
  result arrays - misses too (``init``), so the caster pre-fills nothing;
* :func:`rigid_pairs` - moving rigid instances of one mesh: box tests
  of each ray against the group box and each instance's box for the ray's
  time slice (or whole swept boxes), and for every (ray, instance) pair met,
  the inverse transform at the ray's time (:class:`.geometry.MotionKeys`:
  lerp, slerp, stretch inverse) applied to the ray, written as float64
  object-space rays and float32 embree rays, in chunks that fit the caller's
  buffers; many instances are found through a BVH of their boxes;
* :func:`rigid_shade` / :func:`rigid_shade_rows` - normals and material of
  moving hits at their times (the latter straight into the result rows);
* :func:`group_finish` - after embree's call on a group's pairs: refinement,
  nearest pair per ray and the won fields written into the caster's arrays;
* :func:`finish_hits` - the caster's epilogue (miss t, moving hits' positions).

Kernels are serial (``cache=True``): embree's ``run()`` is single-threaded
and the caster works in 8192-ray chunks; ``nogil=True``, so tracer threads
casting at once run them in parallel.  Importing this module fails where
numba is missing; the embree backend then keeps its numpy path.
"""
from __future__ import annotations

import os

# Same policy as the numba backend: OpenMP workers (if numba ever starts them) sleep
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import numpy as np  # noqa: E402
from numba import njit  # noqa: E402

__all__ = ["rays32", "guard_rays32", "occluded_of", "static_finish", "rigid_pairs",
           "rigid_shade", "rigid_shade_rows", "group_finish", "finish_hits", "refine_plane", "slerp_table", "warm_up"]

FAR32 = float(np.float32(1e37))     # embree's "no tfar" value, as float64
_HUGE = 1e300                       # stands in for 1/0 in the slab test (0 * _HUGE = 0, no NaN)


# ---------------------------------------------------------------- embree input
@njit(cache=True, nogil=True, error_model="numpy")
def rays32(o, d, start, t1, centre, o32, d32, far32):
    """Rays o, d (m, 3) float64 shifted to start (m,) and the mesh centre (3,) -> o32, d32 (m, 3), far32 (m,)."""
    for i in range(o.shape[0]):
        s = start[i]
        for c in range(3):
            o32[i, c] = np.float32((s * d[i, c] + o[i, c]) - centre[c])
            d32[i, c] = np.float32(d[i, c])
        far = max(t1[i] - s, 0.0)
        far32[i] = np.float32(min(far, FAR32))


@njit(cache=True, nogil=True, error_model="numpy")
def _plane_t(plane_n, plane_w, p, o, d, i, fallback):
    """Float64 t of ray i of o, d (m, 3) on triangle p's plane n . x = w; ``fallback`` (embree's
    own t) where the plane test is undefined (ray parallel to the plane)."""
    n0, n1, n2 = plane_n[p, 0], plane_n[p, 1], plane_n[p, 2]
    t = (plane_w[p] - (n0 * o[i, 0] + n1 * o[i, 1] + n2 * o[i, 2])) / (n0 * d[i, 0] + n1 * d[i, 1] + n2 * d[i, 2])
    return t if np.isfinite(t) else fallback


@njit(cache=True, nogil=True, error_model="numpy")
def refine_plane(o, d, p, start, tfar, plane_n, plane_w, tt):
    """Float64 t (m,) into tt of rays o, d on the planes of triangles p (m,) (p < 0: left alone).

    Where the plane test is undefined (ray parallel to the plane) embree's own
    ``start + tfar`` stands.
    """
    for i in range(o.shape[0]):
        q = p[i]
        if q < 0:
            continue
        tt[i] = _plane_t(plane_n, plane_w, q, o, d, i, start[i] + np.float64(tfar[i]))


# ---------------------------------------------------------------- static part
@njit(cache=True, nogil=True, error_model="numpy")
def guard_rays32(o, d, tmax, has_tmax, guard, centre, tmin, o32, d32, far32):
    """Guard and embree rays in one pass (``tmin_of`` + :func:`rays32` from tmin).

    o, d (m, 3) float64 world rays; tmax (m,) (read only if ``has_tmax``,
    else +inf); guard (1,) or (m,) distances: one for every ray (TMIN_REL *
    scale) or each ray's own.  Writes tmin (m,) = guard / |d|
    (|d| = 0 or NaN: guard), and the float32 rays o32, d32 (m, 3), far32 (m,)
    starting at tmin, shifted to the mesh centre (3,) - the same float64
    operations as ``tmin_of`` then ``rays32``.
    """
    for i in range(o.shape[0]):
        d0, d1, d2 = d[i, 0], d[i, 1], d[i, 2]
        L = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        s = (guard[i] if guard.shape[0] > 1 else guard[0]) / (L if L > 0 else 1.0)
        tmin[i] = s
        for c in range(3):
            o32[i, c] = np.float32((s * d[i, c] + o[i, c]) - centre[c])
            d32[i, c] = np.float32(d[i, c])
        t1 = tmax[i] if has_tmax else np.inf
        far = max(t1 - s, 0.0)
        far32[i] = np.float32(min(far, FAR32))


@njit(cache=True, nogil=True, error_model="numpy")
def occluded_of(geom, blocked):
    """blocked (m,) bool = embree's OCCLUDED answer geom (m,) != -1."""
    for i in range(geom.shape[0]):
        blocked[i] = geom[i] != -1


@njit(cache=True, nogil=True, error_model="numpy")
def static_finish(o, d, start, tfar, primID, u32, v32, t0, plane_n, plane_w, ids, ng_tab, nsc, smooth, k,
                  best_t, best_part, prim, u_out, v_out, inst_out, p_out, mat_out, ng_out, ns_out, pos_out,
                  again, init, final, tmax, has_tmax):
    """Refine embree's closest hits on the baked static scene and write the won ones.

    Inputs per ray (m,): o, d (m, 3) world rays, start = guard t0 (the cast
    started there), embree's tfar, primID, u32, v32.  Tables per baked
    triangle: plane_n (F, 3), plane_w (F,), ids (F, 3) int32 (instance,
    mesh-local prim, material), ng_tab (F, 3), nsc (F, 3, 3) float32 corner
    normals (used when ``smooth``).  A ray whose refined t lies in
    (t0, best_t) overwrites best_t, best_part (= k), prim, u, v, instance,
    mesh prim, material, ng, ns, position.  Rays whose refined t is inside the
    guard (t <= t0) are listed in ``again`` for a re-cast; returns their count.

    init : the output arrays are uninitialised (first part of the caster):
        best_t starts as tmax (m,) (+inf unless ``has_tmax``) and every ray
        that does not win gets the miss values (best_part, prim, instance,
        mesh prim, material -1; u, v, ng, ns 0; position NaN).
    final : no part follows: rays that do not win get t = +inf at once (rays
        listed in ``again`` keep best_t = tmax for their re-cast).
    """
    n_again = 0
    for i in range(o.shape[0]):
        if init:
            t1 = tmax[i] if has_tmax else np.inf
        else:
            t1 = best_t[i]
        q = primID[i]
        won = False
        recast = False
        t = 0.0
        if q >= 0:
            # Float64 t on the triangle's plane (embree's where undefined)
            t = _plane_t(plane_n, plane_w, q, o, d, i, start[i] + np.float64(tfar[i]))
            if t <= t0[i]:
                again[n_again] = i
                n_again += 1
                recast = True
            elif t < t1:
                won = True
        if not won:
            if init:
                # Miss values (a re-cast may still overwrite them)
                best_t[i] = np.inf if (final and not recast) else t1
                best_part[i] = -1
                prim[i] = -1
                u_out[i] = 0.0
                v_out[i] = 0.0
                inst_out[i] = -1
                p_out[i] = -1
                mat_out[i] = -1
                for c in range(3):
                    ng_out[i, c] = 0.0
                    ns_out[i, c] = 0.0
                    pos_out[i, c] = np.nan
            continue
        # Hit fields
        u = np.float64(u32[i])
        v = np.float64(v32[i])
        best_t[i] = t
        best_part[i] = k
        prim[i] = q
        u_out[i] = u
        v_out[i] = v
        inst_out[i] = ids[q, 0]
        p_out[i] = ids[q, 1]
        mat_out[i] = ids[q, 2]
        for c in range(3):
            ng_out[i, c] = ng_tab[q, c]
            pos_out[i, c] = o[i, c] + t * d[i, c]
        if not smooth:
            for c in range(3):
                ns_out[i, c] = ng_tab[q, c]
            continue
        # Shading normal: float32 barycentric blend of the corner normals, float64 normalise
        w0, w1, w2 = np.float32(1 - u - v), np.float32(u), np.float32(v)
        s0 = np.float64(w0 * nsc[q, 0, 0] + w1 * nsc[q, 1, 0] + w2 * nsc[q, 2, 0])
        s1 = np.float64(w0 * nsc[q, 0, 1] + w1 * nsc[q, 1, 1] + w2 * nsc[q, 2, 1])
        s2 = np.float64(w0 * nsc[q, 0, 2] + w1 * nsc[q, 1, 2] + w2 * nsc[q, 2, 2])
        L = np.sqrt(s0 * s0 + s1 * s1 + s2 * s2)
        if L == 0:
            for c in range(3):
                ns_out[i, c] = ng_tab[q, c]
        else:
            ns_out[i, 0], ns_out[i, 1], ns_out[i, 2] = s0 / L, s1 / L, s2 / L
    return n_again


# ---------------------------------------------------------------- moving instances
@njit(cache=True, nogil=True, error_model="numpy")
def _inv(x):
    return 1.0 / x if abs(x) > 1e-290 else _HUGE


@njit(cache=True, nogil=True, error_model="numpy")
def _meets(lo, hi, ox, oy, oz, ix, iy, iz, t0, t1):
    """Does segment [t0, t1] of the ray meet box lo, hi (3,)?  Conservative (slab test)."""
    near, far = t0, t1
    ta, tb = (lo[0] - ox) * ix, (hi[0] - ox) * ix
    near, far = max(near, min(ta, tb)), min(far, max(ta, tb))
    ta, tb = (lo[1] - oy) * iy, (hi[1] - oy) * iy
    near, far = max(near, min(ta, tb)), min(far, max(ta, tb))
    ta, tb = (lo[2] - oz) * iz, (hi[2] - oz) * iz
    near, far = max(near, min(ta, tb)), min(far, max(ta, tb))
    return near <= far


@njit(cache=True, nogil=True, error_model="numpy")
def slerp_table(Q, first, last, arc):
    """Per key i (K,): the arc to the next key of its transform -> arc (K, 3) = theta, sin theta, sign.

    Q (K, 4) unit quaternions (w, x, y, z); first, last (J,) key ranges.
    The slerp's arccos depends only on the key pair, so it is evaluated once
    here rather than per ray.
    """
    for j in range(first.shape[0]):
        for i in range(first[j], last[j] + 1):
            i1 = min(i + 1, last[j])
            cos_theta = Q[i, 0] * Q[i1, 0] + Q[i, 1] * Q[i1, 1] + Q[i, 2] * Q[i1, 2] + Q[i, 3] * Q[i1, 3]
            theta = np.arccos(min(abs(cos_theta), 1.0))
            arc[i, 0] = theta
            arc[i, 1] = np.sin(theta)
            arc[i, 2] = -1.0 if cos_theta < 0 else 1.0


@njit(cache=True, nogil=True, error_model="numpy")
def _world_to_object(T, Q, S, arc, knots, f, l, time, A, b):
    """A (3, 3), b (3,) of the transform with keys f..l at ``time`` (as MotionKeys.world_to_object).

    arc : (K, 3) from :func:`slerp_table`.
    """
    # Key pair and fraction
    tq = min(max(time, knots[f]), knots[l])
    i = f
    while i + 1 <= l and knots[i + 1] <= tq:
        i += 1
    i = min(i, max(l - 1, f))
    i1 = min(i + 1, l)
    span = knots[i1] - knots[i]
    a = (time - knots[i]) / span if span > 0 else 0.0
    a = min(max(a, 0.0), 1.0)
    # Rotation: slerp along the shorter arc
    theta, sin_theta, sign = arc[i, 0], arc[i, 1], arc[i, 2]
    if sin_theta < 1e-6:
        w0, w1 = 1 - a, a * sign
    else:
        w0, w1 = np.sin((1 - a) * theta) / sin_theta, np.sin(a * theta) / sin_theta * sign
    w = w0 * Q[i, 0] + w1 * Q[i1, 0]
    x = w0 * Q[i, 1] + w1 * Q[i1, 1]
    y = w0 * Q[i, 2] + w1 * Q[i1, 2]
    z = w0 * Q[i, 3] + w1 * Q[i1, 3]
    norm = 1.0 / np.sqrt(w * w + x * x + y * y + z * z)
    w, x, y, z = w * norm, x * norm, y * norm, z * norm
    # R^T
    r00, r01, r02 = 1 - 2 * (y * y + z * z), 2 * (x * y + w * z), 2 * (x * z - w * y)
    r10, r11, r12 = 2 * (x * y - w * z), 1 - 2 * (x * x + z * z), 2 * (y * z + w * x)
    r20, r21, r22 = 2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y)
    # Stretch: lerp, inverse by cofactors
    s00 = S[i, 0, 0] + a * (S[i1, 0, 0] - S[i, 0, 0])
    s01 = S[i, 0, 1] + a * (S[i1, 0, 1] - S[i, 0, 1])
    s02 = S[i, 0, 2] + a * (S[i1, 0, 2] - S[i, 0, 2])
    s11 = S[i, 1, 1] + a * (S[i1, 1, 1] - S[i, 1, 1])
    s12 = S[i, 1, 2] + a * (S[i1, 1, 2] - S[i, 1, 2])
    s22 = S[i, 2, 2] + a * (S[i1, 2, 2] - S[i, 2, 2])
    c00, c01, c02 = s11 * s22 - s12 * s12, s02 * s12 - s01 * s22, s01 * s12 - s02 * s11
    c11, c12, c22 = s00 * s22 - s02 * s02, s01 * s02 - s00 * s12, s00 * s11 - s01 * s01
    inv_det = 1.0 / (s00 * c00 + s01 * c01 + s02 * c02)
    i00, i01, i02 = c00 * inv_det, c01 * inv_det, c02 * inv_det
    i11, i12, i22 = c11 * inv_det, c12 * inv_det, c22 * inv_det
    # A = S^-1 R^T, b = -A T
    A[0, 0] = i00 * r00 + i01 * r10 + i02 * r20
    A[0, 1] = i00 * r01 + i01 * r11 + i02 * r21
    A[0, 2] = i00 * r02 + i01 * r12 + i02 * r22
    A[1, 0] = i01 * r00 + i11 * r10 + i12 * r20
    A[1, 1] = i01 * r01 + i11 * r11 + i12 * r21
    A[1, 2] = i01 * r02 + i11 * r12 + i12 * r22
    A[2, 0] = i02 * r00 + i12 * r10 + i22 * r20
    A[2, 1] = i02 * r01 + i12 * r11 + i22 * r21
    A[2, 2] = i02 * r02 + i12 * r12 + i22 * r22
    T0 = T[i, 0] + a * (T[i1, 0] - T[i, 0])
    T1 = T[i, 1] + a * (T[i1, 1] - T[i, 1])
    T2 = T[i, 2] + a * (T[i1, 2] - T[i, 2])
    for r in range(3):
        b[r] = -(A[r, 0] * T0 + A[r, 1] * T1 + A[r, 2] * T2)


@njit(cache=True, nogil=True, error_model="numpy")
def _emit_pair(i, j, tr, ox, oy, oz, dx, dy, dz, s, e, T, Q, S, arc, knots, first, last, centre, full, A, b,
               n, ray, inst, o64, d64, o32, d32, far32):
    """Write pair n: ray i mapped to instance j's object space at its time tr (directions not renormalised)."""
    _world_to_object(T, Q, S, arc, knots, first[j], last[j], tr, A, b)
    for r in range(3):
        oo = A[r, 0] * ox + A[r, 1] * oy + A[r, 2] * oz + b[r]
        dd = A[r, 0] * dx + A[r, 1] * dy + A[r, 2] * dz
        if full:
            o64[n, r] = oo
            d64[n, r] = dd
        o32[n, r] = np.float32((s * dd + oo) - centre[r])
        d32[n, r] = np.float32(dd)
    far32[n] = np.float32(min(max(e - s, 0.0), FAR32))
    ray[n] = i
    inst[n] = j


@njit(cache=True, nogil=True, error_model="numpy")
def rigid_pairs(o, d, times, t0, t1, skip, start, node_lo, node_hi, level_off, leaf, order, lo, hi, slice_lo,
                slice_hi, T, Q, S, arc, knots, first, last, centre, ray, inst, o64, d64, o32, d32, far32):
    """(ray, instance) pairs of moving instances of one mesh, mapped to object space.

    o, d (m, 3), times, t0, t1 (m,) world rays, from ray ``start`` on; ``skip``
    (m,) bool rays to ignore (already blocked).  Instances are found through a
    BVH of their swept boxes, :class:`.pair_bvh.PairBVH`'s flattened: level l's
    nodes are rows level_off[l] .. level_off[l + 1] of node_lo, node_hi (N, 3);
    node j of level l has children 2j, 2j + 1 on level l + 1; leaf j (last
    level) holds instances order[j * leaf .. j * leaf + leaf - 1] (those < J).
    A small group passes a one-node "BVH" (its swept box, one leaf of all J
    instances): the group box test, then every instance.  Walked depth first
    with an explicit stack.  At a leaf, lo, hi (J, 3) each instance's swept
    box, or for a ray whose time lies in [0, 1] its box over that time slice,
    slice_lo, slice_hi (J, L, 3) (slice l = [l / L, (l + 1) / L]; L = 0: none;
    the slice box is much smaller for fast motion, so fewer pairs are
    transformed and cast), decides.  T, Q, S, knots, first, last: the stacked
    keys of :class:`.geometry.MotionKeys`, arc their :func:`slerp_table`;
    centre (3,) the object-space embree scene's centre.  For each pair k
    written: ray[k], inst[k] (index j), object-space o64, d64 (k, 3) float64
    (if o64 has rows) and the float32 embree rays o32, d32, far32 starting at t0.

    Returns (pairs written, next ray): the pair buffers (capacity C >= J) are
    never overrun -- the kernel stops before a ray that might not fit, and the
    caller calls again from ``next ray`` (< m) after using the pairs.
    """
    A = np.empty((3, 3))
    b = np.empty(3)
    n = 0
    full = o64.shape[0] > 0
    J = lo.shape[0]
    L = slice_lo.shape[1]
    cap = ray.shape[0]
    n_levels = level_off.shape[0] - 1
    stack_l = np.empty(2 * n_levels + 2, np.int64)
    stack_j = np.empty(2 * n_levels + 2, np.int64)
    for i in range(start, o.shape[0]):
        if skip[i]:
            continue
        if n + J > cap:
            return n, i
        ox, oy, oz = o[i, 0], o[i, 1], o[i, 2]
        dx, dy, dz = d[i, 0], d[i, 1], d[i, 2]
        ix, iy, iz = _inv(dx), _inv(dy), _inv(dz)
        s, e = t0[i], t1[i]
        tr = times[i]
        sl = -1
        if L > 0 and tr >= 0.0 and tr <= 1.0:
            sl = min(int(tr * L), L - 1)
        top = 0
        stack_l[0] = 0
        stack_j[0] = 0
        top = 1
        while top > 0:
            top -= 1
            lv = stack_l[top]
            nj = stack_j[top]
            row = level_off[lv] + nj
            if not _meets(node_lo[row], node_hi[row], ox, oy, oz, ix, iy, iz, s, e):
                continue
            if lv < n_levels - 1:
                count = level_off[lv + 2] - level_off[lv + 1]
                for c in range(1, -1, -1):
                    child = 2 * nj + c
                    if child < count:
                        stack_l[top] = lv + 1
                        stack_j[top] = child
                        top += 1
                continue
            for q in range(leaf):
                slot = nj * leaf + q
                if slot >= J:
                    break
                j = order[slot]
                if sl >= 0:
                    if not _meets(slice_lo[j, sl], slice_hi[j, sl], ox, oy, oz, ix, iy, iz, s, e):
                        continue
                elif not _meets(lo[j], hi[j], ox, oy, oz, ix, iy, iz, s, e):
                    continue
                _emit_pair(i, j, tr, ox, oy, oz, dx, dy, dz, s, e, T, Q, S, arc, knots, first, last, centre, full,
                           A, b, n, ray, inst, o64, d64, o32, d32, far32)
                n += 1
    return n, o.shape[0]


@njit(cache=True, nogil=True, error_model="numpy")
def group_finish(o64, d64, ray, inst, t0, t1, tfar, primID, u32, v32, plane_n, plane_w, n_tri, k, t_blk, p_blk,
                 u_blk, v_blk, best_t, best_part, prim, u_out, v_out):
    """After embree's call on a group's (ray, instance) pairs: refine, keep each ray's nearest pair, write the won.

    Per pair (P,): o64, d64 (P, 3) object-space rays, ray, inst, embree's tfar, primID, u32, v32
    (the cast started at t0[ray]).  Per ray (m,): t0, t1 (= best_t before the call; not changed
    until every pair is done) and scratch t_blk, p_blk, u_blk, v_blk.  t is refined on the
    triangle's float64 plane (as :func:`refine_plane`); a pair with t0 < t < t1 is a candidate, a
    ray keeps its nearest candidate (the last of equal ones, as ``EmbreeMesh.cast`` then the
    group's ``np.minimum.at`` merge), and where that beats best_t, best_t, best_part (= k), prim
    (= inst * n_tri + triangle), u, v are written.  Returns False, having written nothing, if any
    refined t lies inside the guard (t <= t0): the caller re-casts that block on the numpy path.
    """
    m = t0.shape[0]
    for i in range(m):
        t_blk[i] = np.inf
    for q in range(ray.shape[0]):
        p = primID[q]
        if p < 0:
            continue
        i = ray[q]
        t = _plane_t(plane_n, plane_w, p, o64, d64, q, t0[i] + np.float64(tfar[q]))
        if t <= t0[i]:
            return False
        if t < t1[i] and t <= t_blk[i]:
            t_blk[i] = t
            p_blk[i] = inst[q] * n_tri + p
            u_blk[i] = np.float64(u32[q])
            v_blk[i] = np.float64(v32[q])
    for i in range(m):
        if t_blk[i] < best_t[i]:
            best_t[i] = t_blk[i]
            best_part[i] = k
            prim[i] = p_blk[i]
            u_out[i] = u_blk[i]
            v_out[i] = v_blk[i]
    return True


@njit(cache=True, nogil=True, error_model="numpy")
def _unit_through_At(A, x, y, z):
    """A^T (x, y, z) normalised (a normal mapped by the inverse-transpose; zero stays zero)."""
    a = A[0, 0] * x + A[1, 0] * y + A[2, 0] * z
    b = A[0, 1] * x + A[1, 1] * y + A[2, 1] * z
    c = A[0, 2] * x + A[1, 2] * y + A[2, 2] * z
    L = np.sqrt(a * a + b * b + c * c)
    if L > 0:
        a, b, c = a / L, b / L, c / L
    return a, b, c


@njit(cache=True, nogil=True, error_model="numpy")
def _shade_one(q, jj, uk, vk, tk, T, Q, S, arc, knots, first, last, V, F, normals, smooth, A, b, ng, ns, row):
    """ng[row], ns[row] (world, unit) of triangle q of instance jj at barycentrics uk, vk and time tk."""
    _world_to_object(T, Q, S, arc, knots, first[jj], last[jj], tk, A, b)
    # Geometric normal: object cross product through A^T, normalised
    a0, a1, a2 = F[q, 0], F[q, 1], F[q, 2]
    e10, e11, e12 = V[a1, 0] - V[a0, 0], V[a1, 1] - V[a0, 1], V[a1, 2] - V[a0, 2]
    e20, e21, e22 = V[a2, 0] - V[a0, 0], V[a2, 1] - V[a0, 1], V[a2, 2] - V[a0, 2]
    n0, n1, n2 = e11 * e22 - e12 * e21, e12 * e20 - e10 * e22, e10 * e21 - e11 * e20
    g0, g1, g2 = _unit_through_At(A, n0, n1, n2)
    ng[row, 0], ng[row, 1], ng[row, 2] = g0, g1, g2
    if not smooth:
        ns[row, 0], ns[row, 1], ns[row, 2] = g0, g1, g2
        return
    # Shading normal: float64 blend of the corner normals, through A^T
    w0, w1, w2 = 1 - uk - vk, uk, vk
    m0 = w0 * normals[q, 0, 0] + w1 * normals[q, 1, 0] + w2 * normals[q, 2, 0]
    m1 = w0 * normals[q, 0, 1] + w1 * normals[q, 1, 1] + w2 * normals[q, 2, 1]
    m2 = w0 * normals[q, 0, 2] + w1 * normals[q, 1, 2] + w2 * normals[q, 2, 2]
    s0, s1, s2 = _unit_through_At(A, m0, m1, m2)
    if s0 == 0 and s1 == 0 and s2 == 0:
        s0, s1, s2 = g0, g1, g2
    ns[row, 0], ns[row, 1], ns[row, 2] = s0, s1, s2


@njit(cache=True, nogil=True, error_model="numpy")
def rigid_shade(j, tri, u, v, times, T, Q, S, arc, knots, first, last, V, F, normals, material_ids,
                ng, ns, mat):
    """World normals and material of hits on moving instances (as InstanceShading.shade).

    j, tri (m,) instance (index into the keys) and triangle; u, v, times (m,);
    V (nv, 3) float64 object vertices, F (nf, 3) triangles, normals (nf, 3, 3)
    float64 corner normals or (0, 3, 3) for flat shading.  Writes ng, ns (m, 3),
    mat (m,).
    """
    A = np.empty((3, 3))
    b = np.empty(3)
    smooth = normals.shape[0] > 0
    for k in range(tri.shape[0]):
        q = tri[k]
        _shade_one(q, j[k], u[k], v[k], times[k], T, Q, S, arc, knots, first, last, V, F, normals, smooth, A, b,
                   ng, ns, k)
        mat[k] = material_ids[q]


@njit(cache=True, nogil=True, error_model="numpy")
def rigid_shade_rows(rows, prim, n_tri, u, v, times, instances, T, Q, S, arc, knots, first, last, V, F, normals,
                     material_ids, inst_out, p_out, ng, ns, mat):
    """:func:`rigid_shade` written straight into the caster's result rows.

    rows (k,) the rays a group won; prim, u, v, times (n,) every ray's group
    primitive (``j * n_tri + triangle``), barycentrics and time; instances
    (J,) scene instance of each member.  Writes inst_out, p_out, mat (n,)
    int32 and ng, ns (n, 3) at those rows.
    """
    A = np.empty((3, 3))
    b = np.empty(3)
    smooth = normals.shape[0] > 0
    for k in range(rows.shape[0]):
        r = rows[k]
        jj = prim[r] // n_tri
        q = prim[r] - jj * n_tri
        _shade_one(q, jj, u[r], v[r], times[r], T, Q, S, arc, knots, first, last, V, F, normals, smooth, A, b,
                   ng, ns, r)
        inst_out[r] = instances[jj]
        p_out[r] = q
        mat[r] = material_ids[q]


@njit(cache=True, nogil=True, error_model="numpy")
def finish_hits(best_part, is_bounded, best_t, o, d, pos):
    """Caster epilogue: misses (best_part < 0) get t = +inf; rays won by a bounded part get
    pos = o + t d (n, 3) (the unbounded static part wrote its own positions)."""
    for i in range(best_part.shape[0]):
        k = best_part[i]
        if k < 0:
            best_t[i] = np.inf
        elif is_bounded[k]:
            t = best_t[i]
            for c in range(3):
                pos[i, c] = o[i, c] + t * d[i, c]


def warm_up() -> float:
    """Compile (or load from numba's on-disk cache) every kernel above; seconds taken.

    The embree backend calls them on its first rays otherwise (see
    docs/raycast.md for the measured first-use cost).
    """
    import time
    start = time.perf_counter()
    from .build import make_caster
    from ..motion import MotionTransform
    from ..scene import Instance, Material, Mesh, Scene
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32)
    mesh = Mesh(vertices=V, triangles=np.array([[0, 1, 2]], np.int32), material_ids=np.zeros(1, np.int32),
                normals=np.tile(np.array([0, 0, 1], np.float32), (1, 3, 1)))
    M1 = np.eye(4)
    M1[:3, 3] = (0, 0, 1)
    scene = Scene(meshes=[mesh], instances=[Instance(0), Instance(0, MotionTransform(np.array([0.0, 1.0]),
                                                                                  np.stack([M1, M1 * 1.0])))],
                  materials=[Material()])
    try:
        caster = make_caster(scene, "embree")
    except Exception:          # no embreex: nothing of this module will run
        return time.perf_counter() - start
    o, d = np.array([[0.2, 0.2, 2.0]]), np.array([[0.0, 0.0, -1.0]])
    caster.intersect(o, d, np.zeros(1))
    caster.occluded(o, d, np.zeros(1), np.full(1, 10.0))
    from .contact import warm_up as warm_contacts    # surfaces in contact (every backend's caster)
    warm_contacts()
    return time.perf_counter() - start
