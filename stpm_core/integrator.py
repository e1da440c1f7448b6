"""Distribution ray tracing of the image: camera samples spread over pixel area
*and* shutter time, specular chains, next-event estimation and photon look-ups.

Wavefront layout: the image is cut into tiles; a tile's samples (pixels x spp,
about 64k at once) are traced together, bounce by bounce, over a shrinking set
of live paths.  No Python loop runs per ray.  Tiles run on a thread pool and
reach the film in tile order (results do not depend on the thread count).

Per camera sample i (docs/rendering.md has the equations):

* film position ``x_i`` = pixel + jitter in one cell of a stratified grid;
* time ``t_i = shutter.sample(xi_i)`` with ``xi_i`` stratified per pixel and its
  strata *randomly permuted per pixel*, so time strata are decorrelated from
  the pixel strata;
* the path follows delta lobes (mirror, clear glass, specular coat) from the
  camera; at every non-delta vertex ``x`` reached that way it is shaded with

  - Direct   = sum_lights f(wo, wi) |cos| L_i / p      (shadow ray at t_i;
               the lights include one entry per emissive instance)
  - Caustic  = rho_d / pi * E_caustic(x, n, t_i)      (``PhotonMaps.estimate``)
  - Indirect = rho_d / pi * E_global(x, n, t_i)
  - Emit     = emission and light shapes seen along the chain + world radiance
               for escaping rays

  each multiplied by the chain throughput ``beta``.  Combined = their sum.

Rough glossy lobes at a shading vertex get light only through next-event
estimation (``bsdf_eval`` includes every non-delta lobe); photon estimates
multiply by the diffuse albedo only (a photon map stores irradiance, which
cannot be weighted by a glossy lobe without incoming directions).
"""
from __future__ import annotations

import threading
from dataclasses import dataclass, field

import numpy as np

from . import shading_kernels as _K
from .bsdf import MaterialTable, bsdf_eval, bsdf_sample, diffuse_albedo, emission, has_nondelta
from .camera import camera_to_world, generate_rays, image_plane
from .film import BH_INVERSE_CDF, DEPTH_BACKGROUND, PASSES, Film, filter_offsets
from .parallel import ordered_map, worker_count
from .raycast.geometry import GUARD_FRACTION, instance_offsets, offset_lengths
from .sampling import rng_for, skip_uniforms

__all__ = ["TraceStats", "trace_image", "camera_samples", "shade_paths"]

# Random streams (second entry of rng_for(seed, ...)): one per purpose.
STREAM_CAMERA = 0x5A3
# Samples traced together in one wavefront batch (tile pixels x spp): large
# batches amortise Python overhead; the caster cuts them into embree-sized chunks.
BATCH_SAMPLES = 65536
# Bounces after which Russian roulette may end a specular chain.
RR_START = 3


@dataclass
class TraceStats:
    """Counters of one image trace."""

    camera_rays: int = 0
    bounce_rays: int = 0
    shadow_rays: int = 0
    photon_lookups: int = 0
    seconds: float = 0.0
    extra: dict = field(default_factory=dict)

    def merge(self, other: "TraceStats") -> None:
        """Add another trace's counters (tile results) into this one."""
        self.camera_rays += other.camera_rays
        self.bounce_rays += other.bounce_rays
        self.shadow_rays += other.shadow_rays
        self.photon_lookups += other.photon_lookups

    @property
    def rays(self) -> int:
        return self.camera_rays + self.bounce_rays + self.shadow_rays


# ----------------------------------------------------------------------------
# Camera samples: stratified positions and decorrelated stratified times
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


def _light_uniforms(light, n: int, rng: np.random.Generator, out: np.ndarray | None = None) -> np.ndarray:
    """Uniforms (n, 2) for one light's samples, one block of the stream per light.

    Delta lights ignore them: their block is skipped (``skip_uniforms``) and
    zeros are returned, the stream ending where drawing would leave it.
    out: an (n, 2) buffer to draw into.
    """
    if _is_delta_light(light):
        skip_uniforms(rng, 2 * n)
        return np.zeros((n, 2)) if out is None else _fill(out, 0.0)
    return rng.random((n, 2)) if out is None else rng.random(out=out)


def _world_normals(light, ng: np.ndarray, wo: np.ndarray) -> np.ndarray | None:
    """For the world light: geometric normals (n, 3) turned toward wo, about which its NEE samples
    cosine-distributed directions (none below the surface); None for every other light."""
    return _face_forward(ng, wo) if light.type == "WORLD" else None


def _fill(a: np.ndarray, value: float) -> np.ndarray:
    a[...] = value
    return a


