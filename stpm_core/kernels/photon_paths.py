"""Photon paths in compiled kernels: one bounce of a batch of photons.

``stpm_core.photons.trace.trace_photon_paths`` drives the wavefront (cast the
batch at each photon's own time, draw the random numbers, pack the stored
records); :func:`photon_bounce` does the per-photon work of a bounce,
docs/photon-mapping.md ("Tracing") has the equations:

* **deposit**: a photon is stored at a hit with a non-delta lobe when its
  path qualifies: the caustic map after >= 1 specular or glossy bounce
  (L (S|G)+ D), the global map after >= ``min_nondelta`` diffuse bounces
  (docs/rendering.md, "Path partition"); ``n_delta`` counts the bounces through a
  delta or a glossy lobe, ``n_nondelta`` those through the DIFFUSE lobe or a rough coat
  (the dim, broad reflection of a plastic's dielectric layer: the global map carries it, so
  the caustic photons need not be aimed at every Principled surface);
* **diffuse bounce budget** (``RenderSettings.diffuse_bounces``, Cycles' count):
  ``n_diffuse`` counts the photon's bounces off the DIFFUSE lobe that Cycles would count
  as diffuse bounces -- all but a first one at the photon's first hit (the light came
  straight from the light there: Cycles' next-event estimation, no bounce).  A camera
  vertex reading the photon adds one (its own diffuse bounce), so a photon is stored only
  while ``n_diffuse + 1 <= max_diffuse`` and stops once no later vertex could be stored;
* **scatter**: global photons: (wi, weight, lobe) = ``bsdf_sample_lobe`` at the hit, with
  weight = f |cos| / pdf (n, 3) or a delta lobe's throughput, where a photon reflected off a
  non-delta lobe carries the adjoint BSDF, f(wo = wi, wi = wo) (:func:`adjoint_weight`);
  caustic photons:
  ``bsdf_sample_path`` (they stop where the DIFFUSE lobe is chosen, and a rough lobe's
  weight counts the non-diffuse lobes alone);
* **Russian roulette by albedo**: the photon survives with
  q = min(1, max_c weight_c) and its power becomes Phi weight / q, so stored
  powers stay even; caustic paths go on only through delta and glossy lobes;
* **adjoint BSDF**: the camera side evaluates f(wo, wi) with wo toward the viewer, and Cycles'
  closures are not reciprocal: a coated base's diffuse lobe is scaled by 1 - (the coat's albedo
  at wo), a rough coat or metal by energy compensation at wo, a bump-mapped lobe by a shadowing
  term at wi.  A photon arriving along wo (toward the light) and leaving along wi goes the other
  way, so it must carry f(wi, wo) |cos wi| / pdf(wi | wo) (Veach 1997, section 3.7).  Taking
  f(wo, wi) instead gave a coated floor's diffuse light the coat's loss at the *light's* angle,
  not at the receiver's: on the textured room, whose sun strikes a Principled floor at 55 degrees
  and whose walls see that floor at grazing angles, the walls' Indirect read up to 10 % bright
  (docs/blender.md, the room section).  Refraction keeps f(wo, wi) and the eta^2 below;
* **refraction**: a photon crossing a dielectric interface (wi and wo on opposite sides of ng
  through a closure with a glass lobe) has its power scaled by (n_i / n_t)^2 = 1 / eta^2
  (eta = ior entering, 1 / ior leaving, the closures' convention).  The camera side, as Cycles,
  carries no eta^2 at a refraction; the photons then must (Veach 1997, section 5.2: the adjoint
  of a refracting BSDF differs by it), so an estimate read in water seen from the air above is
  rho E / (pi n^2) as Cycles renders it.  A photon that enters and leaves a closed glass
  object gets 1 / eta^2 and eta^2: no change;
* **spawn**: the next ray starts at p offset by EPS along ng to wi's side,
  with its own self-intersection guard ``guard_fraction`` x EPS.
"""
from __future__ import annotations

from ..numba_probe import njit
from .bsdf import (CLEARCOAT, COAT, DIFFUSE, GLASS_R, GLASS_T, METAL, PATH_GLOSSY, PATH_STOP, bsdf_eval_pdf,
                   bsdf_sample_lobe, bsdf_sample_path, needs_bsdf_call)
from .closure import C_CC_ROUGH, C_IOR, C_NONDELTA, C_ROUGHNESS, C_W_GLASS
from .sampling import offset_origin

__all__ = ["photon_bounce", "adjoint_weight"]

_JIT = dict(cache=True, nogil=True, fastmath=False, error_model="numpy")


