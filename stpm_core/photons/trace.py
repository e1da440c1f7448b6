"""Photon tracing with one shutter time per path.

Every photon path draws ONE normalised shutter time t from the shutter
distribution (stratified over the photons of a batch), or takes the fixed
``time_override`` of an accumulation-buffer still; every intersection along
that path is cast at t, so the path sees the scene exactly as it was at t.

Two maps (docs/photon-mapping.md, "Tracing"):

* caustic map -- paths L S+ D.  Photons are emitted only toward the bounding
  spheres of the instances that have a delta lobe (their bounds swept over
  the whole shutter), with :meth:`LightSet.emit_toward`.  A photon aimed at
  target j must hit instance j first (so overlapping cones never count a path
  twice), continues only through delta lobes, and is stored at every
  non-delta surface reached after >= 1 delta bounce.  Its record is flagged ``delta_only``
  (``record.delta_only``) when no bounce was off a rough lobe: the photons a rough lobe of a
  camera vertex reads (docs/rendering.md, "Path partition").
* global map -- photons from :meth:`LightSet.emit` over the whole emission,
  stored at non-delta surfaces after >= 1 non-delta bounce.  Direct light is
  next-event estimation's job and L S+ D belongs to the caustic map, so the
  camera reads the global map directly at its first diffuse vertex.  With final
  gathering (which reads the global map only at gather vertices) the photons stored
  with no DIFFUSE-lobe bounce behind them (only rough coats: L (S|G|C)* C (S|G|C)* D)
  go to the caustic map instead (``coat_paths``), which the camera vertex reads.

Both follow ``settings.diffuse_bounces`` as Cycles counts diffuse bounces: the camera vertex
reading a photon makes one, each of the photon's bounces off a DIFFUSE lobe another, except one
at its first hit (that light came straight from the light: next-event estimation's, no bounce in
Cycles).  A photon is stored only where the sum is within the budget and stops where it no
longer can be (``kernels.photon_paths``): with 0 no photon is stored (direct light only, as
Cycles: no caustics either); with 1 the caustic map and the global map's L D D photons.

Russian roulette by albedo: after a bounce with throughput ``weight`` =
f |cos| / pdf (n, 3), a photon survives with q = min(1, max_c weight_c) and
its power becomes Phi * weight / q, so surviving photons keep about the same
power (stored powers stay even, which keeps the density estimate's variance low).
"""
from __future__ import annotations

import os

import numpy as np

from .. import kernels as _kernels
from ..kernels.bsdf import ggx_albedo_tables
from ..kernels.closure import C_HAS_DELTA, C_NONDELTA, C_ROUGH_LOBE, C_W_GLASS, C_W_METAL, N_CLOSURE, pack_materials
from ..kernels.svm import shade
from ..kernels.photon_paths import photon_bounce
from ..parallel import ordered_map, worker_count
from ..raycast.geometry import GUARD_FRACTION, instance_offsets, offset_lengths
from ..sampling import rng_for, stratified_1d
from ..shading import constant_shading, hit_geometry, shading_data
from ..transparency import TRANSPARENT_MAX_BOUNCES, pass_through
from . import guide as _guide
from .record import make_records, photon_origin, PHOTON_DTYPE

__all__ = ["specular_targets", "split_counts", "trace_photon_paths", "trace_caustic_map", "trace_global_map"]

STREAM_CAUSTIC = 0xCA05       # rng stream ids (independent of the camera's streams)
STREAM_GLOBAL = 0x610B
BATCH = 1 << 16               # photon paths traced together
_NO_U3 = np.zeros((0, 3))
_NO_U = np.zeros(0)
_NO_BUDGET = 1 << 30          # diffuse_bounces=None: no diffuse bounce budget