def _direct(ctx, p, ng, ns, wo, mat, times, eps, rng, stats: TraceStats) -> np.ndarray:
    """Next-event estimate (n, 3): sum over lights of f(wo, wi) |cos(ns, wi)| L_i / p * V.

    eps (n,): each point's shadow-ray origin offset (``_eps_rows``).

    Lights of zero power are skipped; shadow rays are cast only for samples
    whose unshadowed contribution is positive (light in front, BSDF > 0).
    """
    n = p.shape[0]
    Ld = np.zeros((n, 3))
    lights = ctx.lights
    for li in range(len(lights)):
        if lights.power[li] <= 0.0:
            continue
        # Sample a point / direction on the light at each sample's time
        wi, dist, weight = lights.sample_direct(li, p, times, _light_uniforms(lights.lights[li], n, rng),
                                                normals=_world_normals(lights.lights[li], ng, wo))
        f = bsdf_eval(ctx.table, mat, wo, wi, ns, ng)
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


def _photon_term(ctx, kind: str, p, ns_f, wo, mat, times, stats: TraceStats) -> np.ndarray | None:
    """rho_d / pi * E_kind(p, ns, t) (n, 3), None when there is no such map."""
    if ctx.maps is None or not ctx.map_kinds.get(kind, False) or p.shape[0] == 0:
        return None
    rho = diffuse_albedo(ctx.table, mat, wo, ns_f)
    live = np.nonzero(np.any(rho > 0.0, axis=1))[0]
    out = np.zeros((p.shape[0], 3))
    if live.size:
        E = ctx.maps.estimate(kind, p[live], ns_f[live], times[live])
        stats.photon_lookups += live.size
        out[live] = rho[live] / np.pi * E
    return out


def _seen_lights(lights, o: np.ndarray, d: np.ndarray, t: np.ndarray, t_scene: np.ndarray,
                 camera_ray: bool = False, visible_camera=None) -> np.ndarray:
    """Radiance (n, 3) of light shapes hit by rays o + s d (unit d) before t_scene (n,).

    What a delta chain (mirror, glass) sees of the lights themselves, as in
    Cycles.  Camera rays see light i only if ``visible_camera[i]`` (from
    ``scene.metadata['light_visible_camera']``, exported from Blender's
    Object > Visibility > Camera; False by default as in Blender).  AREA lights are one-sided emitters facing their local -Z with radiance
    ``color P / (pi A)``; POINT / SPOT lights of radius r > 0 are spheres of
    radiance ``I / (pi r^2)`` (I = color P / (4 pi); spots masked by their cone).
    Radius-0 lights and suns are not visible.  Same shapes and units as
    :class:`stpm_core.lights.LightSet`.
    """
    from .lights import area_light_normal, spot_attenuation

    n = o.shape[0]
    L = np.zeros((n, 3))
    for li, light in enumerate(lights.lights):
        if light.type in ("MESH", "WORLD"):
            continue                          # emissive triangles: the caster hits them (Emit); world: misses
        color = np.asarray(light.color, float)
        if light.power <= 0 or not np.any(color > 0):
            continue
        if camera_ray and not (visible_camera is not None and li < len(visible_camera) and visible_camera[li]):
            continue
        if light.type == "AREA":
            # Plane of the light at each ray's time; local coordinates of the crossing
            M = light.transform.at(t)
            sy = light.size_y if light.shape in ("RECTANGLE", "ELLIPSE") else light.size
            ex, ey = 0.5 * light.size * M[:, :3, 0], 0.5 * sy * M[:, :3, 1]
            c = M[:, :3, 3]
            n_emit, A4 = area_light_normal(ex, ey, M[:, :3, 2])   # -Z side, as LightSet (Cycles' rule)
            cos_d = np.sum(d * n_emit, axis=1)
            with np.errstate(divide="ignore", invalid="ignore"):
                s_hit = np.sum((c - o) * n_emit, axis=1) / cos_d
            q = o + np.nan_to_num(s_hit, nan=0.0, posinf=0.0, neginf=0.0)[:, None] * d - c
            a = np.sum(q * ex, axis=1) / np.maximum(np.sum(ex * ex, axis=1), 1e-300)
            b = np.sum(q * ey, axis=1) / np.maximum(np.sum(ey * ey, axis=1), 1e-300)
            disk = light.shape in ("DISK", "ELLIPSE")
            inside = (a * a + b * b <= 1.0) if disk else ((np.abs(a) <= 1.0) & (np.abs(b) <= 1.0))
            area = (np.pi if disk else 4.0) * A4
            seen = inside & (cos_d < 0) & (s_hit > 0) & (s_hit < t_scene) & (area > 0)
            L[seen] += color * light.power / (np.pi * area[seen, None])
        elif light.type in ("POINT", "SPOT") and light.radius > 0:
            # Sphere of radius r around the light's position at each ray's time
            M = light.transform.at(t)
            oc = o - M[:, :3, 3]
            r = float(light.radius)
            bq = np.sum(oc * d, axis=1)
            disc = bq * bq - (np.sum(oc * oc, axis=1) - r * r)
            s_hit = -bq - np.sqrt(np.maximum(disc, 0.0))
            seen = (disc > 0) & (s_hit > 0) & (s_hit < t_scene)
            radiance = np.broadcast_to(color * light.power / (4 * np.pi) / (np.pi * r * r), (n, 3))
            if light.type == "SPOT":
                axis = -M[:, :3, 2] / np.linalg.norm(M[:, :3, 2], axis=1, keepdims=True)
                radiance = radiance * spot_attenuation(light, np.sum(-d * axis, axis=1))[:, None]
            L[seen] += radiance[seen]
    return L


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


