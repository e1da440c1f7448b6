"""Rough (frosted) glass: GGX refraction (Walter et al. 2007) with Cycles' glass energy compensation.

A rough dielectric interface of ior 1.5, entered and left: its white-furnace albedo (reflection +
refraction) is 1 with the compensation (Cycles' Multiscatter GGX glass preserves energy by
construction), and the single-scattering part alone equals the tabulated glass albedo and an
independent quadrature of Walter's BTDF + BRDF; the sampling density equals the pdf the mixture
reports (histogram); the sample weight's expectation equals the integral of f cos from bsdf_eval
over the whole sphere (both hemispheres); the refraction obeys the generalised reciprocity
f(wo, wi) / n_i^2 = f(wi, wo) / n_o^2 once the per-wo compensation is divided out; the shipped
table kernels/glass_albedo.npy is its construction.
"""
import numpy as np
import pytest

from oracles import bsdf_numpy as oracle
from stpm_core.bsdf import MaterialTable, bsdf_eval, bsdf_pdf, bsdf_sample
from stpm_core.kernels import bsdf as kb
from stpm_core.kernels import closure as kc
from stpm_core.sampling import uniform_sphere
from stpm_core.scene import Material

Z = np.array([0.0, 0.0, 1.0])
IOR = 1.5


def _wo(mu, side, n):
    return np.tile([np.sqrt(1 - mu * mu), 0.0, side * mu], (n, 1))


def _sample(mat, mu, side, n=200_000, seed=0):
    table = MaterialTable([mat])
    rng = np.random.default_rng(seed)
    wo = _wo(mu, side, n)
    N = np.tile(Z, (n, 1))
    wi, w, delta = bsdf_sample(table, np.zeros(n, int), wo, N, N, rng.random((n, 3)))
    return table, wo, wi, w, delta


def _k_glass(table, wo):
    return oracle._Hit(table, np.zeros(len(wo), int), wo, np.tile(Z, (len(wo), 1)), np.tile(Z, (len(wo), 1))).k_glass


def test_rough_glass_closure_flags():
    rows = kc.pack_materials([Material.glass(IOR, roughness=0.3), Material.glass(IOR), Material.glass(1.0, roughness=0.3)])
    assert rows[0, kc.C_ROUGH_LOBE] == 1 and rows[0, kc.C_NONDELTA] == 1 and rows[0, kc.C_HAS_DELTA] == 0
    assert rows[1, kc.C_ROUGH_LOBE] == 0 and rows[1, kc.C_NONDELTA] == 0 and rows[1, kc.C_HAS_DELTA] == 1
    assert rows[2, kc.C_HAS_DELTA] == 1                        # ior 1: the refraction stays a delta (Cycles)


@pytest.mark.parametrize("roughness", [0.3, 0.6, 1.0])
@pytest.mark.parametrize("side", [1, -1])                    # entering (eta 1.5) / leaving (eta 1 / 1.5)
def test_white_furnace_rough_glass(roughness, side):
    """Compensated: R + T = 1 (within 1.5 %, the table's interpolation); single scattering alone (the
    weight / k_glass) = the tabulated glass albedo E(mu) within 0.5 %; nothing is a delta."""
    mat = Material.glass(IOR, roughness=roughness)
    E, _ = kb.ggx_albedo_tables()
    eta = IOR if side > 0 else 1 / IOR
    for mu in (0.15, 0.5, 0.9):
        table, wo, wi, w, delta = _sample(mat, mu, side)
        assert not delta.any()
        assert abs(w[:, 0].mean() - 1.0) < 0.015, (roughness, side, mu, w[:, 0].mean())
        ss = w[:, 0] / _k_glass(table, wo[:1])[0, 0]
        assert abs(ss.mean() - kb.glass_albedo(E, mu, roughness, eta)) < 0.005
        refracted = wi[:, 2] * side < 0
        assert refracted.mean() > 0.003 and (~refracted).mean() > 0.01   # both lobes are sampled