def has_delta(table, mat) -> np.ndarray:
    """(n,) bool: the material casts caustics: a delta lobe (clear glass, mirror metal, smooth coat:
    the closure's ``C_HAS_DELTA`` flag, ``kernels.closure``) or a rough metal or glass lobe (glossy
    caustics: the caustic map carries L (S|G)+ D), read for material ids mat (-1: none); a node
    graph counts when some hit can pick such a lobe (``table.graph_caustic``: e.g. the glass or
    smooth coat of a Mix Shader, which the blended constants hide)."""
    mat = np.asarray(mat, dtype=np.int64)
    row = np.where(mat < 0, table.closures.shape[0] - 1, mat)
    rows = table.closures[row]
    glossy = (rows[:, C_ROUGH_LOBE] > 0.0) & ((rows[:, C_W_METAL] > 0.0) | (rows[:, C_W_GLASS] > 0.0))
    graph = getattr(table, "graph_caustic", None)
    from_graph = graph[row] if graph is not None else False
    return (rows[:, C_HAS_DELTA] > 0.0) | glossy | from_graph


def specular_targets(scene, table) -> list[tuple[int, np.ndarray, float]]:
    """Instances that cast caustics (:func:`has_delta`) and the sphere bounding them over the whole shutter.

    (At its one instant u = 0.5 when the shutter is closed: motion outside it is unused.)

    Returns a list of (instance index, centre (3,), radius) in scene units.
    """
    out = []
    for ii, inst in enumerate(scene.instances):
        mesh = scene.meshes[inst.mesh]
        mats = np.unique(np.asarray(mesh.material_ids))
        if mats.size == 0 or not np.any(has_delta(table, mats)):
            continue
        vlo, vhi = mesh.vertex_bounds()
        if not np.all(np.isfinite(vlo)):
            continue                                     # no vertices
        if scene.shutter.is_instant:
            # A closed shutter: every path is at u = 0.5, so aim at the instance as it is then
            M = inst.transform.at(0.5)
            w = np.asarray(mesh.vertices_at(0.5), dtype=np.float64) @ M[:3, :3].T + M[:3, 3]
            lo, hi = w.min(0), w.max(0)
        else:
            lo, hi = inst.transform.bounds_of(vlo, vhi)
        out.append((ii, 0.5 * (lo + hi), max(0.5 * float(np.linalg.norm(hi - lo)), 1e-6)))
    return out


def split_counts(total: int, weights: np.ndarray) -> np.ndarray:
    """Split ``total`` photons in proportion to ``weights`` (largest remainder) -> (L,) int64."""
    w = np.maximum(np.asarray(weights, dtype=np.float64), 0.0)
    if total <= 0 or w.size == 0 or w.sum() <= 0:
        return np.zeros(w.size, dtype=np.int64)
    exact = total * w / w.sum()
    n = np.floor(exact).astype(np.int64)
    rest = total - int(n.sum())
    if rest > 0:
        n[np.argsort(-(exact - n), kind="stable")[:rest]] += 1
    return n


def _times(scene, n: int, rng, time_override) -> np.ndarray:
    """One shutter time per photon path (n,): stratified shutter samples, the fixed still time, or
    (``time_override`` a tuple (lo, hi) of shutter mass) stratified over that part of the shutter."""
    if isinstance(time_override, tuple):
        lo, hi = time_override
        return scene.shutter.sample(lo + (hi - lo) * stratified_1d(n, rng))
    if time_override is not None:
        return np.full(n, float(time_override))
    return scene.shutter.sample(stratified_1d(n, rng))