@njit(**_JIT)
def adjoint_weight(C, cr, E, E_avg, wo, wi, ns, ng, lobe, w0, w1, w2):
    """(w0, w1, w2): the weight of a photon that arrived along wo (unit, toward the light) and
    leaves along wi, drawn by ``bsdf_sample_lobe`` (which returned lobe and the weight w =
    f(wo, wi) |ns . wi| / pdf(wi | wo)), with the adjoint BSDF: f(wi, wo) |ns . wi| / pdf(wi | wo)
    (module docstring, "adjoint BSDF").

    Only where the two differ: a non-delta reflection (wi on wo's side of ng) off a closure that is
    not a bare diffuse lobe (``needs_bsdf_call``: a coat, a rough lobe or a replaced normal).  Delta
    lobes (mirror angles, so the same Fresnel both ways), refractions (their eta^2 is
    ``photon_bounce``'s) and bare diffuse lobes keep w."""
    if lobe < 0 or not needs_bsdf_call(C, cr):
        return w0, w1, w2
    rough = C[cr, C_ROUGHNESS] > 0.0
    if (lobe == COAT or lobe == METAL or lobe == GLASS_R) and not rough:
        return w0, w1, w2                                # a delta reflection
    if lobe == CLEARCOAT and not C[cr, C_CC_ROUGH] > 0.0:
        return w0, w1, w2                                # the smooth coat layer's mirror
    if lobe == GLASS_T:
        return w0, w1, w2                                # a refraction (delta or rough)
    go = wo[0] * ng[0] + wo[1] * ng[1] + wo[2] * ng[2]
    gi = wi[0] * ng[0] + wi[1] * ng[1] + wi[2] * ng[2]
    if not go * gi > 0.0:
        return w0, w1, w2                                # (a weight of 0 below the face stays 0)
    _, _, _, pdf = bsdf_eval_pdf(C, cr, E, E_avg, wo, wi, ns, ng)
    if not pdf > 0.0:
        return 0.0, 0.0, 0.0
    f0, f1, f2, _ = bsdf_eval_pdf(C, cr, E, E_avg, wi, wo, ns, ng)
    r = abs(wi[0] * ns[0] + wi[1] * ns[1] + wi[2] * ns[2]) / pdf
    return f0 * r, f1 * r, f2 * r


