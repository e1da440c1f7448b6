"""Camera paths in compiled (numba) kernels: the one implementation of the
tracer's per-sample work.  Python (``stpm_core.integrator``) only drives the
wavefront: it draws the random numbers in a fixed order, casts each bounce's
rays (embree or the numba BVH) and calls these kernels in between.

Kernels, in the order a bounce uses them (docs/rendering.md has the
equations with these names):

* :func:`camera_tile` -- stratified film positions (placed by the pixel
  filter's inverse CDF) and permuted stratified shutter numbers of one tile;
* :func:`lens_tile` -- stratified lens uniforms (depth of field only);
* :func:`camera_rays` -- pinhole / thin-lens / ortho rays (:func:`aperture_point`), camera
  clipping ``tmax0``;
* the closure of every hit comes first, from :func:`stpm_core.kernels.svm.shade_rows`:
  hit r's closure is row ``crow[r]`` of ``C`` (the material table itself when no material has a
  node program, else one row per hit filled by the interpreter); nothing after it depends on
  how it was made;
* :func:`classify_hits` -- one bounce's bookkeeping: world radiance of misses,
  surface emission, Depth / Normal / coverage of the first hit, and the rows to
  shade (non-delta lobe) and to continue (delta lobe);
* :func:`denoising_rows` (with ``RenderSettings.denoise``) -- Cycles' denoising features of the
  bounce: Denoising Albedo and Normal at the first diffuse-like vertex, the feature throughput
  through specular-like ones (:func:`denoising_seen_add`: light shapes seen on the way);
* :func:`light_strata` -- the uniforms of one light's samples, stratified over each pixel's samples;
* :func:`nee_light` -- next-event estimation of one light at the shaded rows:
  the light samples (:func:`stpm_core.kernels.lights.sample_light_rows`, every light
  type), the BSDF (:func:`stpm_core.kernels.bsdf.bsdf_eval`), the unshadowed
  contribution and the shadow rays where it is positive; then
  :func:`nee_accumulate` adds the unblocked ones;
* :func:`seen_lights_add` -- light shapes (area lights, spheres, soft-falloff discs, the cones of
  suns of angle > 0 where rays escape) hit by camera rays and by rays leaving delta or rough lobes;
* :func:`photon_albedo` / :func:`photon_add` -- the diffuse albedo and the
  query rows of the photon-map look-ups, and rho / pi E added into a pass;
* :func:`specular_step` -- continue through delta and rough non-diffuse lobes: BSDF sample
  (``bsdf_sample_cont``), throughput, Russian roulette, offset origins of the next rays;
* :func:`scatter_add`, :func:`active_channels`, :func:`pixel_sums`,
  :func:`tile_finish` -- per-sample passes and per-pixel sums of one tile.

Every kernel is serial and releases the GIL (tiles run on the tracer's thread
pool).  numba is required: :func:`stpm_core.kernels.require` names the cause in
one line when it cannot be imported or a kernel cannot be compiled.  First use
compiles the kernels (tens of seconds with numba's cache cold); later
processes load them from numba's on-disk cache.
"""
from __future__ import annotations

import math

import numpy as np

from ..numba_probe import njit
from .bsdf import (PATH_GLOSSY, PATH_STOP, bsdf_eval_lobes, bsdf_eval_pdf, bsdf_eval_split, bsdf_eval_plain_w,
                   bsdf_eval_smooth, bsdf_sample_cont, denoising_features, diffuse_albedo, needs_bsdf_call)
from .environment import env_radiance
from .closure import (C_BASE, C_EMISSIVE, C_EMIT, C_HAS_DELTA, C_NONDELTA, C_ROUGH_LOBE, C_W_BASE, closure_row)
from .lights import light_pdf, mesh_light_pdf, sample_light_rows, seen_light, world_nee_pdf
from .sampling import dot, load_pose, offset_origin, pose_buffer, row3

__all__ = ["camera_tile", "lens_tile", "aperture_point", "camera_rays", "classify_hits", "denoising_rows", "denoising_seen_add", "light_strata",
           "nee_light",
           "offset_rows", "terminator_rows", "smooth_surface_heights", "nee_accumulate",
           "seen_lights_add", "photon_albedo", "photon_add", "specular_step", "scatter_add", "active_channels",
           "pixel_sums", "tile_finish"]

_JIT = dict(cache=True, nogil=True, fastmath=False, error_model="numpy")
_INV_PI = 1.0 / np.pi


# ----------------------------------------------------------------------------
# Camera
# ----------------------------------------------------------------------------
@njit(**_JIT)
def _argsort_row(keys, p, S, order):
    """order[:S] = argsort(keys[p, :S]): insertion sort (S, a pixel's samples, is small; random
    keys have no ties)."""
    for j in range(S):
        order[j] = j
    for j in range(1, S):
        k = order[j]
        key = keys[p, k]
        i = j - 1
        while i >= 0 and keys[p, order[i]] > key:
            order[i + 1] = order[i]
            i -= 1
        order[i + 1] = k


