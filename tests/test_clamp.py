"""Clamp Direct / Indirect (RenderSettings.clamp_direct, clamp_indirect; Cycles' names and meaning):
each contribution to a sample is scaled so its largest channel is at most the clamp -- direct for
the camera's first hit (what it emits or sees of the world, and its next-event estimate),
indirect after a bounce and for the photon maps.  Off (0) by default."""
from __future__ import annotations

import numpy as np
import pytest

from scenes import make_scene, ortho_camera_down, plane_mesh
from stpm_core.errors import SettingsError
from stpm_core.render import render
from stpm_core.scene import Material
from stpm_core.settings import RenderSettings

L = np.array([5.0, 2.5, 1.0])


def _render(**kw):
    floor = plane_mesh(1.0, material=0)
    floor.vertices = (np.asarray(floor.vertices) + np.float32([-0.5, 0, 0])).astype(np.float32)
    mirror = plane_mesh(1.0, material=1)
    mirror.vertices = (np.asarray(mirror.vertices) + np.float32([0.5, 0, 0])).astype(np.float32)
    sc = make_scene([floor, mirror], [Material.diffuse((0.8, 0.8, 0.8)), Material.mirror((1, 1, 1))],
                    ortho_camera_down(2.0, 2.0), world=L, resolution=(16, 16))
    s = dict(samples=4, photons_caustic=0, photons_global=0, effects="MANUAL", caustics=False, indirect=False,
             filter_width=0.0, seed=1)
    s.update(kw)
    return render(sc, RenderSettings(**s)).passes["Combined"][..., :3]


def test_clamps_scale_each_contribution_down_to_their_value():
    free = _render()
    clamped = _render(clamp_direct=1.0, clamp_indirect=2.0)
    # the diffuse plane (direct light) and the mirror (the world seen after one bounce: indirect),
    # away from their shared edge and the border
    diffuse, mirror = (slice(5, 11), slice(1, 6)), (slice(5, 11), slice(10, 15))
    np.testing.assert_allclose(free[diffuse].reshape(-1, 3), np.broadcast_to(0.8 * L, (30, 3)), rtol=1e-6)
    np.testing.assert_allclose(free[mirror].reshape(-1, 3), np.broadcast_to(L, (30, 3)), rtol=1e-6)
    np.testing.assert_allclose(clamped[diffuse].reshape(-1, 3),
                               np.broadcast_to(0.8 * L / 4.0, (30, 3)), rtol=1e-6)      # 4 -> 1
    np.testing.assert_allclose(clamped[mirror].reshape(-1, 3), np.broadcast_to(L * 2.0 / 5.0, (30, 3)),
                               rtol=1e-6)                                                # 5 -> 2 (hue kept)
    # the background is the world seen by camera rays: a direct contribution, 5 -> 1
    np.testing.assert_allclose(clamped[0], np.broadcast_to(L / 5.0, (16, 3)), rtol=1e-6)


def test_clamp_settings_are_checked():
    with pytest.raises(SettingsError, match="clamp_direct"):
        RenderSettings(clamp_direct=-1.0)
    with pytest.raises(SettingsError, match="clamp_indirect"):
        RenderSettings(clamp_indirect=float("nan"))
    assert RenderSettings().clamp_direct == 0.0 and RenderSettings().clamp_indirect == 0.0
