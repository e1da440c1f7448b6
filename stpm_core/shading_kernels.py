"""Fused numba kernels for the tracer's per-sample work (the numpy code in
integrator.py, camera.py, bsdf.py, lights.py and film.py stays the reference
and the fallback).

Kernels (docs/rendering.md, "Performance", has the equations with these names):

* :func:`camera_tile` -- stratified film positions (placed by the pixel
  filter's inverse CDF) and permuted stratified shutter numbers of one tile
  (``integrator.camera_samples``);
* :func:`camera_rays` -- pinhole / ortho rays, camera clipping ``tmax0``
  (``camera.generate_rays``);
* :func:`classify_hits` -- one bounce's bookkeeping: world radiance of misses,
  surface emission, Depth / Normal / coverage of the first hit, and the rows to
  shade (non-delta lobe) and to continue (delta lobe);
* :func:`nee_point` / :func:`nee_given` -- next-event estimation setup for one
  light: the light sample (point / spot of radius 0 inline; any other light
  from ``LightSet.sample_direct``), the BSDF of materials without rough lobes
  (``bsdf.bsdf_eval``'s shortcut) or a given f, the unshadowed contribution and
  the shadow rays of the rows where it is positive (``integrator._direct``);
* :func:`nee_accumulate`, :func:`scatter_add` -- add the unblocked
  contributions, add per-row values into per-sample passes (weighted by beta);
* :func:`pixel_sums`, :func:`tile_finish` -- per-pixel sums of one tile's
  samples and the film window they make (``film.Film.tile_sums``).

They use the same random numbers as the numpy code and agree with it to float
rounding (tests/test_shading_kernels.py; e.g. a normalisation multiplies by
1 / |v| where numpy divides by |v|).  Every kernel is serial and releases
the GIL (tiles run on the tracer's thread pool).

``AVAILABLE`` is False when numba cannot be imported or ``STPM_NO_NUMBA=1``;
the integrator then runs the numpy path only (also after a kernel fails to
compile: ``CompileError``, then :func:`disable`).  First use compiles the
kernels (about 17 s on this machine with every numba cache cold, embree
kernels included), later processes load them from numba's cache.
"""
from __future__ import annotations

import math

import numpy as np

from .numba_probe import probe

__all__ = ["AVAILABLE", "CompileError", "camera_tile", "camera_rays", "classify_hits", "nee_point", "nee_given", "nee_world",
           "nee_accumulate", "scatter_add", "active_channels", "pixel_sums", "tile_finish", "disable", "IMPORT_ERROR"]

AVAILABLE, IMPORT_ERROR = probe()
if AVAILABLE:
    from numba import njit
    from numba.core.errors import NumbaError as CompileError
else:
    class CompileError(Exception):
        """Stands for numba's errors when numba is missing (never raised)."""


def disable(reason: str) -> None:
    """Switch the kernels off for this process (the integrator falls back to numpy)."""
    global AVAILABLE, IMPORT_ERROR
    AVAILABLE = False
    IMPORT_ERROR = reason


if not AVAILABLE:                              # pragma: no cover - depends on the platform
    def njit(*a, **k):                         # noqa: D103 -- placeholder so the module imports
        def wrap(f):
            return f
        return wrap

_JIT = dict(cache=True, nogil=True, fastmath=False, error_model="numpy")
# Small helpers called per row: inlined into the kernels (a call with many array arguments is costly)
_JIT_INLINE = dict(_JIT, inline="always")
_INV_PI = 1.0 / np.pi


