"""The numpy camera-path tracer the compiled kernels replaced, kept as a slow reference.

The same estimator as ``stpm_core.integrator`` (docs/rendering.md): stratified
camera samples, each at its own shutter time, delta chains from the camera,
next-event estimation and photon-map look-ups at the first non-delta vertex,
every random number drawn in the same order as the kernels' driver.  Written
with whole-array numpy operations on the numpy BSDF and light oracles, so
``trace_image_numpy`` renders a tiny scene to the same image as
``integrator.trace_image`` up to float rounding (tests/test_kernel_paths.py).
Nothing in ``stpm_core`` imports this module.
"""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from oracles import lights_numpy
from oracles.bsdf_numpy import bsdf_eval, bsdf_eval_cont, bsdf_sample_cont, diffuse_albedo, emission, has_nondelta
from stpm_core.bsdf import MaterialTable
from stpm_core.camera import camera_to_world, image_plane
from stpm_core.film import DEPTH_BACKGROUND, PASSES, Film, filter_offsets
from stpm_core.integrator import CONT_RR, RR_START, STREAM_CAMERA, BATCH_SAMPLES, TraceStats, _map_kinds
from stpm_core.raycast.geometry import GUARD_FRACTION, instance_offsets, offset_lengths
from stpm_core.sampling import rng_for, skip_uniforms

__all__ = ["camera_samples", "generate_rays", "shade_paths", "trace_image_numpy", "tile_sums_numpy"]


