"""The layered material's BSDF per hit, compiled: the one implementation of shading.

Every function reads one closure row ``C[cr]`` (passed as the array C and the row index cr, so no
row view is made per hit) (:mod:`stpm_core.kernels.closure`,
columns ``C_*``), never a ``MaterialTable``, so the same code serves constant
materials and, later, closures filled per hit by the shader-node interpreter.
Vectors are 3-tuples of float64; ``wo`` and ``wi`` point away from the surface.
docs/lights-and-materials.md ("Materials") has the formulas with these names.

Seven lobes (N_LOBES), weights w_base = (1 - metallic)(1 - transmission),
w_metal = metallic, w_glass = (1 - metallic) transmission:

=========  =======================================================================
DIFFUSE    w_base (1 - F_coat(wo)) base_color / pi, F_coat = specular F_diel(cos_o, ior)
COAT       w_base specular F_diel(ior): delta mirror (roughness 0) or GGX with Cycles' energy
           compensation (1 + F_ms (1 - E(mu_o)) / E(mu_o))
METAL      w_metal Schlick(base_color): delta mirror or GGX (rough: times k_metal)
GLASS_R    w_glass F_diel(eta) tint_r: delta mirror or GGX (rough: times k_glass).
           tint_r = the closure's C_TINT_R, Cycles' reflection tint: white for a Principled BSDF
           (its specular tint, which STPM does not have), the colour for a Glass BSDF
GLASS_T    w_glass (1 - F_diel(eta)) tint_t: delta refraction, or (roughness > 0, ior != 1)
           Walter et al.'s GGX BTDF (1 - F(wo.h)) tint_t D G2 |wo.h||wi.h| eta^2 / (cos_o cos_i
           (wo.h + eta wi.h)^2) times k_glass, Cycles' glass energy compensation
           1 + F_ms (1 - E_g(mu_o)) / E_g(mu_o) (E_g: the tabulated GGX glass albedo, F_ss = tint_t).
           tint_t = the closure's C_TINT_T, Cycles' transmission tint: sqrt(base_color) for a
           Principled BSDF, the colour for a Glass BSDF
METAL_MS   no longer a lobe (probability 0): a rough METAL lobe is scaled by Cycles' energy
           compensation k_metal = 1 + F_ms (1 - E(mu_o)) / E(mu_o) per channel instead
CLEARCOAT  Blender's Principled Coat, a layer over all the lobes above: cw F_diel(ior_c) about its
           own normal ncs (the smooth shading normal), delta mirror (Coat Roughness 0) or GGX of
           alpha_c = Coat Roughness^2 times k_cc (as COAT's); the lobes above are times
           att = (1 - F_cc(wo)) mix(1, coat_tint^(1 / cos_t), cw) per channel (closure C_CC_*)
=========  =======================================================================

GGX lobes: D G2 / (4 cos_o cos_i) times their Fresnel at wo.h (alpha =
roughness^2, at least 1e-4), height-correlated Smith G2, visible-normal
sampling with pdf G1(wo) D / (4 cos_o).  Normals as they come, as Cycles: each call turns ng
toward wo and ns by the same sign (the back-face flip of Cycles' ``sd->N``, ``sd->Ng``; a shading
normal that disagrees with its face keeps disagreeing), and wo on ng's side is entering (eta =
ior), else leaving (eta = 1 / ior): a mesh with flipped normals is glass seen from inside.  The
specular lobes (coat, metal, glass) use ``nss``, ns raised toward ng wherever it differs from ng
(smooth or custom normals, Normal inputs: ``ensure_valid_specular_reflection``) and are 0 when
wo is below it (Cycles' microfacet closures: no lobe for wo under N).  A glossy reflection lobe
is 0 unless wi is above both ng and its normal, a refraction unless wi is below ng (and, rough,
below nss); the DIFFUSE lobe is evaluated wherever wi is above ns, also below the face, where the
shadow ray decides (:func:`diffuse_side`, as Cycles); a sampled reflection below ng or refraction
above it has weight 0.  Rough glass samples one
visible normal h and reflects or refracts through it, the choice per microfacet as Cycles
(F(wo.h) mean(tint_r) against (1 - F) mean(tint_t)) inside the glass lobes' joint probability.

Per-hit functions (compiled once; the kernels call them):

* :func:`bsdf_eval_pdf` -- f (1/sr) of the non-delta lobes and the
  mixture solid-angle pdf ``pdf_nd = sum_j p_j pdf_j(wi)`` with which
  :func:`bsdf_sample` returns wi through a non-delta lobe (for MIS);
* :func:`bsdf_eval` -- the same f; materials without a rough lobe take the
  short form :func:`bsdf_eval_smooth`, ``w_base (1 - F_coat(wo)) base_color / pi`` (equal to
  rounding), and a diffuse without coat or replaced normal the shortest,
  :func:`bsdf_eval_plain`, ``w_base base_color / pi``, which calls nothing (``paths.nee_light``
  evaluates it in its loop without calls, the others in a loop of their own);
* :func:`bsdf_sample` -- wi from the lobe u0 picks (probability p_j
  proportional to an albedo estimate at wo) and the direction u1, u2 pick;
  weight = f_nd |cos| / pdf_nd for a non-delta lobe, throughput / p_j for a
  delta lobe, 0 for a failed sample;
* :func:`bsdf_sample_path` -- the same choice for a photon path whose DIFFUSE lobe the photon
  maps carry: stop on DIFFUSE, else continue (delta, or rough with the weight of the
  non-diffuse lobes alone);
* :func:`bsdf_sample_cont` -- the same choice for a camera path: a delta lobe, or the rough
  non-diffuse lobes' part of f at wi drawn by any non-delta lobe (DIFFUSE included), weighed by
  one-sample multiple importance sampling over the lobes; :func:`bsdf_eval_cont` its f and density;
* :func:`diffuse_albedo` -- w_base (1 - F_coat(|wo . ns|)) base_color, what
  multiplies photon irradiance;
* :func:`denoising_features` -- Cycles' Denoising Albedo / Normal at a vertex: each lobe's albedo
  at wo, diffuse-like or specular-like by its roughness, and whether the features stop here;
* :func:`fresnel_dielectric` -- F_diel(cos_i, eta), exact unpolarised, 1 under TIR;
* :func:`ggx_albedo`, :func:`ggx_albedo_avg` -- look-ups of the single-scattering
  GGX albedo E(mu, alpha) (bilinear) and E_avg(alpha) (linear) in the tables
  of :func:`ggx_albedo_tables` (a plain function, built once per process);
  :func:`glass_albedo`, :func:`glass_albedo_avg` the same for rough glass (the shipped
  ``glass_albedo.npy``, :func:`build_glass_table`).

Batch kernels (loops over hits, used by ``stpm_core.bsdf`` and the tests):
:func:`eval_batch`, :func:`sample_batch`, :func:`albedo_batch`.

Same random numbers and formulas as the numpy oracle (tests/oracles/bsdf_numpy.py),
equal to float rounding (tests/test_kernel_bsdf.py).  Dot products are summed
x + y + z in order (numpy's einsum adds x + z first on this machine's SIMD
path), so results may differ in the last bit.
"""
from __future__ import annotations

import math
import threading
from pathlib import Path

import numpy as np

from ..numba_probe import njit
from .sampling import JIT_INLINE, basis, cosine_hemisphere, dot
from .closure import (C_ALPHA, C_BASE, C_TINT_R, C_TINT_T, C_BUMPED, C_COAT, C_IOR, C_NS, C_ROUGH_LOBE, C_ROUGHNESS, C_SPECULAR,
                      C_CC_ALPHA, C_CC_HAS_N, C_CC_IOR, C_CC_N, C_CC_ROUGH, C_CC_TINT, C_CC_WEIGHT,
                      C_W_BASE, C_W_GLASS, C_W_METAL, C_METAL_CONST, closure_row)

__all__ = ["DIFFUSE", "COAT", "METAL", "GLASS_R", "GLASS_T", "METAL_MS", "CLEARCOAT", "N_LOBES", "PATH_STOP", "PATH_DELTA", "PATH_GLOSSY",
           "bsdf_eval_pdf", "bsdf_eval", "bsdf_eval_lobes", "bsdf_eval_smooth", "bsdf_eval_plain", "bsdf_eval_plain_w", "needs_bsdf_call", "bsdf_sample", "bsdf_sample_lobe", "bsdf_sample_path", "bsdf_sample_cont", "bsdf_eval_cont", "bsdf_eval_split", "diffuse_albedo", "fresnel_dielectric",
           "fresnel_dielectric_fss", "coat_albedo", "glass_albedo", "glass_albedo_avg", "build_glass_table",
           "ggx_albedo", "ggx_albedo_avg", "ggx_albedo_tables", "eval_batch", "sample_batch", "albedo_batch",
           "denoising_features", "DENOISE_ALPHA"]

DIFFUSE, COAT, METAL, GLASS_R, GLASS_T, METAL_MS, CLEARCOAT = range(7)
N_LOBES = 7

_JIT = dict(cache=True, nogil=True, fastmath=False, error_model="numpy")
_EPS = 1e-9
_ETA1 = 1e-4                    # |ior - 1| below this: refraction is a delta even when rough (Cycles' rule)
_PI = math.pi
_INV_PI = 1.0 / math.pi
_N_MU = 32                      # table rows: cos(theta_o) midpoints (k + 0.5) / 32
_N_ALPHA = 32                   # table columns: alpha = k / 31 (np.linspace(0, 1, 32))
_ALPHA_STEP = 1.0 / 31.0        # np.linspace's step: grid point k is k * step (the last is 1.0)


# ----------------------------------------------------------------------------
# Vectors and frames
# ----------------------------------------------------------------------------
@njit(**_JIT)
def _normalized(v, floor):
    """v / max(|v|, floor) (a division, as numpy's ``v /= norm``)."""
    n = max(math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]), floor)
    return (v[0] / n, v[1] / n, v[2] / n)


@njit(**_JIT)
def _reflect(w, n):
    """2 (w . n) n - w."""
    d = 2.0 * dot(w, n)
    return (d * n[0] - w[0], d * n[1] - w[1], d * n[2] - w[2])


@njit(**_JIT)
def _to_frame(loc, t, b, n):
    """loc_x t + loc_y b + loc_z n."""
    return (loc[0] * t[0] + loc[1] * b[0] + loc[2] * n[0],
            loc[0] * t[1] + loc[1] * b[1] + loc[2] * n[1],
            loc[0] * t[2] + loc[1] * b[2] + loc[2] * n[2])


@njit(**_JIT)
def _oriented(wo, ns, ng):
    """Cycles' back-face flip: (s ns, s ng, entering = wo on ng's side), s = +1 when entering, else -1.

    Both normals turn by the same sign, as Cycles' ``sd->N`` and ``sd->Ng`` (geom/shader_data.h):
    the face (ng, the winding) alone decides front and back; a shading normal on the other side
    of its face (inward custom normals, smooth normals of a mesh with inconsistent winding) stays
    there, and the lobes below it give nothing, as in Cycles."""
    entering = dot(wo, ng) >= 0.0
    s = 1.0 if entering else -1.0
    return (ns[0] * s, ns[1] * s, ns[2] * s), (ng[0] * s, ng[1] * s, ng[2] * s), entering


def diffuse_side():
    """Documentation only: which side of a surface the DIFFUSE lobe lights.

    As Cycles' BSDFs (``bsdf_diffuse_eval``: max(N . wi, 0) / pi; its ``bump_shadowing_term``:
    "the BSDF evaluation functions allow for light leaking through the actual geometry and only
    check that the directions are in the correct hemisphere w.r.t. the shading normal"), the
    DIFFUSE lobe is evaluated wherever wi lies above the facing shading normal nsf, also where wi
    is below the face (ngf . wi < 0: the band of a smooth-shaded mesh next to its shadow
    terminator).  There the shadow ray decides: it leaves from below the face
    (``sampling.offset_origin``) and a closed mesh blocks it, unless the object's
    ``shadow_terminator_geometry_offset`` lifts its origin onto the smooth surface
    (``paths.terminator_origin``; docs/rendering.md, "Shadow terminator").  A Normal input's
    bumped normal is held back by ``bump_shadowing`` (wi on the other side of the smooth normal:
    0).  The glossy lobes keep the face's side (reflection above ngf, refraction below)."""