def _specular_step(ctx, rng, spec, idx, beta, mat, wo, ns, ng, bounce: int):
    """Continue the rows spec (k,) through their delta lobes: (idx, beta, wi, go) of those rows.

    mat (k,), wo, ns, ng (k, 3) the hits at those rows; idx / beta (None: every sample / unit
    throughput) are narrowed to them and beta takes the lobe's weight; go (k,) keeps the rows
    that sampled a delta lobe with some throughput left and (from RR_START on) survived Russian
    roulette, beta / q.  Random numbers: (k, 3) for the lobes, then (k,) for the roulette.
    """
    u = rng.random((spec.size, 3))
    idx = spec if idx is None else idx[spec]
    beta = None if beta is None else beta[spec]
    wi, weight, is_delta = bsdf_sample(ctx.table, mat, wo, ns, ng, u)
    beta = weight if beta is None else beta * weight
    go = is_delta & np.any(beta > 0.0, axis=1)
    if bounce + 1 >= RR_START:
        q = np.clip(np.max(beta, axis=1), 0.05, 1.0)
        go &= rng.random(idx.size) < q
        beta = beta / q[:, None]
    return idx, beta, wi, go


def shade_paths(ctx, o: np.ndarray, d: np.ndarray, times: np.ndarray, tmax0: np.ndarray,
                rng: np.random.Generator, stats: TraceStats, cam_pos: np.ndarray,
                cam_axis: np.ndarray) -> dict[str, np.ndarray]:
    """Radiance of the camera rays o, d (n, 3) at times (n,) split into passes.

    tmax0 (n,) clips the camera rays; cam_pos, cam_axis (n, 3) are the camera
    position and unit view axis at each sample's time (for Depth).

    Returns pass name -> (n, C) float64 (Combined alpha = 1, or coverage when
    the film is transparent; Depth along the view axis; Normal at the first hit).

    Bookkeeping: ``idx = None`` stands for "every sample, in order" (the first
    bounce, and later ones while no path has ended), so the common case pays
    for no gathers or scatters; ``beta = None`` is a throughput of 1.

    With the compiled kernels (``shading_kernels.AVAILABLE``) the same
    estimator runs through :func:`_shade_paths_fast` (same random numbers,
    same result to float rounding).
    """
    if _K.AVAILABLE and getattr(ctx, "kernels", False):
        V = _shade_paths_fast(ctx, o, d, times, tmax0, rng, stats, cam_pos, cam_axis)
        return _pass_views(V)
    n = o.shape[0]
    # Path state: idx maps live rows to samples (None = all), beta their throughput (None = 1)
    idx = None
    beta = None
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

    def add(dst: np.ndarray, rows, value: np.ndarray, w=None) -> None:
        """dst[idx[rows]] += w * value (rows None = all live rows; w None = beta)."""
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
        # visible to glossy / transmission rays, i.e. in mirrors and through glass.
        if ctx.visible_lights:
            add(L_emit, None, _seen_lights(ctx.lights, o, d, t, hits.t, camera_ray=(bounce == 0),
                                           visible_camera=ctx.light_visible_camera))

        # -- Escaped rays see the world ------------------------------------------------
        if not all_hit and np.any(world_L > 0):
            if not (bounce == 0 and ctx.film_transparent):
                miss = np.nonzero(~hit)[0]
                add(L_emit, miss, np.broadcast_to(world_L, (miss.size, 3)))

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
            t = t[keep]
            p, ng, ns, mat = hits.position[keep], hits.ng[keep], hits.ns[keep], hits.material[keep]
            eps = _eps_rows(ctx, hits.instance[keep], p)
            wo = -d[keep]                     # directions are unit (camera, bsdf_sample)
        else:
            p, ng, ns, mat = hits.position, hits.ng, hits.ns, hits.material
            eps = _eps_rows(ctx, hits.instance, p)
            wo = -d

        # -- Emission of surfaces seen along the chain ---------------------------------------
        if ctx.any_emission:
            e_rows = np.nonzero(ctx.emissive[mat])[0]
            if e_rows.size:
                add(L_emit, e_rows, emission(ctx.table, mat[e_rows]))

        # -- Shade non-delta vertices: Direct, Caustic, Indirect -----------------------------
        nd = has_nondelta(ctx.table, mat)
        sh = None if nd.all() else np.nonzero(nd)[0]
        if sh is None or sh.size:
            p_s, ng_s, ns_s, wo_s = _rows(p, sh), _rows(ng, sh), _rows(ns, sh), _rows(wo, sh)
            mat_s, t_s = _rows(mat, sh), _rows(t, sh)
            if len(ctx.lights):
                add(L_direct, sh, _direct(ctx, p_s, ng_s, ns_s, wo_s, mat_s, t_s, _rows(eps, sh), rng, stats))
            if ctx.maps is not None:
                ns_f = _face_forward(ns_s, wo_s)
                for kind, dst in (("caustic", L_caustic), ("global", L_indirect)):
                    val = _photon_term(ctx, kind, p_s, ns_f, wo_s, mat_s, t_s, stats)
                    if val is not None:
                        add(dst, sh, val)

        if bounce == ctx.max_depth:
            break
        # -- Continue through delta lobes only (materials without one end here) -------------
        spec = np.nonzero(ctx.has_delta[mat])[0]
        if spec.size == 0:
            break
        p, ng, eps = p[spec], ng[spec], eps[spec]
        idx, beta, wi, go = _specular_step(ctx, rng, spec, idx, beta, mat[spec], wo[spec], ns[spec], ng, bounce)
        idx, beta = idx[go], beta[go]
        o = _offset(p[go], ng[go], wi[go], eps[go])
        guard = GUARD_FRACTION * eps[go]
        d = wi[go]
        tmax = None

    combined = np.concatenate([L_emit + L_direct + L_indirect + L_caustic,
                               (covered if ctx.film_transparent else np.ones(n))[:, None]], axis=1)
    return {"Combined": combined, "Depth": depth[:, None], "Normal": normal,
            "Emit": L_emit, "Direct": L_direct, "Indirect": L_indirect, "Caustic": L_caustic}


