"""A static view reads the shutter's average (integrator.static_view_setup / static_view_rows).

docs/photon-mapping.md, "Static views read the shutter's average": with TEMPORAL or KD4D maps,
a camera ray's first hit on a static surface that no moving object comes near along the ray is
estimated with STANDARD -- the pixel's expected value there is the shutter average of the
irradiance, which STANDARD reads from all photons.
"""
from __future__ import annotations

import numpy as np
import pytest

from stpm_core import integrator
from stpm_core.demo import demo_scene, demo_settings
from stpm_core.motion import MotionTransform
from stpm_core.render import render
from stpm_core.settings import RenderSettings


class _Maps:
    reads_standard = True

    def __init__(self, estimator="TEMPORAL"):
        self.estimator = estimator


def _segments(setup, o, p, inst):
    return integrator.static_view_rows(setup, np.asarray(o, float), np.asarray(p, float), np.asarray(inst))


def test_rows_near_a_moving_sphere_are_not_static():
    """The demo's glass sphere (r = 0.5, centre z = 0.8) slides from x = -0.5 to 0.5 at y = 0."""
    scene = demo_scene((16, 12))
    setup = integrator.static_view_setup(scene, _Maps())
    assert setup is not None
    static = setup[0]
    assert static.tolist() == [True, False]                     # floor static, sphere moving
    o = np.array([[0.0, -3.0, 0.8]] * 6)
    p = np.array([[0.0, 3.0, 0.0],      # through the sphere's path (passes y = 0 at z ~ 0.4)
                  [2.0, 3.0, 0.8],      # x = 1 at y = 0: 0.5 beyond the sphere's last centre, grazing
                  [3.0, 3.0, 0.8],      # x = 1.5 at y = 0: 1 m from the last centre: clear
                  [0.0, 3.0, 2.7],      # z = 1.75 at y = 0: 0.95 above the centre: clear
                  [0.0, -0.1, 0.8],     # ends before the path (y = -0.1, 0.1 from it; r = 0.5): near
                  [0.0, -1.0, 0.8]])    # ends 1 m before the path: clear
    ok = _segments(setup, o, p, [0] * 6)
    assert ok.tolist() == [False, False, True, True, False, True]
    # the moving sphere itself is never a static view, nor a miss
    assert not _segments(setup, o[:2], p[:2], [1, -1]).any()


def test_capsules_are_tighter_than_the_swept_box():
    """A ray through the swept box's corner but clear of the sphere at every instant is static."""
    scene = demo_scene((16, 12))
    setup = integrator.static_view_setup(scene, _Maps())
    lo, hi = setup[1][0], setup[2][0]
    # vertical, at y = -0.49 from z = 0.31 down: inside the box (y in [-0.5, 0.5], z from 0.3 up),
    # 0.69 from the sphere centre's path (y = 0, z = 0.8) where closest, so clear of r = 0.5
    o, p = np.array([[-0.8, -0.49, 0.31]]), np.array([[-0.8, -0.49, 0.0]])
    assert np.all(lo <= [-0.8, -0.49, 0.31]) and np.all([-0.8, -0.49, 0.31] <= hi)
    assert _segments(setup, o, p, [0]).tolist() == [True]
    # at x = -0.4 (on the path), 0.46 from it where closest: near
    o, p = np.array([[-0.4, -0.3, 0.45]]), np.array([[-0.4, -0.3, 0.0]])
    assert _segments(setup, o, p, [0]).tolist() == [False]


@pytest.mark.parametrize("what", ["STANDARD", "moving camera", "instant shutter", "no flag", "off"])
def test_no_static_view_where_it_cannot_hold(what, monkeypatch):
    scene = demo_scene((16, 12))
    maps = _Maps()
    if what == "STANDARD":
        maps = _Maps("STANDARD")
    elif what == "moving camera":
        M = scene.camera.transform.at(0.0)
        M2 = M.copy()
        M2[0, 3] += 0.1
        scene.camera.transform = MotionTransform(times=np.array([0.0, 1.0]), matrices=np.stack([M, M2]))
    elif what == "instant shutter":
        scene.shutter.close = scene.shutter.open
    elif what == "no flag":
        maps = object()                 # the progressive kernel's / SPPM's maps
    else:
        monkeypatch.setattr(integrator, "STATIC_VIEW", False)
    assert integrator.static_view_setup(scene, maps) is None


def _caustic(settings, static_view, monkeypatch):
    monkeypatch.setattr(integrator, "STATIC_VIEW", static_view)
    r = render(demo_scene((64, 48)), settings)
    return r.passes["Caustic"][..., :3].astype(np.float64).mean(axis=-1), r.stats


