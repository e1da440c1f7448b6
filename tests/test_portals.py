"""Light portals (Blender's area lights with Cycles' ``is_portal``) and per-light photon budgets.

A closed room lit by the world through one window (tests/portal_scenes.py).  A portal changes
only how the world is sampled, never the image's expectation:

* next-event estimation through the portal: the density the sampler reports (and MIS uses,
  ``lights.world_nee_pdf``) is the density it draws from (a histogram over the sphere against
  the integrated density) and integrates to 1;
* world photons through the portal: unbiased (the flux crossing the window and a patch elsewhere
  equals pi L A, also for an environment image), and far more of them stored in the room;
* renders with and without the portal agree within the noise (block Z-test over seeds);
* a light's ``photon_weight`` changes its share of the photons, not the image.
"""
from __future__ import annotations

import numpy as np
import pytest

from stpm_core.kernels.environment import env_lookup_batch
from stpm_core.kernels.light_params import kernel_light, light_poses
from stpm_core.kernels.lights import sample_pdf_batch, world_nee_pdf_batch
from stpm_core.lights import LightSet
from stpm_core.render import render
from stpm_core.scenefile import load_scene, save_scene
from stpm_core.settings import RenderSettings
from stpm_core.motion import MotionTransform
from stpm_core.world_light import PORTAL_NEE_FRACTION

from portal_scenes import WINDOW, inside, portal_light, room_scene

P_FLOOR = np.array([-0.2, 0.1, 1e-3])        # a floor point in the room
N_FLOOR = np.array([0.0, 0.0, 1.0])


def _sky(h: int = 32, w: int = 64) -> np.ndarray:
    """A small equirectangular sky (h, w, 3), row 0 at the bottom: dark ground, bright blue-ish sky
    and a 2 x 2 texel sun."""
    v = (np.arange(h) + 0.5) / h
    img = np.empty((h, w, 3), np.float32)
    img[...] = np.where(v[:, None, None] > 0.5, np.array([0.6, 0.8, 1.2]), np.array([0.1, 0.08, 0.05]))
    img[24:26, 6:8] = 40.0
    return img


def _world(sc):
    ls = LightSet(sc)
    li = [l.type for l in ls.lights].index("WORLD")
    return ls, li


def _sphere_grid(n_t: int, n_p: int):
    """Cell centres (n_t n_p, 3) of a (cos theta, phi) grid of equal-area cells, and each cell's solid angle."""
    ct = -1.0 + 2.0 * (np.arange(n_t) + 0.5) / n_t
    ph = 2.0 * np.pi * (np.arange(n_p) + 0.5) / n_p
    C, P = np.meshgrid(ct, ph, indexing="ij")
    S = np.sqrt(1.0 - C * C)
    d = np.stack([S * np.cos(P), S * np.sin(P), C], axis=-1).reshape(-1, 3)
    return d, 4.0 * np.pi / (n_t * n_p)


def _cell(d, n_t, n_p):
    """Cell index of unit directions d (n, 3) on the grid of :func:`_sphere_grid`."""
    it = np.clip(((d[:, 2] + 1.0) * 0.5 * n_t).astype(int), 0, n_t - 1)
    ip = np.clip((np.mod(np.arctan2(d[:, 1], d[:, 0]), 2 * np.pi) / (2 * np.pi) * n_p).astype(int), 0, n_p - 1)
    return it * n_p + ip


