"""The layered material of :class:`stpm_core.scene.Material`, vectorised over hits.

Six lobes (docs/lights-and-materials.md has every formula with these names):

=========  ==========================================  ==========================
lobe       weight (before Fresnel)                     shape
=========  ==========================================  ==========================
DIFFUSE    w_base = (1-metallic)(1-transmission)       base_color / pi * (1 - F_coat(wo))
COAT       w_base                                      specular * F_diel(ior); mirror or GGX
METAL      w_metal = metallic                          Schlick(F0 = base_color); mirror or GGX
GLASS_R    w_glass = (1-metallic) transmission         F_diel(eta) tint_r; mirror or GGX
GLASS_T    w_glass                                     (1 - F_diel) tint_t; refraction or GGX BTDF
METAL_MS   (probability 0: rough metal's multiple scattering scales METAL, Cycles' way)
=========  ==========================================  ==========================

Roughness 0 makes COAT / METAL / GLASS_R / GLASS_T delta lobes; above 0 they are GGX
(alpha = roughness^2, height-correlated Smith G2, visible-normal sampling);
rough metal is scaled by Cycles' energy compensation (the energy single scattering loses), so a
white rough metal reflects all light like Cycles' default Multiscatter GGX.
Rough glass is GGX reflection + GGX refraction (Walter et al. 2007, frosted glass) with
Cycles' glass energy compensation (a tabulated glass albedo).
Refraction does not scale radiance by eta^2 (the same BSDF serves camera paths
and photons; over a closed object the factors cancel).

Conventions: wo and wi point AWAY from the surface.  ``ng`` / ``ns`` may face
either way; each call turns both by the sign that puts ng toward wo (as Cycles'
back-face flip: a shading normal on the other side of its face stays there).  The
specular lobes use ns raised where it differs from ng so the mirror reflection of wo
stays above the surface (Cycles' ensure_valid_specular_reflection), and give nothing
where wo is below that normal.  A reflection lobe gives 0 unless wi is above both ng
and its normal (no light leaks through the shading normal), a transmission lobe unless
wi is below ng.  For GLASS, wo on the ng side = entering (eta = ior), else leaving
(1 / ior): a mesh with flipped normals is glass seen from inside, as in Cycles.

The shading itself is compiled: the public functions below hand the material
closures (``MaterialTable.closures``, :func:`stpm_core.kernels.closure.pack_materials`)
to the batch kernels of :mod:`stpm_core.kernels.bsdf`, the one implementation.
The former numpy implementation is the test oracle ``tests/oracles/bsdf_numpy.py``.
"""
from __future__ import annotations

import numpy as np

from .kernels import bsdf as _k
from .kernels import kernel_array
from .kernels.closure import C_EMIT, C_NONDELTA, pack_materials
from .nodes.graph import shader_lobes

__all__ = ["MaterialTable", "bsdf_eval", "bsdf_pdf", "bsdf_sample", "diffuse_albedo",
           "has_nondelta", "emission"]


class MaterialTable:
    """Per-material arrays (M,) / (M, 3) gathered once, indexed by hit material ids.

    Attributes: base_color (M, 3), tint_t (M, 3) (the glass transmission tint), tint_r (M, 3) (the
    glass reflection tint), metallic, transmission, roughness, specular,
    ior (M,), emission (M, 3), alpha = roughness^2 (M,), and the lobe weights
    w_base, w_metal, w_glass (M,).  Index -1 (a miss) reads as black, no lobes.
    ``graph_caustic`` (M + 1,) bool: the material's node graph can pick a lobe the caustic tracer
    follows in some hit (:func:`stpm_core.nodes.shader_lobes`), whatever its blended constants say.
    ``closures`` (M + 1, N_CLOSURE): the same numbers as closure rows, what the BSDF kernels read.
    """

    def __init__(self, materials):
        mats = list(materials)
        M = len(mats)
        # One extra row at the end: index -1 lands on an inert black material
        self.base_color = np.zeros((M + 1, 3))
        self.tint_t = np.zeros((M + 1, 3))       # GLASS_T's transmission tint (None: base_color)
        self.tint_r = np.zeros((M + 1, 3))       # GLASS_R's reflection tint (None: white)
        self.emission = np.zeros((M + 1, 3))
        self.metallic = np.zeros(M + 1)
        self.transmission = np.zeros(M + 1)
        self.roughness = np.zeros(M + 1)
        self.specular = np.zeros(M + 1)
        self.ior = np.ones(M + 1)
        for i, m in enumerate(mats):
            self.base_color[i] = np.asarray(m.base_color, float)
            tint = getattr(m, "transmission_tint", None)
            self.tint_t[i] = np.asarray(m.base_color if tint is None else tint, float)
            tint_r = getattr(m, "reflection_tint", None)
            self.tint_r[i] = 1.0 if tint_r is None else np.asarray(tint_r, float)
            self.emission[i] = np.asarray(m.emission, float)
            self.metallic[i] = m.metallic
            self.transmission[i] = m.transmission
            self.roughness[i] = m.roughness
            self.specular[i] = m.specular
            self.ior[i] = m.ior
        self.alpha = self.roughness ** 2
        self.w_metal = self.metallic.copy()
        self.w_glass = (1.0 - self.metallic) * self.transmission
        self.w_base = (1.0 - self.metallic) * (1.0 - self.transmission)
        self.w_base[M] = 0.0
        self.size = M
        # Per-material flags, so per-hit tests are one gather
        self.rough_lobe = (self.roughness > 0) & ((self.w_metal > 0) | (self.w_glass > 0)
                                                  | ((self.w_base > 0) & (self.specular > 0)))
        self.nondelta = ((self.w_base > 0) & (self.base_color.max(axis=1) > 0)) | self.rough_lobe
        self.coat = (self.w_base > 0) & (self.specular > 0)
        # Node graphs: can some hit pick a lobe the caustic tracer follows (nodes.shader_lobes)?
        # The constants above are the graph's blend and can hide one (a Mix Shader's smooth coat)
        self.graph_caustic = np.zeros(M + 1, dtype=bool)
        for i, m in enumerate(mats):
            if getattr(m, "graph", None) is not None:
                self.graph_caustic[i] = shader_lobes(m.graph)[0]
        self.closures = pack_materials(mats)

    def __len__(self) -> int:
        return self.size