# ----------------------------------------------------------------------------
# Camera
# ----------------------------------------------------------------------------
@njit(**_JIT)
def camera_tile(x0, y0, tw, th, S, jit, perm_u, time_u, with_time, radius, table, px, py, xi):
    """Film positions px, py (P*S,) and shutter numbers xi (P*S,) of a tile's P = tw*th pixels.

    jit (P, S, 2), perm_u (P, S), time_u (P, S): the uniforms
    ``integrator.camera_samples`` draws, in its order.  Position: cell j of a
    rows x cols grid (j < rows*cols) jittered, else uniform, giving u in
    [0, 1)^2; then px = ix + 1/2 + radius F^-1(u_x) with F^-1 linear in
    ``table`` (``film.BH_INVERSE_CDF``, as ``film.filter_offsets``), or
    px = ix + u_x for the box filter (radius 0).  xi = (pi_p(j) + U) / S with
    pi_p = argsort(perm_u[p]) (only when with_time; xi is left unset otherwise).
    """
    rows = max(1, int(math.floor(math.sqrt(S))))
    cols = max(1, S // rows)
    m = rows * cols
    M1 = table.shape[0] - 1
    order = np.empty(S, np.int64)
    for p in range(tw * th):
        ix = x0 + p % tw
        iy = y0 + p // tw
        base = p * S
        for j in range(S):
            if j < m:
                cy, cx = j // cols, j % cols
                ux = cx / cols + jit[p, j, 0] / cols
                uy = cy / rows + jit[p, j, 1] / rows
            else:
                ux = jit[p, j, 0]
                uy = jit[p, j, 1]
            if radius > 0:
                s = ux * M1
                k = min(int(s), M1 - 1)
                f = s - k
                px[base + j] = ix + 0.5 + radius * (table[k] * (1.0 - f) + table[k + 1] * f)
                s = uy * M1
                k = min(int(s), M1 - 1)
                f = s - k
                py[base + j] = iy + 0.5 + radius * (table[k] * (1.0 - f) + table[k + 1] * f)
            else:
                px[base + j] = ix + ux
                py[base + j] = iy + uy
        if not with_time:
            continue
        # argsort of perm_u[p] (insertion sort: S is small; random keys have no ties)
        for j in range(S):
            order[j] = j
        for j in range(1, S):
            k = order[j]
            key = perm_u[p, k]
            i = j - 1
            while i >= 0 and perm_u[p, order[i]] > key:
                order[i + 1] = order[i]
                i -= 1
            order[i + 1] = k
        for j in range(S):
            xi[base + j] = (order[j] + time_u[p, j]) / S


@njit(**_JIT)
def camera_rays(px, py, W, H, half_w, half_h, cx, cy, R, pos, ortho, clip_start, clip_end, o, d, tmax0):
    """Rays o, d (n, 3) and clipping distances tmax0 (n,) through film positions px, py (n,).

    R (k, 3, 3) unit-column rotations and pos (k, 3) camera positions, k = 1
    (static camera) or n (one pose per sample).  Same formulas as
    ``camera.generate_rays`` and the clipping in ``integrator.trace_image``.
    """
    n = px.shape[0]
    one = R.shape[0] == 1
    for i in range(n):
        r = 0 if one else i
        x = cx + (2.0 * px[i] / W - 1.0) * half_w
        y = cy + (1.0 - 2.0 * py[i] / H) * half_h
        ax0, ax1, ax2 = -R[r, 0, 2], -R[r, 1, 2], -R[r, 2, 2]
        if ortho:
            z = -clip_start
            for a in range(3):
                o[i, a] = R[r, a, 0] * x + R[r, a, 1] * y + R[r, a, 2] * z + pos[r, a]
                d[i, a] = -R[r, a, 2]
            tmax0[i] = clip_end - clip_start
        else:
            d0 = R[r, 0, 0] * x + R[r, 0, 1] * y - R[r, 0, 2]
            d1 = R[r, 1, 0] * x + R[r, 1, 1] * y - R[r, 1, 2]
            d2 = R[r, 2, 0] * x + R[r, 2, 1] * y - R[r, 2, 2]
            inv = 1.0 / math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)      # (one division, not three)
            d0, d1, d2 = d0 * inv, d1 * inv, d2 * inv
            d[i, 0], d[i, 1], d[i, 2] = d0, d1, d2
            o[i, 0], o[i, 1], o[i, 2] = pos[r, 0], pos[r, 1], pos[r, 2]
            tmax0[i] = clip_end / max(d0 * ax0 + d1 * ax1 + d2 * ax2, 1e-12)