# ----------------------------------------------------------------------------
# The same paths through the compiled kernels (shading_kernels)
# ----------------------------------------------------------------------------
# Column of each pass in the per-sample matrix V (n, 20): PASSES order
_COL = {}
_c = 0
for _name, _nc, _ in PASSES:
    _COL[_name] = (_c, _c + _nc)
    _c += _nc
N_CHANNELS = _c
_NO_IDX = np.zeros(0, np.int64)
_NO_ROWS3 = np.zeros((0, 3))


def _compact_layout(ctx) -> dict[str, tuple[int, int]]:
    """Columns of the per-sample matrix of a tile: only the passes this render can fill.

    Depth, Normal, Emit, Direct always; Indirect / Caustic with their photon
    map; ``Alpha`` (the coverage, Combined's alpha) with a transparent film.
    Combined RGB (= Emit + Direct + Indirect + Caustic) and an alpha of 1 are
    formed by the film sums.  Narrow rows: the tile's matrix is streamed from
    memory several times (first hit, next-event estimation, per-pixel sums).
    """
    names = [("Depth", 1), ("Normal", 3), ("Emit", 3), ("Direct", 3)]
    if "Indirect" not in ctx.zero_passes:
        names.append(("Indirect", 3))
    if "Caustic" not in ctx.zero_passes:
        names.append(("Caustic", 3))
    if ctx.film_transparent:
        names.append(("Alpha", 1))
    out, c = {}, 0
    for name, k in names:
        out[name] = (c, c + k)
        c += k
    return out


def _pass_views(V: np.ndarray) -> dict[str, np.ndarray]:
    """Pass name -> (n, C) view of the per-sample matrix V (n, 20)."""
    return {name: V[:, a:b] for name, (a, b) in _COL.items()}


def _first_pose(a: np.ndarray) -> np.ndarray:
    """(k, 3) contiguous: one row when every row of a (n, 3) is the same view (stride 0)."""
    a = np.asarray(a, np.float64)
    if a.shape[0] > 0 and a.strides[0] == 0:
        return np.ascontiguousarray(a[:1])
    return np.ascontiguousarray(a)