@njit(**_JIT)
def photon_bounce(rows, P, NG, NS, D, C, E, E_avg, Phi, T, n_delta, n_nondelta, n_diffuse, n_lobe, caustic, min_nondelta,
                  max_diffuse, reader, split_coat, last, U, U_rr, EPS, guard_fraction, store, o_next, d_next, Phi_next,
                  T_next, nd_next, nn_next, ndf_next, nl_next, guard_next):
    """One bounce of the photons whose rays hit: rows (k,) index the bounce's hit arrays.

    P, NG, NS (m, 3) hit points and normals; D (k, 3), Phi (k, 3) W, T (k,),
    n_delta, n_nondelta, n_diffuse (k,) int32: direction, power, time and bounce counts of
    each kept photon (row j of these belongs to hit rows[j]); C (k, N_CLOSURE)
    the closures of its hit.  caustic: the caustic map's rules (else global with
    ``min_nondelta``).  max_diffuse: Cycles' diffuse bounce budget (module docstring; the
    caller passes a large number for none).  reader: the diffuse bounces the camera path makes to
    read a photon that is not at its first hit (1: the camera vertex that reads the map; 2 with final
    gathering, whose gather vertex reads it after the camera vertex's diffuse bounce; a photon at
    its first hit is direct light there, read for 1).  last: the final bounce (store only; U, U_rr unused).
    U (k, 3), U_rr (k,) uniforms for the BSDF sample and the roulette; EPS (k,)
    origin offsets (scene units).

    n_lobe (k,) int32: the photon's bounces off the DIFFUSE lobe so far (its first hit's included);
    caustic photons (which stop on the DIFFUSE lobe): their bounces off a rough lobe, so a stored
    caustic photon with n_lobe 0 came through delta lobes alone (the record's ``delta_only`` flag).
    split_coat (global photons with final gathering): a photon stored with no DIFFUSE-lobe bounce
    behind it (its non-delta bounces all rough coats: L (S|G|C)* C (S|G|C)* D) is written as
    ``-1 - j`` in ``store``: those paths reach the vertex through no diffuse vertex, so with
    final gathering a camera vertex reads them, from the caustic map (docs/photon-mapping.md,
    "The path partition with final gathering"); the other photons as ``j``.

    Writes the photons to store into ``store`` (j, or -1 - j as above) and the surviving
    photons' next rays and state into the ``*_next`` arrays; returns (n_store, n_next).
    """
    n_store = 0
    n_next = 0
    for j in range(rows.shape[0]):
        r = rows[j]
        nondelta = C[j, C_NONDELTA] > 0.0
        # -- Store the photon (a camera vertex reading it makes one more diffuse bounce) ----------
        first = n_delta[j] == 0 and n_nondelta[j] == 0
        readable = n_diffuse[j] + (1 if first else reader) <= max_diffuse
        if nondelta and readable and ((caustic and n_delta[j] >= 1)
                                      or (not caustic and n_nondelta[j] >= min_nondelta)):
            store[n_store] = -1 - j if (split_coat and not caustic and n_lobe[j] == 0) else j
            n_store += 1
        if last:
            continue
        # -- Sample the next direction from the BSDF ---------------------------------------
        g = (NG[r, 0], NG[r, 1], NG[r, 2])
        wo = (-D[j, 0], -D[j, 1], -D[j, 2])
        ns = (NS[r, 0], NS[r, 1], NS[r, 2])
        if caustic:
            # L (S|G)+ D: on through delta and rough non-diffuse lobes, stopping on the diffuse one
            wi0, wi1, wi2, w0, w1, w2, kind, _ = bsdf_sample_path(C, j, E, E_avg, wo, ns, g, U[j, 0], U[j, 1],
                                                                  U[j, 2], caustic)
            spec_bounce = kind != PATH_STOP
            diffuse_bounce = False
            diffuse_lobe = False                         # (the DIFFUSE lobe stops a caustic path)
        else:
            wi0, wi1, wi2, w0, w1, w2, lobe = bsdf_sample_lobe(C, j, E, E_avg, wo, ns, g, U[j, 0], U[j, 1], U[j, 2])
            # the photon carries the adjoint BSDF f(wi, wo) (module docstring)
            w0, w1, w2 = adjoint_weight(C, j, E, E_avg, wo, (wi0, wi1, wi2), ns, g, lobe, w0, w1, w2)
            kind = PATH_STOP
            diffuse_lobe = lobe == DIFFUSE
            diffuse_bounce = diffuse_lobe or (lobe == COAT and C[j, C_ROUGHNESS] > 0.0)
            spec_bounce = not diffuse_bounce
        # -- Possibly terminate the path with Russian roulette (by albedo) -------------------
        q = min(max(max(w0, max(w1, w2)), 0.0), 1.0)
        alive = U_rr[j] < q
        if caustic:
            alive = alive and spec_bounce
        # Cycles' diffuse bounces: the DIFFUSE lobe's, but at the first hit (next-event estimation's light)
        nd = n_diffuse[j] + (1 if (diffuse_lobe and not first) else 0)
        if nd + reader > max_diffuse:
            alive = False                                # no camera vertex may read it any more
        if not alive:
            continue
        qq = q if q > 0.0 else 1.0
        # -- Refraction: power x (n_i / n_t)^2 = 1 / eta^2, the eta^2 the camera side leaves out ------
        # (module docstring); entering (wo on ng's side): eta = ior, leaving: 1 / ior
        go = wo[0] * g[0] + wo[1] * g[1] + wo[2] * g[2]
        gi = wi0 * g[0] + wi1 * g[1] + wi2 * g[2]
        if go * gi < 0.0 and C[j, C_W_GLASS] > 0.0:
            ior = C[j, C_IOR]
            qq = qq * (ior * ior if go > 0.0 else 1.0 / (ior * ior))      # Phi w / qq below
        # -- Spawn the continuation ray, offset off the surface --------------------------------
        e = EPS[j]
        o_next[n_next, 0], o_next[n_next, 1], o_next[n_next, 2] = offset_origin((P[r, 0], P[r, 1], P[r, 2]), g, e,
                                                                                (wi0, wi1, wi2))
        d_next[n_next, 0], d_next[n_next, 1], d_next[n_next, 2] = wi0, wi1, wi2
        Phi_next[n_next, 0] = Phi[j, 0] * w0 / qq
        Phi_next[n_next, 1] = Phi[j, 1] * w1 / qq
        Phi_next[n_next, 2] = Phi[j, 2] * w2 / qq
        T_next[n_next] = T[j]
        nd_next[n_next] = n_delta[j] + (1 if spec_bounce else 0)
        nn_next[n_next] = n_nondelta[j] + (1 if diffuse_bounce else 0)
        ndf_next[n_next] = nd
        # (caustic photons: their bounces off a rough lobe, which take the record's delta-only flag away)
        nl_next[n_next] = n_lobe[j] + (1 if (diffuse_lobe or (caustic and kind == PATH_GLOSSY)) else 0)
        guard_next[n_next] = guard_fraction * e
        n_next += 1
    return n_store, n_next
