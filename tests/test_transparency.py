"""Transparent surfaces (stpm_core/transparency.py): analytic answers on small core scenes.

A white diffuse floor (rho = 0.8) at z = 0 under a sun from straight above (S W/m^2), seen by an
orthographic camera from above, with sheets of a Transparent BSDF (tint c) above it.  Each sheet
the camera ray crosses multiplies what it sees by c, and each sheet the shadow ray crosses
multiplies the sun's light by c: L = rho / pi * S * c^(2 k) for k sheets.  More sheets than
``RenderSettings.transparent_max_bounces`` (default ``TRANSPARENT_MAX_BOUNCES`` = 8, Cycles')
absorb the ray: black where the camera ray meets them, shadow where the shadow ray does.  Photons
pass the same way: the global map's irradiance on the floor below a sheet is c times the
unshadowed one, and 0 with a limit of 0.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from stpm_core.nodes import Link, Node, ShaderGraph
from stpm_core.render import render
from stpm_core.scene import Material, Light
from stpm_core.motion import MotionTransform
from stpm_core.settings import RenderSettings
from stpm_core.transparency import TRANSPARENT_MAX_BOUNCES

from scenes import make_scene, ortho_camera_down, plane_mesh, translate

S = 3.0
RHO = 0.8
TINT = (0.9, 0.6, 0.3)


def _sheet_material(tint=TINT, mix=None) -> Material:
    nodes = {"T": Node("ShaderNodeBsdfTransparent", inputs={"Color": tuple(tint)}, outputs={"BSDF": "SHADER"})}
    surface = Link("T", "BSDF")
    if mix is not None:      # Mix(Transparent, Diffuse black, fac = mix): a fraction mix is opaque black
        nodes["D"] = Node("ShaderNodeBsdfDiffuse", inputs={"Color": (0.0, 0.0, 0.0)}, outputs={"BSDF": "SHADER"})
        nodes["M"] = Node("ShaderNodeMixShader", inputs={"Fac": mix, "Shader": Link("T", "BSDF"),
                                                         "Shader_001": Link("D", "BSDF")},
                          outputs={"Shader": "SHADER"})
        surface = Link("M", "Shader")
    return Material(name="Sheet", graph=ShaderGraph(nodes=nodes, surface=surface))


def _scene(n_sheets: int, mix=None, res=(8, 8)):
    floor = plane_mesh(4.0, z=0.0, material=0)
    objs = [floor] + [(plane_mesh(4.0, z=0.0, material=1, name=f"sheet{i}"), translate(0, 0, 0.2 + 0.1 * i))
                      for i in range(n_sheets)]
    mats = [Material(name="Floor", base_color=np.full(3, RHO)), _sheet_material(mix=mix)]
    sun = Light(type="SUN", power=S, transform=MotionTransform.static(np.eye(4)))
    return make_scene(objs, mats, ortho_camera_down(5.0, 1.0), [sun], resolution=res)


@pytest.mark.parametrize("k", [0, 1, 3])
def test_each_sheet_tints_the_view_and_the_shadow(k):
    res = render(_scene(k), RenderSettings(samples=2, photons_global=0, photons_caustic=0))
    expect = RHO / math.pi * S * np.asarray(TINT) ** (2 * k)
    np.testing.assert_allclose(res.passes["Combined"][..., :3], np.broadcast_to(expect, (8, 8, 3)), rtol=1e-6)   # float32 passes


@pytest.mark.parametrize("limit", [0, 1, 3, TRANSPARENT_MAX_BOUNCES])
def test_more_sheets_than_the_limit_absorb_the_ray(limit):
    """transparent_max_bounces = L: L sheets are passed (camera and shadow ray, L each), L + 1 are
    black (as Cycles: the path ends where the limit is hit; the default L is 8)."""
    s = RenderSettings(samples=1, photons_global=0, photons_caustic=0, transparent_max_bounces=limit)
    if limit == TRANSPARENT_MAX_BOUNCES:
        s = RenderSettings(samples=1, photons_global=0, photons_caustic=0)            # the default
    res = render(_scene(limit + 1), s)
    assert np.all(res.passes["Combined"][..., :3] == 0.0)
    res = render(_scene(limit), s)
    expect = RHO / math.pi * S * np.asarray(TINT) ** (2 * limit)
    np.testing.assert_allclose(res.passes["Combined"][..., :3], np.broadcast_to(expect, (8, 8, 3)), rtol=1e-5)


def _scene_camera_below(n_sheets: int):
    """_scene with the camera under the sheets (z = 0.15): only the shadow rays cross them."""
    sc = _scene(n_sheets)
    sc.camera = ortho_camera_down(0.15, 1.0)
    return sc


def _scene_light_below(n_sheets: int):
    """_scene lit by a point light under the sheets (z = 0.1) instead of the sun: only the camera
    rays cross them."""
    sc = _scene(n_sheets)
    sc.lights = [Light(type="POINT", power=50.0, transform=MotionTransform.static(translate(0.0, 0.0, 0.1)))]
    return sc


@pytest.mark.parametrize("limit", [1, 2, 8])
def test_the_limit_holds_for_shadow_rays_and_camera_rays_alike(limit):
    """Three sheets: shadow rays alone (camera under them) and camera rays alone (light under
    them) get through with a limit of 3 or more and are stopped by 1 or 2."""
    s = RenderSettings(samples=1, photons_global=0, photons_caustic=0, transparent_max_bounces=limit)
    shadow = render(_scene_camera_below(3), s).passes["Combined"][..., :3]
    camera = render(_scene_light_below(3), s).passes["Combined"][..., :3]
    if limit >= 3:
        np.testing.assert_allclose(shadow, np.broadcast_to(RHO / math.pi * S * np.asarray(TINT) ** 3, (8, 8, 3)),
                                   rtol=1e-5)
        assert np.all(camera > 0.0)
    else:
        assert np.all(shadow == 0.0) and np.all(camera == 0.0)


def test_a_mix_with_an_opaque_shader_passes_in_proportion():
    """Mix(Transparent, black Diffuse, 0.25): 75 % of camera rays and 75 % of shadow rays pass, so
    the floor's mean is rho / pi S (0.75 c)^2, each sample 0 or c^2 / 0.75^0 scaled (unbiased)."""
    res = render(_scene(1, mix=0.25, res=(16, 16)), RenderSettings(samples=64, photons_global=0, photons_caustic=0,
                                                                   seed=3))
    got = res.passes["Combined"][..., :3].mean(axis=(0, 1))
    expect = RHO / math.pi * S * (0.75 * np.asarray(TINT)) ** 2
    np.testing.assert_allclose(got, expect, rtol=0.03)