def _direct_fast(ctx, sh: np.ndarray, hits, d: np.ndarray, t_s: np.ndarray, rng, stats: TraceStats,
                 dst: np.ndarray, idx_k, use_idx: bool, beta_k, use_beta: bool) -> bool:
    """:func:`_direct` at the hit rows sh (k,) of ``hits`` (rays d), by the NEE kernels, added
    straight into dst (n, 3) (the Direct pass: dst[idx[row]] += beta[row] * contribution, light by
    light); returns whether any shadow ray was cast.

    Same random numbers as :func:`_direct` (one (k, 2) block per light);
    POINT / SPOT lights of radius 0 and the world are sampled in the kernels, other lights by
    ``LightSet.sample_direct``; materials with rough lobes get f from ``bsdf_eval`` (and every
    light through ``sample_direct``).
    """
    k = sh.size
    cast_any = False
    lights, table = ctx.lights, ctx.table
    P, NG, NS, mat = hits.position, hits.ng, hits.ns, hits.material
    EPS = _scratch("eps", (P.shape[0],))
    EPS[sh] = _eps_rows(ctx, hits.instance[sh], P[sh])      # shadow-ray offsets of the shaded rows
    gathered = None
    so, sd = _scratch("so", (k, 3)), _scratch("sd", (k, 3))
    stmax, live = _scratch("stmax", (k,)), _scratch("live", (k,), np.int64)
    contrib = _scratch("contrib", (k, 3))
    for li in range(len(lights)):
        if lights.power[li] <= 0.0:
            continue
        light = lights.lights[li]
        u = _light_uniforms(light, k, rng, out=_scratch("u_light", (k, 2)))
        point = light.type in ("POINT", "SPOT") and float(light.radius) <= 0.0
        if point and not ctx.rough_any:
            C, _, _, Z = lights._frame(li, t_s[:1] if light.transform.is_static else t_s)
            spot = light.type == "SPOT"
            cos_half = float(np.cos(0.5 * light.spot_size)) if spot else 1.0
            smooth = (1.0 - cos_half) * float(light.spot_blend) if spot else 0.0
            m = _K.nee_point(sh, P, NG, NS, d, mat, _first_pose(C), lights.intensity(li), spot, cos_half, smooth,
                             _first_pose(Z), _NO_ROWS3, False, table.w_base, table.coat, table.specular,
                             table.ior, table.base_color, EPS, contrib, so, sd, stmax, live)
        elif light.type == "WORLD" and not ctx.rough_any:
            m = _K.nee_world(sh, P, NG, NS, d, mat, u, np.asarray(light.color, np.float64), table.w_base, table.coat,
                             table.specular, table.ior, table.base_color, EPS, contrib, so, sd, stmax, live)
        else:
            if gathered is None:
                gathered = (P[sh], NG[sh], NS[sh], -d[sh], mat[sh])
            p_s, ng_s, ns_s, wo_s, mat_s = gathered
            wi, dist, weight = lights.sample_direct(li, p_s, t_s, u, normals=_world_normals(light, ng_s, wo_s))
            wi = np.ascontiguousarray(wi, np.float64)
            weight = np.ascontiguousarray(np.broadcast_to(weight, (k, 3)), np.float64)
            dist = np.ascontiguousarray(np.broadcast_to(dist, (k,)), np.float64)
            if ctx.rough_any:
                f, use_f = np.ascontiguousarray(bsdf_eval(table, mat_s, wo_s, wi, ns_s, ng_s)), True
            else:
                f, use_f = _NO_ROWS3, False
            m = _K.nee_given(sh, P, NG, NS, d, mat, wi, dist, weight, f, use_f, table.w_base, table.coat,
                             table.specular, table.ior, table.base_color, EPS, contrib, so, sd, stmax, live)
        if m == 0:
            continue
        lv = live[:m]
        blocked = ctx.caster.occluded(so[:m], sd[:m], np.take(t_s, lv, out=_scratch("t_live", (m,))), stmax[:m],
                                      guard=GUARD_FRACTION * EPS[sh[lv]])
        stats.shadow_rays += m
        cast_any = True
        _K.nee_accumulate(dst, sh, idx_k, use_idx, beta_k, use_beta, contrib, lv,
                          np.ascontiguousarray(blocked, np.bool_))
    return cast_any


