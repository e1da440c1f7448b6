"""Method PROGRESSIVE: the shrinking space-time kernel, its look-ups, convergence, stops and merges.

Layers tested, cheapest first:

* the schedule V_i / V_1 against its product form;
* the compiled fixed-region look-ups (``FlatTree.range_sum``, ``FlatTree.knn_radius``) against a
  brute-force numpy oracle, photon by photon;
* one pass's estimate on synthetic photon maps with known irradiance (uniform, changing in time,
  a closed furnace): unbiased for its fixed kernel, shutter ends included;
* whole renders of the moving caustic / moving receiver with their exact images
  (``tests/test_compare.py``): the error falls with passes at a log-log slope <= -0.2 and below
  fixed-k TEMPORAL's, and no pass has a NaN or a negative pixel;
* stops: passes, time limit, noise threshold (its estimate against the true error), cancel;
* merges of partial results (``stpm merge``): bit-equal to one process, refusals.
"""
from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from scenes import make_scene, ortho_camera_down, plane_mesh, translate
from stpm_core.errors import RenderCancelled, SettingsError
from stpm_core.motion import MotionTransform
from stpm_core.photons.estimators import PhotonMap
from stpm_core.photons.maps import PhotonMaps
from stpm_core.photons.progressive import (PILOT_K, Pilot, ProgressiveMaps, auto_shrink_alpha, kernel_dims,
                                           shrink_ratio)
from stpm_core.photons.record import make_records
from stpm_core.progressive import PassSums, noise_estimate
from stpm_core.render import render
from stpm_core.scene import Light, Material
from stpm_core.settings import RenderSettings
from stpm_core.shutter import Shutter
from test_compare import analytic_moving_caustic, moving_caustic_scene

ROOT = Path(__file__).resolve().parents[1]
BOX = Shutter(1.0, 2.0)
UP = np.array([0.0, 0.0, 1.0])


# ----------------------------------------------------------------------------
# The schedule
# ----------------------------------------------------------------------------
@pytest.mark.parametrize("alpha", [0.2, 0.4, 2 / 3])
def test_shrink_ratio_is_the_product_of_the_recurrence(alpha):
    V = 1.0
    for i in range(1, 200):
        assert math.isclose(shrink_ratio(i, alpha), V, rel_tol=1e-12)
        V *= (i + alpha) / (i + 1)
    # V_i ~ i^(a - 1): the measure goes to zero, slower than 1 / i
    assert shrink_ratio(10_000, alpha) / shrink_ratio(1000, alpha) == pytest.approx(10 ** (alpha - 1), rel=1e-3)


def test_automatic_alpha_follows_the_kernel_dimension():
    assert kernel_dims("STANDARD") == 2 and kernel_dims("TEMPORAL") == 3 and kernel_dims("KD4D") == 3
    assert auto_shrink_alpha("STANDARD") == pytest.approx(0.5)
    assert auto_shrink_alpha("TEMPORAL") == pytest.approx(0.4) == auto_shrink_alpha("KD4D")


def test_pass_strata_cover_the_shutter_once_per_round():
    from stpm_core.progressive import pass_stratum
    from stpm_core.strata import STRATA_CAP, is_round_end
    assert [pass_stratum(i) for i in (1, 2, 3, 4)] == [(0.0, 1.0)] * 4           # pairs 1, 2: the whole shutter
    assert [pass_stratum(i) for i in range(5, 9)] == [(0.0, 0.5)] * 2 + [(0.5, 1.0)] * 2
    assert [pass_stratum(i)[0] for i in range(9, 17, 2)] == [0.0, 0.5, 0.25, 0.75]  # bit-reversed
    ends = [n for n in range(8 * STRATA_CAP + 1) if is_round_end(n)]
    C = STRATA_CAP
    assert ends == [0, 1, 2, 3, 4] + [2 ** k for k in range(3, (4 * C).bit_length())] + [4 * C + 2 * C, 4 * C + 4 * C]
    for a, b in zip(ends[4:], ends[5:]):                 # every round: each stratum once per pair, no gap
        odd = sorted(pass_stratum(i) for i in range(a + 1, b + 1, 2))
        assert odd == sorted(pass_stratum(i) for i in range(a + 2, b + 1, 2))   # the halves alike
        assert odd[0][0] == 0.0 and odd[-1][1] == 1.0
        assert all(x[1] == y[0] for x, y in zip(odd, odd[1:]))
        assert len({hi - lo for lo, hi in odd}) == 1
    with pytest.raises(ValueError):
        pass_stratum(0)


def test_an_image_holds_whole_rounds_and_passes_of_a_cut_round_are_left_out():
    """Passes 1..20: the image is the mean of passes 1..16 (a round of 8 strata began at 17); the
    preview shown after each pass includes them all; the halves are the odd / even passes of 1..16."""
    rng = np.random.default_rng(3)
    imgs = {i: {"Combined": rng.random((4, 5, 4)).astype(np.float32)} for i in range(1, 21)}
    s = PassSums(1)
    for i in range(1, 21):
        s.add(i, imgs[i])
        assert s.end - 1 in (0, 1, 2, 3, 4, 8, 16) and s.next == i + 1
    assert s.count == 16 and s.pending == 4
    want = sum(imgs[i]["Combined"].astype(np.float64) for i in range(1, 17)) / 16
    assert np.allclose(s.image()["Combined"], want, atol=1e-6)
    every = sum(imgs[i]["Combined"].astype(np.float64) for i in range(1, 21)) / 20
    assert np.allclose(s.preview()["Combined"], every, atol=1e-6)
    assert s.n_odd == s.n_even == 8
    # a stratified-free run (SPPM) folds every pass
    u = PassSums(1, stratified=False)
    for i in range(1, 6):
        u.add(i, imgs[i])
    assert u.count == 5 and u.pending == 0


