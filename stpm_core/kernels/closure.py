"""The material closure: what the compiled kernels know about a surface at a hit.

A closure is one float64 row of ``N_CLOSURE`` numbers (columns named ``C_*``
below).  Today every hit on material ``m`` reads the constant row
``closures[m]`` of :func:`pack_materials`; the shader-node interpreter
(the next step, in the manner of Cycles' SVM) will fill the same row per hit
from the material's instruction array and then call :func:`finish_closure`,
so the BSDF kernels (:mod:`stpm_core.kernels.bsdf`) never change when a node
is added.  Materials are data: a new scene never compiles a new kernel.

Primary columns (what a Principled BSDF sets; ``Material`` in
:mod:`stpm_core.scene`): base colour RGB, emission RGB (W m^-2 sr^-1),
metallic, transmission, roughness, specular, ior.  Derived columns
(:func:`finish_closure`; the same formulas as ``bsdf.MaterialTable``):

=================  =============================================================
``C_ALPHA``        GGX alpha = roughness^2
``C_W_BASE``       (1 - metallic)(1 - transmission): diffuse + coat weight
``C_W_METAL``      metallic
``C_W_GLASS``      (1 - metallic) transmission
``C_ROUGH_LOBE``   1 if some GGX lobe (roughness > 0 and a metal, glass or coat lobe; or a coat layer,
                   C_CC_WEIGHT > 0, of Coat Roughness > 0)
``C_NONDELTA``     1 if some lobe is not a delta (shade / store photons here)
``C_COAT``         1 if the diffuse base has a coat (w_base > 0 and specular > 0)
``C_HAS_DELTA``    1 if some lobe is a delta (roughness 0 and a glass, metal or coat lobe, or a coat
                   layer of Coat Roughness 0: paths / photons continue specularly); rough glass is a
                   GGX lobe, not a delta
``C_EMISSIVE``     1 if some emission channel is > 0
``C_PROGRAM``      first instruction of the material's node program; -1 = constant
``C_NS``           the hit's smooth shading normal (3 columns) when ``C_BUMPED``: a Normal
                   input replaced it (``kernels.svm``); the BSDF's bump shadowing term reads it
``C_BUMPED``       1 where a Normal input replaced the shading normal, else 0
``C_TRANSPARENT``  the tint (3 columns) of a transparent closure (Transparent BSDF, Principled
                   Alpha < 1, chosen per hit by ``kernels.svm``), else 0
``C_PASS``         1 where the closure is transparent: rays go on straight through the surface,
                   tinted by C_TRANSPARENT (``stpm_core.transparency``); its other lobes are empty
``C_TINT_T``       the transmission tint (3 columns) of the GLASS_T lobe (and the F_ss of rough
                   glass' energy compensation), as Cycles: sqrt(base colour) for a Principled BSDF,
                   the colour itself for a Glass BSDF (``Material.transmission_tint``; None = base)
``C_TINT_R``       the reflection tint (3 columns) of the GLASS_R lobe, as Cycles: white for a
                   Principled BSDF (its specular tint, which STPM does not have), the colour itself
                   for a Glass BSDF (``Material.reflection_tint``; None = white)
``C_METAL_CONST``  1 where the METAL lobe's Fresnel is its colour at every angle (a Glossy BSDF:
                   Cycles 5.0 gives it no Fresnel; ``Material.constant_fresnel``), 0 for Schlick's
                   F0 + (1 - F0)(1 - cos)^5 with F0 = base colour (a Principled BSDF's metal)
``C_CC_WEIGHT``    a Principled BSDF's Coat Weight in [0, 1] (the CLEARCOAT lobe over every other
                   lobe, ``kernels.bsdf``); 0 = no coat layer.  Primary, with ``C_CC_ROUGH`` (Coat
                   Roughness), ``C_CC_IOR`` (Coat IOR, >= 1) and ``C_CC_TINT`` (3 columns, Coat Tint)
``C_CC_ALPHA``     the coat's GGX alpha = Coat Roughness^2 (derived)
``C_CC_N``         3 columns: a linked Coat Normal (world, unit, as the node outputs it), when
                   ``C_CC_HAS_N`` is 1; else the coat follows the BSDF's own normal
=================  =============================================================

The last row (index M, where hit material -1 lands) is an inert black closure.
"""
from __future__ import annotations

