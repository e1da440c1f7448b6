"""The numpy photon tracer the compiled kernels replaced, kept as a slow reference.

``trace_photon_paths`` has the signature and the random-number order of
``stpm_core.photons.trace.trace_photon_paths`` and runs on the numpy BSDF
oracle, so both store the same records up to float rounding
(tests/test_kernel_photons.py).  Nothing in ``stpm_core`` imports this module.
"""
from __future__ import annotations

import numpy as np

from oracles.bsdf_numpy import (COAT, DIFFUSE, GLASS_T, bsdf_eval, bsdf_pdf, bsdf_sample_lobe, bsdf_sample_path,
                                 has_nondelta)
from stpm_core.photons.record import PHOTON_DTYPE, make_records
from stpm_core.raycast.geometry import GUARD_FRACTION, offset_lengths

__all__ = ["trace_photon_paths"]


def trace_photon_paths(caster, table, o, d, Phi, t, rng, *, mode: str, max_depth: int, inst_offset: np.ndarray,
                       target_instance: int | None = None, min_nondelta: int = 1,
                       origin: np.ndarray | None = None, diffuse_bounces: int | None = None) -> np.ndarray:
    """Trace photon paths and return the stored records.

    Parameters
    ----------
    caster : ray caster (``intersect(o, d, times)``).
    table : bsdf.MaterialTable.
    o, d : (n, 3) origins and unit directions; Phi : (n, 3) W; t : (n,) path times.
    mode : 'caustic' (store after >= 1 delta or glossy bounce, continue only through
        them, first hit must be ``target_instance``) or 'global' (store after >=
        ``min_nondelta`` diffuse bounces, a rough coat's counting as one; 0 also stores
        first hits, which only tests use).
    max_depth : bounces followed.
    inst_offset : (n_instances,) per-object part of the ray-origin offset along the geometric
        normal (scene units; ``raycast.geometry.instance_offsets``, applied by ``offset_lengths``).
    origin : (3,) world point stored positions are relative to (record.photon_origin).
    diffuse_bounces : Cycles' diffuse bounce budget (None: none): a photon is stored while the
        DIFFUSE-lobe bounces it made (but one at its first hit) plus 1 (the camera vertex reading
        it) are within it, and stops when they no longer are.

    Returns
    -------
    (m,) PHOTON_DTYPE records.
    """
    o = np.asarray(o, dtype=np.float64)
    d = np.asarray(d, dtype=np.float64)
    Phi = np.asarray(Phi, dtype=np.float64)
    t = np.asarray(t, dtype=np.float64)
    # Photons with no power carry nothing
    live = np.any(Phi > 0.0, axis=1)
    o, d, Phi, t = o[live], d[live], Phi[live], t[live]
    n_delta = np.zeros(o.shape[0], dtype=np.int32)      # delta bounces so far
    n_nondelta = np.zeros(o.shape[0], dtype=np.int32)   # non-delta bounces so far
    n_diffuse = np.zeros(o.shape[0], dtype=np.int32)    # diffuse bounces as Cycles counts them
    budget = np.inf if diffuse_bounces is None else diffuse_bounces
    stored = []
    guard = None                                         # emitted rays: the caster's own guard
    for depth in range(max_depth + 1):
        if o.shape[0] == 0:
            break
        # -- Intersect every path at its own time -------------------------------------
        hits = caster.intersect(o, d, t, None, guard=guard)
        keep = hits.hit
        if mode == "caustic" and depth == 0 and target_instance is not None:
            keep &= hits.instance == target_instance     # this target's cone owns only its own first hits
        idx = np.nonzero(keep)[0]
        if idx.size == 0:
            break
        d, Phi, t = d[idx], Phi[idx], t[idx]
        n_delta, n_nondelta, n_diffuse = n_delta[idx], n_nondelta[idx], n_diffuse[idx]
        p, ng, ns, mat = hits.position[idx], hits.ng[idx], hits.ns[idx], hits.material[idx]
        wo = -d                                          # toward where the photon came from
        nondelta = has_nondelta(table, mat)
        # -- Store the photon ---------------------------------------------------------------
        if mode == "caustic":
            store = nondelta & (n_delta >= 1)
        else:
            store = nondelta & (n_nondelta >= min_nondelta)
        store &= n_diffuse + 1 <= budget
        if np.any(store):
            stored.append(make_records(p[store], wo[store], Phi[store], t[store], origin, ng=ng[store]))
        if depth == max_depth:
            break
        # -- Sample the next direction from the BSDF --------------------------------------
        u = rng.random((idx.size, 3))
        if mode == "caustic":
            # L (S|G)+ D: on through delta and glossy lobes; the DIFFUSE lobe and a rough coat stop
            wi, weight, kind, _ = bsdf_sample_path(table, mat, wo, ns, ng, u, stop_coat=True)
            spec_b = kind != 0
            diffuse_lobe = np.zeros(idx.size, bool)
        else:
            wi, weight, is_delta, lobe = bsdf_sample_lobe(table, mat, wo, ns, ng, u)
            rough = table.roughness[np.where(mat < 0, table.size, mat)] > 0
            # The adjoint BSDF f(wi, wo) |ns . wi| / pdf(wi | wo) for a non-delta reflection off a
            # closure that is not a bare diffuse lobe (kernels.photon_paths.adjoint_weight)
            mi = np.where(mat < 0, table.size, mat)
            adj = np.nonzero((lobe >= 0) & ~is_delta & (lobe != GLASS_T) & (table.rough_lobe[mi] | table.coat[mi])
                             & (np.sum(wo * ng, axis=1) * np.sum(wi * ng, axis=1) > 0.0))[0]
            if adj.size:
                a = (mat[adj], wo[adj], wi[adj], ns[adj], ng[adj])
                pdf = bsdf_pdf(table, a[0], a[1], a[2], a[3], a[4])
                f = bsdf_eval(table, a[0], a[2], a[1], a[3], a[4])
                r = np.abs(np.sum(a[2] * a[3], axis=1)) / np.where(pdf > 0, pdf, 1.0)
                weight = weight.copy()
                weight[adj] = np.where((pdf > 0)[:, None], f * r[:, None], 0.0)
            spec_b = ~((lobe == DIFFUSE) | ((lobe == COAT) & rough))
            diffuse_lobe = lobe == DIFFUSE
        # -- Possibly terminate the path with Russian roulette (by albedo) -------------------
        q = np.clip(weight.max(axis=1), 0.0, 1.0)
        alive = rng.random(idx.size) < q
        if mode == "caustic":
            alive &= spec_b
        Phi = Phi * weight / np.where(q > 0, q, 1.0)[:, None]
        # A refraction scales power by (n_i / n_t)^2: wi and wo on opposite sides of ng through glass
        mi = np.where(mat < 0, table.size, mat)
        cos_o = np.sum(wo * ng, axis=1)
        crossed = (cos_o * np.sum(wi * ng, axis=1) < 0.0) & (table.w_glass[mi] > 0.0)
        n_ratio = np.where(cos_o > 0.0, 1.0 / table.ior[mi], table.ior[mi])          # n_i / n_t
        Phi = np.where(crossed[:, None], Phi * (n_ratio ** 2)[:, None], Phi)
        n_diffuse = n_diffuse + (diffuse_lobe & ((n_delta + n_nondelta) > 0))   # not at the first hit
        alive &= n_diffuse + 1 <= budget
        n_delta = n_delta + spec_b                       # delta or glossy bounces
        n_nondelta = n_nondelta + ~spec_b                # diffuse (or rough coat) bounces
        # -- Spawn the continuation rays, offset off the surface ------------------------------
        side = np.where(np.sum(wi * ng, axis=1) >= 0.0, 1.0, -1.0)
        e = offset_lengths(inst_offset, hits.instance[idx], p)
        o = p + (e * side)[:, None] * ng
        sel = np.nonzero(alive)[0]
        o, d, Phi, t = o[sel], wi[sel], Phi[sel], t[sel]
        guard = GUARD_FRACTION * e[sel]                  # the rays' own guards (geometry.ray_guard)
        n_delta, n_nondelta, n_diffuse = n_delta[sel], n_nondelta[sel], n_diffuse[sel]
    if not stored:
        return np.empty(0, dtype=PHOTON_DTYPE)
    return np.concatenate(stored)