# ---------------------------------------------------------------------------
# Arguments for the kernels: contiguous int64 ids, (n, 3) float64 vectors
# ---------------------------------------------------------------------------

def _ids(mat) -> np.ndarray:
    return kernel_array(np.asarray(mat, dtype=np.int64).reshape(-1), np.int64)


def _vec(v, n: int) -> np.ndarray:
    a = np.asarray(v, dtype=np.float64)
    if a.shape != (n, 3):
        a = np.broadcast_to(a, (n, 3))
    return kernel_array(a)


# ---------------------------------------------------------------------------
# Public API
# ---------------------------------------------------------------------------

def bsdf_eval(table: MaterialTable, mat, wo, wi, ns, ng) -> np.ndarray:
    """f(wo, wi) (n, 3) in 1/sr for the non-delta lobes (diffuse, rough coat / metal / glass reflection)."""
    mat = _ids(mat)
    n = mat.shape[0]
    E, E_avg = _k.ggx_albedo_tables()
    f = np.empty((n, 3))
    _k.eval_batch(table.closures, E, E_avg, mat, _vec(wo, n), _vec(wi, n), _vec(ns, n), _vec(ng, n),
                  f, np.empty(0))
    return f


def bsdf_pdf(table: MaterialTable, mat, wo, wi, ns, ng) -> np.ndarray:
    """Solid-angle density (n,) with which :func:`bsdf_sample` returns wi through a non-delta lobe (for MIS)."""
    mat = _ids(mat)
    n = mat.shape[0]
    E, E_avg = _k.ggx_albedo_tables()
    f = np.empty((n, 3))
    pdf = np.empty(n)
    _k.eval_batch(table.closures, E, E_avg, mat, _vec(wo, n), _vec(wi, n), _vec(ns, n), _vec(ng, n), f, pdf)
    return pdf


def bsdf_sample(table: MaterialTable, mat, wo, ns, ng, u):
    """Sample wi from the material at wo.

    Parameters
    ----------
    table : MaterialTable; mat : (n,) int material ids.
    wo : (n, 3) unit, away from the surface; ns, ng : (n, 3) unit normals.
    u : (n, 3) uniforms: u[:, 0] picks the lobe (and reflect / refract for
        glass), u[:, 1:] the direction.

    Returns
    -------
    wi : (n, 3) unit direction away from the surface.
    weight : (n, 3) f * |cos(ns, wi)| / pdf (delta lobes: their Fresnel and
        colour throughput / selection probability); 0 for failed samples.
    is_delta : (n,) bool, True when a delta lobe was chosen.
    """
    mat = _ids(mat)
    n = mat.shape[0]
    E, E_avg = _k.ggx_albedo_tables()
    u = np.ascontiguousarray(np.asarray(u, dtype=np.float64))
    wi = np.empty((n, 3))
    weight = np.empty((n, 3))
    is_delta = np.empty(n, dtype=bool)
    _k.sample_batch(table.closures, E, E_avg, mat, _vec(wo, n), _vec(ns, n), _vec(ng, n), u, wi, weight, is_delta)
    return wi, weight, is_delta


def diffuse_albedo(table: MaterialTable, mat, wo, ns) -> np.ndarray:
    """Diffuse reflectance (n, 3) after the coat: w_base * (1 - F_coat(wo)) * base_color, F_coat the
    coat's albedo at wo (smooth: specular F_diel; rough: the tabulated rough-coat albedo).

    Photon-map radiance = diffuse_albedo / pi * irradiance.  ``ns`` may face
    either way (the cosine is taken as |wo . ns|).
    """
    mat = _ids(mat)
    n = mat.shape[0]
    out = np.empty((n, 3))
    E, _ = _k.ggx_albedo_tables()
    _k.albedo_batch(table.closures, E, mat, _vec(wo, n), _vec(ns, n), out)
    return out


def has_nondelta(table: MaterialTable, mat) -> np.ndarray:
    """(n,) bool: the material has a lobe that is not a delta (diffuse or rough), i.e. shade / store photons here
    (the closure's ``C_NONDELTA`` flag, what the kernels read)."""
    mat = np.asarray(mat, dtype=np.int64)
    return table.closures[np.where(mat < 0, table.size, mat), C_NONDELTA] > 0.0


def emission(table: MaterialTable, mat) -> np.ndarray:
    """Emitted radiance (n, 3) W/(m^2 sr), both sides; 0 for misses (mat = -1)."""
    mat = np.asarray(mat, dtype=np.int64)
    return table.closures[np.where(mat < 0, table.size, mat), C_EMIT:C_EMIT + 3]
