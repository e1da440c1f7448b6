"""Shutter-curve numerics: the inverse CDF, the window mass and KD4D's clipped-ball measure.

The curve is piecewise linear, so every quantity here has an exact answer:
``Shutter.cdf(Shutter.sample(xi)) = xi`` to rounding, and ``slab_ball_volume``
(a quadratic times the density) is checked against an independent quadrature
that splits the span at the curve's knots.  Curves include the hard ones: a
spike narrower than any fixed quadrature's node spacing, trailing zeros,
weights at the ends of the float range.
"""
from __future__ import annotations

import numpy as np
import pytest

from scenes import make_scene, moving, ortho_camera_down, plane_mesh, point_light, sphere_mesh
from stpm_core.errors import SceneError
from stpm_core.photons.estimators import PhotonMap, shutter_mass, slab_ball_volume
from stpm_core.photons.record import make_records
from stpm_core.render import render
from stpm_core.scene import Material
from stpm_core.settings import RenderSettings
from stpm_core.shutter import Shutter

_RNG = np.random.default_rng(20261125)
_SPIKE = np.zeros(101)
_SPIKE[50] = 1.0                                  # a triangle of support [0.49, 0.51]: 2 % of the shutter
_NARROW = np.zeros(201)
_NARROW[100] = 1.0                                # support [0.495, 0.505]: 1 % of the shutter
CURVES = {
    "box": None,
    "flat": np.full(7, 0.3),
    "triangle": np.array([0.0, 1.0, 0.0]),
    "ramp": np.array([1.0, 3.0]),
    "spike": _SPIKE,
    "narrow": _NARROW,
    "random101": _RNG.random(101),
    "random33_gaps": _RNG.random(33) * (_RNG.random(33) > 0.5),
}
_GX, _GW = np.polynomial.legendre.leggauss(12)


def _reference_volume(curve, R, t, s):
    """V/s by 12-point Gauss-Legendre on each piece of [t - R/s, t + R/s] cut at 0, 1 and the knots (n,)."""
    c = np.ones(2) if curve is None else np.asarray(curve, dtype=np.float64)
    u = np.linspace(0.0, 1.0, c.shape[0])
    total = np.sum(0.5 * (c[1:] + c[:-1]) * np.diff(u))
    out = np.zeros(len(R))
    for i, (Ri, ti) in enumerate(zip(R, t)):
        a, b = max(ti - Ri / s, 0.0), min(ti + Ri / s, 1.0)
        if b <= a:
            continue
        cuts = np.concatenate([[a], u[(u > a) & (u < b)], [b]])
        for lo, hi in zip(cuts[:-1], cuts[1:]):
            tau = 0.5 * (lo + hi) + 0.5 * (hi - lo) * _GX
            f = np.pi * (Ri * Ri - s * s * (tau - ti) ** 2) * np.interp(tau, u, c) / total
            out[i] += 0.5 * (hi - lo) * (_GW @ f)
    return out


# ----------------------------------------------------------------------------
# slab_ball_volume: exact for the piecewise-linear density
# ----------------------------------------------------------------------------
@pytest.mark.parametrize("name", list(CURVES))
def test_slab_ball_volume_matches_fine_quadrature(name):
    curve = CURVES[name]
    shutter = Shutter(1.0, 2.0, curve=curve)
    rng = np.random.default_rng(7)
    n = 400
    t = np.concatenate([rng.random(n - 40), rng.uniform(-0.3, 1.3, 20), [0.0, 1.0, 0.5, 0.49, 0.51] * 4])
    for s in (1e-3, 0.37, 1.0, 40.0):
        half_span = 10 ** rng.uniform(-4, 0.7, n)                 # R/s from 1e-4 to 5 shutters
        R = half_span * s
        V = slab_ball_volume(shutter, R, t, s)
        ref = _reference_volume(curve, R, t, s)
        assert np.all(np.isfinite(V)) and np.all(V >= 0)
        assert np.all((V == 0) == (ref == 0))                     # zero exactly where no support is spanned
        nz = ref > 0
        assert np.max(np.abs(V[nz] / ref[nz] - 1)) < 1e-9


def test_slab_ball_volume_closed_forms():
    # box: unclipped (4/3) pi R^3 / s, halved at the shutter's ends; a flat curve is the same shutter
    R, t, s = np.array([0.1, 0.1, 0.1]), np.array([0.5, 0.0, 1.0]), 0.5
    for shutter in (Shutter(1.0, 2.0), Shutter(1.0, 2.0, curve=np.full(5, 2.0))):
        V = slab_ball_volume(shutter, R, t, s)
        assert np.allclose(V, 4 / 3 * np.pi * 0.1 ** 3 / s * np.array([1.0, 0.5, 0.5]), rtol=1e-13)
    # a span covering the whole shutter: pi (R^2 - s^2 E[(tau - t)^2]); triangle: E = 1/24 + (t - 1/2)^2
    tri = Shutter(1.0, 2.0, curve=np.array([0.0, 1.0, 0.0]))
    t = np.array([0.0, 0.3, 0.5, 1.0])
    V = slab_ball_volume(tri, np.full(4, 3.0), t, 1.0)
    assert np.allclose(V, np.pi * (9.0 - (1 / 24 + (t - 0.5) ** 2)), rtol=1e-13)