# ----------------------------------------------------------------------------
# Camera samples and rays
# ----------------------------------------------------------------------------
def camera_samples(ix: np.ndarray, iy: np.ndarray, spp: int, shutter, rng: np.random.Generator,
                   time_override: float | None = None, *, filter_width: float
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Film positions and times for ``spp`` samples in each of the pixels (ix, iy) (P,).

    Returns px, py (P*spp,) continuous pixel coordinates and times (P*spp,)
    normalised shutter times (sample-major within each pixel).

    Position: uniforms u on a rows x cols jittered grid per pixel (rows =
    floor(sqrt spp), cols = spp // rows), leftover samples uniform, placed by
    the pixel filter (filter importance sampling, ``film.filter_offsets``):
    px = ix + 1/2 + filter_offsets(u_x, filter_width), likewise py; the box
    filter (``filter_width`` 0) keeps px = ix + u_x.  Time: xi = (pi_p(j) + U) / spp
    with pi_p a random permutation per pixel, mapped through ``shutter.sample``
    (the shutter curve's inverse CDF); ``time_override`` fixes every time.
    The time numbers take their place in the random stream in every case (an
    instant shutter sees the paths of a very short one).
    """
    P, S = ix.shape[0], int(spp)
    rows = max(1, int(np.floor(np.sqrt(S))))
    cols = max(1, S // rows)
    m = rows * cols
    # Position strata: cell j = (j % cols, j // cols), jittered
    cy, cx = np.divmod(np.arange(m), cols)
    jit = rng.random((P, S, 2))
    ux = np.concatenate([np.broadcast_to((cx / cols), (P, m)) + jit[:, :m, 0] / cols, jit[:, m:, 0]], axis=1)
    uy = np.concatenate([np.broadcast_to((cy / rows), (P, m)) + jit[:, :m, 1] / rows, jit[:, m:, 1]], axis=1)
    if filter_width > 0:
        px = (ix[:, None] + 0.5 + filter_offsets(ux, filter_width)).ravel()
        py = (iy[:, None] + 0.5 + filter_offsets(uy, filter_width)).ravel()
    else:
        px = (ix[:, None] + ux).ravel()
        py = (iy[:, None] + uy).ravel()
    # Time strata, permuted independently in each pixel (when every time is the same the
    # numbers are skipped, not made: the stream stays where drawing them would leave it)
    if time_override is not None or shutter.is_instant:
        skip_uniforms(rng, 2 * P * S)
        times = np.full(P * S, float(time_override)) if time_override is not None else shutter.sample(np.zeros(P * S))
        return px, py, times
    perm = np.argsort(rng.random((P, S)), axis=1)
    xi = ((perm + rng.random((P, S))) / S).ravel()
    return px, py, shutter.sample(xi)


def generate_rays(camera, resolution, px: np.ndarray, py: np.ndarray, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Primary rays through continuous pixel positions at their own times.

    Parameters
    ----------
    camera : scene.Camera.
    resolution : (W, H) pixels.
    px, py : (n,) float pixel coordinates (px left -> right, py top -> bottom).
    times : (n,) normalised shutter times.

    Returns
    -------
    origins : (n, 3) world positions (PERSP: the camera position; ORTHO: on the
        plane at ``clip_start`` in front of the camera).
    dirs : (n, 3) unit world directions.
    """
    px = np.asarray(px, dtype=np.float64)
    py = np.asarray(py, dtype=np.float64)
    W, H = int(resolution[0]), int(resolution[1])
    half_w, half_h, cx, cy = image_plane(camera, resolution)
    # Image-plane point: x right, y up (row 0 = top)
    x = cx + (2.0 * px / W - 1.0) * half_w
    y = cy + (1.0 - 2.0 * py / H) * half_h
    R, pos = camera_to_world(camera, times)
    if camera.transform.is_static:
        R, pos = R[:1], pos[:1]                  # one pose: matrix products, not per-ray einsum
    if camera.type == "ORTHO":
        # Parallel rays down -Z from the plane at clip_start
        local_o = np.stack([x, y, np.full_like(x, -float(camera.clip_start))], axis=-1)
        origins = (local_o @ R[0].T + pos[0]) if R.shape[0] == 1 else np.einsum("nij,nj->ni", R, local_o) + pos
        dirs = np.broadcast_to(-R[:, :, 2], (x.shape[0], 3))
    else:
        # Pinhole: the ray through (x, y, -1) on the plane at unit distance
        local_d = np.stack([x, y, -np.ones_like(x)], axis=-1)
        dirs = (local_d @ R[0].T) if R.shape[0] == 1 else np.einsum("nij,nj->ni", R, local_d)
        dirs /= np.sqrt(np.einsum("ij,ij->i", dirs, dirs))[:, None]
        origins = np.broadcast_to(pos, (x.shape[0], 3)).copy()
    return origins, np.ascontiguousarray(dirs)



# ----------------------------------------------------------------------------
# Shading helpers
# ----------------------------------------------------------------------------
def _offset(p: np.ndarray, ng: np.ndarray, w: np.ndarray, eps: np.ndarray) -> np.ndarray:
    """Ray origin p moved by eps (n,) along ng to the side w (n, 3) points to."""
    side = np.where(np.sum(ng * w, axis=1) >= 0.0, 1.0, -1.0)
    return p + (eps * side)[:, None] * ng


def _eps_rows(ctx, instance: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Origin offsets (n,) for secondary rays leaving hits on ``instance`` (n,) at p (n, 3): local to
    the object hit and to the point's float32 resolution (raycast.geometry.offset_lengths)."""
    return offset_lengths(ctx.inst_offset, instance, p)


def _face_forward(n: np.ndarray, w: np.ndarray) -> np.ndarray:
    """n (n, 3) flipped to the hemisphere of w (n, 3)."""
    return n * np.where(np.sum(n * w, axis=1) >= 0.0, 1.0, -1.0)[:, None]


def _rows(a: np.ndarray, sel: np.ndarray | None) -> np.ndarray:
    """a[sel], or a itself when sel is None (every row, in order: no copy)."""
    return a if sel is None else a[sel]


def _is_delta_light(light) -> bool:
    """A light sampled without random numbers: POINT / SPOT of radius 0, SUN of angle 0."""
    if light.type in ("POINT", "SPOT"):
        return float(light.radius) <= 0.0
    return light.type == "SUN" and float(light.angle) <= 0.0


_M32 = np.uint64(0xFFFFFFFF)


def _u32_mul(x: np.ndarray, c: int) -> np.ndarray:
    return (x * np.uint64(c)) & _M32


def _bits_reversed(v: np.ndarray) -> np.ndarray:
    """(uint64) the 32 bits of v in reverse order, bit by bit."""
    out = np.zeros_like(v)
    for b in range(32):
        out |= ((v >> np.uint64(b)) & np.uint64(1)) << np.uint64(31 - b)
    return out


def _hash(x: np.ndarray) -> np.ndarray:
    x = x ^ (x >> np.uint64(16))
    x = _u32_mul(x, 0x7FEB352D)
    x = x ^ (x >> np.uint64(15))
    x = _u32_mul(x, 0x846CA68B)
    return x ^ (x >> np.uint64(16))


def _owen(v: np.ndarray, seed: np.ndarray) -> np.ndarray:
    """Burley's hash-based Owen scramble of 32-bit fractions v with seeds (broadcast)."""
    x = (_bits_reversed(v) + seed) & _M32
    for c in (0x6C50B47C, 0xB82F1E52, 0xC7AFE638, 0x8D22F6E6):
        x = x ^ _u32_mul(x, c)
    return _bits_reversed(x)


def _sobol_second(i: np.ndarray) -> np.ndarray:
    """Sobol's second coordinate of indices i as 32-bit fractions: digit d (weight 2^-d) is the parity of
    sum_j C(j, d - 1) i_j, i_j the bits of i (Pascal's matrix; C(j, k) is odd iff k's bits are j's, Lucas)."""
    y = np.zeros(i.shape, np.uint64)
    for d in range(1, 33):
        par = np.zeros(i.shape, np.uint64)
        for j in range(32):
            if (d - 1) & j == d - 1:
                par ^= (i >> np.uint64(j)) & np.uint64(1)
        y |= par << np.uint64(32 - d)
    return y


def _shuffle(keys: np.ndarray, n: int) -> np.ndarray:
    """(P, n): a random permutation of range(n) per row, Fisher-Yates with keys (P, >= n): from the
    identity, for t = n - 1 down to 1 swap entries t and min(floor(keys[:, t] (t + 1)), t)."""
    perm = np.tile(np.arange(n), (keys.shape[0], 1))
    pix = np.arange(keys.shape[0])
    for t in range(n - 1, 0, -1):
        a = np.minimum((keys[:, t] * (t + 1)).astype(np.int64), t)
        perm[pix, t], perm[pix, a] = perm[pix, a], perm[pix, t].copy()
    return perm


def _gf_times_alpha(v: np.ndarray, s: int) -> np.ndarray:
    """alpha v in GF(s), s = 2^k (alpha = x; the field's polynomial from a table)."""
    polys = {4: 0b111, 8: 0b1011, 16: 0b10011, 32: 0b100101, 64: 0b1000011, 128: 0b10001001,
             256: 0b100011101, 512: 0b1000010001, 1024: 0b10000001001}
    w = 2 * v
    return np.where(w >= s, w ^ polys[s], w)


def _light_uniforms(light, samples: np.ndarray, strata: tuple, rng: np.random.Generator) -> np.ndarray:
    """Uniforms (k, 2) for one light's samples at the k shaded rows whose tile samples are
    ``samples`` (k,), one block of the stream per light; strata = (n, S): the tile's n samples,
    S per pixel (consecutive).

    Keys (n / S, S) then jitters (k, 2) are drawn.  A pixel's points: the first S of the
    (0, 2)-sequence, Owen-scrambled with seeds from keys[:, 0].  S = s^2, s = 2^k >= 4: sample j
    (film cell (j % s, j // s)) takes the point in light cell (sigma_x(cx ^ cy), sigma_y(cx ^ alpha
    cy)), an orthogonal array against the film cell, sigma_x / sigma_y shuffled by keys[:, 0:s] /
    keys[:, s-1:2s-1]; any other S: point pi_p(j), the pixel's samples shuffled by its keys.
    U = (the point's 32 bits + jitter) / 2^32.  Delta lights ignore them: their block is skipped
    (``skip_uniforms``) and zeros are returned, the stream ending where drawing would leave it.
    """
    n, S = strata
    k = samples.size
    if _is_delta_light(light):
        skip_uniforms(rng, n + 2 * k)
        return np.zeros((k, 2))
    return _strata_uniforms(samples, strata, rng)


def _strata_uniforms(samples: np.ndarray, strata: tuple, rng: np.random.Generator) -> np.ndarray:
    """:func:`_light_uniforms` of a non-delta light: keys (n / S, S) then jitters (k, 2) drawn, the
    pixels' points placed (also the continuation lobes' directions, ``_specular_step``)."""
    n, S = strata
    k = samples.size
    keys = rng.random((n // S, S))
    jit = rng.random((k, 2))
    P = n // S
    p, jj = samples // S, samples % S
    # the pixels' Owen-scrambled (0, 2)-sequence points
    seed_x = _hash((keys[:, 0] * 4294967296.0).astype(np.uint64))[:, None]
    seed_y = _hash(seed_x ^ np.uint64(0x9E3779B9))
    t = np.arange(S, dtype=np.uint64)[None, :]
    X, Y = _owen(_bits_reversed(t), seed_x), _owen(_sobol_second(t), seed_y)
    s = int(round(np.sqrt(S)))
    if s * s == S and s >= 4 and s & (s - 1) == 0 and s <= 1024:
        j = np.arange(S)
        cx, cy = j % s, j // s
        lx, ly = cx ^ cy, cx ^ _gf_times_alpha(cy, s)
        sx, sy = _shuffle(keys, s), _shuffle(keys[:, s - 1:], s)
        bits = np.uint64(32 - int(np.log2(s)))
        slot = np.empty((P, S), np.int64)
        slot[np.arange(P)[:, None], ((Y >> bits) * np.uint64(s) + (X >> bits)).astype(np.int64)] = np.arange(S)[None, :]
        c = slot[p, sy[p, ly[jj]] * s + sx[p, lx[jj]]]
    else:
        c = _shuffle(keys, S)[p, jj]
    u = np.empty((k, 2))
    u[:, 0] = np.minimum((X[p, c].astype(np.float64) + jit[:, 0]) / 4294967296.0, 1.0 - 2.0 ** -53)
    u[:, 1] = np.minimum((Y[p, c].astype(np.float64) + jit[:, 1]) / 4294967296.0, 1.0 - 2.0 ** -53)
    return u


def _world_normals(light, ng: np.ndarray, wo: np.ndarray) -> np.ndarray | None:
    """For the world light: geometric normals (n, 3) turned toward wo, about which its NEE samples
    cosine-distributed directions (none below the surface); None for every other light."""
    return _face_forward(ng, wo) if light.type == "WORLD" else None


def _fill(a: np.ndarray, value: float) -> np.ndarray:
    a[...] = value
    return a


def _direct(ctx, p, ng, ns, wo, mat, times, eps, rng, stats: TraceStats, mis=(False, False), samples=None,
            strata=None) -> np.ndarray:
    """Next-event estimate (n, 3): sum over lights of f(wo, wi) |cos(ns, wi)| L_i / p * V.

    samples (n,): the tile sample of each point, strata = (tile samples, samples per pixel): the
    lights' uniforms are stratified over each pixel's samples (``_light_uniforms``; None: none).

    eps (n,): each point's shadow-ray origin offset (``_eps_rows``).  mis: ((n,) bool, (n,) bool) the
    paths may go on through a rough reflection / a rough refraction after this (the glossy /
    transmission budget left); a sample on that side of the surface of the world, of AREA lights, POINT /
    SPOT spheres and MESH lights then weigh the part f_c of f those lobes sample (density p_c) by
    the power heuristic p_l^2 / (p_l^2 + p_c^2), p_l the light's own density (the world's cos(ng_f, wi) / pi,
    ``lights_numpy.nee_pdf``; delta lights and suns: inf, no weighing).

    Lights of zero power are skipped; shadow rays are cast only for samples
    whose unshadowed contribution is positive (light in front, BSDF > 0).
    """
    n = p.shape[0]
    Ld = np.zeros((n, 3))
    lights = ctx.lights
    mis_refl_all, mis_trans_all = mis
    for li in range(len(lights)):
        if lights.power[li] <= 0.0:
            continue
        # Sample a point / direction on the light at each sample's time
        u_l = _light_uniforms(lights.lights[li], np.arange(n) if samples is None else samples,
                              (n, 1) if strata is None else strata, rng)
        wi, dist, weight = lights_numpy.sample_direct(lights, li, p, times, u_l,
                                                      normals=_world_normals(lights.lights[li], ng, wo))
        f = bsdf_eval(ctx.table, mat, wo, wi, ns, ng)
        mis_refl, mis_trans = np.broadcast_to(mis_refl_all, (n,)), np.broadcast_to(mis_trans_all, (n,))
        if np.any(mis_refl | mis_trans):
            if lights.lights[li].type == "WORLD":
                p_l = np.maximum(np.einsum("ij,ij->i", wi, _face_forward(ng, wo)), 0.0) / np.pi
            else:
                j = x_l = None
                if lights.lights[li].type == "MESH":
                    j, x_l = lights_numpy.mesh_triangle_of_sample(lights, li, u_l), p + dist[:, None] * wi
                p_l = lights_numpy.nee_pdf(lights, li, p, wi, times, x=x_l, j=j)
            f_c, p_c = bsdf_eval_cont(ctx.table, mat, wo, wi, ns, ng)
            # the continuation of wi's side may go on: a reflection (wi on wo's side of ng) within
            # the glossy budget, a refraction within the transmission budget
            refl = np.einsum("ij,ij->i", wi, ng) * np.einsum("ij,ij->i", wo, ng) > 0
            ok = np.where(refl, mis_refl, mis_trans)
            x = np.where(ok & np.isfinite(p_l), _mis_weight(p_c, p_l), 0.0)
            f = f - f_c * x[:, None]
        contrib = f * (np.abs(np.einsum("ij,ij->i", ns, wi)))[:, None]
        contrib *= weight
        live = np.nonzero(np.any(contrib > 0.0, axis=1))[0]
        if live.size == 0:
            continue
        # Shadow rays at the same time, stopping just short of the light
        all_rows = live.size == n
        sel = None if all_rows else live
        wl, pl, dl, el = _rows(wi, sel), _rows(p, sel), _rows(dist, sel), _rows(eps, sel)
        o = _offset(pl, _rows(ng, sel), wl, el)
        # Aim from the offset origin at the light point itself and stop a margin short of
        # it: emissive triangles are geometry the shadow ray must not reach
        fin = np.isfinite(dl)
        v = np.where(fin[:, None], pl + np.where(fin, dl, 0.0)[:, None] * wl - o, wl)
        s = np.sqrt(np.einsum("ij,ij->i", v, v))
        dirs = v / s[:, None]
        tmax = np.where(fin, s * (1.0 - 1e-6) - 2.0 * el, np.inf)
        blocked = ctx.caster.occluded(o, dirs, _rows(times, sel), tmax, guard=GUARD_FRACTION * el)
        stats.shadow_rays += live.size
        contrib[live[blocked]] = 0.0
        Ld += contrib
    return Ld


def _photon_term(ctx, kind: str, p, ns_f, wo, mat, times, stats: TraceStats, ng=None) -> np.ndarray | None:
    """rho_d / pi * E_kind(p, ns, t) (n, 3), None when there is no such map; ng (n, 3): the queries'
    geometric normals whose tangent slab bounds the photons counted (zero rows: none)."""
    if ctx.maps is None or not ctx.map_kinds.get(kind, False) or p.shape[0] == 0:
        return None
    rho = diffuse_albedo(ctx.table, mat, wo, ns_f)
    live = np.nonzero(np.any(rho > 0.0, axis=1))[0]
    out = np.zeros((p.shape[0], 3))
    if live.size:
        E = ctx.maps.estimate(kind, p[live], ns_f[live], times[live], ng=None if ng is None else ng[live])
        stats.photon_lookups += live.size
        out[live] = rho[live] / np.pi * E
    return out


def _seen_lights(lights, o, d, t, t_scene, camera_ray=False, visible_camera=None, only=None):
    """Radiance (n, 3) of light shapes hit before t_scene: the numpy light oracle's ``seen_lights_numpy``."""
    return lights_numpy.seen_lights_numpy(lights, o, d, t, t_scene, camera_ray, visible_camera, only)


def _mis_weight(p_c: np.ndarray, p_l: np.ndarray) -> np.ndarray:
    """Power heuristic (n,) p_c^2 / (p_c^2 + p_l^2) of a path that reached a light through a rough
    lobe (density p_c) against next-event estimation's p_l: 1 where p_l = 0, 0 where p_l = inf or
    p_c = 0."""
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        w = p_c ** 2 / (p_c ** 2 + p_l ** 2)
    w = np.where(np.isfinite(p_l) & (p_c > 0), w, 0.0)
    return np.where(p_l > 0, w, 1.0)


# ----------------------------------------------------------------------------
# Paths of one batch of camera samples
# ----------------------------------------------------------------------------
def _cast_bounce(ctx, o, d, times, idx, tmax, m: int, bounce: int, stats: TraceStats, guard=None):
    """One bounce's m rays o, d (m, 3) cast at their times (idx (m,): their samples, None = all).

    guard (m,): the rays' own self-intersection guards (``GUARD_FRACTION`` of their origin
    offsets; None for camera rays).  Counts them as camera (bounce 0) or bounce rays; returns
    (times t (m,), Hits).
    """
    t = times if idx is None else times[idx]
    hits = ctx.caster.intersect(o, d, t, tmax, guard=guard)
    if bounce == 0:
        stats.camera_rays += m
    else:
        stats.bounce_rays += m
    return t, hits


def _specular_step(ctx, rng, spec, idx, beta, mat, wo, ns, ng, bounce: int, counts, strata):
    """Continue the rows spec (k,) through their delta and rough non-diffuse lobes: (idx, beta,
    wi, go, glossy) of those rows.

    mat (k,), wo, ns, ng (k, 3) the hits at those rows; idx / beta (None: every sample / unit
    throughput) are narrowed to them and beta takes the lobe's weight (``bsdf_sample_path``: the
    DIFFUSE lobe stops the path, the photon maps carry it); go (k,) keeps the rows that went on
    with some throughput left and (from RR_START on) survived Russian roulette, beta / q; glossy
    (k,) marks those that left a rough lobe.  Random numbers: the directions' strata
    (:func:`_strata_uniforms`, u[:, 1:3]), the lobe pick's (another block's first column, u[:, 0]),
    then (k,) for the roulette.
    """
    u = np.empty((spec.size, 3))
    idx = spec if idx is None else idx[spec]
    u[:, 1:3] = _strata_uniforms(idx, strata, rng)     # the directions: stratified per pixel (strata = (n, S))
    u[:, 0] = _strata_uniforms(idx, strata, rng)[:, 0]  # the lobe's pick: the same, another block
    beta = None if beta is None else beta[spec]
    wi, weight, kind, p_c, u_w = bsdf_sample_cont(ctx.table, mat, wo, ns, ng, u)
    beta = weight if beta is None else beta * weight
    go = (kind != 0) & np.any(beta > 0.0, axis=1)
    # bounce budgets (Cycles' Glossy / Transmission bounces): a delta lobe within its own kind's, a
    # rough lobe within both
    trans = np.einsum("ij,ij->i", wi, _face_forward(ng, wo)) < 0.0
    gl_ok, tr_ok = counts[:, 0] < ctx.glossy_bounces, counts[:, 1] < ctx.transmission_bounces
    go &= np.where(trans, tr_ok, gl_ok)
    # Russian roulette where a DIFFUSE pick carries the rough lobes' part (u_w >= 0): on at
    # probability beta' / CONT_RR, then beta' / q
    ru = go & (u_w >= 0.0)
    q = np.where(ru, np.minimum(np.max(beta, axis=1) / CONT_RR, 1.0), 1.0)
    go &= ~ru | (u_w < q)
    beta = beta / np.where(q > 0, q, 1.0)[:, None]
    counts = counts + np.stack([~trans, trans], axis=1).astype(np.int32)
    if bounce + 1 >= RR_START:
        q = np.clip(np.max(beta, axis=1), 0.05, 1.0)
        go &= rng.random(idx.size) < q
        beta = beta / q[:, None]
    # the world's weight where the ray escapes: 1 after a delta lobe, the power heuristic after a
    # rough one when the world is a light (0 when it is not: it sends nothing then)
    world_w = np.ones(idx.size)
    g = kind == 2
    if np.any(g):
        p_l = np.maximum(np.einsum("ij,ij->i", wi, _face_forward(ng, wo)), 0.0) / np.pi
        p_g = np.where(g, p_c, 0.0)                      # (delta rows: inf, unused)
        w = _mis_weight(p_g, p_l) if ctx.world_light else 0.0
        world_w = np.where(g, w, 1.0)
    return idx, beta, wi, go, g, world_w, counts, np.where(g, p_c, np.inf)


def shade_paths(ctx, o: np.ndarray, d: np.ndarray, times: np.ndarray, tmax0: np.ndarray,
                rng: np.random.Generator, stats: TraceStats, cam_pos: np.ndarray,
                cam_axis: np.ndarray, spp: int = 1) -> dict[str, np.ndarray]:
    """Radiance of the camera rays o, d (n, 3) at times (n,) split into passes.

    spp: the samples of each pixel, consecutive in o, over which next-event estimation stratifies
    each light's samples (``_light_uniforms``).

    tmax0 (n,) clips the camera rays; cam_pos, cam_axis (n, 3) are the camera
    position and unit view axis at each sample's time (for Depth).

    Returns pass name -> (n, C) float64 (Combined alpha = 1, or coverage when
    the film is transparent; Depth along the view axis; Normal at the first hit).

    Bookkeeping: ``idx = None`` stands for "every sample, in order" (the first
    bounce, and later ones while no path has ended), so the common case pays
    for no gathers or scatters; ``beta = None`` is a throughput of 1.

    """
    n = o.shape[0]
    # Path state: idx maps live rows to samples (None = all), beta their throughput (None = 1)
    idx = None
    beta = None
    glossy = None                            # (live rows,) bool: the ray left a rough lobe
    world_w = None                           # (live rows,) the world's weight where the ray escapes
    p_cont = None                            # (live rows,) the density the rough lobe drew the ray with
    counts = None                            # (live rows, 2) reflections, transmissions so far
    tmax = tmax0                             # camera clipping for the first segment
    guard = None                             # camera rays: the caster's own guard
    # Per-sample outputs
    L_emit = np.zeros((n, 3))
    L_direct = np.zeros((n, 3))
    L_indirect = np.zeros((n, 3))
    L_caustic = np.zeros((n, 3))
    depth = np.full(n, DEPTH_BACKGROUND)
    normal = np.zeros((n, 3))
    covered = np.zeros(n)
    world_L = ctx.world_radiance

    def add(dst: np.ndarray, rows, value: np.ndarray, w=None, emitted=None) -> None:
        """dst[idx[rows]] += w * value (rows None = all live rows; w None = beta); emitted (rows,)
        the multiple-importance weight of light reached through a rough lobe, used on rows that
        left one (None: 1)."""
        if emitted is not None and glossy is not None:
            g = glossy if rows is None else glossy[rows]
            value = np.where(g[:, None], emitted[:, None] * value, value)
        w = beta if w is None else w
        if w is not None:
            value = (w if rows is None else w[rows]) * value
        target = idx if rows is None else (rows if idx is None else idx[rows])
        if target is None:
            dst += value
        else:
            dst[target] += value

    for bounce in range(ctx.max_depth + 1):
        m = n if idx is None else idx.size
        if m == 0:
            break
        t, hits = _cast_bounce(ctx, o, d, times, idx, tmax, m, bounce, stats, guard)
        hit = hits.hit
        all_hit = bool(hit.all())

        # -- Lights seen through delta lobes (before the next surface) -------------------------
        # Cycles' defaults: lights are invisible to camera rays (visible_camera off) and
        # visible to glossy / transmission rays, i.e. in mirrors and through glass; a sun of
        # angle > 0 where the ray escapes (t_scene = inf)
        if ctx.visible_lights:
            for li in range(len(ctx.lights)):
                if ctx.lights.lights[li].type not in ("AREA", "POINT", "SPOT", "SUN"):
                    continue                  # meshes: their triangles are hit (below); the world: misses
                val = _seen_lights(ctx.lights, o, d, t, hits.t, camera_ray=(bounce == 0),
                                   visible_camera=ctx.light_visible_camera, only=li)
                w = None if glossy is None else _mis_weight(p_cont, lights_numpy.nee_pdf(ctx.lights, li, o, d, t))
                add(L_emit, None, val, emitted=w)

        # -- Escaped rays see the world ------------------------------------------------
        if not all_hit and np.any(world_L > 0):
            if not (bounce == 0 and ctx.film_transparent):
                miss = np.nonzero(~hit)[0]
                ww = 1.0 if world_w is None else world_w[miss][:, None]
                add(L_emit, miss, np.broadcast_to(world_L, (miss.size, 3)) * ww)

        # -- First hit: Depth, Normal, coverage -------------------------------------------
        if bounce == 0:
            hs = None if all_hit else np.nonzero(hit)[0]
            pos = hits.position if all_hit else hits.position[hs]
            hs_all = slice(None) if all_hit else hs
            depth[hs_all] = np.einsum("ij,ij->i", pos - _rows(cam_pos, hs), _rows(cam_axis, hs))
            normal[hs_all] = _rows(hits.ns, hs)
            covered[hs_all] = 1.0

        # -- Keep the paths that hit something ------------------------------------------
        if not all_hit:
            keep = np.nonzero(hit)[0]
            if keep.size == 0:
                break
            idx = keep if idx is None else idx[keep]
            beta = None if beta is None else beta[keep]
            glossy = None if glossy is None else glossy[keep]
            world_w = None if world_w is None else world_w[keep]
            p_cont = None if p_cont is None else p_cont[keep]
            o, d = o[keep], d[keep]
            counts = None if counts is None else counts[keep]
            t = t[keep]
            p, ng, ns, mat = hits.position[keep], hits.ng[keep], hits.ns[keep], hits.material[keep]
            hit_inst, hit_prim = hits.instance[keep], hits.prim[keep]
            eps = _eps_rows(ctx, hits.instance[keep], p)
            wo = -d                           # directions are unit (camera, bsdf_sample)
        else:
            p, ng, ns, mat = hits.position, hits.ng, hits.ns, hits.material
            hit_inst, hit_prim = hits.instance, hits.prim
            eps = _eps_rows(ctx, hits.instance, p)
            wo = -d

        # -- Emission of surfaces seen along the chain ---------------------------------------
        if ctx.any_emission:
            e_rows = np.nonzero(ctx.emissive[mat])[0]
            if e_rows.size:
                w = None
                if glossy is not None:
                    inst, prim = _rows(hit_inst, e_rows), _rows(hit_prim, e_rows)
                    w = np.ones(e_rows.size)
                    for li, (instance, J) in ctx.mesh_emitters.items():
                        sel = np.nonzero((inst == instance) & (J[prim] >= 0))[0]
                        if sel.size:
                            r = e_rows[sel]
                            w[sel] = _mis_weight(p_cont[r], lights_numpy.nee_pdf(
                                ctx.lights, li, o[r], d[r], t[r], x=p[r], j=J[prim[sel]]))
                add(L_emit, e_rows, emission(ctx.table, mat[e_rows]), emitted=w)

        # -- Shade non-delta vertices: Direct, Caustic, Indirect -----------------------------
        nd = has_nondelta(ctx.table, mat)
        sh = None if nd.all() else np.nonzero(nd)[0]
        if sh is None or sh.size:
            p_s, ng_s, ns_s, wo_s = _rows(p, sh), _rows(ng, sh), _rows(ns, sh), _rows(wo, sh)
            mat_s, t_s = _rows(mat, sh), _rows(t, sh)
            if len(ctx.lights):
                c = np.zeros((p.shape[0], 2), np.int32) if counts is None else counts
                mis = ((bounce < ctx.max_depth) & (_rows(c[:, 0], sh) < ctx.glossy_bounces),
                       (bounce < ctx.max_depth) & (_rows(c[:, 1], sh) < ctx.transmission_bounces))
                rows = np.arange(p.shape[0]) if sh is None else sh
                add(L_direct, sh, _direct(ctx, p_s, ng_s, ns_s, wo_s, mat_s, t_s, _rows(eps, sh), rng, stats,
                                          mis=mis, samples=rows if idx is None else idx[rows], strata=(n, spp)))
            if ctx.maps is not None:
                ns_f = _face_forward(ns_s, wo_s)
                # the tangent slab on instances that hold still (docs/photon-mapping.md, "Tangent slab")
                ng_q = ng_s * ctx.still[_rows(hit_inst, sh)][:, None]
                for kind, dst in (("caustic", L_caustic), ("global", L_indirect)):
                    val = _photon_term(ctx, kind, p_s, ns_f, wo_s, mat_s, t_s, stats, ng=ng_q)
                    if val is not None:
                        add(dst, sh, val)

        if bounce == ctx.max_depth:
            break
        # -- Continue through delta and rough non-diffuse lobes (the diffuse lobe ends here) ------
        spec = np.nonzero(ctx.has_delta[mat])[0]
        if spec.size == 0:
            break
        p, ng, eps = p[spec], ng[spec], eps[spec]
        counts = np.zeros((spec.size, 2), np.int32) if counts is None else counts[spec]
        idx, beta, wi, go, gl, ww, counts, pc = _specular_step(ctx, rng, spec, idx, beta, mat[spec], wo[spec],
                                                               ns[spec], ng, bounce, counts, (n, spp))
        idx, beta, glossy, world_w, counts, p_cont = idx[go], beta[go], gl[go], ww[go], counts[go], pc[go]
        if not glossy.any():
            glossy = world_w = p_cont = None
        o = _offset(p[go], ng[go], wi[go], eps[go])
        guard = GUARD_FRACTION * eps[go]
        d = wi[go]
        tmax = None

    combined = np.concatenate([L_emit + L_direct + L_indirect + L_caustic,
                               (covered if ctx.film_transparent else np.ones(n))[:, None]], axis=1)
    return {"Combined": combined, "Depth": depth[:, None], "Normal": normal,
            "Emit": L_emit, "Direct": L_direct, "Indirect": L_indirect, "Caustic": L_caustic}



# ----------------------------------------------------------------------------
# The image
# ----------------------------------------------------------------------------
def _has_delta_lobe(materials) -> np.ndarray:
    """(M + 1,) bool: can a camera path go on from the material: a delta lobe (mirror, clear glass,
    smooth coat) or a rough one (metal, glass reflection, coat)?"""
    out = np.zeros(len(materials) + 1, bool)
    for i, m in enumerate(materials):
        base = (1 - m.metallic) * (1 - m.transmission)
        out[i] = ((1 - m.metallic) * m.transmission > 0) or m.metallic > 0 or (base > 0 and m.specular > 0)
    return out


def tile_sums_numpy(film: Film, x0: int, y0: int, tw: int, th: int, values: dict):
    """Per-pixel sums of one tile's samples in numpy (``Film.tile_sums``' window format)."""
    P = tw * th
    n = next(iter(values.values())).shape[0]
    S = n // P
    active, arrays, c0 = [], [], 0
    for name, c, _ in PASSES:
        a = np.asarray(values[name], np.float64).reshape(n, c)
        if np.any(a):
            active.append((c0, c))
            arrays.append(a)
        c0 += c
    V = np.concatenate(arrays + [np.ones((n, 1))], axis=1)
    w = V.reshape(P, S, -1).sum(axis=1).reshape(th, tw, -1).astype(np.float32)
    ya, yb, xa, xb = y0, min(y0 + th, film.height), x0, min(x0 + tw, film.width)
    return (ya, yb, xa, xb), active, w[:yb - ya, :xb - xa]


def trace_image_numpy(scene, settings, caster, lights, maps=None, *, time_override=None, stream: int = 0):
    """The whole image through the numpy tracer: (passes name -> (H, W, C) float32, TraceStats)."""
    W, H = (int(scene.resolution[0]), int(scene.resolution[1]))
    spp = int(settings.samples)
    table = MaterialTable(scene.materials)
    ctx = SimpleNamespace(scene=scene, caster=caster, lights=lights, table=table, maps=maps,
                          map_kinds=_map_kinds(maps), max_depth=int(settings.max_depth),
                          inst_offset=instance_offsets(scene), world_radiance=np.asarray(scene.world.radiance, float),
                          film_transparent=bool(scene.metadata.get("film_transparent", False)))
    ctx.has_delta = _has_delta_lobe(scene.materials)
    # 1 where an instance neither moves nor deforms over the shutter (its look-ups keep to the tangent slab)
    ctx.still = np.array([float(inst.transform.is_static and not scene.meshes[inst.mesh].is_deforming)
                          for inst in scene.instances])
    ctx.world_light = any(l.type == "WORLD" for l in lights.lights)
    ctx.glossy_bounces, ctx.transmission_bounces = int(settings.glossy_bounces), int(settings.transmission_bounces)
    ctx.any_emission = any(np.any(np.asarray(m.emission) > 0) for m in scene.materials)
    ctx.emissive = np.any(table.emission > 0, axis=1)
    # MESH lights with power: light index -> (instance, J), J[prim] its triangle index (-1: none)
    ctx.mesh_emitters = {}
    for li, l in enumerate(lights.lights):
        if l.type == "MESH" and l.power > 0:
            J = -np.ones(len(scene.meshes[scene.instances[l.instance].mesh].triangles), np.int64)
            for jj, prim in enumerate(np.asarray(l.prims)):
                J[prim] = jj
            ctx.mesh_emitters[li] = (l.instance, J)
    ctx.light_visible_camera = [bool(v) for v in (scene.metadata.get("light_visible_camera") or [])]
    ctx.visible_lights = any(l.type == "AREA" or (l.type in ("POINT", "SPOT") and l.radius > 0)
                             or (l.type == "SUN" and l.angle > 0) for l in lights.lights)
    film = Film(W, H, settings.filter_width)
    cam = scene.camera
    side = int(np.clip(np.sqrt(BATCH_SAMPLES / spp), 1, 64))
    stats = TraceStats()
    for ti, (x0, y0) in enumerate([(x0, y0) for y0 in range(0, H, side) for x0 in range(0, W, side)]):
        gy, gx = np.mgrid[y0:min(y0 + side, H), x0:min(x0 + side, W)]
        rng = rng_for(settings.seed, STREAM_CAMERA, stream, ti)
        px, py, times = camera_samples(gx.ravel(), gy.ravel(), spp, scene.shutter, rng, time_override,
                                       filter_width=film.radius)
        o, d = generate_rays(cam, (W, H), px, py, times)
        R, pos = camera_to_world(cam, times[:1] if cam.transform.is_static else times)
        axis = np.broadcast_to(-R[:, :, 2], (len(times), 3))
        pos = np.broadcast_to(pos, (len(times), 3))
        if cam.type == "ORTHO":
            tmax0 = np.full(len(times), cam.clip_end - cam.clip_start)
        else:
            tmax0 = cam.clip_end / np.maximum(np.sum(d * axis, axis=1), 1e-12)
        values = shade_paths(ctx, o, d, times, tmax0, rng, stats, pos, axis, spp=spp)
        film.add_window(tile_sums_numpy(film, x0, y0, gx.shape[1], gx.shape[0], values))
    return film.resolve(), stats