# ----------------------------------------------------------------------------
# One bounce's bookkeeping
# ----------------------------------------------------------------------------
@njit(**_JIT)
def classify_hits(t, mat, nondelta, has_delta, emissive, emission, world, add_world,
                  idx, use_idx, beta, use_beta, V, c_emit, first, c_depth, c_normal, depth_bg,
                  P, NS, cam_pos, cam_axis, covered, sh, spec):
    """Bookkeeping of m rays' hits; returns (n_hit, n_sh, n_spec, n_emit) (n_emit: rows added to Emit).

    t (m,) hit distances (inf: miss), mat (m,) material ids; nondelta,
    has_delta, emissive (M + 1,) bool and emission (M + 1, 3) per material.
    Row r belongs to sample ``idx[r]`` (``r`` when not use_idx) with
    throughput ``beta[r]`` (1 when not use_beta).  V (n, C) holds the
    samples' pass values, Emit in columns c_emit .. c_emit + 2.  The first
    bounce (every sample once, in order) starts each sample's row of V: 0,
    Depth (column c_depth) = depth_bg, then for a hit Depth = (P - cam_pos) .
    cam_axis, Normal (c_normal ..) = NS and covered = 1 (cam_pos, cam_axis
    (k, 3), k = 1 or n).  Adds world (3,) radiance of misses (if add_world)
    and emission of emissive hits into Emit.  Writes the hit rows with a
    non-delta lobe into sh and those with a delta lobe into spec, in row order.
    """
    m = t.shape[0]
    C = V.shape[1]
    n_hit = 0
    n_sh = 0
    n_spec = 0
    n_emit = 0
    one = cam_pos.shape[0] == 1
    for r in range(m):
        i = idx[r] if use_idx else r
        if first:
            for c in range(C):
                V[i, c] = 0.0
            V[i, c_depth] = depth_bg
            covered[i] = 0.0
        if not np.isfinite(t[r]):
            if add_world:
                n_emit += 1
                for c in range(3):
                    V[i, c_emit + c] += (beta[r, c] * world[c]) if use_beta else world[c]
            continue
        n_hit += 1
        mm = mat[r]
        if mm < 0:
            mm = nondelta.shape[0] - 1
        if first:
            k = 0 if one else i
            V[i, c_depth] = ((P[r, 0] - cam_pos[k, 0]) * cam_axis[k, 0] + (P[r, 1] - cam_pos[k, 1]) * cam_axis[k, 1]
                             + (P[r, 2] - cam_pos[k, 2]) * cam_axis[k, 2])
            for c in range(3):
                V[i, c_normal + c] = NS[r, c]
            covered[i] = 1.0
        if emissive[mm]:
            n_emit += 1
            for c in range(3):
                V[i, c_emit + c] += (beta[r, c] * emission[mm, c]) if use_beta else emission[mm, c]
        if nondelta[mm]:
            sh[n_sh] = r
            n_sh += 1
        if has_delta[mm]:
            spec[n_spec] = r
            n_spec += 1
    return n_hit, n_sh, n_spec, n_emit


@njit(**_JIT_INLINE)
def _add_row(dst, r, idx, use_idx, beta, use_beta, val, k):
    """dst[idx[r]] += beta[r] * val[k] (3 channels; idx / beta optional)."""
    i = idx[r] if use_idx else r
    for c in range(3):
        dst[i, c] += (beta[r, c] * val[k, c]) if use_beta else val[k, c]


@njit(**_JIT)
def scatter_add(dst, rows, idx, use_idx, beta, use_beta, val):
    """dst[idx[rows[k]]] += beta[rows[k]] * val[k] for every k (idx / beta optional), val (k, 3)."""
    for k in range(rows.shape[0]):
        _add_row(dst, rows[k], idx, use_idx, beta, use_beta, val, k)


# ----------------------------------------------------------------------------
# Next-event estimation
# ----------------------------------------------------------------------------
@njit(**_JIT_INLINE)
def _fresnel_dielectric(cos_i, eta):
    """Unpolarised Fresnel reflectance (bsdf.fresnel_dielectric for one value)."""
    cos_i = min(max(cos_i, 0.0), 1.0)
    sin2_t = (1.0 - cos_i * cos_i) / (eta * eta)
    if sin2_t >= 1.0:
        return 1.0
    cos_t = math.sqrt(max(0.0, 1.0 - sin2_t))
    r_s = (cos_i - eta * cos_t) / max(cos_i + eta * cos_t, 1e-300)
    r_p = (eta * cos_i - cos_t) / max(eta * cos_i + cos_t, 1e-300)
    return 0.5 * (r_s * r_s + r_p * r_p)