def test_slab_ball_volume_sees_a_spike_between_any_fixed_nodes():
    # the reviewer's case: ball centred on a flash of 1 % of the shutter, spanning +-0.2: the whole
    # flash is inside, so V/s = pi R^2 - s^2 pi E[(tau - t)^2] ~ pi R^2 (fixed 8-node rule gave 0)
    flash = np.zeros(101)
    flash[50:52] = 1.0                                            # 1 on [0.50, 0.51], ramps to 0 at 0.49, 0.52
    shutter = Shutter(0.75, 1.25, curve=flash)
    V = slab_ball_volume(shutter, np.array([0.2]), np.array([0.505]), 1.0)[0]
    assert 0.99 * np.pi * 0.04 < V < np.pi * 0.04
    # spans that only graze the support's ends: tiny but > 0 and finite; spans beside it: exactly 0
    lo, hi = shutter.support
    assert (lo, hi) == pytest.approx((0.49, 0.52))
    R = np.array([0.1, 0.1, 0.1, 0.1, 1e-6, 1e-6])
    t = np.array([lo - 0.1 + 1e-9, hi + 0.1 - 1e-9, lo - 0.1 - 1e-9, hi + 0.1 + 1e-9, 0.505, 0.2])
    V = slab_ball_volume(shutter, R, t, 1.0)
    assert np.all(V[:2] > 0) and np.all(np.isfinite(V))
    assert np.all(V[2:4] == 0) and V[4] > 0 and V[5] == 0


def test_kd4d_normalisation_gives_zero_not_inf_where_no_support_is_spanned():
    # PhotonMap._normalise divides by max(measure, 1e-300): with measure 0 the photons found are 0 too
    flash = np.zeros(101)
    flash[50] = 1.0
    shutter = Shutter(1.0, 2.0, curve=flash)
    rng = np.random.default_rng(3)
    n = 2000
    recs = make_records(np.column_stack([rng.uniform(-0.5, 0.5, (n, 2)), np.zeros(n)]), np.tile([0.0, 0.0, 1.0], (n, 1)),
                        np.full((n, 3), 1.0 / n), shutter.sample(rng.random(n)))
    m = PhotonMap(recs, shutter, time_scale=1.0)
    E = m._normalise("KD4D", np.zeros((2, 3)), np.array([0.01, 0.01]), np.zeros(2), np.array([0.1, 0.9]), "BOX")
    assert np.array_equal(E, np.zeros((2, 3)))


@pytest.mark.parametrize("curve", [_SPIKE, _NARROW, np.exp(-0.5 * ((np.linspace(0, 1, 101) - 0.5) / 0.03) ** 2)],
                         ids=["spike", "narrow", "gaussian"])
def test_kd4d_reads_uniform_irradiance_at_any_time_with_a_flash_shutter(curve):
    # E = 1 W/m^2 on a plane, photon times from a flash-like shutter; KD4D queried at times all over
    # the shutter (mostly where no photon is): the ball reaches the flash and its measure counts the
    # flash's mass only, so the estimate stays unbiased and finite
    shutter = Shutter(1.0, 2.0, curve=curve)
    rng = np.random.default_rng(11)
    n = 60_000
    pos = np.column_stack([rng.uniform(-0.5, 0.5, (n, 2)), np.zeros(n)])
    recs = make_records(pos, np.tile([0.0, 0.0, 1.0], (n, 1)), np.full((n, 3), 1.0 / n),
                        shutter.sample((np.arange(n) + rng.random(n)) / n))
    m = PhotonMap(recs, shutter, time_scale=1.0)
    q = 6000
    p = np.column_stack([rng.uniform(-0.35, 0.35, (q, 2)), np.zeros(q)])
    E = m.estimate(p, np.tile([0.0, 0.0, 1.0], (q, 1)), rng.random(q), estimator="KD4D", k=50)[:, 0]
    assert np.all(np.isfinite(E))
    assert abs(E.mean() - 1.0) < 0.03


