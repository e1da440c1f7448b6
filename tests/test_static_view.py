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