def test_a_pass_traces_photons_and_camera_samples_in_its_stratum():
    from stpm_core.integrator import trace_image
    from stpm_core.lights import LightSet
    from stpm_core.photons import build_photon_maps
    from stpm_core.raycast import make_caster
    scene = moving_caustic_scene((24, 16))
    st = RenderSettings(**dict(BASE, photons_caustic=4000))
    caster, lights = make_caster(scene), LightSet(scene)
    maps = build_photon_maps(scene, st, caster, lights, time_override=(0.25, 0.5))
    t = maps.maps["caustic"].time
    assert t.size > 100 and t.min() >= 0.25 and t.max() <= 0.5
    seen = []

    class Spy:
        def has(self, kind):
            return kind == "caustic"

        def estimate(self, kind, p, ns, tq, ng=None):
            seen.append(np.asarray(tq).copy())
            return np.zeros((len(p), 3))
    trace_image(scene, st, caster, lights, Spy(), time_override=(0.25, 0.5))
    tq = np.concatenate(seen)
    assert tq.min() >= 0.25 and tq.max() <= 0.5 and tq.max() - tq.min() > 0.2


def test_settings_refuse_a_progressive_render_that_never_stops_and_bad_alphas():
    with pytest.raises(SettingsError, match="never stop"):
        RenderSettings(method="PROGRESSIVE", passes=0)
    RenderSettings(method="PROGRESSIVE", passes=0, time_limit=5.0)
    RenderSettings(method="PROGRESSIVE", passes=0, noise_threshold=0.05)
    for bad in (1.0, -0.1, float("nan"), "0.5"):
        with pytest.raises(SettingsError, match="shrink_alpha"):
            RenderSettings(method="PROGRESSIVE", shrink_alpha=bad)


