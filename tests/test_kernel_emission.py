"""Photon emission kernels (stpm_core.kernels.emission) against the numpy oracle (tests/oracles/emission_numpy.py).

For every light type, shape and option, static and moving (rotating keys, a scale that crosses
zero, deforming and moving mesh lights): ``emit`` and ``emit_toward`` (targets near, far,
containing the light, one centre per photon) give the oracle's origins, directions and powers to
float rounding from the same seed, and leave the generator in the same state.  Physical checks:
the powers of ``emit`` sum to ``LightSet.flux`` within Monte Carlo error, a point light at the
exact centre of its target covers the sphere of directions with the whole flux.
"""
from __future__ import annotations

import numpy as np
import pytest

from oracles import emission_numpy as oracle
from scenes import box_mesh, make_scene, ortho_camera_down, plane_mesh, sphere_mesh, translate
from stpm_core.kernels import emission
from stpm_core.lights import LightSet
from stpm_core.motion import MotionTransform
from stpm_core.scene import Light, Material, Mesh

RTOL, ATOL = 1e-9, 1e-12
N = 2000


# ----------------------------------------------------------------------------
# Poses
# ----------------------------------------------------------------------------
def _rot(axis, angle):
    """Rotation matrix (3, 3) about a unit axis (Rodrigues)."""
    k = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


def _pose(pos, R=None, scale=(1.0, 1.0, 1.0)):
    M = np.eye(4)
    M[:3, :3] = (np.eye(3) if R is None else R) @ np.diag(scale)
    M[:3, 3] = pos
    return M


def _static(pos=(0.0, 0.0, 2.0), R=None, scale=(1.0, 1.0, 1.0)):
    return MotionTransform.static(_pose(pos, R, scale))


def _moving(scale=(1.0, 1.0, 1.0)):
    """Three keys: translation, rotation about changing axes (and a scale) across the shutter."""
    return MotionTransform(times=np.array([0.0, 0.4, 1.0]), matrices=np.stack([
        _pose((0.0, 0.0, 2.0), _rot((1, 0, 0), 0.2), scale),
        _pose((0.3, 0.1, 2.2), _rot((0, 1, 0), 0.5) @ _rot((1, 0, 0), 0.3), scale),
        _pose((0.5, -0.2, 2.1), _rot((0, 0, 1), 1.0) @ _rot((0, 1, 0), 0.4), scale)]))


def _flipping():
    """A light mirrored along Z during the shutter: its Z scale crosses zero (rows with no direction)."""
    return MotionTransform(times=np.array([0.0, 1.0]),
                           matrices=np.stack([_pose((0.0, 0.0, 2.0)), _pose((0.2, 0.0, 2.0), scale=(1, 1, -1))]))


# ----------------------------------------------------------------------------
# Scenes: one light (or emitter) above a floor and a box (the sun's and world's bounds)
# ----------------------------------------------------------------------------
MATS = [Material.diffuse((0.8, 0.8, 0.8)), Material.emitter((2.0, 1.0, 0.5)), Material.emitter((0.3, 0.6, 0.9))]


def _scene(lights=(), emitters=(), world=(0.0, 0.0, 0.0)):
    objects = [plane_mesh(4.0), (box_mesh((-0.5, -0.5, 0.0), (0.5, 0.5, 0.8)), translate(0.8, 0.3, 0.0))]
    return make_scene(objects + list(emitters), MATS, ortho_camera_down(), list(lights), world=world)


def _light(typ, transform, **kw):
    kw.setdefault("power", 300.0)
    return Light(type=typ, color=np.array([1.0, 0.7, 0.4]), transform=transform, **kw)


def _mixed_box():
    """A small box whose triangles emit two radiances, two of them not at all."""
    m = box_mesh((-0.2, -0.15, -0.1), (0.2, 0.15, 0.1), name="glow")
    m.material_ids = np.array([1, 1, 2, 2, 0, 0, 1, 2, 1, 2, 2, 1], np.int32)
    return m


def _deforming_quad():
    """An emitting quad that stretches and tilts over three vertex steps."""
    v0 = plane_mesh(0.6, 0.4, material=1).vertices.astype(np.float64)
    v1 = v0 * np.array([1.5, 0.8, 1.0]) + np.array([0.1, 0.0, 0.0])
    v2 = v0.copy()
    v2[:, 2] = 0.3 * v0[:, 0]
    V = np.stack([v0, v1, v2]).astype(np.float32)
    return Mesh(vertices=V, triangles=np.array([[0, 1, 2], [0, 2, 3]], np.int32),
                material_ids=np.array([1, 2], np.int32), vertex_times=np.array([0.0, 0.3, 1.0]), name="deform")