@pytest.mark.parametrize("roughness,mu,eta", [(0.3, 0.7, IOR), (0.6, 0.4, 1 / IOR), (0.6, 0.9, IOR), (1.0, 0.5, 1 / IOR)])
def test_glass_albedo_table_against_quadrature(roughness, mu, eta):
    """E_glass = int (f_R + f_T) cos over the sphere by a quadrature of Walter et al.'s single-scattering
    BRDF D G2 F / (4 cos_o) and BTDF D G2 (1 - F) |wo.h| |wi.h| eta^2 / (cos_o (wo.h + eta wi.h)^2),
    written here from the paper, not from the kernels."""
    a = roughness ** 2
    wo = np.array([np.sqrt(1 - mu * mu), 0, mu])
    m = 800
    th, ph = np.meshgrid((np.arange(m) + 0.5) / m * np.pi, (np.arange(m) + 0.5) / m * 2 * np.pi, indexing="ij")
    wi = np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], -1).reshape(-1, 3)
    dw = (np.sin(th) * (np.pi / m) * (2 * np.pi / m)).ravel()
    up = wi[:, 2] > 0
    h = np.where(up[:, None], wi + wo, -(wo + eta * wi))
    h /= np.linalg.norm(h, axis=1, keepdims=True)
    h *= np.sign(h[:, 2])[:, None]
    D = a * a / (np.pi * (h[:, 2] ** 2 * (a * a - 1) + 1) ** 2)
    lam = lambda c: 0.5 * (np.sqrt(1 + a * a * (1 - c * c) / (c * c)) - 1)
    G2 = 1 / (1 + lam(mu) + lam(wi[:, 2]))
    c = np.clip(h @ wo, 0, 1)
    g2 = eta * eta - 1 + c * c
    gg = np.sqrt(np.maximum(g2, 0))
    with np.errstate(divide="ignore", invalid="ignore"):
        F = np.where(g2 > 0, 0.5 * ((gg - c) / (gg + c)) ** 2 * (1 + ((c * (gg + c) - 1) / (c * (gg - c) + 1)) ** 2), 1.0)
    wo_h, wi_h = h @ wo, np.sum(wi * h, axis=1)
    f_r = D * G2 * F / (4 * mu)
    f_t = D * G2 * (1 - F) * np.abs(wo_h * wi_h) * eta * eta / (mu * (wo_h + eta * wi_h) ** 2)
    ok_t = (wo_h > 0) & (wi_h < 0)
    E_quad = np.sum(np.where(up, f_r, np.where(ok_t, f_t, 0.0)) * dw)
    E, _ = kb.ggx_albedo_tables()
    assert abs(kb.glass_albedo(E, mu, roughness, eta) - E_quad) < 0.006, (kb.glass_albedo(E, mu, roughness, eta), E_quad)


@pytest.mark.parametrize("side,roughness", [(1, 0.3), (-1, 0.3), (1, 0.7), (-1, 0.7)])
@pytest.mark.parametrize("reflection_tint", [None, (0.2, 0.5, 0.9)])
def test_pdf_matches_sample_histogram_rough_glass(side, roughness, reflection_tint):
    """bsdf_pdf integrated over regions of both hemispheres equals the fraction of samples landing there
    (with a reflection tint too: Cycles' reflect / refract split F mean(tint_r) against (1 - F) mean(tint_t))."""
    mat = Material.glass(IOR, color=(0.8, 0.6, 0.4), roughness=roughness)
    mat.reflection_tint = None if reflection_tint is None else np.array(reflection_tint)
    table, wo, wi, w, _ = _sample(mat, 0.6, side, n=300_000)
    rng = np.random.default_rng(3)
    n = 600_000
    u = uniform_sphere(rng.random((n, 2)))
    N = np.tile(Z, (n, 1))
    p = bsdf_pdf(table, np.zeros(n, int), np.tile(wo[0], (n, 1)), u, N, N)
    for region in (lambda d: d[:, 2] * side < 0,                                # refracted
                   lambda d: (d[:, 2] * side < 0) & (d[:, 0] < -0.3),           # around the refraction peak
                   lambda d: (d[:, 2] * side > 0) & (d[:, 0] < -0.3),           # around the mirror direction
                   lambda d: (d[:, 2] * side > 0) & (d[:, 1] > 0.3)):
        frac = np.mean(region(wi) & (w[:, 0] > 0))
        integral = np.mean(p * region(u)) * 4 * np.pi
        assert abs(frac - integral) < 0.01, (frac, integral)


@pytest.mark.parametrize("mat", [
    Material.glass(IOR, color=(0.9, 0.5, 0.3), roughness=0.4),
    Material(base_color=np.array([0.9, 0.5, 0.3]), transmission=1.0, roughness=0.4, ior=IOR,
             reflection_tint=np.array([0.9, 0.5, 0.3])),                                         # Glass BSDF
    Material(base_color=np.array([0.7, 0.6, 0.5]), transmission=0.6, roughness=0.5, ior=IOR,
             reflection_tint=np.array([0.2, 0.4, 1.0])),                                         # tinted, + diffuse
    Material(base_color=np.array([0.7, 0.6, 0.5]), transmission=0.6, roughness=0.5, ior=IOR),     # glass + diffuse
    Material(base_color=np.array([0.8, 0.8, 0.8]), metallic=0.4, transmission=0.8, roughness=0.3, ior=IOR),
])
@pytest.mark.parametrize("side", [1, -1])
def test_sample_weight_matches_eval_integral_rough_glass(mat, side):
    """E[weight g(wi)] from bsdf_sample equals the integral of f |cos| g over the sphere from bsdf_eval."""
    table, wo, wi, w, delta = _sample(mat, 0.55, side, n=200_000)
    assert not delta.any()
    rng = np.random.default_rng(1)
    n = 400_000
    wu = uniform_sphere(rng.random((n, 2)))
    N = np.tile(Z, (n, 1))
    fu = bsdf_eval(table, np.zeros(n, int), np.tile(wo[0], (n, 1)), wu, N, N) * (np.abs(wu[:, 2]) * 4 * np.pi)[:, None]
    for g in (lambda d: np.ones(len(d)), lambda d: (d[:, 2] * side < 0).astype(float),
              lambda d: (d[:, 0] > 0.2).astype(float)):
        for ch in (0, 2):
            v, vu = w[:, ch] * g(wi), fu[:, ch] * g(wu)
            se = np.hypot(v.std() / np.sqrt(len(v)), vu.std() / np.sqrt(len(vu)))
            assert abs(v.mean() - vu.mean()) < 4 * se + 1e-3, (ch, v.mean(), vu.mean())


