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

import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np

from .bsdf import MaterialTable, bsdf_eval, bsdf_sample, diffuse_albedo, emission, has_nondelta
from .camera import camera_to_world, generate_rays
from .errors import RenderCancelled
from .film import DEPTH_BACKGROUND, Film
from .sampling import rng_for

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
                   time_override: float | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Film positions and times for ``spp`` samples in each of the pixels (ix, iy) (P,).

    Returns px, py (P*spp,) continuous pixel coordinates and times (P*spp,)
    normalised shutter times (sample-major within each pixel).

    Position: a rows x cols jittered grid per pixel (rows = floor(sqrt spp),
    cols = spp // rows), leftover samples uniform.  Time: xi = (pi_p(j) + U) / spp
    with pi_p a random permutation per pixel, mapped through ``shutter.sample``
    (the shutter curve's inverse CDF); ``time_override`` fixes every time.
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
    px = (ix[:, None] + ux).ravel()
    py = (iy[:, None] + uy).ravel()
    # Time strata, permuted independently in each pixel
    perm = np.argsort(rng.random((P, S)), axis=1)
    xi = ((perm + rng.random((P, S))) / S).ravel()
    if time_override is not None:
        times = np.full(P * S, float(time_override))
    else:
        times = shutter.sample(xi)
    return px, py, times


# ----------------------------------------------------------------------------
# Shading helpers
# ----------------------------------------------------------------------------
def _offset(p: np.ndarray, ng: np.ndarray, w: np.ndarray, eps: float) -> np.ndarray:
    """Ray origin p moved by eps along ng to the side w (n, 3) points to."""
    side = np.where(np.sum(ng * w, axis=1) >= 0.0, 1.0, -1.0)
    return p + (eps * side)[:, None] * ng


def _face_forward(n: np.ndarray, w: np.ndarray) -> np.ndarray:
    """n (n, 3) flipped to the hemisphere of w (n, 3)."""
    return n * np.where(np.sum(n * w, axis=1) >= 0.0, 1.0, -1.0)[:, None]


def _rows(a: np.ndarray, sel: np.ndarray | None) -> np.ndarray:
    """a[sel], or a itself when sel is None (every row, in order: no copy)."""
    return a if sel is None else a[sel]


def _direct(ctx, p, ng, ns, wo, mat, times, rng, stats: TraceStats) -> np.ndarray:
    """Next-event estimate (n, 3): sum over lights of f(wo, wi) |cos(ns, wi)| L_i / p * V.

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
        wi, dist, weight = lights.sample_direct(li, p, times, rng.random((n, 2)))
        f = bsdf_eval(ctx.table, mat, wo, wi, ns, ng)
        contrib = f * (np.abs(np.einsum("ij,ij->i", ns, wi)))[:, None]
        contrib *= weight
        live = np.nonzero(np.any(contrib > 0.0, axis=1))[0]
        if live.size == 0:
            continue
        # Shadow rays at the same time, stopping just short of the light
        all_rows = live.size == n
        sel = None if all_rows else live
        wl, pl, dl = _rows(wi, sel), _rows(p, sel), _rows(dist, sel)
        o = _offset(pl, _rows(ng, sel), wl, ctx.eps)
        # Aim from the offset origin at the light point itself and stop a margin short of
        # it: emissive triangles are geometry the shadow ray must not reach
        fin = np.isfinite(dl)
        v = np.where(fin[:, None], pl + np.where(fin, dl, 0.0)[:, None] * wl - o, wl)
        s = np.sqrt(np.einsum("ij,ij->i", v, v))
        dirs = v / s[:, None]
        tmax = np.where(fin, s * (1.0 - 1e-6) - 2.0 * ctx.eps, np.inf)
        blocked = ctx.caster.occluded(o, dirs, _rows(times, sel), tmax)
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
    from .lights import spot_attenuation

    n = o.shape[0]
    L = np.zeros((n, 3))
    for li, light in enumerate(lights.lights):
        if light.type == "MESH":
            continue                          # emissive triangles: the caster hits them (Emit)
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
            cross = np.cross(ex, ey)
            A4 = np.linalg.norm(cross, axis=1)
            n_emit = -cross / np.maximum(A4, 1e-300)[:, None]
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
    """
    n = o.shape[0]
    # Path state: idx maps live rows to samples (None = all), beta their throughput (None = 1)
    idx = None
    beta = None
    tmax = tmax0                             # camera clipping for the first segment
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
        t = times if idx is None else times[idx]
        hits = ctx.caster.intersect(o, d, t, tmax)
        if bounce == 0:
            stats.camera_rays += m
        else:
            stats.bounce_rays += m
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
            wo = -d[keep]                     # directions are unit (camera, bsdf_sample)
        else:
            p, ng, ns, mat = hits.position, hits.ng, hits.ns, hits.material
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
                add(L_direct, sh, _direct(ctx, p_s, ng_s, ns_s, wo_s, mat_s, t_s, rng, stats))
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
        u = rng.random((spec.size, 3))
        idx = spec if idx is None else idx[spec]
        beta = None if beta is None else beta[spec]
        p, ng, ns, wo, mat = p[spec], ng[spec], ns[spec], wo[spec], mat[spec]
        wi, weight, is_delta = bsdf_sample(ctx.table, mat, wo, ns, ng, u)
        beta = weight if beta is None else beta * weight
        go = is_delta & np.any(beta > 0.0, axis=1)

        # -- Possibly terminate the chain with Russian roulette -------------------------------
        if bounce + 1 >= RR_START:
            q = np.clip(np.max(beta, axis=1), 0.05, 1.0)
            go &= rng.random(idx.size) < q
            beta = beta / q[:, None]

        idx, beta = idx[go], beta[go]
        o = _offset(p[go], ng[go], wi[go], ctx.eps)
        d = wi[go]
        tmax = None

    combined = np.concatenate([L_emit + L_direct + L_indirect + L_caustic,
                               (covered if ctx.film_transparent else np.ones(n))[:, None]], axis=1)
    return {"Combined": combined, "Depth": depth[:, None], "Normal": normal,
            "Emit": L_emit, "Direct": L_direct, "Indirect": L_indirect, "Caustic": L_caustic}


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
    eps: float
    world_radiance: np.ndarray
    film_transparent: bool
    has_delta: np.ndarray = None             # (M + 1,) bool per material; last row = miss
    visible_lights: bool = False             # some light has a shape a ray can hit
    any_emission: bool = True                # some material emits
    emissive: np.ndarray = None              # (M + 1,) bool per material: emits
    light_visible_camera: list = None        # per light: seen by camera rays (Blender's visible_camera)


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


def _worker_count(settings) -> int:
    """Tile worker threads: settings.threads, 0 = all cores."""
    n = int(getattr(settings, "threads", 0) or 0)
    return max(1, n if n > 0 else (os.cpu_count() or 1))


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
    lo, hi = scene.bounds()
    extent = float(np.linalg.norm(hi - lo))
    ctx = _Context(scene=scene, caster=caster, lights=lights, table=table, maps=maps,
                   map_kinds=_map_kinds(maps), max_depth=int(settings.max_depth),
                   eps=1e-5 * max(extent, 1e-3) + 1e-7 * float(np.max(np.abs(np.concatenate([lo, hi])), initial=0.0)),
                   world_radiance=np.asarray(scene.world.radiance, float),
                   film_transparent=bool(scene.metadata.get("film_transparent", False)))
    ctx.has_delta = _has_delta_lobe(scene.materials)
    ctx.any_emission = any(np.any(np.asarray(m.emission) > 0) for m in scene.materials)
    ctx.emissive = np.any(table.emission > 0, axis=1)
    ctx.light_visible_camera = [bool(v) for v in (scene.metadata.get("light_visible_camera") or [])]
    ctx.visible_lights = any(l.type == "AREA" or (l.type in ("POINT", "SPOT") and l.radius > 0)
                             for l in lights.lights)
    film = Film(W, H, settings.filter_width)
    cam = scene.camera

    # Tiles: square blocks of about BATCH_SAMPLES samples
    side = int(np.clip(np.sqrt(BATCH_SAMPLES / spp), 1, 64))
    tiles = [(x0, y0) for y0 in range(0, H, side) for x0 in range(0, W, side)]
    static_cam = cam.transform.is_static

    def trace_tile(ti: int):
        """Tile ti traced and splatted: (film window, TraceStats).  Pure function of (seed, stream, ti)."""
        x0, y0 = tiles[ti]
        tstats = TraceStats()
        # Pixels of the tile and their camera samples
        gy, gx = np.mgrid[y0:min(y0 + side, H), x0:min(x0 + side, W)]
        rng = rng_for(settings.seed, STREAM_CAMERA, stream, ti)
        px, py, times = camera_samples(gx.ravel(), gy.ravel(), spp, scene.shutter, rng, time_override)
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
        # Filter splat here (on the worker); the film only adds the window, in tile order
        return film.splat_tile(x0, y0, gx.shape[1], gx.shape[0], px, py, values), tstats

    # Trace tiles on worker threads (embree and most numpy kernels release the GIL);
    # the film takes them in tile order, so the result does not depend on the threads.
    workers = _worker_count(settings)
    f0, f1 = progress_span
    pool = ThreadPoolExecutor(max_workers=workers) if workers > 1 else None
    pending: dict = {}
    try:
        for ti in range(len(tiles)):
            if cancel is not None and cancel():
                raise RenderCancelled("render cancelled")
            if pool is None:
                result = trace_tile(ti)
            else:
                # Keep up to 2 tiles per worker in flight
                for tj in range(ti, min(ti + 2 * workers, len(tiles))):
                    if tj not in pending:
                        pending[tj] = pool.submit(trace_tile, tj)
                result = pending.pop(ti).result()
            window, tstats = result
            film.add_window(window)
            stats.merge(tstats)
            if progress is not None:
                progress(f0 + (f1 - f0) * (ti + 1) / len(tiles), f"tracing tile {ti + 1}/{len(tiles)}")
    finally:
        if pool is not None:
            for fut in pending.values():
                fut.cancel()
            pool.shutdown(wait=True)
    stats.seconds = _time.perf_counter() - t_start
    return film.resolve(), stats