def test_demo_static_floor_caustic_matches_the_accumulation_buffer(monkeypatch):
    """The demo's caustic slides over a static floor.  At a static view the right answer is the
    shutter average: an accumulation buffer of 24 stills reads it; TEMPORAL with static views is
    within 5 % of it over the image, STANDARD's value bit for bit on the floor in front of the
    sphere.  Without static views TEMPORAL reads it about 1.9x (a k-nearest window in time at an
    instant without the caustic widens until it reaches the caustic's photons)."""
    base = demo_settings(quick=True).replace(samples=8, photons_caustic=60_000, photons_global=0, k_nearest=20,
                                             seed=5)
    acc, _ = _caustic(base.replace(method="ACCUMULATION", accumulation_steps=24, samples=1), True, monkeypatch)
    sv, st = _caustic(base, True, monkeypatch)
    plain, st0 = _caustic(base, False, monkeypatch)
    std, _ = _caustic(base.replace(estimator="STANDARD"), True, monkeypatch)
    assert st["estimator"] == "TEMPORAL" and st["static_lookups"] > 0.6 * st["photon_lookups"]
    assert st0["static_lookups"] == 0
    front = slice(36, 48)                                       # floor rows in front of the sphere
    np.testing.assert_array_equal(sv[front], std[front])
    assert abs(sv.mean() / acc.mean() - 1.0) < 0.05, (sv.mean(), acc.mean())
    assert plain.mean() / acc.mean() > 1.3, (plain.mean(), acc.mean())


def test_a_bent_path_is_covered_by_its_parts():
    """Keys at 0, 0.5, 1 put the sphere's centre at angles 0, 45 and 90 degrees on a 1 m circle
    (translation interpolated linearly between keys: two chords with a corner).  Vertical rays:
    through the corner, near (r = 0.3); at (0.35, 0.35), 0.47 m from both chords, clear (one capsule
    from the first key to the last would be 0.21 m from it: near); 0.5 m beyond the corner, clear."""
    scene = demo_scene((16, 12))
    sphere = scene.meshes[1]
    sphere.vertices = np.asarray(sphere.vertices) * 0.6                  # r = 0.3
    ang = np.radians([0.0, 45.0, 90.0])
    M = np.stack([np.eye(4)] * 3)
    M[:, 0, 3], M[:, 1, 3], M[:, 2, 3] = np.cos(ang), np.sin(ang), 0.8
    scene.instances[1].transform = MotionTransform(times=np.array([0.0, 0.5, 1.0]), matrices=M)
    setup = integrator.static_view_setup(scene, _Maps())
    assert setup[3].shape[0] > 1                                        # not one straight capsule
    corner = np.array([np.cos(ang[1]), np.sin(ang[1])])
    mid = np.array([0.35, 0.35])                                        # inside the corner, off both chords
    beyond = corner * (1.0 + 0.5 / 1.0)
    o = np.array([[corner[0], corner[1], 3.0], [mid[0], mid[1], 3.0], [beyond[0], beyond[1], 3.0]])
    p = o.copy()
    p[:, 2] = 0.0
    assert _segments(setup, o, p, [0, 0, 0]).tolist() == [False, True, True]


def test_progressive_reads_static_views_with_the_disc(monkeypatch):
    """PROGRESSIVE: a static view's kernel is the surface disc (its own pilot region and a = 0.5).
    The demo's caustic after 24 passes: within 10 % of the accumulation buffer (measured 1.077; the
    rest is the space-time kernel's early bias behind the sphere, 1.058 at 96 passes); without static
    views 1.57 (1.18 at 96 passes)."""
    base = demo_settings(quick=True).replace(samples=1, photons_caustic=12_500, photons_global=0, k_nearest=20,
                                             seed=5)
    acc, _ = _caustic(base.replace(method="ACCUMULATION", accumulation_steps=24, samples=8,
                                   photons_caustic=60_000), True, monkeypatch)
    prog, st = _caustic(base.replace(method="PROGRESSIVE", passes=24), True, monkeypatch)
    plain, st0 = _caustic(base.replace(method="PROGRESSIVE", passes=24), False, monkeypatch)
    assert st["static_lookups"] > 0.6 * st["photon_lookups"] and st0["static_lookups"] == 0
    assert abs(prog.mean() / acc.mean() - 1.0) < 0.10, (prog.mean(), acc.mean())
    assert plain.mean() / acc.mean() > 1.3, (plain.mean(), acc.mean())
    assert np.all(np.isfinite(prog)) and prog.min() >= 0.0