@pytest.mark.parametrize("image", [False, True])
def test_portal_nee_density_is_what_the_sampler_draws(image):
    sc = room_scene(portal=True, image=_sky() if image else None)
    ls, li = _world(sc)
    k = kernel_light(ls, li)
    poses = light_poses(ls, li, np.zeros(1))
    env = k[-1]
    assert env[5].shape == (1, 12)
    # -- samples and the density the sampler reports for each
    n = 200_000
    rng = np.random.default_rng(3)
    p = np.broadcast_to(P_FLOOR, (n, 3)).copy()
    nrm = np.broadcast_to(N_FLOOR, (n, 3)).copy()
    S = np.empty((n, 8))
    sample_pdf_batch(k[0], poses, *k[2:], p, np.zeros(n), rng.random((n, 2)), nrm, S)
    wi = np.ascontiguousarray(S[:, :3])
    again = np.empty(n)
    world_nee_pdf_batch(env, poses, p, nrm, wi, again)
    np.testing.assert_allclose(S[:, 7], again, rtol=1e-9)
    # the portal draws about half the samples: they pass through the window
    o_win = (1.0 - P_FLOOR[0]) / np.maximum(wi[:, 0], 1e-12)
    x = P_FLOOR + o_win[:, None] * wi
    y0, y1, z0, z1 = WINDOW
    through = (wi[:, 0] > 0) & (x[:, 1] >= y0) & (x[:, 1] <= y1) & (x[:, 2] >= z0) & (x[:, 2] <= z1)
    assert through.mean() > 0.9 * PORTAL_NEE_FRACTION
    # -- the density over a fine sphere grid (12 x 12 points per cell): integral 1, and the
    # histogram of the samples over the cells matches it.  The grid is turned by a fixed rotation R
    # so that no portal edge runs along a cell boundary (from a point under the window its vertical
    # edges are meridians)
    R = np.linalg.qr(np.random.default_rng(5).normal(size=(3, 3)))[0]
    n_t, n_p, sub = 48, 96, 12
    dg, dw = _sphere_grid(n_t * sub, n_p * sub)
    cells = _cell(dg, n_t, n_p)
    dg = dg @ R.T
    m = dg.shape[0]
    pdf = np.empty(m)
    world_nee_pdf_batch(env, poses, np.broadcast_to(P_FLOOR, (m, 3)).copy(), np.broadcast_to(N_FLOOR, (m, 3)).copy(),
                        dg, pdf)
    assert pdf.sum() * dw == pytest.approx(1.0, abs=0.01)
    expect = np.bincount(cells, weights=pdf * dw, minlength=n_t * n_p) * n
    got = np.bincount(_cell(wi @ R, n_t, n_p), minlength=n_t * n_p)
    big = expect > 30
    z = (got[big] - expect[big]) / np.sqrt(expect[big])
    assert np.abs(z).max() < 5.5, np.abs(z).max()
    assert np.mean(z * z) < 1.3, np.mean(z * z)
    small_e, small_g = expect[~big].sum(), got[~big].sum()        # the thin cells, pooled
    assert abs(small_g - small_e) < 5.0 * np.sqrt(small_e) + 1.0, (small_g, small_e)


def test_portal_nee_is_off_outside_the_room_and_without_facing_side():
    """A point on the portal's back side (outside the room) gets the sampler without portals."""
    sc = room_scene(portal=True)
    ls, li = _world(sc)
    k = kernel_light(ls, li)
    poses = light_poses(ls, li, np.zeros(1))
    p = np.array([[2.0, 0.0, 1.2]])
    nrm = np.array([[0.0, 0.0, 1.0]])
    wi = np.array([[0.0, 0.6, 0.8]])
    out = np.empty(1)
    world_nee_pdf_batch(k[-1], poses, p, nrm, wi, out)
    assert out[0] == pytest.approx(0.8 / np.pi)


def _flux_through(o, d, Phi, c, e1, e2, nrm):
    """(3,) power of the photon lines crossing the rectangle (corner c, edges e1, e2) along +nrm."""
    dn = d @ nrm
    s = ((c - o) @ nrm) / np.where(dn == 0, np.inf, dn)
    x = o + s[:, None] * d - c
    a, b = x @ e1 / (e1 @ e1), x @ e2 / (e2 @ e2)
    hit = (dn > 0) & (a >= 0) & (a <= 1) & (b >= 0) & (b <= 1)
    return Phi[hit].sum(axis=0), hit