import numpy as np

from ..numba_probe import njit

__all__ = ["N_CLOSURE", "pack_materials", "finish_closure", "finish_closure_at", "closure_row"] + [
    "C_BASE", "C_EMIT", "C_METALLIC", "C_TRANSMISSION", "C_ROUGHNESS", "C_SPECULAR", "C_IOR", "C_ALPHA",
    "C_W_BASE", "C_W_METAL", "C_W_GLASS", "C_ROUGH_LOBE", "C_NONDELTA", "C_COAT", "C_HAS_DELTA",
    "C_EMISSIVE", "C_PROGRAM", "C_NS", "C_BUMPED", "C_TRANSPARENT", "C_PASS", "C_TINT_T", "C_TINT_R",
    "C_METAL_CONST", "C_CC_WEIGHT", "C_CC_ROUGH", "C_CC_IOR", "C_CC_TINT", "C_CC_ALPHA", "C_CC_N", "C_CC_HAS_N"]

C_BASE = 0            # 3 columns: base colour RGB
C_EMIT = 3            # 3 columns: emitted radiance RGB
C_METALLIC = 6
C_TRANSMISSION = 7
C_ROUGHNESS = 8
C_SPECULAR = 9
C_IOR = 10
C_ALPHA = 11
C_W_BASE = 12
C_W_METAL = 13
C_W_GLASS = 14
C_ROUGH_LOBE = 15
C_NONDELTA = 16
C_COAT = 17
C_HAS_DELTA = 18
C_EMISSIVE = 19
C_PROGRAM = 20
C_NS = 21             # 3 columns: the smooth shading normal before a Normal input replaced it
C_BUMPED = 24         # 1 where a Normal input (normal map, bump) replaced the hit's shading normal
C_TRANSPARENT = 25    # 3 columns: the tint of a transparent closure (C_PASS = 1), else 0
C_PASS = 28           # 1 where the hit's closure is transparent: the ray passes on, tinted
C_TINT_T = 29         # 3 columns: the GLASS_T transmission tint (Principled: sqrt(base); Glass BSDF: its colour)
C_TINT_R = 32         # 3 columns: the GLASS_R reflection tint (Principled: white; Glass BSDF: its colour)
C_METAL_CONST = 35    # 1: the METAL lobe reflects its colour at every angle (Glossy BSDF); 0: Schlick (Principled)
C_CC_WEIGHT = 36      # Coat Weight in [0, 1]: Blender's coat layer (the CLEARCOAT lobe) over all the others
C_CC_ROUGH = 37       # Coat Roughness in [0, 1] (0: a delta mirror)
C_CC_IOR = 38         # Coat IOR in [1, 10]
C_CC_TINT = 39        # 3 columns: Coat Tint, the colour of the layer at normal incidence
C_CC_ALPHA = 42       # derived: Coat Roughness^2
C_CC_N = 43           # 3 columns: a linked Coat Normal (world, unit), used where C_CC_HAS_N is 1
C_CC_HAS_N = 46       # 1: the coat layer's normal is C_CC_N (a linked Coat Normal); 0: the BSDF's own
N_CLOSURE = 47


@njit(cache=True, nogil=True)
def finish_closure(c):
    """Fill the derived columns of closure row c (N_CLOSURE,) from its primary columns, in place."""
    finish_closure_at(c.reshape((1, c.shape[0])), 0)