def _case(name):
    """(LightSet, light index) of case ``name``."""
    kind, _, opt = name.partition(":")
    moving = "moving" in opt
    tr = _moving() if moving else _static()
    if kind in ("point", "spot"):
        radius = 0.2 if ("soft" in opt or "sphere" in opt) else 0.0
        kw = dict(radius=radius, use_soft_falloff="soft" in opt)
        if kind == "spot":
            kw.update(spot_size=1.1, spot_blend=0.0 if "blend0" in opt else 0.3)
            if "flip" in opt:
                tr = _flipping()
        return LightSet(_scene([_light(kind.upper(), tr, **kw)])), 0
    if kind == "area":
        shape = opt.split(",")[0].upper()
        scale = (1.0, 1.0, 1.0)
        if "scaled" in opt:
            scale = (1.7, 0.6, 1.0)
        if "mirrored" in opt:
            scale = (1.0, 1.0, -1.0)
        tr = _moving(scale) if moving else _static(R=_rot((1, 1, 0), 0.4), scale=scale)
        if "flip" in opt:
            tr = _flipping()
        if "dead" in opt:
            tr = _static(scale=(1.0, 1.0, 0.0))
        l = _light("AREA", tr, shape=shape, size=0.5, size_y=0.3)
        return LightSet(_scene([l])), 0
    if kind == "sun":
        angle = {"angle0": 0.0, "angle": 0.1, "wide": 3.5}[opt.split(",")[0]]
        if "flip" in opt:
            tr = _flipping()
        if "dead" in opt:
            tr = _static(scale=(0.0, 0.0, 0.0))
        return LightSet(_scene([_light("SUN", tr, power=3.0, angle=angle)])), 0
    if kind == "mesh":
        if "deforming" in opt:
            obj = (_deforming_quad(), _moving() if moving else translate(0.0, 0.0, 2.0))
        elif "box" in opt:
            obj = (_mixed_box(), _moving() if moving else _pose((0.0, 0.0, 2.0), _rot((1, 2, 3), 0.7)))
        else:
            obj = (sphere_mesh(0.2, 6, 12, material=1, name="ball"), _moving() if moving else translate(0, 0, 2))
        ls = LightSet(_scene(emitters=[obj]))
        assert ls.lights[0].type == "MESH"
        return ls, 0
    if kind == "world":
        ls = LightSet(_scene(world=(0.2, 0.3, 0.4)))
        assert ls.lights[-1].type == "WORLD"
        return ls, len(ls) - 1
    raise ValueError(name)


CASES = [
    "point:static", "point:moving", "point:soft,static", "point:soft,moving", "point:sphere,static",
    "point:sphere,moving",
    "spot:static", "spot:moving", "spot:blend0,static", "spot:blend0,moving", "spot:soft,static",
    "spot:soft,moving", "spot:sphere,static", "spot:sphere,moving", "spot:flip",
    "area:square,static", "area:square,moving", "area:rectangle,static", "area:rectangle,moving",
    "area:disk,static", "area:disk,moving", "area:ellipse,static", "area:ellipse,moving",
    "area:rectangle,scaled,moving", "area:ellipse,scaled,static", "area:square,mirrored,static",
    "area:disk,mirrored,moving", "area:square,flip", "area:square,dead",
    "mesh:ball,static", "mesh:ball,moving", "mesh:box,static", "mesh:box,moving",
    "mesh:deforming,static", "mesh:deforming,moving",
    "sun:angle0,static", "sun:angle0,moving", "sun:angle,static", "sun:angle,moving", "sun:wide,static",
    "sun:angle,flip", "sun:angle0,dead",
    "world",
]

# Target spheres of emit_toward: near the lights (they sit around (0, 0, 2)), far, containing
# every light at every time, and one centre per photon.
TARGETS = {
    "near": (np.array([0.2, 0.1, 1.0]), 0.3),
    "far": (np.array([30.0, -20.0, -40.0]), 0.5),
    "contains": (np.array([0.1, 0.0, 2.0]), 2.0),
    "per_photon": (np.random.default_rng(9).uniform([-1.0, -1.0, 0.0], [1.0, 1.0, 1.0], (N, 3)), 0.25),
}

def _times(n=N, seed=11):
    return np.random.default_rng(seed).random(n)


def _assert_same(got, want, rng_got, rng_want, label):
    """Kernel outputs equal the oracle's to float rounding; both generators in the same state."""
    for name, g, w in zip(("origins", "dirs", "power"), got, want):
        w = np.broadcast_to(w, g.shape)
        assert g.shape == (w.shape[0], 3) and g.dtype == np.float64
        np.testing.assert_allclose(g, w, rtol=RTOL, atol=ATOL, err_msg=f"{label}: {name}")
    assert rng_got.bit_generator.state == rng_want.bit_generator.state, label
    assert rng_got.random() == rng_want.random(), label