@njit(**_JIT)
def _valid_specular(ng, wi, n):
    """Cycles' ``ensure_valid_specular_reflection``: n (unit, facing) raised toward ng (facing wi,
    the direction toward the viewer) just enough that the mirror reflection of wi about it leaves
    at least min(0.9 wi.ng, 0.01) above the surface; n itself when it already does."""
    d = 2.0 * dot(n, wi)
    r = (d * n[0] - wi[0], d * n[1] - wi[1], d * n[2] - wi[2])
    iz = dot(wi, ng)
    threshold = min(0.9 * iz, 0.01)
    if dot(ng, r) >= threshold:
        return n
    c = dot(n, ng)
    x = (n[0] - c * ng[0], n[1] - c * ng[1], n[2] - c * ng[2])
    lx = math.sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2])
    if lx > 0.0:
        x = (x[0] / lx, x[1] / lx, x[2] / lx)
    else:
        x = n
    ix = dot(wi, x)
    a = ix * ix + iz * iz
    b = 2.0 * (a + iz * threshold)
    cc = (threshold + iz) * (threshold + iz)
    disc = math.sqrt(max(b * b - 4.0 * a * cc, 0.0))
    nz2 = 0.25 * (b + disc) / a if ix < 0 else 0.25 * (b - disc) / a
    nx = math.sqrt(max(1.0 - nz2, 0.0))
    nz = math.sqrt(max(nz2, 0.0))
    return (nx * x[0] + nz * ng[0], nx * x[1] + nz * ng[1], nx * x[2] + nz * ng[2])


# ----------------------------------------------------------------------------
# Fresnel
# ----------------------------------------------------------------------------
@njit(**_JIT)
def fresnel_dielectric(cos_i, eta):
    """Unpolarised dielectric reflectance F_diel for cos_i (clamped to [0, 1]) and eta = n_t / n_i; 1 under TIR."""
    cos_i = min(max(cos_i, 0.0), 1.0)
    sin2_t = (1.0 - cos_i * cos_i) / (eta * eta)
    if sin2_t >= 1.0:
        return 1.0
    cos_t = math.sqrt(max(0.0, 1.0 - sin2_t))
    r_s = (cos_i - eta * cos_t) / max(cos_i + eta * cos_t, 1e-300)
    r_p = (eta * cos_i - cos_t) / max(eta * cos_i + cos_t, 1e-300)
    return 0.5 * (r_s * r_s + r_p * r_p)


@njit(**_JIT)
def fresnel_dielectric_fss(eta):
    """Hemispherical average of the dielectric Fresnel reflectance, Cycles' polynomial fit
    (``fresnel_dielectric_Fss``)."""
    if eta < 1.0:
        return 0.997118 + eta * (0.1014 - eta * (0.965241 + eta * 0.130607))
    return (eta - 1.0) / (4.08567 + 1.00071 * eta)


@njit(**_JIT)
def _fresnel_schlick(C, cr, cos):
    """The METAL lobe's Fresnel, an RGB tuple: Schlick(F0 = base colour of closure row C[cr], cos) =
    F0 + (1 - F0)(1 - cos)^5 (a Principled BSDF's metal), or the base colour at every angle where
    ``C_METAL_CONST`` (a Glossy BSDF: Cycles 5.0 sets up no Fresnel for it, its colour weighs the lobe)."""
    b0, b1, b2 = C[cr, C_BASE], C[cr, C_BASE + 1], C[cr, C_BASE + 2]
    if C[cr, C_METAL_CONST] > 0:
        return (b0, b1, b2)
    m = math.pow(min(max(1.0 - cos, 0.0), 1.0), 5.0)       # (numpy's ** 5 is pow; x*x*x*x*x rounds differently)
    return (b0 + (1.0 - b0) * m, b1 + (1.0 - b1) * m, b2 + (1.0 - b2) * m)


# ----------------------------------------------------------------------------
# GGX
# ----------------------------------------------------------------------------
@njit(**_JIT)
def _ggx_D(cos_h, alpha):
    """GGX normal distribution D(h) per sr of microfacet normals (cos_h = h . n)."""
    if not cos_h > 0:
        return 0.0
    a2 = alpha * alpha
    c2 = cos_h * cos_h
    denom = c2 * (a2 - 1.0) + 1.0
    return a2 / max(_PI * denom * denom, 1e-300)


@njit(**_JIT)
def _ggx_lambda(cos, alpha):
    """Smith Lambda(w) for GGX: (sqrt(1 + alpha^2 tan^2) - 1) / 2."""
    c2 = max(cos * cos, 1e-300)
    tan2 = max(1.0 - c2, 0.0) / c2
    return 0.5 * (math.sqrt(1.0 + alpha * alpha * tan2) - 1.0)


@njit(**_JIT)
def _ggx_sample_vndf(wx, wy, wz, alpha, u0, u1):
    """Visible-normal sample h (local, unit) for the local view direction (wx, wy, wz), wz > 0 (Heitz 2018)."""
    # Stretch the view direction to the hemisphere configuration
    v0, v1, v2 = _normalized((alpha * wx, alpha * wy, wz), 0.0)
    lensq = v0 * v0 + v1 * v1
    if lensq > 0:
        inv = 1.0 / math.sqrt(max(lensq, 1e-300))
        T1 = (-v1 * inv, v0 * inv, 0.0)
    else:
        T1 = (1.0, 0.0, 0.0)
    T2 = (v1 * T1[2] - v2 * T1[1], v2 * T1[0] - v0 * T1[2], v0 * T1[1] - v1 * T1[0])
    # Sample the projected disk, warped toward the visible half
    r = math.sqrt(u0)
    phi = 2.0 * _PI * u1
    t1 = r * math.cos(phi)
    t2 = r * math.sin(phi)
    s = 0.5 * (1.0 + v2)
    t2 = (1.0 - s) * math.sqrt(max(0.0, 1.0 - t1 * t1)) + s * t2
    tz = math.sqrt(max(0.0, 1.0 - t1 * t1 - t2 * t2))
    n0 = t1 * T1[0] + t2 * T2[0] + tz * v0
    n1 = t1 * T1[1] + t2 * T2[1] + tz * v1
    n2 = t1 * T1[2] + t2 * T2[2] + tz * v2
    # Unstretch
    return _normalized((alpha * n0, alpha * n1, max(n2, 1e-12)), 0.0)


# ----------------------------------------------------------------------------
# GGX albedo tables (multiple-scattering energy compensation, Kulla & Conty 2017)
# ----------------------------------------------------------------------------
_MU = (np.arange(_N_MU) + 0.5) / _N_MU           # cos(theta_o) midpoints
_ALPHA = np.linspace(0.0, 1.0, _N_ALPHA)         # GGX alpha grid
_TABLES: tuple[np.ndarray, np.ndarray] | None = None
_TABLES_LOCK = threading.Lock()


@njit(**_JIT)
def _albedo_table_weights(mu, al, g, w):
    """Sample weights w (n_mu, n_alpha, K*K) of the albedo table: G2 / G1(wo) of the visible-normal
    sample (g[i], g[j]) for wo = (sqrt(1 - mu^2), 0, mu), 0 when the reflection leaves the hemisphere."""
    K = g.shape[0]
    for a in range(mu.shape[0]):
        m = mu[a]
        wx = math.sqrt(1.0 - m * m)
        for b in range(al.shape[0]):
            alpha = al[b]
            lam_o = _ggx_lambda(m, alpha)
            for i in range(K):
                for j in range(K):
                    h = _ggx_sample_vndf(wx, 0.0, m, alpha, g[i], g[j])
                    wi_z = 2.0 * (wx * h[0] + 0.0 * h[1] + m * h[2]) * h[2] - m
                    lam_i = _ggx_lambda(wi_z, alpha)
                    w[a, b, i * K + j] = (1.0 + lam_o) / (1.0 + lam_o + lam_i) if wi_z > 0 else 0.0


_N_Z = 32                       # coat-albedo slices: r = (ior - 1) / (ior + 1) = k / 31 * R_MAX
_R_MAX = 9.0 / 11.0             # ior 10, the closure's largest


@njit(**_JIT)
def _coat_table_weights(mu, al, g, gw, zs, w):
    """w (n_z, n_mu, n_alpha): the mean over the stratified visible-normal samples (g[i], g[j]),
    weighed gw[i] gw[j] (:func:`_graded_grid`), of G2 / G1(wo) F_diel(wo . h, ior) for
    wo = (sqrt(1 - mu^2), 0, mu), ior = (1 + r) / (1 - r) for the slices' r values zs."""
    K = g.shape[0]
    for c in range(zs.shape[0]):
        ior = (1.0 + zs[c]) / (1.0 - zs[c])
        for a in range(mu.shape[0]):
            m = mu[a]
            wx = math.sqrt(1.0 - m * m)
            for b in range(al.shape[0]):
                alpha = al[b]
                lam_o = _ggx_lambda(m, alpha)
                acc = 0.0
                for i in range(K):
                    for j in range(K):
                        h = _ggx_sample_vndf(wx, 0.0, m, alpha, g[i], g[j])
                        wo_h = wx * h[0] + m * h[2]
                        wi_z = 2.0 * wo_h * h[2] - m
                        if wi_z > 0:
                            lam_i = _ggx_lambda(wi_z, alpha)
                            acc += gw[i] * gw[j] * (1.0 + lam_o) / (1.0 + lam_o + lam_i) * fresnel_dielectric(
                                min(max(wo_h, 0.0), 1.0), ior)
                w[c, a, b] = acc / (K * K)


_N_GZ = 16                      # glass-albedo slices: z = sqrt((ior - 1) / (ior + 1)) = k / 15 * Z_MAX
_GZ_MAX = math.sqrt(_R_MAX)     # ior 10
_GLASS_E = 1 + _N_Z             # first glass slice of E: (side, k) at _GLASS_E + side * 16 + k
_GLASS_EAVG = _N_ALPHA          # first glass entry of E_avg: (side, k, j) at _GLASS_EAVG + (side * 16 + k) * 32 + j


@njit(**_JIT)
def _glass_table_weights(mu, rs, g, gw, zs, w):
    """w (2, n_z, n_mu, n_rough): the single-scattering albedo of rough GGX glass (reflection plus
    refraction through the visible-normal samples (g[i], g[j]), each weighed by its Fresnel share:
    F G2 / G1(wo) reflected when it leaves above, (1 - F) G2 / G1(wo) refracted when it goes below)
    for wo = (sqrt(1 - mu^2), 0, mu), alpha = max(rough^2, 1e-4), eta = ior (side 0, entering) or
    1 / ior (side 1, leaving), ior = (1 + z^2) / (1 - z^2) for the slices' z values zs.  z = 0 (ior 1)
    is 1, as Cycles' table (a refraction of eta 1 is singular there).  Sample (i, j) weighs
    gw[i] gw[j] (:func:`_graded_grid`)."""
    K = g.shape[0]
    for side in range(2):
        for c in range(zs.shape[0]):
            r2 = zs[c] * zs[c]
            ior = (1.0 + r2) / (1.0 - r2)
            eta = ior if side == 0 else 1.0 / ior
            for a in range(mu.shape[0]):
                m = mu[a]
                wx = math.sqrt(1.0 - m * m)
                for b in range(rs.shape[0]):
                    if not zs[c] > 0.0:
                        w[side, c, a, b] = 1.0
                        continue
                    alpha = max(rs[b] * rs[b], 1e-4)
                    lam_o = _ggx_lambda(m, alpha)
                    acc = 0.0
                    for i in range(K):
                        for j in range(K):
                            h = _ggx_sample_vndf(wx, 0.0, m, alpha, g[i], g[j])
                            wo_h = wx * h[0] + m * h[2]
                            F = fresnel_dielectric(min(max(wo_h, 0.0), 1.0), eta)
                            wr_z = 2.0 * wo_h * h[2] - m
                            q = gw[i] * gw[j]
                            if wr_z > 0:
                                acc += q * F * (1.0 + lam_o) / (1.0 + lam_o + _ggx_lambda(wr_z, alpha))
                            if F < 1.0:
                                cos_t = math.sqrt(max(0.0, 1.0 - (1.0 - wo_h * wo_h) / (eta * eta)))
                                wt_z = -m / eta + (wo_h / eta - cos_t) * h[2]
                                if wt_z < 0:
                                    acc += q * (1.0 - F) * (1.0 + lam_o) / (1.0 + lam_o + _ggx_lambda(wt_z, alpha))
                    w[side, c, a, b] = acc / (K * K)