@njit(**_JIT_INLINE)
def _nee_row(k, r, wi0, wi1, wi2, dist, w0, w1, w2, P, NG, NS, D, mat, f_in, use_f,
             w_base, coat, specular, ior, base_color, EPS, contrib, so, sd, stmax, live, n_live):
    """Shared tail of the NEE kernels for shading row k (hit row r): BSDF, contribution, shadow ray
    (origin offset EPS[r] along the geometric normal)."""
    g0, g1, g2 = NG[r, 0], NG[r, 1], NG[r, 2]
    s0, s1, s2 = NS[r, 0], NS[r, 1], NS[r, 2]
    if use_f:
        f0, f1, f2 = f_in[k, 0], f_in[k, 1], f_in[k, 2]
    else:
        # bsdf_eval for materials without rough lobes: diffuse under a smooth coat's Fresnel
        wo0, wo1, wo2 = -D[r, 0], -D[r, 1], -D[r, 2]
        sg = 1.0 if wo0 * g0 + wo1 * g1 + wo2 * g2 >= 0.0 else -1.0
        gf0, gf1, gf2 = g0 * sg, g1 * sg, g2 * sg
        ss = 1.0 if s0 * gf0 + s1 * gf1 + s2 * gf2 >= 0.0 else -1.0
        sf0, sf1, sf2 = s0 * ss, s1 * ss, s2 * ss
        cos_i = wi0 * sf0 + wi1 * sf1 + wi2 * sf2
        mm = mat[r]
        if mm < 0:
            mm = w_base.shape[0] - 1
        scale = 0.0
        if cos_i > 0 and wi0 * gf0 + wi1 * gf1 + wi2 * gf2 > 0:
            scale = w_base[mm]
            if coat[mm]:
                cos_o = min(max(wo0 * sf0 + wo1 * sf1 + wo2 * sf2, 0.0), 1.0)
                scale *= 1.0 - specular[mm] * _fresnel_dielectric(cos_o, ior[mm])
        f0 = scale * base_color[mm, 0] * _INV_PI
        f1 = scale * base_color[mm, 1] * _INV_PI
        f2 = scale * base_color[mm, 2] * _INV_PI
    cosa = abs(s0 * wi0 + s1 * wi1 + s2 * wi2)
    c0 = f0 * cosa * w0
    c1 = f1 * cosa * w1
    c2 = f2 * cosa * w2
    contrib[k, 0], contrib[k, 1], contrib[k, 2] = c0, c1, c2
    if not (c0 > 0.0 or c1 > 0.0 or c2 > 0.0):
        return n_live
    # Shadow ray from p offset along ng to wi's side, aimed at the light point, stopping short
    eps = EPS[r]
    side = eps * (1.0 if g0 * wi0 + g1 * wi1 + g2 * wi2 >= 0.0 else -1.0)
    p0, p1, p2 = P[r, 0], P[r, 1], P[r, 2]
    o0, o1, o2 = p0 + side * g0, p1 + side * g1, p2 + side * g2
    so[n_live, 0], so[n_live, 1], so[n_live, 2] = o0, o1, o2
    if np.isfinite(dist):
        v0, v1, v2 = p0 + dist * wi0 - o0, p1 + dist * wi1 - o1, p2 + dist * wi2 - o2
        s = math.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
        inv = 1.0 / s
        sd[n_live, 0], sd[n_live, 1], sd[n_live, 2] = v0 * inv, v1 * inv, v2 * inv
        stmax[n_live] = s * (1.0 - 1e-6) - 2.0 * eps
    else:
        s = math.sqrt(wi0 * wi0 + wi1 * wi1 + wi2 * wi2)
        sd[n_live, 0], sd[n_live, 1], sd[n_live, 2] = wi0 / s, wi1 / s, wi2 / s
        stmax[n_live] = np.inf
    live[n_live] = k
    return n_live + 1