def _shade_paths_fast(ctx, o, d, times, tmax0, rng, stats: TraceStats, cam_pos, cam_axis,
                      V: np.ndarray | None = None, layout: dict | None = None,
                      touched: set | None = None) -> np.ndarray:
    """:func:`shade_paths` through the kernels -> V (n, 20): the passes' channels in PASSES order.

    Same control flow, random numbers and estimator as the numpy loop in
    :func:`shade_paths`; per bounce, ``classify_hits`` does the misses, the
    emission and the first-hit passes in one pass over the hits, and the
    shading / continuing rows index the caster's arrays directly (no gathers).
    layout: pass name -> (first, end) column of V; None: every pass in
    PASSES order (20 columns, Combined included).  Other layouts come from
    :func:`_compact_layout` (no Combined: ``Film.tile_sums_matrix`` derives it).
    V: an (n, width) float64 buffer to fill, any content (None: a new one).
    touched: a set that receives the names of the passes among Emit, Direct,
    Indirect and Caustic that got any value (the others are 0 everywhere).
    """
    n = o.shape[0]
    full = layout is None
    cols = _COL if full else layout
    if V is None:
        V = np.empty((n, max(b for _, b in cols.values())))   # classify_hits starts every row (first bounce)
    L_emit, L_direct = V[:, slice(*cols["Emit"])], V[:, slice(*cols["Direct"])]
    L_indirect = V[:, slice(*cols["Indirect"])] if "Indirect" in cols else None
    L_caustic = V[:, slice(*cols["Caustic"])] if "Caustic" in cols else None
    covered = np.empty(n) if full else _scratch("covered", (n,))
    cam_pos, cam_axis = _first_pose(cam_pos), _first_pose(cam_axis)
    world_L = np.asarray(ctx.world_radiance, np.float64)
    world_on = bool(np.any(world_L > 0))
    table = ctx.table
    # Passes that received something (the others stay 0: the film sums can skip them)
    touched = set() if touched is None else touched
    idx = None
    beta = None
    tmax = tmax0
    guard = None                             # camera rays: the caster's own guard
    for bounce in range(ctx.max_depth + 1):
        m = n if idx is None else idx.size
        if m == 0:
            break
        t, hits = _cast_bounce(ctx, o, d, times, idx, tmax, m, bounce, stats, guard)
        use_idx, use_beta = idx is not None, beta is not None
        idx_k = idx if use_idx else _NO_IDX
        beta_k = beta if use_beta else _NO_ROWS3
        sh, spec = _scratch("sh", (m,), np.int64), _scratch("spec", (m,), np.int64)
        n_hit, n_sh, n_spec, n_emit = _K.classify_hits(
            hits.t, hits.material, table.nondelta, ctx.has_delta, ctx.emissive, table.emission, world_L,
            world_on and not (bounce == 0 and ctx.film_transparent), idx_k, use_idx, beta_k, use_beta, V,
            cols["Emit"][0], bounce == 0, cols["Depth"][0], cols["Normal"][0], DEPTH_BACKGROUND,
            hits.position, hits.ns, cam_pos, cam_axis, covered, sh, spec)
        if ctx.visible_lights:
            # After classify_hits, which starts the rows (the numpy loop adds these first: the same
            # sum on the first bounce, where each row gets at most one other term; rounding later)
            val = _seen_lights(ctx.lights, o, d, t, hits.t, camera_ray=(bounce == 0),
                               visible_camera=ctx.light_visible_camera)
            _K.scatter_add(L_emit, np.arange(m), idx_k, use_idx, beta_k, use_beta, val)
            touched.add("Emit")
        if n_emit:
            touched.add("Emit")
        if n_hit == 0:
            break
        sh, spec = sh[:n_sh], spec[:n_spec]
        if n_sh:
            t_s = np.take(t, sh, out=_scratch("t_s", (n_sh,)))
            if len(ctx.lights) and _direct_fast(ctx, sh, hits, d, t_s, rng, stats, L_direct, idx_k, use_idx,
                                                beta_k, use_beta):
                touched.add("Direct")
            if ctx.maps is not None:
                p_s, ns_s, wo_s, mat_s = hits.position[sh], hits.ns[sh], -d[sh], hits.material[sh]
                ns_f = _face_forward(ns_s, wo_s)
                for kind, dst in (("caustic", L_caustic), ("global", L_indirect)):
                    val = _photon_term(ctx, kind, p_s, ns_f, wo_s, mat_s, t_s, stats)
                    if val is not None:
                        _K.scatter_add(dst, sh, idx_k, use_idx, beta_k, use_beta, np.ascontiguousarray(val))
                        touched.add("Caustic" if kind == "caustic" else "Indirect")
        if bounce == ctx.max_depth or n_spec == 0:
            break
        # -- Continue through delta lobes only (as in shade_paths) ---------------------------
        p, ng = hits.position[spec], hits.ng[spec]
        idx, beta, wi, go = _specular_step(ctx, rng, spec, idx, beta, hits.material[spec], -d[spec], hits.ns[spec],
                                           ng, bounce)
        idx, beta = idx[go], np.ascontiguousarray(beta[go])
        e = _eps_rows(ctx, hits.instance[spec[go]], p[go])
        o = _offset(p[go], ng[go], wi[go], e)
        guard = GUARD_FRACTION * e
        d = np.ascontiguousarray(wi[go])
        tmax = None

    if full:
        a, b = _COL["Combined"]
        V[:, a:a + 3] = L_emit + L_direct + L_indirect + L_caustic
        V[:, a + 3] = covered if ctx.film_transparent else 1.0
    elif "Alpha" in cols:
        V[:, cols["Alpha"][0]] = covered
    return V


# ----------------------------------------------------------------------------
# The image
# ----------------------------------------------------------------------------
@dataclass
class _Context:
    """What every batch needs (built once per trace)."""

    scene: object
    caster: object
    lights: object
    table: object
    maps: object
    map_kinds: dict
    max_depth: int
    inst_offset: np.ndarray                  # (n_instances,) object part of the ray offsets (_eps_rows)
    world_radiance: np.ndarray
    film_transparent: bool
    has_delta: np.ndarray = None             # (M + 1,) bool per material; last row = miss
    visible_lights: bool = False             # some light has a shape a ray can hit
    any_emission: bool = True                # some material emits
    emissive: np.ndarray = None              # (M + 1,) bool per material: emits
    light_visible_camera: list = None        # per light: seen by camera rays (Blender's visible_camera)
    rough_any: bool = False                  # some material has a rough (GGX) lobe
    kernels: bool = False                    # shade with the compiled kernels (shading_kernels)
    zero_passes: tuple = ()                  # passes that stay 0 for every sample
    layout: dict = None                      # columns of a tile's per-sample matrix (_compact_layout)


def _has_delta_lobe(materials) -> np.ndarray:
    """(M + 1,) bool: can bsdf_sample pick a delta lobe (mirror, clear glass, smooth coat)?

    Follows stpm_core.bsdf: refraction is always a delta; metal, glass
    reflection and the coat are deltas at roughness 0.  Row M (index -1) is False.
    """
    out = np.zeros(len(materials) + 1, bool)
    for i, m in enumerate(materials):
        base = (1 - m.metallic) * (1 - m.transmission)
        smooth = m.roughness == 0
        out[i] = ((1 - m.metallic) * m.transmission > 0) or (smooth and (m.metallic > 0 or (base > 0 and m.specular > 0)))
    return out