# ----------------------------------------------------------------------------
# Compiled fixed-region look-ups against brute force
# ----------------------------------------------------------------------------
def _random_map(N, rng, s=0.8):
    pos = rng.uniform(-1, 1, (N, 3))
    pos[: N // 2, 2] = 0.0                                   # half of them on a plane
    wi = rng.normal(size=(N, 3))
    wi /= np.linalg.norm(wi, axis=1, keepdims=True)
    return PhotonMap(make_records(pos, wi, rng.exponential(1e-3, (N, 3)), rng.random(N)), BOX, time_scale=s)


@pytest.mark.parametrize("dims,shape,cone", [(3, "ball", False), (3, "ball", True), (4, "ball", False),
                                             (4, "ball", True), (4, "cyl", False), (4, "cyl", True)])
def test_range_sums_equal_brute_force(dims, shape, cone):
    rng = np.random.default_rng(dims + 10 * cone + (shape == "cyl"))
    m = _random_map(20_000, rng)
    tree = m.flat_tree(dims)
    n = 400
    q = np.zeros((n, 4))
    q[:, :3] = rng.uniform(-1, 1, (n, 3))
    q[: n // 2, 2] = 0.0
    q[:, 3] = m.time_scale * rng.random(n)
    ns = rng.normal(size=(n, 3)).astype(np.float32)
    rad = rng.uniform(0.02, 0.3, n)
    half = rng.uniform(0.01, 0.5, n) if shape == "cyl" else None
    Phi, cnt = tree.range_sum(q, ns, rad, half, cone, 1.1, 1)
    # oracle: every photon against every query, in float64 from the float32 records
    P = m.records["position"].astype(np.float64)
    T = m.time_scale * m.records["time"].astype(np.float64)
    d3 = np.linalg.norm(P[None] - q[:, None, :3], axis=2)
    dt = np.abs(T[None] - q[:, None, 3])
    if dims == 3:
        inside, dist = d3 < rad[:, None], d3
    elif shape == "ball":
        dist = np.sqrt(d3 ** 2 + dt ** 2)
        inside = dist < rad[:, None]
    else:
        inside, dist = (d3 < rad[:, None]) & (dt <= half[:, None]), d3
    side = (m.wi @ ns.T).T > 0
    w = np.where(inside & side, 1.0 - dist / (1.1 * rad[:, None]) if cone else 1.0, 0.0)
    assert np.array_equal(cnt, inside.sum(1))
    assert np.allclose(Phi, w @ m.power.astype(np.float64), rtol=1e-9, atol=1e-15)


@pytest.mark.parametrize("dims", [3, 4])
def test_capped_knn_radius_equals_brute_force(dims):
    rng = np.random.default_rng(dims)
    m = _random_map(5000, rng)
    tree = m.flat_tree(dims)
    q = np.zeros((300, 4))
    q[:, :3] = rng.uniform(-1.5, 1.5, (300, 3))
    q[:, 3] = m.time_scale * rng.random(300)
    P = m.records["position"].astype(np.float64)
    d2 = ((P[None] - q[:, None, :3]) ** 2).sum(2)
    if dims == 4:
        d2 += (m.time_scale * m.records["time"].astype(np.float64)[None] - q[:, None, 3]) ** 2
    kth = np.sqrt(np.sort(d2, axis=1)[:, PILOT_K - 1])
    assert np.allclose(tree.knn_radius(q, PILOT_K, np.inf, 2), kth, rtol=1e-12)
    cap = float(np.median(kth))
    assert np.allclose(tree.knn_radius(q, PILOT_K, cap, 2), np.minimum(kth, cap), rtol=1e-12)


# ----------------------------------------------------------------------------
# One pass's estimate on synthetic maps
# ----------------------------------------------------------------------------
def _maps(m):
    empty = PhotonMap(m.records[:0], m.shutter, time_scale=m.time_scale)
    return PhotonMaps({"caustic": m, "global": empty}, estimator="TEMPORAL", k=30, kernel="BOX", temporal_alpha=0,
                      time_scale=m.time_scale)


def _plane(N, seed, E_of_t=lambda t: np.ones_like(t), shutter=BOX):
    """Photons uniform on the unit square of z = 0, times stratified over the shutter, irradiance E(t) W/m^2."""
    rng = np.random.default_rng(seed)
    t = shutter.sample((np.arange(N) + rng.random(N)) / N)
    pos = np.column_stack([rng.uniform(-0.5, 0.5, (N, 2)), np.zeros(N)])
    Phi = np.repeat((E_of_t(t) / N)[:, None], 3, axis=1)
    return PhotonMap(make_records(pos, np.tile(UP, (N, 1)), Phi, t), shutter, time_scale=1.0)


def _pilot(estimator, N, seed, **kw):
    n_pilot = int(math.ceil(N * (PILOT_K - 1) / 30))
    return Pilot(_maps(_plane(n_pilot, seed, **kw)), {"caustic": (30 / (PILOT_K - 1)) * n_pilot / N, "global": 1.0},
                 estimator, 1.0, 0.0)


@pytest.mark.parametrize("estimator", ["STANDARD", "TEMPORAL"])
def test_pilot_region_table_is_bounded_and_does_not_change_the_regions(estimator, monkeypatch):
    """The table of pilot regions per grid cell stops growing at GRID_CELLS_MAX cells (it grew by a
    cell per camera sample and pass, and its upkeep came to dominate late passes); regions of cells
    beyond it are computed on the fly: the same values as with an unbounded table."""
    import stpm_core.photons.progressive as pp
    rng = np.random.default_rng(4)
    batches = []
    for _ in range(6):
        q = np.column_stack([rng.uniform(-0.4, 0.4, (3000, 2)), np.zeros(3000), rng.random(3000)])
        batches.append((q, np.tile(UP, (3000, 1)).astype(np.float32)))
    big = _pilot(estimator, 20_000, 5)
    want = [big.initial_size("caustic", q, n) for q, n in batches]
    monkeypatch.setattr(pp, "GRID_CELLS_MAX", 4000)
    small = _pilot(estimator, 20_000, 5)
    for (q, n), (r0, tau0) in zip(batches, want):
        r, tau = small.initial_size("caustic", q, n)
        assert np.array_equal(r, r0) and (tau is None) == (tau0 is None)
        assert tau is None or np.array_equal(tau, tau0)
        assert small._grids["caustic"]["table"].count <= 4000
    assert big._grids["caustic"]["table"].count > 4000            # the small table did fill up
    keys = big._grids["caustic"]["table"].keys()
    assert keys.size == big._grids["caustic"]["table"].count and np.all(np.diff(keys) > 0)   # no duplicates


@pytest.mark.parametrize("estimator", ["STANDARD", "TEMPORAL", "KD4D"])
@pytest.mark.parametrize("kernel", ["BOX", "CONE"])
def test_one_pass_reads_a_uniform_plane_unbiased_at_every_time(estimator, kernel):
    # E = 1 W/m^2 everywhere and always: a fixed region is unbiased for any size and shape, so the
    # mean over queries is 1 within noise -- at the shutter's ends too, where the region is clipped.
    # (The queries share the photons near them: the noise of the mean is about 1 / sqrt(photons
    # read), about 1 % here.)
    N = 400_000
    pilot = _pilot(estimator, N, 1)
    rng = np.random.default_rng(3)
    p = np.column_stack([rng.uniform(-0.4, 0.4, (20_000, 2)), np.zeros(20_000)])
    ns = np.tile(UP, (len(p), 1))
    for i in (1, 30):
        pm = ProgressiveMaps(_maps(_plane(N, 100 + i)), pilot, pass_index=i, alpha=0.4, kernel=kernel)
        for lo, hi in ((0.0, 0.05), (0.3, 0.7), (0.95, 1.0)):
            E = pm.estimate("caustic", p, ns, rng.uniform(lo, hi, len(p)))[:, 0]
            assert abs(E.mean() - 1.0) < 0.03, (estimator, kernel, i, lo, E.mean())
        st = pm.stats
        # pass 1 holds about k = 30 photons; pass 30's region is smaller by the schedule
        expect = 30 * shrink_ratio(i, 0.4)
        assert 0.7 * expect < st["caustic_photons_per_estimate"] < 1.3 * expect, (i, st)


@pytest.mark.parametrize("estimator", ["TEMPORAL", "KD4D"])
def test_one_pass_follows_light_that_changes_during_the_shutter(estimator):
    # E(t) = 0.5 + t (linear in time): a window symmetric about t reads E(t) without bias where it
    # is not clipped by the shutter's ends; STANDARD would read the mean, 1.0.  (TEMPORAL's pilot
    # sees a slow ramp as light that holds still and gives pass 4 windows of about +-0.25 of the
    # shutter: clipped, and so biased toward the inside, within that of the ends; the windows shrink
    # with the passes.)
    N = 400_000
    law = dict(E_of_t=lambda t: 0.5 + t)
    pilot = _pilot(estimator, N, 2, **law)
    pm = ProgressiveMaps(_maps(_plane(N, 7, **law)), pilot, pass_index=4, alpha=0.4)
    rng = np.random.default_rng(5)
    p = np.column_stack([rng.uniform(-0.4, 0.4, (20_000, 2)), np.zeros(20_000)])
    for t0 in (0.5,) if estimator == "TEMPORAL" else (0.25, 0.5, 0.75):
        t = rng.uniform(t0 - 0.1, t0 + 0.1, len(p))
        E = pm.estimate("caustic", p, np.tile(UP, (len(p), 1)), t)[:, 0]
        assert abs(E.mean() - (0.5 + t.mean())) < 0.03, (estimator, t0, E.mean())


def test_a_closed_furnace_converges_to_the_interreflection():
    # The closed diffuse sphere of tests/test_photons.py: the global map's irradiance is
    # P rho / (1 - rho) / area everywhere, and so is every pass's mean
    from test_photons import P, _area_uniform_points, _sphere_furnace, trace
    rho = 0.5
    scene, mesh = _sphere_furnace(rho)
    settings = dict(photons_global=30_000, photons_caustic=0, max_depth=40, diffuse_bounces=1024)  # no budget
    pilot_maps = trace(scene, **{**settings, "photons_global": 15_000, "seed": 99})
    pilot = Pilot(pilot_maps, {"caustic": 1.0, "global": (30 / (PILOT_K - 1)) * 0.5}, "STANDARD", 1.0, 0.0)
    rng = np.random.default_rng(4)
    p, area = _area_uniform_points(mesh, rng, 4000)
    ns = -p / np.linalg.norm(p, axis=1, keepdims=True)
    truth = P * rho / (1 - rho) / area
    acc = np.zeros(len(p))
    for i in range(1, 9):
        pm = ProgressiveMaps(trace(scene, **settings, seed=i), pilot, pass_index=i, alpha=0.5)
        acc += pm.estimate("global", p, ns, rng.random(len(p)))[:, 0]
    assert abs(acc.mean() / 8 / truth - 1) < 0.02


# ----------------------------------------------------------------------------
# Whole renders against exact images
# ----------------------------------------------------------------------------
RES = (48, 32)
BASE = dict(samples=2, photons_caustic=20_000, photons_global=0, k_nearest=10, seed=1, effects="MANUAL",
            caustics=True, indirect=False)


def _rmse(img, ref):
    return float(np.sqrt(np.mean((np.asarray(img, np.float64)[:, :, :3] - ref) ** 2)))


def _errors_by_pass(scene, ref, settings):
    errs, bad = {}, []

    def on_pass(img, info):
        errs[info["pass"]] = _rmse(img["Combined"], ref)
        for name in ("Combined", "Direct", "Caustic", "Emit", "Indirect"):
            a = img[name]
            if not np.all(np.isfinite(a)) or a.min() < 0:
                bad.append((info["pass"], name))
    result = render(scene, settings, on_pass=on_pass)
    return errs, bad, result


@pytest.mark.parametrize("mirror", [(-0.25, 0.25), (0.0, 0.0)], ids=["moving caustic", "moving receiver"])
def test_progressive_converges_on_scenes_with_exact_answers(mirror):
    scene = moving_caustic_scene(RES, mirror=mirror)
    ref = analytic_moving_caustic(RES, sub=6, n_t=128, mirror=mirror)
    settings = RenderSettings(method="PROGRESSIVE", estimator="TEMPORAL", passes=64, **BASE)
    errs, bad, result = _errors_by_pass(scene, ref, settings)
    assert not bad, bad                                          # no NaN, no negative pixel, at any pass
    assert result.stats["progressive"]["passes"] == 64 and result.stats["progressive"]["stopped_by"] == "passes"
    # log-log slope of the error over passes 4..64 (a 16x range), least squares
    i = np.arange(4, 65)
    slope = np.polyfit(np.log(i), np.log([errs[k] for k in i]), 1)[0]
    assert slope <= -0.2, (slope, errs[4], errs[64])
    # fixed-k TEMPORAL with the pass's photons never gets there, however many samples it takes
    # (its error stays at its bias): the same photons, the 64 passes' 128 samples per pixel
    fixed = render(scene, RenderSettings(method="PHOTON", estimator="TEMPORAL", **{**BASE, "samples": 128}))
    assert errs[64] < 0.8 * _rmse(fixed.passes["Combined"], ref), (errs[64], _rmse(fixed.passes["Combined"], ref))


def test_a_static_scene_converges_to_the_standard_estimate():
    # Static mirror and receivers: the plan reads it with STANDARD (a 2D disc, a = 0.5); many passes
    # agree with a STANDARD render of many photons, block by block
    scene = moving_caustic_scene(RES, mirror=(0.0, 0.0))
    for inst in scene.instances:                        # the mirror and the box stand still
        if not inst.transform.is_static:
            inst.transform = MotionTransform.static(inst.transform.at(0.5))
    st = dict(BASE, effects="AUTO")
    prog = render(scene, RenderSettings(method="PROGRESSIVE", passes=24, **st))
    assert prog.stats["estimator"] == "STANDARD"
    assert prog.stats["progressive"]["kernel_dims"] == 2 and prog.stats["progressive"]["shrink_alpha"] == 0.5
    ref = render(scene, RenderSettings(method="PHOTON", **{**st, "photons_caustic": 1_000_000, "samples": 48,
                                                            "k_nearest": 50})).passes["Caustic"]
    a, b = prog.passes["Caustic"].astype(np.float64), ref.astype(np.float64)
    blocks = lambda x: x[:, :, 0].reshape(4, 8, 6, 8).mean(axis=(1, 3))
    lit = blocks(b) > 0.1 * blocks(b).max()
    assert abs(a.mean() / b.mean() - 1) < 0.03
    assert np.all(np.abs(blocks(a)[lit] / blocks(b)[lit] - 1) < 0.1)


def test_same_seed_same_image_and_passes_are_independent_of_where_they_start():
    scene = moving_caustic_scene((24, 16))
    base = dict(BASE, photons_caustic=3000)
    a = render(scene, RenderSettings(method="PROGRESSIVE", passes=4, **base))
    b = render(scene, RenderSettings(method="PROGRESSIVE", passes=4, **base))
    assert all(np.array_equal(a.passes[k], b.passes[k]) for k in a.passes)
    # passes 3..4 rendered on their own are exactly the last two of the four
    c = render(scene, RenderSettings(method="PROGRESSIVE", passes=2, pass_offset=2, **base))
    assert c.sums.first == 3 and c.sums.end == 5
    d = render(scene, RenderSettings(method="PROGRESSIVE", passes=2, **base))
    merged = d.sums.merged(c.sums)
    for k in a.sums.sums:
        assert np.allclose(merged.sums[k], a.sums.sums[k], rtol=1e-12, atol=0)
        assert np.array_equal(merged.image()[k], a.passes[k]), k


# ----------------------------------------------------------------------------
# Stops
# ----------------------------------------------------------------------------
def _soft_shadow_scene(size=0.6, power=200.0, res=(32, 24)):
    """A plane under an area light above a small occluder: soft-shadow noise only (no photons)."""
    light = Light(type="AREA", power=power, size=size, transform=MotionTransform.static(translate(0, 0, 1.5)))
    occluder = plane_mesh(0.4, z=0.6, material=0, name="occluder")
    return make_scene([plane_mesh(10.0, material=0), occluder], [Material.diffuse((0.8, 0.8, 0.8))],
                      ortho_camera_down(height=3.0, ortho_scale=2.0), [light], resolution=res)


def test_a_cancel_or_a_time_limit_keeps_the_passes_so_far():
    scene = moving_caustic_scene((24, 16))
    shown = []
    st = RenderSettings(method="PROGRESSIVE", passes=50, **dict(BASE, photons_caustic=2000))
    result = render(scene, st, on_pass=lambda img, info: shown.append(info["pass"]),
                    cancel=lambda: len(shown) >= 3)
    assert result.stats["progressive"]["stopped_by"] == "cancelled"
    assert result.stats["progressive"]["passes"] == len(shown) == 3
    assert any("cancelled after 3 passes: the image holds passes 1-3" in w for w in result.warnings), result.warnings
    assert np.all(np.isfinite(result.passes["Combined"])) and result.passes["Combined"][..., :3].max() > 0
    # a cancel before the first pass finished has nothing to keep
    with pytest.raises(RenderCancelled):
        render(scene, st, cancel=lambda: True)
    # a time limit stops after at least one pass
    quick = render(scene, st.replace(passes=0, time_limit=1e-6))
    assert quick.stats["progressive"]["passes"] == 1 and quick.stats["progressive"]["stopped_by"] == "time_limit"


def _true_noise(img, ref):
    """95th percentile over 8x8 blocks of the true relative RMS error (luminance) against ref."""
    Y = lambda x: np.asarray(x, np.float64)[:, :, :3] @ np.array([0.2126, 0.7152, 0.0722])
    e2 = (Y(img) - Y(ref)) ** 2 / (np.abs(Y(ref)) + 1e-3 * np.abs(Y(ref)).mean()) ** 2
    H, W = e2.shape
    blocks = np.sqrt(e2.reshape(H // 8, 8, W // 8, 8).mean(axis=(1, 3)))
    return float(np.percentile(blocks, 95))


def test_noise_threshold_stops_near_the_true_noise_and_harder_scenes_take_more_passes():
    threshold = 0.08
    st = RenderSettings(method="PROGRESSIVE", passes=0, noise_threshold=threshold, samples=1, photons_caustic=0,
                        photons_global=0)
    runs = {}
    for name, size in (("easy", 0.6), ("hard", 0.15)):
        scene = _soft_shadow_scene(size=size)
        ref = render(scene, RenderSettings(samples=1024, photons_caustic=0, photons_global=0, seed=77)).passes["Combined"]
        runs[name] = []
        for seed in range(3):
            r = render(scene, st.replace(seed=seed))
            pr = r.stats["progressive"]
            assert pr["stopped_by"] == "noise_threshold" and pr["noise_p95"] <= threshold
            true = _true_noise(r.passes["Combined"], ref)
            assert threshold / 1.5 <= true <= 1.5 * threshold, (name, seed, true, pr)
            runs[name].append(pr["passes"])
    assert np.mean(runs["hard"]) > 1.5 * np.mean(runs["easy"]), runs


def _moving_occluder_scene(res=(32, 24)):
    """The soft-shadow scene with its occluder sliding x = -0.5 -> 0.5 over the shutter: motion blur."""
    from scenes import moving
    light = Light(type="AREA", power=200.0, size=0.6, transform=MotionTransform.static(translate(0, 0, 1.5)))
    occluder = (plane_mesh(0.4, z=0.0, material=0, name="occluder"), moving((-0.5, 0, 0.6), (0.5, 0, 0.6)))
    return make_scene([plane_mesh(10.0, material=0), occluder], [Material.diffuse((0.8, 0.8, 0.8))],
                      ortho_camera_down(height=3.0, ortho_scale=2.0), [light], resolution=res,
                      shutter=Shutter(1.0, 2.0))


def test_noise_threshold_stops_with_motion_blur():
    """Time strata must not read as noise: the odd and even passes of whole rounds cover the same strata,
    so on a motion-blurred shadow the estimate follows the true error and the threshold is reached
    (before, the halves covered different parts of the shutter and the estimate stalled near 0.19)."""
    scene = _moving_occluder_scene()
    ref = render(scene, RenderSettings(samples=1024, photons_caustic=0, photons_global=0, seed=77)).passes["Combined"]
    st = RenderSettings(method="PROGRESSIVE", passes=400, noise_threshold=0.08, samples=1, photons_caustic=0,
                        photons_global=0)
    for seed in range(2):
        pr = (r := render(scene, st.replace(seed=seed))).stats["progressive"]
        assert pr["stopped_by"] == "noise_threshold" and pr["noise_p95"] <= 0.08, pr
        true = _true_noise(r.passes["Combined"], ref)
        assert 0.08 / 1.5 <= true <= 0.08 * 1.5 and true / pr["noise_p95"] < 1.3, (seed, true, pr)


def test_a_stop_inside_a_round_leaves_its_passes_out_of_the_image():
    """Cancelled after pass 20 of 32 on a moving shadow: the image is the one of 16 passes (bit for bit)
    -- passes 17-20 reached 2 of the 16 time strata of their round and would band the motion trail --
    and says so; the display after each pass had them."""
    scene = _moving_occluder_scene((16, 12))
    st = RenderSettings(method="PROGRESSIVE", passes=32, samples=1, photons_caustic=0, photons_global=0)
    shown = []
    r20 = render(scene, st, on_pass=lambda img, info: shown.append(img["Combined"]), cancel=lambda: len(shown) >= 20)
    r16 = render(scene, st.replace(passes=16))
    pr = r20.stats["progressive"]
    assert pr["stopped_by"] == "cancelled" and pr["scheduled_rounds"]
    assert pr["passes"] == 16 and pr["passes_rendered"] == 20 and pr["left_out"] == [17, 20, 32]
    assert np.array_equal(r20.passes["Combined"], r16.passes["Combined"])
    assert any("passes 17-20 are left out" in w and "ends at pass 32" in w for w in r20.warnings), r20.warnings
    assert any("cancelled after 20 passes: the image holds passes 1-16" in w for w in r20.warnings), r20.warnings
    assert len(shown) == 20 and not np.array_equal(shown[-1], r20.passes["Combined"])
    assert r16.stats["progressive"]["left_out"] is None and not any("left out" in w for w in r16.warnings)


def test_pass_and_time_limits_end_with_smaller_whole_rounds():
    """passes = 20: passes 17-20 form a round of 2 strata (not the schedule's 16), so all 20 are in the
    image and every part of the shutter weighs alike.  A time limit likewise takes rounds that fit in
    the time left: nothing left out, and it is not stopped early by a round that would not fit."""
    from stpm_core.progressive import render_passes  # noqa: F401  (the loop under test)
    from stpm_core.strata import Rounds
    r = Rounds()
    assert r.begin(17, 4) == 4 and not r.scheduled                                       # 2 strata, in pairs
    assert [r.stratum(i) for i in range(17, 21)] == [(0.0, 0.5)] * 2 + [(0.5, 1.0)] * 2 and r.is_end(20)
    assert r.begin(21, 3) == 1 and r.stratum(21) == (0.0, 1.0) and r.is_end(21) and r.begin(22, 0) == 0
    assert r.begin(22, 100) == 16 and r.stratum(22) == (0.0, 1 / 8)                   # the schedule's 8 strata again
    scene = _moving_occluder_scene((16, 12))
    st = RenderSettings(method="PROGRESSIVE", passes=20, samples=1, photons_caustic=0, photons_global=0)
    pr = render(scene, st).stats["progressive"]
    assert pr["passes"] == pr["passes_rendered"] == 20 and pr["left_out"] is None and not pr["scheduled_rounds"]
    # a limit of about 24 passes of this machine's speed (measured on the 20 passes above, so a loaded
    # machine does not turn the check into a speed test): the render gets past the first 16
    limit = max(1.5, 24.0 * float(np.median(pr["pass_seconds"])))
    timed = render(scene, st.replace(passes=0, time_limit=limit)).stats["progressive"]
    assert timed["stopped_by"] == "time_limit" and timed["left_out"] is None
    assert timed["passes"] == timed["passes_rendered"] > 16, (limit, timed["pass_seconds"])
    assert sum(timed["pass_seconds"]) > 0.6 * limit, timed["pass_seconds"]     # the time was used


def test_noise_estimate_of_known_noise():
    # Passes = a flat image of 1 plus Gaussian noise of sigma per pass: the mean of n passes has a
    # relative standard error sigma / sqrt(n), which the odd/even estimate recovers
    rng = np.random.default_rng(0)
    sigma, n = 0.2, 16
    sums = PassSums(1)
    for i in range(1, n + 1):
        img = 1.0 + sigma * rng.standard_normal((64, 64, 1))
        sums.add(i, {"Combined": np.concatenate([np.repeat(img, 3, axis=2), np.ones((64, 64, 1))], axis=2)})
    est = noise_estimate(sums)
    assert est["noise_mean"] == pytest.approx(sigma / math.sqrt(n), rel=0.1)


# ----------------------------------------------------------------------------
# Partial results and stpm merge
# ----------------------------------------------------------------------------
def _cli(*args, cwd):
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    return subprocess.run([sys.executable, "-m", "stpm_core.cli", *args], cwd=cwd, env=env, capture_output=True,
                          text=True, timeout=600)


@pytest.fixture(scope="module")
def parts(tmp_path_factory):
    from stpm_core.scenefile import save_scene
    d = tmp_path_factory.mktemp("merge")
    save_scene(moving_caustic_scene((24, 16)), d / "mc.stpm", RenderSettings(**dict(BASE, photons_caustic=2000)))
    for args in (("--passes", "8", "-o", "full.exr"), ("--pass-offset", "0", "--passes", "4", "-o", "a.exr"),
                 ("--pass-offset", "4", "--passes", "4", "-o", "b.exr"), ("--pass-offset", "8", "--passes", "8",
                                                                            "-o", "c.exr"),
                 ("--pass-offset", "4", "--passes", "4", "--seed", "5", "-o", "s.exr"),
                 ("--pass-offset", "4", "--passes", "4", "--resolution", "12x8", "-o", "r.exr")):
        out = _cli("render", "mc.stpm", "--method", "progressive", "-q", *args, cwd=d)
        assert out.returncode == 0, out.stderr
    return d


def test_merged_partials_equal_one_process(parts):
    from stpm_core.imageio import read_exr
    out = _cli("merge", "b.exr", "a.exr", "-o", "m.exr", "--stats", "m.json", cwd=parts)
    assert out.returncode == 0, out.stderr
    full, merged = read_exr(parts / "full.exr"), read_exr(parts / "m.exr")
    for name in ("Combined", "Caustic", "Direct", "Depth", "Normal"):
        assert np.array_equal(full[name], merged[name]), name
    info = json.loads((parts / "m.json").read_text())["progressive"]
    assert info["passes"] == 8 and info["pass_first"] == 1 and info["pass_end"] == 9
    meta = merged["_metadata"]                      # where it came from, as a render's EXR says
    assert json.loads(meta["stpm:settings"])["method"] == "PROGRESSIVE" and meta["stpm:scene"].endswith("mc.stpm")
    assert "stpm:plan" in meta and "stpm:frame" in meta
    # a later range alone merges (it is a whole image), with a warning that passes are missing
    out = _cli("merge", "b.exr", "-o", "late.exr", cwd=parts)
    assert out.returncode == 0 and "passes 1..4 are missing" in out.stderr, out.stderr


def test_partials_are_whole_rounds_of_time_strata(parts):
    """A partial that would end inside a round, or a pass offset inside one: one line before rendering."""
    out = _cli("render", "mc.stpm", "--method", "progressive", "--pass-offset", "4", "--passes", "5", "-o", "x.exr",
               cwd=parts)
    assert out.returncode == 1 and "inside a round of time strata" in out.stderr, out.stderr
    assert "use --passes 4, 12, 28" in out.stderr and "Splitting one frame between machines" in out.stderr, out.stderr
    out = _cli("render", "mc.stpm", "--method", "progressive", "--pass-offset", "5", "--passes", "3", "-o", "x.exr",
               cwd=parts)
    assert out.returncode == 1 and "--pass-offset 5 is inside a round" in out.stderr, out.stderr
    # a time limit that ends the first round early: said, nothing written (a partial holds whole rounds)
    out = _cli("render", "mc.stpm", "--method", "progressive", "--pass-offset", "16", "--passes", "0",
               "--time-limit", "0.001", "-q", "-o", "x.exr", cwd=parts)
    assert out.returncode == 1 and "before its first round of time strata (passes 17..32)" in out.stderr, out.stderr
    assert out.stderr.count("\n") == 1, out.stderr
    assert not (parts / "x.exr").exists() and not (parts / "x.png").exists()


@pytest.mark.parametrize("files,message", [
    (("a.exr", "a.exr"), "overlaps"),
    (("a.exr", "c.exr"), "missing"),
    (("a.exr", "s.exr"), "different seeds (5 and 1)"),
    (("a.exr", "r.exr"), "different resolutions (12x8 and 24x16)"),
    (("a.exr", "full.exr"), "not a partial result"),
    (("a.exr", "nothere.exr"), "not found"),
])
def test_merge_refuses_overlaps_gaps_and_mismatches(parts, files, message):
    out = _cli("merge", *files, "-o", "bad.exr", cwd=parts)
    assert out.returncode == 1 and message in out.stderr and out.stderr.count("\n") == 1, out.stderr
    assert not (parts / "bad.exr").exists()


def test_merge_refuses_damaged_partials(parts):
    # A truncated file and a header whose pass counts lie: one line each, nothing written
    data = (parts / "b.exr").read_bytes()
    (parts / "trunc.exr").write_bytes(data[: len(data) // 2])
    out = _cli("merge", "a.exr", "trunc.exr", "-o", "bad.exr", cwd=parts)
    assert out.returncode == 1 and out.stderr.startswith("stpm: error:") and out.stderr.count("\n") == 1, out.stderr
    import OpenImageIO as oiio
    from stpm_core.imageio import read_exr, write_exr
    b = read_exr(parts / "b.exr")
    meta = {k: v for k, v in b.pop("_metadata").items() if k.startswith("stpm:")}
    b.pop("_channels")
    meta["stpm:partial"] = meta["stpm:partial"].replace('"n_odd": 2', '"n_odd": 7')
    write_exr(parts / "lie.exr", b, meta)
    out = _cli("merge", "a.exr", "lie.exr", "-o", "bad.exr", cwd=parts)
    assert out.returncode == 1 and "pass counts" in out.stderr, out.stderr
    assert not (parts / "bad.exr").exists()
    del oiio


def test_progressive_options_that_do_nothing_or_surprise_are_named(parts):
    """--passes on a photon render does nothing: said.  --method progressive on a file set up for one
    big photon render makes every pass that big: said, with the preset's per-pass values."""
    out = _cli("render", "mc.stpm", "--passes", "8", "--time-limit", "5", "-q", "-o", "y.exr", cwd=parts)
    assert out.returncode == 0 and "--passes / --time-limit have no effect with --method photon" in out.stderr, \
        out.stderr
    from stpm_core.scenefile import save_scene
    save_scene(moving_caustic_scene((12, 8)), parts / "big.stpm",
               RenderSettings(**dict(BASE, samples=16, photons_caustic=500)))
    out = _cli("render", "big.stpm", "--method", "progressive", "--passes", "1", "-q", "-o", "z.exr", cwd=parts)
    assert out.returncode == 0 and "every progressive pass traces the file's 16 samples" in out.stderr, out.stderr
    out = _cli("render", "big.stpm", "--method", "progressive", "--passes", "1", "--samples", "1", "-q",
               "-o", "z.exr", cwd=parts)
    assert out.returncode == 0 and "every progressive pass" not in out.stderr, out.stderr


def test_a_time_limit_alone_says_that_the_pass_limit_still_stops_the_render(parts):
    """`--time-limit 60` (docs/cli.md's example) without --passes stopped at the file's 16 passes,
    silently (artist review: 16 passes in 16.8 s at --time-limit 20): now said before rendering."""
    out = _cli("render", "mc.stpm", "--method", "progressive", "--time-limit", "30", "--stats", "t.json", "-q",
               "-o", "t.exr", cwd=parts)
    assert out.returncode == 0, out.stderr
    assert json.loads((parts / "t.json").read_text())["progressive"]["stopped_by"] == "passes"
    assert "--time-limit without --passes: the render also stops at the file's pass limit (16 passes)" \
        in out.stderr and "--passes 0" in out.stderr, out.stderr
    out = _cli("render", "mc.stpm", "--method", "progressive", "--passes", "0", "--time-limit", "0.5", "-q",
               "-o", "t.exr", cwd=parts)
    assert out.returncode == 0 and "pass limit" not in out.stderr, out.stderr


def test_pass_offset_needs_the_progressive_method(parts):
    out = _cli("render", "mc.stpm", "--pass-offset", "0", "-o", "x.exr", cwd=parts)
    assert out.returncode == 1 and "--method progressive" in out.stderr


# ----------------------------------------------------------------------------
# The SPPM baseline of stpm compare (one instant per pass, pbrt-v4's radius update)
# ----------------------------------------------------------------------------
def test_sppm_radius_follows_pbrts_update():
    from stpm_core.compare.sppm import GAMMA, SPPMMaps, radical_inverse
    assert [radical_inverse(i) for i in range(5)] == [0.0, 0.5, 0.25, 0.75, 0.125]
    m = _plane(50_000, 4)
    pilot = _pilot("STANDARD", 50_000, 5)
    n = 200
    state = {k: {"R": np.full(n, np.nan), "N": np.zeros(n)} for k in ("caustic", "global")}
    g = np.linspace(-0.35, 0.35, 20)
    p = np.column_stack([np.repeat(g, 10), np.tile(g[::2], 20), np.zeros(n)])
    ns = np.tile(UP, (n, 1))
    sm = SPPMMaps(_maps(m), pilot, state)
    E1 = sm.estimate("caustic", p, ns, np.zeros(n), pixels=np.arange(n))
    R1, N1 = state["caustic"]["R"].copy(), state["caustic"]["N"].copy()
    q = np.zeros((n, 4))
    q[:, :3] = p
    r0, _ = pilot.initial_size("caustic", q, ns.astype(np.float32))
    _, M = m.flat_tree(3).range_sum(q, ns.astype(np.float32), r0, None, False, 1.1, 1)
    assert np.allclose(N1, GAMMA * M)
    assert np.allclose(R1, r0 * np.sqrt(GAMMA * M / M))                  # first pass: N = 0
    assert abs(E1[:, 0].mean() - 1.0) < 0.05                              # ~30 photons each: noisy but right
    sm.estimate("caustic", p, ns, np.zeros(n), pixels=np.arange(n))
    assert np.all(state["caustic"]["R"] < R1)                             # shrinks pass by pass


def test_sppm_passes_are_stills_and_strobe_when_few():
    from stpm_core.compare.sppm import render_sppm
    scene = moving_caustic_scene(RES)
    ref = analytic_moving_caustic(RES, sub=6, n_t=128)
    errs_sppm, errs_prog = {}, {}
    st = RenderSettings(passes=16, **dict(BASE, samples=1))
    result = render_sppm(scene, st, on_pass=lambda img, info: errs_sppm.__setitem__(info["pass"],
                                                                                   _rmse(img["Combined"], ref)))
    assert result.stats["progressive"]["passes"] == 16 and result.stats["method"] == "SPPM"
    render(scene, RenderSettings(method="PROGRESSIVE", passes=2, **dict(BASE, samples=1)),
           on_pass=lambda img, info: errs_prog.__setitem__(info["pass"], _rmse(img["Combined"], ref)))
    assert errs_sppm[16] < 0.5 * errs_sppm[1]                              # converging
    # one instant per pass: its first passes are stills of the moving box and caustic
    assert errs_sppm[1] > 1.3 * errs_prog[1] and errs_sppm[2] > errs_prog[2], (errs_sppm, errs_prog)


def test_partials_carry_their_working_space_and_do_not_mix_them(tmp_path):
    # a Blender 5 file in ACEScg: the partial says so, the merged EXR is tagged as Blender tags it,
    # and a partial of another working space is refused
    from stpm_core.errors import StpmError
    from stpm_core.imageio import read_exr
    from stpm_core.partial import merge, read_partial, write_partial
    rng = np.random.default_rng(1)

    def sums(first):
        s = PassSums(first)
        s.add(first, {"Combined": rng.random((4, 6, 4)).astype(np.float32)})
        return s
    kw = dict(seed=1, scene_digest="c" * 64, settings_digest="d" * 64)
    write_partial(tmp_path / "a.exr", sums(1), working="ACESCG", **kw)
    write_partial(tmp_path / "b.exr", sums(2), working="REC709", **kw)
    assert read_partial(tmp_path / "a.exr")[1]["working_space"] == "ACESCG"
    assert read_exr(tmp_path / "a.exr")["_metadata"].get("colorInteropID")
    with pytest.raises(StpmError, match="different working colour spaces"):
        merge([tmp_path / "a.exr", tmp_path / "b.exr"])


@pytest.mark.parametrize("static_views", [False, True])
def test_a_pass_builds_only_the_tree_its_regions_read(monkeypatch, static_views):
    """A pass's maps get no k-nearest trees up front (TEMPORAL's time-slice trees went unread, about
    half of a pass's tree building): the 4D tree its fixed regions read, and with static views
    (integrator.static_view_setup: the moving mirror's caustic lands on a static floor) the 3D tree
    of their discs."""
    import stpm_core.progressive as prog
    from stpm_core import integrator
    monkeypatch.setattr(integrator, "STATIC_VIEW", static_views)
    built = []
    real = prog.build_photon_maps

    def spy(*a, **k):
        maps = real(*a, **k)
        built.append(maps)
        return maps
    monkeypatch.setattr(prog, "build_photon_maps", spy)
    st = RenderSettings(**{**BASE, "photons_caustic": 3000, "samples": 1}, method="PROGRESSIVE", passes=2)
    render(moving_caustic_scene((16, 12)), st)
    assert len(built) == 2
    for maps in built:
        m = maps.maps["caustic"]
        assert m.n > 0 and m._slices == {} and set(m._flat) == ({3, 4} if static_views else {4})