# ----------------------------------------------------------------------------
# Later vertices: a path camera -> v1 -> ... -> vk all static reads STANDARD at vk
# ----------------------------------------------------------------------------
def test_kernel_matches_the_numpy_oracle():
    """``kernels.static_views.static_segments`` (through static_view_rows) against the numpy form it
    replaced, on random segments around the demo's sphere path and a bent path, with and without
    a chain flag and with one origin for all rows."""
    from oracles.static_view_numpy import static_view_rows as oracle
    rng = np.random.default_rng(3)
    scene = demo_scene((16, 12))
    setups = [integrator.static_view_setup(scene, _Maps())]
    M = np.stack([np.eye(4)] * 3)
    ang = np.radians([0.0, 45.0, 90.0])
    M[:, 0, 3], M[:, 1, 3], M[:, 2, 3] = np.cos(ang), np.sin(ang), 0.8
    scene.instances[1].transform = MotionTransform(times=np.array([0.0, 0.5, 1.0]), matrices=M)
    setups.append(integrator.static_view_setup(scene, _Maps()))
    n = 4000
    o = rng.uniform(-2.0, 2.0, (n, 3))
    p = rng.uniform(-2.0, 2.0, (n, 3))
    p[:50] = o[:50]                                              # empty segments
    p[50:100, :2] = o[50:100, :2]                                # axis-parallel ones
    inst = rng.integers(-1, 2, n)
    chain = rng.random(n) < 0.7
    for setup in setups:
        for c in (None, chain):
            got = integrator.static_view_rows(setup, o, p, inst, c)
            np.testing.assert_array_equal(got, oracle(setup, o, p, inst, c))
            assert 0 < got.sum() < n
        np.testing.assert_array_equal(integrator.static_view_rows(setup, o[:1], p, inst),
                                      oracle(setup, o[:1], p, inst))


def _mirror_scene(box_at, floor):
    """An orthographic camera (1 m x 1 m, looking +y at z = 1.5 .. 2.5) sees only a static 45-degree
    mirror (normal (0, -1, -1) / sqrt 2, centred at (0, 0, 2)), which shows the static floor straight
    below it (x, y in [-0.5, 0.5]): every photon query is a camera path's second vertex, reached
    by vertical segments from the mirror.  A point light in front lights the floor directly and
    through the mirror (a caustic).  A box (half-size 0.3) slides 1 m along x at box_at (its
    centre's y, z at the shutter's middle) during the shutter."""
    from scenes import box_mesh, look_at, make_scene, moving, plane_mesh, point_light
    from stpm_core.scene import Camera, Material
    from stpm_core.shutter import Shutter
    c, s = np.cos(np.radians(135.0)), np.sin(np.radians(135.0))
    R = np.eye(4)
    R[1:3, 1:3] = [[c, -s], [s, c]]
    R[:3, 3] = (0.0, 0.0, 2.0)
    mats = [floor, Material.mirror(), Material.diffuse((0.5, 0.5, 0.5))]
    x, y, z = box_at
    objs = [plane_mesh(10.0, z=0.0, material=0, name="floor"), (plane_mesh(2.0, material=1, name="mirror"), R),
            (box_mesh((-0.3, -0.3, -0.3), (0.3, 0.3, 0.3), material=2), moving((x - 0.5, y, z), (x + 0.5, y, z)))]
    cam = Camera(type="ORTHO", transform=MotionTransform.static(look_at((0.0, -5.0, 2.0), (0.0, 0.0, 2.0))),
                 ortho_scale=1.0, clip_start=0.01, clip_end=100.0)
    return make_scene(objs, mats, cam, [point_light((0.0, -1.5, 1.0), 100.0)], resolution=(24, 24),
                      shutter=Shutter(1.0, 2.0))


