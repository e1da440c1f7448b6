"""The numpy BSDF the compiled kernels (:mod:`stpm_core.kernels.bsdf`) are tested against.

This is the vectorised numpy implementation that shaded the renderer before the
kernels became the one implementation (``stpm_core/bsdf.py`` up to that change),
kept verbatim as an oracle: same lobes (DIFFUSE, COAT, METAL, GLASS_R, GLASS_T,
METAL_MS), same formulas (docs/lights-and-materials.md), same random numbers.
Material data comes from :class:`stpm_core.bsdf.MaterialTable`, the GGX albedo
tables from :func:`stpm_core.kernels.bsdf.ggx_albedo_tables`;
:func:`_ggx_albedo_table_numpy` is the original table construction, kept so a
test can check the kernels module builds the same numbers.

Changes since: GLASS_T is tinted by ``MaterialTable.tint_t`` (the material's transmission tint,
Cycles' sqrt(base) for a Principled BSDF) instead of base_color, and GLASS_R by
``MaterialTable.tint_r`` (the reflection tint, Cycles' Glass BSDF colour; white otherwise): its
Fresnel weight is F tint_r, and rough glass reflects with probability F mean(tint_r) / (F
mean(tint_r) + (1 - F) mean(tint_t)) (Cycles' ``FresnelDielectricTint``, bsdf_microfacet.h).  Normals as they come, as Cycles and the kernels (issue 14, item 5): ``ns``
turns with ``ng`` (the back-face flip) instead of onto ``ng``'s side, and the specular lobes use
``nss``, ``ns`` raised by ``ensure_valid_specular_reflection`` where it differs from ``ng``, and
vanish where ``wo`` is below it.  Since the shadow-terminator change (issue 14, deliverable 5) the
DIFFUSE lobe is evaluated wherever ``wi`` is above ``ns``, also below the face (Cycles'
``bsdf_diffuse_eval``; the shadow ray decides there).
"""
from __future__ import annotations

import numpy as np

from stpm_core.bsdf import MaterialTable
from stpm_core.kernels.bsdf import ggx_albedo_tables
from stpm_core.sampling import cosine_hemisphere, orthonormal_basis

__all__ = ["MaterialTable", "bsdf_eval", "bsdf_pdf", "bsdf_sample", "diffuse_albedo",
           "has_nondelta", "emission", "fresnel_dielectric", "fresnel_schlick"]

DIFFUSE, COAT, METAL, GLASS_R, GLASS_T, METAL_MS = range(6)
_EPS = 1e-9

# ---------------------------------------------------------------------------
# Fresnel and GGX
# ---------------------------------------------------------------------------

def fresnel_dielectric(cos_i: np.ndarray, eta: np.ndarray) -> np.ndarray:
    """Unpolarised Fresnel reflectance (n,) for cos_i >= 0 and eta = n_t / n_i; 1 under TIR."""
    cos_i = np.clip(cos_i, 0.0, 1.0)
    sin2_t = (1.0 - cos_i * cos_i) / (eta * eta)
    tir = sin2_t >= 1.0
    cos_t = np.sqrt(np.maximum(0.0, 1.0 - sin2_t))
    r_s = (cos_i - eta * cos_t) / np.maximum(cos_i + eta * cos_t, 1e-300)
    r_p = (eta * cos_i - cos_t) / np.maximum(eta * cos_i + cos_t, 1e-300)
    return np.where(tir, 1.0, 0.5 * (r_s * r_s + r_p * r_p))


def fresnel_schlick(F0: np.ndarray, cos: np.ndarray) -> np.ndarray:
    """Schlick's approximation (n, 3): F0 + (1 - F0)(1 - cos)^5."""
    m = np.clip(1.0 - cos, 0.0, 1.0) ** 5
    return F0 + (1.0 - F0) * m[:, None]


