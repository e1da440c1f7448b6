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

Rough glossy lobes at a shading vertex get light through next-event estimation (``bsdf_eval``
includes every non-delta lobe) and the paths that go on through them; photon estimates multiply
by the diffuse albedo, except that a rough reflection lobe of roughness >=
``GLOSSY_CAUSTIC_MIN_ROUGHNESS`` also reads the caustic map's delta-only photons, each weighed by
f_c(wo, wi_p) (then its paths drop what they reach through delta vertices alone; docs/rendering.md,
"Path partition").
"""
from __future__ import annotations

import math
import threading
from dataclasses import dataclass, field, replace as _replace

import numpy as np

from . import kernels as _kernels
from .kernels import kernel_array
from .camera import camera_to_world, image_plane, lens_args
from .film import BH_INVERSE_CDF, DENOISING_GUIDES, DEPTH_BACKGROUND, PASSES, Film
from .kernels import gather as _G
from .kernels import paths as _K
from .kernels import static_views as _SV
from .kernels.bsdf import ggx_albedo_tables
from .kernels.closure import (C_CC_ROUGH, C_CC_WEIGHT, C_PASS, C_ROUGH_LOBE, C_ROUGHNESS, C_W_GLASS, N_CLOSURE,
                              pack_materials)
from .kernels.light_params import light_params, light_poses, mesh_arrays
from .world_light import constant_environment
from .kernels.svm import shade_rows
from .parallel import ordered_map, worker_count
from .photons import sharing as _sharing
from .photons.estimators import plane_weights
from .raycast.geometry import GUARD_FRACTION, OFFSET_POS, instance_offsets, offset_lengths, segment_of
from .sampling import rng_for, skip_uniforms
from .scene import light_visibility
from .shading import hit_geometry, shading_data
from .transparency import pass_through, shadow_transmittance

__all__ = ["TraceStats", "trace_image", "shade_paths"]

# Random streams (second entry of rng_for(seed, ...)): one per purpose.
STREAM_CAMERA = 0x5A3
STREAM_PATTERN = 0xAD5                   # adaptive sampling: a round's camera samples, per tile
ADAPTIVE_STREAM = 0xADA                  # adaptive sampling: a round's batches (under STREAM_CAMERA)
# Samples traced together in one wavefront batch (tile pixels x spp): large
# batches amortise Python overhead; the caster cuts them into embree-sized chunks.
BATCH_SAMPLES = 65536
# Bounces after which Russian roulette may end a specular chain.
RR_START = 3
#: Russian roulette of the continuations that DIFFUSE picks make for the rough lobes' part of f
#: (``kernels.bsdf.bsdf_sample_cont``, ``kernels.paths.specular_step``): a path whose throughput is
#: below CONT_RR goes on with probability throughput / CONT_RR (docs/rendering.md, "Continuation
#: weights": at 0.25 the review's scene casts 5 % more bounce rays, a scene of default Principled
#: BSDFs at roughness 0.5 2.7x as many, +20 % CPU time; 0.5 and 1 trade variance back for rays)
CONT_RR = 0.25
#: A static view reads the shutter's average (docs/photon-mapping.md, "Static views read the
#: shutter's average"): with TEMPORAL or KD4D maps, a camera ray's first hit on a static surface,
#: seen along a ray no moving object crosses during the shutter, is estimated with STANDARD (the
#: same expected value there, all photons, a cheaper search).  False: every query uses the
#: render's estimator.
STATIC_VIEW = True
#: A moving instance's sweep is tested as capsules around its bounding sphere's path over
#: STATIC_VIEW_STEPS equal parts of the shutter; at most STATIC_VIEW_MAX_CAPSULES capsules in all
#: (fewer parts per instance when many move, down to one each)
STATIC_VIEW_STEPS = 16
STATIC_VIEW_MAX_CAPSULES = 256
#: Static views also for the rough lobes' caustic look-ups (``_glossy_caustic``).  Off: measured on
#: the product shot (Final, seed 1), STANDARD there read the caustic region 0.966 of the converged
#: reference with block correlation 0.888 (the render's TEMPORAL: 0.989 / 0.959): k-NN blur that
#: TEMPORAL's window widening had offset, and a pixel's samples sharing one time-blind estimate
#: (docs/photon-mapping.md, "Later vertices").
STATIC_VIEW_GLOSSY = False
#: The roughness from which a rough reflection lobe (coat, metal) of a camera vertex reads the caustic
#: map (L S+ x through that lobe: each delta-only caustic photon weighed by f_c(wo, wi_p)), and the
#: paths that leave the vertex through its rough lobes stop counting the light they reach through
#: delta vertices alone (docs/rendering.md, "Path partition").  Below it a lobe is too sharp for a
#: k-nearest disc and stays path traced; inf switches the rule off.
GLOSSY_CAUSTIC_MIN_ROUGHNESS = 0.5


@dataclass
class TraceStats:
    """Counters of one image trace."""

    camera_rays: int = 0
    bounce_rays: int = 0
    shadow_rays: int = 0
    photon_lookups: int = 0                  # photon-map queries (shading points x maps)
    photon_estimates: int = 0                # of them estimated; the others shared one (photons.sharing)
    static_lookups: int = 0                  # of the look-ups, those read as STANDARD: a static view (static_view_rows)
    gather_rays: int = 0                     # final gathering's rays (all bounces)
    gather_lookups: int = 0                  # final gathering's reads of the precomputed irradiance
    seconds: float = 0.0
    extra: dict = field(default_factory=dict)

    def merge(self, other: "TraceStats") -> None:
        """Add another trace's counters (tile results) into this one."""
        self.camera_rays += other.camera_rays
        self.bounce_rays += other.bounce_rays
        self.shadow_rays += other.shadow_rays
        self.photon_lookups += other.photon_lookups
        self.photon_estimates += other.photon_estimates
        self.static_lookups += other.static_lookups
        self.gather_rays += other.gather_rays
        self.gather_lookups += other.gather_lookups

    @property
    def rays(self) -> int:
        return self.camera_rays + self.bounce_rays + self.shadow_rays + self.gather_rays


# ----------------------------------------------------------------------------
# Random numbers of the lights
# ----------------------------------------------------------------------------
def _is_delta_light(light) -> bool:
    """A light sampled without random numbers: POINT / SPOT of radius 0, SUN of angle 0."""
    if light.type in ("POINT", "SPOT"):
        return float(light.radius) <= 0.0
    return light.type == "SUN" and float(light.angle) <= 0.0


def _light_uniforms(light, samples: np.ndarray, strata: tuple, rng: np.random.Generator, out: np.ndarray) -> np.ndarray:
    """Uniforms (k, 2) for one light's samples at k shaded rows, one block of the stream per light,
    written into out.

    samples (k,) int64: each row's sample in the tile; strata = (n, S): the tile's n samples, S
    per pixel.  Drawn: the pixels' keys (n / S, S) (their permutations and scramble seed), then
    jitters (k, 2); placed by ``kernels.paths.light_strata`` (each pixel's samples of the light
    stratified).  Delta lights ignore them: that block is skipped (``skip_uniforms``) and zeros
    are returned, the stream ending where drawing would leave it.
    """
    n, S = strata
    k = samples.shape[0]
    if _is_delta_light(light):
        skip_uniforms(rng, n + 2 * k)
        out[...] = 0.0
        return out
    return strata_uniforms(samples, strata, rng, out)


