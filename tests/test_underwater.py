"""A floor under flat water, lit by a sun through the surface and seen from the air above (bpy 5.0).

The water is one sheet (a plane with a Glass BSDF, normal up): light and camera are in the air,
the floor is in the water.  Photons carry flux through the surface, so the floor's irradiance is
E = E_sun cos(theta_i) T(theta_i) (a flat surface keeps the beam's footprint on a parallel floor);
the floor's radiance in the water is rho E / pi, and the camera above sees it through the surface
divided by n^2 (radiance over n^2 is what is conserved across an interface), times T(theta_v):

    L = rho / pi * E_sun cos(theta_i) T(theta_i) * T(theta_v) / n^2

Cycles renders exactly this: its camera paths carry no eta^2 at a refraction and its path traced
caustic (floor -> surface -> sun) sees the sun's disc compressed by the refraction.  Measured on
``blend_scenes/sunlit_pool.blend`` at 80 x 60 (floor centre, mean luminance): flat water,
IOR 1.33: Cycles MNEE 0.0742, STPM 0.0726; IOR 1.6: Cycles MNEE 0.0509, STPM 0.0524; IOR 1.0001:
Cycles path tracing 0.128, STPM 0.130; rippled water with motion blur: Cycles path tracing
(2048 spp) 0.0753, STPM 0.0722.  Until 2026-12-06 STPM's photons carried no 1 / eta^2 either,
so everything under water read n^2 too bright (1.77x at IOR 1.33; 0.127 where Cycles has 0.074).

A closed glass object changes nothing: a photon entering and leaving it gets 1 / eta^2 and eta^2
(the glass-slab and sphere caustic tests hold that).
"""
from __future__ import annotations

import math

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from test_addon_scenes import add_camera, add_light, add_mesh, fresh, set_world  # noqa: E402
from cycles_ref import render_stpm  # noqa: E402

SUN_E = 3.0                       # W/m^2
SUN_ELEVATION = 60.0              # degrees
RHO = 0.8
#: photon noise over the floor's centre (400k photons, k = 50): measured 0.997-1.022 of expected(ior)
#: (IOR 1.0001, 1.33, 1.6; seeds 0-2); the old code was 77 % and 156 % too bright (n^2)
TOL = 0.04


def _fresnel(cos_i: float, eta: float) -> float:
    """Unpolarised dielectric reflectance for cos_i in the incident medium, eta = n_t / n_i."""
    s2 = (1.0 - cos_i * cos_i) / (eta * eta)
    if s2 >= 1.0:
        return 1.0
    cos_t = math.sqrt(1.0 - s2)
    rs = (cos_i - eta * cos_t) / (cos_i + eta * cos_t)
    rp = (eta * cos_i - cos_t) / (eta * cos_i + cos_t)
    return 0.5 * (rs * rs + rp * rp)


def expected(ior: float) -> float:
    """Radiance (W/(m^2 sr)) of the floor's centre seen straight down from the air (module docstring)."""
    cos_i = math.sin(math.radians(SUN_ELEVATION))
    return RHO / math.pi * SUN_E * cos_i * (1.0 - _fresnel(cos_i, ior)) * (1.0 - _fresnel(1.0, ior)) / ior ** 2


def _scene(ior: float) -> None:
    scene = fresh()
    scene.render.resolution_x, scene.render.resolution_y = 32, 24
    set_world((0.0, 0.0, 0.0))
    floor = bpy.data.materials.new("Floor")
    floor.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = (RHO, RHO, RHO, 1.0)
    floor.node_tree.nodes["Principled BSDF"].inputs["Roughness"].default_value = 1.0
    floor.node_tree.nodes["Principled BSDF"].inputs["Specular IOR Level"].default_value = 0.0
    water = bpy.data.materials.new("Water")
    tree = water.node_tree
    tree.nodes.remove(tree.nodes["Principled BSDF"])
    glass = tree.nodes.new("ShaderNodeBsdfGlass")
    glass.inputs["IOR"].default_value = ior
    glass.inputs["Roughness"].default_value = 0.0
    tree.links.new(glass.outputs[0], tree.nodes["Material Output"].inputs["Surface"])
    add_mesh("plane", "Floor", (0, 0, 0), floor, size=8.0)
    add_mesh("plane", "Water", (0, 0, 1.0), water, size=9.0)        # one sheet, normal up: air above
    add_light("SUN", "Sun", (0, 0, 5), energy=SUN_E, angle=math.radians(0.5)).rotation_euler = (
        math.radians(90.0 - SUN_ELEVATION), 0.0, 0.0)
    add_camera((0.0, 0.0, 3.0), (0.0, 0.0, 0.0), lens=24.0)        # straight down, 4.5 m wide
    scene.render.use_motion_blur = False


@pytest.mark.parametrize("ior", [1.33, 1.6])
def test_floor_under_water_seen_from_above_is_rho_E_over_pi_n_squared(ior):
    """Caustic pass (the floor's only light: the sun's shadow rays stop at the surface, as in Cycles)
    at the image centre against ``expected(ior)``."""
    _scene(ior)
    imgs, res = render_stpm(bpy.context.scene, samples=4, seeds=(0,), photons_caustic=400_000,
                            photons_global=0, k_nearest=50)
    assert res.plan["caustics"], res.plan["reasons"]
    lum = imgs[0].mean(axis=-1)
    got = float(lum[6:18, 8:24].mean())            # the central 2.2 x 1.7 m
    want = expected(ior)
    print(f"ior {ior}: floor centre {got:.5f}, expected {want:.5f} (ratio {got / want:.4f}); "
          f"without 1 / n^2 it would be {want * ior ** 2:.5f}")
    assert abs(got / want - 1.0) < TOL, (got, want)