@pytest.mark.parametrize("limit", [TRANSPARENT_MAX_BOUNCES, 0])
def test_photons_pass_transparent_sheets_tinted(limit):
    """Global-map photons (stored from the first diffuse hit on, min_nondelta = 0) land on the
    floor through the sheet, each with the sun's power times the tint: over the middle 3 x 3 m of
    the floor they sum to S c W/m^2 (the sun's irradiance through the sheet); with
    transparent_max_bounces = 0 the sheet stops them all (and stores none: it is not diffuse)."""
    from stpm_core.bsdf import MaterialTable
    from stpm_core.lights import LightSet
    from stpm_core.photons.trace import trace_global_map
    from stpm_core.raycast import make_caster
    sc = _scene(1)
    caster, lights = make_caster(sc), LightSet(sc)
    recs, _ = trace_global_map(sc, RenderSettings(photons_global=20000, max_depth=1, transparent_max_bounces=limit),
                               caster, lights, MaterialTable(sc.materials), min_nondelta=0)
    from stpm_core.photons.record import photon_origin
    pos, power = recs["position"] + photon_origin(sc), recs["power"]     # records are relative to it
    assert np.all(np.abs(pos[:, 2]) < 1e-3)                     # nothing stored on the sheet
    inside = (np.abs(pos[:, 0]) < 1.5) & (np.abs(pos[:, 1]) < 1.5)
    E = power[inside].sum(axis=0) / 9.0
    np.testing.assert_allclose(E, S * np.asarray(TINT) if limit else 0.0, rtol=0.05)


