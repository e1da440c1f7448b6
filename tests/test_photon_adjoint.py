"""Photons carry the adjoint BSDF: the power a photon bounce sends into each direction is the
BSDF as the camera side (and Cycles) evaluates it seen *from* that direction.

Cycles' closures are not reciprocal: a coated base's diffuse lobe is scaled by 1 - (the coat's
albedo at the viewing direction wo), rough coats and metals by energy compensation at wo.  A photon
arriving from the light along wo and leaving along wi stands for light that a viewer at wi sees,
so ``kernels.photon_paths.photon_bounce`` must weigh it by f(wi, wo) |cos wi| / pdf, not f(wo, wi)
(docs/photon-mapping.md, "Tracing"; Veach 1997, 3.7).  With f(wo, wi) the room's walls, which see
its coated floor at grazing angles while the sun strikes it at 55 degrees, read up to 10 % bright
(docs/blender.md, the textured room).

The test drives ``photon_bounce`` itself (Russian roulette included) with photons arriving along
one direction, bins the power it sends on by outgoing angle, and compares each bin with the
integral of ``bsdf_eval_pdf(wo = outgoing, wi = toward the light) |cos|`` over the bin.
"""
from __future__ import annotations

import numpy as np
import pytest

from stpm_core.bsdf import MaterialTable
from stpm_core.kernels import bsdf as kb
from stpm_core.kernels.closure import N_CLOSURE
from stpm_core.kernels.photon_paths import photon_bounce
from stpm_core.sampling import uniform_sphere
from stpm_core.scene import Material

#: outgoing polar-angle bins (radians from the normal): near the normal, middle (past the 55-degree
#: mirror direction, where a smooth coat's delta lobe sends its photons), grazing
BINS = ((0.0, 0.5), (1.0, 1.25), (1.3, 1.5))


def _bounce(mat: Material, theta_in: float, n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """(outgoing directions (m, 3), their powers (m, 3)) of n global photons of power 1 each arriving
    at a plane (normal +Z) from polar angle theta_in, after one ``photon_bounce``."""
    table = MaterialTable([mat])
    E, E_avg = kb.ggx_albedo_tables()
    rng = np.random.default_rng(seed)
    z = np.tile([0.0, 0.0, 1.0], (n, 1))
    d = np.tile([-np.sin(theta_in), 0.0, -np.cos(theta_in)], (n, 1))       # travelling toward the plane
    C = np.ascontiguousarray(np.repeat(table.closures[:1], n, axis=0))
    assert C.shape == (n, N_CLOSURE)
    i32 = lambda v: np.full(n, v, np.int32)
    out = [np.empty((n, 3)), np.empty((n, 3)), np.empty((n, 3)), np.empty(n), i32(0), i32(0), i32(0), i32(0),
           np.empty(n)]
    store = np.empty(n, np.int64)
    _, n_next = photon_bounce(np.arange(n), np.zeros((n, 3)), z, z, d, C, E, E_avg, np.ones((n, 3)), np.zeros(n),
                              i32(0), i32(0), i32(0), i32(0), False, 1, 1 << 20, 1, False, False,
                              rng.random((n, 3)), rng.random(n), np.full(n, 1e-4), 0.5, store, *out)
    return out[1][:n_next], out[2][:n_next]


def _expected(mat: Material, theta_in: float, n: int, seed: int) -> tuple:
    """((len(BINS), 3) integral over each bin of f(wo = outgoing, wi = toward the light) cos(outgoing),
    the (n, 3) samples f cos / pdf, their (n,) polar angles): n uniform directions on the upper
    hemisphere (pdf 1 / 2 pi)."""
    table = MaterialTable([mat])
    E, E_avg = kb.ggx_albedo_tables()
    rng = np.random.default_rng(seed)
    w = uniform_sphere(rng.random((n, 2)))
    w[:, 2] = np.abs(w[:, 2])
    z = np.tile([0.0, 0.0, 1.0], (n, 1))
    light = np.tile([np.sin(theta_in), 0.0, np.cos(theta_in)], (n, 1))
    f = np.empty((n, 3))
    kb.eval_batch(table.closures, E, E_avg, np.zeros(n, np.int64), w, light, z, z, f, np.empty(0))
    val = f * w[:, 2:3] * 2.0 * np.pi
    th = np.arccos(np.clip(w[:, 2], -1.0, 1.0))
    return np.array([[val[(th >= a) & (th < b), c].sum() / n for c in range(3)] for a, b in BINS]), val, th


@pytest.mark.parametrize("mat", [
    Material(base_color=np.array([0.6, 0.4, 0.25]), specular=1.0, roughness=0.6, ior=1.5),    # the room's floor
    Material(base_color=np.array([0.7, 0.7, 0.7]), specular=1.0, roughness=0.0, ior=1.5),    # a smooth coat
    Material.mirror((0.95, 0.6, 0.45), roughness=0.35),                                       # rough copper
])
def test_photon_bounce_sends_the_power_a_viewer_there_sees(mat):
    theta_in = np.radians(55.0)
    n = 400_000
    wi, Phi = _bounce(mat, theta_in, n, seed=5)
    th = np.arccos(np.clip(wi[:, 2], -1.0, 1.0))
    want, val, th_u = _expected(mat, theta_in, n, seed=6)
    for b, (a, c) in enumerate(BINS):
        sel, sel_u = (th >= a) & (th < c), (th_u >= a) & (th_u < c)
        got = Phi[sel, 0].sum() / n
        se = np.hypot(np.sqrt(np.sum(Phi[sel, 0] ** 2)) / n, np.sqrt(np.sum(val[sel_u, 0] ** 2)) / n)
        assert want[b, 0] > 1e-3, (b, want[b, 0])
        assert abs(got - want[b, 0]) < 4.0 * se + 1e-4, (b, got, want[b, 0], se)