@njit(**_JIT)
def nee_point(rows, P, NG, NS, D, mat, C, I, spot, cos_half, smooth, Z, f_in, use_f,
              w_base, coat, specular, ior, base_color, EPS, contrib, so, sd, stmax, live):
    """NEE of a POINT / SPOT light of radius 0 at the hit rows ``rows`` (n,); returns the shadow-ray count.

    C, Z (k, 3) light position and unit axis (k = 1 static, else per row of
    ``rows``), I (3,) intensity W/sr; spot mask with cos_half / smooth as
    ``lights.spot_attenuation``.  f_in (n, 3) is used when use_f (materials
    with rough lobes), else the shortcut BSDF from the material arrays.
    EPS (n_hits,): shadow-ray origin offset of each hit row (scene units).
    Writes contrib (n, 3) = f |ns . wi| I / d^2 (x mask) and, for the rows
    where it is positive, shadow rays so, sd (n, 3), stmax (n,) and the
    shading row index live (n,).
    """
    n = rows.shape[0]
    one = C.shape[0] == 1
    n_live = 0
    for k in range(n):
        r = rows[k]
        j = 0 if one else k
        # p - c: light -> p, normalised
        v0, v1, v2 = P[r, 0] - C[j, 0], P[r, 1] - C[j, 1], P[r, 2] - C[j, 2]
        dd = math.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
        inv = 1.0 / max(dd, 1e-300)
        t0, t1, t2 = v0 * inv, v1 * inv, v2 * inv
        g = 1.0 / max(dd * dd, 1e-300) if dd > 0.0 else 0.0
        w0, w1, w2 = I[0] * g, I[1] * g, I[2] * g
        if spot:
            # spot_attenuation(-wi . -Z) with wi = -to_p
            x = (t0 * -Z[j, 0] + t1 * -Z[j, 1] + t2 * -Z[j, 2]) - cos_half
            if smooth <= 0.0:
                a = 1.0 if x > 0.0 else 0.0
            elif x > 0.0:
                s = min(max(x / smooth, 0.0), 1.0)
                a = s * s * (3.0 - 2.0 * s)
            else:
                a = 0.0
            w0, w1, w2 = w0 * a, w1 * a, w2 * a
        n_live = _nee_row(k, r, -t0, -t1, -t2, dd, w0, w1, w2, P, NG, NS, D, mat, f_in, use_f,
                          w_base, coat, specular, ior, base_color, EPS, contrib, so, sd, stmax, live, n_live)
    return n_live


@njit(**_JIT)
def nee_given(rows, P, NG, NS, D, mat, wi, dist, weight, f_in, use_f,
              w_base, coat, specular, ior, base_color, EPS, contrib, so, sd, stmax, live):
    """NEE at hit rows ``rows`` (n,) for a light sampled elsewhere: wi (n, 3), dist (n,), weight (n, 3).

    Same outputs as :func:`nee_point`; returns the shadow-ray count.
    """
    n_live = 0
    for k in range(rows.shape[0]):
        n_live = _nee_row(k, rows[k], wi[k, 0], wi[k, 1], wi[k, 2], dist[k], weight[k, 0], weight[k, 1],
                          weight[k, 2], P, NG, NS, D, mat, f_in, use_f, w_base, coat, specular, ior,
                          base_color, EPS, contrib, so, sd, stmax, live, n_live)
    return n_live


@njit(**_JIT)
def nee_world(rows, P, NG, NS, D, mat, U, L, w_base, coat, specular, ior, base_color, EPS, contrib, so, sd, stmax,
              live):
    """NEE of the world light (constant radiance L (3,)) at the hit rows ``rows`` (n,), uniforms U (n, 2).

    As ``WorldLight.sample`` with the geometric normal turned toward -D (the integrator's
    ``_world_normals``): wi cosine-distributed about it (Shirley-Chiu disc, Duff et al. basis, the
    same float operations as ``sampling.cosine_hemisphere`` / ``to_world``), weight = L pi / cos,
    shadow rays to infinity.  Same outputs as :func:`nee_point`; returns the shadow-ray count.
    Materials without rough lobes only (the shortcut BSDF of :func:`_nee_row`).
    """
    n_live = 0
    for k in range(rows.shape[0]):
        r = rows[k]
        # normal n: ng turned toward wo = -D
        g0, g1, g2 = NG[r, 0], NG[r, 1], NG[r, 2]
        if -(g0 * D[r, 0] + g1 * D[r, 1] + g2 * D[r, 2]) < 0.0:
            g0, g1, g2 = -g0, -g1, -g2
        # cosine hemisphere from the concentric disc
        a = 2.0 * U[k, 0] - 1.0
        b = 2.0 * U[k, 1] - 1.0
        if abs(a) > abs(b):
            rr = a
            phi = 0.25 * np.pi * (b / (1.0 if a == 0.0 else a))
        else:
            rr = b
            phi = 0.5 * np.pi - 0.25 * np.pi * (a / (1.0 if b == 0.0 else b))
        lx, ly = rr * math.cos(phi), rr * math.sin(phi)
        lz = math.sqrt(max(0.0, 1.0 - (lx * lx + ly * ly)))
        # orthonormal basis about n
        sg = 1.0 if g2 >= 0.0 else -1.0
        aa = -1.0 / (sg + g2)
        bb = g0 * g1 * aa
        t0, t1, t2 = 1.0 + sg * g0 * g0 * aa, sg * bb, -sg * g0
        b0, b1, b2 = bb, sg + g1 * g1 * aa, -g1
        wi0 = lx * t0 + ly * b0 + lz * g0
        wi1 = lx * t1 + ly * b1 + lz * g1
        wi2 = lx * t2 + ly * b2 + lz * g2
        c = np.pi / max(lz, 1e-12)
        # (f_in = contrib: a placeholder, not read without rough lobes)
        n_live = _nee_row(k, r, wi0, wi1, wi2, np.inf, c * L[0], c * L[1], c * L[2], P, NG, NS, D, mat,
                          contrib, False, w_base, coat, specular, ior, base_color, EPS, contrib, so, sd, stmax,
                          live, n_live)
    return n_live