def _graded_grid(K: int, p: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """(g, gw) (K,) float64: sample coordinates u = 1 - (1 - m)^p at the midpoints m = (i + 0.5) / K
    and their weights du/dm = p (1 - m)^(p - 1), so mean(gw f(g)) is the midpoint rule for int_0^1 f.

    The visible-normal samples' first coordinate u0 = r^2 reaches GGX's long tail (microfacets
    far from n, whose reflections leave the hemisphere) only as u0 -> 1; a uniform midpoint grid
    stops 1 / (2K) short of it and overestimates the albedo at small alpha (K = 24: +1.1 % at
    mu 0.89, alpha 0.097, against an h-space quadrature; +0.6 % at alpha 0.0645, mu 0.48).  The
    graded grid (K = 64, p = 3) agrees with that quadrature within 0.05 %.  Used for u1 too (any
    change of variables is exact)."""
    m = (np.arange(K) + 0.5) / K
    return 1.0 - (1.0 - m) ** p, p * (1.0 - m) ** (p - 1)


def ggx_albedo_tables() -> tuple[np.ndarray, np.ndarray]:
    """(E (65, 32, 32), E_avg (32 + 1024,)) float64 C-contiguous, built on first use and cached.

    E[0, i, j] = single-scattering GGX albedo (F = 1) at mu = (i + 0.5) / 32 and
    alpha = j / 31 (at least 1e-4): the mean of the visible-normal sample weight
    G2 / G1(wo) over a 64 x 64 graded grid (:func:`_graded_grid`), samples leaving the hemisphere
    counting 0; E_avg[j] = 2 int E(mu) mu dmu (midpoint rule).
    E[1 + k, i, j] = the albedo of a rough dielectric coat (specular 1) of ior (1 + r_k) / (1 - r_k),
    r_k = k / 31 * 9 / 11 (ior 1 .. 10; F0 = r^2): the same samples weighted by
    F_diel(wo . h, ior), times the coat's
    energy compensation ``_coat_compensation`` -- what the diffuse base under it loses
    (:func:`coat_albedo`).
    E[33 + 16 s + k, i, j] = the single-scattering albedo of rough GGX glass (reflection plus
    refraction, :func:`build_glass_table`) at mu_i, roughness j / 31 (not alpha: sqrt(alpha), as
    Cycles' ``ggx_glass_E``), z_k = k / 15 sqrt(9 / 11) = sqrt((ior - 1) / (ior + 1)), entering
    (s = 0, eta = ior) or leaving (s = 1, eta = 1 / ior); E_avg[32 + (16 s + k) 32 + j] its
    2 int E mu dmu (:func:`glass_albedo`, :func:`glass_albedo_avg`).
    """
    global _TABLES
    with _TABLES_LOCK:
        if _TABLES is None:
            K = 64
            g, gw = _graded_grid(K)
            al = np.maximum(_ALPHA, 1e-4)
            w = np.empty((_MU.size, _ALPHA.size, K * K))
            _albedo_table_weights(_MU, al, g, w)
            E0 = np.clip((w.reshape(_MU.size, _ALPHA.size, K, K) * gw[:, None] * gw[None, :]).mean(axis=(2, 3)),
                         0.0, 1.0)
            E_avg = np.ascontiguousarray(2.0 * np.mean(E0 * _MU[:, None], axis=0))
            EF = _load_coat_table()
            if EF is None:                      # (no shipped table: build it, about 5 s)
                EF = build_coat_table(E0, E_avg)
            EG = _load_glass_table()
            if EG is None:                      # (no shipped table: build it, a few s)
                EG = build_glass_table()
            E = np.ascontiguousarray(np.concatenate([E0[None], EF, EG.reshape(2 * _N_GZ, _N_MU, _N_ALPHA)]))
            EG_avg = 2.0 * np.mean(EG * _MU[None, None, :, None], axis=2)      # (2, n_z, n_rough)
            E_avg = np.ascontiguousarray(np.concatenate([E_avg, EG_avg.ravel()]))
            E.flags.writeable = False
            E_avg.flags.writeable = False
            _TABLES = (E, E_avg)
        return _TABLES


COAT_TABLE_FILE = Path(__file__).with_name("coat_albedo.npy")


def build_coat_table(E0: np.ndarray, E_avg: np.ndarray, slices=None) -> np.ndarray:
    """The rough-coat albedo slices (n_z, 32, 32) of :func:`ggx_albedo_tables` from E0 = E[0] and
    E_avg (slices: the k to build, default all 32; ~0.15 s each).  Written to COAT_TABLE_FILE by
    ``python -m stpm_core.kernels.bsdf``; tests check the file against this construction."""
    K = 48
    g, gw = _graded_grid(K)
    al = np.maximum(_ALPHA, 1e-4)
    ks = np.arange(_N_Z) if slices is None else np.asarray(slices, np.int64)
    zs = ks / (_N_Z - 1) * _R_MAX
    EF = np.empty((zs.size, _MU.size, _ALPHA.size))
    _coat_table_weights(_MU, al, g, gw, zs, EF)
    for c, r in enumerate(zs):
        ior = (1.0 + r) / (1.0 - r)
        for b in range(_ALPHA.size):
            for a in range(_MU.size):
                EF[c, a, b] *= _coat_compensation(E0[a, b], E_avg[b], fresnel_dielectric_fss(ior))
    return np.clip(EF, 0.0, 1.0)


def _load_table(path, shape: tuple):
    """A shipped float64 table of this shape, or None (missing, unreadable or another shape)."""
    try:
        T = np.load(path)
    except (OSError, ValueError):
        return None
    return T if T.shape == shape and T.dtype == np.float64 else None


def _load_coat_table():
    return _load_table(COAT_TABLE_FILE, (_N_Z, _N_MU, _N_ALPHA))


GLASS_TABLE_FILE = Path(__file__).with_name("glass_albedo.npy")


def build_glass_table(K: int = 128, slices=None) -> np.ndarray:
    """The rough-glass albedo (2, 16, 32, 32) of :func:`ggx_albedo_tables` (entering / leaving,
    z, mu, roughness): a K x K graded grid of visible-normal samples per cell (:func:`_graded_grid`)
    (``_glass_table_weights``), clipped to [0, 1] (slices: the z indices k to build, default all
    16; about 4 s each: the total internal reflection edge of the refraction needs K = 128 for
    1e-3).  Written to GLASS_TABLE_FILE by ``python -m stpm_core.kernels.bsdf``; tests check the
    file against this construction."""
    g, gw = _graded_grid(K)
    ks = np.arange(_N_GZ) if slices is None else np.asarray(slices, np.int64)
    zs = ks / (_N_GZ - 1) * _GZ_MAX
    w = np.empty((2, zs.size, _MU.size, _ALPHA.size))
    _glass_table_weights(_MU, _ALPHA, g, gw, zs, w)
    return np.clip(w, 0.0, 1.0)


def _load_glass_table():
    return _load_table(GLASS_TABLE_FILE, (2, _N_GZ, _N_MU, _N_ALPHA))


@njit(**_JIT)
def _coat_compensation(e_o, e_avg, f_ss):
    """Cycles' energy compensation of a rough dielectric layer (microfacet_ggx_preserve_energy):
    1 + F_ms (1 - E(mu_o)) / E(mu_o), F_ms = F_ss E_avg / (1 - F_ss (1 - E_avg))."""
    e_o = max(e_o, 1e-3)
    f_ms = f_ss * e_avg / (1.0 - f_ss * (1.0 - e_avg))
    return 1.0 + f_ms * (1.0 - e_o) / e_o


@njit(**JIT_INLINE)                  # called with a literal slice: one copy per caller, not per literal
def _bilinear(E, s, mu, alpha):
    """Slice s of E (n, 32, 32) at (mu, alpha): bilinear, clamped at the edges."""
    x = min(max(mu * 32 - 0.5, 0.0), 31 - 1e-9)
    y = min(max(alpha * 31, 0.0), 31 - 1e-9)
    i = min(int(x), 30)
    j = min(int(y), 30)
    fx = x - i
    fy = y - j
    return ((1 - fx) * (1 - fy) * E[s, i, j] + fx * (1 - fy) * E[s, i + 1, j]
            + (1 - fx) * fy * E[s, i, j + 1] + fx * fy * E[s, i + 1, j + 1])


@njit(**_JIT)
def ggx_albedo(E, mu, alpha):
    """E(mu, alpha): bilinear look-up in the table E[0] (32, 32), clamped at the edges."""
    return _bilinear(E, 0, mu, alpha)


@njit(**_JIT)
def coat_albedo(E, mu, alpha, ior):
    """Albedo at mu of a rough dielectric coat (specular 1, energy-compensated) of this ior: the
    slices E[1:] (:func:`ggx_albedo_tables`), bilinear in (mu, alpha), linear in r = (ior - 1) / (ior + 1)."""
    z = max(ior - 1.0, 0.0) / (ior + 1.0) / _R_MAX * (_N_Z - 1)
    z = min(max(z, 0.0), _N_Z - 1 - 1e-9)
    k = min(int(z), _N_Z - 2)
    fz = z - k
    return (1.0 - fz) * _bilinear(E, 1 + k, mu, alpha) + fz * _bilinear(E, 2 + k, mu, alpha)


@njit(**_JIT)
def _glass_z(eta):
    """(side, k, fz): the glass table's side (0: eta >= 1, 1: leaving) and slice position of eta."""
    side = 0 if eta >= 1.0 else 1
    ior = eta if eta >= 1.0 else 1.0 / eta
    z = math.sqrt(max(ior - 1.0, 0.0) / (ior + 1.0)) / _GZ_MAX * (_N_GZ - 1)
    z = min(max(z, 0.0), _N_GZ - 1 - 1e-9)
    k = min(int(z), _N_GZ - 2)
    return side, k, z - k


@njit(**_JIT)
def glass_albedo(E, mu, rough, eta):
    """Single-scattering albedo at mu of rough GGX glass (reflection + refraction, Fresnel of eta =
    n_t / n_i, roughness rough = sqrt(alpha)): the glass slices of E, bilinear in (mu, rough),
    linear in z = sqrt((ior - 1) / (ior + 1)), the leaving side's slices for eta < 1."""
    side, k, fz = _glass_z(eta)
    s = _GLASS_E + side * _N_GZ + k
    return (1.0 - fz) * _bilinear(E, s, mu, rough) + fz * _bilinear(E, s + 1, mu, rough)


@njit(**_JIT)
def glass_albedo_avg(E_avg, rough, eta):
    """2 int glass_albedo(mu) mu dmu at (rough, eta): linear in rough (grid k / 31) and in z."""
    side, k, fz = _glass_z(eta)
    y = min(max(rough * 31.0, 0.0), 31 - 1e-9)
    j = min(int(y), 30)
    fy = y - j
    o0 = _GLASS_EAVG + (side * _N_GZ + k) * _N_ALPHA + j
    o1 = o0 + _N_ALPHA
    return ((1.0 - fz) * ((1.0 - fy) * E_avg[o0] + fy * E_avg[o0 + 1])
            + fz * ((1.0 - fy) * E_avg[o1] + fy * E_avg[o1 + 1]))


@njit(**_JIT)
def _alpha_grid(k):
    return 1.0 if k == _N_ALPHA - 1 else k * _ALPHA_STEP


@njit(**_JIT)
def ggx_albedo_avg(E_avg, alpha):
    """E_avg(alpha): linear interpolation on the alpha grid k / 31 (``np.interp``'s formula, clamped)."""
    last = _N_ALPHA - 1
    if alpha <= 0.0:
        return E_avg[0]
    if alpha >= 1.0:
        return E_avg[last]
    j = min(int(alpha * 31.0), last - 1)
    while j > 0 and _alpha_grid(j) > alpha:
        j -= 1
    while j < last - 1 and _alpha_grid(j + 1) <= alpha:
        j += 1
    xj = _alpha_grid(j)
    if xj == alpha:
        return E_avg[j]
    slope = (E_avg[j + 1] - E_avg[j]) / (_alpha_grid(j + 1) - xj)
    return slope * (alpha - xj) + E_avg[j]


# ----------------------------------------------------------------------------
# The hit: oriented normals, Fresnel at wo, lobe selection probabilities
# ----------------------------------------------------------------------------
@njit(**_JIT)
def _hit(C, cr, E, E_avg, wo, ns, ng):
    """Everything about closure row C[cr] at wo that does not depend on wi.

    Returns (ns', ng', nss, cos_o = wo . nss (not clamped), eta_glass, alpha, F_coat, F_glass,
    F_metal (RGB), ms_scale (RGB) = k_metal, the rough metal's energy compensation per channel
    (1 when smooth), ms_Eo = E(mu_o), k_coat (the rough
    coat's energy compensation, 1 otherwise), p_lobe (6 lobes)).  nss: the normal of the specular
    lobes (coat, metal, glass): ns' raised so the mirror reflection of wo stays above the surface
    wherever it differs from ng' (smooth and custom normals; a Normal input, ``C_BUMPED``), as
    Cycles' ``maybe_ensure_valid_specular_reflection`` (``_valid_specular``; flat faces keep ns' =
    ng'); the diffuse lobes keep ns'.  Where wo is below nss (a shading normal facing away from
    the viewer, which raising does not fix: inward custom normals) the specular lobes get
    probability 0, as Cycles' microfacet closures sample and evaluate nothing for wo under N.
    """
    nsf, ngf, entering = _oriented(wo, ns, ng)
    if C[cr, C_BUMPED] > 0 or nsf[0] != ngf[0] or nsf[1] != ngf[1] or nsf[2] != ngf[2]:
        nss = _valid_specular(ngf, wo, nsf)
    else:
        nss = nsf
    alpha = max(C[cr, C_ALPHA], 1e-4)
    rough = C[cr, C_ROUGHNESS] > 0.0
    spec = C[cr, C_SPECULAR]
    w_base, w_metal, w_glass = C[cr, C_W_BASE], C[cr, C_W_METAL], C[cr, C_W_GLASS]
    ior = C[cr, C_IOR]
    eta_glass = ior if entering else 1.0 / ior          # n_t / n_i for glass
    cos_o = dot(wo, nss)
    cos_oc = min(max(cos_o, 0.0), 1.0)
    # Fresnel at wo for each lobe the closure has
    # the coat's albedo at wo: what the diffuse base under it loses (smooth: the Fresnel at wo;
    # rough: the tabulated rough-coat albedo, as Cycles' layering weight 1 - albedo)
    F_coat = 0.0
    if w_base > 0 and spec > 0:
        F_coat = spec * (coat_albedo(E, cos_oc, alpha, ior) if rough else fresnel_dielectric(cos_oc, ior))
    F_glass = fresnel_dielectric(cos_oc, eta_glass) if w_glass > 0 else 0.0
    F_metal = _fresnel_schlick(C, cr, cos_oc) if w_metal > 0 else (0.0, 0.0, 0.0)
    # Rough METAL: the energy single scattering loses, returned as Cycles does for Multiscatter
    # GGX (microfacet_ggx_preserve_energy): the GGX lobe times 1 + F_ms (1 - E(mu_o)) / E(mu_o) per
    # channel, F_ms = F_ss E_avg / (1 - F_ss (1 - E_avg)), F_ss = F0 + (1 - F0) / 21 (Schlick's
    # hemispherical average)
    ms_scale = (1.0, 1.0, 1.0)                          # k_metal, per channel
    ms_Eo = 1.0
    if w_metal > 0 and rough:
        e_avg = ggx_albedo_avg(E_avg, alpha)
        ms_Eo = ggx_albedo(E, cos_oc, alpha)
        b0, b1, b2 = C[cr, C_BASE], C[cr, C_BASE + 1], C[cr, C_BASE + 2]
        if C[cr, C_METAL_CONST] > 0:
            # a constant Fresnel (Glossy BSDF): F_ss is the colour itself (Cycles'
            # bsdf_microfacet_setup_fresnel_constant)
            ms_scale = (_coat_compensation(ms_Eo, e_avg, b0), _coat_compensation(ms_Eo, e_avg, b1),
                        _coat_compensation(ms_Eo, e_avg, b2))
        else:
            ms_scale = (_coat_compensation(ms_Eo, e_avg, b0 + (1.0 - b0) / 21.0),
                        _coat_compensation(ms_Eo, e_avg, b1 + (1.0 - b1) / 21.0),
                        _coat_compensation(ms_Eo, e_avg, b2 + (1.0 - b2) / 21.0))
    # Rough COAT: the energy single scattering loses, returned as Cycles does for its dielectric
    # layer (microfacet_ggx_preserve_energy): f_ss (1 + F_ms (1 - E(mu_o)) / E(mu_o)),
    # F_ms = F_ss E_avg / (1 - F_ss (1 - E_avg)), F_ss = specular Fss_diel(ior)
    k_coat = 1.0
    if F_coat > 0 and rough:
        k_coat = _coat_compensation(ggx_albedo(E, cos_oc, alpha), ggx_albedo_avg(E_avg, alpha),
                                    spec * fresnel_dielectric_fss(ior))
    # Rough glass: the energy single scattering loses, returned as Cycles does for its Multiscatter
    # GGX glass (microfacet_ggx_preserve_energy, the glass table): reflection and refraction times
    # 1 + F_ms (1 - E(mu_o)) / E(mu_o) per channel, E the glass albedo of this eta (side), F_ms
    # from F_ss = the transmission tint (1 / E(mu_o) for a white one)
    k_glass = (1.0, 1.0, 1.0)
    if w_glass > 0 and rough:
        rg = C[cr, C_ROUGHNESS]
        g_eo = glass_albedo(E, cos_oc, rg, eta_glass)
        g_avg = glass_albedo_avg(E_avg, rg, eta_glass)
        k_glass = (_coat_compensation(g_eo, g_avg, C[cr, C_TINT_T]),
                   _coat_compensation(g_eo, g_avg, C[cr, C_TINT_T + 1]),
                   _coat_compensation(g_eo, g_avg, C[cr, C_TINT_T + 2]))
    # Blender's Coat (CLEARCOAT): a GGX dielectric layer of weight cw over every other lobe, as
    # Cycles' Principled BSDF (svm/closure.h): its lobe cw F_diel(wo.h, coat ior) (rough: times the
    # energy compensation k_cc, F_ss = Fss_diel(coat ior), as the COAT lobe's), and what lies below
    # attenuated by att = (1 - F_cc) mix(1, coat_tint^(1 / cos_t), cw) per channel, F_cc = cw times
    # the layer's albedo at wo (:func:`coat_albedo`; smooth: F_diel(cos_c)), cos_t the cosine of wo
    # refracted into the layer (Beer's law through a layer of unit thickness).  Its normal ncs is
    # nss: Cycles' Coat Normal defaults to the Principled BSDF's N (its Normal input, if linked).
    cw = C[cr, C_CC_WEIGHT]
    ncs = nss
    cos_c = cos_o
    alpha_c = max(C[cr, C_CC_ALPHA], 1e-4)
    F_cc = 0.0
    k_cc = 1.0
    att = (1.0, 1.0, 1.0)
    if cw > 0.0:
        ncs, cos_c, F_cc, k_cc, att = _coat_layer(C, cr, E, E_avg, wo, nsf, ngf, nss, alpha_c)
    # Lobe selection probabilities proportional to an albedo estimate (the lower lobes' times the
    # coat layer's mean attenuation)
    m_att = (att[0] + att[1] + att[2]) / 3.0
    mean_base = (C[cr, C_BASE] + C[cr, C_BASE + 1] + C[cr, C_BASE + 2]) / 3.0
    e0 = w_base * (1.0 - F_coat) * mean_base * m_att                  # DIFFUSE
    e1 = w_base * F_coat * m_att                                      # COAT (F_coat: its albedo)
    e2 = w_metal * ((F_metal[0] * ms_scale[0] + F_metal[1] * ms_scale[1] + F_metal[2] * ms_scale[2]) / 3.0) * m_att
    mean_tint_r = (C[cr, C_TINT_R] + C[cr, C_TINT_R + 1] + C[cr, C_TINT_R + 2]) / 3.0
    e3 = w_glass * F_glass * mean_tint_r * m_att                      # GLASS_R
    mean_tint = (C[cr, C_TINT_T] + C[cr, C_TINT_T + 1] + C[cr, C_TINT_T + 2]) / 3.0
    e4 = w_glass * (1.0 - F_glass) * mean_tint * m_att                # GLASS_T
    e5 = 0.0                                                          # METAL_MS (no longer a lobe)
    e6 = F_cc if cos_c > 0.0 else 0.0                                 # CLEARCOAT (F_cc: its albedo)
    if not cos_o > 0.0:
        # wo below the specular normal: Cycles' microfacet closures give nothing (bsdf_microfacet_
        # sample / eval return at cos_NI <= 0); only the diffuse lobe is left
        e1 = e2 = e3 = e4 = 0.0
    total = e0 + e1 + e2 + e3 + e4 + e5 + e6
    if total > 0:
        t = max(total, 1e-300)
        p_lobe = (e0 / t, e1 / t, e2 / t, e3 / t, e4 / t, e5 / t, e6 / t)
    else:
        p_lobe = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    return (nsf, ngf, nss, cos_o, eta_glass, alpha, F_coat, F_glass, F_metal, ms_scale, ms_Eo, k_coat, k_glass, p_lobe,
            ncs, cos_c, alpha_c, F_cc, k_cc, att)


@njit(**_JIT)
def _coat_normal(C, cr, wo, nsf, ngf, nss):
    """The CLEARCOAT lobe's normal, as Cycles (svm/closure.h): a linked Coat Normal (``C_CC_HAS_N``:
    C_CC_N, the node's world normal, raised as nss is by ``_valid_specular``), else nss, the
    specular lobes' normal (Cycles' coat normal defaults to the Principled BSDF's N, its Normal
    input where one is linked)."""
    if not C[cr, C_CC_HAS_N] > 0:
        return nss
    return _valid_specular(ngf, wo, (C[cr, C_CC_N], C[cr, C_CC_N + 1], C[cr, C_CC_N + 2]))


@njit(**_JIT)
def _coat_attenuation(C, cr, cos_cc, F_cc):
    """(a0, a1, a2): what the coat layer leaves of the lobes below it at wo, (1 - F_cc) times
    mix(1, coat_tint^(1 / cos_t), cw) per channel; cos_cc = wo . ncs clamped to [0, 1], cos_t its
    refraction into the layer of ior C_CC_IOR (Cycles: the optical depth 1 / cos_t)."""
    cw = C[cr, C_CC_WEIGHT]
    layer = max(1.0 - F_cc, 0.0)
    t0, t1, t2 = C[cr, C_CC_TINT], C[cr, C_CC_TINT + 1], C[cr, C_CC_TINT + 2]
    if t0 == 1.0 and t1 == 1.0 and t2 == 1.0:
        return layer, layer, layer
    inv = 1.0 / C[cr, C_CC_IOR]
    cos_t = math.sqrt(max(1.0 - inv * inv * (1.0 - cos_cc * cos_cc), 0.0))
    depth = 1.0 / max(cos_t, 1e-6)
    return (layer * (1.0 + cw * (math.pow(t0, depth) - 1.0)), layer * (1.0 + cw * (math.pow(t1, depth) - 1.0)),
            layer * (1.0 + cw * (math.pow(t2, depth) - 1.0)))


@njit(**_JIT)
def _coat_layer(C, cr, E, E_avg, wo, nsf, ngf, nss, alpha_c):
    """(ncs, cos_c, F_cc, k_cc, att) of the CLEARCOAT layer (Coat Weight cw > 0) at wo: its normal,
    wo . ncs (not clamped), its albedo at wo times cw, its energy compensation (1 when smooth) and
    the attenuation of the lobes below (:func:`_coat_attenuation`)."""
    cw = C[cr, C_CC_WEIGHT]
    ior_c = C[cr, C_CC_IOR]
    ncs = _coat_normal(C, cr, wo, nsf, ngf, nss)
    cos_c = dot(wo, ncs)
    cos_cc = min(max(cos_c, 0.0), 1.0)
    k_cc = 1.0
    if C[cr, C_CC_ROUGH] > 0.0:
        F_cc = cw * coat_albedo(E, cos_cc, alpha_c, ior_c)
        k_cc = _coat_compensation(ggx_albedo(E, cos_cc, alpha_c), ggx_albedo_avg(E_avg, alpha_c),
                                  fresnel_dielectric_fss(ior_c))
    else:
        F_cc = cw * fresnel_dielectric(cos_cc, ior_c)
    return ncs, cos_c, F_cc, k_cc, _coat_attenuation(C, cr, cos_cc, F_cc)


# ----------------------------------------------------------------------------
# Evaluation: f and pdf of the non-delta lobes
# ----------------------------------------------------------------------------
@njit(**JIT_INLINE)
def bump_shadowing(C, cr, wi, nsf, ngf):
    """Cycles' bump shadowing term of diffuse lobes (kernel/closure/bsdf.h, ``bump_shadowing_term``;
    Conty Estevez et al. 2019) for a closure whose shading normal nsf (facing) replaced a smooth
    one Ns (``C_BUMPED``; 1 otherwise): 0 when wi and nsf lie on different sides of Ns; else,
    with cos_d = |Ns . nsf|, cos_i = |Ns . wi|, alpha^2 = clamp(tan^2(d) / 8, 0, 1), the GGX
    shadowing G1 = 1 / (1 + (sqrt(1 + alpha^2 tan^2(i)) - 1) / 2)."""
    if not C[cr, C_BUMPED] > 0:
        return 1.0
    s0, s1, s2 = C[cr, C_NS], C[cr, C_NS + 1], C[cr, C_NS + 2]
    t = 1.0 if s0 * ngf[0] + s1 * ngf[1] + s2 * ngf[2] >= 0.0 else -1.0       # Ns on the facing side
    s0, s1, s2 = t * s0, t * s1, t * s2
    cos_si = s0 * wi[0] + s1 * wi[1] + s2 * wi[2]
    cos_sn = s0 * nsf[0] + s1 * nsf[1] + s2 * nsf[2]
    if cos_si * cos_sn * dot(nsf, wi) < 0.0:
        return 0.0
    cos_i, cos_d = abs(cos_si), abs(cos_sn)
    if cos_d >= 1.0 or cos_i >= 1.0:
        return 1.0
    if cos_i < 1e-6:
        return 0.0
    a2 = min(max(0.125 * (1.0 / (cos_d * cos_d) - 1.0), 0.0), 1.0)
    lam = 0.5 * (math.sqrt(1.0 + a2 * (1.0 / (cos_i * cos_i) - 1.0)) - 1.0)
    return 1.0 / (1.0 + lam)


@njit(**_JIT)
def _diffuse_part(C, cr, hit, wi):
    """(f0, f1, f2, pdf) of the DIFFUSE lobe at wi for the hit of :func:`_hit`: base / pi under the
    coat's Fresnel at wo, wherever wi is above the shading normal (not the face:
    :func:`diffuse_side`), and its share of the mixture density."""
    ns, ng, nss, cos_o, eta_glass, alpha, F_coat, F_glass, F_metal, ms_scale, ms_Eo, k_coat, k_glass, p_lobe, ncs, cos_c, alpha_c, F_cc, k_cc, att = hit
    w_base = C[cr, C_W_BASE]
    b0, b1, b2 = C[cr, C_BASE], C[cr, C_BASE + 1], C[cr, C_BASE + 2]
    cos_i = dot(wi, ns)
    f0 = f1 = f2 = pdf = 0.0
    if cos_i > 0:
        d = w_base * (1.0 - F_coat) * bump_shadowing(C, cr, wi, ns, ng)
        f0 = d * b0 / _PI * att[0]                  # (att: what the coat layer above leaves)
        f1 = d * b1 / _PI * att[1]
        f2 = d * b2 / _PI * att[2]
        pdf = p_lobe[DIFFUSE] * cos_i / _PI
    return f0, f1, f2, pdf


@njit(**_JIT)
def _eval_pdf_hit(C, cr, E, hit, wo, wi):
    """(f0, f1, f2, pdf) of the non-delta lobes at wi for the hit of :func:`_hit`."""
    f0, f1, f2, pdf = _diffuse_part(C, cr, hit, wi)
    return _glossy_add(C, cr, E, hit, wo, wi, f0, f1, f2, pdf, 1.0)


@njit(**_JIT)
def _glossy_add(C, cr, E, hit, wo, wi, f0, f1, f2, pdf, coat_w):
    """(f0, f1, f2, pdf) plus f and the mixture pdf of the non-delta lobes other than DIFFUSE (rough
    COAT times coat_w (1 or 0), METAL, GLASS_R, GLASS_T and CLEARCOAT) at wi, for the hit of :func:`_hit`.

    CLEARCOAT (Coat Roughness > 0): cw F_diel(wo.h, coat ior) k_cc D G2 / (4 cos_c cos_i) about its
    normal ncs with alpha = Coat Roughness^2 (wi above ng and ncs); the lobes below it are times
    the layer's attenuation att (:func:`_hit`).  Reflection (wi above ng and nss): the GGX lobes about nss.  Refraction (wi below ng and nss):
    rough GLASS_T, Walter et al.'s BTDF as Cycles evaluates it (no 1 / eta^2 radiance scaling),
    h = -(wo + eta wi) turned toward nss.  The glass lobes pick reflection or refraction per
    microfacet h as Cycles: refraction with probability (1 - F) t / (F r + (1 - F) t), F =
    F_diel(wo.h, eta), r = mean(tint_r), t = mean(tint_t), inside their joint probability
    p_lobe[GLASS_R] + p_lobe[GLASS_T]."""
    ns, ng, nss, cos_o, eta_glass, alpha, F_coat, F_glass, F_metal, ms_scale, ms_Eo, k_coat, k_glass, p_lobe, ncs, cos_c, alpha_c, F_cc, k_cc, att = hit
    if not C[cr, C_ROUGH_LOBE] > 0:
        return f0, f1, f2, pdf
    if C[cr, C_CC_ROUGH] > 0.0 and cos_c > 0.0 and C[cr, C_CC_WEIGHT] > 0.0:
        # -- Rough CLEARCOAT, about its own normal ncs with its own alpha
        cos_ic = dot(wi, ncs)
        Nc = (C[cr, C_NS], C[cr, C_NS + 1], C[cr, C_NS + 2]) if C[cr, C_BUMPED] > 0 else ns
        bump_ok_c = not (dot(Nc, wi) * dot(Nc, ncs) * cos_ic < 0.0)   # (the bump shadowing, as below)
        if cos_ic > 0.0 and dot(wi, ng) > 0.0 and bump_ok_c:
            hc = _normalized((wo[0] + wi[0], wo[1] + wi[1], wo[2] + wi[2]), 1e-300)
            Dc = _ggx_D(dot(hc, ncs), alpha_c)
            lam_oc = _ggx_lambda(cos_c, alpha_c)
            G2c = 1.0 / (1.0 + lam_oc + _ggx_lambda(cos_ic, alpha_c))
            cos_ce = max(cos_c, _EPS)
            Fc = fresnel_dielectric(min(max(dot(wo, hc), 0.0), 1.0), C[cr, C_CC_IOR])
            sc = C[cr, C_CC_WEIGHT] * Fc * k_cc * Dc * G2c / max(4.0 * cos_ce * max(abs(dot(wi, ns)), _EPS), 1e-300)
            f0, f1, f2 = f0 + sc, f1 + sc, f2 + sc
            pdf = pdf + p_lobe[CLEARCOAT] * Dc / ((1.0 + lam_oc) * 4.0 * cos_ce)
    if not (cos_o > 0 and C[cr, C_ROUGHNESS] > 0.0):
        return f0, f1, f2, pdf                       # (the main lobes are deltas or see wo from below)
    w_base, w_metal, w_glass = C[cr, C_W_BASE], C[cr, C_W_METAL], C[cr, C_W_GLASS]
    cos_i = dot(wi, ns)
    side = dot(wi, ng)
    cos_is = dot(wi, nss)
    # Cycles' bump_shadowing_term for every closure whose normal is not the smooth one Ns (the
    # shading normal before a Normal input replaced it, else ns itself, off which nss may have
    # been raised): wi on the other side of Ns than nss says: no reflection, no refraction
    if C[cr, C_BUMPED] > 0:
        Ns = (C[cr, C_NS], C[cr, C_NS + 1], C[cr, C_NS + 2])
    else:
        Ns = ns
    bump_ok = not (dot(Ns, wi) * dot(Ns, nss) * cos_is < 0.0)
    cos_oe = max(cos_o, _EPS)
    lam_o = _ggx_lambda(cos_o, alpha)
    G1o = 1.0 / (1.0 + lam_o)
    p_glass = p_lobe[GLASS_R] + p_lobe[GLASS_T]
    r_mean = (C[cr, C_TINT_R] + C[cr, C_TINT_R + 1] + C[cr, C_TINT_R + 2]) / 3.0
    t_mean = (C[cr, C_TINT_T] + C[cr, C_TINT_T + 1] + C[cr, C_TINT_T + 2]) / 3.0
    if cos_is > 0 and side > 0:
        # -- GGX reflection terms (rough COAT / METAL / GLASS_R), about the specular normal nss; f
        # is divided by the |ns . wi| the integrator multiplies (so f |ns . wi| = D G2 F / (4 cos_o))
        hv = _normalized((wo[0] + wi[0], wo[1] + wi[1], wo[2] + wi[2]), 1e-300)
        cos_h = dot(hv, nss)
        wo_h = min(max(dot(wo, hv), 0.0), 1.0)
        D = _ggx_D(cos_h, alpha)
        lam_i = _ggx_lambda(cos_is, alpha)
        G2 = 1.0 / (1.0 + lam_o + lam_i)
        p_ggx = G1o * D / (4.0 * cos_oe)                 # VNDF pdf of wi (solid angle)
        spec = D * G2 / max(4.0 * cos_oe * max(abs(cos_i), _EPS), 1e-300)
        if not bump_ok:
            spec = 0.0
        # COAT: specular F_diel(wo.h, ior); METAL: Schlick(base, wo.h); GLASS_R: F_diel(wo.h, eta) tint_r
        F_c = C[cr, C_SPECULAR] * fresnel_dielectric(wo_h, C[cr, C_IOR])
        F_m = _fresnel_schlick(C, cr, wo_h)
        F_g = fresnel_dielectric(wo_h, eta_glass)
        s = w_base * F_c * k_coat * coat_w * spec
        sg = w_glass * F_g * spec
        sm = w_metal * spec
        f0 = f0 + att[0] * (s + sg * C[cr, C_TINT_R] * k_glass[0] + sm * F_m[0] * ms_scale[0])
        f1 = f1 + att[1] * (s + sg * C[cr, C_TINT_R + 1] * k_glass[1] + sm * F_m[1] * ms_scale[1])
        f2 = f2 + att[2] * (s + sg * C[cr, C_TINT_R + 2] * k_glass[2] + sm * F_m[2] * ms_scale[2])
        rt = F_g * r_mean + (1.0 - F_g) * t_mean
        split_r = F_g * r_mean / rt if rt > 0 else 0.0
        pdf = pdf + p_ggx * (p_lobe[COAT] * coat_w + p_lobe[METAL] + p_glass * split_r)
    elif cos_is < 0 and side < 0 and w_glass > 0 and abs(C[cr, C_IOR] - 1.0) >= _ETA1:
        # -- Rough GLASS_T: f |ns . wi| = (1 - F) tint D G2 |wo.h| |wi.h| eta^2 / (cos_o (wo.h + eta wi.h)^2)
        eta = eta_glass
        ht = _normalized((-(wo[0] + eta * wi[0]), -(wo[1] + eta * wi[1]), -(wo[2] + eta * wi[2])), 1e-300)
        if dot(ht, nss) < 0.0:
            ht = (-ht[0], -ht[1], -ht[2])
        wo_h = dot(wo, ht)
        wi_h = dot(wi, ht)
        if not (wo_h > 0 and wi_h < 0 and bump_ok):
            return f0, f1, f2, pdf
        D = _ggx_D(dot(ht, nss), alpha)
        lam_i = _ggx_lambda(cos_is, alpha)
        G2 = 1.0 / (1.0 + lam_o + lam_i)
        F_g = fresnel_dielectric(min(wo_h, 1.0), eta)
        den = wo_h + eta * wi_h
        jac = eta * eta * (-wi_h) / max(den * den, 1e-300)      # d omega_h / d omega_i
        common = D * wo_h * jac / cos_oe                       # VNDF pdf of wi / G1(wo)
        st = w_glass * (1.0 - F_g) * G2 * common / max(abs(cos_i), _EPS)
        f0 = f0 + st * C[cr, C_TINT_T] * k_glass[0] * att[0]
        f1 = f1 + st * C[cr, C_TINT_T + 1] * k_glass[1] * att[1]
        f2 = f2 + st * C[cr, C_TINT_T + 2] * k_glass[2] * att[2]
        rt = F_g * r_mean + (1.0 - F_g) * t_mean
        split_t = (1.0 - F_g) * t_mean / rt if rt > 0 else 0.0
        pdf = pdf + p_glass * split_t * G1o * common
    return f0, f1, f2, pdf


@njit(**_JIT)
def bsdf_eval_pdf(C, cr, E, E_avg, wo, wi, ns, ng):
    """(f0, f1, f2, pdf): f (1/sr) of the non-delta lobes of closure row C[cr] at (wo, wi) and the
    mixture solid-angle pdf with which :func:`bsdf_sample` returns wi through them."""
    return _eval_pdf_hit(C, cr, E, _hit(C, cr, E, E_avg, wo, ns, ng), wo, wi)


@njit(**_JIT)
def _glass_reflection(C, cr, hit, wo, wi):
    """(f0, f1, f2): the rough GLASS_R term of :func:`_glossy_add` alone at wi (0 unless wi is on the
    reflection side), for the hit of :func:`_hit`."""
    ns, ng, nss, cos_o, eta_glass, alpha, F_coat, F_glass, F_metal, ms_scale, ms_Eo, k_coat, k_glass, p_lobe, ncs, cos_c, alpha_c, F_cc, k_cc, att = hit
    w_glass = C[cr, C_W_GLASS]
    cos_is = dot(wi, nss)
    if not (C[cr, C_ROUGHNESS] > 0 and cos_o > 0 and w_glass > 0 and cos_is > 0 and dot(wi, ng) > 0):
        return 0.0, 0.0, 0.0
    Ns = (C[cr, C_NS], C[cr, C_NS + 1], C[cr, C_NS + 2]) if C[cr, C_BUMPED] > 0 else ns
    if dot(Ns, wi) * dot(Ns, nss) * cos_is < 0.0:
        return 0.0, 0.0, 0.0
    cos_oe = max(cos_o, _EPS)
    hv = _normalized((wo[0] + wi[0], wo[1] + wi[1], wo[2] + wi[2]), 1e-300)
    wo_h = min(max(dot(wo, hv), 0.0), 1.0)
    D = _ggx_D(dot(hv, nss), alpha)
    G2 = 1.0 / (1.0 + _ggx_lambda(cos_o, alpha) + _ggx_lambda(cos_is, alpha))
    sg = w_glass * fresnel_dielectric(wo_h, eta_glass) * D * G2 / max(4.0 * cos_oe * max(abs(dot(wi, ns)), _EPS),
                                                                       1e-300)
    return (sg * C[cr, C_TINT_R] * k_glass[0] * att[0], sg * C[cr, C_TINT_R + 1] * k_glass[1] * att[1],
            sg * C[cr, C_TINT_R + 2] * k_glass[2] * att[2])


@njit(**_JIT)
def bsdf_eval_lobes(C, cr, E, E_avg, wo, wi, ns, ng, vis):
    """(f0, f1, f2): :func:`bsdf_eval_pdf`'s f restricted to the closures a light is visible to
    (Blender's Object > Visibility > Ray Visibility of the light; Cycles' ``SHADER_EXCLUDE_*``
    leaves a hidden kind's closures out of a light sample's BSDF).  vis bits: 1 diffuse (the
    DIFFUSE lobe), 2 glossy (the rough COAT and METAL lobes), 4 transmission.  The glass lobes
    (GLASS_R and GLASS_T: one glass closure in Cycles, a Glass BSDF's or a Principled BSDF's
    transmission) are left out only when both glossy and transmission are hidden, as Cycles 5.0
    renders it (measured: a rough glass pane lit from behind keeps its light with either off)."""
    hit = _hit(C, cr, E, E_avg, wo, ns, ng)
    f0, f1, f2, _ = _eval_pdf_hit(C, cr, E, hit, wo, wi)
    d0 = d1 = d2 = 0.0
    if dot(wi, hit[0]) > 0:
        d = C[cr, C_W_BASE] * (1.0 - hit[6]) * bump_shadowing(C, cr, wi, hit[0], hit[1]) / _PI
        at = hit[19]                                 # (what the coat layer leaves)
        d0, d1, d2 = d * C[cr, C_BASE] * at[0], d * C[cr, C_BASE + 1] * at[1], d * C[cr, C_BASE + 2] * at[2]
    if dot(wi, hit[1]) > 0:                      # reflection: coat + metal + glass reflection
        g0, g1, g2 = _glass_reflection(C, cr, hit, wo, wi)
    else:                                        # refraction: the glass lobe alone
        g0, g1, g2 = f0 - d0, f1 - d1, f2 - d2
    kd = 1.0 if vis & 1 else 0.0
    ks = 1.0 if vis & 2 else 0.0
    kg = 1.0 if vis & 6 else 0.0
    return (kd * d0 + ks * (f0 - d0 - g0) + kg * g0, kd * d1 + ks * (f1 - d1 - g1) + kg * g1,
            kd * d2 + ks * (f2 - d2 - g2) + kg * g2)


@njit(**_JIT)
def bsdf_eval(C, cr, E, E_avg, wo, wi, ns, ng):
    """(f0, f1, f2): f (1/sr) of the non-delta lobes: :func:`bsdf_eval_pdf` where the closure has a
    rough lobe, else :func:`bsdf_eval_smooth`."""
    if C[cr, C_ROUGH_LOBE] > 0:
        f0, f1, f2, _ = bsdf_eval_pdf(C, cr, E, E_avg, wo, wi, ns, ng)
        return f0, f1, f2
    return bsdf_eval_smooth(C, cr, wo, wi, ns, ng)


@njit(**_JIT)
def needs_bsdf_call(C, cr):
    """Does evaluating closure row C[cr] need more than :func:`bsdf_eval_plain` (a rough lobe, a
    coat, a coat layer (CLEARCOAT) or a replaced normal)?"""
    return C[cr, C_ROUGH_LOBE] > 0 or C[cr, C_COAT] > 0 or C[cr, C_BUMPED] > 0 or C[cr, C_CC_WEIGHT] > 0


@njit(**_JIT)
def bsdf_eval_plain(C, cr, wo, wi, ns, ng):
    """(f0, f1, f2) of a closure that is a bare diffuse lobe (no rough lobe, no coat, no replaced
    normal: ``not needs_bsdf_call(C, cr)``): w_base base_color / pi where wi lies above the facing
    shading normal, else 0 (:func:`diffuse_side`).  :func:`bsdf_eval_smooth` of such a closure, bit
    for bit; small enough that LLVM inlines it, so a loop calling it contains no call (a call
    makes the loop save and reload its floating-point values around it, on every row)."""
    return bsdf_eval_plain_w(C[cr, C_W_BASE], C[cr, C_BASE], C[cr, C_BASE + 1], C[cr, C_BASE + 2], wo, wi, ns, ng)


@njit(**_JIT)
def bsdf_eval_plain_w(w_base, b0, b1, b2, wo, wi, ns, ng):
    """:func:`bsdf_eval_plain` of a closure whose C_W_BASE is w_base and base colour (b0, b1, b2),
    read from the row earlier (``paths.nee_light`` reads each row once)."""
    nsf, ngf, _ = _oriented(wo, ns, ng)
    scale = 0.0
    if dot(wi, nsf) > 0:             # (not ngf: the shadow ray decides, :func:`diffuse_side`)
        scale = w_base
    return (scale * b0 * _INV_PI, scale * b1 * _INV_PI, scale * b2 * _INV_PI)


@njit(**_JIT)
def bsdf_eval_smooth(C, cr, wo, wi, ns, ng):
    """(f0, f1, f2) of a closure without a rough lobe (``C[cr, C_ROUGH_LOBE] == 0``): the diffuse
    lobe w_base (1 - F_coat(wo)) base_color / pi directly (no hit set-up, no call to the compiled
    rough-lobe code).  The coat's Fresnel is taken at its own normal, as :func:`_hit` does (ns
    raised where it differs from ng); without coat or replaced normal it is :func:`bsdf_eval_plain`.
    A (smooth) coat layer (CLEARCOAT) above attenuates it by ``_coat_attenuation``."""
    if not (C[cr, C_COAT] > 0 or C[cr, C_BUMPED] > 0 or C[cr, C_CC_WEIGHT] > 0):
        return bsdf_eval_plain(C, cr, wo, wi, ns, ng)
    nsf, ngf, _ = _oriented(wo, ns, ng)
    scale = 0.0
    a0 = a1 = a2 = 1.0
    if dot(wi, nsf) > 0:             # (not ngf: the shadow ray decides, :func:`diffuse_side`)
        scale = C[cr, C_W_BASE] * bump_shadowing(C, cr, wi, nsf, ngf)
        nc = nsf
        if C[cr, C_BUMPED] > 0 or nsf[0] != ngf[0] or nsf[1] != ngf[1] or nsf[2] != ngf[2]:
            nc = _valid_specular(ngf, wo, nsf)
        if C[cr, C_COAT] > 0:
            cos_o = min(max(dot(wo, nc), 0.0), 1.0)
            scale *= 1.0 - C[cr, C_SPECULAR] * fresnel_dielectric(cos_o, C[cr, C_IOR])
        if C[cr, C_CC_WEIGHT] > 0:
            ncs = _coat_normal(C, cr, wo, nsf, ngf, nc)
            cos_cc = min(max(dot(wo, ncs), 0.0), 1.0)
            a0, a1, a2 = _coat_attenuation(C, cr, cos_cc,
                                           C[cr, C_CC_WEIGHT] * fresnel_dielectric(cos_cc, C[cr, C_CC_IOR]))
    return (scale * C[cr, C_BASE] * _INV_PI * a0, scale * C[cr, C_BASE + 1] * _INV_PI * a1,
            scale * C[cr, C_BASE + 2] * _INV_PI * a2)


# ----------------------------------------------------------------------------
# Sampling
# ----------------------------------------------------------------------------
@njit(**_JIT)
def _sample_lobe(C, cr, hit, wo, u0, u1, u2):
    """(lobe, p_chosen, is_delta, wi, u_res) for the hit of :func:`_hit`: u0 picks the lobe by the CDF
    of p_lobe, u1, u2 the direction (unit wi); p_chosen = 0 when the lobe has probability 0 (wi = 0).
    u_res: where u0 fell inside the chosen lobe's interval (and, rough glass, inside its reflect /
    refract choice), rescaled to [0, 1): a uniform independent of the choice and of wi (Cycles
    rescales its closure-pick uniform the same way), which :func:`bsdf_sample_cont` spends on
    Russian roulette."""
    nsf, ngf, nss, cos_o, eta_glass, alpha, F_coat, F_glass, F_metal, ms_scale, ms_Eo, k_coat, k_glass, p_lobe, ncs, cos_c, alpha_c, F_cc, k_cc, att = hit
    rough = C[cr, C_ROUGHNESS] > 0.0
    # -- Choose a lobe by the CDF of p_lobe
    lobe = 0                                            # number of CDF entries <= u0
    cdf = 0.0
    for k in range(N_LOBES):
        cdf += p_lobe[k]
        if u0 >= cdf:
            lobe += 1
    lobe = min(lobe, CLEARCOAT)
    p_chosen = p_lobe[lobe]
    if not p_chosen > 0:
        return lobe, 0.0, False, (0.0, 0.0, 0.0), 0.0
    lo = 0.0                                            # the chosen lobe's interval starts here
    for k in range(lobe):
        lo += p_lobe[k]
    u_res = min(max((u0 - lo) / p_chosen, 0.0), 0.9999999999999999)
    is_refl = lobe == COAT or lobe == METAL or lobe == GLASS_R
    grough = rough and abs(C[cr, C_IOR] - 1.0) >= _ETA1   # rough refraction (ior 1: a delta, as Cycles)
    is_delta = (lobe == GLASS_T and not grough) or (is_refl and not rough)
    # -- Direction
    if lobe == CLEARCOAT:
        # the coat layer: a GGX visible normal about its own normal ncs (its own alpha), or its mirror
        if C[cr, C_CC_ROUGH] > 0.0:
            t, b = basis(ncs)
            lx, ly, lz = _normalized((dot(wo, t), dot(wo, b), max(cos_c, 1e-6)), 0.0)
            hw = _to_frame(_ggx_sample_vndf(lx, ly, lz, alpha_c, u1, u2), t, b, ncs)
            return lobe, p_chosen, False, _normalized(_reflect(wo, hw), 1e-300), u_res
        return lobe, p_chosen, True, _normalized(_reflect(wo, ncs), 1e-300), u_res
    if (lobe == GLASS_R or lobe == GLASS_T) and grough:
        # Rough glass: a GGX visible normal about nss, then reflect or refract through it, the
        # choice per microfacet as Cycles (F mean(tint_r), F = F_diel(wo.h, eta), against
        # (1 - F) mean(tint_t)), by where u0 fell inside the two glass lobes' joint probability
        p_glass = p_lobe[GLASS_R] + p_lobe[GLASS_T]
        t, b = basis(nss)
        lx, ly, lz = _normalized((dot(wo, t), dot(wo, b), max(cos_o, 1e-6)), 0.0)
        hw = _to_frame(_ggx_sample_vndf(lx, ly, lz, alpha, u1, u2), t, b, nss)
        wo_h = min(max(dot(wo, hw), 0.0), 1.0)
        F_g = fresnel_dielectric(wo_h, eta_glass)
        r_mean = (C[cr, C_TINT_R] + C[cr, C_TINT_R + 1] + C[cr, C_TINT_R + 2]) / 3.0
        t_mean = (C[cr, C_TINT_T] + C[cr, C_TINT_T + 1] + C[cr, C_TINT_T + 2]) / 3.0
        rt = F_g * r_mean + (1.0 - F_g) * t_mean
        if not rt > 0:
            return lobe, 0.0, False, (0.0, 0.0, 0.0), 0.0
        us = min(max((u0 - (p_lobe[DIFFUSE] + p_lobe[COAT] + p_lobe[METAL])) / p_glass, 0.0), 1.0)
        split = F_g * r_mean / rt
        if us < split:
            lobe = GLASS_R
            u_res = min(us / split, 0.9999999999999999)
            wi = _reflect(wo, hw)
        else:
            u_res = min(max((us - split) / (1.0 - split), 0.0), 0.9999999999999999)
            lobe = GLASS_T
            eta = eta_glass
            cos_t = math.sqrt(max(0.0, 1.0 - (1.0 - wo_h * wo_h) / (eta * eta)))
            k = wo_h / eta - cos_t
            wi = (-wo[0] / eta + k * hw[0], -wo[1] / eta + k * hw[1], -wo[2] / eta + k * hw[2])
        return lobe, p_glass, False, _normalized(wi, 1e-300), u_res
    if lobe == DIFFUSE or lobe == METAL_MS:
        # Cosine hemisphere about ns
        t, b = basis(nsf)
        wi = _to_frame(cosine_hemisphere(u1, u2), t, b, nsf)
    elif is_refl and rough:
        # GGX visible normal about the specular normal, then mirror about it
        t, b = basis(nss)
        lx, ly, lz = _normalized((dot(wo, t), dot(wo, b), max(cos_o, 1e-6)), 0.0)
        hw = _to_frame(_ggx_sample_vndf(lx, ly, lz, alpha, u1, u2), t, b, nss)
        wi = _reflect(wo, hw)
    elif is_refl:
        # Smooth reflection: mirror about the specular normal
        wi = _reflect(wo, nss)
    else:
        # GLASS_T: refraction through ns (entering: eta = ior; leaving: 1 / ior)
        eta = eta_glass
        co = min(max(cos_o, 0.0), 1.0)
        cos_t = math.sqrt(max(0.0, 1.0 - (1.0 - co * co) / (eta * eta)))
        k = co / eta - cos_t
        wi = (-wo[0] / eta + k * nss[0], -wo[1] / eta + k * nss[1], -wo[2] / eta + k * nss[2])
    return lobe, p_chosen, is_delta, _normalized(wi, 1e-300), u_res


@njit(**_JIT)
def _on_lobe_side(lobe, side):
    """True when side = wi . ng' is where lobe sends light: below ng' for GLASS_T, above otherwise."""
    return side < 0.0 if lobe == GLASS_T else side > 0.0


@njit(**_JIT)
def _delta_weight(C, cr, hit, lobe, p_chosen, wi):
    """Throughput / p_chosen (3-tuple) of delta lobe ``lobe`` toward wi; 0 if a reflection lands
    below ng or a refraction above it (a leak through the shading normal)."""
    nsf, ngf, nss, cos_o, eta_glass, alpha, F_coat, F_glass, F_metal, ms_scale, ms_Eo, k_coat, k_glass, p_lobe, ncs, cos_c, alpha_c, F_cc, k_cc, att = hit
    side = dot(wi, ngf)
    if not (side < 0 if lobe == GLASS_T else side > 0):
        return 0.0, 0.0, 0.0
    if lobe == CLEARCOAT:
        return F_cc / p_chosen, F_cc / p_chosen, F_cc / p_chosen          # cw F_diel(cos_c, coat ior)
    if lobe == COAT:
        thr = C[cr, C_W_BASE] * F_coat
        t0 = t1 = t2 = thr
    elif lobe == METAL:
        w_metal = C[cr, C_W_METAL]
        t0, t1, t2 = w_metal * F_metal[0], w_metal * F_metal[1], w_metal * F_metal[2]
    elif lobe == GLASS_R:
        thr = C[cr, C_W_GLASS] * F_glass
        t0, t1, t2 = thr * C[cr, C_TINT_R], thr * C[cr, C_TINT_R + 1], thr * C[cr, C_TINT_R + 2]
    else:
        thr = C[cr, C_W_GLASS] * (1.0 - F_glass)
        t0, t1, t2 = thr * C[cr, C_TINT_T], thr * C[cr, C_TINT_T + 1], thr * C[cr, C_TINT_T + 2]
    return t0 * att[0] / p_chosen, t1 * att[1] / p_chosen, t2 * att[2] / p_chosen     # (under the coat layer)


@njit(**_JIT)
def bsdf_sample_lobe(C, cr, E, E_avg, wo, ns, ng, u0, u1, u2):
    """(wi0, wi1, wi2, w0, w1, w2, lobe): :func:`bsdf_sample` with the lobe chosen (-1: none)."""
    hit = _hit(C, cr, E, E_avg, wo, ns, ng)
    lobe, p_chosen, is_delta, wi, _ = _sample_lobe(C, cr, hit, wo, u0, u1, u2)
    if not p_chosen > 0:
        return 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, -1
    wi0, wi1, wi2 = wi
    if is_delta:
        t0, t1, t2 = _delta_weight(C, cr, hit, lobe, p_chosen, wi)
        return wi0, wi1, wi2, t0, t1, t2, lobe
    # -- Non-delta lobes: mixture f cos / pdf over every non-delta lobe; a sample of a reflection
    # lobe below ng or a refraction above it is 0 (as Cycles' sampling: the mixture pdf on each
    # side counts only the lobes meant for it)
    if not _on_lobe_side(lobe, dot(wi, hit[1])):
        return wi0, wi1, wi2, 0.0, 0.0, 0.0, lobe
    f0, f1, f2, pdf = _eval_pdf_hit(C, cr, E, hit, wo, wi)
    if not pdf > 0:
        return wi0, wi1, wi2, 0.0, 0.0, 0.0, lobe
    r = abs(dot(wi, hit[0])) / max(pdf, 1e-300)
    return wi0, wi1, wi2, f0 * r, f1 * r, f2 * r, lobe


@njit(**_JIT)
def bsdf_sample(C, cr, E, E_avg, wo, ns, ng, u0, u1, u2):
    """(wi0, wi1, wi2, w0, w1, w2, is_delta): wi from closure row C[cr] at wo.

    u0 picks the lobe by the CDF of p_lobe (and so reflect / refract for
    glass), u1, u2 the direction.  Weight: throughput / p_lobe for a delta
    lobe (0 if a reflection lands below ng or a refraction above it), else
    f_nd |cos| / pdf_nd over all non-delta lobes; wi = 0 and weight 0 when the
    chosen lobe has probability 0.
    """
    wi0, wi1, wi2, w0, w1, w2, lobe = bsdf_sample_lobe(C, cr, E, E_avg, wo, ns, ng, u0, u1, u2)
    return wi0, wi1, wi2, w0, w1, w2, lobe_is_delta(C, cr, lobe)


@njit(**_JIT)
def lobe_is_delta(C, cr, lobe):
    """Is ``lobe`` of closure row C[cr] a delta (smooth reflection / refraction; ior-1 glass refracts
    as a delta even when rough; CLEARCOAT by its own Coat Roughness)?"""
    if lobe == CLEARCOAT:
        return not C[cr, C_CC_ROUGH] > 0.0
    rough = C[cr, C_ROUGHNESS] > 0.0
    grough = rough and abs(C[cr, C_IOR] - 1.0) >= _ETA1
    return (lobe == GLASS_T and not grough) or ((lobe == COAT or lobe == METAL or lobe == GLASS_R) and not rough)


#: what :func:`bsdf_sample_path` chose: nothing / the DIFFUSE lobe (the path stops), a delta lobe,
#: a rough lobe other than DIFFUSE
PATH_STOP, PATH_DELTA, PATH_GLOSSY = 0, 1, 2


@njit(**_JIT)
def bsdf_sample_path(C, cr, E, E_avg, wo, ns, ng, u0, u1, u2, stop_coat):
    """(wi0, wi1, wi2, w0, w1, w2, kind, pdf): how a photon path continues from closure row C[cr]
    at wo when the photon maps carry the light its DIFFUSE lobe reflects (docs/photon-mapping.md;
    camera paths: :func:`bsdf_sample_cont`).

    The lobe and direction as :func:`bsdf_sample` (the same u0, u1, u2 give the same wi).  kind
    ``PATH_STOP``: the DIFFUSE lobe was chosen (with stop_coat also a rough COAT), or nothing
    (weight 0, pdf 0); ``PATH_DELTA``: a delta lobe, weight throughput / p_lobe as
    :func:`bsdf_sample` (pdf inf); ``PATH_GLOSSY``: another rough lobe, weight f_g |cos| / pdf_g,
    f_g and pdf_g = sum_j p_j pdf_j(wi) over the rough lobes that do not stop
    (:func:`bsdf_eval_cont`), so that E[weight L] over the non-stopping choices is the integral
    of f_g L cos: with what the stopping lobes' estimators carry, nothing is counted twice.
    """
    hit = _hit(C, cr, E, E_avg, wo, ns, ng)
    lobe, p_chosen, is_delta, wi, _ = _sample_lobe(C, cr, hit, wo, u0, u1, u2)
    wi0, wi1, wi2 = wi
    if not p_chosen > 0 or lobe == DIFFUSE:
        return wi0, wi1, wi2, 0.0, 0.0, 0.0, PATH_STOP, 0.0
    if is_delta:
        t0, t1, t2 = _delta_weight(C, cr, hit, lobe, p_chosen, wi)
        return wi0, wi1, wi2, t0, t1, t2, PATH_DELTA, np.inf
    if stop_coat and lobe == COAT:
        return wi0, wi1, wi2, 0.0, 0.0, 0.0, PATH_STOP, 0.0
    if not _on_lobe_side(lobe, dot(wi, hit[1])):
        return wi0, wi1, wi2, 0.0, 0.0, 0.0, PATH_GLOSSY, 0.0
    f0, f1, f2, pdf = _glossy_add(C, cr, E, hit, wo, wi, 0.0, 0.0, 0.0, 0.0, 0.0 if stop_coat else 1.0)
    if not pdf > 0:
        return wi0, wi1, wi2, 0.0, 0.0, 0.0, PATH_GLOSSY, 0.0
    r = abs(dot(wi, hit[0])) / max(pdf, 1e-300)
    return wi0, wi1, wi2, f0 * r, f1 * r, f2 * r, PATH_GLOSSY, pdf


@njit(**_JIT)
def bsdf_sample_cont(C, cr, E, E_avg, wo, ns, ng, u0, u1, u2, stop_coat):
    """(wi0, wi1, wi2, w0, w1, w2, kind, pdf, u_rr): how a camera path goes on from closure row C[cr]
    at wo (docs/rendering.md, "Path partition" and "Continuation weights").

    The lobe and direction as :func:`bsdf_sample` (the same u0, u1, u2 give the same wi).  What
    goes on is the light the continuation lobes reflect, f_c = the rough lobes other than DIFFUSE
    (without a rough COAT when stop_coat; :func:`bsdf_eval_cont`), whichever non-delta lobe drew
    wi: one-sample multiple importance sampling over the lobes (the balance heuristic, as Cycles
    weighs a sampled closure against the others), weight = f_c |cos| / pdf_nd, pdf_nd = sum_j p_j
    pdf_j(wi) over every non-delta lobe (DIFFUSE included), so that E[weight L] over all non-delta
    choices is the integral of f_c L cos.  A DIFFUSE pick therefore goes on too, carrying the
    glossy part of f at a cosine-drawn wi (the photon maps carry the diffuse part).  kind
    ``PATH_STOP``: nothing to carry (no continuation lobe, f_c = 0 at wi, a sample on the wrong side
    of the surface; weight 0, pdf 0); ``PATH_DELTA``: a delta lobe, weight throughput / p_lobe as
    :func:`bsdf_sample` (pdf inf); ``PATH_GLOSSY``: the rest, pdf = pdf_nd (the density of the
    direction, for multiple importance sampling against next-event estimation).  u_rr: where a
    lobe that does not carry on (DIFFUSE; a rough COAT with stop_coat) drew wi, a uniform
    independent of the choice and of wi (``_sample_lobe``'s u_res) for the Russian roulette of
    ``paths.specular_step`` (these picks are most of the hits on a coated diffuse and carry small
    weights); -1 (no roulette) where a continuation lobe drew it, whose paths went on before.

    Why not :func:`bsdf_sample_path`'s weight f_c |cos| / (p_c pdf_c) on the continuation lobes'
    own picks alone (what camera paths did until 2026-12-06): a rough coat over a diffuse base is
    picked with its albedo's share, under 2 % on a default Principled BSDF at roughness 1, so one
    hit in 50 carried the coat's whole reflection with a weight of up to 2.5 (the GGX sample does
    not follow the Fresnel factor, 0.04 to 1 over the microfacets): fireflies where that lobe sees
    something bright (issue 14).
    """
    hit = _hit(C, cr, E, E_avg, wo, ns, ng)
    lobe, p_chosen, is_delta, wi, u_rr = _sample_lobe(C, cr, hit, wo, u0, u1, u2)
    wi0, wi1, wi2 = wi
    if not p_chosen > 0:
        return wi0, wi1, wi2, 0.0, 0.0, 0.0, PATH_STOP, 0.0, u_rr
    if is_delta:
        t0, t1, t2 = _delta_weight(C, cr, hit, lobe, p_chosen, wi)
        return wi0, wi1, wi2, t0, t1, t2, PATH_DELTA, np.inf, u_rr
    if not C[cr, C_ROUGH_LOBE] > 0 or not _on_lobe_side(lobe, dot(wi, hit[1])):
        return wi0, wi1, wi2, 0.0, 0.0, 0.0, PATH_STOP, 0.0, u_rr
    coat_w = 0.0 if stop_coat else 1.0
    f0, f1, f2, pdf = _glossy_add(C, cr, E, hit, wo, wi, 0.0, 0.0, 0.0, 0.0, coat_w)
    if not (f0 > 0.0 or f1 > 0.0 or f2 > 0.0):
        return wi0, wi1, wi2, 0.0, 0.0, 0.0, PATH_STOP, 0.0, u_rr
    if stop_coat:
        pdf = _eval_pdf_hit(C, cr, E, hit, wo, wi)[3]
    else:
        # the DIFFUSE lobe's share of the mixture density (as _eval_pdf_hit)
        cos_d = dot(wi, hit[0])
        if cos_d > 0 and dot(wi, hit[1]) > 0:
            pdf += hit[13][DIFFUSE] * cos_d / _PI
    if not pdf > 0:
        return wi0, wi1, wi2, 0.0, 0.0, 0.0, PATH_STOP, 0.0, u_rr
    r = abs(dot(wi, hit[0])) / pdf
    if not (lobe == DIFFUSE or (stop_coat and lobe == COAT)):
        u_rr = -1.0                                     # a continuation lobe's own pick: no roulette
    return wi0, wi1, wi2, f0 * r, f1 * r, f2 * r, PATH_GLOSSY, pdf, u_rr


@njit(**_JIT)
def bsdf_eval_cont(C, cr, E, E_avg, wo, wi, ns, ng, stop_coat):
    """(f0, f1, f2, pdf): f (1/sr) of the rough lobes whose light camera paths carry on
    (:func:`bsdf_sample_cont`: every non-delta lobe but DIFFUSE; without a rough COAT when
    stop_coat) and the density pdf_nd with which :func:`bsdf_sample_cont` returns wi (every
    non-delta lobe's, DIFFUSE included, as :func:`bsdf_eval_pdf`; for multiple importance
    sampling; 0 where f is 0)."""
    hit = _hit(C, cr, E, E_avg, wo, ns, ng)
    f0, f1, f2, _ = _glossy_add(C, cr, E, hit, wo, wi, 0.0, 0.0, 0.0, 0.0, 0.0 if stop_coat else 1.0)
    if not (f0 > 0.0 or f1 > 0.0 or f2 > 0.0):
        return 0.0, 0.0, 0.0, 0.0
    return f0, f1, f2, _eval_pdf_hit(C, cr, E, hit, wo, wi)[3]


@njit(**_JIT)
def bsdf_eval_split(C, cr, E, E_avg, wo, wi, ns, ng, stop_coat):
    """(f0, f1, f2, c0, c1, c2, p_c): :func:`bsdf_eval_pdf`'s f and :func:`bsdf_eval_cont`'s (c, p_c)
    from one :func:`_hit` (next-event estimation weighed against the continuation,
    ``paths.nee_light``).  The same values bit for bit as the two calls: f = f_diffuse + g, g the
    other rough lobes' sum, which without stop_coat is c itself (``_glossy_add`` adds g to what it is
    given); p_c the mixture density (0 where c is 0)."""
    hit = _hit(C, cr, E, E_avg, wo, ns, ng)
    d0, d1, d2, pdf_d = _diffuse_part(C, cr, hit, wi)
    g0, g1, g2, pdf = _glossy_add(C, cr, E, hit, wo, wi, 0.0, 0.0, 0.0, pdf_d, 1.0)
    f0, f1, f2 = d0 + g0, d1 + g1, d2 + g2
    c0, c1, c2 = g0, g1, g2
    if stop_coat:
        c0, c1, c2, _ = _glossy_add(C, cr, E, hit, wo, wi, 0.0, 0.0, 0.0, 0.0, 0.0)
    if not (c0 > 0.0 or c1 > 0.0 or c2 > 0.0):
        return f0, f1, f2, 0.0, 0.0, 0.0, 0.0
    return f0, f1, f2, c0, c1, c2, pdf


# ----------------------------------------------------------------------------
# Other queries
# ----------------------------------------------------------------------------
@njit(**_JIT)
def diffuse_albedo(C, cr, E, wo, ns):
    """(r, g, b) = w_base (1 - F_coat(|wo . ns|)) base_color: the diffuse reflectance after the coat
    (photon radiance = diffuse_albedo / pi * irradiance), F_coat = specular F_diel(mu, ior) for a
    smooth coat, specular ``coat_albedo``(E, mu, alpha, ior) for a rough one; ns may face either way.
    Under a coat layer (CLEARCOAT) times its attenuation at mu (``_coat_attenuation``)."""
    mu = min(abs(dot(wo, ns)), 1.0)
    spec = C[cr, C_SPECULAR]
    if C[cr, C_ROUGHNESS] > 0.0:
        F = spec * coat_albedo(E, mu, max(C[cr, C_ALPHA], 1e-4), C[cr, C_IOR]) if spec > 0 else 0.0
    else:
        F = spec * fresnel_dielectric(mu, C[cr, C_IOR])
    k = C[cr, C_W_BASE] * (1.0 - F)
    cw = C[cr, C_CC_WEIGHT]
    if cw > 0.0:
        if C[cr, C_CC_ROUGH] > 0.0:
            F_cc = cw * coat_albedo(E, mu, max(C[cr, C_CC_ALPHA], 1e-4), C[cr, C_CC_IOR])
        else:
            F_cc = cw * fresnel_dielectric(mu, C[cr, C_CC_IOR])
        a0, a1, a2 = _coat_attenuation(C, cr, mu, F_cc)
        return k * C[cr, C_BASE] * a0, k * C[cr, C_BASE + 1] * a1, k * C[cr, C_BASE + 2] * a2
    return k * C[cr, C_BASE], k * C[cr, C_BASE + 1], k * C[cr, C_BASE + 2]


#: Cycles' line between specular-like and diffuse-like closures for the denoising features: a lobe
#: whose GGX alpha (roughness^2) is above it counts as diffuse (``denoising_passes.h``, 0.075^2
#: compared with alpha_x alpha_y); DIFFUSE always does
DENOISE_ALPHA = 0.075


@njit(**_JIT)
def denoising_features(C, cr, E, E_avg, wo, ns, ng):
    """Cycles' denoising features of closure row C[cr] seen from wo: (diffuse-like albedo (3-tuple),
    specular-like albedo (3-tuple), normal (3-tuple), stop).

    As Cycles' ``film_write_denoising_features_surface``: each lobe's albedo at wo (its weight times
    its directional reflectance, as STPM's BSDF defines it: DIFFUSE w_base (1 - F_coat) base_color,
    COAT w_base F_coat, METAL w_metal F_metal(wo), GLASS w_glass (F tint_r + (1 - F) tint_t)) goes to the
    diffuse-like sum when the lobe is DIFFUSE or its alpha is above :data:`DENOISE_ALPHA`, else to
    the specular-like sum; the normal is the lobes' normals (DIFFUSE: the facing shading normal, the
    others: the specular normal nss) weighted by their mean albedo.  stop: this vertex writes the
    features (no lobe has any weight, or diffuse-like lobes hold more than a quarter of it); else
    the camera path carries them on, its feature throughput times the specular-like albedo.
    """
    hit = _hit(C, cr, E, E_avg, wo, ns, ng)
    nsf, ngf, nss, cos_o, eta_glass, alpha, F_coat, F_glass, F_metal, ms_scale, ms_Eo, k_coat, k_glass, p_lobe, ncs, cos_c, alpha_c, F_cc, k_cc, att = hit
    w_base, w_metal, w_glass = C[cr, C_W_BASE], C[cr, C_W_METAL], C[cr, C_W_GLASS]
    rough_like = C[cr, C_ALPHA] > DENOISE_ALPHA
    d0 = d1 = d2 = 0.0                               # diffuse-like albedo
    s0 = s1 = s2 = 0.0                               # specular-like albedo
    n0 = n1 = n2 = 0.0                               # weighted normal
    w_sum = 0.0
    w_diffuse = 0.0
    # -- CLEARCOAT: the coat layer over everything (grey)
    if F_cc > 0.0 and cos_c > 0.0:
        nc_w = F_cc
        n0, n1, n2 = nc_w * ncs[0], nc_w * ncs[1], nc_w * ncs[2]
        w_sum += nc_w
        if C[cr, C_CC_ALPHA] > DENOISE_ALPHA:
            d0 = d1 = d2 = F_cc
            w_diffuse += nc_w
        else:
            s0 = s1 = s2 = F_cc
    # -- DIFFUSE: the base under the coat
    k = w_base * (1.0 - F_coat)
    a0, a1, a2 = k * C[cr, C_BASE] * att[0], k * C[cr, C_BASE + 1] * att[1], k * C[cr, C_BASE + 2] * att[2]
    w = (a0 + a1 + a2) / 3.0
    if w > 0.0:
        d0, d1, d2 = d0 + a0, d1 + a1, d2 + a2
        n0, n1, n2 = n0 + w * nsf[0], n1 + w * nsf[1], n2 + w * nsf[2]
        w_sum += w
        w_diffuse += w
    if cos_o > 0.0:                                  # the specular lobes give nothing for wo under nss
        for lobe in range(3):
            if lobe == 0:                            # COAT (grey)
                a0 = a1 = a2 = w_base * F_coat
            elif lobe == 1:                          # METAL
                a0, a1, a2 = w_metal * F_metal[0], w_metal * F_metal[1], w_metal * F_metal[2]
            else:                                    # GLASS: reflection and transmission
                a0 = w_glass * (F_glass * C[cr, C_TINT_R] + (1.0 - F_glass) * C[cr, C_TINT_T])
                a1 = w_glass * (F_glass * C[cr, C_TINT_R + 1] + (1.0 - F_glass) * C[cr, C_TINT_T + 1])
                a2 = w_glass * (F_glass * C[cr, C_TINT_R + 2] + (1.0 - F_glass) * C[cr, C_TINT_T + 2])
            a0, a1, a2 = a0 * att[0], a1 * att[1], a2 * att[2]      # (under the coat layer)
            w = (a0 + a1 + a2) / 3.0
            if not w > 0.0:
                continue
            n0, n1, n2 = n0 + w * nss[0], n1 + w * nss[1], n2 + w * nss[2]
            w_sum += w
            if rough_like:
                d0, d1, d2 = d0 + a0, d1 + a1, d2 + a2
                w_diffuse += w
            else:
                s0, s1, s2 = s0 + a0, s1 + a1, s2 + a2
    if w_sum > 0.0:
        n0, n1, n2 = n0 / w_sum, n1 / w_sum, n2 / w_sum
    stop = (not w_sum > 0.0) or w_diffuse * 4.0 > w_sum
    return (d0, d1, d2), (s0, s1, s2), (n0, n1, n2), stop


# ----------------------------------------------------------------------------
# Batch kernels
# ----------------------------------------------------------------------------
@njit(**_JIT)
def eval_batch(closures, E, E_avg, mat, wo, wi, ns, ng, f_out, pdf_out):
    """f_out (n, 3) = :func:`bsdf_eval` and pdf_out (n,) = the pdf of :func:`bsdf_eval_pdf` for
    material ids mat (n,) (-1 = miss: the inert last closure row); pdf_out of length 0 skips the pdf."""
    want_pdf = pdf_out.shape[0] > 0
    for i in range(mat.shape[0]):
        cr = closure_row(closures, mat[i])
        o = (wo[i, 0], wo[i, 1], wo[i, 2])
        d = (wi[i, 0], wi[i, 1], wi[i, 2])
        s = (ns[i, 0], ns[i, 1], ns[i, 2])
        g = (ng[i, 0], ng[i, 1], ng[i, 2])
        if want_pdf:
            f0, f1, f2, pdf = bsdf_eval_pdf(closures, cr, E, E_avg, o, d, s, g)
            pdf_out[i] = pdf
            if not closures[cr, C_ROUGH_LOBE] > 0:
                f0, f1, f2 = bsdf_eval(closures, cr, E, E_avg, o, d, s, g)
        else:
            f0, f1, f2 = bsdf_eval(closures, cr, E, E_avg, o, d, s, g)
        f_out[i, 0], f_out[i, 1], f_out[i, 2] = f0, f1, f2


@njit(**_JIT)
def sample_batch(closures, E, E_avg, mat, wo, ns, ng, u, wi_out, weight_out, delta_out):
    """:func:`bsdf_sample` per row: wi_out, weight_out (n, 3), delta_out (n,) bool from u (n, 3)."""
    for i in range(mat.shape[0]):
        cr = closure_row(closures, mat[i])
        wi0, wi1, wi2, w0, w1, w2, dl = bsdf_sample(
            closures, cr, E, E_avg, (wo[i, 0], wo[i, 1], wo[i, 2]), (ns[i, 0], ns[i, 1], ns[i, 2]),
            (ng[i, 0], ng[i, 1], ng[i, 2]), u[i, 0], u[i, 1], u[i, 2])
        wi_out[i, 0], wi_out[i, 1], wi_out[i, 2] = wi0, wi1, wi2
        weight_out[i, 0], weight_out[i, 1], weight_out[i, 2] = w0, w1, w2
        delta_out[i] = dl


@njit(**_JIT)
def albedo_batch(closures, E, mat, wo, ns, out):
    """:func:`diffuse_albedo` per row into out (n, 3)."""
    for i in range(mat.shape[0]):
        cr = closure_row(closures, mat[i])
        r, g, b = diffuse_albedo(closures, cr, E, (wo[i, 0], wo[i, 1], wo[i, 2]), (ns[i, 0], ns[i, 1], ns[i, 2]))
        out[i, 0], out[i, 1], out[i, 2] = r, g, b


if __name__ == "__main__":            # python -m stpm_core.kernels.bsdf: (re)write the coat and glass tables
    _E0 = ggx_albedo_tables()[0][0]
    np.save(COAT_TABLE_FILE, build_coat_table(_E0, ggx_albedo_tables()[1][:_N_ALPHA]))
    print(f"wrote {COAT_TABLE_FILE}")
    np.save(GLASS_TABLE_FILE, build_glass_table())
    print(f"wrote {GLASS_TABLE_FILE}")