def strata_uniforms(samples: np.ndarray, strata: tuple, rng: np.random.Generator, out: np.ndarray) -> np.ndarray:
    """Uniforms (k, 2) for k rows whose tile samples are samples (k,) int64, each pixel's samples
    stratified against their film cells (``kernels.paths.light_strata``), written into out;
    strata = (n, S): the tile's n samples, S per pixel.  Drawn: keys (n / S, S), then jitters
    (k, 2).  A light's samples at a bounce (:func:`_light_uniforms`) and the directions of the
    continuation lobes (``kernels.paths.specular_step``'s u1, u2) take one block each."""
    n, S = strata
    k = samples.shape[0]
    keys = rng.random(out=_scratch("light_keys", (n // S, S)))
    jit = rng.random(out=_scratch("light_jit", (k, 2)))
    _K.light_strata(samples, S, keys, jit, out)
    return out


def _has_shape(light) -> bool:
    """Can a ray hit the light itself (an AREA light, a POINT / SPOT sphere of radius > 0, the cone of a
    SUN of angle > 0 for rays that escape the scene)?"""
    return (light.type == "AREA" or (light.type in ("POINT", "SPOT") and float(light.radius) > 0.0)
            or (light.type == "SUN" and float(light.angle) > 0.0))


# ----------------------------------------------------------------------------
# Paths of one batch of camera samples, through the kernels (kernels.paths)
# ----------------------------------------------------------------------------
# Column of each pass in the per-sample matrix V (n, 26): PASSES order, then the denoising guides
# (the film's channel order; the guides only with RenderSettings.denoise)
_COL = {}
_c = 0
for _name, _nc, _ in PASSES + DENOISING_GUIDES:
    _COL[_name] = (_c, _c + _nc)
    _c += _nc
_NO_IDX = np.zeros(0, np.int64)
_NO_U = np.zeros(0)
_NO_ROWS3 = np.zeros((0, 3))
_NO_FLAGS = np.zeros(0, np.uint8)
_NO_TERM = np.zeros((1, 7))              # no shadow-terminator data (kernels.paths.nee_light, use_term False)


def _compact_layout(ctx) -> dict[str, tuple[int, int]]:
    """Columns of the per-sample matrix of a tile: only the passes this render can fill.

    Depth, Normal, Emit, Direct always; Indirect / Caustic with their photon
    map; ``Alpha`` (the coverage, Combined's alpha) with a transparent film; Denoising Albedo and
    Normal with ``RenderSettings.denoise``.
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
    if ctx.features:
        names.extend((name, k) for name, k, _ in DENOISING_GUIDES)
    out, c = {}, 0
    for name, k in names:
        out[name] = (c, c + k)
        c += k
    return out


_IDENTITY_POSE = np.eye(4)[None].copy()


def _no_mis(k: int) -> np.ndarray:
    out = _scratch("no_mis", (k,), np.uint8)
    out[:] = 0
    return out


def mis_rows(ctx, bounce: int, counts, sh: np.ndarray) -> np.ndarray:
    """(k,) uint8 bits: where the shaded row sh[i]'s path may go on through a rough lobe (bounces
    left, ``kernels.paths.specular_step``): 1 through a reflection (the Glossy budget left), 2
    through a refraction (the Transmission budget left).  Next-event estimation of a light on
    that side of the surface is then weighed against the continuation (``kernels.paths.nee_light``)."""
    out = _scratch("mis", (sh.size,), np.uint8)
    if bounce >= ctx.max_depth:
        out[:] = 0
    elif counts is None:
        out[:] = (1 if ctx.glossy_bounces > 0 else 0) | (2 if ctx.transmission_bounces > 0 else 0)
    else:
        c = counts[sh]
        out[:] = (c[:, 0] < ctx.glossy_bounces) * np.uint8(1) | (c[:, 1] < ctx.transmission_bounces) * np.uint8(2)
    return out


def _world_poses(ctx, t: np.ndarray) -> np.ndarray:
    """The world mapping's map-to-world matrices (k, 4, 4) at the rows' times t (k = 1: static)."""
    if ctx.world_li < 0:
        return _IDENTITY_POSE
    return light_poses(ctx.lights, ctx.world_li, t)


def _first_pose(a: np.ndarray) -> np.ndarray:
    """(k, 3) contiguous: one row when every row of a (n, 3) is the same view (stride 0)."""
    a = np.asarray(a, np.float64)
    if a.shape[0] > 0 and a.strides[0] == 0:
        return np.ascontiguousarray(a[:1])
    return np.ascontiguousarray(a)


def _light_vis(ctx, li: int) -> int:
    """Light li's Ray Visibility bits (1 diffuse, 2 glossy, 4 transmission; 7 = all, lights past
    the exported ones: the world, mesh lights)."""
    vis = ctx.light_vis
    return int(vis[li]) if vis is not None and li < len(vis) else 7


def _direct(ctx, sh: np.ndarray, hits, d: np.ndarray, C: np.ndarray, crow: np.ndarray, t_s: np.ndarray, rng,
            stats: TraceStats, dst: np.ndarray, idx_k, use_idx: bool, beta_k, use_beta: bool, mis: np.ndarray = None,
            clamp: float = 0.0, strata: tuple = None, sid: np.ndarray = None) -> bool:
    """Next-event estimation at the hit rows sh (k,) of ``hits`` (rays d, closures C, hit r's is row
    crow[r], ``kernels.svm.shade_rows``), added straight
    into dst (n, 3) (the Direct pass: dst[idx[row]] += beta[row] * contribution, light by light);
    returns whether any shadow ray was cast.  mis (k,) uint8: the paths of these rows may go on
    through their rough lobes (the world's samples are then weighed against them,
    ``kernels.paths.nee_light``; :func:`mis_rows`; None: none may);
    clamp: each light sample's contribution at most this (0: off; Cycles' Clamp Direct / Indirect);
    strata: (n, S) the tile's sample count and samples per pixel (None: (k, 1), no strata), over
    which the light's uniforms are stratified; sid (live rows,) int64: each row's stratum among
    them when it is not its sample (split paths, :func:`shade_paths`; None: idx_k's).

    Per light with power: its (k, 2) uniforms (``_light_uniforms``), ``kernels.paths.nee_light``
    (light sample + BSDF + shadow-ray set-up), the shadow rays at the rows' times, then
    ``nee_accumulate`` of the unblocked ones.
    """
    k = sh.size
    cast_any = False
    lights = ctx.lights
    P, NG, NS = hits.position, hits.ng, hits.ns
    EPS = _scratch("eps", (P.shape[0],))
    _K.offset_rows(sh, ctx.inst_offset, hits.instance, P, OFFSET_POS, EPS)   # shadow-ray offsets of the shaded rows
    TERM = _terminator(ctx, sh, hits, t_s) if ctx.term_any else _NO_TERM
    so, sd = _scratch("so", (k, 3)), _scratch("sd", (k, 3))
    stmax, live = _scratch("stmax", (k,)), _scratch("live", (k,), np.int64)
    contrib = _scratch("contrib", (k, 3))
    S = _scratch("light_samples", (k, 8))
    E, E_avg = ctx.ggx
    if strata is None:
        samples, strata = np.arange(k), (k, 1)
    elif sid is not None:
        samples = np.take(sid, sh, out=_scratch("light_samples_of", (k,), np.int64))
    else:
        samples = np.take(idx_k, sh, out=_scratch("light_samples_of", (k,), np.int64)) if use_idx else sh
    for li in range(len(lights)):
        if lights.power[li] <= 0.0:
            continue
        vis = _light_vis(ctx, li)
        if vis == 0:
            continue                     # Ray Visibility: no diffuse, glossy or transmission ray sees it
        light = lights.lights[li]
        u = _light_uniforms(light, samples, strata, rng, _scratch("u_light", (k, 2)))
        prm, mesh = ctx.light_data[li]
        poses = light_poses(lights, li, t_s)
        m = _K.nee_light(sh, P, NG, NS, d, C, crow, E, E_avg, prm, poses, *mesh, t_s, u, EPS, TERM,
                         ctx.term_any,
                         _no_mis(k) if mis is None or vis != 7 else mis, ctx.stop_coat, contrib, so, sd, stmax, live,
                         S, vis)
        if m == 0:
            continue
        if getattr(light, "textured", False):
            # a textured emitter: the kernels weighed its samples with radiance 1; each live
            # sample now gets what its own light point emits
            lv = live[:m]
            wi, dist = S[lv, 0:3], S[lv, 3:4]
            Le = light.point_emission(u[lv], P[sh[lv]] + dist * wi, wi, t_s[lv])
            contrib[lv] *= Le
        lv = live[:m]
        t_live = np.take(t_s, lv, out=_scratch("t_live", (m,)))
        if ctx.shading.transparent:
            # shadow rays pass transparent surfaces, tinted by them
            T = shadow_transmittance(ctx.caster, ctx.shading, ctx.inst_offset, so[:m], sd[:m], t_live, stmax[:m],
                                     GUARD_FRACTION * EPS[sh[lv]], rng, limit=ctx.transparent_max_bounces)
            contrib[lv] *= T
            blocked = ~np.any(T > 0.0, axis=1)
        else:
            blocked = ctx.caster.occluded(so[:m], sd[:m], t_live, stmax[:m], guard=GUARD_FRACTION * EPS[sh[lv]])
        stats.shadow_rays += m
        cast_any = True
        _K.nee_accumulate(dst, sh, idx_k, use_idx, beta_k, use_beta, contrib, lv,
                          np.ascontiguousarray(blocked, np.bool_), float(clamp))
    return cast_any


def terminator_settings(scene) -> tuple[np.ndarray, np.ndarray]:
    """Per instance (n_instances,): the shadow-terminator cutoff (``Instance.shadow_terminator_
    geometry_offset`` where the mesh has smooth normals, deforming or not, else 0) and the shading
    offset's frequency multiplier 1 / (1 - s / 2) (s = ``shadow_terminator_shading_offset``; 1: off),
    as Cycles' ``scene/object.cpp`` stores them."""
    n = len(scene.instances)
    cut, freq = np.zeros(n), np.ones(n)
    for i, inst in enumerate(scene.instances):
        mesh = scene.meshes[inst.mesh]
        if mesh.normals is not None:
            cut[i] = float(getattr(inst, "shadow_terminator_geometry_offset", 0.1))
        so = float(getattr(inst, "shadow_terminator_shading_offset", 0.0))
        freq[i] = 1.0 / (1.0 - 0.5 * so) if so < 2.0 else 1.0       # Cycles: a multiplier <= 1 is off
    return cut, freq


def _term_mesh(ctx, mi: int) -> tuple:
    """(vertices (K, V, 3) float32, triangles (F, 3) int32, corner normals (K, F, 3, 3) float32,
    vertex times (K,) float64 or None) of mesh mi at its K vertex steps (K = 1: rigid), contiguous,
    kept per render (``kernels.paths.terminator_rows`` reads them per hit)."""
    kept = ctx.term_meshes.get(mi)
    if kept is None:
        m = ctx.scene.meshes[mi]
        V = np.asarray(m.vertices, np.float32)
        deforming = m.is_deforming
        V = V if deforming else V.reshape(-1, 3)[None]
        N = m.normal_keys
        if N.shape[0] != V.shape[0]:                    # one set of normals shared by every step
            N = np.repeat(N[:1], V.shape[0], axis=0)
        kept = (np.ascontiguousarray(V), np.ascontiguousarray(m.triangles, np.int32),
                np.ascontiguousarray(N, np.float32), np.asarray(m.vertex_times, np.float64) if deforming else None)
        ctx.term_meshes[mi] = kept
    return kept


def _terminator(ctx, sh: np.ndarray, hits, t_s: np.ndarray) -> np.ndarray:
    """TERM (m, 7) of ``kernels.paths.nee_light`` for the shaded rows sh (k,) (times t_s (k,)): each
    row's cutoff 0 and frequency multiplier 1, then per instance with a cutoff > 0
    ``kernels.paths.terminator_rows`` of its rows (its mesh as :func:`_term_mesh` keeps it, its
    linear part at the rows' times); an instance with only a shading offset gets its multiplier."""
    TERM = _scratch("term", (hits.t.shape[0], 7))
    TERM[sh, 5] = 0.0
    TERM[sh, 6] = 1.0
    inst = hits.instance[sh]
    scene = ctx.scene
    for i in np.unique(inst):
        i = int(i)
        cut, fm = ctx.term_cut[i], ctx.term_freq[i]
        if not (cut > 0.0 or fm > 1.0):
            continue
        sel = np.flatnonzero(inst == i)
        rows = np.ascontiguousarray(sh[sel], np.int64)
        if not cut > 0.0:
            TERM[rows, 6] = fm
            continue
        Vs, T, Ns, vt = _term_mesh(ctx, scene.instances[i].mesh)
        if vt is None:
            seg, frac = np.zeros(sel.size, np.int64), np.zeros(sel.size)
        else:                                           # each row's vertex step at its time
            seg, frac = segment_of(vt, np.asarray(t_s, np.float64)[sel])
            seg, frac = np.ascontiguousarray(seg, np.int64), np.ascontiguousarray(frac, np.float64)
        tr = scene.instances[i].transform
        if tr.is_static:
            M = np.ascontiguousarray(np.asarray(tr.matrices[0], np.float64)[None, :3, :3])
        else:
            M = np.ascontiguousarray(np.asarray(tr.at(np.asarray(t_s, np.float64)[sel]), np.float64)[:, :3, :3])
        _K.terminator_rows(rows, np.ascontiguousarray(hits.prim, np.int32), Vs, T, Ns, seg, frac, M,
                           np.ascontiguousarray(hits.u, np.float64), np.ascontiguousarray(hits.v, np.float64),
                           float(cut), float(fm), TERM)
    return TERM


def _seen_lights(ctx, o, d, t, t_scene, first: bool, glossy=None, p_c=None):
    """Radiance (m, 3) of light shapes hit by rays o + s d (unit d) at times t before t_scene (m,),
    summed over lights in order, and the same weighed for multiple importance sampling (rows
    that left a rough lobe, ``glossy`` (m,) uint8 or None, with density p_c (m,):
    ``kernels.paths.seen_lights_add``); (None, None) when no light can be seen by these rays.

    What camera rays and delta chains see of the lights themselves, as in Cycles: camera rays see
    light i only if Blender's Object > Visibility > Camera is on for it
    (``scene.metadata['light_visible_camera']``, off by default); AREA lights are one-sided
    emitters of radiance color P / (pi A), POINT / SPOT of radius r > 0 have radiance
    I / (pi r^2), spot-masked, on the disc facing the ray's origin (soft falloff) or the sphere,
    a SUN of angle > 0 radiance color S / (pi sin^2(angle / 2)) in its cone where the ray escapes (t_scene inf;
    ``kernels.lights.seen_light``).
    """
    L = Lw = None
    vis = ctx.light_visible_camera
    use_glossy = glossy is not None
    for li in ctx.shaped_lights:
        if first and not (li < len(vis) and vis[li]):
            continue
        if not first and _light_vis(ctx, li) != 7:
            continue          # a light hidden from some ray kind: next-event estimation carries it whole
        if L is None:
            L, Lw = np.zeros((o.shape[0], 3)), np.zeros((o.shape[0], 3))
        _K.seen_lights_add(ctx.light_data[li][0], light_poses(ctx.lights, li, t), o, d, t_scene, first, L, Lw,
                           glossy if use_glossy else _NO_FLAGS, use_glossy, p_c if use_glossy else _NO_U)
    return L, Lw


def _glossy_emission(ctx, gem: np.ndarray, hits, o, t: np.ndarray, C, crow, p_c, dst, idx_k, use_idx: bool,
                     beta_k, use_beta: bool, clamp: float) -> None:
    """Emission of the emissive hits gem (k,) of rays that left a rough lobe (density p_c (m,), from
    o (m, 3) at times t (m,)), weighed against next-event estimation and added into dst (Emit).

    The hit's triangle belongs to a MESH light with power (``ctx.mesh_emitters``): the power
    heuristic p_c^2 / (p_c^2 + p_l^2) (``kernels.paths.mesh_emission_mis``); else next-event
    estimation never draws it, and the path counts it whole (weight 1)."""
    W = np.ones(gem.size)
    inst = hits.instance[gem]
    for li, (instance, J_of_prim) in ctx.mesh_emitters.items():
        sel = np.flatnonzero(inst == instance)
        if sel.size == 0:
            continue
        rows = np.ascontiguousarray(gem[sel])
        J = np.ascontiguousarray(J_of_prim[hits.prim[rows]], np.int64)
        Wl = np.ones(sel.size)
        steps, corners, q = ctx.light_data[li][1][:3]              # kernels.light_params.mesh_arrays
        _K.mesh_emission_mis(rows, o, hits.position, t, p_c, light_poses(ctx.lights, li, t[rows]), steps, corners,
                             q, J, Wl)
        W[sel] = Wl
    _K.emission_rows_add(dst, gem, C, crow, W, idx_k, use_idx, beta_k, use_beta, float(clamp))


def _estimate(ctx, kind: str, p, ns, t, group, extra: dict, estimator: str | None = None, ng=None):
    """(E (n, 3) irradiance of map ``kind`` at the queries, estimates made): alone, or shared by
    ``group`` (``photons.sharing``); estimator None: the render's.  ng (n, 3): the queries' geometric
    normals (their tangent slabs, ``PhotonMap.estimate``)."""
    if estimator is not None:
        extra = dict(extra, estimator=estimator)
    if group is None:
        return ctx.maps.estimate(kind, p, ns, t, ng=ng, **extra), p.shape[0]
    return _sharing.shared_estimate(lambda p, ns, t, ng=None: ctx.maps.estimate(kind, p, ns, t, support=True, ng=ng,
                                                                                **extra),
                                    p, ns, t, group, ng=ng)


def _estimate_split(ctx, kind: str, p, ns, t, group, extra: dict, static: np.ndarray | None, ng):
    """:func:`_estimate` where the queries of static views (static (n,) bool, or None: none) read the
    maps with STANDARD, the others with the render's estimator (ng (n, 3) the geometric normals)."""
    if static is None or not static.any():
        return _estimate(ctx, kind, p, ns, t, group, extra, ng=ng)
    E, estimated = np.empty((p.shape[0], 3)), 0
    for sel, est in ((static, "STANDARD"), (~static, None)):
        if sel.any():
            # (np.take: half the time of fancy indexing for these row gathers)
            i = np.flatnonzero(sel)
            E[i], e = _estimate(ctx, kind, np.take(p, i, axis=0), np.take(ns, i, axis=0), np.take(t, i),
                                None if group is None else np.take(group, i), extra_sel(extra, i), est,
                                np.take(ng, i, axis=0))
            estimated += e
    return E, estimated


def static_view_setup(scene, maps) -> tuple | None:
    """What :func:`static_view_rows` needs, or None when no query may read the shutter's average.

    Returns (static (n_instances,) bool: the instance neither moves nor deforms within the shutter;
    lo, hi (M, 3): each moving instance's box over the whole shutter; a, b (K, 3), r (K,): capsules
    (segments a-b, radius r) that hold every moving instance at every instant -- the sphere around
    its vertices (centred on their box) has its centre sampled at ``STATIC_VIEW_STEPS`` + 1 instants, consecutive samples joined, the
    radius widened by the path's bend between them).  None unless ``STATIC_VIEW``, the maps answer
    STANDARD too (``PhotonMaps``; not the progressive kernel or SPPM's per-pixel statistics), the
    render's estimator depends on time (TEMPORAL, KD4D), the shutter is open and the camera does
    not move.
    """
    if not STATIC_VIEW or maps is None or not getattr(maps, "reads_standard", False):
        return None
    if str(getattr(maps, "estimator", "STANDARD")).upper() not in ("TEMPORAL", "KD4D"):
        return None
    if scene.shutter.is_instant or not scene.camera.transform.is_static or not scene.instances:
        return None
    static = np.array([inst.transform.is_static and not scene.meshes[inst.mesh].is_deforming
                       for inst in scene.instances], dtype=bool)
    if not static.any():
        return None
    moving = [inst for inst, s in zip(scene.instances, static) if not s]
    steps = max(1, min(STATIC_VIEW_STEPS, STATIC_VIEW_MAX_CAPSULES // max(len(moving), 1)))
    lo, hi, ca, cb, cr = [], [], [], [], []
    for inst in moving:
        a, b = scene.meshes[inst.mesh].vertex_bounds()
        if not (np.all(np.isfinite(a)) and np.all(np.isfinite(b))):
            continue                                      # no vertices
        box_lo, box_hi = inst.transform.bounds_of(a, b)
        lo.append(box_lo)
        hi.append(box_hi)
        # the object's bounding sphere at 2 * steps + 1 instants: the ends and middles of the parts
        M = inst.transform.at(np.linspace(0.0, 1.0, 2 * steps + 1))
        c = np.einsum("kij,j->ki", M[:, :3, :3], 0.5 * (a + b)) + M[:, :3, 3]
        v = np.asarray(scene.meshes[inst.mesh].vertices, np.float64).reshape(-1, 3)   # every time step
        radius = float(np.sqrt(np.max(np.sum((v - 0.5 * (a + b)) ** 2, axis=1)))) \
            * float(np.max(np.linalg.norm(M[:, :3, :3], axis=1)))
        p0, pm, p1 = c[0:-1:2], c[1::2], c[2::2]
        # how far the middle instant's centre is from the part's chord: the bend (twice, for margin)
        e = p1 - p0
        u = np.clip(np.einsum("ki,ki->k", pm - p0, e) / np.maximum(np.einsum("ki,ki->k", e, e), 1e-300), 0.0, 1.0)
        bend = np.linalg.norm(pm - (p0 + u[:, None] * e), axis=1)
        slack = 1e-6 * (1.0 + np.abs(c).max())
        e_all = c[-1] - c[0]
        u_all = np.clip((c - c[0]) @ e_all / max(float(e_all @ e_all), 1e-300), 0.0, 1.0)
        if np.max(np.linalg.norm(c - (c[0] + u_all[:, None] * e_all), axis=1)) <= slack:
            p0, p1, bend = c[:1], c[-1:], np.zeros(1)        # a straight path (translation): one capsule
        ca.append(p0)
        cb.append(p1)
        cr.append(radius * 1.01 + 2.0 * bend + slack)
    cat = (lambda v, w: np.concatenate(v).reshape(-1, w) if v else np.zeros((0, w)))
    lo, hi = np.array(lo).reshape(-1, 3), np.array(hi).reshape(-1, 3)
    return static, lo, hi, cat(ca, 3), cat(cb, 3), cat(cr, 1).ravel()


def static_view_rows(setup: tuple, o: np.ndarray, position: np.ndarray, instance: np.ndarray,
                     chain: np.ndarray | None = None) -> np.ndarray:
    """(m,) bool: ray segments from o (m, 3) (or (1, 3)) to their hits at ``position`` (m, 3) on
    ``instance`` (m,) (-1: a miss) that are static views -- the instance is static (``setup[0]``)
    and the segment comes near no moving instance at any instant of the shutter (it misses each
    moving instance's box, or all of its capsules: :func:`static_view_setup`), so every instant
    sees the same point along that ray.  chain (m,) bool or None: the path before the segment is
    time-independent (camera rays: None, every row); a later segment counts only where its path's
    did (docs/photon-mapping.md, "Later vertices").  ``kernels.static_views.static_segments``.
    """
    static, lo, hi, ca, cb, cr = setup
    m = instance.shape[0]
    out = np.empty(m, np.uint8)
    use_chain = chain is not None
    _SV.static_segments(kernel_array(o), kernel_array(position), kernel_array(instance, np.int32),
                        kernel_array(chain, np.uint8) if use_chain else _NO_FLAGS, use_chain,
                        kernel_array(static, np.uint8), kernel_array(lo), kernel_array(hi), kernel_array(ca),
                        kernel_array(cb), kernel_array(cr), out)
    return out.view(np.bool_)


def glossy_caustic_rows(ctx, C, crow) -> np.ndarray:
    """(m,) bool: the hits (closure rows C[crow]) whose rough lobes read the caustic map (docs/rendering.md,
    "Path partition"): with ``ctx.glossy_caustic``, a rough reflection lobe (coat, metal; no glass
    lobe, not transparent) of roughness >= ``ctx.glossy_floor``, and no coat layer sharper than that (a
    Principled Coat, ``C_CC_*``, whose lobe would read the map too)."""
    if not ctx.glossy_caustic:
        return np.zeros(crow.shape[0], bool)
    return ((C[crow, C_ROUGH_LOBE] > 0.0) & (C[crow, C_W_GLASS] <= 0.0) & (C[crow, C_PASS] <= 0.0)
            & (C[crow, C_ROUGHNESS] >= ctx.glossy_floor)
            & ((C[crow, C_CC_WEIGHT] <= 0.0) | (C[crow, C_CC_ROUGH] >= ctx.glossy_floor)))


def _glossy_caustic(ctx, sh, kc, hits, d, C, crow, t_s, stats, dst, idx_k, use_idx, beta_k, use_beta, rho,
                    has_rho, spp: int = 1, estimator: str | None = None):
    """Caustic at the covered rows sh[kc]: rho_d / pi * E_caustic (where has_rho[kc]) plus the rough
    lobes' reading of the caustic map, L_g = sum_p w_p f_c(wo, wi_p) Phi_p / measure over the same
    estimate's delta-only photons (``PhotonMaps.estimate(..., glossy=...)``), times beta.  spp > 1
    (a pixel's samples consecutive): shared between a pixel's queries on one instance as E is, where
    their view directions also agree (``photons.sharing``, ``SHARE_WO_COS``).  estimator: the maps'
    (None: the render's; 'STANDARD' at static views)."""
    rows = sh[kc]
    est = {} if estimator is None else {"estimator": estimator}
    wo = -d[rows]
    ns, ng = hits.ns[rows], hits.ng[rows]
    ng_q = ng * ctx.plane_w[hits.instance[rows]][:, None]       # the tangent slab's normal (0: none)
    n_f = np.where((np.einsum("ij,ij->i", ns, wo) < 0.0)[:, None], -ns, ns)
    gW = np.ascontiguousarray(np.concatenate([wo, ns, ng], axis=1), np.float64)
    gC = np.ascontiguousarray(C[crow[rows]], np.float64)
    E_t, E_avg = ctx.ggx
    coat_w = 0.0 if ctx.stop_coat else 1.0
    p_q = np.ascontiguousarray(hits.position[rows])
    if spp > 1 and _sharing.SHARE_RADIUS_FRACTION > 0.0 and getattr(ctx.maps, "shares_lookups", False):
        group = (idx_k[rows] if use_idx else rows) // spp * (ctx.n_instances + 1) + hits.instance[rows]

        def estimate(p, ns_q, t_q, sel, ng=None):
            # (the sharing's subset sel of the queries: their closure rows and directions go with them)
            return ctx.maps.estimate("caustic", p, ns_q, t_q, support=True,
                                     glossy=(gC[sel], gW[sel], E_t, E_avg, coat_w), ng=ng, **est)

        Ec, Lg, estimated = _sharing.shared_estimate(estimate, p_q, n_f, t_s[kc], group, wo=wo, ng=ng_q)
    else:
        Ec, Lg = ctx.maps.estimate("caustic", p_q, n_f, t_s[kc], glossy=(gC, gW, E_t, E_avg, coat_w), ng=ng_q,
                                   **est)
        estimated = kc.size
    stats.photon_lookups += kc.size
    stats.photon_estimates += estimated
    live = np.flatnonzero(has_rho[kc])
    if live.size:
        _K.photon_add(dst, rows, live, rho[kc], np.ascontiguousarray(Ec[live]), idx_k, use_idx, beta_k, use_beta,
                      ctx.clamp_indirect)
    _K.scatter_add(dst, rows, idx_k, use_idx, beta_k, use_beta, np.ascontiguousarray(Lg), ctx.clamp_indirect)


def _photon_terms(ctx, sh, hits, d, C, crow, t_s, stats: TraceStats, dsts, idx_k, use_idx, beta_k, use_beta,
                  touched, spp: int = 1, rng=None, static_sh: np.ndarray | None = None, cov_sh=None):
    """Caustic and Indirect at the hit rows sh (k,): rho_d / pi * E_kind(p, ns_f, t) added into the passes.

    cov_sh (k,) bool or None: the rows whose rough lobes read the caustic map too (:func:`glossy_caustic_rows`;
    their Caustic from :func:`_glossy_caustic`: E and the glossy radiance from one look-up, shared
    between a pixel's samples where their view directions agree).

    rho_d and the query rows from ``kernels.paths.photon_albedo`` (once for both maps), the
    irradiance estimates from the photon maps (``PhotonMaps.estimate``), ``photon_add`` into dsts.
    spp > 1 (samples of a pixel consecutive): the queries of one pixel on one instance share
    estimates (``photons.sharing``, on while ``SHARE_RADIUS_FRACTION`` > 0 and the maps support it).
    With final gathering (``ctx.final_gather`` > 0) Indirect is :func:`_final_gather`'s instead
    (rng: its random numbers).  static_sh (k,) bool or None (none): the rows that are static views
    (:func:`static_view_rows` along the whole path, ``shade_paths``); their queries read the maps
    with STANDARD, the glossy ones' too.
    """
    k = sh.size
    rho = _scratch("rho", (k, 3))
    p_q, n_q, t_q = _scratch("p_q", (k, 3)), _scratch("n_q", (k, 3)), _scratch("t_q", (k,))
    live = _scratch("live_q", (k,), np.int64)
    n_q_rows = _K.photon_albedo(sh, hits.position, hits.ns, d, C, crow, ctx.ggx[0], t_s, rho, p_q, n_q, t_q, live)
    if cov_sh is not None and cov_sh.any() and ctx.map_kinds.get("caustic", False):
        # rows whose rough lobes read the caustic map: their own look-ups (diffuse and glossy at once)
        has_rho = np.zeros(k, bool)
        has_rho[live[:n_q_rows]] = True
        kc = np.flatnonzero(cov_sh)
        if static_sh is not None and STATIC_VIEW_GLOSSY:
            # static views among them read STANDARD (the shutter's average), the others the render's estimator
            st_c = static_sh[kc]
            for sel, est in ((kc[st_c], "STANDARD"), (kc[~st_c], None)):
                if sel.size:
                    _glossy_caustic(ctx, sh, sel, hits, d, C, crow, t_s, stats, dsts["Caustic"], idx_k, use_idx,
                                    beta_k, use_beta, rho, has_rho, spp, estimator=est)
            stats.static_lookups += int(np.count_nonzero(st_c))
        else:
            _glossy_caustic(ctx, sh, kc, hits, d, C, crow, t_s, stats, dsts["Caustic"], idx_k, use_idx, beta_k,
                            use_beta, rho, has_rho, spp)
        touched.add("Caustic")
        # the other rows' caustic look-ups below (the global map's for all queried rows)
        keep_c = ~cov_sh[live[:n_q_rows]]
    else:
        keep_c = None
    if n_q_rows == 0:
        return
    # the queries' geometric normals: each look-up counts only photons in its surface's tangent slab
    # (zero on moving or deforming instances: no slab there, estimators.plane_weights)
    rows_q = sh[live[:n_q_rows]]
    ng_q = np.take(hits.ng, rows_q, axis=0) * np.take(ctx.plane_w, np.take(hits.instance, rows_q))[:, None]
    extra = {}
    if getattr(ctx.maps, "per_pixel", False):
        # maps keeping statistics per pixel (compare's SPPM baseline) are told each query's pixel
        rows = sh[live[:n_q_rows]]
        samples = idx_k[rows] if use_idx else rows
        x0, y0, tw, S, W, kept = _SCRATCH.tile
        p = samples // S if kept is None else kept[samples // S]
        extra["pixels"] = (y0 + p // tw) * W + x0 + p % tw
    # Sharing: a pixel's queries on one instance reuse a representative's estimate (photons.sharing)
    group = None
    if spp > 1 and _sharing.SHARE_RADIUS_FRACTION > 0.0 and getattr(ctx.maps, "shares_lookups", False):
        rows = sh[live[:n_q_rows]]
        group = (idx_k[rows] if use_idx else rows) // spp * (ctx.n_instances + 1) + hits.instance[rows]
    q_static = None
    if static_sh is not None:
        q_static = static_sh[live[:n_q_rows]]
        n_static = int(np.count_nonzero(q_static))
        q_static = q_static if n_static else None
    for kind, name in (("caustic", "Caustic"), ("global", "Indirect")):
        if not ctx.map_kinds.get(kind, False):
            continue
        if kind == "caustic" and keep_c is not None:
            # the caustic map at the rows not covered by _glossy_caustic
            sel = np.flatnonzero(keep_c)
            if sel.size:
                lv = np.ascontiguousarray(live[:n_q_rows][sel])
                pq, nq, tq = p_q[:n_q_rows][sel], n_q[:n_q_rows][sel], t_q[:n_q_rows][sel]
                st_sel = None if q_static is None else q_static[sel]
                E, estimated = _estimate_split(ctx, kind, pq, nq, tq, None if group is None else group[sel],
                                               extra_sel(extra, sel), st_sel, ng_q[sel])
                stats.static_lookups += 0 if st_sel is None else int(np.count_nonzero(st_sel))
                stats.photon_lookups += sel.size
                stats.photon_estimates += estimated
                _K.photon_add(dsts[name], sh, lv, rho, np.ascontiguousarray(E, np.float64), idx_k, use_idx, beta_k,
                              use_beta, ctx.clamp_indirect)
                touched.add(name)
            continue
        if kind == "global" and ctx.final_gather > 0:
            # final gathering: rays from the diffuse lobe read the precomputed irradiance where they land
            _final_gather(ctx, sh, hits, live[:n_q_rows], rho, p_q[:n_q_rows], n_q[:n_q_rows], t_q[:n_q_rows],
                          idx_k, use_idx, beta_k, use_beta, dsts[name], stats, rng)
            touched.add(name)
            continue
        E, estimated = _estimate_split(ctx, kind, p_q[:n_q_rows], n_q[:n_q_rows], t_q[:n_q_rows], group, extra,
                                       q_static, ng_q)
        stats.static_lookups += 0 if q_static is None else n_static
        E = np.ascontiguousarray(E, np.float64)
        stats.photon_lookups += n_q_rows
        stats.photon_estimates += estimated
        _K.photon_add(dsts[name], sh, live[:n_q_rows], rho, E, idx_k, use_idx, beta_k, use_beta, ctx.clamp_indirect)
        touched.add(name)


def extra_sel(extra: dict, sel: np.ndarray) -> dict:
    """The per-query keyword arguments of a look-up (``pixels``) for the queries sel."""
    return {key: val[sel] for key, val in extra.items()}


# Gather rays traced at once (a chunk of a tile's queries times final_gather_samples)
GATHER_BATCH = 1 << 17
# Light samples per cache point for its direct irradiance (_cache_direct), and the random stream
GATHER_DIRECT_SAMPLES = 4
STREAM_GATHER_DIRECT = 0x6A7


def _cache_direct(ctx, cache, seed: int) -> None:
    """Add the direct irradiance at the final-gathering cache points (``photons.gather``), once.

    Next-event estimation (:func:`_direct`, every light, shadow rays at the point's time t_i) at
    each point x_i with a white Lambertian closure (f = 1 / pi) viewed along its shading normal:
    E_direct = pi x the mean of ``GATHER_DIRECT_SAMPLES`` light samples (each light's samples
    stratified over them).  Rows in chunks of ``BATCH_SAMPLES``.
    """
    from types import SimpleNamespace
    from .scene import Material
    n, S = cache.n, GATHER_DIRECT_SAMPLES
    rng = rng_for(int(seed), STREAM_GATHER_DIRECT, 0, 0)
    # cache points are photon hits, without the triangle coordinates the shadow-terminator lift
    # needs (``_terminator``): their shadow rays start at the point itself
    ctx = _replace(ctx, term_any=False)
    C = pack_materials([Material(base_color=np.ones(3), roughness=1.0)])
    E_dir = np.zeros((n, 3))
    step = max(S, BATCH_SAMPLES // S * S)
    rows_all = np.repeat(np.arange(n), S)                 # the S samples of a point consecutive (strata)
    for a in range(0, rows_all.size, step):
        rows = rows_all[a:a + step]
        k = rows.size
        hits = SimpleNamespace(position=np.ascontiguousarray(cache.pos[rows]), ng=np.ascontiguousarray(cache.normal[rows]),
                               ns=np.ascontiguousarray(cache.shading_normal[rows]),
                               instance=np.ascontiguousarray(cache.instance[rows], np.int32))   # as Hits
        d = -hits.ns                                      # viewed along the normal: wo = ns
        dst = np.zeros((k, 4))[:, :3]                     # a strided view, as a pass's columns of V
        _direct(ctx, np.arange(k), hits, np.ascontiguousarray(d), C, np.zeros(k, np.int64),
                np.ascontiguousarray(cache.time[rows]), rng, TraceStats(), dst, _NO_IDX, False, _NO_ROWS3, False,
                strata=(k, S))
        np.add.at(E_dir, rows, dst)
    cache.add_direct(E_dir * (np.pi / S))



def _final_gather(ctx, sh, hits, live, rho, p_q, n_q, t_q, idx_k, use_idx: bool, beta_k, use_beta: bool, dst,
                  stats: TraceStats, rng) -> None:
    """Indirect by final gathering at the queried rows sh[live] (n,) of ``hits``, added into dst.

    docs/photon-mapping.md, "Final gathering": G = ``ctx.final_gather`` rays per query, cosine-
    sampled about n_q (n, 3) at the query's time t_q (n,) (``kernels.gather.gather_rays``; weight
    beta rho / G).  Each ray is followed through delta and rough lobes (``kernels.paths.specular_step``,
    at most ``ctx.max_depth`` bounces, within the glossy / transmission budgets); at every hit with a
    non-delta lobe it adds rho_d(y) / pi * E(y), E the nearest cache point's precomputed irradiance
    (``photons.gather.IrradianceCache``).  Emission, lights and the world seen by gather rays are not
    added: the light that reaches x straight from a light is next-event estimation's at x, and after
    delta / rough vertices only it is the caustic map's (L (S|G)+ D x).
    """
    cache = ctx.maps.gather_cache
    G = int(ctx.final_gather)
    if cache is None or live.size == 0:
        return
    clamp = ctx.clamp_indirect / G if ctx.clamp_indirect > 0 else 0.0     # each ray is 1 / G of the estimate
    E_tab, E_avg = ctx.ggx
    sd = ctx.shading
    step = max(1, GATHER_BATCH // G)
    for a in range(0, live.size, step):
        lv = np.ascontiguousarray(live[a:a + step])
        nq = lv.size
        rows = sh[lv]
        EPS = offset_lengths(ctx.inst_offset, hits.instance[rows], hits.position[rows])
        U = rng.random((nq * G, 2))
        m = nq * G
        o, d = np.empty((m, 3)), np.empty((m, 3))
        t, parent, w, guard = np.empty(m), np.empty(m, np.int64), np.empty((m, 3)), np.empty(m)
        m = _G.gather_rays(sh, lv, hits.position, hits.ng, rho, np.ascontiguousarray(n_q[a:a + step]),
                           np.ascontiguousarray(t_q[a:a + step]), idx_k, use_idx, beta_k, use_beta, G, U, EPS,
                           GUARD_FRACTION, o, d, t, parent, w, guard)
        o, d, t, parent, w, guard = o[:m], d[:m], t[:m], parent[:m], w[:m], guard[:m]
        counts = np.zeros((m, 2), np.int32)
        for bounce in range(ctx.max_depth):
            if m == 0:
                break
            # -- Cast the gather rays and shade their hits ------------------------------------
            gh = ctx.caster.intersect(o, d, t, None, guard=guard)
            stats.gather_rays += m
            crow = np.empty(m, np.int64)
            C = shade_rows(sd, gh.material, hit_geometry(gh, d, sd=sd, times=t) if sd.uses_programs else None,
                           int(rng.integers(1 << 62)) if sd.uses_mix else 0,
                           np.empty((m + sd.closures.shape[0], N_CLOSURE)), crow)
            if sd.transparent:
                w = pass_through(ctx.caster, sd, ctx.inst_offset, gh, d, t, C, w, rng, limit=ctx.transparent_max_bounces)
            # -- Which hits read the cache, which go on (emission and the world: not gathered) ------
            sh2, spec2, gem2 = np.empty(m, np.int64), np.empty(m, np.int64), np.empty(m, np.int64)
            _, n_sh, n_spec, _, _ = _K.classify_hits(
                gh.t, C, crow, ctx.env, _IDENTITY_POSE, d, False, _NO_IDX, False, _NO_ROWS3, False, _NO_FLAGS, _NO_U,
                False, np.zeros((m, 3)), 0, False, 0, 0, 0.0, gh.position, gh.ns, _NO_ROWS3, _NO_ROWS3,
                _NO_U, sh2, spec2, gem2, 0.0)
            # -- rho_d(y) / pi * E(y) from the nearest cache point -----------------------------
            if n_sh:
                sh2 = sh2[:n_sh]
                rho2 = np.empty((n_sh, 3))
                p2, n2, t2 = np.empty((n_sh, 3)), np.empty((n_sh, 3)), np.empty(n_sh)
                live2 = np.empty(n_sh, np.int64)
                n_live = _K.photon_albedo(sh2, gh.position, gh.ns, d, C, crow, E_tab, t[sh2], rho2, p2, n2, t2, live2)
                if n_live:
                    live2 = live2[:n_live]
                    E2 = cache.lookup(sh2, live2, gh, d, t)
                    stats.gather_lookups += n_live
                    _K.photon_add(dst, sh2, live2, rho2, E2, parent, True, w, True, clamp)
            if n_spec == 0 or bounce + 1 == ctx.max_depth:
                break
            # -- Go on through delta and rough lobes -------------------------------------------
            spec2 = spec2[:n_spec]
            u = rng.random((n_spec, 3))
            rr = bounce + 1 >= RR_START
            u_rr = rng.random(n_spec) if rr else _NO_U
            EPS2 = offset_lengths(ctx.inst_offset, gh.instance[spec2], gh.position[spec2])
            idx_n, beta_n = np.empty(n_spec, np.int64), np.empty((n_spec, 3))
            o_n, d_n, guard_n = np.empty((n_spec, 3)), np.empty((n_spec, 3)), np.empty(n_spec)
            glossy_n, world_w_n, pc_n = np.empty(n_spec, np.uint8), np.empty(n_spec), np.empty(n_spec)
            counts_n = np.empty((n_spec, 2), np.int32)
            n_go = _K.specular_step(spec2, np.arange(m), True, w, True, gh.position, gh.ng, gh.ns, d, C, crow, E_tab, E_avg,
                                    u, rr, u_rr, EPS2, GUARD_FRACTION, ctx.stop_coat, CONT_RR, ctx.env, _IDENTITY_POSE, False,
                                    np.ascontiguousarray(counts[spec2]), ctx.glossy_bounces,
                                    ctx.transmission_bounces, idx_n, beta_n, o_n, d_n, guard_n, glossy_n, world_w_n,
                                    pc_n, counts_n, False, _NO_FLAGS, _NO_ROWS3, _NO_FLAGS, _NO_ROWS3)
            # (idx = the rows themselves: idx_n is each continuing ray's row, whose sample and time it keeps)
            m = n_go
            go = idx_n[:m]
            parent, t = parent[go], t[go]
            w, o, d, guard, counts = beta_n[:m], o_n[:m], d_n[:m], guard_n[:m], counts_n[:m]


def shade_paths(ctx, o, d, times, tmax0, rng, stats: TraceStats, cam_pos, cam_axis,
                V: np.ndarray | None = None, layout: dict | None = None,
                touched: set | None = None, cam_R: np.ndarray | None = None, spp: int = 1) -> np.ndarray:
    """Radiance of the camera rays o, d (n, 3) at times (n,) split into passes -> V (n, K).

    tmax0 (n,) clips the camera rays; cam_pos, cam_axis (k, 3) (k = 1 or n) are
    the camera position and unit view axis at each sample's time (for Depth).

    Per bounce: cast, ``kernels.svm.shade_rows`` (the hits' closures), ``classify_hits``
    (misses see the world, emission, the first hit's Depth / Normal / coverage, the
    rows to shade and to continue), light shapes seen along the rays, next-event
    estimation (:func:`_direct`) and photon look-ups (:func:`_photon_terms`) at the
    rows with a non-delta lobe, then ``specular_step`` through delta lobes.

    Bookkeeping: ``idx`` maps live rows to samples (absent: every sample, in
    order: the first bounce and later ones while no path has ended), ``beta``
    their throughput (absent: 1), so the common case pays for no gathers.

    layout: pass name -> (first, end) column of V; None: every pass in PASSES
    order (Combined included, alpha = 1 or the coverage with a transparent film).
    Other layouts come from :func:`_compact_layout` (no Combined:
    ``Film.tile_sums_matrix`` derives it).  V: an (n, width) float64 buffer to
    fill, any content (None: a new one).  touched: a set that receives the
    names of the passes among Emit, Direct, Indirect and Caustic that got any
    value (the others are 0 everywhere).

    Denoising features (``ctx.features``): ``kernels.paths.denoising_rows`` after ``classify_hits``
    (and ``denoising_seen_add`` for light shapes), carried through ``specular_step``; cam_R (k, 3, 3)
    the camera's rotation at each sample's time for Cycles' camera-space normal (None: world space).

    spp: the samples of each pixel, consecutive in o (the tile's layout): next-event estimation
    stratifies each light's samples over them (``kernels.paths.light_strata``; 1: none).

    Random numbers per bounce: with node programs that choose a closure per hit (Mix / Add
    Shader, Alpha), keys (n / spp, spp) and (m, 2) jitters for those choices (each pixel's
    stratified, ``svm.shade_rows``' U), then the node programs' seed; per light with power
    (n / spp, spp) permutation keys and (k, 2)
    jitters at the shaded rows (skipped for delta lights), then two such blocks (keys, then (k', 2)
    jitters) for the lobes of the k' continuing rows, the directions' (u1, u2) and the pick's (u0,
    its first column), and, from ``RR_START`` on, (k',) for Russian roulette.
    """
    n = o.shape[0]
    full = layout is None
    cols = _COL if full else layout
    if V is None:
        V = np.empty((n, max(b for _, b in cols.values())))   # classify_hits starts every row (first bounce)
    L_emit, L_direct = V[:, slice(*cols["Emit"])], V[:, slice(*cols["Direct"])]
    dsts = {name: V[:, slice(*cols[name])] for name in ("Indirect", "Caustic") if name in cols}
    covered = np.empty(n) if full else _scratch("covered", (n,))
    cam_pos, cam_axis = _first_pose(cam_pos), _first_pose(cam_axis)
    world_on = bool(np.any(np.asarray(ctx.world_radiance) > 0))
    E, E_avg = ctx.ggx
    touched = set() if touched is None else touched
    idx = None                               # live row -> sample (None: every sample, in order)
    beta = None                              # path throughput (None: 1)
    glossy = None                            # 1 where the ray left a rough lobe (None: none did)
    counts = None                            # (live rows, 2) int32 reflections, transmissions so far (None: 0)
    world_w = None                           # the world's weight where the ray escapes (with glossy)
    p_c = None                               # the density the rough lobe drew the ray with (with glossy)
    feat = _NO_FLAGS                         # 1 where a path still looks for its denoising features (bounce 0: all)
    dft = _NO_ROWS3                          # their throughput: the specular-like albedos met (bounce 0: 1)
    if ctx.features:
        ca, cn = cols["Denoising Albedo"][0], cols["Denoising Normal"][0]
        cam_R = _IDENTITY_POSE[:, :3, :3].copy() if cam_R is None else np.ascontiguousarray(cam_R, np.float64)
    tmax = tmax0                             # camera clipping for the first segment
    guard = None                             # camera rays: the caster's own guard
    sid = None                               # each live row's stratum, split paths (None: its sample)
    done = None                              # (live rows,) uint8: 1 where the path has split (with sid)
    split = 1                                # strata per sample (ctx.rough_splits once paths split)
    cov = None                               # (live rows,) uint8: 1 where the path left a vertex whose rough
                                             # lobes read the caustic map and met delta vertices only since
                                             # (None: none did; glossy_caustic_rows)
    chain = None                             # (live rows,) bool: camera -> ... -> the ray's origin is a static
                                             # view (static_view_rows; None: bounce 0 all, later none)
    for bounce in range(ctx.max_depth + 1):
        m = n if idx is None else idx.size
        if m == 0:
            break
        # -- Cast the bounce's rays at their samples' times --------------------------------------
        t = times if idx is None else times[idx]
        hits = ctx.caster.intersect(o, d, t, tmax, guard=guard)
        if bounce == 0:
            stats.camera_rays += m
        else:
            stats.bounce_rays += m
        # -- Closures of the hits: the material table's rows, or the node programs' per hit ---------
        crow = _scratch("crow", (m,), np.int64)            # hit r's closure is row crow[r] of C
        sd = ctx.shading
        # room for a row per hit and the material table after them (shade_rows: hits without a
        # program of their own, misses among them, point into the table)
        # Mix Shader / Alpha choices: each pixel's samples stratified (as the lobe picks), one
        # block per bounce, its first column
        u_mix = None
        if sd.uses_mix and sd.uses_programs:
            rows = np.arange(m) if idx is None else (idx if sid is None else sid)
            u_mix = np.ascontiguousarray(strata_uniforms(rows, (n * split, int(spp) * split), rng,
                                                         _scratch("mix_strata", (m, 2)))[:, 0])
        C = shade_rows(sd, hits.material, hit_geometry(hits, d, sd=sd, times=t) if sd.uses_programs else None,
                       int(rng.integers(1 << 62)) if sd.uses_mix else 0,
                       _scratch("closure", (m + sd.closures.shape[0], N_CLOSURE)), crow, u_mix)
        if sd.transparent:
            # transparent hits (cut-outs, Transparent BSDF): the rays go on to what lies behind
            beta = pass_through(ctx.caster, sd, ctx.inst_offset, hits, d, t, C, beta, rng, tmax=tmax,
                                limit=ctx.transparent_max_bounces)
        use_idx, use_beta, use_glossy = idx is not None, beta is not None, glossy is not None
        idx_k = idx if use_idx else _NO_IDX
        beta_k = beta if use_beta else _NO_ROWS3
        glossy_k = glossy if use_glossy else _NO_FLAGS
        world_w_k = world_w if use_glossy else _NO_U
        # -- Misses, emission, first-hit passes; rows to shade and to continue ---------------------
        sh, spec = _scratch("sh", (m,), np.int64), _scratch("spec", (m,), np.int64)
        gem = _scratch("gem", (m,), np.int64)
        clamp = ctx.clamp_direct if bounce == 0 else ctx.clamp_indirect      # Cycles' Clamp Direct / Indirect
        env_b, wposes_b = ctx.env_camera if bounce == 0 else ctx.env, _world_poses(ctx, t)
        add_world = world_on and not (bounce == 0 and ctx.film_transparent)
        n_hit, n_sh, n_spec, n_emit, n_gem = _K.classify_hits(
            hits.t, C, crow, env_b, wposes_b, d, add_world,
            idx_k, use_idx, beta_k, use_beta, glossy_k, world_w_k, use_glossy, V, cols["Emit"][0], bounce == 0, cols["Depth"][0], cols["Normal"][0], DEPTH_BACKGROUND,
            hits.position, hits.ns, cam_pos, cam_axis, covered, sh, spec, gem, clamp)
        if n_gem:
            # emitters hit through a rough lobe: weighed against next-event estimation there
            _glossy_emission(ctx, gem[:n_gem], hits, o, t, C, crow, p_c, L_emit, idx_k, use_idx, beta_k, use_beta,
                             clamp)
            touched.add("Emit")
        # -- Denoising features: albedo and normal at the first diffuse-like vertex ---------------
        feat_b, dft_b = _NO_FLAGS, _NO_ROWS3         # after this bounce's vertices (specular_step carries them)
        if ctx.features:
            feat_b, dft_b = _scratch("feat_b", (m,), np.uint8), _scratch("dft_b", (m, 3))
            _K.denoising_rows(hits.t, C, crow, env_b, wposes_b, d, add_world, idx_k, use_idx, beta_k, use_beta, glossy_k,
                              world_w_k, use_glossy, hits.ns, hits.ng, E, E_avg, cam_R, bounce == 0, feat, dft,
                              feat_b, dft_b, V, ca, cn, clamp)
        # -- Lights seen along the rays (before the next surface) -----------------------------------
        if ctx.shaped_lights:
            val, val_w = _seen_lights(ctx, o, d, t, hits.t, bounce == 0, glossy, p_c)
            if val is not None and ctx.features:
                # Cycles' Denoising Albedo sees them through specular-like rough lobes too
                _K.denoising_seen_add(V, ca, np.arange(m), idx_k, use_idx, beta_k, use_beta, bounce == 0, feat,
                                      dft, val, clamp)
            if val is not None:
                # after a rough lobe, weighed against next-event estimation at its vertex
                _K.scatter_add(L_emit, np.arange(m), idx_k, use_idx, beta_k, use_beta, val_w, clamp)
                touched.add("Emit")
        if n_emit:
            touched.add("Emit")
        if n_hit == 0:
            break
        sh, spec = sh[:n_sh], spec[:n_spec]
        # the hits whose rough lobes read the caustic map (their paths then drop the light they reach
        # through delta vertices alone)
        cov_hit = glossy_caustic_rows(ctx, C, crow) if ctx.glossy_caustic else None
        # the hits that are static views: the whole path to them the same at every instant (their
        # photon queries read the shutter's average with STANDARD; docs/photon-mapping.md)
        sv = None
        if ctx.static_view is not None and (bounce == 0 or chain is not None):
            sv = static_view_rows(ctx.static_view, o, hits.position, hits.instance, chain)
            sv = sv if sv.any() else None
        # -- Shade non-delta vertices: Direct, Caustic, Indirect -------------------------------------
        if n_sh:
            t_s = np.take(t, sh, out=_scratch("t_s", (n_sh,)))
            if len(ctx.lights) and _direct(ctx, sh, hits, d, C, crow, t_s, rng, stats, L_direct, idx_k, use_idx,
                                           beta_k, use_beta, mis=mis_rows(ctx, bounce, counts, sh), clamp=clamp,
                                           strata=(n * split, int(spp) * split), sid=sid):
                touched.add("Direct")
            if ctx.maps is not None:
                _photon_terms(ctx, sh, hits, d, C, crow, t_s, stats, dsts, idx_k, use_idx, beta_k, use_beta, touched,
                              int(spp), rng=rng, static_sh=None if sv is None else sv[sh],
                              cov_sh=None if cov_hit is None else cov_hit[sh])
        if bounce == ctx.max_depth or n_spec == 0:
            break
        # -- Continue through delta lobes, or with the rough non-diffuse lobes' part of f ------------
        # the lobes' uniforms, each pixel's samples stratified against the film as the lights'
        # (Cycles' Sobol dimensions): the directions (u1, u2) one block, then the pick u0 (which
        # lobe, a smooth dielectric's reflect or refract, and the roulette of its remainder) the
        # first column of another
        # Path splitting: a path's first vertex with a rough lobe goes on with ctx.rough_splits rays,
        # each carrying 1 / rough_splits; the copies become rows of their own (hit arrays gathered),
        # each its own stratum for the lobes' and later lights' uniforms: sample x rough_splits +
        # copy (paths that have not split keep sample x rough_splits)
        Pc, NGc, NSc, Dc, crow_c = hits.position, hits.ng, hits.ns, d, crow
        feat_c, dft_c = feat_b, dft_b
        rows_c = spec                            # the hit row of each continuation
        beta_c, use_beta_c, idx_c, use_idx_c = beta_k, use_beta, idx_k, use_idx
        sid_c = None if sid is None else sid[spec]
        sid_rows = samp_rows = done_rows = None  # with strata of their own: per row of idx_n, its stratum / sample
        if sid is not None:
            # paths split earlier keep their strata: idx_n gets each continuation's hit row
            idx_c, use_idx_c, sid_rows, samp_rows, done_rows = _NO_IDX, False, sid, idx, done
        elif cov_hit is not None or sv is not None:
            # (the caustic-map rule and static views need each continuation's hit row: idx_n gets it,
            # mapped below)
            idx_c, use_idx_c = _NO_IDX, False
        if ctx.rough_splits > 1:
            Ns = int(ctx.rough_splits)
            rough = C[crow[spec], C_ROUGH_LOBE] > 0.0
            if done is not None:
                rough &= done[spec] == 0
            if rough.any():
                reps = np.where(rough, Ns, 1)
                rows_c = np.repeat(spec, reps)
                copy = np.arange(rows_c.size) - np.repeat(np.cumsum(reps) - reps, reps)
                samples_c = rows_c if idx is None else idx[rows_c]
                sid_c = (samples_c * Ns if sid is None else sid[rows_c]) + copy
                split_c = np.repeat(rough, reps)
                done_c = split_c.astype(np.uint8) if done is None else done[rows_c] | split_c
                split = Ns
                Pc, NGc, NSc, Dc = hits.position[rows_c], hits.ng[rows_c], hits.ns[rows_c], d[rows_c]
                crow_c = np.ascontiguousarray(crow[rows_c])
                beta_c = np.ones((rows_c.size, 3)) if beta is None else beta[rows_c]
                beta_c[split_c] *= 1.0 / Ns
                use_beta_c = True
                idx_c, use_idx_c = _NO_IDX, False   # idx_n: the continuation's copy
                sid_rows, samp_rows, done_rows = sid_c, samples_c, done_c
                if ctx.features:
                    feat_c, dft_c = feat_b[rows_c], dft_b[rows_c]
                n_spec = rows_c.size
        spec_k = rows_c if rows_c is spec else np.arange(n_spec)
        u = _scratch("u_cont", (n_spec, 3))
        if sid_c is not None:
            samples = sid_c
        else:
            samples = spec if idx is None else np.take(idx, spec)
        u[:, 1:3] = strata_uniforms(samples, (n * split, int(spp) * split), rng, _scratch("dir_strata", (n_spec, 2)))
        u[:, 0] = strata_uniforms(samples, (n * split, int(spp) * split), rng, _scratch("pick_strata", (n_spec, 2)))[:, 0]
        rr = bounce + 1 >= RR_START
        u_rr = rng.random(n_spec) if rr else _NO_U
        EPS = offset_lengths(ctx.inst_offset, hits.instance[rows_c], hits.position[rows_c])
        idx_n = np.empty(n_spec, np.int64)
        beta_n, o_n, d_n, guard_n = np.empty((n_spec, 3)), np.empty((n_spec, 3)), np.empty((n_spec, 3)), np.empty(n_spec)
        glossy_n, world_w_n, pc_n = np.empty(n_spec, np.uint8), np.empty(n_spec), np.empty(n_spec)
        counts_n = np.empty((n_spec, 2), np.int32)
        counts_s = np.zeros((n_spec, 2), np.int32) if counts is None else np.ascontiguousarray(counts[rows_c])
        feat_n, dft_n = (np.empty(n_spec, np.uint8), np.empty((n_spec, 3))) if ctx.features else (_NO_FLAGS, _NO_ROWS3)
        t_spec = t[rows_c] if ctx.world_li >= 0 and not ctx.lights.lights[ctx.world_li].transform.is_static else t[:1]
        n_go = _K.specular_step(spec_k, idx_c, use_idx_c, beta_c, use_beta_c, Pc, NGc, NSc, Dc, C, crow_c,
                                E, E_avg, u, rr, u_rr, EPS, GUARD_FRACTION, ctx.stop_coat, CONT_RR, ctx.env,
                                _world_poses(ctx, t_spec), ctx.world_li >= 0, counts_s, ctx.glossy_bounces,
                                ctx.transmission_bounces, idx_n, beta_n, o_n, d_n, guard_n, glossy_n, world_w_n,
                                pc_n, counts_n, ctx.features, feat_c, dft_c, feat_n, dft_n)
        src = None                               # each continuation's hit row (with cov_hit or sv)
        if sid_rows is not None:
            # idx_n holds each continuation's row (copy); back to its sample, and its stratum
            j = idx_n[:n_go]
            if cov_hit is not None or sv is not None:
                src = j.copy() if rows_c is spec else rows_c[j]
            sid, done = sid_rows[j], done_rows[j]
            idx_n[:n_go] = samp_rows[j]
        elif cov_hit is not None or sv is not None:
            src = idx_n[:n_go].copy()
            if idx is not None:
                idx_n[:n_go] = idx[src]
        if cov_hit is not None:
            # Path partition (docs/rendering.md): a path that left a covered vertex through its rough
            # lobes and met only delta vertices since reaches lights whose light the caustic map
            # carries: its emission, world and light shapes count 0 (weight 0 against the map's 1:
            # marked as leaving a rough lobe with density 0); a rough continuation starts afresh
            g_n = glossy_n[:n_go]
            cov_n = np.where(g_n != 0, cov_hit[src], 0 if cov is None else cov[src]).astype(np.uint8)
            drop = (g_n == 0) & (cov_n != 0)
            if drop.any():
                g_n[drop] = 1
                pc_n[:n_go][drop] = 0.0
                world_w_n[:n_go][drop] = 0.0
            cov = cov_n if cov_n.any() else None
        # a continuation from a static view goes on testing its segments (Later vertices)
        chain = None
        if sv is not None:
            chain = sv[src]
            chain = chain if chain.any() else None
        idx, beta, o, d, guard = idx_n[:n_go], beta_n[:n_go], o_n[:n_go], d_n[:n_go], guard_n[:n_go]
        glossy = glossy_n[:n_go] if glossy_n[:n_go].any() else None
        world_w = world_w_n[:n_go] if glossy is not None else None
        p_c = pc_n[:n_go] if glossy is not None else None
        counts = counts_n[:n_go]
        if ctx.features:
            feat, dft = feat_n[:n_go], dft_n[:n_go]
        tmax = None

    if full:
        a, b = _COL["Combined"]
        V[:, a:a + 3] = L_emit + L_direct + dsts.get("Indirect", 0.0) + dsts.get("Caustic", 0.0)
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
    maps: object
    map_kinds: dict
    max_depth: int
    inst_offset: np.ndarray                  # (n_instances,) object part of the ray offsets (offset_lengths)
    world_radiance: np.ndarray               # (3,) constant, or an image world's mean radiance
    film_transparent: bool
    env: tuple = None                        # the world's environment arrays (kernels.environment)
    env_camera: tuple = None                 # what camera rays see of it (World.camera_image, else env)
    world_li: int = -1                       # the world's light index, -1 when it does not shine
    stop_coat: bool = False                  # camera paths carry no rough coat on (kernels.bsdf.bsdf_sample_cont)
    glossy_bounces: int = 4                  # RenderSettings.glossy_bounces / transmission_bounces
    rough_splits: int = 1                    # RenderSettings.rough_splits: continuations of a first rough vertex
    glossy_caustic: bool = False             # rough lobes read the caustic map (glossy_caustic_rows, trace_image)
    glossy_floor: float = np.inf             # ... from this roughness (GLOSSY_CAUSTIC_MIN_ROUGHNESS)
    transmission_bounces: int = 12
    transparent_max_bounces: int = 8         # RenderSettings.transparent_max_bounces: passes in a row (transparency)
    clamp_direct: float = 0.0                # RenderSettings.clamp_direct / clamp_indirect (0: off)
    clamp_indirect: float = 0.0
    closures: np.ndarray = None              # (M + 1, N_CLOSURE) material closure rows (kernels.closure)
    shading: object = None                   # shading.ShadingData: node programs, textures, mesh attributes
    ggx: tuple = None                        # (E (32, 32), E_avg (32,)) GGX albedo tables (kernels.bsdf)
    light_data: list = None                  # per light: (parameter row, mesh arrays) (kernels.light_params)
    shaped_lights: tuple = ()                # lights a ray can hit (AREA, POINT / SPOT of radius > 0, SUN of angle > 0) with power
    mesh_emitters: dict = None               # MESH light index -> (instance, (F,) int64 prim -> its triangle j or -1)
    light_visible_camera: list = None        # per light: seen by camera rays (Blender's visible_camera)
    light_vis: np.ndarray = None             # (L,) uint8 per exported light: 1 diffuse | 2 glossy | 4 transmission (_light_vis)
    zero_passes: tuple = ()                  # passes that stay 0 for every sample
    layout: dict = None                      # columns of a tile's per-sample matrix (_compact_layout)
    features: bool = False                   # RenderSettings.denoise: Denoising Albedo / Normal (kernels.paths.denoising_rows)
    n_instances: int = 0                     # the scene's instances (a photon query's group is pixel x instance)
    plane_w: np.ndarray = None               # (n_instances,) 1: static, look-ups keep to the tangent slab; 0: moving
    final_gather: int = 0                    # RenderSettings.final_gather_samples (0: the global map read directly)
    term_cut: np.ndarray = None              # (n_instances,) shadow-terminator cutoff, 0: off (terminator_settings)
    term_freq: np.ndarray = None             # (n_instances,) shading offset's frequency multiplier, 1: off
    term_any: bool = False                   # some instance has either (next-event estimation reads TERM)
    term_meshes: dict = field(default_factory=dict)   # mesh -> its arrays for terminator_rows (_term_mesh)
    static_view: tuple = None                # static_view_setup: camera rays that may read STANDARD (None: none)


def _mesh_emitters(scene, lights) -> dict:
    """MESH lights with power: light index -> (instance, J), J (F,) int64 over the instance mesh's
    triangles: the light's triangle index j of each emitting triangle, -1 for the others (what
    ``kernels.paths.mesh_emission_mis`` needs to find next-event estimation's density of a hit)."""
    out = {}
    for li, l in enumerate(lights.lights):
        if l.type != "MESH" or not l.power > 0:
            continue
        F = len(scene.meshes[scene.instances[l.instance].mesh].triangles)
        J = np.full(F, -1, np.int64)
        J[np.asarray(l.prims, np.int64)] = np.arange(len(l.prims))
        out[li] = (int(l.instance), J)
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
    size = int(math.prod(shape))           # (np.prod, a ufunc reduction: 10 us a call at load 9, math.prod 0.3)
    buf = _SCRATCH.bufs.get(name)
    if buf is None or buf.size < size or buf.dtype != np.dtype(dtype):
        buf = np.empty(size, dtype)
        _SCRATCH.bufs[name] = buf
    return buf[:size].reshape(shape)


def _trace_tile(ctx, film, cam, resolution, x0, y0, tw, th, spp, shutter, rng, time_override, tstats,
                inside=None):
    """One tile: (film window, TraceStats).

    Draws the camera uniforms (positions (P, S, 2), then the time permutation
    keys and jitters (P, S) each, or skips them for one instant), places them
    with ``camera_tile`` (stratified positions through the pixel filter's
    inverse CDF, time strata permuted per pixel), makes rays with
    ``camera_rays``, shades with :func:`shade_paths` and sums per pixel with
    ``Film.tile_sums_matrix``.

    inside : (th, tw) bool or None: the tile's pixels to trace (a Render Region's edge tile); the
    camera uniforms (and a thin lens's) are drawn for the whole tile, so a pixel's camera rays are a
    whole frame's; the samples of the other pixels are dropped before any ray is cast, and they stay
    empty in the window.  The shading's random numbers then follow from the pixels kept: the
    pixels equal a whole frame's in distribution, not bit for bit.
    """
    P, S = tw * th, int(spp)
    n = P * S
    # The camera uniforms: positions (P, S, 2), then time keys and jitters (P, S) (drawn into reused buffers)
    jit = rng.random(out=_scratch("jit", (P, S, 2)))
    px, py, xi = _scratch("px", (n,)), _scratch("py", (n,)), _scratch("xi", (n,))
    stratum = isinstance(time_override, tuple)          # (lo, hi) of the shutter's mass: a progressive pass
    with_time = (time_override is None or stratum) and not shutter.is_instant
    if with_time:
        perm_u = rng.random(out=_scratch("perm_u", (P, S)))
        time_u = rng.random(out=_scratch("time_u", (P, S)))
    else:
        skip_uniforms(rng, 2 * P * S)
        perm_u = time_u = np.zeros((P, 0))
    _K.camera_tile(x0, y0, tw, th, S, jit, perm_u, time_u, with_time, film.radius, BH_INVERSE_CDF, px, py, xi)
    if stratum and with_time:
        lo, hi = time_override
        times = shutter.sample(lo + (hi - lo) * xi)
    elif time_override is not None and not stratum:
        times = np.full(n, float(time_override))
    else:
        times = shutter.sample(xi if with_time else np.zeros(n))
    kept = None
    if inside is not None:
        # -- A Render Region's edge tile: the samples of its pixels alone ------------------------------
        kept = np.flatnonzero(inside.ravel())
        rows = (kept[:, None] * S + np.arange(S)).ravel()
        px, py, xi, times = px[rows], py[rows], xi[rows], np.asarray(times)[rows]
    _SCRATCH.tile = (x0, y0, tw, S, int(resolution[0]), kept)     # a sample's pixel, for per-pixel maps
    V, chan, keep = _shade_samples(ctx, cam, resolution, px, py, times, S, rng, tstats,
                                   lens_rows=None if kept is None else (n, rows))
    if kept is None:
        return film.tile_sums_matrix(x0, y0, tw, th, V, combined_is_sum=True,
                                      alpha_one=not ctx.film_transparent, channels=np.asarray(chan),
                                      columns=np.flatnonzero(keep)), tstats
    w_kept = film.pixel_sums_matrix(S, V, np.asarray(chan), np.flatnonzero(keep), alpha_one=not ctx.film_transparent)
    w = np.zeros((th, tw, w_kept.shape[1]), np.float32)
    w.reshape(th * tw, -1)[kept] = w_kept
    return ((y0, y0 + th, x0, x0 + tw), [(0, film.n_channels)], w), tstats


_NO_LENS = np.zeros((0, 2))            # camera_rays' lens uniforms for a pinhole


def _shade_samples(ctx, cam, resolution, px, py, times, S, rng, tstats, lens_rows=None):
    """Camera rays through film positions px, py (n,) at times (n,), shaded: (V, chan, keep).

    The samples are laid out as pixels of S consecutive samples.  A camera with a thin lens
    (``aperture_radius > 0``) first draws its lens uniforms from rng, keys (n / S, S) then jitters
    (n / S, S, 2), placed per pixel by ``kernels.paths.lens_tile``; with ``lens_rows`` = (m, rows)
    (a Render Region's edge tile: the samples are rows of a tile of m) they are drawn for all m
    and the rows kept, so every sample's camera ray is the whole tile's.  V (n, m) float64 (a reused
    buffer: valid until this thread's next call) holds the layout's columns (``ctx.layout``),
    chan (m,) each column's image channel, keep (m,) bool the columns some sample reached.
    """
    n = px.shape[0]
    R, pos = camera_to_world(cam, times[:1] if cam.transform.is_static else times)
    R = kernel_array(R[:1] if cam.transform.is_static else R)
    pos = kernel_array(pos[:1] if cam.transform.is_static else pos)
    half_w, half_h, cx, cy = image_plane(cam, resolution)
    # The thin lens: per-pixel stratified lens uniforms, drawn only for a camera with an aperture
    aperture, focus, blades, rotation, ratio = lens_args(cam)
    if aperture > 0.0:
        m = n if lens_rows is None else int(lens_rows[0])
        keys = rng.random(out=_scratch("lens_keys", (m // S, S)))
        jit = rng.random(out=_scratch("lens_jit", (m // S, S, 2)))
        lens_uv = _scratch("lens_uv", (m, 2))
        _K.lens_tile(S, keys, jit, lens_uv)
        if lens_rows is not None:
            lens_uv = np.ascontiguousarray(lens_uv[lens_rows[1]])
    else:
        lens_uv = _NO_LENS
    o, d, tmax0 = _scratch("o", (n, 3)), _scratch("d", (n, 3)), _scratch("tmax0", (n,))
    _K.camera_rays(px, py, int(resolution[0]), int(resolution[1]), float(half_w), float(half_h), float(cx),
                   float(cy), R, pos, cam.type == "ORTHO", float(cam.clip_start), float(cam.clip_end),
                   lens_uv, aperture, focus, blades, rotation, ratio, o, d, tmax0)
    axis = np.ascontiguousarray(-R[:, :, 2])
    touched: set = set()
    layout = ctx.layout
    V = shade_paths(ctx, o, d, times, tmax0, rng, tstats, pos, axis,
                    V=_scratch("V", (n, max(b for _, b in layout.values()))), layout=layout, touched=touched,
                    cam_R=R if ctx.features else None, spp=S)
    # Image channel of every column of V; columns of passes nothing reached are left out
    chan, keep = [], []
    for name, (a, b) in layout.items():
        c0 = _COL["Combined"][0] + 3 if name == "Alpha" else _COL[name][0]
        chan.extend(range(c0, c0 + b - a))
        keep.extend([name not in ("Emit", "Direct", "Indirect", "Caustic") or name in touched] * (b - a))
    return V, chan, np.asarray(keep, bool)


def adaptive_on(settings, time_override=None, maps=None) -> bool:
    """Does trace_image sample adaptively?  With ``use_adaptive_sampling``, a threshold > 0 and more
    samples than the minimum (else there is one round: the fixed render, bit for bit), for the
    whole shutter (not an accumulation still or a progressive pass: ``time_override``), unless the
    maps keep per-pixel statistics (compare's SPPM baseline)."""
    from .adaptive import min_samples
    thr = float(getattr(settings, "adaptive_threshold", 0.0))
    return (bool(getattr(settings, "use_adaptive_sampling", False)) and thr > 0.0
            and int(settings.samples) > min_samples(thr, int(getattr(settings, "adaptive_min_samples", 0)))
            and time_override is None and not getattr(maps, "per_pixel", False))


def _round_pattern(settings, scene, film, stream, tile, r, B, active):
    """The camera samples of round r in one tile (x0, y0, tw, th): film positions px, py and shutter
    numbers xi (k B,) of the tile's pixels with active (th, tw) True, B per pixel, and their row-major
    image indices (k,).

    The uniforms are drawn for every pixel of the tile from the stream (seed, STREAM_PATTERN,
    stream, tile index, r) and placed by ``camera_tile`` (B-sample strata), then the active pixels'
    rows are kept: a pixel's samples in a round do not depend on which other pixels take part."""
    ti, (x0, y0, tw, th) = tile
    P = tw * th
    W = int(scene.resolution[0])
    rng = rng_for(settings.seed, STREAM_PATTERN, stream, ti, r)
    jit = rng.random((P, B, 2))
    with_time = not scene.shutter.is_instant
    if with_time:
        perm_u, time_u = rng.random((P, B)), rng.random((P, B))
    else:
        perm_u = time_u = np.zeros((P, 0))
    n = P * B
    px, py, xi = np.empty(n), np.empty(n), np.zeros(n)
    _K.camera_tile(x0, y0, tw, th, B, jit, perm_u, time_u, with_time, film.radius, BH_INVERSE_CDF, px, py, xi)
    p = np.flatnonzero(active.ravel())
    rows = (p[:, None] * B + np.arange(B)).ravel()
    pix = (y0 + p // tw) * W + x0 + p % tw
    return px[rows], py[rows], xi[rows], pix


def _trace_adaptive(ctx, film, scene, settings, stream, stats, progress, cancel, progress_span,
                    mask=None) -> np.ndarray:
    """Adaptive sampling into film (docs/rendering.md, "Adaptive sampling"; :mod:`stpm_core.adaptive`):
    returns each pixel's sample count (H * W,) float64.

    Rounds (``adaptive.schedule``): round r gives sample indices first .. first + B - 1 to every pixel
    that needs samples (all in round 0), its camera samples from :func:`_round_pattern`; the round's
    pixels are traced in batches of about BATCH_SAMPLES samples (whole pixels, tile by tile), each on
    the random stream (seed, STREAM_CAMERA, stream, ADAPTIVE_STREAM, r, batch), in batch order
    into the film.  Each batch also sums twice its samples of odd index (the half buffer A); after the
    round ``adaptive.pixel_error`` and ``adaptive.need_samples`` choose the next round's pixels.
    """
    from . import adaptive as _A

    W, H = (int(scene.resolution[0]), int(scene.resolution[1]))
    spp = int(settings.samples)
    thr = float(settings.adaptive_threshold)
    n_min = _A.min_samples(thr, int(settings.adaptive_min_samples))
    rounds = _A.schedule(spp, n_min)
    side = int(np.clip(np.sqrt(BATCH_SAMPLES / rounds[0][1]), 1, 64))
    tiles = [(x0, y0, min(side, W - x0), min(side, H - y0)) for y0 in range(0, H, side) for x0 in range(0, W, side)]
    half = np.zeros((H * W, 3))               # A: twice the Combined RGB sums of the samples of odd index
    need = np.ones((H, W), bool) if mask is None else mask.copy()    # the pixels that take the next round
    f0, f1 = progress_span
    traced = 0
    for r, (first, B) in enumerate(rounds):
        # -- The round's camera samples, tile by tile --------------------------------------------
        parts = [_round_pattern(settings, scene, film, stream, (ti, t), r, B, need[t[1]:t[1] + t[3], t[0]:t[0] + t[2]])
                 for ti, t in enumerate(tiles) if need[t[1]:t[1] + t[3], t[0]:t[0] + t[2]].any()]
        if not parts:
            break
        PX, PY, XI, PIX = (np.concatenate([q[i] for q in parts]) for i in range(4))
        per = max(1, BATCH_SAMPLES // B)       # pixels per batch
        n_batch = (PIX.size + per - 1) // per
        odd = ((first + np.arange(B)) % 2 == 1)

        def trace_batch(bi: int, r=r, B=B, PX=PX, PY=PY, XI=XI, PIX=PIX, per=per, odd=odd):
            """Batch bi of the round: (its pixels, their sums (k, C + 1), their A (k, 3), TraceStats)."""
            a, b = bi * per, min((bi + 1) * per, PIX.size)
            rows = slice(a * B, b * B)
            rng = rng_for(settings.seed, STREAM_CAMERA, stream, ADAPTIVE_STREAM, r, bi)
            times = scene.shutter.sample(XI[rows])
            ts = TraceStats()
            V, chan, keep = _shade_samples(ctx, scene.camera, (W, H), np.ascontiguousarray(PX[rows]),
                                           np.ascontiguousarray(PY[rows]), times, B, rng, ts)
            w = film.pixel_sums_matrix(B, V, np.asarray(chan), np.flatnonzero(keep),
                                       alpha_one=not ctx.film_transparent)
            # Combined RGB of each sample (its parts' sum, as the film's), twice summed over odd indices
            comb = np.zeros((V.shape[0], 3))
            for name in ("Emit", "Direct", "Indirect", "Caustic"):
                if name in ctx.layout and keep[ctx.layout[name][0]]:
                    c0 = ctx.layout[name][0]
                    comb += V[:, c0:c0 + 3]
            A = 2.0 * comb.reshape(b - a, B, 3)[:, odd].sum(axis=1)
            return PIX[a:b], w, A, ts

        for bi, (pix, w, A, ts) in enumerate(ordered_map(trace_batch, n_batch, worker_count(settings), cancel)):
            film.add_pixels(pix, w)
            half[pix] += A
            stats.merge(ts)
            if progress is not None:
                progress(f0 + (f1 - f0) * (r + (bi + 1) / n_batch) / len(rounds),
                         f"adaptive round {r + 1}/{len(rounds)}: {PIX.size} pixels, batch {bi + 1}/{n_batch}")
        traced += PIX.size * B
        # -- Which pixels go on: the error of each, the unconverged set dilated by one pixel ---------
        I, N = film.combined_sums()
        need = _A.need_samples(_A.pixel_error(I, half, N).reshape(H, W), thr)
        if mask is not None:                  # a Render Region: its pixels only
            need &= mask
    counts = film.combined_sums()[1].astype(np.float64)
    inside = counts if mask is None or not mask.any() else counts[mask.ravel()]
    stats.extra["adaptive"] = {
        "threshold": thr, "min_samples": int(n_min), "max_samples": spp, "rounds": len(rounds),
        "samples_mean": float(inside.mean()), "samples_min": int(inside.min()), "samples_max": int(inside.max()),
        "samples_traced": int(traced),
    }
    return counts


def window_mask(window, W: int, H: int) -> np.ndarray | None:
    """(H, W) bool: the pixels of window (x0, y0, x1, y1), rows from the top, clipped to the image;
    None for None (every pixel)."""
    if window is None:
        return None
    x0, y0, x1, y1 = (int(v) for v in window)
    mask = np.zeros((H, W), bool)
    mask[max(y0, 0):max(min(y1, H), 0), max(x0, 0):max(min(x1, W), 0)] = True
    return mask


def trace_image(scene, settings, caster, lights, maps=None, *, table=None, time_override: float | None = None,
                stream: int = 0, progress=None, cancel=None, progress_span=(0.0, 1.0),
                window=None) -> tuple[dict, TraceStats]:
    """Trace the whole image; returns (passes name -> (H, W, C) float32, TraceStats).

    Parameters
    ----------
    scene, settings : Scene, RenderSettings (samples, seed, max_depth, filter_width).
    caster : from ``make_caster(scene)``; lights : ``LightSet(scene)``.
    maps : ``PhotonMaps`` or None (then Caustic and Indirect are 0).
    time_override : every camera sample at this normalised time (accumulation stills), or a tuple
        (lo, hi) of shutter mass: the camera samples' times stratified over that part of the shutter
        only (a progressive pass's time stratum).
    stream : extra random stream id (the accumulation instant), so stills differ.
    progress(fraction, message), cancel() -> bool: polled once per batch.
    window : (x0, y0, x1, y1) pixels (rows from the top) or None: trace only those pixels (a Render
        Region); the other pixels stay 0 (Depth: the background).  Without adaptive sampling the
        tiles wholly inside the window are traced as in a whole frame (a tile's samples do not depend
        on which tiles are traced: its pixels equal a whole frame's bit for bit), and the tiles the
        window's edges cross trace the window's pixels alone (:func:`_trace_tile`'s ``inside``: equal
        to a whole frame's in distribution).  Adaptive sampling samples the window's pixels alone.
    """
    import time as _time

    t_start = _time.perf_counter()
    _kernels.require()
    W, H = (int(scene.resolution[0]), int(scene.resolution[1]))
    spp = int(settings.samples)
    stats = TraceStats()
    closures = table.closures if table is not None else pack_materials(scene.materials)
    ctx = _Context(scene=scene, caster=caster, lights=lights, maps=maps,
                   map_kinds=_map_kinds(maps), max_depth=int(settings.max_depth),
                   inst_offset=instance_offsets(scene),
                   world_radiance=np.asarray(scene.world.radiance, float),
                   film_transparent=bool(scene.metadata.get("film_transparent", False)),
                   closures=closures, ggx=ggx_albedo_tables(),
                   clamp_direct=float(settings.clamp_direct), clamp_indirect=float(settings.clamp_indirect),
                   glossy_bounces=int(settings.glossy_bounces),
                   rough_splits=int(settings.rough_splits),
                   transmission_bounces=int(settings.transmission_bounces),
                   transparent_max_bounces=int(settings.transparent_max_bounces))
    ctx.shading = shading_data(scene, closures)
    ctx.term_cut, ctx.term_freq = terminator_settings(scene)
    ctx.term_any = bool(np.any(ctx.term_cut > 0.0) or np.any(ctx.term_freq > 1.0))
    ctx.light_data = [(light_params(lights, li), mesh_arrays(lights, li)) for li in range(len(lights))]
    ctx.world_li = next((li for li, l in enumerate(lights.lights) if l.type == "WORLD"), -1)
    ctx.env = (lights.lights[ctx.world_li].env if ctx.world_li >= 0
               else constant_environment(np.asarray(scene.world.radiance, float)))
    ctx.env_camera = lights.lights[ctx.world_li].env_camera if ctx.world_li >= 0 else ctx.env
    ctx.shaped_lights = tuple(li for li, l in enumerate(lights.lights)
                              if _has_shape(l) and l.power > 0 and np.any(np.asarray(l.color, float) > 0))
    ctx.mesh_emitters = _mesh_emitters(scene, lights)
    ctx.light_visible_camera = [bool(v) for v in (scene.metadata.get("light_visible_camera") or [])]
    ctx.light_vis = light_visibility(scene)
    # Passes no sample can reach: photon passes without that map (the film sums skip them)
    ctx.zero_passes = tuple(name for name, kind in (("Caustic", "caustic"), ("Indirect", "global"))
                            if maps is None or not ctx.map_kinds.get(kind, False))
    ctx.features = bool(getattr(settings, "denoise", False))
    ctx.n_instances = len(scene.instances)
    ctx.plane_w = plane_weights(scene)
    ctx.static_view = static_view_setup(scene, maps)
    if ctx.static_view is not None and hasattr(maps, "prepare_standard"):
        maps.prepare_standard()
    ctx.final_gather = int(getattr(settings, "final_gather_samples", 0)) if getattr(maps, "gather_cache", None) is not None else 0
    if ctx.final_gather and maps.gather_cache.direct_pending:
        # the cache's direct irradiance: next-event estimation at its points (photons.gather)
        _cache_direct(ctx, maps.gather_cache, settings.seed)
    # Rough lobes read the caustic map where it can weigh photons by them and every light with power
    # sends caustic photons (else the light its paths would drop is in no map): docs/rendering.md
    ctx.glossy_floor = float(GLOSSY_CAUSTIC_MIN_ROUGHNESS)
    ctx.glossy_caustic = bool(np.isfinite(ctx.glossy_floor) and maps is not None and ctx.map_kinds.get("caustic", False)
                              and getattr(maps, "glossy_lookups", False)
                              and not getattr(maps, "per_pixel", False)
                              and np.all((lights.power <= 0) | (lights.photon_weight > 0)))
    ctx.layout = _compact_layout(ctx)
    film = Film(W, H, settings.filter_width, passes=PASSES + DENOISING_GUIDES if ctx.features else PASSES)
    cam = scene.camera

    if adaptive_on(settings, time_override, maps):
        # -- Adaptive sampling: rounds of samples for the pixels not yet converged -----------------
        counts = _trace_adaptive(ctx, film, scene, settings, stream, stats, progress, cancel, progress_span,
                                 window_mask(window, W, H))
        stats.seconds = _time.perf_counter() - t_start
        passes = film.resolve()
        passes["Sample Count"] = counts.reshape(H, W, 1).astype(np.float32)
        if ctx.features:
            passes["Noisy Image"] = passes["Combined"]
        return passes, stats

    # Tiles: square blocks of about BATCH_SAMPLES samples
    side = int(np.clip(np.sqrt(BATCH_SAMPLES / spp), 1, 64))
    tiles = [(x0, y0) for y0 in range(0, H, side) for x0 in range(0, W, side)]
    # A Render Region: the tiles it touches, each keeping its index (its random stream), and of a
    # tile its edges cross, the pixels inside it
    mask = window_mask(window, W, H)
    traced = [ti for ti, (x0, y0) in enumerate(tiles)
              if mask is None or mask[y0:y0 + side, x0:x0 + side].any()]

    def trace_tile(i: int):
        """Tile traced[i] traced and summed per pixel: (film window, TraceStats).  Pure function of
        (seed, stream, tile index, the window's pixels in the tile)."""
        ti = traced[i]
        x0, y0 = tiles[ti]
        tw, th = min(side, W - x0), min(side, H - y0)
        inside = None if mask is None else mask[y0:y0 + th, x0:x0 + tw]
        rng = rng_for(settings.seed, STREAM_CAMERA, stream, ti)
        return _trace_tile(ctx, film, cam, (W, H), x0, y0, tw, th, spp, scene.shutter, rng, time_override,
                           TraceStats(), inside=None if inside is None or inside.all() else inside)

    # Trace tiles on worker threads (embree and most numpy kernels release the GIL);
    # the film takes them in tile order, so the result does not depend on the threads.
    f0, f1 = progress_span
    for i, (tile_sums, tstats) in enumerate(ordered_map(trace_tile, len(traced), worker_count(settings), cancel)):
        film.add_window(tile_sums)
        stats.merge(tstats)
        if progress is not None:
            progress(f0 + (f1 - f0) * (i + 1) / len(traced), f"tracing tile {i + 1}/{len(traced)}")
    stats.seconds = _time.perf_counter() - t_start
    passes = film.resolve()
    if ctx.features:
        passes["Noisy Image"] = passes["Combined"]       # Cycles' name for the raw image beside the denoised one
    if getattr(settings, "use_adaptive_sampling", False) and time_override is None:
        # adaptive sampling asked for, one round (samples <= the minimum): every pixel took them all
        passes["Sample Count"] = np.full((H, W, 1), float(spp), np.float32)
    return passes, stats