@pytest.mark.parametrize("image", [False, True])
def test_portal_photons_are_unbiased(image):
    """The power of the emitted photon lines crossing the window into the room, and crossing a patch the
    portal does not aim at, is the world's flux through them: pi L A (constant L), or the
    cosine-weighted integral of the image over the hemisphere times A."""
    sky = _sky() if image else None
    y0, y1, z0, z1 = WINDOW
    win = (np.array([1.0, y0, z0]), np.array([0.0, y1 - y0, 0.0]), np.array([0.0, 0.0, z1 - z0]),
           np.array([-1.0, 0.0, 0.0]))
    patch = (np.array([-0.5, -0.5, 0.5]), np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]),
             np.array([0.0, 0.0, -1.0]))           # a 1 m^2 horizontal patch, lit from above
    res = {}
    for portal in (False, True):
        sc = room_scene(portal=portal, image=sky)
        ls, li = _world(sc)
        rng = np.random.default_rng(11)
        o, d, Phi = ls.emit(li, 400_000, np.full(1, 0.5), rng)
        assert np.all(np.isfinite(Phi)) and Phi.min() >= 0
        res[portal] = [_flux_through(o, d, Phi, *r) for r in (win, patch)]
        if image:
            # the expected flux: A * integral of L(omega) cos over the hemisphere the light comes from
            env = kernel_light(ls, li)[-1]
            dg, dw = _sphere_grid(512, 1024)
            L = np.empty_like(dg)
            env_lookup_batch(env, light_poses(ls, li, np.zeros(1)), dg, L)
        for (c, e1, e2, nrm), (got, _) in zip((win, patch), res[portal]):
            A = np.linalg.norm(np.cross(e1, e2))
            if image:
                cos = np.maximum(-(dg @ nrm), 0.0)       # light from omega travels along -omega
                want = A * (L * cos[:, None]).sum(axis=0) * dw
            else:
                want = np.pi * A * np.ones(3)
            np.testing.assert_allclose(got, want, rtol=0.04 if portal else 0.06, err_msg=f"portal={portal}")
    # most photons go through the window with the portal, a few per cent without
    frac = {p: res[p][0][1].mean() for p in res}
    assert frac[True] > 0.6 and frac[False] < 0.05, frac


def _settings(**kw):
    base = dict(samples=4, photons_caustic=0, photons_global=30_000, k_nearest=30, diffuse_bounces=2,
                seed=0, effects="MANUAL", caustics=False, indirect=True, threads=1)
    base.update(kw)
    return RenderSettings(**base)


def _renders(sc, seeds, **kw):
    out, stats = [], None
    for s in seeds:
        r = render(sc, _settings(seed=s, **kw))
        out.append(np.asarray(r.passes["Combined"][..., :3], np.float64))
        stats = r.stats
    return np.stack(out), stats


def _ztest(a, b, block=8):
    from cycles_ref import block_ztest
    return block_ztest(a, b, block=block, floor=0.01)


def test_portal_keeps_the_image_and_stores_more_photons_in_the_room():
    seeds = (0, 1, 2, 3)
    off, st_off = _renders(room_scene(portal=False), seeds)
    on, st_on = _renders(room_scene(portal=True), seeds)
    r = _ztest(on, off)
    print("portal on vs off:", r.summary(), "stored", st_on["photons_global"], st_off["photons_global"])
    assert r.z_abs_max < 4.5, r.summary()
    assert abs(r.mean_ratio - 1.0) < 0.05, r.summary()
    # every stored photon is in the room (nothing outside stores: no ground): the count is the room's
    assert st_on["photons_global"] > 5 * st_off["photons_global"], (st_on["photons_global"], st_off["photons_global"])