def test_kd4d_render_with_a_flash_shutter_is_finite_and_agrees_with_temporal():
    # the reviewer's scene: glass sphere sliding over a floor, shutter curve a flash on 1 % of it
    flash = np.zeros(101)
    flash[50:52] = 1.0
    mats = [Material.diffuse((0.8, 0.8, 0.8)), Material.glass(1.5)]
    scene = make_scene([plane_mesh(6.0), (sphere_mesh(0.5, 10, 20, material=1), moving((-0.3, 0, 1), (0.3, 0, 1)))],
                       mats, ortho_camera_down(5.0, 4.0), [point_light((0.3, 0.2, 3), 300)],
                       shutter=Shutter(0.75, 1.25, curve=flash), resolution=(24, 16))
    caustic = {}
    for est in ("TEMPORAL", "KD4D"):
        res = render(scene, RenderSettings(samples=4, photons_caustic=20000, photons_global=0, k_nearest=16, seed=1,
                                           filter_width=0.0, estimator=est))
        assert all(np.all(np.isfinite(a)) for a in res.passes.values())
        caustic[est] = float(res.passes["Caustic"][..., :3].mean())
    assert caustic["TEMPORAL"] > 0
    assert abs(caustic["KD4D"] / caustic["TEMPORAL"] - 1) < 0.1


# ----------------------------------------------------------------------------
# Shutter.sample / cdf / shutter_mass: one consistent map, inside the support
# ----------------------------------------------------------------------------
def _random_curves(rng):
    yield rng.random(101)
    yield rng.random(33) * (rng.random(33) > 0.6)                 # gaps and zero ends
    yield 1.0 + 1e-13 * rng.random(50)                            # nearly flat: slopes ~ 1e-11
    yield np.concatenate([np.zeros(40), rng.random(3), np.zeros(60)])
    yield rng.random(17) ** 8 * 1e-310                            # subnormal weights
    yield rng.random(9) * 1.7e308                                 # near the top of the float range
    yield np.array([0.0, 5e-324, 0.0])


def test_cdf_inverts_sample_and_sample_stays_in_the_support():
    rng = np.random.default_rng(5)
    xi = np.concatenate([rng.random(20_000), [0.0, 1.0, np.nextafter(1.0, 0.0), 5e-324, 0.5]])
    for curve in _random_curves(rng):
        shutter = Shutter(1.0, 2.0, curve=curve)
        u = shutter.sample(xi)
        assert np.all(np.isfinite(u))
        assert np.max(np.abs(shutter.cdf(u) - xi)) < 1e-12
        lo, hi = shutter.support
        assert np.all((u >= lo) & (u <= hi))
        assert shutter.sample(np.array([0.0]))[0] == lo and shutter.sample(np.array([1.0]))[0] == hi
        order = np.argsort(xi)
        assert np.all(np.diff(u[order]) >= 0)                     # monotone: strata stay strata
        # window masses agree with the sampled times
        x1, x2 = np.sort(rng.random((2, 500)), axis=0)
        assert np.allclose(shutter_mass(shutter, shutter.sample(x1), shutter.sample(x2)), x2 - x1, rtol=0, atol=1e-12)


def test_curve_scale_does_not_matter():
    xi = np.linspace(0.0, 1.0, 101)
    base = np.array([0.0, 1.0, 3.0, 2.0])
    ref = Shutter(1.0, 2.0, curve=base)
    for k in (5e-321, 1e-300, 1e300, 1.7e308 / 3):
        sh = Shutter(1.0, 2.0, curve=base * k)
        assert np.allclose(sh.sample(xi), ref.sample(xi), rtol=0, atol=1e-15)
        assert np.allclose(sh.density(xi), ref.density(xi), rtol=1e-12)
    # flat curves at the ends of the float range are box shutters: u = xi
    for c in ([1e-320, 1e-320], [1.7e308] * 3):
        assert np.allclose(Shutter(1.0, 2.0, curve=np.array(c)).sample(xi), xi, rtol=0, atol=1e-15)
    # a curve whose trapezoid areas underflow is a triangle, not NaN
    tri = Shutter(1.0, 2.0, curve=np.array([0.0, 5e-324, 0.0]))
    assert np.allclose(tri.sample(np.array([0.125, 0.5, 0.875])), [0.25, 0.5, 0.75], atol=1e-15)


def test_sample_never_lands_where_the_density_is_zero():
    sh = Shutter(0.75, 1.25, curve=np.array([1.0, 0.0, 0.0, 0.0]))
    u = sh.sample(np.array([0.999999, np.nextafter(1.0, 0.0), 1.0]))
    assert u[-1] == pytest.approx(1 / 3, abs=1e-15) and np.all(u <= 1 / 3 + 1e-15)
    lead = Shutter(1.0, 2.0, curve=np.array([0.0, 0.0, 0.0, 1.0, 0.0]))
    assert lead.sample(np.array([0.0]))[0] == 0.5 and lead.sample(np.array([1.0]))[0] == 1.0
    assert lead.support == (0.5, 1.0)


@pytest.mark.parametrize("curve", [[0.0, 0.0, 0.0], [0.0], [1.0, np.inf], [1.0, np.nan], [1.0, -1e-300], [np.inf, np.inf]])
def test_bad_curves_are_refused(curve):
    with pytest.raises(SceneError):
        Shutter(1.0, 2.0, curve=np.array(curve))