def _ggx_D(cos_h: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """GGX normal distribution D(h) (n,) per sr of microfacet normals (cos_h = h . n)."""
    a2 = alpha * alpha
    c2 = cos_h * cos_h
    denom = c2 * (a2 - 1.0) + 1.0
    return np.where(cos_h > 0, a2 / np.maximum(np.pi * denom * denom, 1e-300), 0.0)


def _ggx_lambda(cos: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """Smith Lambda(w) (n,) for GGX: (sqrt(1 + alpha^2 tan^2) - 1) / 2."""
    c2 = np.maximum(cos * cos, 1e-300)
    tan2 = np.maximum(1.0 - c2, 0.0) / c2
    return 0.5 * (np.sqrt(1.0 + alpha * alpha * tan2) - 1.0)


def _ggx_sample_vndf(wo_local: np.ndarray, alpha: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Visible-normal sample h (n, 3) local (Heitz 2018) for wo_local (n, 3) with z > 0."""
    # Stretch the view direction to the hemisphere configuration
    vh = np.stack([alpha * wo_local[:, 0], alpha * wo_local[:, 1], wo_local[:, 2]], axis=-1)
    vh /= np.linalg.norm(vh, axis=-1, keepdims=True)
    lensq = vh[:, 0] ** 2 + vh[:, 1] ** 2
    inv = 1.0 / np.sqrt(np.maximum(lensq, 1e-300))
    T1 = np.where((lensq > 0)[:, None], np.stack([-vh[:, 1] * inv, vh[:, 0] * inv, np.zeros_like(inv)], -1),
                  np.array([1.0, 0.0, 0.0]))
    T2 = np.cross(vh, T1)
    # Sample the projected disk, warped toward the visible half
    r = np.sqrt(u[:, 0])
    phi = 2.0 * np.pi * u[:, 1]
    t1 = r * np.cos(phi)
    t2 = r * np.sin(phi)
    s = 0.5 * (1.0 + vh[:, 2])
    t2 = (1.0 - s) * np.sqrt(np.maximum(0.0, 1.0 - t1 * t1)) + s * t2
    nh = t1[:, None] * T1 + t2[:, None] * T2 + np.sqrt(np.maximum(0.0, 1.0 - t1 * t1 - t2 * t2))[:, None] * vh
    # Unstretch
    h = np.stack([alpha * nh[:, 0], alpha * nh[:, 1], np.maximum(nh[:, 2], 1e-12)], axis=-1)
    return h / np.linalg.norm(h, axis=-1, keepdims=True)


# Directional albedo of single-scattering GGX (F = 1), for multiple-scattering
# energy compensation (Kulla & Conty 2017), tabulated once on first use.
_MU = (np.arange(32) + 0.5) / 32                 # cos(theta_o) midpoints
_ALPHA = np.linspace(0.0, 1.0, 32)              # GGX alpha grid


def _ggx_albedo_table_numpy() -> tuple[np.ndarray, np.ndarray]:
    """E(mu, alpha) (32, 32) = integral of f_ggx cos over wi for F = 1, and E_avg(alpha) = 2 int E mu dmu (32,).

    Deterministic: a 64 x 64 graded grid of visible-normal samples per cell (u = 1 - (1 - m)^3 at
    the midpoints m, weight 3 (1 - m)^2: the grid reaches GGX's tail as u0 -> 1), E = weighted
    mean of the sample weight G2 / G1(wo) over samples that stay above the surface.
    """
    K = 64
    m = (np.arange(K) + 0.5) / K
    g, gw = 1.0 - (1.0 - m) ** 3, 3 * (1.0 - m) ** 2
    uu = np.stack(np.meshgrid(g, g, indexing="ij"), -1).reshape(-1, 2)
    mu, al = np.meshgrid(_MU, np.maximum(_ALPHA, 1e-4), indexing="ij")
    mu, al = np.repeat(mu.ravel(), K * K), np.repeat(al.ravel(), K * K)
    u = np.tile(uu, (_MU.size * _ALPHA.size, 1))
    wo = np.stack([np.sqrt(1 - mu * mu), np.zeros_like(mu), mu], -1)
    h = _ggx_sample_vndf(wo, al, u)
    wi_z = 2.0 * np.sum(wo * h, -1) * h[:, 2] - mu
    lam_o, lam_i = _ggx_lambda(mu, al), _ggx_lambda(wi_z, al)
    w = np.where(wi_z > 0, (1.0 + lam_o) / (1.0 + lam_o + lam_i), 0.0)
    E = np.clip((w.reshape(_MU.size, _ALPHA.size, K, K) * gw[:, None] * gw[None, :]).mean(axis=(2, 3)), 0.0, 1.0)
    E_avg = 2.0 * np.mean(E * _MU[:, None], axis=0)
    return E, E_avg


def _table_bilinear(s, mu: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """Bilinear look-up (n,) of slice(s) s of the kernel's tables E at (mu, alpha) (clamped)."""
    E, _ = ggx_albedo_tables()
    x = np.clip(mu * 32 - 0.5, 0, 31 - 1e-9)
    y = np.clip(alpha * 31, 0, 31 - 1e-9)
    i, j = np.minimum(x.astype(int), 30), np.minimum(y.astype(int), 30)
    fx, fy = x - i, y - j
    return ((1 - fx) * (1 - fy) * E[s, i, j] + fx * (1 - fy) * E[s, i + 1, j]
            + (1 - fx) * fy * E[s, i, j + 1] + fx * fy * E[s, i + 1, j + 1])


def _ggx_albedo(mu: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """Bilinear look-up of E(mu, alpha) (n,) in the table (clamped at the edges)."""
    return _table_bilinear(0, mu, alpha)


def _coat_albedo(mu: np.ndarray, alpha: np.ndarray, ior: np.ndarray) -> np.ndarray:
    """Rough-coat albedo (specular 1) (n,): slices 1.. of the table, bilinear in (mu, alpha), linear
    in r = (ior - 1) / (ior + 1) on 32 steps to 9 / 11."""
    z = np.clip(np.maximum(ior - 1.0, 0.0) / (ior + 1.0) / (9.0 / 11.0) * 31, 0, 31 - 1e-9)
    k = np.minimum(z.astype(int), 30)
    fz = z - k
    return (1 - fz) * _table_bilinear(1 + k, mu, alpha) + fz * _table_bilinear(2 + k, mu, alpha)


def _ggx_albedo_avg(alpha: np.ndarray) -> np.ndarray:
    """E_avg(alpha) (n,) by linear interpolation."""
    _, E_avg = ggx_albedo_tables()
    return np.interp(alpha, _ALPHA, E_avg[:32])


_GZ_MAX = np.sqrt(9.0 / 11.0)                   # the glass slices' z = sqrt((ior - 1) / (ior + 1)) = k / 15 * this


def _glass_z(eta: np.ndarray):
    """(side, k, fz) (n,): slices of the glass albedo (side 1 for eta < 1, at 1 / eta) and position in z."""
    side = (eta < 1.0).astype(int)
    ior = np.where(eta >= 1.0, eta, 1.0 / eta)
    z = np.clip(np.sqrt(np.maximum(ior - 1.0, 0.0) / (ior + 1.0)) / _GZ_MAX * 15, 0, 15 - 1e-9)
    k = np.minimum(z.astype(int), 14)
    return side, k, z - k


def _glass_albedo(mu: np.ndarray, rough: np.ndarray, eta: np.ndarray) -> np.ndarray:
    """Single-scattering rough-glass albedo (n,): slices 33 + 16 side + k of the table, bilinear in
    (mu, roughness), linear in z."""
    side, k, fz = _glass_z(eta)
    s = 33 + side * 16 + k
    return (1 - fz) * _table_bilinear(s, mu, rough) + fz * _table_bilinear(s + 1, mu, rough)


def _glass_albedo_avg(rough: np.ndarray, eta: np.ndarray) -> np.ndarray:
    """Its 2 int E mu dmu (n,): E_avg[32 + (16 side + k) 32 + j], linear in roughness and z."""
    _, E_avg = ggx_albedo_tables()
    side, k, fz = _glass_z(eta)
    y = np.clip(rough * 31.0, 0.0, 31 - 1e-9)
    j = np.minimum(y.astype(int), 30)
    fy = y - j
    o0 = 32 + (side * 16 + k) * 32 + j
    o1 = o0 + 32
    return (1 - fz) * ((1 - fy) * E_avg[o0] + fy * E_avg[o0 + 1]) + fz * ((1 - fy) * E_avg[o1] + fy * E_avg[o1 + 1])


# ---------------------------------------------------------------------------
# Frames and per-hit gathers
# ---------------------------------------------------------------------------

def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.einsum("ij,ij->i", a, b)


def _reflect(w: np.ndarray, n: np.ndarray) -> np.ndarray:
    return 2.0 * _dot(w, n)[:, None] * n - w


def _oriented(wo, ns, ng):
    """Cycles' back-face flip: (s ns, s ng, entering (n,) bool = wo on ng's side), s = +-1 turning ng
    toward wo; ns keeps its side of ng (a shading normal facing away from its face stays so)."""
    ng = np.asarray(ng, float)
    ns = np.asarray(ns, float)
    entering = _dot(wo, ng) >= 0.0
    s = np.where(entering, 1.0, -1.0)[:, None]
    return ns * s, ng * s, entering


def _valid_specular(ng, wi, n):
    """Cycles' ``ensure_valid_specular_reflection`` per row: n (n, 3) raised toward ng (facing wi)
    just enough that the mirror reflection of wi about it leaves at least min(0.9 wi.ng, 0.01)
    above the surface; n itself where it already does.  Dot products summed x + y + z as the
    kernel does: near grazing the root is ill-conditioned, and einsum's order moved f by 5e-9."""
    def dot3(a, b):
        return a[:, 0] * b[:, 0] + a[:, 1] * b[:, 1] + a[:, 2] * b[:, 2]
    r = 2.0 * dot3(n, wi)[:, None] * n - wi
    iz = dot3(wi, ng)
    threshold = np.minimum(0.9 * iz, 0.01)
    ok = dot3(ng, r) >= threshold
    x = n - dot3(n, ng)[:, None] * ng
    lx = np.sqrt(dot3(x, x))
    x = np.where((lx > 0)[:, None], x / np.where(lx > 0, lx, 1.0)[:, None], n)
    ix = dot3(wi, x)
    a = ix * ix + iz * iz
    b = 2.0 * (a + iz * threshold)
    c = (threshold + iz) * (threshold + iz)
    disc = np.sqrt(np.maximum(b * b - 4.0 * a * c, 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        nz2 = np.where(ix < 0, 0.25 * (b + disc) / a, 0.25 * (b - disc) / a)
    raised = np.sqrt(np.maximum(1.0 - nz2, 0.0))[:, None] * x + np.sqrt(np.maximum(nz2, 0.0))[:, None] * ng
    return np.where(ok[:, None], n, raised)


class _Hit:
    """Per-hit gathers for one call: weights, colours, eta and Fresnel at wo."""

    def __init__(self, table: MaterialTable, mat, wo, ns, ng):
        mat = np.asarray(mat, dtype=np.int64)
        self.m = np.where(mat < 0, table.size, mat)
        m = self.m
        self.wo = np.asarray(wo, float)
        self.ns, self.ng, self.entering = _oriented(self.wo, ns, ng)
        # The specular lobes' normal: ns raised where it differs from ng (smooth / custom normals)
        self.nss = self.ns.copy()
        d = np.nonzero(np.any(self.ns != self.ng, axis=1))[0]
        if d.size:
            self.nss[d] = _valid_specular(self.ng[d], self.wo[d], self.ns[d])
        self.base = table.base_color[m]
        self.tint = table.tint_t[m]              # GLASS_T's transmission tint (Principled: sqrt(base))
        self.tint_r = table.tint_r[m]            # GLASS_R's reflection tint (Glass BSDF: its colour)
        self.alpha = np.maximum(table.alpha[m], 1e-4)
        self.rough = table.roughness[m] > 0.0
        self.spec = table.specular[m]
        self.w_base, self.w_metal, self.w_glass = table.w_base[m], table.w_metal[m], table.w_glass[m]
        ior = table.ior[m]
        self.eta_glass = np.where(self.entering, ior, 1.0 / ior)   # n_t / n_i for glass
        self.ior = ior
        self.cos_o = _dot(self.wo, self.nss)
        cos_o = np.clip(self.cos_o, 0.0, 1.0)
        # Fresnel at wo for each lobe (computed only on the rows that have the lobe)
        n = self.m.shape[0]
        self.F_coat = np.zeros(n)                # the coat's albedo at wo (smooth: its Fresnel)
        i = np.nonzero((self.w_base > 0) & (self.spec > 0))[0]
        if i.size:
            self.F_coat[i] = self.spec[i] * np.where(self.rough[i], _coat_albedo(cos_o[i], self.alpha[i], ior[i]),
                                                     fresnel_dielectric(cos_o[i], ior[i]))
        self.F_glass = np.zeros(n)
        i = np.nonzero(self.w_glass > 0)[0]
        if i.size:
            self.F_glass[i] = fresnel_dielectric(cos_o[i], self.eta_glass[i])
        self.F_metal = np.zeros((n, 3))
        i = np.nonzero(self.w_metal > 0)[0]
        if i.size:
            self.F_metal[i] = fresnel_schlick(self.base[i], cos_o[i])
        # Rough metal: Cycles' energy compensation of Multiscatter GGX, per channel
        # k_metal = 1 + F_ms (1 - E_o) / E_o, F_ms = F_ss E_avg / (1 - F_ss (1 - E_avg)), F_ss = F0 + (1 - F0) / 21
        self.ms_scale = np.ones((n, 3))          # k_metal
        i = np.nonzero((self.w_metal > 0) & self.rough)[0]
        if i.size:
            a = self.alpha[i]
            E_avg = _ggx_albedo_avg(a)[:, None]
            F_ss = self.base[i] + (1.0 - self.base[i]) / 21.0
            F_ms = F_ss * E_avg / (1.0 - F_ss * (1.0 - E_avg))
            e_o = np.maximum(_ggx_albedo(cos_o[i], a), 1e-3)[:, None]
            self.ms_scale[i] = 1.0 + F_ms * (1.0 - e_o) / e_o
        # Rough coat: Cycles' energy compensation of its dielectric layer, 1 + F_ms (1 - E_o) / E_o
        self.k_coat = np.ones(n)
        i = np.nonzero((self.F_coat > 0) & self.rough)[0]
        if i.size:
            a = self.alpha[i]
            e_o = np.maximum(_ggx_albedo(cos_o[i], a), 1e-3)
            e_av = _ggx_albedo_avg(a)
            eta = ior[i]
            fss = self.spec[i] * np.where(eta < 1.0, 0.997118 + eta * (0.1014 - eta * (0.965241 + eta * 0.130607)),
                                          (eta - 1.0) / (4.08567 + 1.00071 * eta))
            f_ms = fss * e_av / (1.0 - fss * (1.0 - e_av))
            self.k_coat[i] = 1.0 + f_ms * (1.0 - e_o) / e_o
        # Rough glass: Cycles' energy compensation of its Multiscatter GGX glass, per channel
        # k_glass = 1 + F_ms (1 - E_o) / E_o with the glass albedo E, F_ss = the transmission tint
        self.grough = self.rough & (np.abs(ior - 1.0) >= 1e-4)      # rough refraction (ior 1: a delta)
        self.k_glass = np.ones((n, 3))
        i = np.nonzero((self.w_glass > 0) & self.rough)[0]
        if i.size:
            rg = table.roughness[m][i]
            e_o = np.maximum(_glass_albedo(cos_o[i], rg, self.eta_glass[i]), 1e-3)[:, None]
            e_av = _glass_albedo_avg(rg, self.eta_glass[i])[:, None]
            fss = self.tint[i]
            f_ms = fss * e_av / (1.0 - fss * (1.0 - e_av))
            self.k_glass[i] = 1.0 + f_ms * (1.0 - e_o) / e_o
        # Lobe selection probabilities proportional to an albedo estimate
        mean_base = self.base.mean(axis=1)
        mean_tint = self.tint.mean(axis=1)
        est = np.stack([
            self.w_base * (1.0 - self.F_coat) * mean_base,
            self.w_base * self.F_coat,
            self.w_metal * (self.F_metal * self.ms_scale).mean(axis=1),
            self.w_glass * self.F_glass * self.tint_r.mean(axis=1),
            self.w_glass * (1.0 - self.F_glass) * mean_tint,
            np.zeros(n),                                     # METAL_MS: no longer a lobe
        ], axis=-1)
        est[~(self.cos_o > 0), 1:] = 0.0          # wo below the specular normal: only the diffuse lobe
        total = est.sum(axis=1, keepdims=True)
        self.p_lobe = np.where(total > 0, est / np.maximum(total, 1e-300), 0.0)
        # Lobes that are deltas at this hit
        self.delta = np.stack([np.zeros_like(self.rough), ~self.rough, ~self.rough, ~self.rough,
                               ~self.grough, np.zeros_like(self.rough)], axis=-1)

    def take(self, idx: np.ndarray) -> "_Hit":
        """The same gathers for rows idx only."""
        if idx.shape[0] == self.m.shape[0]:
            return self                            # idx = all rows, in order
        out = object.__new__(_Hit)
        for k, v in self.__dict__.items():
            out.__dict__[k] = v[idx] if isinstance(v, np.ndarray) else v
        return out


def _microfacet(h: _Hit, wi: np.ndarray):
    """GGX reflection terms for wi (n, 3) -> valid (n,) bool, D G2 / (4 cos_o cos_i) (n,),
    visible-normal pdf of wi (n,) per sr, and wo . h (n,)."""
    cos_is = _dot(wi, h.nss)
    cos_i = _dot(wi, h.ns)
    valid = (cos_is > 0) & (h.cos_o > 0) & (_dot(wi, h.ng) > 0)
    hv = h.wo + wi
    hv /= np.maximum(np.linalg.norm(hv, axis=-1, keepdims=True), 1e-300)
    cos_h = _dot(hv, h.nss)
    wo_h = np.clip(_dot(h.wo, hv), 0.0, 1.0)
    D = _ggx_D(cos_h, h.alpha)
    lam_o = _ggx_lambda(h.cos_o, h.alpha)
    lam_i = _ggx_lambda(cos_is, h.alpha)
    G2 = 1.0 / (1.0 + lam_o + lam_i)
    G1o = 1.0 / (1.0 + lam_o)
    cos_o = np.maximum(h.cos_o, _EPS)
    pdf = G1o * D / (4.0 * cos_o)                 # VNDF pdf of wi (solid angle)
    # f is divided by the |ns . wi| the integrator multiplies
    spec = D * G2 / np.maximum(4.0 * cos_o * np.maximum(np.abs(cos_i), _EPS), 1e-300)
    # Cycles' bump_shadowing_term: wi on the other side of ns than the raised nss says: no reflection
    spec = np.where(_dot(h.ns, wi) * _dot(h.ns, h.nss) * cos_is < 0.0, 0.0, spec)
    return valid, spec, pdf, wo_h


def _eval_pdf(h: _Hit, wi: np.ndarray, diffuse: bool = True, coat: float = 1.0):
    """Non-delta f (n, 3) and mixture pdf (n,) of the non-delta lobes for directions wi (without
    the DIFFUSE lobe when not ``diffuse``; the rough COAT times ``coat``)."""
    n = wi.shape[0]
    f = np.zeros((n, 3))
    pdf = np.zeros(n)
    cos_i = _dot(wi, h.ns)
    above = cos_i > 0            # DIFFUSE: above ns, also below the face (the shadow ray decides, as Cycles)
    # DIFFUSE: base / pi under the coat's Fresnel at wo
    if diffuse:
        f += np.where(above, h.w_base * (1.0 - h.F_coat), 0.0)[:, None] * h.base / np.pi
        pdf += np.where(above, h.p_lobe[:, DIFFUSE] * cos_i / np.pi, 0.0)
    # Rough lobes (GGX), on the rows that have one
    r = np.nonzero(h.rough & ((h.w_metal > 0) | (h.w_glass > 0) | ((h.w_base > 0) & (h.spec > 0))))[0]
    if r.size:
        hr = h.take(r)
        valid, spec, p_ggx, wo_h = _microfacet(hr, wi[r])
        spec = np.where(valid, spec, 0.0)
        p_ggx = np.where(valid, p_ggx, 0.0)
        # COAT (rough): specular * F_diel(wo.h, ior)
        F_c = hr.spec * fresnel_dielectric(wo_h, hr.ior)
        # METAL (rough): Schlick(base, wo.h)
        F_m = fresnel_schlick(hr.base, wo_h)
        # GLASS_R (rough): exact dielectric at wo.h times the reflection tint, energy-compensated;
        # reflection or refraction chosen per microfacet (F mean(tint_r) against (1 - F) mean(tint))
        # inside p_lobe[GLASS_R] + p_lobe[GLASS_T]
        F_g = fresnel_dielectric(wo_h, hr.eta_glass)
        f[r] += (hr.w_base * F_c * hr.k_coat * coat * spec)[:, None] \
            + (hr.w_glass * F_g * spec)[:, None] * hr.tint_r * hr.k_glass \
            + (hr.w_metal * spec)[:, None] * F_m * hr.ms_scale
        refl_w = F_g * hr.tint_r.mean(axis=1)
        rt = refl_w + (1.0 - F_g) * hr.tint.mean(axis=1)
        split_r = np.where(rt > 0, refl_w / np.where(rt > 0, rt, 1.0), 0.0)
        p_glass = hr.p_lobe[:, GLASS_R] + hr.p_lobe[:, GLASS_T]
        pdf[r] += p_ggx * (hr.p_lobe[:, COAT] * coat + hr.p_lobe[:, METAL] + p_glass * split_r)
        # GLASS_T (rough): Walter et al.'s BTDF as Cycles, wi below ng and nss
        ft, pt = _refraction(hr, wi[r])
        f[r] += ft
        pdf[r] += pt
    return f, pdf


def _refraction(h: _Hit, wi: np.ndarray):
    """Rough GLASS_T f (n, 3) and pdf (n,) at wi: f |ns.wi| = w_glass (1 - F(wo.h)) tint k_glass
    D G2 |wo.h| |wi.h| eta^2 / (cos_o (wo.h + eta wi.h)^2), h = -(wo + eta wi) toward nss; pdf =
    (p_R + p_T) (1 - F) t / (F r + (1 - F) t) G1(wo) D |wo.h| / cos_o eta^2 |wi.h| / (wo.h + eta wi.h)^2
    (r, t: the means of the reflection and transmission tints)."""
    n = wi.shape[0]
    cos_is = _dot(wi, h.nss)
    cos_i = _dot(wi, h.ns)
    valid = (h.cos_o > 0) & (cos_is < 0) & (_dot(wi, h.ng) < 0) & (h.w_glass > 0) & h.grough
    valid &= ~(_dot(h.ns, wi) * _dot(h.ns, h.nss) * cos_is < 0.0)          # bump_shadowing_term
    eta = h.eta_glass
    ht = -(h.wo + eta[:, None] * wi)
    ht /= np.maximum(np.linalg.norm(ht, axis=-1, keepdims=True), 1e-300)
    ht = np.where((_dot(ht, h.nss) < 0)[:, None], -ht, ht)
    wo_h, wi_h = _dot(h.wo, ht), _dot(wi, ht)
    valid &= (wo_h > 0) & (wi_h < 0)
    D = _ggx_D(_dot(ht, h.nss), h.alpha)
    lam_o, lam_i = _ggx_lambda(h.cos_o, h.alpha), _ggx_lambda(cos_is, h.alpha)
    G2 = 1.0 / (1.0 + lam_o + lam_i)
    G1o = 1.0 / (1.0 + lam_o)
    F = fresnel_dielectric(np.minimum(wo_h, 1.0), eta)
    den = wo_h + eta * wi_h
    jac = eta * eta * (-wi_h) / np.maximum(den * den, 1e-300)
    common = D * wo_h * jac / np.maximum(h.cos_o, _EPS)
    st = h.w_glass * (1.0 - F) * G2 * common / np.maximum(np.abs(cos_i), _EPS)
    f = np.where(valid[:, None], st[:, None] * h.tint * h.k_glass, 0.0)
    trans_w = (1.0 - F) * h.tint.mean(axis=1)
    rt = F * h.tint_r.mean(axis=1) + trans_w
    split_t = np.where(rt > 0, trans_w / np.where(rt > 0, rt, 1.0), 0.0)
    p_glass = h.p_lobe[:, GLASS_R] + h.p_lobe[:, GLASS_T]
    pdf = np.where(valid, p_glass * split_t * G1o * common, 0.0)
    return f, pdf


# ---------------------------------------------------------------------------
# Public API
# ---------------------------------------------------------------------------

def bsdf_eval(table: MaterialTable, mat, wo, wi, ns, ng) -> np.ndarray:
    """f(wo, wi) (n, 3) in 1/sr for the non-delta lobes (diffuse, rough coat / metal / glass reflection)."""
    mat = np.asarray(mat, dtype=np.int64)
    m = np.where(mat < 0, table.size, mat)
    wo = np.asarray(wo, float)
    wi = np.asarray(wi, float)
    rough = table.rough_lobe[m]
    if rough.all():
        h = _Hit(table, mat, wo, ns, ng)
        f, _ = _eval_pdf(h, wi)
        return f
    # Rows without a rough lobe: the diffuse lobe under a smooth coat's Fresnel
    ns_f, ng_f, _ = _oriented(wo, ns, ng)
    cos_i = _dot(wi, ns_f)
    above = cos_i > 0            # (not ng_f: the shadow ray decides, as Cycles)
    scale = np.where(above, table.w_base[m], 0.0)
    c = np.nonzero(table.coat[m] & above)[0]
    if c.size:
        mc = m[c]
        nc = ns_f[c]
        d = np.nonzero(np.any(nc != ng_f[c], axis=1))[0]       # the coat's normal, as _Hit's nss
        if d.size:
            nc = nc.copy()
            nc[d] = _valid_specular(ng_f[c][d], wo[c][d], nc[d])
        cos_o = np.clip(_dot(wo[c], nc), 0.0, 1.0)
        scale[c] *= 1.0 - table.specular[mc] * fresnel_dielectric(cos_o, table.ior[mc])
    f = scale[:, None] * table.base_color[m] * (1.0 / np.pi)
    # Rows with a rough lobe: the full evaluation
    r = np.nonzero(rough)[0]
    if r.size:
        h = _Hit(table, mat[r], wo[r], np.asarray(ns, float)[r], np.asarray(ng, float)[r])
        f[r], _ = _eval_pdf(h, wi[r])
    return f


def bsdf_pdf(table: MaterialTable, mat, wo, wi, ns, ng) -> np.ndarray:
    """Solid-angle density (n,) with which :func:`bsdf_sample` returns wi through a non-delta lobe (for MIS)."""
    h = _Hit(table, mat, wo, ns, ng)
    _, pdf = _eval_pdf(h, np.asarray(wi, float))
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
    wi, weight, is_delta, _lobe = bsdf_sample_lobe(table, mat, wo, ns, ng, u)
    return wi, weight, is_delta


def bsdf_sample_path(table: MaterialTable, mat, wo, ns, ng, u, stop_coat: bool = False):
    """How a camera path (or a caustic photon) goes on: (wi, weight, kind, pdf) with kind 0 = stop
    (the DIFFUSE lobe, with stop_coat a rough COAT too, or nothing), 1 = a delta lobe (weight as
    :func:`bsdf_sample`), 2 = another rough lobe, weight f_g |cos| / pdf_g over the rough lobes
    that do not stop, pdf = pdf_g on those rows (the kernel: ``kernels.bsdf.bsdf_sample_path``)."""
    wi, weight, is_delta, lobe = bsdf_sample_lobe(table, mat, wo, ns, ng, u)
    rough_coat = (lobe == COAT) & ~is_delta
    stop = (lobe < 0) | (lobe == DIFFUSE) | (rough_coat & stop_coat)
    kind = np.where(stop, 0, np.where(is_delta, 1, 2))
    g = np.nonzero(kind == 2)[0]
    weight = np.where(stop[:, None], 0.0, weight)
    pdf_out = np.where(kind == 1, np.inf, 0.0)
    if g.size:
        h = _Hit(table, np.asarray(mat)[g], np.asarray(wo, float)[g], np.asarray(ns, float)[g], np.asarray(ng, float)[g])
        f, pdf = _eval_pdf(h, wi[g], diffuse=False, coat=0.0 if stop_coat else 1.0)
        pdf = np.where(_on_lobe_side(lobe[g], _dot(wi[g], h.ng)), pdf, 0.0)
        cos_i = np.abs(_dot(wi[g], h.ns))
        weight[g] = np.where((pdf > 0)[:, None], f * (cos_i / np.maximum(pdf, 1e-300))[:, None], 0.0)
        pdf_out[g] = pdf
    return wi, weight, kind, pdf_out


def bsdf_sample_cont(table: MaterialTable, mat, wo, ns, ng, u, stop_coat: bool = False):
    """How a camera path goes on: (wi, weight, kind, pdf, u_rr), kind 0 = stop, 1 = a delta lobe
    (weight as :func:`bsdf_sample`), 2 = the continuation lobes' part f_c (the rough lobes but
    DIFFUSE, and the rough COAT with stop_coat) at wi drawn by any non-delta lobe, weight f_c |cos|
    / pdf_nd (one-sample MIS over every non-delta lobe), pdf = pdf_nd; u_rr the uniform for the
    roulette of DIFFUSE (and, with stop_coat, rough COAT) picks, -1 on the others (the kernel:
    ``kernels.bsdf.bsdf_sample_cont``)."""
    wi, weight, is_delta, lobe, u_res = bsdf_sample_lobe(table, mat, wo, ns, ng, u, residual=True)
    mat = np.asarray(mat)
    n = wi.shape[0]
    ok = lobe >= 0
    kind = np.where(ok & is_delta, 1, 0)
    weight = np.where((kind == 1)[:, None], weight, 0.0)
    pdf_out = np.where(kind == 1, np.inf, 0.0)
    u_rr = np.where(ok, u_res, 0.0)
    g = np.nonzero(ok & ~is_delta & table.rough_lobe[mat])[0]
    if g.size:
        h = _Hit(table, mat[g], np.asarray(wo, float)[g], np.asarray(ns, float)[g], np.asarray(ng, float)[g])
        f, _ = _eval_pdf(h, wi[g], diffuse=False, coat=0.0 if stop_coat else 1.0)
        _, pdf = _eval_pdf(h, wi[g])
        go = _on_lobe_side(lobe[g], _dot(wi[g], h.ng)) & np.any(f > 0, axis=1) & (pdf > 0)
        cos_i = np.abs(_dot(wi[g], h.ns))
        weight[g] = np.where(go[:, None], f * (cos_i / np.maximum(pdf, 1e-300))[:, None], 0.0)
        pdf_out[g] = np.where(go, pdf, 0.0)
        kind[g] = np.where(go, 2, 0)
        own = ~((lobe[g] == DIFFUSE) | ((lobe[g] == COAT) & stop_coat))
        u_rr[g] = np.where(go & own, -1.0, u_rr[g])
    return wi, weight, kind, pdf_out, u_rr


def bsdf_eval_cont(table: MaterialTable, mat, wo, wi, ns, ng, stop_coat: bool = False):
    """(f (n, 3), pdf (n,)): f of the rough lobes whose light camera paths carry on (every
    non-delta lobe but DIFFUSE; the rough COAT unless stop_coat) and the density pdf_nd with which
    :func:`bsdf_sample_cont` draws wi (every non-delta lobe's; 0 where f is 0)."""
    h = _Hit(table, mat, np.asarray(wo, float), np.asarray(ns, float), np.asarray(ng, float))
    wi = np.asarray(wi, float)
    f, _ = _eval_pdf(h, wi, diffuse=False, coat=0.0 if stop_coat else 1.0)
    _, pdf = _eval_pdf(h, wi)
    return f, np.where(np.any(f > 0, axis=1), pdf, 0.0)


def bsdf_sample_lobe(table: MaterialTable, mat, wo, ns, ng, u, residual: bool = False):
    """:func:`bsdf_sample` and the lobe chosen (n,) (-1 where the lobe had probability 0); with
    residual also u_res (n,): where u0 fell inside the chosen lobe's interval (rough glass: inside
    its reflect / refract share), rescaled to [0, 1) (the kernel's ``_sample_lobe``)."""
    h = _Hit(table, mat, wo, ns, ng)
    u = np.asarray(u, float)
    n = u.shape[0]
    rows = np.arange(n)
    # Choose a lobe by the CDF of p_lobe
    cdf = np.cumsum(h.p_lobe, axis=1)
    lobe = np.minimum(np.sum(u[:, 0:1] >= cdf, axis=1), METAL_MS)
    p_chosen = h.p_lobe[rows, lobe]
    ok = p_chosen > 0
    lo = np.where(lobe > 0, cdf[rows, np.maximum(lobe - 1, 0)], 0.0)
    u_res = np.where(ok, np.clip((u[:, 0] - lo) / np.where(ok, p_chosen, 1.0), 0.0, _BELOW_ONE), 0.0)
    wi = np.zeros((n, 3))
    weight = np.zeros((n, 3))
    # Rough glass: a visible normal, then reflect or refract through it, chosen per microfacet by
    # where u0 fell inside p_lobe[GLASS_R] + p_lobe[GLASS_T] (F mean(tint_r) against (1 - F) mean(tint))
    rg = ok & ((lobe == GLASS_R) | (lobe == GLASS_T)) & h.grough
    i = np.nonzero(rg)[0]
    if i.size:
        t_f, b_f = orthonormal_basis(h.nss[i])
        wo_i = h.wo[i]
        wo_loc = np.stack([_dot(wo_i, t_f), _dot(wo_i, b_f), np.maximum(h.cos_o[i], 1e-6)], axis=-1)
        wo_loc /= np.linalg.norm(wo_loc, axis=-1, keepdims=True)
        hl = _ggx_sample_vndf(wo_loc, h.alpha[i], u[i, 1:3])
        hw = hl[:, 0:1] * t_f + hl[:, 1:2] * b_f + hl[:, 2:3] * h.nss[i]
        wo_h = np.clip(_dot(wo_i, hw), 0.0, 1.0)
        eta = h.eta_glass[i]
        F = fresnel_dielectric(wo_h, eta)
        refl_w = F * h.tint_r[i].mean(axis=1)
        rt = refl_w + (1.0 - F) * h.tint[i].mean(axis=1)
        pl = h.p_lobe[i]
        us = np.clip((u[i, 0] - (pl[:, DIFFUSE] + pl[:, COAT] + pl[:, METAL])) / (pl[:, GLASS_R] + pl[:, GLASS_T]), 0, 1)
        split = refl_w / np.where(rt > 0, rt, 1.0)
        refl = us < split
        u_res[i] = np.where(refl, np.minimum(us / np.where(refl, split, 1.0), _BELOW_ONE),
                            np.clip((us - split) / np.where(refl, 1.0, 1.0 - split), 0.0, _BELOW_ONE))
        cos_t = np.sqrt(np.maximum(0.0, 1.0 - (1.0 - wo_h * wo_h) / (eta * eta)))
        refr = -wo_i / eta[:, None] + (wo_h / eta - cos_t)[:, None] * hw
        wi[i] = np.where(refl[:, None], _reflect(wo_i, hw), refr)
        lobe[i] = np.where(refl, GLASS_R, GLASS_T)
        ok[i] = rt > 0
    is_delta = h.delta[rows, lobe] & ok
    is_refl = ((lobe == COAT) | (lobe == METAL) | (lobe == GLASS_R)) & ~rg

    # -- Directions, each lobe kind on its own rows ---------------------------
    # Diffuse and the metal's multiple-scattering lobe: cosine hemisphere about ns
    i = np.nonzero(ok & ((lobe == DIFFUSE) | (lobe == METAL_MS)))[0]
    if i.size:
        t_f, b_f = orthonormal_basis(h.ns[i])
        loc = cosine_hemisphere(u[i, 1:3])
        wi[i] = loc[:, 0:1] * t_f + loc[:, 1:2] * b_f + loc[:, 2:3] * h.ns[i]
    # Rough reflection: GGX visible normal, then mirror about it
    i = np.nonzero(ok & is_refl & h.rough)[0]
    if i.size:
        t_f, b_f = orthonormal_basis(h.nss[i])
        wo_i = h.wo[i]
        wo_loc = np.stack([_dot(wo_i, t_f), _dot(wo_i, b_f), np.maximum(h.cos_o[i], 1e-6)], axis=-1)
        wo_loc /= np.linalg.norm(wo_loc, axis=-1, keepdims=True)
        hl = _ggx_sample_vndf(wo_loc, h.alpha[i], u[i, 1:3])
        hw = hl[:, 0:1] * t_f + hl[:, 1:2] * b_f + hl[:, 2:3] * h.nss[i]
        wi[i] = _reflect(wo_i, hw)
    # Smooth reflection: mirror about the specular normal nss
    i = np.nonzero(ok & is_refl & ~h.rough)[0]
    if i.size:
        wi[i] = _reflect(h.wo[i], h.nss[i])
    # Smooth refraction through nss (entering: eta = ior; leaving: 1 / ior)
    i = np.nonzero(ok & (lobe == GLASS_T) & ~rg)[0]
    if i.size:
        eta = h.eta_glass[i]
        cos_o = np.clip(h.cos_o[i], 0.0, 1.0)
        cos_t = np.sqrt(np.maximum(0.0, 1.0 - (1.0 - cos_o ** 2) / (eta * eta)))
        wi[i] = -h.wo[i] / eta[:, None] + (cos_o / eta - cos_t)[:, None] * h.nss[i]
    wi /= np.maximum(np.linalg.norm(wi, axis=-1, keepdims=True), 1e-300)

    # -- Delta lobes: Fresnel / colour throughput over the selection probability
    i = np.nonzero(is_delta)[0]
    if i.size:
        li = lobe[i]
        thr = np.zeros((i.size, 3))
        thr += np.where(li == COAT, h.w_base[i] * h.F_coat[i], 0.0)[:, None]
        thr += np.where(li == METAL, h.w_metal[i], 0.0)[:, None] * h.F_metal[i]
        thr += np.where(li == GLASS_R, h.w_glass[i] * h.F_glass[i], 0.0)[:, None] * h.tint_r[i]
        thr += np.where(li == GLASS_T, h.w_glass[i] * (1.0 - h.F_glass[i]), 0.0)[:, None] * h.tint[i]
        # Reflections must stay above ng, refractions cross it (no leaks)
        side = _dot(wi[i], h.ng[i])
        good = np.where(li == GLASS_T, side < 0, side > 0)
        weight[i] = np.where(good[:, None], thr / p_chosen[i][:, None], 0.0)

    # -- Non-delta lobes: mixture f * cos / pdf over every non-delta lobe; a reflection lobe's
    # sample below ng or a refraction's above it is 0
    i = np.nonzero(ok & ~is_delta)[0]
    if i.size:
        hs = h.take(i)
        f, pdf = _eval_pdf(hs, wi[i])
        cos_i = np.abs(_dot(wi[i], hs.ns))
        keep = (pdf > 0) & _on_lobe_side(lobe[i], _dot(wi[i], hs.ng))
        weight[i] = np.where(keep[:, None], f * (cos_i / np.maximum(pdf, 1e-300))[:, None], 0.0)
    if residual:
        return wi, weight, is_delta, np.where(ok, lobe, -1), np.where(ok, u_res, 0.0)
    return wi, weight, is_delta, np.where(ok, lobe, -1)


_BELOW_ONE = 0.9999999999999999     # the largest float64 below 1 (the kernel's clip of u_res)


def _on_lobe_side(lobe: np.ndarray, side: np.ndarray) -> np.ndarray:
    """(n,) bool: wi . ng (side) is where the lobe sends light: below for GLASS_T, above otherwise."""
    return np.where(lobe == GLASS_T, side < 0.0, side > 0.0)


def diffuse_albedo(table: MaterialTable, mat, wo, ns) -> np.ndarray:
    """Diffuse reflectance (n, 3) after the coat: w_base * (1 - F_coat(wo)) * base_color (smooth coat:
    specular F_diel; rough: specular times the tabulated rough-coat albedo).

    Photon-map radiance = diffuse_albedo / pi * irradiance.  ``ns`` may face
    either way (the cosine is taken as |wo . ns|).
    """
    mat = np.asarray(mat, dtype=np.int64)
    m = np.where(mat < 0, table.size, mat)
    cos_o = np.minimum(np.abs(_dot(np.asarray(wo, float), np.asarray(ns, float))), 1.0)
    rough = table.roughness[m] > 0.0
    F = table.specular[m] * np.where(rough, _coat_albedo(cos_o, np.maximum(table.alpha[m], 1e-4), table.ior[m]),
                                     fresnel_dielectric(cos_o, table.ior[m]))
    return (table.w_base[m] * (1.0 - F))[:, None] * table.base_color[m]


def has_nondelta(table: MaterialTable, mat) -> np.ndarray:
    """(n,) bool: the material has a lobe that is not a delta (diffuse or rough), i.e. shade / store photons here."""
    mat = np.asarray(mat, dtype=np.int64)
    return table.nondelta[np.where(mat < 0, table.size, mat)]


def emission(table: MaterialTable, mat) -> np.ndarray:
    """Emitted radiance (n, 3) W/(m^2 sr), both sides; 0 for misses (mat = -1)."""
    mat = np.asarray(mat, dtype=np.int64)
    return table.emission[np.where(mat < 0, table.size, mat)]