def _stochastic_floor(kind: str) -> Material:
    """A white floor whose closure is picked per hit: Mix(Transparent, Diffuse) by 0.5, or
    Add(Emission ~0, Diffuse), or a Principled BSDF of Alpha 0.5."""
    d = Node("ShaderNodeBsdfDiffuse", inputs={"Color": (RHO, RHO, RHO)}, outputs={"BSDF": "SHADER"})
    if kind == "mix":
        nodes = {"T": Node("ShaderNodeBsdfTransparent", inputs={"Color": (1.0, 1.0, 1.0)}, outputs={"BSDF": "SHADER"}),
                 "D": d, "M": Node("ShaderNodeMixShader", inputs={"Fac": 0.5, "Shader": Link("T", "BSDF"),
                                                                  "Shader_001": Link("D", "BSDF")},
                                   outputs={"Shader": "SHADER"})}
        out = Link("M", "Shader")
    elif kind == "add":
        nodes = {"E": Node("ShaderNodeEmission", inputs={"Color": (1.0, 1.0, 1.0), "Strength": 1e-6},
                           outputs={"Emission": "SHADER"}),
                 "D": d, "A": Node("ShaderNodeAddShader", inputs={"Shader": Link("E", "Emission"),
                                                                  "Shader_001": Link("D", "BSDF")},
                                   outputs={"Shader": "SHADER"})}
        out = Link("A", "Shader")
    else:
        nodes = {"P": Node("ShaderNodeBsdfPrincipled", inputs={"Base Color": (RHO, RHO, RHO), "Alpha": 0.5,
                                                               "Specular IOR Level": 0.0},
                           outputs={"BSDF": "SHADER"})}
        out = Link("P", "BSDF")
    return Material(name=kind, graph=ShaderGraph(nodes=nodes, surface=out))


@pytest.mark.parametrize("kind", ["mix", "add", "alpha"])
def test_photons_are_stored_on_surfaces_that_pick_their_closure(kind):
    """The photon map estimates the irradiance on a surface whatever closure a photon picks there:
    on a floor of Mix(Transparent, Diffuse), Add(Emission, Diffuse) or Principled Alpha 0.5 the
    stored photons still sum to the sun's S W/m^2 (before: half, as only the diffuse picks were
    stored, and camera paths weigh by their own pick again: Indirect came out x0.5)."""
    from stpm_core.bsdf import MaterialTable
    from stpm_core.lights import LightSet
    from stpm_core.photons.record import photon_origin
    from stpm_core.photons.trace import trace_global_map
    from stpm_core.raycast import make_caster
    floor = plane_mesh(4.0, z=0.0, material=0)
    sun = Light(type="SUN", power=S, transform=MotionTransform.static(np.eye(4)))
    sc = make_scene([floor], [_stochastic_floor(kind)], ortho_camera_down(5.0, 1.0), [sun], resolution=(8, 8))
    recs, _ = trace_global_map(sc, RenderSettings(photons_global=20000, max_depth=1), make_caster(sc),
                               LightSet(sc), MaterialTable(sc.materials), min_nondelta=0)
    pos = recs["position"] + photon_origin(sc)
    inside = (np.abs(pos[:, 0]) < 1.5) & (np.abs(pos[:, 1]) < 1.5) & (np.abs(pos[:, 2]) < 1e-3)
    E = recs["power"][inside].sum(axis=0) / 9.0
    np.testing.assert_allclose(E, S, rtol=0.05)