def test_portal_lowers_the_noise_of_direct_light():
    """Next-event estimation through the window: the same expectation, much less noise in the room
    (per-pixel standard deviation over seeds, median over the lit pixels)."""
    seeds = tuple(range(6))
    kw = dict(photons_global=0, samples=2, diffuse_bounces=0)
    off, _ = _renders(room_scene(portal=False), seeds, **kw)
    on, _ = _renders(room_scene(portal=True), seeds, **kw)
    r = _ztest(on, off)
    m = off.mean(axis=(0, 3))
    lit = m > 0.05 * np.percentile(m, 90)
    sd_on, sd_off = on.mean(-1).std(0, ddof=1)[lit], off.mean(-1).std(0, ddof=1)[lit]
    ratio = float(np.median(sd_on / np.maximum(sd_off, 1e-12)))
    print("direct, portal on vs off:", r.summary(), "noise ratio", ratio)
    assert r.z_abs_max < 4.5 and abs(r.mean_ratio - 1.0) < 0.05, r.summary()
    assert ratio < 0.6, ratio


def test_photon_weight_moves_photons_not_the_image():
    seeds = (0, 1, 2, 3)
    sc = room_scene(portal=True, lamp=3.0)
    base, st0 = _renders(sc, seeds)
    sc.lights[0].photon_weight = 6.0
    more, st1 = _renders(sc, seeds)
    n0 = st0["photon_stats"]["photons_emitted_global_per_light"]
    n1 = st1["photon_stats"]["photons_emitted_global_per_light"]
    assert sum(n0) == sum(n1) == 30_000
    assert n1[0] > 2.5 * n0[0] and n1[1] < n0[1], (n0, n1)
    r = _ztest(more, base)
    print("weight 6 vs 1:", r.summary(), n0, n1)
    assert r.z_abs_max < 4.5, r.summary()
    assert abs(r.mean_ratio - 1.0) < 0.05, r.summary()
    # the world's own weight
    sc.lights[0].photon_weight = 1.0
    sc.world.photon_weight = 0.0
    st = render(sc, _settings(samples=1)).stats
    assert st["photon_stats"]["photons_emitted_global_per_light"] == [30_000, 0]


def test_portals_and_weights_survive_the_scene_file(tmp_path):
    sc = room_scene(portal=True, lamp=2.0)
    sc.lights[0].photon_weight = 2.5
    sc.world.photon_weight = 0.5
    save_scene(sc, tmp_path / "room.stpm")
    back = load_scene(tmp_path / "room.stpm")
    assert len(back.portals) == 1 and back.portals[0].type == "AREA"
    np.testing.assert_allclose(back.portals[0].transform.at(np.zeros(1)), portal_light().transform.at(np.zeros(1)))
    assert back.portals[0].size == pytest.approx(0.8)
    assert back.lights[0].photon_weight == 2.5 and back.world.photon_weight == 0.5
    plain = room_scene(portal=False)
    save_scene(plain, tmp_path / "plain.stpm")
    back = load_scene(tmp_path / "plain.stpm")
    assert back.portals == [] and back.world.photon_weight == 1.0


def test_backwards_or_empty_portal_is_named_in_the_warnings():
    """A portal whose emitting side faces away from the camera (placed backwards in the window)
    or that has no area does nothing: the render's warnings say so; a correct one is silent."""
    from stpm_core.scene import scene_warnings
    sc = room_scene(portal=True)
    assert not [w for w in scene_warnings(sc) if "portal" in w]
    back = portal_light()
    M = back.transform.at(np.array([0.5]))[0].copy()
    M[:3, 1] *= -1.0                  # rotated 180 degrees about X: -Z now points out of the window
    M[:3, 2] *= -1.0
    back.transform = MotionTransform.static(M)
    sc.portals = [back]
    w = [x for x in scene_warnings(sc) if "portal" in x]
    assert len(w) == 1 and "faces away from the camera" in w[0] and "'portal'" in w[0]
    sc.portals = [portal_light(shrink=0.0)]
    w = [x for x in scene_warnings(sc) if "portal" in x]
    assert len(w) == 1 and "ignored" in w[0]