def test_refraction_reciprocity():
    """Walter et al.'s BTDF (no 1 / eta^2 radiance scaling, as Cycles): f(a, b) / n_b^2 = f(b, a) / n_a^2
    for a in air (n = 1), b in the glass (n = 1.5), once the compensation k_glass(wo) is divided out."""
    mat = Material.glass(IOR, color=(0.7, 0.8, 0.9), roughness=0.5)
    table = MaterialTable([mat])
    rng = np.random.default_rng(4)
    n = 4000
    a = uniform_sphere(rng.random((n, 2)))
    b = uniform_sphere(rng.random((n, 2)))
    a[:, 2], b[:, 2] = np.abs(a[:, 2]), -np.abs(b[:, 2])
    N = np.tile(Z, (n, 1))
    f_ab = bsdf_eval(table, np.zeros(n, int), a, b, N, N) / _k_glass(table, a)
    f_ba = bsdf_eval(table, np.zeros(n, int), b, a, N, N) / _k_glass(table, b)
    assert (f_ab.max(axis=1) > 0).mean() > 0.15          # (a refraction pair needs wo . wi < -1 / eta)
    np.testing.assert_allclose(f_ab / IOR ** 2, f_ba, rtol=1e-9, atol=1e-13)


def test_refraction_leaves_through_ng_and_tir():
    """Refracted samples cross ng; leaving beyond the critical angle with a small roughness, nearly all
    light is reflected back (total internal reflection at almost every microfacet)."""
    mat = Material.glass(IOR, roughness=0.05)
    _, wo, wi, w, _ = _sample(mat, 0.3, -1)                   # leaving at 72.5 deg, critical 41.8 deg
    assert np.mean(w[:, 0] * (wi[:, 2] > 0)) < 1e-3
    assert abs(np.mean(w[:, 0]) - 1.0) < 0.01
    _, wo, wi, w, _ = _sample(mat, 0.8, 1)
    live = w[:, 0] > 0
    refracted = live & (wi[:, 2] < 0)
    assert refracted.mean() > 0.9
    # Snell's law about the macro normal, blurred by the roughness
    sin_t = np.hypot(wi[refracted, 0], wi[refracted, 1])
    assert abs(np.median(sin_t) - 0.6 / IOR) < 0.02


def test_glass_table_file_is_its_construction():
    """kernels/glass_albedo.npy (loaded by ggx_albedo_tables) = build_glass_table, on one z slice."""
    E, E_avg = kb.ggx_albedo_tables()
    ks = [7]
    got = E[33:].reshape(2, 16, 32, 32)[:, ks]
    np.testing.assert_allclose(got, kb.build_glass_table(slices=ks), rtol=0, atol=1e-12)
    # E_avg's glass entries: 2 int E mu dmu (midpoint rule)
    mu = (np.arange(32) + 0.5) / 32
    EG = E[33:].reshape(2, 16, 32, 32)
    np.testing.assert_allclose(E_avg[32:].reshape(2, 16, 32), 2 * np.mean(EG * mu[None, None, :, None], axis=2),
                               rtol=1e-12)


def test_glass_albedo_lookups_match_the_oracle():
    rng = np.random.default_rng(8)
    E, E_avg = kb.ggx_albedo_tables()
    mu = np.concatenate([rng.random(300), [0.0, 1.0]])
    r = np.concatenate([rng.random(300), [0.0, 1.0]])
    eta = np.concatenate([rng.choice([1.0, 1.33, 1.5, 1 / 1.5, 2.4, 1 / 2.4, 10.0, 0.1], 300), [1.5, 1 / 1.5]])
    got = np.array([kb.glass_albedo(E, a, b, c) for a, b, c in zip(mu, r, eta)])
    np.testing.assert_allclose(got, oracle._glass_albedo(mu, r, eta), rtol=1e-13, atol=1e-15)
    got = np.array([kb.glass_albedo_avg(E_avg, b, c) for b, c in zip(r, eta)])
    np.testing.assert_allclose(got, oracle._glass_albedo_avg(r, eta), rtol=1e-13, atol=1e-15)