def trace_photon_paths(caster, table, o, d, Phi, t, rng, *, mode: str, max_depth: int, inst_offset: np.ndarray,
                       target_instance: int | None = None, min_nondelta: int = 1,
                       origin: np.ndarray | None = None, shading=None, diffuse_bounces: int | None = None,
                       transparent_bounces: int = TRANSPARENT_MAX_BOUNCES, reader: int = 1,
                       s_lit: np.ndarray | None = None, coat_paths: list | None = None,
                       path_ids: np.ndarray | None = None):
    """Trace photon paths and return the stored records.

    Parameters
    ----------
    caster : ray caster (``intersect(o, d, times)``).
    table : bsdf.MaterialTable (its ``closures`` rows are what the kernels read).
    o, d : (n, 3) origins and unit directions; Phi : (n, 3) W; t : (n,) path times.
    mode : 'caustic' (store after >= 1 delta or glossy bounce, continue only through
        delta and glossy lobes, first hit must be ``target_instance``) or 'global' (store
        after >= ``min_nondelta`` diffuse bounces, a rough coat's counting as one; 0 also
        stores first hits, which only tests use).
    max_depth : bounces followed.
    diffuse_bounces : Cycles' diffuse bounce budget (``RenderSettings.diffuse_bounces``): a photon
        is stored only where a camera vertex reading it makes at most this many diffuse bounces on
        the whole path, and stops where none could (``kernels.photon_paths``); None: no budget.
    reader : diffuse bounces the camera path makes to read a photon stored after its first hit: 1
        (the camera vertex reads the map) or 2 (final gathering: a gather vertex reads it after the
        camera vertex's own diffuse bounce); a first-hit photon counts 1 (direct light there).
    transparent_bounces : transparent surfaces passed in a row before one absorbs the photon
        (``RenderSettings.transparent_max_bounces``).
    inst_offset : (n_instances,) per-object part of the ray-origin offset along the geometric
        normal (scene units; ``raycast.geometry.instance_offsets``, applied by ``offset_lengths``).
    origin : (3,) world point stored positions are relative to (record.photon_origin).
    shading : ``shading.ShadingData`` of the scene (node programs, textures, mesh attributes);
        None: every hit reads its material's constant closure row.
    s_lit : (n,) distances from the origins below which a photon's first hit receives nothing
        (``LightSet.emit(..., with_s_lit=True)``: a soft-falloff light's photons); such photons
        are dropped.  None: every first hit counts.
    coat_paths : a list (global mode): the records of photons stored with no DIFFUSE-lobe bounce
        behind them (their non-delta bounces all rough coats) are appended to it instead of
        returned; with final gathering they belong to the caustic map (a camera vertex reads them:
        docs/photon-mapping.md, "The path partition with final gathering").  None: all returned.
    path_ids : (n,) int64 or None: a number per path; given, the paths' numbers of the returned
        records come back too (``benchmarks/bench_guiding.py`` sorts the power stored in view by
        where each photon first landed).  ``photon_bounce`` copies each surviving path's time
        unchanged, so here it is handed the row numbers instead and the times and numbers follow.

    Returns
    -------
    (m,) PHOTON_DTYPE records; with ``path_ids`` also their paths' numbers (m,) int64.

    Per bounce: cast every path at its own time, keep the hits (at the first
    bounce of a caustic path: only hits on its target), gather their closures,
    draw (k, 3) uniforms for the BSDF and (k,) for the roulette (not at the
    last bounce), and let ``kernels.photon_paths.photon_bounce`` store,
    scatter, roulette and spawn.
    """
    _kernels.require()
    o = np.asarray(o, dtype=np.float64)
    d = np.asarray(d, dtype=np.float64)
    Phi = np.asarray(Phi, dtype=np.float64)
    t = np.asarray(t, dtype=np.float64)
    closures = getattr(table, "closures", None)
    if closures is None:
        closures = pack_materials(table)                 # a list of materials
    E, E_avg = ggx_albedo_tables()
    caustic = mode == "caustic"
    # Photons with no power carry nothing
    live = np.any(Phi > 0.0, axis=1)
    o, d, Phi, t = o[live], d[live], Phi[live], t[live]
    ids = None if path_ids is None else np.asarray(path_ids, np.int64)[live]
    stored_ids = []                                      # (with path_ids) the numbers of stored's rows
    s_lit = None if s_lit is None else np.asarray(s_lit, dtype=np.float64)[live]
    n_delta = np.zeros(o.shape[0], dtype=np.int32)      # delta bounces so far
    n_nondelta = np.zeros(o.shape[0], dtype=np.int32)   # non-delta bounces so far
    n_diffuse = np.zeros(o.shape[0], dtype=np.int32)    # diffuse bounces as Cycles counts them
    n_lobe = np.zeros(o.shape[0], dtype=np.int32)       # bounces off the DIFFUSE lobe (the first hit's too)
    split_coat = coat_paths is not None and not caustic
    max_diffuse = _NO_BUDGET if diffuse_bounces is None else int(diffuse_bounces)
    stored = []
    guard = None                                         # emitted rays: the caster's own guard
    for depth in range(max_depth + 1):
        if o.shape[0] == 0:
            break
        # -- Intersect every path at its own time -------------------------------------
        hits = caster.intersect(o, d, t, None, guard=guard)
        keep = hits.hit
        if caustic and depth == 0 and target_instance is not None:
            keep &= hits.instance == target_instance     # this target's cone owns only its own first hits
        if depth == 0 and s_lit is not None:
            keep &= hits.t >= s_lit                       # a soft-falloff light's disc does not reach them
        idx = np.nonzero(keep)[0]
        k = idx.size
        if k == 0:
            break
        d, Phi, t = np.ascontiguousarray(d[idx]), np.ascontiguousarray(Phi[idx]), t[idx]
        if ids is not None:
            ids = ids[idx]
        n_delta, n_nondelta, n_diffuse, n_lobe = n_delta[idx], n_nondelta[idx], n_diffuse[idx], n_lobe[idx]
        C = np.empty((k, N_CLOSURE))
        sd = shading if shading is not None else constant_shading(closures)
        if sd.uses_programs:
            G = hit_geometry(hits, d, idx, sd=sd, times=t)
            shade(sd, np.ascontiguousarray(hits.material[idx]), G, int(rng.integers(1 << 62)) if sd.uses_mix else 0, C)
            if sd.uses_normals:
                hits.ns[idx] = G[2]                      # Normal inputs (normal maps) set the shading normals
        else:
            shade(sd, np.ascontiguousarray(hits.material[idx]), None, 0, C)
        if sd.store_any:
            # A surface that picks its closure per hit (Mix / Add Shader, Alpha): the map estimates
            # the irradiance there whatever this photon's pick (camera paths weigh by their own
            # pick), so a photon whose pick scatters nothing here (transparency, emission, a delta
            # lobe) is stored as well, by the map's path rule
            first = (n_delta == 0) & (n_nondelta == 0)
            rule = (((n_delta >= 1) if caustic else (n_nondelta >= min_nondelta))
                    & (n_diffuse + np.where(first, 1, int(reader)) <= max_diffuse))
            extra = np.flatnonzero(sd.store_mask[hits.material[idx]]
                                   & (C[:, C_NONDELTA] <= 0.0) & rule)
            if extra.size:
                coat = split_coat & (n_lobe[extra] == 0)
                for part, out in ((extra[~coat], stored), (extra[coat], coat_paths)):
                    if part.size:
                        out.append(make_records(hits.position[idx[part]], -d[part], Phi[part], t[part], origin,
                                                _delta_flag(caustic, out is coat_paths, n_lobe[part]),
                                                ng=hits.ng[idx[part]]))
                        if ids is not None and out is stored:
                            stored_ids.append(ids[part])
        if sd.transparent:
            # transparent hits: the photon goes on behind, its power tinted (not a bounce)
            Phi = pass_through(caster, sd, inst_offset, hits, d, t, C, Phi, rng, at=idx, limit=transparent_bounces)
        last = depth == max_depth
        # -- Random numbers of the bounce: BSDF lobe and direction, then the roulette ----------
        U = rng.random((k, 3)) if not last else _NO_U3
        U_rr = rng.random(k) if not last else _NO_U
        EPS = offset_lengths(inst_offset, hits.instance[idx], hits.position[idx])
        store = np.empty(k, np.int64)
        o_n, d_n, Phi_n = np.empty((k, 3)), np.empty((k, 3)), np.empty((k, 3))
        t_n, g_n = np.empty(k), np.empty(k)
        nd_n, nn_n, ndf_n = np.empty(k, np.int32), np.empty(k, np.int32), np.empty(k, np.int32)
        nl_n = np.empty(k, np.int32)
        # (with path_ids the kernel carries row numbers where the times go: T_next = T[j])
        T, T_t = (t, None) if ids is None else (np.arange(k, dtype=np.float64), t)
        n_store, n_next = photon_bounce(idx, hits.position, hits.ng, hits.ns, d, C, E, E_avg, Phi, T, n_delta,
                                        n_nondelta, n_diffuse, n_lobe, caustic, int(min_nondelta), max_diffuse,
                                        int(reader), split_coat, last, U, U_rr, EPS, GUARD_FRACTION, store, o_n, d_n,
                                        Phi_n, t_n, nd_n, nn_n, ndf_n, nl_n, g_n)
        # -- Store the photons (store: j, or -1 - j for coat_paths) ------------------------------
        if n_store:
            s = store[:n_store]
            for part, out in ((s[s >= 0], stored), (-1 - s[s < 0], coat_paths)):
                if part.size:
                    out.append(make_records(hits.position[idx[part]], -d[part], Phi[part], t[part], origin,
                                            _delta_flag(caustic, out is coat_paths, n_lobe[part]),
                                            ng=hits.ng[idx[part]]))
                    if ids is not None and out is stored:
                        stored_ids.append(ids[part])
        if last:
            break
        o, d, Phi, t, guard = o_n[:n_next], d_n[:n_next], Phi_n[:n_next], t_n[:n_next], g_n[:n_next]
        if ids is not None:
            rows = t.astype(np.int64)
            t, ids = T_t[rows], ids[rows]
        n_delta, n_nondelta, n_diffuse, n_lobe = nd_n[:n_next], nn_n[:n_next], ndf_n[:n_next], nl_n[:n_next]
    recs = np.concatenate(stored) if stored else np.empty(0, dtype=PHOTON_DTYPE)
    if ids is None:
        return recs
    return recs, (np.concatenate(stored_ids) if stored_ids else np.empty(0, np.int64))