# ----------------------------------------------------------------------------
# Kernel = oracle
# ----------------------------------------------------------------------------
@pytest.mark.parametrize("case", CASES)
def test_emit_matches_the_numpy_oracle(case):
    ls, li = _case(case)
    t = _times()
    got = emission.emit(ls, li, N, t, rng_a := np.random.default_rng(5))
    want = oracle.emit(ls, li, N, t, rng_b := np.random.default_rng(5))
    _assert_same(got, want, rng_a, rng_b, case)
    assert np.allclose(np.linalg.norm(got[1], axis=1), 1.0, atol=1e-12)


@pytest.mark.parametrize("target", list(TARGETS))
@pytest.mark.parametrize("case", CASES)
def test_emit_toward_matches_the_numpy_oracle(case, target):
    ls, li = _case(case)
    c, r = TARGETS[target]
    t = _times()
    got = emission.emit_toward(ls, li, N, t, rng_a := np.random.default_rng(6), c, r)
    want = oracle.emit_toward(ls, li, N, t, rng_b := np.random.default_rng(6), c, r)
    _assert_same(got, want, rng_a, rng_b, f"{case} -> {target}")
    assert np.allclose(np.linalg.norm(got[1], axis=1), 1.0, atol=1e-12)


@pytest.mark.parametrize("case", ["point:moving", "point:sphere,moving", "spot:moving", "area:disk,moving",
                                  "mesh:box,moving", "mesh:deforming,moving", "sun:angle,moving", "world"])
@pytest.mark.parametrize("times", [0.3, np.array([0.7])])
def test_one_time_for_every_photon(case, times):
    """A scalar or (1,) time: every photon at that time (the oracle gives (1, 3) where it does not broadcast)."""
    ls, li = _case(case)
    got = emission.emit(ls, li, 300, times, rng_a := np.random.default_rng(1))
    want = oracle.emit(ls, li, 300, times, rng_b := np.random.default_rng(1))
    _assert_same(got, want, rng_a, rng_b, case)
    c, r = TARGETS["near"]
    got = emission.emit_toward(ls, li, 300, times, rng_a, c, r)
    want = oracle.emit_toward(ls, li, 300, times, rng_b, c, r)
    _assert_same(got, want, rng_a, rng_b, case)


@pytest.mark.parametrize("case", ["point:static", "point:soft,static", "point:sphere,static", "spot:static"])
def test_point_light_at_the_exact_centre_of_its_target(case):
    """Emission point = target centre: the whole sphere of directions, kernel = oracle; a point light's
    photons then carry its whole flux (the spot's its intensity over 4 pi, masked)."""
    ls, li = _case(case)
    c = ls._frame(li, np.zeros(1))[0][0]
    t = _times()
    got = emission.emit_toward(ls, li, N, t, rng_a := np.random.default_rng(2), c, 0.4)
    want = oracle.emit_toward(ls, li, N, t, rng_b := np.random.default_rng(2), c, 0.4)
    _assert_same(got, want, rng_a, rng_b, case)
    o, d, P = got
    assert abs(np.mean(d[:, 2] > 0) - 0.5) < 0.05                  # every direction
    if case.startswith("point"):
        assert np.allclose(P.sum(0), ls.flux(li), rtol=1e-12)


def test_no_photons():
    ls, li = _case("mesh:box,moving")
    rng = np.random.default_rng(0)
    for o, d, P in (emission.emit(ls, li, 0, np.zeros(0), rng),
                    emission.emit_toward(ls, li, 0, np.zeros(0), rng, np.zeros(3), 1.0)):
        assert o.shape == d.shape == P.shape == (0, 3)
    assert rng.random() == np.random.default_rng(0).random()


# ----------------------------------------------------------------------------
# Physics: emitted power sums to the light's flux
# ----------------------------------------------------------------------------
@pytest.mark.parametrize("case", [c for c in CASES if "flip" not in c])
def test_emitted_power_sums_to_the_flux(case):
    """sum of photon powers = LightSet.flux within 5 sigma (exact for lights with equal powers).

    Deforming meshes change area over the shutter and the flux is that at mid-shutter: their
    photons are emitted at t = 0.5.
    """
    ls, li = _case(case)
    n = 100_000
    t = np.full(n, 0.5) if "deforming" in case else _times(n)
    o, d, P = emission.emit(ls, li, n, t, np.random.default_rng(3))
    flux = ls.flux(li)
    total = P.sum(0)
    sigma = np.sqrt(n) * P.std(0)
    assert np.all(np.abs(total - flux) <= 5.0 * sigma + 1e-9 * np.abs(flux) + 1e-300), (total, flux, sigma)
    if "dead" in case:
        assert np.all(P == 0.0) and np.all(flux == 0.0)
    else:
        assert np.all(flux > 0.0)