def _map_kinds(maps) -> dict:
    """Which photon maps exist: {'caustic': bool, 'global': bool}."""
    if maps is None:
        return {"caustic": False, "global": False}
    st = getattr(maps, "stats", {}) or {}
    kinds = {}
    for k in ("caustic", "global"):
        has = getattr(maps, "has", None)
        if callable(has):
            kinds[k] = bool(has(k))
        else:
            n = st.get(f"{k}_photons", st.get(f"photons_{k}", None))
            kinds[k] = True if n is None else int(n) > 0
    return kinds


class _ThreadScratch(threading.local):
    """Per-thread buffers reused from tile to tile (fresh large arrays cost page faults)."""

    def __init__(self):
        self.bufs: dict = {}


_SCRATCH = _ThreadScratch()


def _scratch(name: str, shape: tuple, dtype=np.float64) -> np.ndarray:
    """This thread's buffer ``name`` viewed as an uninitialised array of shape / dtype.

    Valid until the same thread asks for ``name`` again (the next tile).
    """
    size = int(np.prod(shape))
    buf = _SCRATCH.bufs.get(name)
    if buf is None or buf.size < size or buf.dtype != np.dtype(dtype):
        buf = np.empty(size, dtype)
        _SCRATCH.bufs[name] = buf
    return buf[:size].reshape(shape)


def _trace_tile_fast(ctx, film, cam, resolution, x0, y0, tw, th, spp, shutter, rng, time_override, tstats):
    """One tile through the kernels: (film window, TraceStats); same samples as the numpy tile.

    Draws the camera uniforms in :func:`camera_samples`' order, makes rays with
    ``camera_rays`` (the formulas of ``camera.generate_rays``), shades with
    :func:`_shade_paths_fast` and sums per pixel with ``Film.tile_sums_matrix``.
    """
    P, S = tw * th, int(spp)
    n = P * S
    # The uniforms of camera_samples, in its order (drawn into reused buffers)
    jit = rng.random(out=_scratch("jit", (P, S, 2)))
    px, py, xi = _scratch("px", (n,)), _scratch("py", (n,)), _scratch("xi", (n,))
    with_time = time_override is None and not shutter.is_instant
    if with_time:
        perm_u = rng.random(out=_scratch("perm_u", (P, S)))
        time_u = rng.random(out=_scratch("time_u", (P, S)))
    else:
        skip_uniforms(rng, 2 * P * S)
        perm_u = time_u = np.zeros((P, 0))
    _K.camera_tile(x0, y0, tw, th, S, jit, perm_u, time_u, with_time, film.radius, BH_INVERSE_CDF, px, py, xi)
    if time_override is not None:
        times = np.full(n, float(time_override))
    else:
        times = shutter.sample(xi if with_time else np.zeros(n))
    R, pos = camera_to_world(cam, times[:1] if cam.transform.is_static else times)
    R = np.ascontiguousarray(R[:1] if cam.transform.is_static else R, np.float64)
    pos = np.ascontiguousarray(pos[:1] if cam.transform.is_static else pos, np.float64)
    half_w, half_h, cx, cy = image_plane(cam, resolution)
    o, d, tmax0 = _scratch("o", (n, 3)), _scratch("d", (n, 3)), _scratch("tmax0", (n,))
    _K.camera_rays(px, py, int(resolution[0]), int(resolution[1]), float(half_w), float(half_h), float(cx),
                   float(cy), R, pos, cam.type == "ORTHO", float(cam.clip_start), float(cam.clip_end), o, d, tmax0)
    axis = np.ascontiguousarray(-R[:, :, 2])
    touched: set = set()
    layout = ctx.layout
    V = _shade_paths_fast(ctx, o, d, times, tmax0, rng, tstats, pos, axis,
                          V=_scratch("V", (n, max(b for _, b in layout.values()))), layout=layout, touched=touched)
    # Image channel of every column of V; columns of passes nothing reached are left out
    chan, keep = [], []
    for name, (a, b) in layout.items():
        c0 = _COL["Combined"][0] + 3 if name == "Alpha" else _COL[name][0]
        chan.extend(range(c0, c0 + b - a))
        keep.extend([name not in ("Emit", "Direct", "Indirect", "Caustic") or name in touched] * (b - a))
    return film.tile_sums_matrix(x0, y0, tw, th, V, combined_is_sum=True,
                                  alpha_one=not ctx.film_transparent, channels=np.asarray(chan),
                                  columns=np.flatnonzero(keep)), tstats


