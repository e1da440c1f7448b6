"""Rectangular AREA lights sampled uniformly in solid angle (the spherical rectangle of
stpm_core/kernels/lights.py; its numpy oracle in tests/oracles/lights_numpy.py).

Analytic reference: a Lambertian rectangle of radiance L parallel to a surface point's plane, one
corner above the point at height c, sides a, b: irradiance E = pi L F with the form factor
F = 1 / (2 pi) [A / sqrt(1 + A^2) atan(B / sqrt(1 + A^2)) + B / sqrt(1 + B^2) atan(A / sqrt(1 + B^2))],
A = a / c, B = b / c; a point under the centre of a w x w square sums four such quadrants.
"""
from __future__ import annotations

import numpy as np
import pytest

from oracles.lights_numpy import spherical_rect_sample
from scenes import make_scene, ortho_camera_down, plane_mesh, translate
from stpm_core.lights import LightSet
from stpm_core.motion import MotionTransform
from stpm_core.scene import Light, Material


def _quadrant_F(a, b, c):
    A, B = a / c, b / c
    return (A / np.sqrt(1 + A * A) * np.arctan(B / np.sqrt(1 + A * A))
            + B / np.sqrt(1 + B * B) * np.arctan(A / np.sqrt(1 + B * B))) / (2 * np.pi)


def _estimates(light, p, n=40_000, seed=3):
    scene = make_scene([plane_mesh(1.0)], [Material.diffuse((0.5, 0.5, 0.5))], ortho_camera_down(), [light])
    ls = LightSet(scene)
    P = np.tile(p, (n, 1))
    wi, dist, weight = ls.sample_direct(0, P, np.zeros(n), np.random.default_rng(seed).random((n, 2)))
    return weight[:, 0] * np.maximum(wi[:, 2], 0.0)          # per-sample irradiance on a +z facing point


@pytest.mark.parametrize("w, h", [(10.0, 1.0), (2.0, 1.0), (0.5, 3.0)])
def test_square_light_irradiance_matches_the_form_factor_with_low_noise(w, h):
    power = 1000.0
    light = Light(type="AREA", shape="SQUARE", size=w, power=power, transform=MotionTransform.static(translate(0, 0, h)))
    e = _estimates(light, np.zeros(3))
    L = power / (np.pi * w * w)
    want = np.pi * L * 4 * _quadrant_F(w / 2, w / 2, h)
    assert e.mean() == pytest.approx(want, rel=0.01)
    # uniform in solid angle: only the cosine varies; by area a 10 m light 1 m above had std/mean 2.8
    assert e.std() / e.mean() < 0.6


def test_rectangle_off_centre_and_behind():
    light = Light(type="AREA", shape="RECTANGLE", size=3.0, size_y=1.0, power=500.0,
                  transform=MotionTransform.static(translate(1.5, 0.5, 2.0)))
    e = _estimates(light, np.zeros(3))
    L = 500.0 / (np.pi * 3.0)
    want = np.pi * L * _quadrant_F(3.0, 1.0, 2.0)          # the point sits under a corner
    assert e.mean() == pytest.approx(want, rel=0.01)
    # a point above the light sees its back: nothing
    assert np.all(_estimates(light, np.array([1.5, 0.5, 3.0])) == 0.0)


def test_sampled_points_lie_on_the_rectangle_and_cover_it():
    rng = np.random.default_rng(1)
    n = 50_000
    o = np.tile([0.2, -0.1, 0.0], (n, 1))
    s, ex, ey = np.array([-1.0, -1.0, 1.0]), np.array([2.0, 0.0, 0.0]), np.array([0.0, 2.0, 0.0])
    q, S = spherical_rect_sample(o, np.tile(s, (n, 1)), np.tile(ex, (n, 1)), np.tile(ey, (n, 1)), rng.random((n, 2)))
    a, b = (q - s) @ ex / 4.0, (q - s) @ ey / 4.0
    assert np.allclose(q[:, 2], 1.0) and a.min() >= 0 and a.max() <= 1 and b.min() >= 0 and b.max() <= 1
    assert a.min() < 0.01 and a.max() > 0.99 and b.min() < 0.01 and b.max() > 0.99
    # S = the solid angle: integral of cos / d^2 over the rectangle (by a fine grid)
    g = (np.arange(400) + 0.5) / 400
    X, Y = np.meshgrid(-1 + 2 * g, -1 + 2 * g)
    d2 = (X - 0.2) ** 2 + (Y + 0.1) ** 2 + 1.0
    assert S[0] == pytest.approx(np.sum(1.0 / d2 ** 1.5) * (2 / 400) ** 2, rel=1e-4)


def test_rotated_light_from_float32_matrices_is_sampled_by_solid_angle():
    """Blender hands over float32 matrices: a rotated light's X and Y columns are orthogonal only to
    ~1e-8.  The solid-angle path must still be taken (std/mean of the per-sample irradiance stays low)."""
    from scenes import look_at
    M = look_at((0.3, -0.2, 1.0), (0.35, -0.1, 0.0), up=(0.3, 1.0, 0.2)).astype(np.float32).astype(np.float64)
    X, Y = M[:3, 0], M[:3, 1]
    assert 1e-10 < abs(X @ Y) / (np.linalg.norm(X) * np.linalg.norm(Y)) < 1e-5
    light = Light(type="AREA", shape="SQUARE", size=6.0, power=1000.0, transform=MotionTransform.static(M))
    e = _estimates(light, np.zeros(3))
    assert e.std() / e.mean() < 0.6