@njit(**_JIT)
def camera_tile(x0, y0, tw, th, S, jit, perm_u, time_u, with_time, radius, table, px, py, xi):
    """Film positions px, py (P*S,) and shutter numbers xi (P*S,) of a tile's P = tw*th pixels.

    jit (P, S, 2), perm_u (P, S), time_u (P, S): the uniforms
    ``integrator._trace_tile`` draws, in its order (the numpy oracle
    ``tests/oracles/integrator_numpy.camera_samples`` makes the same samples).  Position: cell j of a
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
        _argsort_row(perm_u, p, S, order)
        for j in range(S):
            xi[base + j] = (order[j] + time_u[p, j]) / S


@njit(**_JIT)
def lens_tile(S, keys, jit, uv):
    """Lens uniforms uv (P*S, 2) in [0, 1)^2 of P pixels of S samples each, stratified per pixel.

    keys (P, S), jit (P, S, 2): the uniforms ``integrator._shade_samples`` draws.  The lens square
    has the rows x cols grid of :func:`camera_tile` (m = rows cols <= S cells); sample j of pixel p
    takes cell pi_p(j), pi_p = argsort(keys[p]) (a permutation per pixel, so the lens cell is
    independent of the film cell j and of the time stratum), jittered by jit[p, j]; samples with
    pi_p(j) >= m (the leftovers) are uniform.  Each pixel's S samples thus put one sample in every
    lens cell.
    """
    P = keys.shape[0]
    rows = max(1, int(math.floor(math.sqrt(S))))
    cols = max(1, S // rows)
    m = rows * cols
    order = np.empty(S, np.int64)
    for p in range(P):
        _argsort_row(keys, p, S, order)
        for j in range(S):
            c = order[j]
            r = p * S + j
            if c < m:
                uv[r, 0] = (c % cols + jit[p, j, 0]) / cols
                uv[r, 1] = (c // cols + jit[p, j, 1]) / rows
            else:
                uv[r, 0] = jit[p, j, 0]
                uv[r, 1] = jit[p, j, 1]


@njit(**_JIT)
def aperture_point(u, v, blades, rotation, ratio):
    """Point (x, y) of the unit aperture for uniforms (u, v) in [0, 1)^2, uniform in its area.

    blades < 3: the unit disc by the concentric (Shirley-Chiu) map, which keeps the square's
    strata compact.  blades = n >= 3: the regular n-gon of circumradius 1 whose edge midpoints lie
    at angles rotation + 2 pi k / n (corners half-way between): u picks the triangle (centre, two
    corners) k = floor(n u) and, rescaled, with v places a uniform point in it.  Then x /= ratio
    (anamorphic bokeh).  Camera-space axes: x right, y up.
    """
    if blades < 3:
        a = 2.0 * u - 1.0
        b = 2.0 * v - 1.0
        if a == 0.0 and b == 0.0:
            return 0.0, 0.0
        if a * a > b * b:
            rad, phi = a, 0.25 * math.pi * (b / a)
        else:
            rad, phi = b, 0.5 * math.pi - 0.25 * math.pi * (a / b)
        x, y = rad * math.cos(phi), rad * math.sin(phi)
    else:
        n = float(blades)
        k = math.floor(u * n)
        u1 = min(u * n - k, 1.0)
        half = math.pi / n                           # half the angle a blade's edge subtends
        # Uniform point s (c0 A + c1 B) of the triangle (0, A, B), A, B = the edge's corners at +-half
        s = math.sqrt(u1)
        c0, c1 = s * (1.0 - v), s * v
        px = (c0 + c1) * math.cos(half)
        py = (c0 - c1) * math.sin(half)
        ang = rotation + 2.0 * half * k              # the triangle's own rotation
        ca, sa = math.cos(ang), math.sin(ang)
        x, y = ca * px - sa * py, sa * px + ca * py
    return x / ratio, y


@njit(**_JIT)
def camera_rays(px, py, W, H, half_w, half_h, cx, cy, R, pos, ortho, clip_start, clip_end, lens_uv, aperture,
                focus, blades, rotation, ratio, o, d, tmax0):
    """Rays o, d (n, 3) and clipping distances tmax0 (n,) through film positions px, py (n,).

    R (k, 3, 3) unit-column rotations and pos (k, 3) camera positions, k = 1
    (static camera) or n (one pose per sample).  The tracer's only camera-ray
    code (``camera.generate_rays`` calls it too); the numpy oracle is
    ``tests/oracles/integrator_numpy.generate_rays`` (pinhole only).

    Thin lens (depth of field) when aperture > 0: lens_uv (n, 2) uniforms (:func:`lens_tile`) are
    mapped to the aperture (:func:`aperture_point`) of radius ``aperture`` in the camera's XY plane;
    the ray leaves that lens point towards the point the pinhole ray meets the focus plane (at
    ``focus`` along the view axis), so the focus plane stays sharp.  The lens point is in camera
    space, so a moving camera carries its lens.  aperture = 0: lens_uv may be (0, 2) (a pinhole).
    docs/camera.md, "Depth of field".
    """
    n = px.shape[0]
    one = R.shape[0] == 1
    lens = aperture > 0.0
    fd = max(focus, 1e-5)
    for i in range(n):
        r = 0 if one else i
        x = cx + (2.0 * px[i] / W - 1.0) * half_w
        y = cy + (1.0 - 2.0 * py[i] / H) * half_h
        ax0, ax1, ax2 = -R[r, 0, 2], -R[r, 1, 2], -R[r, 2, 2]
        # Camera-space lens point (lx, ly, 0) and direction (dx, dy, dz) (view axis -z)
        lx = ly = 0.0
        if ortho:
            dx, dy, dz = 0.0, 0.0, -1.0
        else:
            dx, dy, dz = x, y, -1.0
        if lens:
            ux, uy = aperture_point(lens_uv[i, 0], lens_uv[i, 1], blades, rotation, ratio)
            lx, ly = aperture * ux, aperture * uy
            # The pinhole ray meets the focus plane z = -fd at (dx, dy) fd (perspective; ortho: (0, 0) fd)
            dx, dy, dz = dx * fd - lx, dy * fd - ly, -fd
        if ortho:
            # Origin on the near clip plane: the image-plane point (x, y) moved by the lens, then along
            # the ray to z = -clip_start
            sx, sy, sz = x + lx + dx * (clip_start / -dz), y + ly + dy * (clip_start / -dz), -clip_start
        else:
            sx, sy, sz = lx, ly, 0.0
        # To world: direction normalised there (one division, not three), origin
        d0 = R[r, 0, 0] * dx + R[r, 0, 1] * dy + R[r, 0, 2] * dz
        d1 = R[r, 1, 0] * dx + R[r, 1, 1] * dy + R[r, 1, 2] * dz
        d2 = R[r, 2, 0] * dx + R[r, 2, 1] * dy + R[r, 2, 2] * dz
        inv = 1.0 / math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        d0, d1, d2 = d0 * inv, d1 * inv, d2 * inv
        d[i, 0], d[i, 1], d[i, 2] = d0, d1, d2
        for a in range(3):
            o[i, a] = R[r, a, 0] * sx + R[r, a, 1] * sy + R[r, a, 2] * sz + pos[r, a]
        cos_axis = d0 * ax0 + d1 * ax1 + d2 * ax2
        if ortho:
            tmax0[i] = (clip_end - clip_start) / max(cos_axis, 1e-12)
        else:
            tmax0[i] = clip_end / max(cos_axis, 1e-12)


# ----------------------------------------------------------------------------
# One bounce's bookkeeping
# ----------------------------------------------------------------------------
@njit(**_JIT)
def classify_hits(t, C, crow, env, wposes, D, add_world, idx, use_idx, beta, use_beta, glossy, world_w, use_glossy,
                  V, c_emit, first, c_depth, c_normal, depth_bg, P, NS, cam_pos, cam_axis, covered, sh, spec, gem,
                  clamp):
    """Bookkeeping of m rays' hits; returns (n_hit, n_sh, n_spec, n_emit, n_gem) (n_emit: rows added
    to Emit; n_gem: emissive hits of rays that left a rough lobe, written to gem).

    t (m,) hit distances (inf: miss), C (*, N_CLOSURE) closure rows, crow (m,) the row of C of each
    hit (``kernels.svm.shade_rows``).  Row r belongs to sample ``idx[r]`` (``r`` when
    not use_idx) with throughput ``beta[r]`` (1 when not use_beta).  V (n, K)
    holds the samples' pass values, Emit in columns c_emit .. c_emit + 2.  The
    first bounce (every sample once, in order) starts each sample's row of V:
    0, Depth (column c_depth) = depth_bg, then for a hit Depth = (P - cam_pos)
    . cam_axis, Normal (c_normal ..) = NS and covered = 1 (cam_pos, cam_axis
    (k, 3), k = 1 or n).  Adds the world's radiance along the direction D[r] (m, 3)
    of misses (if add_world; ``kernels.environment.env_radiance`` of env with wposes (k, 4, 4)
    its mapping, k = 1 or m; times world_w[r] when use_glossy, :func:`specular_step`) and
    emission of emissive hits into Emit, except on rows that left a rough lobe (``glossy[r]`` 1,
    when use_glossy): those go to gem, in row order, for the caller to weigh against next-event
    estimation (:func:`mesh_emission_mis`, :func:`emission_rows_add`).
    Writes the hit rows with a non-delta lobe into sh and those with a delta or a rough lobe
    (where the path may go on, :func:`specular_step`) into spec, in row order.  Each emission /
    world contribution is clamped to ``clamp`` (0: off).
    """
    m = t.shape[0]
    K = V.shape[1]
    n_hit = 0
    n_sh = 0
    n_spec = 0
    n_emit = 0
    n_gem = 0
    one = cam_pos.shape[0] == 1
    one_w = wposes.shape[0] == 1
    M = pose_buffer(wposes)                  # no views or tuple items per row (sampling.row3)
    img, par = env[0], env[4]
    for r in range(m):
        i = idx[r] if use_idx else r
        if first:
            for c in range(K):
                V[i, c] = 0.0
            V[i, c_depth] = depth_bg
            covered[i] = 0.0
        emits = not (use_glossy and glossy[r] != 0)
        if not np.isfinite(t[r]):
            ww = world_w[r] if use_glossy else 1.0
            if add_world and ww > 0.0:
                n_emit += 1
                if not one_w:
                    load_pose(wposes, r, M)
                e0, e1, e2 = _world_seen(img, par, M, D, r, beta, use_beta, ww, clamp)
                V[i, c_emit] += e0
                V[i, c_emit + 1] += e1
                V[i, c_emit + 2] += e2
            continue
        n_hit += 1
        if first:
            k = 0 if one else i
            V[i, c_depth] = ((P[r, 0] - cam_pos[k, 0]) * cam_axis[k, 0] + (P[r, 1] - cam_pos[k, 1]) * cam_axis[k, 1]
                             + (P[r, 2] - cam_pos[k, 2]) * cam_axis[k, 2])
            for c in range(3):
                V[i, c_normal + c] = NS[r, c]
            covered[i] = 1.0
        cr = crow[r]
        if C[cr, C_EMISSIVE] > 0.0:
            if emits:
                n_emit += 1
                e0, e1, e2 = _emission_seen(C, cr, r, beta, use_beta, clamp)
                V[i, c_emit] += e0
                V[i, c_emit + 1] += e1
                V[i, c_emit + 2] += e2
            else:
                gem[n_gem] = r
                n_gem += 1
        if C[cr, C_NONDELTA] > 0.0:
            sh[n_sh] = r
            n_sh += 1
        if C[cr, C_HAS_DELTA] > 0.0 or C[cr, C_ROUGH_LOBE] > 0.0:
            spec[n_spec] = r
            n_spec += 1
    return n_hit, n_sh, n_spec, n_emit, n_gem


@njit(**_JIT)
def _world_seen(img, par, M, D, r, beta, use_beta, ww, clamp):
    """What row r adds to Emit where its ray escapes: beta[r] (1 when not use_beta) times the world's
    radiance along D[r] (img, par: the env arrays, M its mapping at the row's time) times ww,
    clamped to ``clamp`` (0: off)."""
    world = env_radiance(img, par, M, row3(D, r))
    if use_beta:
        e0, e1, e2 = beta[r, 0] * world[0] * ww, beta[r, 1] * world[1] * ww, beta[r, 2] * world[2] * ww
    else:
        e0, e1, e2 = world[0] * ww, world[1] * ww, world[2] * ww
    f = _clamp_scale(e0, e1, e2, clamp)
    return e0 * f, e1 * f, e2 * f


@njit(**_JIT)
def _emission_seen(C, cr, r, beta, use_beta, clamp):
    """What row r adds to Emit where it hits an emissive surface: beta[r] (1 when not use_beta) times
    the emission of its closure C[cr], clamped to ``clamp`` (0: off)."""
    if use_beta:
        e0, e1, e2 = beta[r, 0] * C[cr, C_EMIT], beta[r, 1] * C[cr, C_EMIT + 1], beta[r, 2] * C[cr, C_EMIT + 2]
    else:
        e0, e1, e2 = C[cr, C_EMIT], C[cr, C_EMIT + 1], C[cr, C_EMIT + 2]
    f = _clamp_scale(e0, e1, e2, clamp)
    return e0 * f, e1 * f, e2 * f


@njit(**_JIT)
def _clamp_scale(c0, c1, c2, clamp):
    """The factor that brings a contribution's largest channel down to ``clamp`` (Cycles'
    Clamp Direct / Indirect, ``film_clamp_light``): 1 when clamp <= 0 (off) or under it."""
    if clamp > 0.0:
        m = max(c0, max(c1, c2))
        if m > clamp:
            return clamp / m
    return 1.0


@njit(**_JIT)
def _add_row(dst, r, idx, use_idx, beta, use_beta, val, k, clamp):
    """dst[idx[r]] += beta[r] * val[k] (3 channels; idx / beta optional), clamped to ``clamp``
    (0: off) as one contribution."""
    i = idx[r] if use_idx else r
    if use_beta:
        c0, c1, c2 = beta[r, 0] * val[k, 0], beta[r, 1] * val[k, 1], beta[r, 2] * val[k, 2]
    else:
        c0, c1, c2 = val[k, 0], val[k, 1], val[k, 2]
    _add_clamped(dst, i, c0, c1, c2, clamp)


@njit(**_JIT)
def _add_clamped(dst, i, c0, c1, c2, clamp):
    """dst[i] += (c0, c1, c2), scaled by :func:`_clamp_scale` when clamp > 0."""
    if clamp > 0.0:
        f = _clamp_scale(c0, c1, c2, clamp)
        c0, c1, c2 = c0 * f, c1 * f, c2 * f
    dst[i, 0] += c0
    dst[i, 1] += c1
    dst[i, 2] += c2


@njit(**_JIT)
def scatter_add(dst, rows, idx, use_idx, beta, use_beta, val, clamp):
    """dst[idx[rows[k]]] += beta[rows[k]] * val[k] for every k (idx / beta optional), val (k, 3), each
    contribution clamped to ``clamp`` (0: off)."""
    for k in range(rows.shape[0]):
        _add_row(dst, rows[k], idx, use_idx, beta, use_beta, val, k, clamp)


# ----------------------------------------------------------------------------
# Denoising features (Cycles' Denoising Albedo and Denoising Normal)
# ----------------------------------------------------------------------------
@njit(**_JIT)
def denoising_rows(t, C, crow, env, wposes, D, add_world, idx, use_idx, beta, use_beta, glossy, world_w, use_glossy,
                   NS, NG, E, E_avg, cam_R, first, feat, dft, feat_next, dft_next, V, c_albedo, c_normal, clamp):
    """One bounce's share of the denoising features, as Cycles writes them (``denoising_passes.h``,
    and the albedo part of ``film_write_emission_or_background_pass``), for the rows of
    :func:`classify_hits`'s bounce (same t, C, crow, env, wposes, D, add_world, idx, beta, glossy,
    world_w, clamp) that still carry features.

    feat (m,) uint8: 1 where row r has not met its first diffuse-like vertex yet (every row on
    the first bounce), dft (m, 3) its feature throughput (1 on the first bounce: the product of the
    specular-like albedos met so far).  Where the row's ray escapes or hits an emitter, Denoising
    Albedo (columns c_albedo ..) gets dft times what :func:`classify_hits` adds to Emit there (an
    emitter also after a specular-like rough lobe, where Emit leaves it to next-event estimation:
    Cycles' albedo gets the emission its BSDF-sampled rays find, e.g. a highlight).  At a
    hit, ``bsdf.denoising_features``: where the diffuse-like lobes hold more than a quarter of the
    lobes' weight (or none has any), Denoising Albedo gets dft times the diffuse-like albedo and
    Denoising Normal (c_normal ..) the lobes' weighted normal in Cycles' camera space (x right, y
    up, z into the view: (n . R_x, n . R_y, -n . R_z) with R (k, 3, 3) the camera's rotation at the
    sample's time, k = 1 or one per sample) and the row carries no features on; otherwise its feature
    throughput is multiplied by the specular-like albedo and the path, if it goes on
    (:func:`specular_step`), takes it to its next vertex.  Results: feat_next, dft_next (m,).  first:
    the bounce that starts every sample (feat and dft are not read: every row carries features with
    throughput 1; V's rows were started, all 0, by :func:`classify_hits`).
    """
    m = t.shape[0]
    one_w = wposes.shape[0] == 1
    M = pose_buffer(wposes)                  # no views or tuple items per row (sampling.row3)
    img, par = env[0], env[4]
    one_c = cam_R.shape[0] == 1
    for r in range(m):
        i = idx[r] if use_idx else r
        on = first or feat[r] != 0
        f0, f1, f2 = (1.0, 1.0, 1.0) if first else (dft[r, 0], dft[r, 1], dft[r, 2])
        feat_next[r] = 0
        dft_next[r, 0], dft_next[r, 1], dft_next[r, 2] = f0, f1, f2
        if not on:
            continue
        if not np.isfinite(t[r]):
            # -- The world seen: its contribution to Emit, times the feature throughput
            ww = world_w[r] if use_glossy else 1.0
            if add_world and ww > 0.0:
                if not one_w:
                    load_pose(wposes, r, M)
                e0, e1, e2 = _world_seen(img, par, M, D, r, beta, use_beta, ww, clamp)
                V[i, c_albedo] += f0 * e0
                V[i, c_albedo + 1] += f1 * e1
                V[i, c_albedo + 2] += f2 * e2
            continue
        # -- An emitter seen: its emission (also through a specular-like rough lobe, where Emit
        # leaves it to next-event estimation), times the feature throughput
        cr = crow[r]
        if C[cr, C_EMISSIVE] > 0.0:
            e0, e1, e2 = _emission_seen(C, cr, r, beta, use_beta, clamp)
            V[i, c_albedo] += f0 * e0
            V[i, c_albedo + 1] += f1 * e1
            V[i, c_albedo + 2] += f2 * e2
        # -- The surface: write the features here, or carry them on through its specular-like lobes
        diff, spec, n, stop = denoising_features(C, cr, E, E_avg, (-D[r, 0], -D[r, 1], -D[r, 2]),
                                                 (NS[r, 0], NS[r, 1], NS[r, 2]), (NG[r, 0], NG[r, 1], NG[r, 2]))
        if stop:
            V[i, c_albedo] += f0 * diff[0]
            V[i, c_albedo + 1] += f1 * diff[1]
            V[i, c_albedo + 2] += f2 * diff[2]
            k = 0 if one_c else i
            V[i, c_normal] += n[0] * cam_R[k, 0, 0] + n[1] * cam_R[k, 1, 0] + n[2] * cam_R[k, 2, 0]
            V[i, c_normal + 1] += n[0] * cam_R[k, 0, 1] + n[1] * cam_R[k, 1, 1] + n[2] * cam_R[k, 2, 1]
            V[i, c_normal + 2] -= n[0] * cam_R[k, 0, 2] + n[1] * cam_R[k, 1, 2] + n[2] * cam_R[k, 2, 2]
        else:
            feat_next[r] = 1
            dft_next[r, 0], dft_next[r, 1], dft_next[r, 2] = f0 * spec[0], f1 * spec[1], f2 * spec[2]


@njit(**_JIT)
def denoising_seen_add(V, c_albedo, rows, idx, use_idx, beta, use_beta, first, feat, dft, val, clamp):
    """Denoising Albedo of light shapes seen along the rows' rays (as :func:`scatter_add` adds them to
    Emit, and also after a specular-like rough lobe): V[idx[r], c_albedo ..] += dft[r] * beta[r] *
    val[k] clamped, r = rows[k], for the rows still carrying features (feat, dft as
    :func:`denoising_rows` takes them: before the vertex)."""
    for k in range(rows.shape[0]):
        r = rows[k]
        if not (first or feat[r] != 0):
            continue
        i = idx[r] if use_idx else r
        if use_beta:
            c0, c1, c2 = beta[r, 0] * val[k, 0], beta[r, 1] * val[k, 1], beta[r, 2] * val[k, 2]
        else:
            c0, c1, c2 = val[k, 0], val[k, 1], val[k, 2]
        g = _clamp_scale(c0, c1, c2, clamp)
        if first:
            V[i, c_albedo] += c0 * g
            V[i, c_albedo + 1] += c1 * g
            V[i, c_albedo + 2] += c2 * g
        else:
            V[i, c_albedo] += dft[r, 0] * c0 * g
            V[i, c_albedo + 1] += dft[r, 1] * c1 * g
            V[i, c_albedo + 2] += dft[r, 2] * c2 * g


# ----------------------------------------------------------------------------
# Next-event estimation
# ----------------------------------------------------------------------------
_M32 = 0xFFFFFFFF
_ONE_BELOW = 1.0 - 2.0 ** -53                          # the largest double below 1


@njit(**_JIT)
def _reverse32(v):
    """The 32 bits of v (0 <= v < 2^32) in reverse order."""
    v = ((v & 0xAAAAAAAA) >> 1) | ((v & 0x55555555) << 1)
    v = ((v & 0xCCCCCCCC) >> 2) | ((v & 0x33333333) << 2)
    v = ((v & 0xF0F0F0F0) >> 4) | ((v & 0x0F0F0F0F) << 4)
    v = ((v & 0xFF00FF00) >> 8) | ((v & 0x00FF00FF) << 8)
    return ((v >> 16) | (v << 16)) & _M32


@njit(**_JIT)
def _hash32(x):
    """A 32-bit integer hash (bijective: a uniform x gives a uniform hash)."""
    x ^= x >> 16
    x = (x * 0x7FEB352D) & _M32
    x ^= x >> 15
    x = (x * 0x846CA68B) & _M32
    return x ^ (x >> 16)


@njit(**_JIT)
def _owen32(v, seed):
    """v (a 32-bit fraction) under a nested uniform (Owen) scramble keyed by seed, hash-based (Burley 2020,
    "Practical hash-based Owen scrambling", the Laine-Karras permutation of the reversed bits: each
    step moves information from a digit only to the digits below it).  A uniform seed gives a uniform
    result for any v; a (0, m, 2)-net stays one."""
    x = (_reverse32(v) + seed) & _M32
    x ^= (x * 0x6C50B47C) & _M32
    x ^= (x * 0xB82F1E52) & _M32
    x ^= (x * 0xC7AFE638) & _M32
    x ^= (x * 0x8D22F6E6) & _M32
    return _reverse32(x)


@njit(**_JIT)
def _sobol2(i):
    """The second Sobol coordinate of index i, as a 32-bit fraction (generator: Pascal's matrix mod 2);
    with the van der Corput first coordinate (reversed bits), a (0, 2)-sequence."""
    y = 0
    v = 1 << 31
    while i:
        if i & 1:
            y ^= v
        i >>= 1
        v ^= v >> 1
    return y


# Irreducible polynomials over GF(2) of degree 2 .. 10 (bit i: the coefficient of x^i): GF(2^k) for
# the orthogonal arrays of light_strata
_GF2_POLY = np.array([0, 0, 0b111, 0b1011, 0b10011, 0b100101, 0b1000011, 0b10001001, 0b100011101, 0b1000010001,
                      0b10000001001], np.int64)


@njit(**_JIT)
def _oa_poly(S):
    """The polynomial of GF(s) (s = 2^k, 2 <= k <= 10) when S = s^2: light_strata's orthogonal array
    of s levels; 0 for every other S (no array: a random permutation instead)."""
    k = 0
    while (1 << (2 * k)) < S:
        k += 1
    if (1 << (2 * k)) == S and 2 <= k <= 10:
        return _GF2_POLY[k]
    return 0


@njit(**_JIT)
def light_strata(samples, S, keys, jit, U):
    """Uniforms U (k, 2) of one light's samples at k shaded rows, stratified over each pixel's samples.

    samples (k,) int64: the tile sample q each row belongs to (pixel p = q // S, the pixel's sample
    j = q % S; a sample has at most one row); keys (P, S): a pixel's uniforms for its permutations
    and its scramble; jit (k, 2): each row's jitter below the points' 32 bits.

    A pixel's S points are the first S of the (0, 2)-sequence (``_reverse32``: van der Corput,
    ``_sobol2``: Sobol's second coordinate) under a nested uniform (Owen) scramble,
    :func:`_owen32`, seeded per pixel by keys[p, 0] (``_hash32``), as Cycles' samples are: S = 2^m
    points form a (0, m, 2)-net (one point in every 2^a x 2^b cut, a + b = m), and on a smooth
    light integral they beat jittered cells by far.  Sample j takes point t_j, U[i] = (X_t + jit[i])
    / 2^32 per axis (X_t the point's 32 bits):

    * S = s^2, s = 2^k (k = 2 .. 10): the point in light cell (lx, ly) of the s x s grid (the net
      holds one in each), with lx = sigma_x(cx + cy), ly = sigma_y(cx + alpha cy) in GF(s) (+ is
      XOR, alpha = x) from the film cell (cx, cy) = (j % s, j // s) of ``camera_tile``: an
      orthogonal array of strength 2 (Bose 1938; Jarosz et al. 2019 for rendering), each of the
      four coordinates (cx, cy, lx, ly) against each other an s x s Latin square, so the light's
      points are stratified against the film's too (Cycles' are, in 4D).  sigma_x, sigma_y: random
      permutations of the s levels per pixel (Fisher-Yates: from the identity, for t = s - 1 down
      to 1 swap entries t and min(floor(keys[p, o + t] (t + 1)), t); o = 0 for sigma_x, s - 1 for
      sigma_y), which keep the array and make each light cell uniform whatever the film cell;
    * any other S: t_j = pi_p(j), a random permutation of the pixel's samples (Fisher-Yates as
      above with keys[p, t], t = S - 1 .. 1).

    Each U[i] is uniform on [0, 1)^2 whatever the film position (the permutations are uniform, the
    seed is added to each point's reversed bits): every light sampler keeps its density
    (docs/rendering.md, "Stratified light samples").  Only the pixels some row belongs to are
    worked out: with the array, all S points of such a pixel (each point's cell fills a slot);
    without it, the pixel's permutation and scramble seeds, and each row's own point alone (at
    later bounces a pixel has a few rows: there a row's cost does not grow with S).
    """
    poly = _oa_poly(S)
    s = 1
    while s * s < S:
        s += 1
    k_s = 0                                           # log2(s) with the array
    while (1 << k_s) < s:
        k_s += 1
    P = keys.shape[0]
    sig = np.empty(2 * s, np.int64)                   # sigma_x, sigma_y of the pixel being worked out
    slot = np.empty(S, np.int64)                      # the net point in each cell (with the array)
    TX = np.empty(S, np.int64)                        # the pixel's points, 32-bit fractions
    TY = np.empty(S, np.int64)
    met = np.zeros(P, np.uint8)                       # 1 for the pixels worked out so far
    pt = np.empty(P * S, np.int64)                    # t_j at p S + j (without the array), for those pixels
    NX = np.empty(P * S, np.int64)                    # the point of each sample (with the array)
    NY = np.empty(P * S, np.int64)
    seeds = np.empty((P, 2), np.int64)                # each pixel's scramble seeds
    for i in range(samples.shape[0]):
        q = samples[i]
        p = q // S
        b = p * S
        if met[p] == 0:
            met[p] = 1
            # -- the pixel's scramble
            seed_x = _hash32(int(keys[p, 0] * 4294967296.0))
            seed_y = _hash32(seed_x ^ 0x9E3779B9)
            seeds[p, 0], seeds[p, 1] = seed_x, seed_y
            # -- each sample's point: by the orthogonal array's cell, or a permutation
            if poly != 0:
                for t in range(S):
                    TX[t] = _owen32(_reverse32(t), seed_x)
                    TY[t] = _owen32(_sobol2(t), seed_y)
                for t in range(S):
                    slot[(TY[t] >> (32 - k_s)) * s + (TX[t] >> (32 - k_s))] = t
                for h in range(2):
                    o = h * (s - 1)
                    for t in range(s):
                        sig[h * s + t] = t
                    for t in range(s - 1, 0, -1):
                        a = min(int(keys[p, o + t] * (t + 1)), t)
                        sig[h * s + t], sig[h * s + a] = sig[h * s + a], sig[h * s + t]
                for j in range(S):
                    cx, cy = j % s, j // s
                    acy = (cy << 1) ^ poly if (cy << 1) & s else cy << 1      # alpha cy in GF(2^k)
                    t = slot[sig[s + (cx ^ acy)] * s + sig[cx ^ cy]]
                    NX[b + j] = TX[t]
                    NY[b + j] = TY[t]
            else:
                for j in range(S):
                    pt[b + j] = j
                for j in range(S - 1, 0, -1):
                    a = min(int(keys[p, j] * (j + 1)), j)
                    pt[b + j], pt[b + a] = pt[b + a], pt[b + j]
        if poly != 0:
            X, Y = NX[q], NY[q]
        else:
            t = pt[q]
            X, Y = _owen32(_reverse32(t), seeds[p, 0]), _owen32(_sobol2(t), seeds[p, 1])
        U[i, 0] = min((X + jit[i, 0]) / 4294967296.0, _ONE_BELOW)
        U[i, 1] = min((Y + jit[i, 1]) / 4294967296.0, _ONE_BELOW)


@njit(**_JIT)
def nee_light(rows, P, NG, NS, D, C, crow, E, E_avg, prm, poses, steps, corners, q, cdf, Le, env, T, U, EPS, TERM,
              use_term, mis, stop_coat, contrib, so, sd, stmax, live, S, vis):
    """Next-event estimation of one light at the hit rows ``rows`` (n,); returns the shadow-ray count.

    P, NG, NS, D (m, 3): hit points, geometric / shading normals and ray
    directions of the bounce; C, crow the hits' closures (hit r's is row crow[r] of C); E, E_avg
    the GGX albedo tables (``kernels.bsdf.ggx_albedo_tables``).  The light:
    its parameter row prm, poses (k, 4, 4) (k = 1 static, else one per row of
    ``rows``), mesh arrays and environment (``kernels.light_params``).  T (n,) the rows'
    times, U (n, 2) the light's uniforms, EPS (m,) each hit's shadow-ray
    origin offset (scene units).

    Per row k (hit r = rows[k]), with wo = -D[r]: (wi, dist, weight) =
    ``lights.sample_light_rows`` (the WORLD samples cosine directions about ng
    turned toward wo), f = ``bsdf_eval``(C[crow[r]], wo, wi), contrib[k] = f |ns . wi|
    weight.  Where it is positive, a shadow ray from p offset by EPS[r] along
    ng to wi's side, aimed at the light point, stopping a margin short of it
    (emissive triangles are geometry the shadow ray must not reach): so, sd
    (n, 3), stmax (n,), and live (n,) the row k it belongs to.  With use_term, TERM (m, 7) holds
    each hit's shadow-terminator data (:func:`terminator_rows`): the shadow ray's origin is first
    lifted toward the smooth surface the vertex normals imply (:func:`terminator_origin`, Cycles'
    ``shadow_ray_offset``), the contribution scaled by :func:`shading_offset_factor` (Cycles'
    ``shift_cos_in``) and, below the face on rows without a rough lobe, by :func:`band_nee_weight`
    (light densities are then computed as with mis).  S (>= n, 8): the light samples
    (``sample_light_rows``; a textured MESH light's caller reads the light points from it).
    vis (int): the lobe kinds the light is visible to (Blender's Ray Visibility of the light):
    bits 1 diffuse, 2 glossy (reflection lobes), 4 transmission (refraction); 7 = all.  Below 7
    f keeps only those lobes (``bsdf_eval_lobes``; the caller passes no mis rows then: paths that
    leave a lobe do not see such a light, so next-event estimation carries it whole).

    Rows k with ``mis[k]`` (uint8 bits: 1 a path may go on from them through a rough reflection, 2
    through a rough refraction, ``integrator.mis_rows``; the bit of wi's side counts: camera paths go on from them through their rough lobes,
    :func:`specular_step`, and pick up the light where they reach it: the world where they escape,
    an AREA light, a POINT / SPOT sphere or a SUN's cone seen along the ray, :func:`seen_lights_add`, an
    emitting triangle of a MESH light they hit, :func:`mesh_emission_mis`): the part f_c of f those
    lobes carry, sampled with density p_c (``bsdf_eval_cont``, here with f from one set-up of the hit:
    ``bsdf_eval_split``; every non-delta lobe's, one-sample multiple importance sampling; stop_coat
    as the continuation) is weighed
    by the power heuristic p_l^2 / (p_l^2 + p_c^2) (:func:`mis_weight`), p_l = S[k, 7] the light's own density
    (``sample_light_rows`` with want_pdf, set when any row has mis), and the paths that reach
    the light by p_c / (p_l + p_c) (docs/rendering.md, "Multiple importance sampling").  Delta
    lights and suns of angle 0 (p_l = inf) keep f whole: the paths do not see them.

    Three loops, each with only the code its rows need (a loop that contains a call, even one it
    never takes, saves and reloads its floating-point values around it and runs up to twice
    slower per row; docs/rendering.md "NEE cost"): the light samples (one sampler, chosen once
    per call), the BSDF of the rows whose closure needs a compiled call (``needs_bsdf_call``: the
    mixture of a rough lobe, or the coat / replaced-normal terms of ``bsdf_eval_smooth``) into
    F, then, with no call, the bare diffuse BSDF of the others (``bsdf_eval_plain``), the
    contribution and the shadow ray of every row.  The second loop reads each row's closure once,
    keeping what the last one needs of a bare diffuse (its weight and colour) in F: the last loop
    reads no closure row (with node programs every hit has a 280-byte row of its own, and the
    rows of a tile are several times what the caches hold).
    """
    n = rows.shape[0]
    any_mis = False
    for k in range(n):
        if mis[k] != 0:
            any_mis = True
            break
    sample_light_rows(prm, poses, steps, corners, q, cdf, Le, env, rows, P, NG, D, T, U, S, any_mis or use_term)
    # -- The BSDF of rows that need a call: a rough lobe's mixture (bsdf_eval_pdf), a coat or a
    #    replaced normal (bsdf_eval_smooth) -------------------------------------------------------
    F = np.empty((n, 4))
    call = np.empty(n, np.uint8)
    for k in range(n):
        r = rows[k]
        cr = crow[r]
        if not needs_bsdf_call(C, cr):
            call[k] = 0
            F[k, 0], F[k, 1], F[k, 2], F[k, 3] = C[cr, C_W_BASE], C[cr, C_BASE], C[cr, C_BASE + 1], C[cr, C_BASE + 2]
            if not vis & 1:
                F[k, 0] = 0.0                   # a bare diffuse lobe the light does not light
            continue
        call[k] = 1 if C[cr, C_ROUGH_LOBE] > 0 else 2
        if vis != 7:
            # -- only the lobe kinds the light is visible to (no mis: the caller passes none)
            if C[cr, C_ROUGH_LOBE] > 0:
                F[k, 0], F[k, 1], F[k, 2] = bsdf_eval_lobes(C, cr, E, E_avg, (-D[r, 0], -D[r, 1], -D[r, 2]),
                                                            (S[k, 0], S[k, 1], S[k, 2]), (NS[r, 0], NS[r, 1], NS[r, 2]),
                                                            (NG[r, 0], NG[r, 1], NG[r, 2]), vis)
            elif vis & 1:
                F[k, 0], F[k, 1], F[k, 2] = bsdf_eval_smooth(C, cr, (-D[r, 0], -D[r, 1], -D[r, 2]),
                                                             (S[k, 0], S[k, 1], S[k, 2]), (NS[r, 0], NS[r, 1], NS[r, 2]),
                                                             (NG[r, 0], NG[r, 1], NG[r, 2]))
            else:
                F[k, 0] = F[k, 1] = F[k, 2] = 0.0      # the smooth path's only NEE lobe is the diffuse one
            continue
        if C[cr, C_ROUGH_LOBE] > 0:
            wo = (-D[r, 0], -D[r, 1], -D[r, 2])
            wi = (S[k, 0], S[k, 1], S[k, 2])
            ns = (NS[r, 0], NS[r, 1], NS[r, 2])
            g = (NG[r, 0], NG[r, 1], NG[r, 2])
            if mis[k] != 0 and S[k, 7] < np.inf and mis[k] & (1 if (wi[0] * g[0] + wi[1] * g[1] + wi[2] * g[2])
                                                             * (wo[0] * g[0] + wo[1] * g[1] + wo[2] * g[2]) > 0.0 else 2):
                # f and the continuation's part of it from one set-up of the hit (bsdf_eval_split)
                f0, f1, f2, c0, c1, c2, p_c = bsdf_eval_split(C, cr, E, E_avg, wo, wi, ns, g, stop_coat)
                x = mis_weight(p_c, S[k, 7])
                f0, f1, f2 = f0 - c0 * x, f1 - c1 * x, f2 - c2 * x
            else:
                f0, f1, f2, _ = bsdf_eval_pdf(C, cr, E, E_avg, wo, wi, ns, g)
            F[k, 0], F[k, 1], F[k, 2] = f0, f1, f2
        else:
            F[k, 0], F[k, 1], F[k, 2] = bsdf_eval_smooth(C, cr, (-D[r, 0], -D[r, 1], -D[r, 2]),
                                                         (S[k, 0], S[k, 1], S[k, 2]), (NS[r, 0], NS[r, 1], NS[r, 2]),
                                                         (NG[r, 0], NG[r, 1], NG[r, 2]))
    n_live = 0
    for k in range(n):
        r = rows[k]
        wi0, wi1, wi2, dist, w0, w1, w2 = S[k, 0], S[k, 1], S[k, 2], S[k, 3], S[k, 4], S[k, 5], S[k, 6]
        g = (NG[r, 0], NG[r, 1], NG[r, 2])
        ns = (NS[r, 0], NS[r, 1], NS[r, 2])
        # -- BSDF and the unshadowed contribution ------------------------------------------
        if call[k] != 0:
            f0, f1, f2 = F[k, 0], F[k, 1], F[k, 2]
        else:
            f0, f1, f2 = bsdf_eval_plain_w(F[k, 0], F[k, 1], F[k, 2], F[k, 3], (-D[r, 0], -D[r, 1], -D[r, 2]),
                                           (wi0, wi1, wi2), ns, g)
        cosa = abs(ns[0] * wi0 + ns[1] * wi1 + ns[2] * wi2)
        c0 = f0 * cosa * w0
        c1 = f1 * cosa * w1
        c2 = f2 * cosa * w2
        if use_term:
            if TERM[r, 6] > 1.0:
                x = shading_offset_factor(TERM[r, 6], ns, g, (D[r, 0], D[r, 1], D[r, 2]), (wi0, wi1, wi2))
                c0, c1, c2 = c0 * x, c1 * x, c2 * x
            if call[k] != 1:             # no rough lobe: the band's light is the diffuse lobe's
                x = band_nee_weight(S[k, 7], cosa, g, (D[r, 0], D[r, 1], D[r, 2]), (wi0, wi1, wi2))
                c0, c1, c2 = c0 * x, c1 * x, c2 * x
        contrib[k, 0], contrib[k, 1], contrib[k, 2] = c0, c1, c2
        if not (c0 > 0.0 or c1 > 0.0 or c2 > 0.0):
            continue
        # -- Shadow ray toward the light point --------------------------------------------------
        p = (P[r, 0], P[r, 1], P[r, 2])
        eps = EPS[r]
        if use_term and TERM[r, 5] > 0.0:
            o0, o1, o2 = offset_origin(terminator_origin(TERM, r, p, ns, g, (D[r, 0], D[r, 1], D[r, 2]),
                                                         (wi0, wi1, wi2)), g, eps, (wi0, wi1, wi2))
        else:
            o0, o1, o2 = offset_origin(p, g, eps, (wi0, wi1, wi2))
        so[n_live, 0], so[n_live, 1], so[n_live, 2] = o0, o1, o2
        if np.isfinite(dist):
            v0, v1, v2 = p[0] + dist * wi0 - o0, p[1] + dist * wi1 - o1, p[2] + dist * wi2 - o2
            s = math.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
            inv = 1.0 / s
            sd[n_live, 0], sd[n_live, 1], sd[n_live, 2] = v0 * inv, v1 * inv, v2 * inv
            stmax[n_live] = s * (1.0 - 1e-6) - 2.0 * eps
        else:
            s = math.sqrt(wi0 * wi0 + wi1 * wi1 + wi2 * wi2)
            sd[n_live, 0], sd[n_live, 1], sd[n_live, 2] = wi0 / s, wi1 / s, wi2 / s
            stmax[n_live] = np.inf
        live[n_live] = k
        n_live += 1
    return n_live


@njit(**_JIT)
def offset_rows(rows, inst_offset, instance, P, offset_pos, EPS):
    """EPS[r] for each hit r in rows: ``raycast.geometry.offset_lengths`` of the hit, the object's
    offset inst_offset[instance[r]] + offset_pos x the hit point's largest |coordinate|, with the
    same float operations (numpy's row-wise maximum over 3 columns and the gathers around it cost
    about 40 ns a row, more than next-event estimation's own loop).  Hit points are finite."""
    for k in range(rows.shape[0]):
        r = rows[k]
        m = 0.0
        for a in range(3):
            v = abs(P[r, a])
            if v > m:
                m = v
        EPS[r] = inst_offset[instance[r]] + offset_pos * m


# ----------------------------------------------------------------------------
# Shadow terminator (Cycles' shadow_ray_offset, shift_cos_in; docs/rendering.md "Shadow terminator")
# ----------------------------------------------------------------------------
@njit(**_JIT)
def smooth_surface_heights(Vs, T, Ns, f, u, v):
    """(h_front, h_back, n) of a point of smooth-shaded triangle f: how far (in units of |n|) its
    shadow rays' origin moves along n to reach the smooth surface the vertex normals imply (Hanika
    2021, "Hacking the shadow terminator"; Cycles' ``shadow_ray_smooth_surface_offset``).

    Vs (V, 3) float32 the mesh's vertices, T (F, 3) int32 its triangles, Ns (F, 3, 3) float32 its
    unit corner normals (one space): corners V_i = Vs[T[f, i]], normals N_i = Ns[f, i]; u, v the
    barycentrics of the point P = (1 - u - v) V0 + u V1 + v V2, n = (1 - u - v) N0 + u N1 + v N2
    (not normalised, as Cycles).  The parabola through the corners' tangent planes, with
    a = (N2 - N0) . (V0 - V2), b = (N2 - N1) . (V1 - V2), c = (N1 - N0) . (V1 - V0) and the weights
    (w0, w1, w2) = (1 - u - v, u, v):  h_par = a w0 (w0 - 1) + (a + b + c) w0 w1 + b w1 (w1 - 1).
    Seen from the normals' side (h_front): the local linear envelope, per corner i with
    e_i = max(0, max_j (V_j - V_i) . N_i), h_i = max(0, (V_i - P) . N_i + e_i),
    h_front = max(min_i h_i, h_par / 2).  From the other side (h_back): e_i = max(0, max_j (V_i -
    V_j) . N_i), h_i = max(0, (P - V_i) . N_i + e_i), h_back = min(-min_i h_i, h_par / 2).
    Scalar code (no per-row arrays): the corners are read once into locals.
    """
    i0, i1, i2 = T[f, 0], T[f, 1], T[f, 2]
    A = (np.float64(Vs[i0, 0]), np.float64(Vs[i0, 1]), np.float64(Vs[i0, 2]))
    B = (np.float64(Vs[i1, 0]), np.float64(Vs[i1, 1]), np.float64(Vs[i1, 2]))
    Cc = (np.float64(Vs[i2, 0]), np.float64(Vs[i2, 1]), np.float64(Vs[i2, 2]))
    NA = (np.float64(Ns[f, 0, 0]), np.float64(Ns[f, 0, 1]), np.float64(Ns[f, 0, 2]))
    NB = (np.float64(Ns[f, 1, 0]), np.float64(Ns[f, 1, 1]), np.float64(Ns[f, 1, 2]))
    NC = (np.float64(Ns[f, 2, 0]), np.float64(Ns[f, 2, 1]), np.float64(Ns[f, 2, 2]))
    return corner_heights(A, B, Cc, NA, NB, NC, u, v)


@njit(**_JIT)
def _vertex_at(Vs, s, a, i):
    """Vertex i (3-tuple, float64) of Vs (K, V, 3) at step s + fraction a (K = 1: step 0)."""
    x0, x1, x2 = np.float64(Vs[s, i, 0]), np.float64(Vs[s, i, 1]), np.float64(Vs[s, i, 2])
    if Vs.shape[0] == 1:
        return x0, x1, x2
    return (x0 + a * (np.float64(Vs[s + 1, i, 0]) - x0), x1 + a * (np.float64(Vs[s + 1, i, 1]) - x1),
            x2 + a * (np.float64(Vs[s + 1, i, 2]) - x2))


@njit(**_JIT)
def _normal_at(Ns, s, a, f, j):
    """Corner j's normal (3-tuple, float64) of triangle f of Ns (K, F, 3, 3) at step s + fraction a."""
    x0, x1, x2 = np.float64(Ns[s, f, j, 0]), np.float64(Ns[s, f, j, 1]), np.float64(Ns[s, f, j, 2])
    if Ns.shape[0] == 1:
        return x0, x1, x2
    return (x0 + a * (np.float64(Ns[s + 1, f, j, 0]) - x0), x1 + a * (np.float64(Ns[s + 1, f, j, 1]) - x1),
            x2 + a * (np.float64(Ns[s + 1, f, j, 2]) - x2))


@njit(**_JIT)
def corner_heights(A, B, Cc, NA, NB, NC, u, v):
    """:func:`smooth_surface_heights` of the triangle with corners A, B, Cc and corner normals NA,
    NB, NC (3-tuples, float64, one space) at barycentrics u, v."""
    w0 = 1.0 - u - v
    w1, w2 = u, v
    P = (w0 * A[0] + w1 * B[0] + w2 * Cc[0], w0 * A[1] + w1 * B[1] + w2 * Cc[1], w0 * A[2] + w1 * B[2] + w2 * Cc[2])
    n = (w0 * NA[0] + w1 * NB[0] + w2 * NC[0], w0 * NA[1] + w1 * NB[1] + w2 * NC[1],
         w0 * NA[2] + w1 * NB[2] + w2 * NC[2])
    a = ((NC[0] - NA[0]) * (A[0] - Cc[0]) + (NC[1] - NA[1]) * (A[1] - Cc[1]) + (NC[2] - NA[2]) * (A[2] - Cc[2]))
    b = ((NC[0] - NB[0]) * (B[0] - Cc[0]) + (NC[1] - NB[1]) * (B[1] - Cc[1]) + (NC[2] - NB[2]) * (B[2] - Cc[2]))
    c = ((NB[0] - NA[0]) * (B[0] - A[0]) + (NB[1] - NA[1]) * (B[1] - A[1]) + (NB[2] - NA[2]) * (B[2] - A[2]))
    h_par = a * w0 * (w0 - 1.0) + (a + b + c) * w0 * w1 + b * w1 * (w1 - 1.0)
    # (V_j - V_i) . N_i for the six ordered pairs, and (V_i - P) . N_i
    dAB, dAC = dot((B[0] - A[0], B[1] - A[1], B[2] - A[2]), NA), dot((Cc[0] - A[0], Cc[1] - A[1], Cc[2] - A[2]), NA)
    dBA, dBC = dot((A[0] - B[0], A[1] - B[1], A[2] - B[2]), NB), dot((Cc[0] - B[0], Cc[1] - B[1], Cc[2] - B[2]), NB)
    dCA, dCB = dot((A[0] - Cc[0], A[1] - Cc[1], A[2] - Cc[2]), NC), dot((B[0] - Cc[0], B[1] - Cc[1], B[2] - Cc[2]), NC)
    qA = dot((A[0] - P[0], A[1] - P[1], A[2] - P[2]), NA)
    qB = dot((B[0] - P[0], B[1] - P[1], B[2] - P[2]), NB)
    qC = dot((Cc[0] - P[0], Cc[1] - P[1], Cc[2] - P[2]), NC)
    hA = max(qA + max(max(dAB, dAC), 0.0), 0.0)
    hB = max(qB + max(max(dBA, dBC), 0.0), 0.0)
    hC = max(qC + max(max(dCA, dCB), 0.0), 0.0)
    h_front = max(min(hA, min(hB, hC)), 0.5 * h_par)
    hA = max(-qA + max(max(-dAB, -dAC), 0.0), 0.0)
    hB = max(-qB + max(max(-dBA, -dBC), 0.0), 0.0)
    hC = max(-qC + max(max(-dCA, -dCB), 0.0), 0.0)
    h_back = min(-min(hA, min(hB, hC)), 0.5 * h_par)
    return h_front, h_back, n


@njit(**_JIT)
def terminator_rows(rows, prim, Vs, T, Ns, SEG, AL, M, BU, BV, cut, freq, TERM):
    """TERM[r] (7,) of hit rows r = rows[k] on one object's smooth-shaded triangles prim[r]: (n_w (3),
    h_front, h_back, cutoff, frequency multiplier), read by :func:`nee_light`.

    Vs (K, V, 3) float32, T (F, 3) int32, Ns (K, F, 3, 3) float32: the object's mesh in object
    space at its K vertex steps (K = 1: rigid); SEG (k,) int64 and AL (k,) float64 each row's step
    and fraction into it (:func:`stpm_core.raycast.geometry.segment_of` of the hit time): corners
    and corner normals are interpolated linearly between the steps, as the ray caster does them,
    before :func:`corner_heights`.  M (k or 1, 3, 3) the object-to-world linear part at the hits'
    times; BU, BV (m,) the hits' barycentrics; cut the object's ``shadow_terminator_geometry_offset``,
    freq its shading offset's frequency multiplier 1 / (1 - s / 2).  The heights in object space,
    n_w = M n (Cycles' ``object_dir_transform``): the lift n_w h is the object-space lift n h carried
    to world space."""
    one = M.shape[0] == 1
    for k in range(rows.shape[0]):
        r = rows[k]
        f = np.int64(prim[r])
        s, a = np.int64(SEG[k]), np.float64(AL[k])
        A = _vertex_at(Vs, s, a, np.int64(T[f, 0]))
        B = _vertex_at(Vs, s, a, np.int64(T[f, 1]))
        Cc = _vertex_at(Vs, s, a, np.int64(T[f, 2]))
        hf, hb, n = corner_heights(A, B, Cc, _normal_at(Ns, s, a, f, np.int64(0)),
                                   _normal_at(Ns, s, a, f, np.int64(1)), _normal_at(Ns, s, a, f, np.int64(2)),
                                   BU[r], BV[r])
        m = 0 if one else k
        TERM[r, 0] = M[m, 0, 0] * n[0] + M[m, 0, 1] * n[1] + M[m, 0, 2] * n[2]
        TERM[r, 1] = M[m, 1, 0] * n[0] + M[m, 1, 1] * n[1] + M[m, 1, 2] * n[2]
        TERM[r, 2] = M[m, 2, 0] * n[0] + M[m, 2, 1] * n[1] + M[m, 2, 2] * n[2]
        TERM[r, 3], TERM[r, 4], TERM[r, 5], TERM[r, 6] = hf, hb, cut, freq


@njit(**_JIT)
def terminator_origin(TERM, r, p, ns, g, d, wi):
    """p lifted toward the smooth surface for a shadow ray toward wi (Cycles' ``shadow_ray_offset``).

    ns, g: the hit's shading and geometric normals, d the arriving ray's direction; both normals
    are first turned to face the viewer (N = ns, Ng = g, negated when g . d > 0).  With
    N_L = |N . wi| (transmit: N . wi < 0, then Ng -> -Ng), NgL = Ng . wi and the cutoff c =
    TERM[r, 5]:  amount = clip(2 - (NgL + N_L) / c, 0, 1) where N_L < c, else clip(1 - NgL / c,
    0, 1); the origin is p + amount h n_w, h = TERM[r, 3] where n_w . Ng > 0 (the normals' side),
    else TERM[r, 4] (:func:`smooth_surface_heights`)."""
    s = -1.0 if g[0] * d[0] + g[1] * d[1] + g[2] * d[2] > 0.0 else 1.0
    NL = s * (ns[0] * wi[0] + ns[1] * wi[1] + ns[2] * wi[2])
    if NL < 0.0:
        NL = -NL
        s = -s
    Ng0, Ng1, Ng2 = s * g[0], s * g[1], s * g[2]
    NgL = Ng0 * wi[0] + Ng1 * wi[1] + Ng2 * wi[2]
    c = TERM[r, 5]
    if NL < c:
        amount = min(max(2.0 - (NgL + NL) / c, 0.0), 1.0)
    else:
        amount = min(max(1.0 - NgL / c, 0.0), 1.0)
    if not amount > 0.0:
        return p
    n0, n1, n2 = TERM[r, 0], TERM[r, 1], TERM[r, 2]
    h = TERM[r, 3] if n0 * Ng0 + n1 * Ng1 + n2 * Ng2 > 0.0 else TERM[r, 4]
    x = amount * h
    return p[0] + x * n0, p[1] + x * n1, p[2] + x * n2


@njit(**_JIT)
def band_nee_weight(p_l, cos_s, g, d, wi):
    """Cycles' weight of a light sample below the face but above the shading normal (the band next
    to a smooth mesh's terminator): p_l^2 / (p_l^2 + p_b^2), p_b = cos_s / pi the diffuse lobe's
    density at wi (cos_s = |ns . wi|), p_l the light's (``sample_light_rows``); 1 above the face
    (g turned toward the viewer, d the arriving ray) and for delta lights and suns of angle 0 (p_l = inf).

    Cycles weighs next-event estimation against the BSDF's own samples with the density its
    ``bsdf_eval`` returns, which counts the band, while ``bsdf_diffuse_sample`` never returns a
    direction below the face: the band's light reaches a Cycles image only through this weighed
    sample (measured: a smooth box under an HDRI 0.7 % brighter than Cycles without it).  STPM's
    camera paths end at the diffuse lobe and count next-event estimation whole elsewhere."""
    s = -1.0 if g[0] * d[0] + g[1] * d[1] + g[2] * d[2] > 0.0 else 1.0
    if s * (g[0] * wi[0] + g[1] * wi[1] + g[2] * wi[2]) >= 0.0:
        return 1.0
    return 1.0 - mis_weight(cos_s * _INV_PI, p_l)


@njit(**_JIT)
def shading_offset_factor(fm, ns, g, d, wi):
    """Cycles' shading offset (``shift_cos_in``, from appleseed) for a light direction wi: with
    cos = N . wi (N: ns turned to face the viewer, g . d < 0), max(cos(fm acos(min(cos, 1))), 0) /
    cos where cos > 0, else 1.  fm = 1 / (1 - s / 2) for the object's
    ``shadow_terminator_shading_offset`` s; at fm = 1 the factor is 1."""
    s = -1.0 if g[0] * d[0] + g[1] * d[1] + g[2] * d[2] > 0.0 else 1.0
    cos = s * (ns[0] * wi[0] + ns[1] * wi[1] + ns[2] * wi[2])
    if not cos > 0.0:
        return 1.0
    cos = min(cos, 1.0)
    return max(math.cos(fm * math.acos(cos)), 0.0) / cos


@njit(**_JIT)
def nee_accumulate(dst, rows, idx, use_idx, beta, use_beta, contrib, live, blocked, clamp):
    """dst[idx[rows[k]]] += beta[rows[k]] * contrib[k], k = live[j], for every shadow ray j not blocked.

    dst (n, 3) the Direct pass of the samples; rows (K,) the hit rows shaded;
    idx / beta optional as in :func:`scatter_add`; each light sample's contribution clamped to
    ``clamp`` (0: off).
    """
    for j in range(live.shape[0]):
        if not blocked[j]:
            k = live[j]
            _add_row(dst, rows[k], idx, use_idx, beta, use_beta, contrib, k, clamp)


# ----------------------------------------------------------------------------
# Light shapes seen along rays
# ----------------------------------------------------------------------------
@njit(**_JIT)
def seen_lights_add(prm, poses, O, D, t_scene, camera_ray, L, Lw, glossy, use_glossy, p_c):
    """L[r] += radiance of this light's shape hit by ray r (O + s D, unit D) before t_scene[r]; Lw[r]
    += the same weighed for multiple importance sampling.

    ``kernels.lights.seen_light`` per row; poses (k, 4, 4), k = 1 or one per ray.  The
    caller skips lights that camera rays may not see (Blender's visible_camera).  Rows that
    left a rough lobe (``glossy[r]``, when use_glossy; next-event estimation at that vertex
    drew this light with density p_l, ``lights.light_pdf`` from the ray's origin) add to Lw the
    radiance times the power heuristic :func:`mis_weight`(p_c[r], p_l), p_c the density with which the
    lobe drew D[r] (:func:`specular_step`); the others add it whole.  L (the denoising features'
    look) gets the radiance unweighed.
    """
    one = poses.shape[0] == 1
    M = pose_buffer(poses)                   # refilled per ray only when the light moves (no views per row)
    for r in range(O.shape[0]):
        if not one:
            load_pose(poses, r, M)
        l0, l1, l2 = seen_light(prm, M, row3(O, r), row3(D, r), t_scene[r], camera_ray)
        if not (l0 > 0.0 or l1 > 0.0 or l2 > 0.0):
            continue
        L[r, 0] += l0
        L[r, 1] += l1
        L[r, 2] += l2
        w = 1.0
        if use_glossy and glossy[r] != 0:
            w = mis_weight(p_c[r], light_pdf(prm, M, row3(O, r), row3(D, r)))
        Lw[r, 0] += l0 * w
        Lw[r, 1] += l1 * w
        Lw[r, 2] += l2 * w


@njit(**_JIT)
def mis_weight(p_c, p_l):
    """Cycles' power heuristic p_c^2 / (p_c^2 + p_l^2): the weight of a path that reached a light
    through a rough lobe (density p_c) against next-event estimation's p_l (which weighs its own
    sample by 1 minus it); 1 for p_l = 0 (next-event estimation could not draw it), 0 for p_l =
    inf (a light it alone counts) or p_c = 0."""
    if not p_l > 0.0:
        return 1.0
    if not p_l < np.inf or not p_c > 0.0:
        return 0.0
    a, b = p_c * p_c, p_l * p_l
    return a / (a + b)


@njit(**_JIT)
def mesh_emission_mis(rows, O, P, T, p_c, poses, steps, corners, q, J, W):
    """W[k] *= :func:`mis_weight`(p_c, p_l) of hit row r = rows[k] (a ray that left a rough
    lobe with density p_c[r] from O[r] and hit P[r], on emitting triangle J[k] of a MESH light, at
    normalised time T[r]), p_l the density with which next-event estimation at O[r] draws that
    point (``lights.mesh_light_pdf``; poses (1 or k, 4, 4) the light's, steps, corners, q its
    arrays).  J[k] < 0 (the triangle is not the light's): W[k] unchanged."""
    one = poses.shape[0] == 1
    M = pose_buffer(poses)
    for k in range(rows.shape[0]):
        j = J[k]
        if j < 0:
            continue
        if not one:
            load_pose(poses, k, M)
        r = rows[k]
        W[k] *= mis_weight(p_c[r], mesh_light_pdf(M, steps, corners, q, j, T[r], row3(O, r), row3(P, r)))


@njit(**_JIT)
def emission_rows_add(dst, rows, C, crow, W, idx, use_idx, beta, use_beta, clamp):
    """dst[idx[r]] += beta[r] W[k] emission of C[crow[r]] for r = rows[k] (idx / beta optional), each
    clamped to ``clamp`` (0: off)."""
    for k in range(rows.shape[0]):
        r = rows[k]
        cr = crow[r]
        w = W[k]
        if not w > 0.0:
            continue
        i = idx[r] if use_idx else r
        c0, c1, c2 = w * C[cr, C_EMIT], w * C[cr, C_EMIT + 1], w * C[cr, C_EMIT + 2]
        if use_beta:
            c0, c1, c2 = c0 * beta[r, 0], c1 * beta[r, 1], c2 * beta[r, 2]
        _add_clamped(dst, i, c0, c1, c2, clamp)


# ----------------------------------------------------------------------------
# Photon-map look-ups at shaded vertices
# ----------------------------------------------------------------------------
@njit(**_JIT)
def photon_albedo(rows, P, NS, D, C, crow, E, T, rho, p_q, n_q, t_q, live):
    """Diffuse albedo rho (n, 3) of the shaded rows ``rows`` (n,) and the query rows of a look-up.

    rho[k] = ``diffuse_albedo``(C[crow[r]], E, wo, ns_f) (E: the GGX tables) with ns_f the shading normal
    turned toward wo = -D[r].  Rows with some rho > 0 are queried: their
    point, ns_f and time go to p_q, n_q (n, 3) and t_q (n,), their k to live;
    returns how many.
    """
    n_live = 0
    for k in range(rows.shape[0]):
        r = rows[k]
        wo = (-D[r, 0], -D[r, 1], -D[r, 2])
        s0, s1, s2 = NS[r, 0], NS[r, 1], NS[r, 2]
        if s0 * wo[0] + s1 * wo[1] + s2 * wo[2] < 0.0:
            s0, s1, s2 = -s0, -s1, -s2
        a0, a1, a2 = diffuse_albedo(C, crow[r], E, wo, (s0, s1, s2))
        rho[k, 0], rho[k, 1], rho[k, 2] = a0, a1, a2
        if a0 > 0.0 or a1 > 0.0 or a2 > 0.0:
            p_q[n_live, 0], p_q[n_live, 1], p_q[n_live, 2] = P[r, 0], P[r, 1], P[r, 2]
            n_q[n_live, 0], n_q[n_live, 1], n_q[n_live, 2] = s0, s1, s2
            t_q[n_live] = T[k]
            live[n_live] = k
            n_live += 1
    return n_live


@njit(**_JIT)
def photon_add(dst, rows, live, rho, E, idx, use_idx, beta, use_beta, clamp):
    """dst[idx[rows[k]]] += beta[rows[k]] * rho[k] / pi * E[j], k = live[j]: a photon pass (n, 3) gets
    the radiance of the irradiance estimates E (j, 3) W/m^2 at the queried rows, each clamped to
    ``clamp`` (0: off)."""
    for j in range(live.shape[0]):
        k = live[j]
        r = rows[k]
        i = idx[r] if use_idx else r
        v0 = rho[k, 0] / np.pi * E[j, 0]
        v1 = rho[k, 1] / np.pi * E[j, 1]
        v2 = rho[k, 2] / np.pi * E[j, 2]
        if use_beta:
            v0, v1, v2 = beta[r, 0] * v0, beta[r, 1] * v1, beta[r, 2] * v2
        _add_clamped(dst, i, v0, v1, v2, clamp)


# ----------------------------------------------------------------------------
# Continuing through delta lobes
# ----------------------------------------------------------------------------
@njit(**_JIT)
def specular_step(spec, idx, use_idx, beta, use_beta, P, NG, NS, D, C, crow, E, E_avg, U, rr, U_rr, EPS, guard_fraction,
                  stop_coat, tau, env, wposes, world_mis, counts, max_glossy, max_transmission, idx_out, beta_out, o_out,
                  d_out, guard_out, glossy_out, world_w_out, pc_out, counts_out, use_feat, feat, dft, feat_out, dft_out):
    """Continue the hit rows spec (k,) through their delta and rough non-diffuse lobes; returns how
    many paths go on.

    Per row j (hit r = spec[j]): (wi, weight, kind, p_c, u_w) = ``bsdf_sample_cont``(C[crow[r]],
    wo = -D[r], U[j], stop_coat): a delta lobe continues the path, and so does any non-delta pick
    with the rough lobes' part of f (one-sample multiple importance sampling over the lobes; the
    DIFFUSE lobe's own light is the photon maps', docs/rendering.md, "Path partition" and
    "Continuation weights"); beta' = beta[r] * weight (weight alone when not use_beta).  The path
    goes on if some beta' > 0; where a DIFFUSE pick drew wi (u_w >= 0) only if u_w < q = min(max
    beta' / tau, 1), then beta' /= q (Russian roulette: such picks are most hits of a coated
    diffuse, with small weights; tau = ``integrator.CONT_RR``); and, when rr
    (Russian roulette from ``integrator.RR_START`` bounces on), if U_rr[j] < q =
    clip(max beta', 0.05, 1), then beta' /= q.  For those: idx_out = the sample (idx[r], or r),
    beta_out = beta', the next ray from p offset by EPS[j] along ng to wi's side (o_out, d_out =
    wi), its self-intersection guard guard_out = guard_fraction * EPS[j], and glossy_out = 1 after
    a rough lobe (the lights the next vertex reaches are then weighed against next-event
    estimation at this one), 0 after a delta lobe.  world_w_out: the weight of the
    world's radiance if the ray escapes: 1 after a delta lobe; after a rough lobe, with
    world_mis (the world is a light of next-event estimation, :func:`nee_light`), the power
    heuristic :func:`mis_weight` of the continuation's density p_c against the world's own p_l
    (``lights.world_nee_pdf``; env and wposes (1 or k, 4, 4) its mapping), else 0.  pc_out: the
    continuation's density p_c (1/sr) after a rough lobe (inf after a delta lobe), against which
    the lights the ray reaches are weighed (:func:`seen_lights_add`, :func:`mesh_emission_mis`).

    Bounce budgets, as Cycles' Glossy / Transmission bounces: counts (k, 2) int32 the row's
    reflections and transmissions so far (counts_out the next rays' after this one).  A lobe,
    delta or rough, goes on while the count of the kind it sampled is below max_glossy (a
    reflection) or max_transmission (wi below the face, a refraction), as Cycles counts them (the
    same condition that gives next-event estimation at the row its multiple-importance weight on
    that side of the surface, ``integrator.mis_rows``).

    use_feat: the denoising features go on with the paths (feat (m,) uint8 and dft (m, 3) of
    :func:`denoising_rows`, indexed by hit row, copied to feat_out, dft_out of the next rays).
    """
    one_w = wposes.shape[0] == 1
    M = pose_buffer(wposes)                  # no views or tuple items per row (sampling.row3)
    func, par, portals = env[1], env[4], env[5]
    n_go = 0
    for j in range(spec.shape[0]):
        r = spec[j]
        wo = (-D[r, 0], -D[r, 1], -D[r, 2])
        g = (NG[r, 0], NG[r, 1], NG[r, 2])
        wi0, wi1, wi2, w0, w1, w2, kind, p_c, u_w = bsdf_sample_cont(C, crow[r], E, E_avg, wo,
                                                                     (NS[r, 0], NS[r, 1], NS[r, 2]), g, U[j, 0], U[j, 1],
                                                                     U[j, 2], stop_coat)
        if use_beta:
            b0, b1, b2 = beta[r, 0] * w0, beta[r, 1] * w1, beta[r, 2] * w2
        else:
            b0, b1, b2 = w0, w1, w2
        go = kind != PATH_STOP and (b0 > 0.0 or b1 > 0.0 or b2 > 0.0)
        n_gl, n_tr = counts[j, 0], counts[j, 1]
        g_f = g if dot(g, wo) >= 0.0 else (-g[0], -g[1], -g[2])
        trans = g_f[0] * wi0 + g_f[1] * wi1 + g_f[2] * wi2 < 0.0
        if trans:
            go = go and n_tr < max_transmission
        else:
            go = go and n_gl < max_glossy
        if go and u_w >= 0.0:
            # Russian roulette where a DIFFUSE pick carries the rough lobes' part of f (small
            # weights on most hits of a coated diffuse): a path whose beta' is below tau goes on
            # with probability beta' / tau and then carries tau
            q = min(max(b0, max(b1, b2)) / tau, 1.0)
            go = u_w < q
            b0, b1, b2 = b0 / q, b1 / q, b2 / q
        if rr:
            q = min(max(max(b0, max(b1, b2)), 0.05), 1.0)
            go = go and U_rr[j] < q
            b0, b1, b2 = b0 / q, b1 / q, b2 / q
        if not go:
            continue
        idx_out[n_go] = idx[r] if use_idx else r
        beta_out[n_go, 0], beta_out[n_go, 1], beta_out[n_go, 2] = b0, b1, b2
        e = EPS[j]
        o_out[n_go, 0], o_out[n_go, 1], o_out[n_go, 2] = offset_origin((P[r, 0], P[r, 1], P[r, 2]), g, e,
                                                                       (wi0, wi1, wi2))
        d_out[n_go, 0], d_out[n_go, 1], d_out[n_go, 2] = wi0, wi1, wi2
        guard_out[n_go] = guard_fraction * e
        glossy_out[n_go] = 1 if kind == PATH_GLOSSY else 0
        w_world = 1.0
        if kind == PATH_GLOSSY:
            w_world = 0.0
            if world_mis:
                if not one_w:
                    load_pose(wposes, j, M)
                p_l = world_nee_pdf(func, par, portals, M, (P[r, 0], P[r, 1], P[r, 2]), g_f, (wi0, wi1, wi2))
                w_world = mis_weight(p_c, p_l)
        world_w_out[n_go] = w_world
        pc_out[n_go] = p_c if kind == PATH_GLOSSY else np.inf
        counts_out[n_go, 0] = n_gl + (0 if trans else 1)
        counts_out[n_go, 1] = n_tr + (1 if trans else 0)
        if use_feat:
            feat_out[n_go] = feat[r]
            dft_out[n_go, 0], dft_out[n_go, 1], dft_out[n_go, 2] = dft[r, 0], dft[r, 1], dft[r, 2]
        n_go += 1
    return n_go


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

    Samples as :func:`camera_tile` lays them out (pixel p = (p % tw,
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