def trace_image(scene, settings, caster, lights, maps=None, *, table=None, time_override: float | None = None,
                stream: int = 0, progress=None, cancel=None, progress_span=(0.0, 1.0)) -> tuple[dict, TraceStats]:
    """Trace the whole image; returns (passes name -> (H, W, C) float32, TraceStats).

    Parameters
    ----------
    scene, settings : Scene, RenderSettings (samples, seed, max_depth, filter_width).
    caster : from ``make_caster(scene)``; lights : ``LightSet(scene)``.
    maps : ``PhotonMaps`` or None (then Caustic and Indirect are 0).
    time_override : every camera sample at this normalised time (accumulation stills).
    stream : extra random stream id (the accumulation instant), so stills differ.
    progress(fraction, message), cancel() -> bool: polled once per batch.
    """
    import time as _time

    t_start = _time.perf_counter()
    W, H = (int(scene.resolution[0]), int(scene.resolution[1]))
    spp = int(settings.samples)
    stats = TraceStats()
    if table is None:
        table = MaterialTable(scene.materials)
    ctx = _Context(scene=scene, caster=caster, lights=lights, table=table, maps=maps,
                   map_kinds=_map_kinds(maps), max_depth=int(settings.max_depth),
                   inst_offset=instance_offsets(scene),
                   world_radiance=np.asarray(scene.world.radiance, float),
                   film_transparent=bool(scene.metadata.get("film_transparent", False)))
    ctx.has_delta = _has_delta_lobe(scene.materials)
    ctx.any_emission = any(np.any(np.asarray(m.emission) > 0) for m in scene.materials)
    ctx.emissive = np.any(table.emission > 0, axis=1)
    ctx.light_visible_camera = [bool(v) for v in (scene.metadata.get("light_visible_camera") or [])]
    ctx.visible_lights = any(l.type == "AREA" or (l.type in ("POINT", "SPOT") and l.radius > 0)
                             for l in lights.lights)
    ctx.rough_any = bool(np.any(table.rough_lobe))
    ctx.kernels = _K.AVAILABLE
    # Passes no sample can reach: photon passes without that map (the film sums skip them)
    ctx.zero_passes = tuple(name for name, kind in (("Caustic", "caustic"), ("Indirect", "global"))
                            if maps is None or not ctx.map_kinds.get(kind, False))
    ctx.layout = _compact_layout(ctx)
    film = Film(W, H, settings.filter_width)
    cam = scene.camera

    # Tiles: square blocks of about BATCH_SAMPLES samples
    side = int(np.clip(np.sqrt(BATCH_SAMPLES / spp), 1, 64))
    tiles = [(x0, y0) for y0 in range(0, H, side) for x0 in range(0, W, side)]
    static_cam = cam.transform.is_static

    def trace_tile(ti: int):
        """Tile ti traced and summed per pixel: (film window, TraceStats).  Pure function of (seed, stream, ti)."""
        x0, y0 = tiles[ti]
        tstats = TraceStats()
        # Pixels of the tile and their camera samples
        gy, gx = np.mgrid[y0:min(y0 + side, H), x0:min(x0 + side, W)]
        rng = rng_for(settings.seed, STREAM_CAMERA, stream, ti)
        if ctx.kernels and _K.AVAILABLE:
            try:
                return _trace_tile_fast(ctx, film, cam, (W, H), x0, y0, gx.shape[1], gx.shape[0], spp,
                                        scene.shutter, rng, time_override, tstats)
            except _K.CompileError as exc:
                # numba could not compile a kernel here: numpy from now on, this tile again
                _K.disable(f"{type(exc).__name__}: {exc}")
                tstats = TraceStats()
                rng = rng_for(settings.seed, STREAM_CAMERA, stream, ti)
        px, py, times = camera_samples(gx.ravel(), gy.ravel(), spp, scene.shutter, rng, time_override,
                                       filter_width=film.radius)
        o, d = generate_rays(cam, (W, H), px, py, times)
        # Camera pose per sample (once for a static camera) for Depth and clipping
        R, pos = camera_to_world(cam, times[:1] if static_cam else times)
        axis = np.broadcast_to(-R[:, :, 2], (len(times), 3))
        pos = np.broadcast_to(pos, (len(times), 3))
        # Camera clipping: the first segment ends at clip_end along the view axis
        if cam.type == "ORTHO":
            tmax0 = np.full(len(times), cam.clip_end - cam.clip_start)
        else:
            tmax0 = cam.clip_end / np.maximum(np.sum(d * axis, axis=1), 1e-12)
        values = shade_paths(ctx, o, d, times, tmax0, rng, tstats, pos, axis)
        # Per-pixel sums here (on the worker); the film only adds the window, in tile order
        return film.tile_sums(x0, y0, gx.shape[1], gx.shape[0], values), tstats

    # Trace tiles on worker threads (embree and most numpy kernels release the GIL);
    # the film takes them in tile order, so the result does not depend on the threads.
    f0, f1 = progress_span
    for ti, (window, tstats) in enumerate(ordered_map(trace_tile, len(tiles), worker_count(settings), cancel)):
        film.add_window(window)
        stats.merge(tstats)
        if progress is not None:
            progress(f0 + (f1 - f0) * (ti + 1) / len(tiles), f"tracing tile {ti + 1}/{len(tiles)}")
    stats.seconds = _time.perf_counter() - t_start
    return film.resolve(), stats