@njit(cache=True, nogil=True, inline="always")      # per hit in kernels.svm: no call left there
def finish_closure_at(C, r):
    """:func:`finish_closure` of row r of C (*, N_CLOSURE), without making a view of the row (the
    interpreter finishes one row per hit: ``kernels.svm``)."""
    metallic = C[r, C_METALLIC]
    transmission = C[r, C_TRANSMISSION]
    rough = C[r, C_ROUGHNESS]
    C[r, C_ALPHA] = rough * rough
    C[r, C_W_METAL] = metallic
    w_glass = (1.0 - metallic) * transmission
    C[r, C_W_GLASS] = w_glass
    w_base = (1.0 - metallic) * (1.0 - transmission)
    C[r, C_W_BASE] = w_base
    coat = w_base > 0.0 and C[r, C_SPECULAR] > 0.0
    cc = C[r, C_CC_WEIGHT] > 0.0                      # Blender's Coat: a dielectric layer over all lobes
    cc_rough = C[r, C_CC_ROUGH]
    C[r, C_CC_ALPHA] = cc_rough * cc_rough
    rough_lobe = (rough > 0.0 and (metallic > 0.0 or w_glass > 0.0 or coat)) or (cc and cc_rough > 0.0)
    base_max = max(C[r, C_BASE], max(C[r, C_BASE + 1], C[r, C_BASE + 2]))
    C[r, C_ROUGH_LOBE] = 1.0 if rough_lobe else 0.0
    C[r, C_NONDELTA] = 1.0 if ((w_base > 0.0 and base_max > 0.0) or rough_lobe) else 0.0
    C[r, C_COAT] = 1.0 if coat else 0.0
    smooth = rough == 0.0
    index_matched = abs(C[r, C_IOR] - 1.0) < 1e-4         # rough glass of ior 1 refracts as a delta (Cycles)
    C[r, C_HAS_DELTA] = 1.0 if ((smooth and (w_glass > 0.0 or metallic > 0.0 or coat))
                                or (w_glass > 0.0 and index_matched) or (cc and cc_rough == 0.0)) else 0.0
    C[r, C_EMISSIVE] = 1.0 if (C[r, C_EMIT] > 0.0 or C[r, C_EMIT + 1] > 0.0 or C[r, C_EMIT + 2] > 0.0) else 0.0


@njit(cache=True, nogil=True)
def _finish_all(rows):
    for i in range(rows.shape[0] - 1):
        finish_closure(rows[i])


def pack_materials(materials) -> np.ndarray:
    """Closure rows (M + 1, N_CLOSURE) float64 of the scene's materials; row M is inert (black, no lobes).

    Same numbers as ``bsdf.MaterialTable`` (tested): a material row is what every hit on it reads
    until node programs fill rows per hit.
    """
    mats = list(materials)
    M = len(mats)
    rows = np.zeros((M + 1, N_CLOSURE))
    for i, m in enumerate(mats):
        rows[i, C_BASE:C_BASE + 3] = np.asarray(m.base_color, float)
        tint = getattr(m, "transmission_tint", None)
        rows[i, C_TINT_T:C_TINT_T + 3] = np.asarray(m.base_color if tint is None else tint, float)
        tint_r = getattr(m, "reflection_tint", None)
        rows[i, C_TINT_R:C_TINT_R + 3] = 1.0 if tint_r is None else np.asarray(tint_r, float)
        rows[i, C_EMIT:C_EMIT + 3] = np.asarray(m.emission, float)
        rows[i, C_METALLIC] = m.metallic
        rows[i, C_TRANSMISSION] = m.transmission
        rows[i, C_ROUGHNESS] = m.roughness
        rows[i, C_SPECULAR] = m.specular
        rows[i, C_IOR] = m.ior
        rows[i, C_PROGRAM] = -1.0
        rows[i, C_METAL_CONST] = 1.0 if getattr(m, "constant_fresnel", False) else 0.0
        # no coat layer (C_CC_WEIGHT 0): a Principled BSDF's Coat is rendered through its node graph
        # (the exporter keeps the graph of a material with a Coat Weight: kernels.svm fills C_CC_*)
        rows[i, C_CC_IOR] = 1.5
        rows[i, C_CC_TINT:C_CC_TINT + 3] = 1.0
    rows[M, C_IOR] = 1.0
    rows[M, C_CC_IOR] = 1.5
    rows[M, C_CC_TINT:C_CC_TINT + 3] = 1.0
    rows[M, C_PROGRAM] = -1.0
    _finish_all(rows)
    return rows


@njit(cache=True, nogil=True, inline="always")      # called with int32 and int64 ids: one copy each otherwise
def closure_row(closures, m):
    """Row index of material id m (-1, a miss, reads the inert last row)."""
    return closures.shape[0] - 1 if m < 0 else m