@njit(**_JIT)
def nee_accumulate(dst, rows, idx, use_idx, beta, use_beta, contrib, live, blocked):
    """dst[idx[rows[k]]] += beta[rows[k]] * contrib[k], k = live[j], for every shadow ray j not blocked.

    dst (n, 3) the Direct pass of the samples; rows (K,) the hit rows shaded;
    idx / beta optional as in :func:`scatter_add`.
    """
    for j in range(live.shape[0]):
        if not blocked[j]:
            k = live[j]
            _add_row(dst, rows[k], idx, use_idx, beta, use_beta, contrib, k)


# ----------------------------------------------------------------------------
# Film
# ----------------------------------------------------------------------------
@njit(**_JIT)
def active_channels(V, skip):
    """Indices (k,) of the columns c of V (n, C) with skip[c] False that are not zero for every sample."""
    n, C = V.shape
    act = np.empty(C, np.int64)
    na = 0
    for c in range(C):
        if skip[c]:
            continue
        for i in range(n):
            if V[i, c] != 0.0:
                act[na] = c
                na += 1
                break
    return act[:na]


@njit(**_JIT)
def pixel_sums(tw, th, S, V, act, win):
    """Per-pixel sums of a tile's samples into win (th, tw, k + 1) float64 (zeroed by the caller).

    Samples as ``integrator.camera_samples`` lays them out (pixel p = (p % tw,
    p // tw) of the tile, its S samples consecutive); V (n, C) sample values,
    act (k,) the columns to sum (the others add nothing, e.g. all zero):
    win[iy, ix, a] = sum_s V[p S + s, act[a]], win[iy, ix, k] = S.
    """
    na = act.shape[0]
    for p in range(tw * th):
        cell = win[p // tw, p % tw]
        for s in range(S):
            row = V[p * S + s]
            for a in range(na):
                cell[a] += row[act[a]]
        cell[na] = S


@njit(**_JIT)
def tile_finish(win, y0, y1, x0, x1, chan, comb, alpha_one, out):
    """The image-channel window out (y1 - y0, x1 - x0, C + 1) float32 from the kernel sums.

    win (h, w, k + 1) float64 from :func:`pixel_sums` (rows y0 .. y1, columns
    x0 .. x1 of it are kept), chan (k,) the image channel of each summed
    column, last column the sample count (out[..., C]).  comb (j,): columns of
    win whose three consecutive sums add up to Combined RGB (channels 0 .. 2:
    the first column of each of Emit / Direct / Indirect / Caustic that was
    summed; empty: Combined is one of chan), added in float64; alpha_one:
    Combined alpha (3) = the sample count.  Channels neither summed nor derived are 0.
    """
    k = chan.shape[0]
    C = out.shape[2] - 1
    for y in range(y1 - y0):
        for x in range(x1 - x0):
            cell = win[y0 + y, x0 + x]
            o = out[y, x]
            for c in range(C + 1):
                o[c] = 0.0
            for a in range(k):
                o[chan[a]] = cell[a]
            o[C] = cell[k]
            if comb.shape[0] > 0:
                r = 0.0
                g = 0.0
                b = 0.0
                for j in range(comb.shape[0]):
                    a = comb[j]
                    r += cell[a]
                    g += cell[a + 1]
                    b += cell[a + 2]
                o[0], o[1], o[2] = r, g, b
            if alpha_one:
                o[3] = cell[k]