@pytest.mark.parametrize("floor", ["diffuse", "rough metal"])
def test_a_static_mirror_shows_a_static_floor_with_standard(floor, monkeypatch):
    """Box far beside the paths (x = 3, y = 1.5): every floor query (the second vertex of a path
    camera -> mirror -> floor, all static) reads STANDARD: the Caustic pass is STANDARD's bit for
    bit (with STATIC_VIEW off, or on main, it is TEMPORAL's: not equal).  Box sliding between the
    mirror and the floor (centre y = 0.3, z = 0.8): the mirror-to-floor segments of floor points at
    y > 0 cross its swept box and come within its capsule (radius 0.52 about y = 0.3, z = 0.8), so
    those paths keep TEMPORAL (although the camera-to-mirror segments are clear); the others read
    STANDARD.  A rough metal floor (roughness 0.6: its rough lobe reads the caustic map, the glossy
    look-up) the same."""
    from stpm_core.scene import Material
    mat = Material.diffuse((0.8, 0.8, 0.8)) if floor == "diffuse" else Material.mirror((0.8, 0.8, 0.8), 0.6)
    # (max_depth 1: the paths end at the floor, camera -> mirror -> floor)
    settings = RenderSettings(samples=4, photons_caustic=40_000, photons_global=0, k_nearest=20, seed=3,
                              estimator="TEMPORAL", threads=1, max_depth=1)

    def caustic(box_at, estimator="TEMPORAL", static_view=True):
        monkeypatch.setattr(integrator, "STATIC_VIEW", static_view)
        monkeypatch.setattr(integrator, "STATIC_VIEW_GLOSSY", True)
        r = render(_mirror_scene(box_at, mat), settings.replace(estimator=estimator))
        return r.passes["Caustic"][..., :3].astype(np.float64), r.stats

    beside = (3.0, 1.5, 0.3)
    tmp, st = caustic(beside)
    std, _ = caustic(beside, "STANDARD")
    off, st_off = caustic(beside, static_view=False)
    assert std.mean() > 0.0 and st["photon_lookups"] > 0
    assert st["static_lookups"] == st["photon_lookups"] and st_off["static_lookups"] == 0
    np.testing.assert_array_equal(tmp, std)
    assert np.count_nonzero(off != std) > 0.5 * off.size
    # the box between the mirror and the floor
    between = (0.0, 0.3, 0.8)
    tmp, st = caustic(between)
    std, _ = caustic(between, "STANDARD")
    assert 0.3 < st["static_lookups"] / st["photon_lookups"] < 0.6, st
    # image rows top (z = 2.5: floor y = -0.5) to bottom (z = 1.5: floor y = 0.5)
    y_floor = -0.5 + (np.arange(24) + 0.5) / 24.0
    np.testing.assert_array_equal(tmp[y_floor < -0.1], std[y_floor < -0.1])
    assert np.all(np.any(tmp[y_floor > 0.1] != std[y_floor > 0.1], axis=(1, 2)))


def test_rough_lobes_at_a_first_static_view_read_standard(monkeypatch):
    """Camera rays straight down onto a rough metal floor (roughness 0.6: its rough lobe reads the
    mirror's caustic, the glossy look-up ``integrator._glossy_caustic``) with a box sliding below
    the floor (no path comes near it).  By default (``STATIC_VIEW_GLOSSY`` off: measured, see
    docs/photon-mapping.md) these rows keep TEMPORAL; with it on every query is a static view and
    the Caustic pass STANDARD's bit for bit."""
    from scenes import box_mesh, moving
    from test_photons import mirror_scene
    from stpm_core.scene import Material
    scene = mirror_scene(box=(box_mesh((-0.3, -0.3, 0.0), (0.3, 0.3, 0.6), material=2),
                              moving((0.0, 0.0, -3.0), (1.0, 0.0, -3.0))))
    # (a diffuse box: the effects plan asks for caustics where a diffuse surface may receive them)
    scene.materials[0] = Material.mirror((0.8, 0.8, 0.8), 0.6)
    scene.materials.append(Material.diffuse())
    scene.resolution = (24, 24)
    settings = RenderSettings(samples=4, photons_caustic=40_000, photons_global=0, k_nearest=20, seed=3,
                              estimator="TEMPORAL", threads=1, max_depth=1)
    monkeypatch.setattr(integrator, "STATIC_VIEW", True)
    s = render(scene, settings.replace(estimator="STANDARD"))
    assert s.passes["Caustic"].mean() > 0.0
    # by default (STATIC_VIEW_GLOSSY off) the rough lobes keep the render's estimator
    d = render(scene, settings)
    assert d.stats["photon_lookups"] > 0 and d.stats["static_lookups"] == 0
    assert not np.array_equal(d.passes["Caustic"], s.passes["Caustic"])
    monkeypatch.setattr(integrator, "STATIC_VIEW_GLOSSY", True)
    r = render(scene, settings)
    assert r.stats["photon_lookups"] > 0 and r.stats["static_lookups"] == r.stats["photon_lookups"]
    np.testing.assert_array_equal(r.passes["Caustic"], s.passes["Caustic"])


def test_progressive_reads_later_static_vertices_with_the_disc(monkeypatch):
    """PROGRESSIVE goes through the same paths: in the mirror scene with the box far away every
    floor query (a path's second vertex) reads the static views' disc; with the box between mirror
    and floor about half do (measured 2220 of 4608); finite, non-negative images."""
    from stpm_core.scene import Material
    monkeypatch.setattr(integrator, "STATIC_VIEW", True)
    settings = RenderSettings(method="PROGRESSIVE", passes=8, samples=1, photons_caustic=20_000, photons_global=0,
                              k_nearest=20, seed=3, max_depth=1)
    for at, lo, hi in (((3.0, 1.5, 0.3), 1.0, 1.0), ((0.0, 0.3, 0.8), 0.3, 0.6)):
        r = render(_mirror_scene(at, Material.diffuse((0.8, 0.8, 0.8))), settings)
        c = r.passes["Caustic"][..., :3]
        assert lo <= r.stats["static_lookups"] / r.stats["photon_lookups"] <= hi, r.stats
        assert np.all(np.isfinite(c)) and c.min() >= 0.0 and c.mean() > 0.0