def _delta_flag(caustic: bool, coat: bool, n_lobe: np.ndarray):
    """The records' delta-only flag (``record.delta_only``): caustic photons with no rough bounce
    (``n_lobe``, which counts a caustic photon's bounces off rough lobes, is 0), never the global
    photons that final gathering moves to the caustic map (``coat_paths``); the global map's own
    records are left unflagged (None: never read for it)."""
    if caustic:
        return n_lobe == 0
    return np.zeros(n_lobe.shape[0], bool) if coat else None


def _run_batches(trace_batch, jobs: list, settings, progress, cancel, message: str) -> list:
    """Records of every batch, in batch order, traced on ``settings.threads`` worker threads.

    jobs: (source, first photon, photons, source's photons) per batch; progress
    is reported as the photons of finished batches over all of them.
    """
    total = max(sum(job[2] for job in jobs), 1)
    out, emitted = [], 0
    for j, recs in enumerate(ordered_map(trace_batch, len(jobs), worker_count(settings), cancel)):
        out.append(recs)
        emitted += jobs[j][2]
        if progress is not None:
            progress(emitted / total, message)
    return out


def trace_caustic_map(scene, settings, caster, lights, table, *, time_override=None,
                      progress=None, cancel=None) -> tuple[np.ndarray, dict]:
    """Caustic map records and counts: ``settings.photons_caustic`` photons aimed at specular instances.

    Photons are split over (light, target) pairs by power x photon weight x solid angle of the
    target's bounding sphere (suns: power x weight x (r_target / r_scene)^2); the split
    only moves variance around, the power weighting of ``emit_toward`` keeps
    every pair unbiased.
    """
    # (the same every pass of a render: kept in the scene's frozen cache while it renders)
    cache = scene.frozen_cache() if hasattr(scene, "frozen_cache") else None
    targets = cache.get("specular_targets") if cache is not None else None
    if targets is None:
        targets = specular_targets(scene, table)
        if cache is not None:
            cache["specular_targets"] = targets
    r_scene, inst_offset = scene.bounding_sphere()[1], instance_offsets(scene)
    origin = photon_origin(scene)
    pairs, weights = [], []
    for li, light in enumerate(lights.lights):
        P = float(lights.power[li]) * float(lights.photon_weight[li])
        if P <= 0.0:
            continue
        pos = light.transform.at(0.5)[:3, 3]
        for (ii, c, r) in targets:
            if light.type in ("SUN", "WORLD"):
                frac = min(1.0, (r / r_scene) ** 2)
            else:
                dist = float(np.linalg.norm(c - pos))
                frac = 1.0 if dist <= r else 0.5 * (1.0 - np.sqrt(max(0.0, 1.0 - (r / dist) ** 2)))
            pairs.append((li, ii, c, r))
            weights.append(P * frac)
    counts = split_counts(int(settings.photons_caustic), np.asarray(weights))
    shading = shading_data(scene, table.closures)
    jobs = [(pi, b0, min(BATCH, int(n_pair) - b0), int(n_pair)) for pi, n_pair in enumerate(counts)
            for b0 in range(0, int(n_pair), BATCH)]

    def trace_batch(j: int) -> np.ndarray:
        """Records of batch j: a pure function of (seed, pair, batch), so threads do not change them."""
        pi, b0, n, n_pair = jobs[j]
        li, ii, c, r = pairs[pi]
        rng = rng_for(settings.seed, STREAM_CAUSTIC, pi, b0 // BATCH)
        t = _times(scene, n, rng, time_override)
        o, d, Phi, s_lit = lights.emit_toward(li, n, t, rng, c, r, with_s_lit=True)
        Phi = Phi * (n / float(n_pair))                  # this batch's share of the pair's photons
        return trace_photon_paths(caster, table, o, d, Phi, t, rng, origin=origin, mode="caustic", s_lit=s_lit,
                                  max_depth=settings.max_depth, inst_offset=inst_offset, target_instance=ii,
                                  shading=shading, diffuse_bounces=settings.diffuse_bounces,
                                  transparent_bounces=settings.transparent_max_bounces)

    out = _run_batches(trace_batch, jobs, settings, progress, cancel, "tracing caustic photons")
    recs = np.concatenate(out) if out else np.empty(0, dtype=PHOTON_DTYPE)
    per_light = np.zeros(len(lights.lights), np.int64)
    for (li, _, _, _), n_pair in zip(pairs, counts):
        per_light[li] += int(n_pair)
    return recs, {"photons_emitted_caustic": int(counts.sum()), "caustic_targets": len(targets),
                  "photons_emitted_caustic_per_light": [int(x) for x in per_light]}


def trace_global_map(scene, settings, caster, lights, table, *, time_override=None,
                     progress=None, cancel=None, min_nondelta: int = 1,
                     coat_paths: list | None = None) -> tuple[np.ndarray, dict]:
    """Global map records and counts: ``settings.photons_global`` photons split over lights by power x
    photon weight (``LightSet.photon_weight``: each light's photons carry its flux divided by their
    number, so the weights move noise between lights and leave the estimate unbiased).

    coat_paths : with final gathering, a list that receives (as one records array, appended) the
    photons stored with no DIFFUSE-lobe bounce behind them (L (S|G|C)* C (S|G|C)* D, C a rough
    coat): they are not in the returned records; the caller puts them into the caustic map, which
    camera vertices read (:func:`trace_photon_paths`).  Without final gathering (or None) every
    photon is returned."""
    # With final gathering the photons are read at the gather vertices, one camera bounce further:
    # the diffuse budget counts it (reader 2, kernels.photon_paths; off when diffuse_bounces < 2)
    gather = int(getattr(settings, "final_gather_samples", 0)) > 0 and int(settings.diffuse_bounces) >= 2
    split = gather and coat_paths is not None
    inst_offset = instance_offsets(scene)
    origin = photon_origin(scene)
    counts = split_counts(int(settings.photons_global),
                          np.asarray(lights.power, dtype=np.float64) * np.asarray(lights.photon_weight, np.float64))
    shading = shading_data(scene, table.closures)
    jobs = [(li, b0, min(BATCH, int(n_light) - b0), int(n_light)) for li, n_light in enumerate(counts)
            for b0 in range(0, int(n_light), BATCH)]
    # -- The camera pilot (what the camera sees: --stats) and, with photon_guiding, the guides -------
    guiding = bool(getattr(settings, "photon_guiding", False))
    guides, marks, cells, pilot_s = [None] * len(lights.lights), [0] * len(lights.lights), None, 0.0
    count_visible = guiding or os.environ.get(_guide.VISIBLE_STATS_ENV, "") not in ("", "0")
    if int(counts.sum()) > 0 and count_visible:
        cells, guides, marks, pilot_s = _guide.guides_for(scene, caster, lights, table, shading=shading,
                                                          inst_offset=inst_offset, origin=origin,
                                                          time_override=time_override, guiding=guiding)

    def trace_batch(j: int) -> tuple[np.ndarray, list]:
        """Records of batch j (and its coat-path records): a pure function of (seed, light, batch),
        so threads do not change them."""
        li, b0, n, n_light = jobs[j]
        rng = rng_for(settings.seed, STREAM_GLOBAL, li, b0 // BATCH)
        t = _times(scene, n, rng, time_override)
        # Each light's emit() spreads its flux over the photons it is given: scale
        # to this batch's share of the light's photons.
        o, d, Phi, s_lit = lights.emit(li, n, t, rng, with_s_lit=True, guide=guides[li])
        Phi = Phi * (n / float(n_light))
        coat: list | None = [] if split else None
        recs = trace_photon_paths(caster, table, o, d, Phi, t, rng, origin=origin, mode="global", s_lit=s_lit,
                                  max_depth=settings.max_depth, inst_offset=inst_offset, min_nondelta=min_nondelta,
                                  shading=shading, diffuse_bounces=settings.diffuse_bounces,
                                  transparent_bounces=settings.transparent_max_bounces, reader=2 if gather else 1,
                                  coat_paths=coat)
        return recs, coat or []

    out = _run_batches(trace_batch, jobs, settings, progress, cancel, "tracing global photons")
    recs = np.concatenate([r for r, _ in out]) if out else np.empty(0, dtype=PHOTON_DTYPE)
    coat = [c for _, cs in out for c in cs]
    if split:
        coat_paths.append(np.concatenate(coat) if coat else np.empty(0, dtype=PHOTON_DTYPE))
    info = {"photons_emitted_global": int(counts.sum()),
            "photons_emitted_global_per_light": [int(x) for x in counts],
            "photons_global_coat_paths": int(sum(c.shape[0] for c in coat)),
            "photons_stored_global": int(recs.shape[0]),
            "photon_guiding": guiding, "guide_pilot_s": pilot_s}
    if cells is not None:
        # photons stored on camera-visible surfaces (the pilot's voxels: photons.guide.VisibleCells)
        on = cells.contains(recs["position"].astype(np.float64) + origin)
        info["photons_stored_visible_global"] = int(np.count_nonzero(on))
        info["photons_stored_visible_global_fraction"] = (info["photons_stored_visible_global"]
                                                          / max(int(counts.sum()), 1))
    if guiding:
        info["guide_marks_per_light"] = [int(x) for x in marks]
        info["guide_marked_cells_per_light"] = [0.0 if g is None else float(g.marked_fraction) for g in guides]
        info["photons_guided_global_per_light"] = [0 if g is None else int(round(g.g * int(c)))
                                                   for g, c in zip(guides, counts)]
    return recs, info
